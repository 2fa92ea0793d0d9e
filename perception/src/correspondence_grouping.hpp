#pragma once
// Private: the correspondence stages shared by registration and recognition (Johnson & Hebert,
// PAMI 1999, section 5): similarity filtering, geometric consistency, grouping, a transform per
// group.
#include <cstdint>
#include <vector>

#include "artisan/core/pose.hpp"
#include "artisan/core/triangle_mesh.hpp"
#include "artisan/perception/icp.hpp"

namespace artisan::detail {

struct Correspondence {
  size_t source;  ///< index into the source (scene) oriented points
  size_t target;  ///< index into the target (model) oriented points
  float similarity;
};

struct GroupingParams {
  double similarity_ratio = 0.5;        ///< [1] drop matches below this share of the best similarity
  double geometric_consistency = 0.25;  ///< [1] T_gc (eq. 9)
  double gamma_m = 0.0;                 ///< [m] gamma of the grouping distance (eq. 10)
  int max_groups = 40;
  int min_group_size = 3;
  size_t max_candidates = 1500;         ///< strongest matches kept for the quadratic stages
};

struct GroupedTransform {
  Transform T_target_source;
  size_t size;
  std::vector<Correspondence> members;
};

/// The geometric consistency of every pair of the candidates a grouping last considered, for the
/// next grouping of mostly the same candidates (a recognizer's search, as surface gets explained).
struct PairAgreements {
  std::vector<Correspondence> candidates;
  std::vector<uint8_t> pair;  ///< n x n
};

struct GroupingResult {
  std::vector<GroupedTransform> groups;
  size_t consistent_candidates = 0;
};

/// The short ICP that verifies a candidate pose on clouds resampled at `resolution_m` (section 5.3).
inline IcpSettings verification_icp(double resolution_m, int iterations) {
  IcpSettings s;
  s.max_iterations = iterations;
  s.max_correspondence_distance_m = 2.0 * resolution_m;
  s.huber_delta_m = 0.5 * resolution_m;
  s.max_source_points = 1500;
  return s;
}

/// With `reuse`, the agreements of pairs it holds are taken from it, and it is replaced by this
/// grouping's (the result is the same either way).
GroupingResult group_correspondences(const PointCloud& source, const PointCloud& target, std::vector<Correspondence> candidates,
                                     const GroupingParams& params, PairAgreements* reuse = nullptr);

}  // namespace artisan::detail
