// Collision scene on Bullet: one btCollisionObject per body with a quantized BVH over the exact
// triangles; query shapes are convex and tested body by body with contactPairTest (closest-point
// algorithms, so positive distances up to a threshold are reported too).
#include "artisan/worldmodel/collision_scene.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

#include <btBulletCollisionCommon.h>

#include "artisan/core/error.hpp"

namespace artisan::worldmodel {
namespace {

// Query shapes keep a small margin: GJK is robust with one, and boxes/cylinders keep their size
// (Bullet puts their margin inside); hulls are shrunk by it towards their centroid.
constexpr double kShapeMargin = 1e-4;

btTransform to_bt(const Transform& T) {
  const Eigen::Matrix3d R = T.rotation();
  btMatrix3x3 basis(R(0, 0), R(0, 1), R(0, 2), R(1, 0), R(1, 1), R(1, 2), R(2, 0), R(2, 1), R(2, 2));
  return btTransform(basis, btVector3(T.translation().x(), T.translation().y(), T.translation().z()));
}

Eigen::Vector3d to_eigen(const btVector3& v) { return {v.x(), v.y(), v.z()}; }

bool finite_pose(const Transform& T) { return T.matrix().allFinite(); }

struct MeshEntry {
  std::shared_ptr<const TriangleMesh> mesh;
  std::unique_ptr<btTriangleIndexVertexArray> arrays;
  std::unique_ptr<btBvhTriangleMeshShape> shape;
};

struct Body {
  int64_t id = 0;
  std::shared_ptr<MeshEntry> entry;
  std::unique_ptr<btCollisionObject> object;
  double margin_m = 0.0;
};

std::unique_ptr<btConvexShape> make_shape(const QueryShape& s) {
  const auto bad = [&](const std::string& what) { return Error("query shape '" + s.name + "': " + what); };
  if (!finite_pose(s.T_world_shape)) throw bad("pose is not finite");
  std::unique_ptr<btConvexShape> shape;
  switch (s.kind) {
    case QueryShape::Kind::box:
      if (!(s.size.allFinite() && s.size.minCoeff() > 0)) throw bad("box size must be positive");
      shape = std::make_unique<btBoxShape>(btVector3(s.size.x() / 2, s.size.y() / 2, s.size.z() / 2));
      break;
    case QueryShape::Kind::sphere:
      if (!(std::isfinite(s.radius_m) && s.radius_m > 0)) throw bad("sphere radius must be positive");
      return std::make_unique<btSphereShape>(s.radius_m);  // a sphere is all margin
    case QueryShape::Kind::cylinder:
      if (!(std::isfinite(s.radius_m) && s.radius_m > 0 && std::isfinite(s.length_m) && s.length_m > 0))
        throw bad("cylinder radius and length must be positive");
      shape = std::make_unique<btCylinderShapeZ>(btVector3(s.radius_m, s.radius_m, s.length_m / 2));
      break;
    case QueryShape::Kind::capsule:
      if (!(std::isfinite(s.radius_m) && s.radius_m > 0 && std::isfinite(s.length_m) && s.length_m >= 0))
        throw bad("capsule radius must be positive and length not negative");
      return std::make_unique<btCapsuleShapeZ>(s.radius_m, s.length_m);
    case QueryShape::Kind::convex_hull: {
      if (s.points.size() < 4) throw bad("a convex hull needs at least 4 points");
      Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
      for (const auto& p : s.points) {
        if (!p.allFinite()) throw bad("hull point is not finite");
        centroid += p.cast<double>();
      }
      centroid /= double(s.points.size());
      auto hull = std::make_unique<btConvexHullShape>();
      for (const auto& p : s.points) {
        // Bullet adds a hull's margin outside it: pull the points in by as much.
        Eigen::Vector3d q = p.cast<double>();
        const Eigen::Vector3d d = q - centroid;
        const double n = d.norm();
        if (n > kShapeMargin) q -= d / n * kShapeMargin;
        hull->addPoint(btVector3(q.x(), q.y(), q.z()), false);
      }
      hull->recalcLocalAabb();
      hull->optimizeConvexHull();
      shape = std::move(hull);
      break;
    }
  }
  shape->setMargin(kShapeMargin);
  return shape;
}

bool allowed(const std::vector<AllowedPair>& pairs, const std::string& shape, int64_t body) {
  return std::any_of(pairs.begin(), pairs.end(), [&](const AllowedPair& p) {
    return (p.shape == "*" || p.shape == shape) && (p.body < 0 || p.body == body);
  });
}

// Collects the closest point pair between one query object and one body.
struct ClosestCallback : btCollisionWorld::ContactResultCallback {
  const btCollisionObject* query = nullptr;
  bool found = false;
  btScalar distance = std::numeric_limits<btScalar>::max();
  btVector3 on_query, on_body;

