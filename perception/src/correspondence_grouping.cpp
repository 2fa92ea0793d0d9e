#include "correspondence_grouping.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>

#include <Eigen/Geometry>

#include "artisan/perception/spin_image.hpp"

namespace artisan::detail {

namespace {

// Whether two correspondences agree: their spin-map coordinates' relative disagreement (eq. 9),
// made symmetric, below T_gc (kConsistent), and the grouping distance that discounts nearby
// pairs (eq. 10) too (kGroupable). The grouping distance is never below the disagreement (its
// denominator is at most 1), so only consistent pairs need it.
constexpr uint8_t kConsistent = 1, kGroupable = 2;

uint8_t agreement(const PointCloud& src, const PointCloud& tgt, const Correspondence& a, const Correspondence& b, float gamma, float t_gc) {
  // A point's spin coordinates about another keep their distance (alpha^2 + beta^2 = |b - a|^2),
  // so the disagreement below is at least the two lengths' relative difference: pairs whose
  // lengths differ by T_gc or more (most, in clutter) disagree whatever their normals. The
  // margin keeps rounding from refusing a pair the full measure would keep.
  const float source_length = (src.points[b.source] - src.points[a.source]).norm();
  const float target_length = (tgt.points[b.target] - tgt.points[a.target]).norm();
  if (std::abs(source_length - target_length) >= 1.001f * t_gc * 0.5f * (source_length + target_length) && source_length + target_length > 0)
    return 0;
  const Eigen::Vector2f s_ab = spin_coordinates(src.points[a.source], src.normals[a.source], src.points[b.source]);
  const Eigen::Vector2f t_ab = spin_coordinates(tgt.points[a.target], tgt.normals[a.target], tgt.points[b.target]);
  const Eigen::Vector2f s_ba = spin_coordinates(src.points[b.source], src.normals[b.source], src.points[a.source]);
  const Eigen::Vector2f t_ba = spin_coordinates(tgt.points[b.target], tgt.normals[b.target], tgt.points[a.target]);
  auto d = [](const Eigen::Vector2f& s, const Eigen::Vector2f& t) {
    const float scale = 0.5f * (s.norm() + t.norm());
    return scale > 0 ? (s - t).norm() / scale : 0.0f;
  };
  auto w = [gamma](float dgc, const Eigen::Vector2f& s, const Eigen::Vector2f& t) {
    return dgc / (1.0f - std::exp(-0.5f * (s.norm() + t.norm()) / gamma) + 1e-9f);
  };
  const float d1 = d(s_ab, t_ab), d2 = d(s_ba, t_ba);
  if (!(std::max(d1, d2) < t_gc)) return 0;
  return std::max(w(d1, s_ab, t_ab), w(d2, s_ba, t_ba)) < t_gc ? kConsistent | kGroupable : kConsistent;
}

Transform transform_from(const PointCloud& src, const PointCloud& tgt, const std::vector<Correspondence>& group) {
  Eigen::Matrix3Xd from(3, group.size()), to(3, group.size());
  for (size_t k = 0; k < group.size(); ++k) {
    from.col(static_cast<Eigen::Index>(k)) = src.points[group[k].source].cast<double>();
    to.col(static_cast<Eigen::Index>(k)) = tgt.points[group[k].target].cast<double>();
  }
  Transform T = Transform::Identity();
  T.matrix() = Eigen::umeyama(from, to, false);
  return T;
}

}  // namespace

GroupingResult group_correspondences(const PointCloud& src, const PointCloud& tgt, std::vector<Correspondence> candidates,
                                     const GroupingParams& params, PairAgreements* reuse) {
  GroupingResult result;
  if (candidates.empty()) return result;
  const float best = std::max_element(candidates.begin(), candidates.end(), [](auto& a, auto& b) { return a.similarity < b.similarity; })->similarity;
  std::erase_if(candidates, [&](const Correspondence& c) { return c.similarity < params.similarity_ratio * best; });
  std::sort(candidates.begin(), candidates.end(), [](auto& a, auto& b) { return a.similarity > b.similarity; });
  if (candidates.size() > params.max_candidates) candidates.resize(params.max_candidates);

  // Geometric consistency (section 5.1). Johnson and Hebert drop matches consistent with under a
  // quarter of the others; in clutter, with several models, the right matches of one instance
  // are a small minority, so a match is kept when it is consistent with enough others to form a
  // group, and seeds are tried in order of how many others agree with them.
  const size_t n = candidates.size();
  const float gamma = static_cast<float>(params.gamma_m), t_gc = static_cast<float>(params.geometric_consistency);
  // Symmetric (the larger of the two directions' disagreements): each pair measured once, and
  // kept once (row a < column b).
  std::vector<uint8_t> pair(n * n, 0);
  const auto agree = [n](const std::vector<uint8_t>& p, size_t a, size_t b) { return a < b ? p[a * n + b] : p[b * n + a]; };
  // Each candidate's place among those `reuse` measured, if it is one of them.
  constexpr size_t kNew = SIZE_MAX;
  std::vector<size_t> before(n, kNew);
  if (reuse && !reuse->candidates.empty()) {
    const auto key = [](const Correspondence& c) { return std::pair{c.source, c.target}; };
    std::vector<std::pair<std::pair<size_t, size_t>, size_t>> old(reuse->candidates.size());
    for (size_t k = 0; k < old.size(); ++k) old[k] = {key(reuse->candidates[k]), k};
    std::sort(old.begin(), old.end());
    for (size_t a = 0; a < n; ++a) {
      const auto it = std::lower_bound(old.begin(), old.end(), std::pair{key(candidates[a]), size_t{0}});
      if (it != old.end() && it->first == key(candidates[a])) before[a] = it->second;
    }
  }
  const size_t m = reuse ? reuse->candidates.size() : 0;
  const auto measured = [&](size_t a, size_t b) {  // by `reuse`, a != b
    const size_t i = std::min(before[a], before[b]), j = std::max(before[a], before[b]);
    return reuse->pair[i * m + j];
  };
#pragma omp parallel for schedule(dynamic, 16)
  for (size_t a = 0; a < n; ++a)
    for (size_t b = a + 1; b < n; ++b)
      pair[a * n + b] = before[a] != kNew && before[b] != kNew ? measured(a, b) : agreement(src, tgt, candidates[a], candidates[b], gamma, t_gc);
  std::vector<size_t> kept, support(n, 0);
#pragma omp parallel
  {
    std::vector<size_t> counted(n, 0);
#pragma omp for schedule(dynamic, 16) nowait
    for (size_t a = 0; a < n; ++a)
      for (size_t b = a + 1; b < n; ++b)
        if (pair[a * n + b] & kConsistent) ++counted[a], ++counted[b];
#pragma omp critical
    for (size_t a = 0; a < n; ++a) support[a] += counted[a];
  }
  for (size_t a = 0; a < n; ++a)
    if (static_cast<int>(support[a]) + 1 >= params.min_group_size) kept.push_back(a);
  std::stable_sort(kept.begin(), kept.end(), [&](size_t a, size_t b) { return support[a] > support[b]; });
  result.consistent_candidates = kept.size();

  // Grouping (section 5.2): from each seed, add matches whose grouping distance to every member
  // stays below T_gc; each group of at least min_group_size gives a transform. A match already in
  // a group is not a seed again.
  std::vector<char> grouped(n, 0);
  for (size_t s = 0; s < kept.size() && static_cast<int>(result.groups.size()) < params.max_groups; ++s) {
    if (grouped[kept[s]]) continue;
    std::vector<size_t> group = {kept[s]};
    for (size_t c : kept) {
      if (c == kept[s]) continue;
      bool ok = true;
      for (size_t g : group)
        if (!(agree(pair, c, g) & kGroupable)) {
          ok = false;
          break;
        }
      if (ok) group.push_back(c);
    }
    if (static_cast<int>(group.size()) < params.min_group_size) continue;
    GroupedTransform g;
    for (size_t k : group) {
      g.members.push_back(candidates[k]);
      grouped[k] = 1;
    }
    g.size = group.size();
    g.T_target_source = transform_from(src, tgt, g.members);
    result.groups.push_back(std::move(g));
  }
  if (reuse) {  // for the next grouping
    reuse->candidates = std::move(candidates);
    reuse->pair = std::move(pair);
  }
  return result;
}

}  // namespace artisan::detail
