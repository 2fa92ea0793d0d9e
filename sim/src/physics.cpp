#include "artisan/sim/physics.hpp"

#include <memory>
#include <numbers>
#include <random>

#include <btBulletDynamicsCommon.h>

namespace artisan::sim {

namespace {

btTransform to_bt(const Transform& T) {
  const Eigen::Matrix3d R = T.linear();
  btMatrix3x3 m(R(0, 0), R(0, 1), R(0, 2), R(1, 0), R(1, 1), R(1, 2), R(2, 0), R(2, 1), R(2, 2));
  return btTransform(m, btVector3(T.translation().x(), T.translation().y(), T.translation().z()));
}

Transform from_bt(const btTransform& t) {
  Transform T = Transform::Identity();
  const btMatrix3x3& m = t.getBasis();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) T.linear()(r, c) = m[r][c];
  T.translation() = Eigen::Vector3d(t.getOrigin().x(), t.getOrigin().y(), t.getOrigin().z());
  return T;
}

// Uniform double in [0, 1) from the top 53 bits: the same on every platform (unlike
// std::uniform_real_distribution).
double uniform01(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

// A Bullet world holding every body of the workcell; owns shapes and meshes.
struct World {
  std::unique_ptr<btDefaultCollisionConfiguration> config = std::make_unique<btDefaultCollisionConfiguration>();
  std::unique_ptr<btCollisionDispatcher> dispatcher = std::make_unique<btCollisionDispatcher>(config.get());
  std::unique_ptr<btDbvtBroadphase> broadphase = std::make_unique<btDbvtBroadphase>();
  std::unique_ptr<btSequentialImpulseConstraintSolver> solver = std::make_unique<btSequentialImpulseConstraintSolver>();
  std::unique_ptr<btDiscreteDynamicsWorld> world;
  std::vector<std::unique_ptr<btTriangleMesh>> meshes;
  std::vector<std::unique_ptr<btCollisionShape>> shapes;
  std::vector<std::unique_ptr<btDefaultMotionState>> motion_states;
  std::vector<std::unique_ptr<btRigidBody>> rigid_bodies;  // one per workcell body, same order
  std::vector<Eigen::Vector3d> com_offsets;                // body frame -> centre-of-mass frame

  World() {
    world = std::make_unique<btDiscreteDynamicsWorld>(dispatcher.get(), broadphase.get(), solver.get(), config.get());
    world->setGravity(btVector3(0, 0, -9.81));
  }
  ~World() {
    for (auto& b : rigid_bodies) world->removeRigidBody(b.get());
  }

  btCollisionShape* shape_for(const Body& b, bool dynamic, double margin, Eigen::Vector3d& com) {
    com.setZero();
    std::unique_ptr<btCollisionShape> s;
    switch (b.shape.kind) {
      case CollisionShape::Kind::box:
        s = std::make_unique<btBoxShape>(btVector3(b.shape.size.x() / 2, b.shape.size.y() / 2, b.shape.size.z() / 2));
        break;
      case CollisionShape::Kind::sphere: s = std::make_unique<btSphereShape>(b.shape.radius_m); break;
      case CollisionShape::Kind::cylinder:
        s = std::make_unique<btCylinderShapeZ>(btVector3(b.shape.radius_m, b.shape.radius_m, b.shape.length_m / 2));
        break;
      case CollisionShape::Kind::mesh:
        if (dynamic) {
          for (const auto& v : b.mesh.vertices) com += v.cast<double>();
          com /= static_cast<double>(b.mesh.vertices.size());
          auto hull = std::make_unique<btConvexHullShape>();
          for (const auto& v : b.mesh.vertices) {
            const Eigen::Vector3d p = v.cast<double>() - com;
            hull->addPoint(btVector3(p.x(), p.y(), p.z()), false);
          }
          hull->recalcLocalAabb();
          hull->optimizeConvexHull();
          s = std::move(hull);
        } else {
          auto tm = std::make_unique<btTriangleMesh>();
          for (const auto& f : b.mesh.faces) {
            const auto& a = b.mesh.vertices[f[0]];
            const auto& c = b.mesh.vertices[f[1]];
            const auto& d = b.mesh.vertices[f[2]];
            tm->addTriangle(btVector3(a.x(), a.y(), a.z()), btVector3(c.x(), c.y(), c.z()), btVector3(d.x(), d.y(), d.z()));
          }
          s = std::make_unique<btBvhTriangleMeshShape>(tm.get(), true);
          meshes.push_back(std::move(tm));
        }
        break;
    }
    s->setMargin(margin);
    shapes.push_back(std::move(s));
    return shapes.back().get();
  }

  void add(const Body& b, const Transform& T_world_body, const SettleParams& p) {
    const bool dynamic = b.drop;
    Eigen::Vector3d com;
    btCollisionShape* shape = shape_for(b, dynamic, p.collision_margin_m, com);
    com_offsets.push_back(com);
    btVector3 inertia(0, 0, 0);
    const double mass = dynamic ? b.mass_kg : 0.0;
    if (dynamic) shape->calculateLocalInertia(mass, inertia);
    const Transform T_world_com = T_world_body * Eigen::Translation3d(com);
    motion_states.push_back(std::make_unique<btDefaultMotionState>(to_bt(T_world_com)));
    btRigidBody::btRigidBodyConstructionInfo info(mass, motion_states.back().get(), shape, inertia);
    info.m_friction = p.friction;
    info.m_rollingFriction = dynamic ? 0.002 : 0.0;
    info.m_restitution = p.restitution;
    info.m_linearDamping = 0.05;
    info.m_angularDamping = 0.2;
    rigid_bodies.push_back(std::make_unique<btRigidBody>(info));
    if (dynamic) rigid_bodies.back()->setActivationState(DISABLE_DEACTIVATION);
    world->addRigidBody(rigid_bodies.back().get());
  }

  Transform pose(size_t i) const {
    btTransform t;
    rigid_bodies[i]->getMotionState()->getWorldTransform(t);
    return from_bt(t) * Eigen::Translation3d(-com_offsets[i]);
  }
};

}  // namespace

SettleResult settle(Workcell& cell, const SettleParams& p) {
  SettleResult result;
  World w;
  std::mt19937_64 rng(cell.drop_seed);
  for (const auto& b : cell.bodies) {
    Transform T = b.T_world_body;
    if (b.drop) {
      ++result.dropped;
      // Seeded perturbation: a tilt about a random horizontal axis and a horizontal shift.
      const double axis_angle = 2 * std::numbers::pi * uniform01(rng);
      const double tilt = p.max_initial_tilt_rad * uniform01(rng);
      const double jx = p.initial_jitter_m * (2 * uniform01(rng) - 1), jy = p.initial_jitter_m * (2 * uniform01(rng) - 1);
      const Eigen::Vector3d axis(std::cos(axis_angle), std::sin(axis_angle), 0);
      Transform perturbed = Transform::Identity();
      perturbed.linear() = Eigen::AngleAxisd(tilt, axis).toRotationMatrix() * T.linear();
      perturbed.translation() = T.translation() + Eigen::Vector3d(jx, jy, 0);
      T = perturbed;
    }
    w.add(b, T, p);
  }
  if (result.dropped == 0) {
    result.at_rest = true;
    return result;
  }
  const int max_steps = static_cast<int>(std::ceil(p.max_time_s / p.time_step_s));
  const int rest_steps = static_cast<int>(std::ceil(p.rest_duration_s / p.time_step_s));
  int calm = 0;
  for (result.steps = 0; result.steps < max_steps && calm < rest_steps; ++result.steps) {
    w.world->stepSimulation(static_cast<btScalar>(p.time_step_s), 0);
    bool all_calm = true;
    for (size_t i = 0; i < cell.bodies.size() && all_calm; ++i) {
      if (!cell.bodies[i].drop) continue;
      const auto* rb = w.rigid_bodies[i].get();
      all_calm = rb->getLinearVelocity().length() < p.rest_linear_m_per_s &&
                 rb->getAngularVelocity().length() < p.rest_angular_rad_per_s;
    }
    calm = all_calm ? calm + 1 : 0;
  }
  result.simulated_time_s = result.steps * p.time_step_s;
  result.at_rest = calm >= rest_steps;
  for (size_t i = 0; i < cell.bodies.size(); ++i) {
    if (!cell.bodies[i].drop) continue;
    cell.bodies[i].T_world_body = w.pose(i);
    const auto* rb = w.rigid_bodies[i].get();
    if (rb->getLinearVelocity().length() >= p.rest_linear_m_per_s || rb->getAngularVelocity().length() >= p.rest_angular_rad_per_s)
      result.still_moving.push_back(cell.bodies[i].name);
  }
  return result;
}

ContactReport check_contacts(const Workcell& cell, const SettleParams& p) {
  World w;
  for (const auto& b : cell.bodies) w.add(b, b.T_world_body, p);
  w.world->performDiscreteCollisionDetection();
  ContactReport report;
  auto* dispatcher = w.world->getDispatcher();
  for (int m = 0; m < dispatcher->getNumManifolds(); ++m) {
    const btPersistentManifold* manifold = dispatcher->getManifoldByIndexInternal(m);
    for (int c = 0; c < manifold->getNumContacts(); ++c) {
      // Bullet's distance between the shapes (margins included); negative means overlap.
      const double depth = -manifold->getContactPoint(c).getDistance();
      if (depth > report.max_penetration_m) {
        report.max_penetration_m = depth;
        auto name = [&](const btCollisionObject* o) {
          for (size_t i = 0; i < w.rigid_bodies.size(); ++i)
            if (w.rigid_bodies[i].get() == o) return cell.bodies[i].name;
          return std::string("?");
        };
        report.deepest_pair = name(manifold->getBody0()) + " / " + name(manifold->getBody1());
      }
    }
  }
  return report;
}

}  // namespace artisan::sim
