#include "artisan/perception/registration.hpp"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numeric>

#include <Eigen/Geometry>

#include "artisan/core/error.hpp"
#include "correspondence_grouping.hpp"

namespace artisan {

namespace {

using detail::Correspondence;
using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

void normalise(const SpinImageStack& stack, Eigen::MatrixXf& z, Eigen::MatrixXf& mask) {
  const int bins = stack.width * stack.width;
  z.resize(bins, static_cast<Eigen::Index>(stack.size()));
  mask.resize(bins, static_cast<Eigen::Index>(stack.size()));
  for (size_t k = 0; k < stack.size(); ++k) {
    Eigen::Map<const Eigen::VectorXf> v(stack.image(k), bins);
    const float mean = v.mean();
    Eigen::VectorXf c = v.array() - mean;
    const float norm = c.norm();
    z.col(static_cast<Eigen::Index>(k)) = norm > 0 ? Eigen::VectorXf(c / norm) : Eigen::VectorXf::Zero(bins);
    mask.col(static_cast<Eigen::Index>(k)) = (v.array() > 0).cast<float>();
  }
}

double resolution_of(const TriangleMesh& mesh) {
  const double r = mesh.median_edge_length();
  if (!(r > 0)) throw Error("registration: a mesh has no faces, so no resolution");
  return r;
}

void check_meshes(const TriangleMesh& target, const TriangleMesh& source) {
  if (target.vertices.empty() || source.vertices.empty())
    throw Error("registration: empty mesh (target " + std::to_string(target.vertices.size()) + ", source " +
                std::to_string(source.vertices.size()) + " vertices)");
}

// How well the inlier correspondences pin the pose down:
//  - conditioning: smallest over largest eigenvalue of the 6x6 point-to-plane information
//    matrix (rows [p x n, n / L], p about the inliers' centroid, L their RMS spread, so
//    rotations and translations weigh alike); near 0 for a cylinder or a sphere;
//  - flatness: RMS distance of the inliers from their best-fit plane [m]; a noisy plane (a
//    floor seen by stereo) has well-spread normals but is still one plane the views slide on.
struct Constraint {
  double conditioning = 0.0;
  double flatness_m = 0.0;
};

Constraint constraint(const PointCloud& src, const PointCloud& tgt, const KdTree3& tree, const Transform& T, double max_distance) {
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3d>> pairs;
  for (size_t i = 0; i < src.points.size(); ++i) {
    const Eigen::Vector3f p = (T * src.points[i].cast<double>()).cast<float>();
    if (const auto j = tree.nearest_within(p, float(max_distance))) pairs.emplace_back(p.cast<double>(), tgt.normals[j->first].cast<double>());
  }
  Constraint c;
  if (pairs.size() < 6) return c;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& [p, n] : pairs) centroid += p;
  centroid /= double(pairs.size());
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto& [p, n] : pairs) cov += (p - centroid) * (p - centroid).transpose();
  cov /= double(pairs.size());
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> shape(cov);
  c.flatness_m = std::sqrt(std::max(0.0, shape.eigenvalues()(0)));
  const double spread = std::sqrt(cov.trace());
  if (!(spread > 0)) return c;
  Eigen::Matrix<double, 6, 6> H = Eigen::Matrix<double, 6, 6>::Zero();
  for (const auto& [p, n] : pairs) {
    Eigen::Matrix<double, 6, 1> J;
    J << ((p - centroid) / spread).cross(n), n;
    H += J * J.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> eig(H);
  const auto& l = eig.eigenvalues();
  c.conditioning = l(5) > 0 ? std::max(0.0, l(0)) / l(5) : 0.0;
  return c;
}

}  // namespace

RegistrationResult refine_registration(const TriangleMesh& target, const TriangleMesh& source,
                                       const Transform& T_target_source_init, const RegistrationSettings& settings) {
  check_meshes(target, source);
  const auto t0 = Clock::now();
  const PointCloud tgt = oriented_points(target), src = oriented_points(source);
  const KdTree3 tree(tgt.points);
  const double res = std::max(resolution_of(target), resolution_of(source));
  RegistrationResult result;
  result.resolution_m = res;
  // Coarse to fine: a wide capture range first, then the settings' distance.
  IcpSettings icp = settings.icp;
  Transform T = T_target_source_init;
  for (double factor : {6.0 * settings.icp_distance_factor, 2.0 * settings.icp_distance_factor, settings.icp_distance_factor}) {
    icp.max_correspondence_distance_m = factor * res;
    icp.huber_delta_m = 0.5 * res;
    const auto r = icp_point_to_plane(src, tgt, tree, T, icp);
    T = r.T_target_source;
    result.overlap_fraction = r.overlap_fraction;
    result.rmse_m = r.rmse_m;
  }
  result.T_target_source = T;
  const Constraint constrained = constraint(src, tgt, tree, T, settings.icp_distance_factor * res);
  result.conditioning = constrained.conditioning;
  result.flatness_m = constrained.flatness_m;
  result.seconds_icp = since(t0);
  if (result.overlap_fraction < settings.min_overlap) {
    result.failure = "overlap " + std::to_string(result.overlap_fraction) + " is below the minimum " + std::to_string(settings.min_overlap);
  } else if (result.rmse_m > settings.max_rmse_factor * res) {
    result.failure = "residual " + std::to_string(result.rmse_m * 1e3) + " mm exceeds " + std::to_string(settings.max_rmse_factor) +
                     " x the resolution " + std::to_string(res * 1e3) + " mm";
  } else if (result.conditioning < settings.min_conditioning) {
    result.failure = "the overlap does not constrain the pose (conditioning " + std::to_string(result.conditioning) + " < " +
                     std::to_string(settings.min_conditioning) + "): it is a surface the views could slide along";
  } else if (result.flatness_m < settings.min_flatness_factor * res) {
    result.failure = "the overlap is one plane (" + std::to_string(result.flatness_m * 1e3) + " mm RMS off it, under " +
                     std::to_string(settings.min_flatness_factor) + " x the resolution): the views could slide and turn on it";
  } else {
    result.success = true;
  }
  return result;
}

