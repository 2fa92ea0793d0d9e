#include "pose_hypotheses.hpp"

#include <numbers>
#include <random>
#include <unordered_map>

namespace artisan::detail {

Transform pose_from_pairs(const Eigen::Vector3f& m_a, const Eigen::Vector3f& nm_a, const Eigen::Vector3f& m_b, const Eigen::Vector3f& nm_b,
                          const Eigen::Vector3f& s_a, const Eigen::Vector3f& ns_a, const Eigen::Vector3f& s_b, const Eigen::Vector3f& ns_b,
                          float length) {
  Eigen::Matrix<double, 3, 4> from, to;
  from << m_a.cast<double>(), m_b.cast<double>(), (m_a + length * nm_a).cast<double>(), (m_b + length * nm_b).cast<double>();
  to << s_a.cast<double>(), s_b.cast<double>(), (s_a + length * ns_a).cast<double>(), (s_b + length * ns_b).cast<double>();
  Transform T = Transform::Identity();
  T.matrix() = Eigen::umeyama(from, to, false);
  return T;
}

std::vector<PoseHypothesis> pair_hypotheses(const PointCloud& model, const PointCloud& scene, const SurfaceSupport& surface_support,
                                            const std::vector<detail::Correspondence>& matches, double res, const RecognitionParams& params) {
  std::vector<PoseHypothesis> made;
  if (params.pair_partners <= 0 || matches.empty()) return made;
  // The matched model points of each scene point.
  std::unordered_map<size_t, size_t> anchor_of;
  std::vector<size_t> anchors;                  // scene point indices
  std::vector<std::vector<size_t>> model_of;    // per anchor: model point indices
  for (const auto& c : matches) {
    auto [it, inserted] = anchor_of.try_emplace(c.target, anchors.size());
    if (inserted) anchors.push_back(c.target), model_of.emplace_back();
    model_of[it->second].push_back(c.source);
  }
  std::vector<Eigen::Vector3f> anchor_points;
  for (const size_t a : anchors) anchor_points.push_back(scene.points[a]);
  const KdTree3 anchor_tree(anchor_points);
  Eigen::AlignedBox3f box;
  for (const auto& p : model.points) box.extend(p);
  const float diameter = box.diagonal().norm();
  const float min_distance = static_cast<float>(params.pair_min_distance_factor * res);
  const float tolerance = static_cast<float>(params.pair_distance_tolerance_factor * res);
  const float angle_tolerance = static_cast<float>(params.pair_angle_tolerance_deg * std::numbers::pi / 180);
  const size_t min_support = surface_support.min_support(params.pair_min_support);
  const auto angle = [](const Eigen::Vector3f& a, const Eigen::Vector3f& b) { return std::acos(std::clamp(a.dot(b), -1.0f, 1.0f)); };

  std::vector<size_t> order(anchors.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::mt19937 rng(params.pair_seed);  // the same scene gives the same hypotheses
  std::shuffle(order.begin(), order.end(), rng);
  if (order.size() > static_cast<size_t>(std::max(params.pair_anchors, 0))) order.resize(static_cast<size_t>(std::max(params.pair_anchors, 0)));
  // The pairs tried, drawn in order (the draws are the hypotheses' order), then made and scored
  // in parallel. The anchors' partners are found in parallel a block of anchors at a time (the
  // lists of all 1,500 anchors would hold some 4 million entries), and drawn from in order.
  constexpr size_t kBlock = 64;
  std::vector<std::vector<size_t>> near(std::min(order.size(), kBlock));
  std::vector<std::pair<size_t, size_t>> tried;
  for (size_t first = 0; first < order.size(); first += kBlock) {
    const size_t count = std::min(kBlock, order.size() - first);
#pragma omp parallel for schedule(dynamic, 4)
    for (size_t k = 0; k < count; ++k) {
      const Eigen::Vector3f& s_a = anchor_points[order[first + k]];
      anchor_tree.within(s_a, diameter, near[k]);
      std::erase_if(near[k], [&](size_t b) { return (anchor_points[b] - s_a).norm() < min_distance; });
    }
    for (size_t k = 0; k < count; ++k)
      for (int t = 0; !near[k].empty() && t < params.pair_partners; ++t) tried.emplace_back(order[first + k], near[k][rng() % near[k].size()]);
  }
  std::vector<std::vector<PoseHypothesis>> of_pair(tried.size());
#pragma omp parallel for schedule(dynamic, 16)
  for (size_t k = 0; k < tried.size(); ++k) {
    const auto [a, b] = tried[k];
    const Eigen::Vector3f& s_a = scene.points[anchors[a]];
    const Eigen::Vector3f& ns_a = scene.normals[anchors[a]];
    const Eigen::Vector3f& s_b = scene.points[anchors[b]];
    const Eigen::Vector3f& ns_b = scene.normals[anchors[b]];
    const Eigen::Vector3f d_s = s_b - s_a;
    const float l_s = d_s.norm();
    const Eigen::Vector3f u_s = d_s / l_s;
    const float f1 = angle(ns_a, u_s), f2 = angle(ns_b, u_s), f3 = angle(ns_a, ns_b);
    for (const size_t m_a : model_of[a])
      for (const size_t m_b : model_of[b]) {
        if (m_a == m_b) continue;
        const Eigen::Vector3f d_m = model.points[m_b] - model.points[m_a];
        const float l_m = d_m.norm();
        if (std::abs(l_m - l_s) > tolerance) continue;
        const Eigen::Vector3f u_m = d_m / l_m;
        if (std::abs(angle(model.normals[m_a], u_m) - f1) > angle_tolerance || std::abs(angle(model.normals[m_b], u_m) - f2) > angle_tolerance ||
            std::abs(angle(model.normals[m_a], model.normals[m_b]) - f3) > angle_tolerance)
          continue;
        PoseHypothesis h;
        h.T_scene_model = pose_from_pairs(model.points[m_a], model.normals[m_a], model.points[m_b], model.normals[m_b], s_a, ns_a, s_b, ns_b, l_s);
        h.first_support = h.support = surface_support.first(h.T_scene_model, 1.5 * res);
        if (h.support >= min_support) of_pair[k].push_back(std::move(h));
      }
  }
  for (auto& hypotheses : of_pair) made.insert(made.end(), std::make_move_iterator(hypotheses.begin()), std::make_move_iterator(hypotheses.end()));
  return made;
}

std::vector<PoseHypothesis> voting_hypotheses(const detail::PairFeatureModel& table, const PointCloud& scene, const std::vector<char>& background,
                                              const SurfaceSupport& surface_support, double res, const RecognitionParams& params) {
  std::vector<PoseHypothesis> made;
  if (params.voting_pool <= 0) return made;
  auto voted = table.vote(scene, background);
  if (voted.size() > static_cast<size_t>(params.voting_pool)) voted.resize(static_cast<size_t>(params.voting_pool));
  const size_t min_support = surface_support.min_support(params.pair_min_support);
  std::vector<PoseHypothesis> scored(voted.size());
#pragma omp parallel for schedule(dynamic, 4)
  for (size_t k = 0; k < voted.size(); ++k) {
    PoseHypothesis& h = scored[k];
    h.T_scene_model = voted[k].T_scene_model;
    h.source = RecognitionCandidate::Source::voting;
    h.first_support = h.support = surface_support.first(h.T_scene_model, 1.5 * res);
  }
  for (auto& h : scored)
    if (h.support >= min_support) made.push_back(std::move(h));
  return made;
}

std::vector<PoseHypothesis> axis_hypotheses(const detail::ModelCylinder& cylinder, const std::vector<detail::SceneAxis>& axes,
                                            const SurfaceSupport& surface_support, double res, const RecognitionParams& params,
                                            RecognitionCandidate::Source source) {
  std::vector<PoseHypothesis> made;
  const size_t min_support = surface_support.min_support(params.pair_min_support);
  for (const auto& axis : axes) {
    const auto poses = detail::poses_on_axis(cylinder, axis, params.axis_step_factor * res, params.turn_steps);
    std::vector<PoseHypothesis> on(poses.size());
#pragma omp parallel for schedule(dynamic, 4)
    for (size_t k = 0; k < poses.size(); ++k) {
      PoseHypothesis& h = on[k];
      h.T_scene_model = poses[k];
      h.source = source;
      h.first_support = h.support = surface_support.first(poses[k], 1.5 * res);
    }
    size_t best = 0;
    for (const auto& h : on) best = std::max(best, h.support);
    for (auto& h : on)
      if (h.support >= min_support && 10 * h.support >= 9 * best) made.push_back(std::move(h));
  }
  return made;
}

std::vector<PoseHypothesis> best_distinct(std::vector<PoseHypothesis> made, const SameSurface& same, size_t pool) {
  std::vector<PoseHypothesis> out;
  std::stable_sort(made.begin(), made.end(), [](const PoseHypothesis& x, const PoseHypothesis& y) { return x.support > y.support; });
  const auto duplicate = [&](const Transform& a, const Transform& b) {
    return same.centre_distance(a, b) < 0.1 * same.diameter() && rotation_angle(a.inverse() * b) < 20.0 * std::numbers::pi / 180;
  };
  for (auto& h : made) {
    if (out.size() >= pool) break;
    if (std::none_of(out.begin(), out.end(), [&](const PoseHypothesis& o) { return duplicate(h.T_scene_model, o.T_scene_model); }))
      out.push_back(std::move(h));
  }
  return out;
}

}  // namespace artisan::detail
