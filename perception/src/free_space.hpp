#pragma once
// Private: what the sensors saw of a scene, and a model at a pose checked against it (the
// free-space and visibility reasoning of recognition: Johnson & Hebert verify a match by the
// model's overlap with the scene; a model may also not stand in front of what a sensor saw, or
// pass through the table it lies on). Used by recognize() and check_pose().
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "artisan/core/pose.hpp"
#include "artisan/core/triangle_mesh.hpp"
#include "artisan/perception/integration.hpp"
#include "artisan/perception/kdtree.hpp"
#include "bin_depths.hpp"

namespace artisan::detail {

// The plane with the most oriented points on it (within `distance`, normals within 20 degrees),
// of those not `taken`: RANSAC, 150 tries from single oriented points.
struct Plane {
  static constexpr float kCos20Deg = 0.93969262f;
  Eigen::Vector3f normal = Eigen::Vector3f::Zero();
  float offset = 0, distance = 0;
  size_t count = 0;
  bool holds(const Eigen::Vector3f& p, const Eigen::Vector3f& n) const {
    return std::abs(normal.dot(p) - offset) <= distance && std::abs(normal.dot(n)) >= kCos20Deg;
  }
};
Plane largest_plane(const PointCloud& cloud, const std::vector<char>& taken, double distance, uint64_t& state);

// A model of the library as its poses are fitted and checked: its points (with normals) and the
// library's k-d tree over them, in the model's frame.
struct LibraryModel {
  const PointCloud& points;
  const KdTree3& tree;
};

// What each sensor saw of the scene, for the free-space test: per view, the nearest scene depth
// in each bin of a projection (gnomonic about the view's main direction for perspective rays, an
// orthographic grid for parallel rays).
class FreeSpace {
 public:
  FreeSpace(const PointCloud& scene, const KdTree3& scene_tree, const std::vector<SensorView>& views, double resolution_m,
            double tolerance_m, double max_incidence_rad, size_t largest_model_points, size_t smallest_support, bool own_bin_only,
            double own_bin_min_incidence_rad);

  struct Check {
    double free_space = 0;  ///< share of the sensor-facing model surface in front of what was seen
    double explained = 1;   ///< share of the model surface a sensor should have seen, and nothing hid, that it did see
    double occluded = 0;    ///< share of the model surface a sensor should have seen that something in front hid
    double planarity = 0;   ///< largest eigenvalue of the mean outer product of the explained surface's normals (1: one plane)
    double continued = 0;   ///< share of the explained surface whose tangent plane the scene carries on beyond the model
    double through = 0;     ///< share of the model on the less of the two sides of a solid's face it passes through
  };
  /// The model (its points at T) against what each view saw. A model point faces a view when its
  /// normal points at the sensor; it should have been seen when it faces the view and nothing of
  /// the model itself lies in front of it. Such a point is
  ///  - explained when a scene point lies within the tolerance (at most 2 resolutions) of it,
  ///    other than on a background plane (a plane larger than any model's whole surface: a
  ///    table, a wall; a model "found" flush with one, sunk into it, is explained by nothing of
  ///    its own);
  ///  - in free space when it lies in front of the nearest surface the sensor saw there (where
  ///    the object cannot be): the nearest in the 3 x 3 bins around its own;
  ///  - occluded when something the sensor saw lies in front of it: no evidence either way, so it
  ///    counts neither for nor against.
  /// With own_bin_only, a point met beyond the grazing incidence whose own bin holds no return
  /// (a face at grazing incidence whose returns the scanner dropped) is no evidence either way
  /// unless something the sensor saw hides it (it counts as occluded).
  Check check(const LibraryModel& model, const Transform& T) const;
  /// The same, measuring `continued` (much of the work) only when `worth_it` holds for
  /// the rest of the check (`continued` 0 then); else it is NaN, not measured. With more than
  /// `most_through` of the model through a solid's face (measured first), nothing else is
  /// measured: every other figure NaN, which no test passes.
  Check check(const LibraryModel& model, const Transform& T, const std::function<bool(const Check&)>& worth_it,
              double most_through = std::numeric_limits<double>::infinity()) const;

  /// Per scene point: on a background plane (a plane larger than any model's whole surface).
  const std::vector<char>& background() const { return background_; }
  /// Per scene point: on a background or a support plane (a connected planar region of more
  /// points than `smallest_support`: a table top seen between the parts on it); the background
  /// planes only when support planes were not asked for.
  const std::vector<char>& support() const { return support_; }