RegistrationResult register_meshes(const TriangleMesh& target, const TriangleMesh& source, const RegistrationSettings& settings) {
  check_meshes(target, source);
  const auto& mp = settings.match;
  RegistrationResult result;
  auto t0 = Clock::now();
  const double res = mp.resolution_m > 0 ? mp.resolution_m : 3.0 * std::max(resolution_of(target), resolution_of(source));
  result.resolution_m = res;
  const PointCloud tgt = resample_oriented_points(oriented_points(target), res);
  const PointCloud src = resample_oriented_points(oriented_points(source), res);
  const KdTree3 tgt_tree(tgt.points), src_tree(src.points);
  std::vector<size_t> scene_points;
  const size_t step = std::max<size_t>(1, static_cast<size_t>(std::lround(1.0 / std::clamp(mp.scene_point_fraction, 1e-3, 1.0))));
  for (size_t i = 0; i < src.points.size(); i += step) scene_points.push_back(i);
  const auto tgt_spins = compute_spin_images(tgt, tgt_tree, {}, res, mp.spin);
  const auto src_spins = compute_spin_images(src, src_tree, scene_points, res, mp.spin);
  result.seconds_spin_images = since(t0);

  // Similarity of every scene spin image with every target spin image (eq. 8): the correlation
  // coefficient over the whole image (a normalised dot product, one matrix product) and the
  // number of bins both images occupy.
  t0 = Clock::now();
  Eigen::MatrixXf zt, mt, zs, ms;
  normalise(tgt_spins, zt, mt);
  normalise(src_spins, zs, ms);
  const Eigen::MatrixXf R = zs.transpose() * zt;
  const Eigen::MatrixXf N = ms.transpose() * mt;
  std::vector<Correspondence> candidates;
  std::vector<float> row(static_cast<size_t>(R.cols()));
  for (Eigen::Index i = 0; i < R.rows(); ++i) {
    for (Eigen::Index j = 0; j < R.cols(); ++j) {
      const float r = std::min(R(i, j), 0.9999f), n = N(i, j);
      row[static_cast<size_t>(j)] = (r > 0 && n > 3) ? std::pow(std::atanh(r), 2.0f) - static_cast<float>(mp.lambda) / (n - 3) : -1e9f;
    }
    // Upper outliers of this scene point's similarity histogram (section 4.3).
    std::vector<float> sorted = row;
    const size_t q1i = sorted.size() / 4, q3i = 3 * sorted.size() / 4;
    std::nth_element(sorted.begin(), sorted.begin() + q3i, sorted.end());
    const float q3 = sorted[q3i];
    std::nth_element(sorted.begin(), sorted.begin() + q1i, sorted.begin() + q3i);
    const float q1 = sorted[q1i];
    const float threshold = q3 + static_cast<float>(mp.outlier_spread) * (q3 - q1);
    // At most the three best outliers per scene point.
    std::vector<std::pair<float, size_t>> best;
    for (size_t j = 0; j < row.size(); ++j)
      if (row[j] > threshold) best.emplace_back(row[j], j);
    std::partial_sort(best.begin(), best.begin() + std::min<size_t>(3, best.size()), best.end(), std::greater<>());
    for (size_t k = 0; k < std::min<size_t>(3, best.size()); ++k)
      candidates.push_back({src_spins.basis[static_cast<size_t>(i)], tgt_spins.basis[best[k].second], best[k].first});
  }
  if (candidates.empty()) {
    result.failure = "no spin-image matches";
    result.seconds_matching = since(t0);
    return result;
  }
  detail::GroupingParams grouping;
  grouping.similarity_ratio = mp.similarity_ratio;
  grouping.geometric_consistency = mp.geometric_consistency;
  grouping.gamma_m = mp.gamma_factor * res;
  grouping.max_groups = mp.max_groups;
  grouping.min_group_size = mp.min_group_size;
  const auto grouped = detail::group_correspondences(src, tgt, std::move(candidates), grouping);
  result.candidate_correspondences = grouped.consistent_candidates;
  const auto& transforms = grouped.groups;
  result.seconds_matching = since(t0);
  if (transforms.empty()) {
    result.failure = "no geometrically consistent group of " + std::to_string(mp.min_group_size) + " matches";
    return result;
  }

  // Verification (section 5.3): a short ICP from each transform on the resampled clouds; the
  // best overlap wins, then the residual.
  t0 = Clock::now();
  const IcpSettings coarse = detail::verification_icp(res, 12);
  double best_score = -1;
  Transform best = Transform::Identity();
  for (const auto& c : transforms) {
    const auto r = icp_point_to_plane(src, tgt, tgt_tree, c.T_target_source, coarse);
    const double score = r.overlap_fraction - 0.1 * r.rmse_m / res;
    ++result.groups_verified;
    if (score > best_score) {
      best_score = score;
      best = r.T_target_source;
      result.consistent_correspondences = c.size;
    }
  }
  const double seconds_verify = since(t0);
  auto refined = refine_registration(target, source, best, settings);
  refined.seconds_icp += seconds_verify;
  refined.seconds_spin_images = result.seconds_spin_images;
  refined.seconds_matching = result.seconds_matching;
  refined.consistent_correspondences = result.consistent_correspondences;
  refined.candidate_correspondences = result.candidate_correspondences;
  refined.groups_verified = result.groups_verified;
  return refined;
}

}  // namespace artisan