  btScalar addSingleResult(btManifoldPoint& cp, const btCollisionObjectWrapper* a, int, int,
                           const btCollisionObjectWrapper*, int, int) override {
    if (cp.getDistance() < distance) {
      found = true;
      distance = cp.getDistance();
      const bool query_is_a = a->getCollisionObject() == query;
      on_query = query_is_a ? cp.getPositionWorldOnA() : cp.getPositionWorldOnB();
      on_body = query_is_a ? cp.getPositionWorldOnB() : cp.getPositionWorldOnA();
    }
    return 0;
  }
};

}  // namespace

struct CollisionScene::Impl {
  btDefaultCollisionConfiguration configuration;
  btCollisionDispatcher dispatcher{&configuration};
  btDbvtBroadphase broadphase;
  btCollisionWorld world{&dispatcher, &broadphase, &configuration};
  std::map<int64_t, Body> bodies;
  std::map<const TriangleMesh*, std::weak_ptr<MeshEntry>> entries;

  std::shared_ptr<MeshEntry> entry_for(std::shared_ptr<const TriangleMesh> mesh) {
    if (auto it = entries.find(mesh.get()); it != entries.end())
      if (auto e = it->second.lock()) return e;
    if (mesh->faces.empty()) throw Error("collision scene: a body mesh has no triangles");
    mesh->validate();
    auto e = std::make_shared<MeshEntry>();
    e->mesh = mesh;
    btIndexedMesh part;
    part.m_numTriangles = int(mesh->faces.size());
    part.m_triangleIndexBase = reinterpret_cast<const unsigned char*>(mesh->faces.data());
    part.m_triangleIndexStride = sizeof(Eigen::Vector3i);
    part.m_numVertices = int(mesh->vertices.size());
    part.m_vertexBase = reinterpret_cast<const unsigned char*>(mesh->vertices.data());
    part.m_vertexStride = sizeof(Eigen::Vector3f);
    part.m_indexType = PHY_INTEGER;
    part.m_vertexType = PHY_FLOAT;
    e->arrays = std::make_unique<btTriangleIndexVertexArray>();
    e->arrays->addIndexedMesh(part, PHY_INTEGER);
    e->shape = std::make_unique<btBvhTriangleMeshShape>(e->arrays.get(), true, true);
    e->shape->setMargin(0);
    entries[mesh.get()] = e;
    return e;
  }

  // Bodies whose bounding box comes within `reach` of the query's.
  template <typename Fn>
  void for_near_bodies(const btCollisionObject& query, double reach, Fn&& fn) const {
    btVector3 qmin, qmax;
    query.getCollisionShape()->getAabb(query.getWorldTransform(), qmin, qmax);
    const btVector3 r(reach, reach, reach);
    for (const auto& [id, body] : bodies) {
      btVector3 bmin, bmax;
      body.object->getCollisionShape()->getAabb(body.object->getWorldTransform(), bmin, bmax);
      if (TestAabbAgainstAabb2(qmin - r, qmax + r, bmin, bmax)) fn(body);
    }
  }

