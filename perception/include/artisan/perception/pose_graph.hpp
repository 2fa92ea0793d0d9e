#pragma once
// Pose-graph adjustment: consistent poses of several views from their pairwise registrations
// (loop closure). Minimises sum_k w_k |log(Z_k^-1 T_i^-1 T_j)|^2 over the node poses T (node 0
// fixed) by Gauss-Newton on SE(3), rotation in radians and translation in metres weighted by
// `translation_weight`.
#include <vector>

#include "artisan/core/pose.hpp"

namespace artisan {

struct PoseGraphEdge {
  int from = 0;                              ///< node i
  int to = 0;                                ///< node j
  Transform T_from_to = Transform::Identity();  ///< measured T_i_j
  double weight = 1.0;                        ///< [1] e.g. the registration's overlap
};

struct PoseGraphSettings {
  int max_iterations = 20;           ///< [1]
  double translation_weight = 10.0;  ///< [1/m] 1 cm of translation error counts like 0.1 rad of rotation
};

struct PoseGraphResult {
  std::vector<Transform> T_root_node;   ///< adjusted poses, node 0 = root = identity
  int iterations = 0;
  double rms_rotation_deg_before = 0.0, rms_rotation_deg_after = 0.0;  ///< [deg] edge residuals
  double rms_translation_m_before = 0.0, rms_translation_m_after = 0.0; ///< [m] edge residuals
};

/// Adjusts `T_root_node` (initial guesses, node 0 the root) to the edges. Throws artisan::Error
/// when an edge names a missing node.
PoseGraphResult optimize_pose_graph(const std::vector<Transform>& T_root_node, const std::vector<PoseGraphEdge>& edges,
                                    const PoseGraphSettings& settings = {});

}  // namespace artisan
