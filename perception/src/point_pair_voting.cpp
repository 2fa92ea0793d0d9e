#include "point_pair_voting.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <unordered_map>

#include <Eigen/Geometry>

#include "artisan/core/error.hpp"
#include "artisan/perception/kdtree.hpp"
#include "artisan/perception/spin_image.hpp"

namespace artisan::detail {

namespace {

// The transform that moves p to the origin and turns n onto +x (section 3.3: T_m->g, T_s->g).
Transform to_local(const Eigen::Vector3f& p, const Eigen::Vector3f& n) {
  const Eigen::Quaterniond q = Eigen::Quaterniond::FromTwoVectors(n.cast<double>(), Eigen::Vector3d::UnitX());
  Transform T = Transform::Identity();
  T.linear() = q.toRotationMatrix();
  T.translation() = -(T.linear() * p.cast<double>());
  return T;
}

// What the rotation about +x of a reference point's local frame needs of it: the point, and the
// rows of the rotation that give a partner's local y and z.
struct AlphaFrame {
  Eigen::Vector3f origin, y, z;
};
AlphaFrame alpha_frame(const Transform& T_local, const Eigen::Vector3f& p) {
  const Eigen::Matrix3f R = T_local.linear().cast<float>();
  return {p, R.row(1).transpose(), R.row(2).transpose()};
}

// The angle of a partner about +x in the local frame of its reference point, in 65536ths of a
// turn: the difference of two of them modulo 2^16 is the rotation between them.
uint32_t alpha_of(const AlphaFrame& f, const Eigen::Vector3f& partner) {
  const Eigen::Vector3f d = partner - f.origin;
  const double turns = std::atan2(static_cast<double>(f.z.dot(d)), static_cast<double>(f.y.dot(d))) / (2 * std::numbers::pi);  // [-0.5, 0.5]
  return static_cast<uint32_t>(static_cast<int64_t>(std::floor(turns * 65536)) & 0xffff);
}

}  // namespace

inline int64_t PairFeatureModel::cell(const Eigen::Vector3f& p1, const Eigen::Vector3f& n1, const Eigen::Vector3f& p2,
                                      const Eigen::Vector3f& n2) const {
  const Eigen::Vector3f d = p2 - p1;
  const float length = d.norm();
  if (!(length > 0.5f * static_cast<float>(params_.step_m))) return -1;
  const auto distance_bin = static_cast<int64_t>(length / static_cast<float>(params_.step_m));
  if (distance_bin >= distance_bins_) return -1;
  const Eigen::Vector3f u = d / length;
  const int64_t a = params_.angle_bins;
  // The bin of the angle whose cosine this is: the table's guess for the cosine's slot, then the
  // bin boundaries' cosines either side.
  const auto angle_bin = [this, a](float cosine) {
    constexpr float half = kCosineSlots / 2;
    int64_t bin = angle_bin_of_cosine_[static_cast<size_t>(std::clamp((cosine + 1) * half, 0.0f, kCosineSlots - 1.0f))];
    while (bin + 1 < a && cosine <= bin_start_cosine_[static_cast<size_t>(bin + 1)]) ++bin;
    while (bin > 0 && cosine > bin_start_cosine_[static_cast<size_t>(bin)]) --bin;
    return bin;
  };
  return ((distance_bin * a + angle_bin(n1.dot(u))) * a + angle_bin(n2.dot(u))) * a + angle_bin(n1.dot(n2));
}

PairFeatureModel::PairFeatureModel(const PointCloud& model_points, const PairVotingParams& params) : params_(params) {
  if (!(params.step_m > 0) || params.angle_bins < 2 || params.angle_bins > 255 || params.alpha_bins < 4 || params.alpha_bins > 4096 ||
      params.reference_stride < 1 || params.peaks_per_reference < 1 || !(params.max_cell_share > 0 && params.max_cell_share <= 1) ||
      !(params.cluster_distance_factor > 0) || !(params.cluster_angle_deg > 0 && params.cluster_angle_deg <= 180))
    throw Error("point-pair voting: step " + std::to_string(params.step_m) + " m must be positive, angle bins " +
                std::to_string(params.angle_bins) + " from 2 to 255, alpha bins " + std::to_string(params.alpha_bins) +
                " from 4 to 4096, reference stride " +
                std::to_string(params.reference_stride) + " and peaks " + std::to_string(params.peaks_per_reference) +
                " at least 1, max_cell_share " + std::to_string(params.max_cell_share) + " in (0, 1], cluster distance factor " +
                std::to_string(params.cluster_distance_factor) + " positive and cluster angle " + std::to_string(params.cluster_angle_deg) +
                " degrees in (0, 180]");
  if (model_points.normals.size() != model_points.points.size()) throw Error("point-pair voting: the model points have no normals");
  // An angle's bin from its cosine without the arc cosine: the cosines where bins start, and a
  // first guess by slots of 1/2048 of the cosine's range.
  for (int k = 0; k < params.angle_bins; ++k)
    bin_start_cosine_.push_back(std::cos(static_cast<float>(k) * std::numbers::pi_v<float> / static_cast<float>(params.angle_bins)));
  for (size_t i = 0; i < angle_bin_of_cosine_.size(); ++i) {
    const double angle = std::acos((static_cast<double>(i) + 0.5) / (kCosineSlots / 2) - 1);
    angle_bin_of_cosine_[i] = static_cast<uint8_t>(std::min(params.angle_bins - 1, static_cast<int>(angle / std::numbers::pi * params.angle_bins)));
  }
  points_ = resample_oriented_points(model_points, params.step_m);
  const auto box = points_.bounds();
  diameter_ = static_cast<double>(box.diagonal().norm());
  distance_bins_ = static_cast<int>(diameter_ / params.step_m) + 1;
  const auto& p = points_.points;
  const auto& n = points_.normals;
  if (p.size() > (size_t{1} << 16))
    throw Error("point-pair voting: " + std::to_string(p.size()) + " model points at step " + std::to_string(params.step_m) +
                " m exceed the table's 65536; use a coarser step");
  std::vector<AlphaFrame> frames;
  for (size_t i = 0; i < p.size(); ++i) T_local_model_.push_back(to_local(p[i], n[i])), frames.push_back(alpha_frame(T_local_model_[i], p[i]));
  const auto a = static_cast<size_t>(params.angle_bins);
  // Counting sort of every ordered pair by its cell: count, prefix sums, fill. Cells holding more
  // than max_cell_share of the pairs are left empty.
  std::vector<int64_t> cells(p.size() * p.size(), -1);
  std::vector<uint32_t> count(static_cast<size_t>(distance_bins_) * a * a * a, 0);
  for (size_t i = 0; i < p.size(); ++i)
    for (size_t j = 0; j < p.size(); ++j)
      if (i != j && (cells[i * p.size() + j] = cell(p[i], n[i], p[j], n[j])) >= 0) ++count[static_cast<size_t>(cells[i * p.size() + j])];
  size_t total = 0;
  for (const auto c : count) total += c;
  const double cap = params.max_cell_share * static_cast<double>(total);
  offsets_.assign(count.size() + 1, 0);
  for (size_t c = 0; c < count.size(); ++c) {
    if (static_cast<double>(count[c]) > cap) dropped_ += count[c], count[c] = 0;
    offsets_[c + 1] = offsets_[c] + count[c];
  }
  entries_.resize(offsets_.back());
  std::vector<uint32_t> fill(offsets_.begin(), offsets_.end() - 1);
  for (size_t i = 0; i < p.size(); ++i)
    for (size_t j = 0; j < p.size(); ++j)
      if (const auto c = cells[i * p.size() + j]; c >= 0 && count[static_cast<size_t>(c)] > 0)
        entries_[fill[static_cast<size_t>(c)]++] = static_cast<uint32_t>(i) << 16 | alpha_of(frames[i], p[j]);
}

std::vector<VotedPose> PairFeatureModel::vote(const PointCloud& scene, const std::vector<char>& ignore) const {
  std::vector<VotedPose> out;
  if (scene.normals.size() != scene.points.size())
    throw Error("point-pair voting: the scene has " + std::to_string(scene.points.size()) + " points but " + std::to_string(scene.normals.size()) +
                " normals");
  if (points_.points.empty() || entries_.empty()) return out;
  PointCloud kept;
  for (size_t i = 0; i < scene.points.size(); ++i)
    if (i >= ignore.size() || !ignore[i]) kept.points.push_back(scene.points[i]), kept.normals.push_back(scene.normals[i]);
  if (kept.points.size() < 2) return out;
  const PointCloud samples = resample_oriented_points(kept, params_.step_m);
  const KdTree3 tree(samples.points);
  const auto& s = samples.points;
  const auto& sn = samples.normals;
  const size_t model_points = points_.points.size();
  const auto alpha_bins = static_cast<uint32_t>(params_.alpha_bins);
  const float radius = static_cast<float>(diameter_);

  // Per reference point: its accumulator's peaks, as poses with their votes (eq. 3-4).
  std::vector<size_t> references;
  for (size_t r = 0; r < s.size(); r += static_cast<size_t>(params_.reference_stride)) references.push_back(r);
  std::vector<std::vector<VotedPose>> peaks(references.size());
#pragma omp parallel
  {
    std::vector<uint32_t> accumulator(model_points * alpha_bins);
    std::vector<size_t> near;
#pragma omp for schedule(dynamic, 8)
    for (size_t k = 0; k < references.size(); ++k) {
      const size_t r = references[k];
      const Transform T_local_scene = to_local(s[r], sn[r]);
      const AlphaFrame frame = alpha_frame(T_local_scene, s[r]);
      tree.within(s[r], radius, near);
      for (const size_t i : near) {
        if (i == r) continue;
        const auto c = cell(s[r], sn[r], s[i], sn[i]);
        if (c < 0) continue;
        const uint32_t* const first = entries_.data() + offsets_[static_cast<size_t>(c)];
        const uint32_t entries = offsets_[static_cast<size_t>(c) + 1] - offsets_[static_cast<size_t>(c)];
        if (entries == 0) continue;
        const uint32_t alpha_s = alpha_of(frame, s[i]);
        // The innermost loop, a billion times per model and scene: plain pointers (through the
        // vectors the compiler reloads the bound after every increment, as the counts might
        // alias the offsets), and each entry one word, its model point over its alpha_m; the
        // rotation alpha_s - alpha_m modulo a turn, times the bins, over 2^16 is its bin.
        uint32_t* const votes = accumulator.data();
        for (const uint32_t* e = first; e != first + entries; ++e)
          ++votes[(*e >> 16) * alpha_bins + ((((alpha_s - *e) & 0xffffu) * alpha_bins) >> 16)];
      }
      // The largest cells, at most peaks_per_reference of them, by blocks: a block none of whose
      // cells could enter is passed on its maximum alone (most are). Read, a block is zeroed
      // for the next reference point.
      auto& mine = peaks[k];
      const auto wanted = static_cast<size_t>(params_.peaks_per_reference);
      std::vector<std::pair<uint32_t, size_t>> best;  // votes, cell
      uint32_t floor = 0;  // a cell must exceed this to enter
      constexpr size_t kBlock = 32;
      for (size_t b = 0; b < accumulator.size(); b += kBlock) {
        uint32_t* const block = accumulator.data() + b;
        const size_t n = std::min(kBlock, accumulator.size() - b);
        uint32_t most = 0;
        for (size_t j = 0; j < n; ++j) most = std::max(most, block[j]);
        if (most <= floor) {
          if (most > 0) std::fill(block, block + n, 0u);
          continue;
        }
        for (size_t j = 0; j < n; ++j) {
          if (block[j] <= floor) continue;
          if (best.size() == wanted) best.pop_back();
          best.insert(std::upper_bound(best.begin(), best.end(), block[j], [](uint32_t v, const auto& e) { return v > e.first; }), {block[j], b + j});
          if (best.size() == wanted) floor = best.back().first;
        }
        std::fill(block, block + n, 0u);
      }
      const Transform T_scene_local = T_local_scene.inverse();
      for (const auto& [votes, c] : best) {
        const size_t m = c / alpha_bins;
        const double alpha = (static_cast<double>(c % alpha_bins) + 0.5) * 2 * std::numbers::pi / static_cast<double>(alpha_bins);
        const Transform R_x(Eigen::AngleAxisd(alpha, Eigen::Vector3d::UnitX()));
        mine.push_back({T_scene_local * R_x * T_local_model_[m], votes});
      }
    }
  }

  // Pose clustering (section 3.4): in vote order, each pose joins the first cluster whose first
  // pose puts the model's centre within cluster_distance of it and turns it by less than
  // cluster_angle; a cluster's votes are its members' sum, its pose their vote-weighted mean
  // (which is finer than the quantised alpha and sampling step of any one of them).
  std::vector<VotedPose> poses;
  for (auto& p : peaks) poses.insert(poses.end(), p.begin(), p.end());
  std::stable_sort(poses.begin(), poses.end(), [](const VotedPose& a, const VotedPose& b) { return a.votes > b.votes; });
  const Eigen::Vector3d centre = points_.bounds().center().cast<double>();
  const double max_distance = params_.cluster_distance_factor * diameter_;
  const double max_angle = params_.cluster_angle_deg * std::numbers::pi / 180;
  struct Cluster {
    Eigen::Matrix3d first;           ///< the first pose's rotation
    Eigen::Vector4d first_rotation;  ///< the same as a quaternion
    Eigen::Vector3d centre, translation_sum = Eigen::Vector3d::Zero();
    Eigen::Vector4d rotation_sum = Eigen::Vector4d::Zero();  ///< quaternions on the first's side
    uint32_t votes = 0;
  };
  std::vector<Cluster> clusters;
  // The clusters by their first pose's centre, in cubes of the cluster distance: a pose's first
  // cluster is among those of the 27 cubes about its own (in each cube's list by creation).
  // Turned by less than max_angle: the trace of the rotation between them above 1 + 2 cos(max_angle).
  std::unordered_map<uint64_t, std::vector<uint32_t>> cubes;
  const auto cube_of = [max_distance](const Eigen::Vector3d& c) {
    return Eigen::Vector3i((c / max_distance).array().floor().cast<int>());
  };
  const auto key_of = [](const Eigen::Vector3i& q) {
    const auto u = [](int v) { return static_cast<uint64_t>(static_cast<uint32_t>(v)); };
    return u(q.x()) * 0x9e3779b97f4a7c15ull ^ u(q.y()) * 0xc2b2ae3d27d4eb4full ^ u(q.z()) * 0x165667b19e3779f9ull;
  };
  const double min_trace = 1 + 2 * std::cos(max_angle);
  for (const auto& p : poses) {
    const Eigen::Vector3d c = p.T_scene_model * centre;
    const Eigen::Matrix3d R = p.T_scene_model.linear();
    const Eigen::Vector3i home = cube_of(c);
    auto first = static_cast<uint32_t>(clusters.size());
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const auto cube = cubes.find(key_of(home + Eigen::Vector3i(dx, dy, dz)));
          if (cube == cubes.end()) continue;
          for (const uint32_t j : cube->second) {
            if (j >= first) break;
            const Cluster& k = clusters[j];
            if ((k.centre - c).norm() < max_distance && k.first.cwiseProduct(R).sum() > min_trace) first = j;
          }
        }
    if (first == clusters.size()) {
      clusters.push_back(Cluster{R, Eigen::Quaterniond(R).coeffs(), c});
      cubes[key_of(home)].push_back(first);
    }
    Cluster& k = clusters[first];
    Eigen::Vector4d q = Eigen::Quaterniond(R).coeffs();
    if (q.dot(k.first_rotation) < 0) q = -q;
    k.rotation_sum += p.votes * q;
    k.translation_sum += p.votes * p.T_scene_model.translation();
    k.votes += p.votes;
  }
  for (const auto& k : clusters) {
    VotedPose v;
    v.T_scene_model.linear() = Eigen::Quaterniond(Eigen::Vector4d(k.rotation_sum.normalized())).toRotationMatrix();
    v.T_scene_model.translation() = k.translation_sum / static_cast<double>(k.votes);
    v.votes = k.votes;
    out.push_back(v);
  }
  std::stable_sort(out.begin(), out.end(), [](const VotedPose& a, const VotedPose& b) { return a.votes > b.votes; });
  return out;
}

}  // namespace artisan::detail
