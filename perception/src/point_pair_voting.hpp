#pragma once
// Private: pose proposals by point-pair-feature voting (Drost, Ulrich, Navab and Ilic, "Model
// Globally, Match Locally: Efficient and Robust 3D Object Recognition", CVPR 2010). Recognition
// uses them beside the spin-image matches: a vote needs no scene point's right model point
// among its nearest spin images, which on pipework (nearly surfaces of revolution) it often is not.
//
// The model: oriented points on a voxel grid of edge `step`, and every ordered pair of them in a
// table indexed by their quantised feature F = (|d|, angle(n1, d), angle(n2, d), angle(n1, n2))
// (eq. 1), with the angle alpha_m that turns the pair about the first point's normal into a
// canonical plane (section 3.3). A scene reference point paired with its scene neighbours votes,
// for each model pair with the same feature, for (model reference point, alpha = alpha_s - alpha_m)
// (eq. 3-4); the accumulator's peaks are poses. Poses of all reference points are clustered
// (section 3.4) and returned by total votes.
#include <array>
#include <cstdint>
#include <vector>

#include "artisan/core/pose.hpp"
#include "artisan/core/triangle_mesh.hpp"

namespace artisan::detail {

struct PairVotingParams {
  double step_m = 0.006;            ///< [m] sampling and distance quantisation step
  int angle_bins = 15;              ///< [1] bins over [0, pi] of each feature angle (12 degrees; 2 to 255)
  int alpha_bins = 30;              ///< [1] bins over [0, 2 pi) of the rotation about the normal (4 to 4096)
  /// [1] cells of the table holding more than this share of the model's pairs are not voted
  /// for: features that many pairs share say little (coplanar pairs on a flange's face, pairs
  /// along a pipe), and cost most (every scene pair on a box's face would vote for all of them)
  double max_cell_share = 0.005;
  int reference_stride = 5;         ///< [1] every n-th scene sample is a reference point
  int peaks_per_reference = 3;      ///< [1] accumulator maxima kept per reference point
  double cluster_distance_factor = 0.1;  ///< [model diameters] largest centre distance within a pose cluster
  double cluster_angle_deg = 24.0;  ///< [deg] largest rotation within a pose cluster
};

struct VotedPose {
  Transform T_scene_model = Transform::Identity();
  uint32_t votes = 0;  ///< summed over the cluster
};

class PairFeatureModel {
 public:
  /// The table of every ordered pair of the model's oriented points resampled at params.step_m.
  PairFeatureModel(const PointCloud& model_points, const PairVotingParams& params);

  /// Pose clusters of the model in `scene` (oriented points), best first. Scene points with
  /// `ignore` set (background planes) are neither reference points nor partners.
  std::vector<VotedPose> vote(const PointCloud& scene, const std::vector<char>& ignore) const;

  const PairVotingParams& params() const { return params_; }
  size_t points() const { return points_.points.size(); }
  size_t pairs() const { return entries_.size(); }  ///< in the table (dropped ones not counted)
  size_t dropped_pairs() const { return dropped_; }
  double diameter() const { return diameter_; }

 private:
  /// The quantised feature's cell in the table, or -1 when it lies beyond the model's diameter.
  int64_t cell(const Eigen::Vector3f& p1, const Eigen::Vector3f& n1, const Eigen::Vector3f& p2, const Eigen::Vector3f& n2) const;

  PairVotingParams params_;
  PointCloud points_;          ///< resampled model points
  std::vector<Transform> T_local_model_;  ///< per point: moves it to the origin, its normal onto +x
  double diameter_ = 0;
  int distance_bins_ = 0;
  std::vector<uint32_t> offsets_;  ///< per cell, into entries_ (cells + 1)
  /// Per model pair, by cell: its reference point's index << 16 | alpha_m in 65536ths of a turn
  std::vector<uint32_t> entries_;
  static constexpr size_t kCosineSlots = 4096;
  std::array<uint8_t, kCosineSlots> angle_bin_of_cosine_{};  ///< a feature angle's bin, near enough, by its cosine's slot of [-1, 1]
  std::vector<float> bin_start_cosine_;                      ///< per feature-angle bin: the cosine of its smallest angle
  size_t dropped_ = 0;  ///< pairs in cells over max_cell_share
};

}  // namespace artisan::detail
