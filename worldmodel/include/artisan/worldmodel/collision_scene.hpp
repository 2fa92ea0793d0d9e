#pragma once
// The collision scene of a world model: static bodies (the environment and the recognized
// objects, exact triangle meshes in bounding-volume hierarchies) checked against convex query
// shapes (boxes, spheres, cylinders, capsules, convex hulls) at poses: collision, minimum
// distance with witness points, and ray casts. Exact on the triangles: the hierarchy only prunes
// (oriented-box separating axes, distance lower bounds), and every triangle that may be within
// reach is decided by an exact narrow phase (point-triangle for spheres, GJK otherwise, EPA for
// penetration depths).
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "artisan/core/pose.hpp"
#include "artisan/core/triangle_mesh.hpp"

namespace artisan::worldmodel {

/// A convex query shape in its own frame.
struct QueryShape {
  enum class Kind { box, sphere, cylinder, capsule, convex_hull };
  std::string name;                                 ///< names the shape in contacts and allowed pairs
  Kind kind = Kind::box;
  Eigen::Vector3d size = Eigen::Vector3d::Zero();   ///< box: full size [m]
  double radius_m = 0.0;                            ///< sphere, cylinder, capsule [m]
  double length_m = 0.0;                            ///< cylinder, capsule: along z [m]
  std::vector<Eigen::Vector3f> points;              ///< convex_hull: its points [m]
  Transform T_world_shape = Transform::Identity();
};

/// A collision that does not count: shape name (or "*") with a body ID (or -1 for any).
struct AllowedPair {
  std::string shape;
  int64_t body = -1;
};

struct Contact {
  std::string shape;
  int64_t body = 0;
  Eigen::Vector3d point_on_shape = Eigen::Vector3d::Zero();  ///< world frame [m]
  Eigen::Vector3d point_on_body = Eigen::Vector3d::Zero();   ///< world frame [m]
  double distance_m = 0.0;  ///< signed surface distance, less the body's margin; < 0 is collision
};

/// How much check() reports; the less, the sooner it can stop.
struct CheckOptions {
  /// Report the deepest contact of each colliding (shape, body) pair, which visits every
  /// triangle within reach; otherwise the first contact found per pair (as deep as that one
  /// triangle's contact), which stops the pair at its first colliding triangle.
  bool deepest_contacts = false;
  /// Stop at the first colliding pair: `in_collision` and one contact (a planner's boolean check).
  bool stop_at_first = false;
};

struct CollisionResult {
  bool in_collision = false;
  std::vector<Contact> contacts;  ///< one per colliding (shape, body) pair, see CheckOptions
};

struct DistanceResult {
  double distance_m = 0.0;         ///< the smallest, or max_distance when nothing is nearer
  std::optional<Contact> closest;  ///< the witness pair, when something is within max_distance
};

struct RayHit {
  bool hit = false;
  int64_t body = 0;
  Eigen::Vector3d point = Eigen::Vector3d::Zero();
  Eigen::Vector3d normal = Eigen::Vector3d::Zero();
  double distance_m = 0.0;
};

/// A body's triangles in a bounding-volume hierarchy: immutable once built, so it can be built on
/// another thread and shared by several bodies (a model recognized twice).
class BodyGeometry;

class CollisionScene {
 public:
  CollisionScene();
  ~CollisionScene();
  CollisionScene(const CollisionScene&) = delete;
  CollisionScene& operator=(const CollisionScene&) = delete;

  /// Adds or replaces body `id`: `mesh` (in the body frame) at `T_world_body`, inflated by
  /// `margin_m` for collision and distance. The hierarchy is built once per mesh and shared:
  /// passing the same mesh object again (e.g. a model recognized twice) reuses it.
  /// Throws artisan::Error for a mesh without faces or with non-finite vertices.
  void set_body(int64_t id, std::shared_ptr<const TriangleMesh> mesh, const Transform& T_world_body, double margin_m = 0.0);
  /// The same with a hierarchy built beforehand (see build_geometry()).
  void set_body(int64_t id, std::shared_ptr<const BodyGeometry> geometry, const Transform& T_world_body, double margin_m = 0.0);
  /// Builds the hierarchy over `mesh` (in the body frame); touches no scene, so any thread may
  /// call it. Throws artisan::Error like set_body().
  static std::shared_ptr<const BodyGeometry> build_geometry(std::shared_ptr<const TriangleMesh> mesh);
  /// Moves a body without rebuilding anything. Throws for an unknown ID.
  void set_pose(int64_t id, const Transform& T_world_body);
  /// Returns false when there was no such body.
  bool remove(int64_t id);
  /// Body `id`'s hierarchy (nullptr when there is no such body): whoever holds it last frees it,
  /// which for millions of triangles takes milliseconds.
  std::shared_ptr<const BodyGeometry> geometry(int64_t id) const;
  bool contains(int64_t id) const;
  std::vector<int64_t> bodies() const;
  size_t triangle_count() const;  ///< over all bodies

  /// Which of `shapes` touch or penetrate a body closer than its margin (allowed pairs skipped).
  /// Throws artisan::Error naming the shape when a shape is malformed (non-positive size,
  /// non-finite pose, fewer than 4 hull points).
  CollisionResult check(const std::vector<QueryShape>& shapes, const std::vector<AllowedPair>& allowed = {},
                        const CheckOptions& options = {}) const;
  /// The smallest distance between any of `shapes` and any body (less the body's margin), up to
  /// `max_distance_m`; the search prunes by the best distance found so far. When a shape
  /// penetrates a body (or comes within its margin) the search stops there: a negative distance
  /// is that contact's depth, not necessarily the deepest (check() with deepest_contacts gives
  /// the deepest per pair; searching for it costs an EPA per overlapping triangle).
  DistanceResult distance(const std::vector<QueryShape>& shapes, double max_distance_m,
                          const std::vector<AllowedPair>& allowed = {}) const;
  /// The first body a ray from `origin` along `direction` meets within `max_range_m`.
  RayHit raycast(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction, double max_range_m) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace artisan::worldmodel