  // Closest pair between a query object and a body, if within `threshold`.
  std::optional<Contact> closest(const std::string& name, btCollisionObject& query, const Body& body, double threshold) {
    ClosestCallback cb;
    cb.query = &query;
    cb.m_closestDistanceThreshold = btScalar(threshold);
    world.contactPairTest(&query, body.object.get(), cb);
    if (!cb.found || cb.distance > threshold) return std::nullopt;
    return Contact{name, body.id, to_eigen(cb.on_query), to_eigen(cb.on_body), double(cb.distance) - body.margin_m};
  }
};

CollisionScene::CollisionScene() : impl_(std::make_unique<Impl>()) {}

CollisionScene::~CollisionScene() {
  for (auto& [id, body] : impl_->bodies) impl_->world.removeCollisionObject(body.object.get());
}

void CollisionScene::set_body(int64_t id, std::shared_ptr<const TriangleMesh> mesh, const Transform& T_world_body, double margin_m) {
  if (!mesh) throw Error("collision scene: body " + std::to_string(id) + " has no mesh");
  if (!finite_pose(T_world_body)) throw Error("collision scene: body " + std::to_string(id) + " has a non-finite pose");
  if (!(std::isfinite(margin_m) && margin_m >= 0))
    throw Error("collision scene: body " + std::to_string(id) + " has a negative or non-finite margin");
  auto entry = impl_->entry_for(std::move(mesh));
  remove(id);
  Body body;
  body.id = id;
  body.entry = entry;
  body.margin_m = margin_m;
  body.object = std::make_unique<btCollisionObject>();
  body.object->setCollisionShape(entry->shape.get());
  body.object->setWorldTransform(to_bt(T_world_body));
  impl_->world.addCollisionObject(body.object.get());
  impl_->bodies.emplace(id, std::move(body));
}

void CollisionScene::set_pose(int64_t id, const Transform& T_world_body) {
  auto it = impl_->bodies.find(id);
  if (it == impl_->bodies.end()) throw Error("collision scene: no body " + std::to_string(id));
  if (!finite_pose(T_world_body)) throw Error("collision scene: body " + std::to_string(id) + " has a non-finite pose");
  it->second.object->setWorldTransform(to_bt(T_world_body));
  impl_->world.updateSingleAabb(it->second.object.get());
}

bool CollisionScene::remove(int64_t id) {
  auto it = impl_->bodies.find(id);
  if (it == impl_->bodies.end()) return false;
  impl_->world.removeCollisionObject(it->second.object.get());
  impl_->bodies.erase(it);
  return true;
}

bool CollisionScene::contains(int64_t id) const { return impl_->bodies.count(id) > 0; }

std::vector<int64_t> CollisionScene::bodies() const {
  std::vector<int64_t> ids;
  for (const auto& [id, body] : impl_->bodies) ids.push_back(id);
  return ids;
}

size_t CollisionScene::triangle_count() const {
  size_t n = 0;
  for (const auto& [id, body] : impl_->bodies) n += body.entry->mesh->faces.size();
  return n;
}

CollisionResult CollisionScene::check(const std::vector<QueryShape>& shapes, const std::vector<AllowedPair>& allowed_pairs) const {
  CollisionResult result;
  for (const auto& s : shapes) {
    auto shape = make_shape(s);
    btCollisionObject query;
    query.setCollisionShape(shape.get());
    query.setWorldTransform(to_bt(s.T_world_shape));
    double reach = 0;
    for (const auto& [id, body] : impl_->bodies) reach = std::max(reach, body.margin_m);
    impl_->for_near_bodies(query, reach, [&](const Body& body) {
      if (allowed(allowed_pairs, s.name, body.id)) return;
      if (auto c = impl_->closest(s.name, query, body, body.margin_m); c && c->distance_m <= 0) {
        result.in_collision = true;
        result.contacts.push_back(*c);
      }
    });
  }
  return result;
}

DistanceResult CollisionScene::distance(const std::vector<QueryShape>& shapes, double max_distance_m,
                                        const std::vector<AllowedPair>& allowed_pairs) const {
  if (!(std::isfinite(max_distance_m) && max_distance_m > 0)) throw Error("distance query: max distance must be positive");
  DistanceResult result;
  result.distance_m = max_distance_m;
  for (const auto& s : shapes) {
    auto shape = make_shape(s);
    btCollisionObject query;
    query.setCollisionShape(shape.get());
    query.setWorldTransform(to_bt(s.T_world_shape));
    double margin = 0;
    for (const auto& [id, body] : impl_->bodies) margin = std::max(margin, body.margin_m);
    impl_->for_near_bodies(query, max_distance_m + margin, [&](const Body& body) {
      if (allowed(allowed_pairs, s.name, body.id)) return;
      // Only pairs nearer than the best so far can improve it.
      const double threshold = std::min(max_distance_m, result.distance_m) + body.margin_m;
      if (auto c = impl_->closest(s.name, query, body, threshold); c && c->distance_m < result.distance_m) {
        result.distance_m = c->distance_m;
        result.closest = *c;
      }
    });
  }
  return result;
}

RayHit CollisionScene::raycast(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, double max_range_m) const {
  if (!origin.allFinite() || !direction.allFinite() || direction.norm() == 0)
    throw Error("ray cast: the origin and direction must be finite and the direction non-zero");
  if (!(std::isfinite(max_range_m) && max_range_m > 0)) throw Error("ray cast: max range must be positive");
  const Eigen::Vector3d to = origin + direction.normalized() * max_range_m;
  const btVector3 a(origin.x(), origin.y(), origin.z()), b(to.x(), to.y(), to.z());
  btCollisionWorld::ClosestRayResultCallback cb(a, b);
  impl_->world.rayTest(a, b, cb);
  RayHit hit;
  if (!cb.hasHit()) return hit;
  hit.hit = true;
  for (const auto& [id, body] : impl_->bodies)
    if (body.object.get() == cb.m_collisionObject) hit.body = id;
  hit.point = to_eigen(cb.m_hitPointWorld);
  hit.normal = to_eigen(cb.m_hitNormalWorld).normalized();
  hit.distance_m = (hit.point - origin).norm();
  return hit;
}

}  // namespace artisan::worldmodel
