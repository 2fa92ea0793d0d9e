#pragma once
// Private: recognition's pose hypotheses (Johnson & Hebert's groups aside) and their cheap
// ranking: pairs of spin-image matches whose point-pair features agree, point-pair-feature
// voting's clusters, poses on the scene's cylinder axes; each scored by the share of a sample of
// the model's points it puts on the scene surface, and the best distinct kept. Used by recognize().
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Geometry>

#include "artisan/core/pose.hpp"
#include "artisan/core/triangle_mesh.hpp"
#include "artisan/perception/icp.hpp"
#include "artisan/perception/kdtree.hpp"
#include "artisan/perception/recognition.hpp"
#include "axis_proposals.hpp"
#include "correspondence_grouping.hpp"
#include "point_pair_voting.hpp"

namespace artisan::detail {

// A pose hypothesis (a group's, a pair of matches', a vote cluster's), with its cheap score.
struct PoseHypothesis {
  Transform T_scene_model = Transform::Identity();
  size_t first_support = 0;  ///< sampled model points on the scene surface when made
  size_t support = 0;        ///< the same, leaving out the surface accepted instances explain
  /// The scene points those sampled model points lie on, once ranked (its pose and tolerance do not
  /// change: its support is recounted from them as surface gets explained).
  std::optional<std::vector<uint32_t>> lies_on;
  bool done = false;         ///< refined and verified (or made redundant): not tried again
  RecognitionCandidate::Source source = RecognitionCandidate::Source::pairs;
  size_t size = 0;           ///< a group's correspondences
  std::optional<IcpResult> coarse;  ///< once refined by the coarse ICP
};

// A cheap verification of a model's pose, which ranks hypotheses before any ICP: of a sample of
// the model's points (evenly spread), those at the pose that lie on the scene surface (within
// `within_m` of a scene point whose normal agrees) not explained by an accepted instance.
class SurfaceSupport {
 public:
  SurfaceSupport(const PointCloud& model, int sample_points, const PointCloud& scene, const KdTree3& scene_tree)
      : model_(model), scene_(scene), tree_(scene_tree), nothing_explained_(scene.points.size(), 0) {
    const size_t step = std::max<size_t>(1, model.points.size() / static_cast<size_t>(std::max(sample_points, 1)));
    for (size_t i = 0; i < model.points.size(); i += step) sample_.push_back(i);
  }
  /// The least support a new hypothesis needs: `share` of the sample.
  size_t min_support(double share) const { return static_cast<size_t>(std::ceil(share * static_cast<double>(sample_.size()))); }
  /// The support of a new hypothesis, with nothing explained yet.
  size_t first(const Transform& T_scene_model, double within_m) const { return (*this)(T_scene_model, within_m, nothing_explained_); }
  size_t operator()(const Transform& T_scene_model, double within_m, const std::vector<char>& explained) const {
    return count(lies_on(T_scene_model, within_m), explained);
  }
  /// The scene point each sampled model point on the scene surface lies on (some may repeat).
  std::vector<uint32_t> lies_on(const Transform& T_scene_model, double within_m) const {
    const Eigen::Isometry3f T = T_scene_model.cast<float>();
    std::vector<uint32_t> on;
    for (const size_t i : sample_) {
      const auto j = tree_.nearest_within(T * model_.points[i], static_cast<float>(within_m));
      if (j && (T.linear() * model_.normals[i]).dot(scene_.normals[j->first]) >= 0.7f) on.push_back(static_cast<uint32_t>(j->first));
    }
    return on;
  }
  /// Of those, the ones not explained.
  static size_t count(const std::vector<uint32_t>& lies_on, const std::vector<char>& explained) {
    return static_cast<size_t>(std::count_if(lies_on.begin(), lies_on.end(), [&](uint32_t j) { return !explained[j]; }));
  }