 private:
  // The scene's largest planes, the largest first, up to three, down to `smallest_support` points
  // (when 0: no support planes, down to `largest_model_points`). Background: a whole plane larger than any model's
  // whole surface (more points than `largest_model_points` has at the same resolution). Support:
  // a connected region of a plane of more than `smallest_support` points (the tops of pipes lying
  // side by side on a table are one plane, but apart).
  void find_planes(size_t largest_model_points, size_t smallest_support);

  /// The face of a solid the scene lies on over a large region (a background or a support plane:
  /// a table top, the floor): its plane, its normal toward the side the sensors saw (its points'
  /// normals), and its region, the convex hull of its points in the plane (a table top is
  /// convex; what stands on it and hides it, at its edges too, makes no hole).
  struct Solid {
    Eigen::Vector3d normal, u, v;
    double offset = 0;
    std::vector<Eigen::Vector2d> hull;   ///< counter-clockwise
    std::vector<Eigen::Vector2d> edges;  ///< unit direction from each hull point to the next
    Solid(const PointCloud& scene, const std::vector<size_t>& face, const Eigen::Vector3f& plane_normal, float plane_offset);
    Eigen::Vector2d in_plane(const Eigen::Vector3d& p) const { return {u.dot(p), v.dot(p)}; }
    /// How far the point's foot on the plane lies outside the face's region [m] (at most 0: inside).
    double outside(const Eigen::Vector3d& p) const;
  };
  /// Whether a point lies over or under a solid's face: its foot on the face's plane in the face's
  /// seen region, or up to `reach` beyond it where the sensors saw something in front of the
  /// plane (the face carries on under what hides it - the parts on a table, the table's rims),
  /// and not past it (beyond a table's edge the sensor sees the floor).
  bool under(const Solid& solid, const Eigen::Vector3d& q, double reach) const;

  struct Key {
    int64_t u, v;
    double depth;
  };
  struct Map {
    SensorView view;
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  ///< rows: local x, y, z (z along the view)
    double bin = 1.0;
    detail::BinDepths nearest;  ///< the nearest scene depth per bin
    detail::BinDepths around;   ///< the nearest in the 3 x 3 bins about each bin (the bins are small)
    Eigen::Vector3d local(const Eigen::Vector3d& p) const {
      return view.rays == SensorView::Rays::kPerspective ? Eigen::Vector3d(R * (p - view.origin_mesh)) : Eigen::Vector3d(R * p);
    }
    Eigen::Vector3d toward(const Eigen::Vector3d& p) const {
      return view.rays == SensorView::Rays::kPerspective ? Eigen::Vector3d(view.origin_mesh - p) : view.toward_sensor_mesh;
    }
    /// The seen depth in the point's own bin, else the nearest around it.
    double seen_at(const Key& k) const {
      const double own = nearest.at(k.u, k.v);
      return std::isfinite(own) ? own : around.at(k.u, k.v);
    }
    std::optional<Key> key(const Eigen::Vector3d& p) const {
      const Eigen::Vector3d q = local(p);
      if (view.rays == SensorView::Rays::kPerspective) {
        if (!(q.z() > 1e-6)) return std::nullopt;
        return Key{static_cast<int64_t>(std::floor(q.x() / q.z() / bin)), static_cast<int64_t>(std::floor(q.y() / q.z() / bin)), q.norm()};
      }
      return Key{static_cast<int64_t>(std::floor(q.x() / bin)), static_cast<int64_t>(std::floor(q.y() / bin)), q.z()};
    }
  };
  const PointCloud& scene_;
  const KdTree3& tree_;
  double resolution_, tolerance_;
  double min_incidence_cos_;  ///< a model point seen at a larger incidence is no evidence either way
  bool own_bin_only_;         ///< a model point whose own bin the sensor saw nothing in is no evidence of free space
  /// The cosine of the incidence from which own_bin_only holds; a surface facing the sensor
  /// more squarely that returned nothing lay in a shadow.
  double grazing_cos_;
  std::vector<char> background_;  ///< per scene point: on a background plane
  std::vector<char> support_;     ///< per scene point: on a background or a support plane
  std::vector<Solid> solids_;     ///< the faces of the background and support planes
  std::vector<Map> maps_;
};

}  // namespace artisan::detail