 private:
  const PointCloud& model_;
  const PointCloud& scene_;
  const KdTree3& tree_;
  const std::vector<char> nothing_explained_;
  std::vector<size_t> sample_;
};

// The rigid transform that maps two oriented model points onto two oriented scene points in the
// least-squares sense (Umeyama on the points and on points a pair length along each normal).
Transform pose_from_pairs(const Eigen::Vector3f& m_a, const Eigen::Vector3f& nm_a, const Eigen::Vector3f& m_b, const Eigen::Vector3f& nm_b,
                          const Eigen::Vector3f& s_a, const Eigen::Vector3f& ns_a, const Eigen::Vector3f& s_b, const Eigen::Vector3f& ns_b,
                          float length);

// Pose hypotheses of one model from pairs of its matches (RecognitionParams::pair_*): for each
// anchor scene point (in a fixed pseudo-random order), partner scene points within the model's
// diameter; every combination of a model match of each whose point-pair features (Drost et al.
// 2010: the distance, the angle of each normal to the joining line, the angle between the
// normals) agree gives a pose, scored by SurfaceSupport: those with enough support.
std::vector<PoseHypothesis> pair_hypotheses(const PointCloud& model, const PointCloud& scene, const SurfaceSupport& surface_support,
                                            const std::vector<detail::Correspondence>& matches, double res, const RecognitionParams& params);

// Hypotheses from point-pair-feature voting: the best vote clusters, scored by SurfaceSupport;
// those with enough support.
std::vector<PoseHypothesis> voting_hypotheses(const detail::PairFeatureModel& table, const PointCloud& scene, const std::vector<char>& background,
                                              const SurfaceSupport& surface_support, double res, const RecognitionParams& params);

// Hypotheses of a model made mostly of one cylinder (RecognitionParams::axis_hypotheses), or of
// a round part of one (round_part_hypotheses: `source` round_part), on the scene's cylinder axes
// of the cylinder's radius, scored by SurfaceSupport: per axis, those with enough support and at
// least 90% of the best there (a pipe partly hidden fits equally well at every shift that keeps
// its seen part on the scene: the visibility tests choose among them).
std::vector<PoseHypothesis> axis_hypotheses(const detail::ModelCylinder& cylinder, const std::vector<detail::SceneAxis>& axes,
                                            const SurfaceSupport& surface_support, double res, const RecognitionParams& params,
                                            RecognitionCandidate::Source source = RecognitionCandidate::Source::axis);

// Whether two poses of a model put its surface in the same place: every one of a sample of its
// points (evenly spread) at one pose lies within a tolerance of the model's surface at the
// other. Poses that a symmetry of the model relates (a flange or a pipe turned about its axis)
// are one pose; comparing rotations would count each turn as another.
class SameSurface {
 public:
  /// `tree`: over the model's points (the library's), kept by the caller.
  SameSurface(const PointCloud& model, const KdTree3& tree, size_t sample_points = 32) : tree_(tree) {
    const size_t step = std::max<size_t>(1, model.points.size() / sample_points);
    for (size_t i = 0; i < model.points.size(); i += step) sample_.push_back(model.points[i]);
    centre_ = Eigen::Vector3d::Zero();
    for (const auto& p : model.points) centre_ += p.cast<double>();
    centre_ /= static_cast<double>(std::max<size_t>(model.points.size(), 1));
    diameter_ = model.bounds().diagonal().norm();
  }
  double diameter() const { return diameter_; }
  /// How far apart the two poses put the centroid of the model's surface.
  double centre_distance(const Transform& a, const Transform& b) const { return (a * centre_ - b * centre_).norm(); }
  bool operator()(const Transform& a, const Transform& b, double tolerance_m) const {
    // The centroid of the surface first (cheap): a symmetry keeps it.
    if (centre_distance(a, b) > tolerance_m) return false;
    const Eigen::Isometry3f T = (b.inverse() * a).cast<float>();
    return std::all_of(sample_.begin(), sample_.end(),
                       [&](const Eigen::Vector3f& x) { return tree_.nearest_within(T * x, static_cast<float>(tolerance_m)).has_value(); });
  }

 private:
  const KdTree3& tree_;
  std::vector<Eigen::Vector3f> sample_;
  Eigen::Vector3d centre_;
  double diameter_ = 0;
};

// The best distinct hypotheses, best first: one of those that put the model's centre within a
// tenth of its diameter and turn it by less than 20 degrees from each other. (Merging a
// symmetric part's turns here as well, as the searches do, lost a pipe in bench scene 2: the
// pool needs the variety.)
std::vector<PoseHypothesis> best_distinct(std::vector<PoseHypothesis> made, const SameSurface& same, size_t pool);

}  // namespace artisan::detail
