#include "artisan/perception/recognition.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>

#include <Eigen/Eigenvalues>

#include "artisan/core/error.hpp"
#include "artisan/perception/icp.hpp"
#include "artisan/perception/kdtree.hpp"
#include "correspondence_grouping.hpp"

namespace artisan {

namespace {
using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }
}  // namespace

Eigen::MatrixXf normalised_spin_images(const SpinImageStack& stack) {
  const int bins = stack.width * stack.width;
  Eigen::MatrixXf z(bins, static_cast<Eigen::Index>(stack.size()));
  for (size_t k = 0; k < stack.size(); ++k) {
    Eigen::Map<const Eigen::VectorXf> v(stack.image(k), bins);
    Eigen::VectorXf c = v.array() - v.mean();
    const float norm = c.norm();
    z.col(static_cast<Eigen::Index>(k)) = norm > 0 ? Eigen::VectorXf(c / norm) : Eigen::VectorXf::Zero(bins);
  }
  return z;
}

SpinImageLibrary::SpinImageLibrary(const ModelLibraryParams& params) : params_(params) {
  if (!(params.resolution_m > 0) || !(params.pca_variance > 0 && params.pca_variance <= 1))
    throw Error("spin-image library: resolution " + std::to_string(params.resolution_m) + " m must be positive and pca_variance " +
                std::to_string(params.pca_variance) + " in (0, 1]");
}

void SpinImageLibrary::add_model(const std::string& name, const TriangleMesh& mesh) {
  if (mesh.faces.empty()) throw Error("spin-image library: model \"" + name + "\" has no faces");
  for (const auto& m : models_)
    if (m.name == name) throw Error("spin-image library: a model named \"" + name + "\" is already in it");
  Model model;
  model.name = name;
  model.points = resample_oriented_points(oriented_points(mesh), params_.resolution_m);
  if (model.points.points.size() < 10) throw Error("spin-image library: model \"" + name + "\" has fewer than 10 points at the library resolution");
  const KdTree3 tree(model.points.points);
  model.images = normalised_spin_images(compute_spin_images(model.points, tree, {}, params_.resolution_m, params_.spin));
  models_.push_back(std::move(model));
  compressed_ = false;
}

void SpinImageLibrary::add_precomputed_model(const std::string& name, PointCloud points, Eigen::MatrixXf images) {
  for (const auto& m : models_)
    if (m.name == name) throw Error("spin-image library: a model named \"" + name + "\" is already in it");
  if (points.normals.size() != points.points.size() || images.rows() != static_cast<Eigen::Index>(bins()) ||
      images.cols() != static_cast<Eigen::Index>(points.points.size()))
    throw Error("spin-image library: precomputed model \"" + name + "\" has " + std::to_string(images.rows()) + " x " +
                std::to_string(images.cols()) + " spin images for " + std::to_string(points.points.size()) + " points; expected " +
                std::to_string(bins()) + " rows");
  models_.push_back({name, std::move(points), std::move(images), {}});
  compressed_ = false;
}

void SpinImageLibrary::compress() {
  if (compressed_ || models_.empty()) return;
  const auto bins = static_cast<Eigen::Index>(this->bins());
  Eigen::Index total = 0;
  for (const auto& m : models_) total += m.images.cols();
  mean_ = Eigen::VectorXf::Zero(bins);
  for (const auto& m : models_) mean_ += m.images.rowwise().sum();
  mean_ /= static_cast<float>(total);
  Eigen::MatrixXd covariance = Eigen::MatrixXd::Zero(bins, bins);
  for (const auto& m : models_) {
    const Eigen::MatrixXd centred = (m.images.colwise() - mean_).cast<double>();
    covariance += centred * centred.transpose();
  }
  covariance /= static_cast<double>(total);
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(covariance);  // ascending eigenvalues
  const Eigen::VectorXd values = eig.eigenvalues().reverse();
  const double sum = values.sum();
  Eigen::Index k = 0;
  double kept = 0;
  while (k < bins && (sum <= 0 || kept / sum < params_.pca_variance)) kept += values[k++];
  k = std::max<Eigen::Index>(k, 1);
  basis_ = eig.eigenvectors().rowwise().reverse().leftCols(k).cast<float>();
  for (auto& m : models_) m.coefficients = project(m.images);
  compressed_ = true;
}

Eigen::MatrixXf SpinImageLibrary::project(const Eigen::MatrixXf& images) const {
  return basis_.transpose() * (images.colwise() - mean_);
}

RecognitionResult recognize(const TriangleMesh& scene, SpinImageLibrary& library, const RecognitionParams& params) {
  if (scene.faces.empty()) throw Error("recognition: the scene mesh has no faces");
  if (library.model_count() == 0) throw Error("recognition: the model library is empty");
  library.compress();
  RecognitionResult result;
  const double res = library.params().resolution_m;
  auto t0 = Clock::now();
  const PointCloud scene_points = resample_oriented_points(oriented_points(scene), res);
  const KdTree3 scene_tree(scene_points.points);
  std::vector<size_t> basis;
  const size_t step = std::max<size_t>(1, static_cast<size_t>(std::lround(1.0 / std::clamp(params.scene_point_fraction, 1e-3, 1.0))));
  for (size_t i = 0; i < scene_points.points.size(); i += step) basis.push_back(i);
  result.scene_points = basis.size();
  const auto stack = compute_spin_images(scene_points, scene_tree, basis, res, library.params().spin);
  const Eigen::MatrixXf scene_images = normalised_spin_images(stack);
  result.seconds_spin_images = since(t0);

  // Nearest library images of each scene image, over all models, in the compressed (or full)
  // space. For unit vectors |a - b|^2 = 2 - 2 r, so a distance estimates the correlation r.
  t0 = Clock::now();
  const Eigen::MatrixXf query = params.compressed_search ? library.project(scene_images) : scene_images;
  const Eigen::VectorXf query_sq = query.colwise().squaredNorm();
  struct Hit {
    float d2;
    size_t model, point;
  };
  std::vector<std::vector<Hit>> best(basis.size());
  for (size_t m = 0; m < library.model_count(); ++m) {
    const Eigen::MatrixXf& lib = params.compressed_search ? library.model_coefficients(m) : library.model_images(m);
    const Eigen::VectorXf lib_sq = lib.colwise().squaredNorm();
    const Eigen::MatrixXf dot = query.transpose() * lib;
#pragma omp parallel for schedule(static)
    for (Eigen::Index i = 0; i < dot.rows(); ++i) {
      auto& b = best[static_cast<size_t>(i)];
      for (Eigen::Index j = 0; j < dot.cols(); ++j) {
        const float d2 = query_sq[i] + lib_sq[j] - 2 * dot(i, j);
        if (static_cast<int>(b.size()) < params.neighbours || d2 < b.back().d2) {
          if (static_cast<int>(b.size()) == params.neighbours) b.pop_back();
          b.insert(std::upper_bound(b.begin(), b.end(), d2, [](float v, const Hit& h) { return v < h.d2; }),
                   Hit{d2, m, static_cast<size_t>(j)});
        }
      }
    }
  }
  std::vector<std::vector<detail::Correspondence>> per_model(library.model_count());
  for (size_t i = 0; i < best.size(); ++i)
    for (const auto& h : best[i]) {
      const float r = 1.0f - 0.5f * h.d2;
      if (r >= params.min_correlation) per_model[h.model].push_back({h.point, basis[i], r});
    }
  result.seconds_search = since(t0);

  // Per model: group, estimate, verify by ICP; accept instances one at a time, removing the
  // scene points each explains.
  t0 = Clock::now();
  const IcpSettings coarse = detail::verification_icp(res, 15);
  IcpSettings fine = coarse;
  fine.max_iterations = 40;
  fine.max_correspondence_distance_m = 1.0 * res;
  fine.max_source_points = 4000;
  detail::GroupingParams grouping;
  grouping.similarity_ratio = 0.0;  // the correlation threshold already filtered
  grouping.geometric_consistency = params.geometric_consistency;
  grouping.gamma_m = params.gamma_factor * res;
  grouping.max_groups = params.max_groups;
  for (size_t m = 0; m < library.model_count(); ++m) {
    const PointCloud& model = library.model_points(m);
    auto candidates = per_model[m];
    std::vector<char> explained(scene_points.points.size(), 0);
    for (int instance = 0; instance < params.max_instances && candidates.size() >= 3; ++instance) {
      const auto grouped = detail::group_correspondences(model, scene_points, candidates, grouping);
      struct Verified {
        Transform T;
        IcpResult icp;
        double score;
        size_t size;
      };
      std::vector<Verified> verified;
      for (const auto& g : grouped.groups) {
        const auto r = icp_point_to_plane(model, scene_points, scene_tree, g.T_target_source, coarse);
        verified.push_back({r.T_target_source, r, r.overlap_fraction - 0.5 * r.rmse_m / res, g.size});
      }
      if (verified.empty()) break;
      std::sort(verified.begin(), verified.end(), [](const Verified& a, const Verified& b) { return a.score > b.score; });
      // Only the winner gets the fine ICP.
      auto& top = verified.front();
      top.icp = icp_point_to_plane(model, scene_points, scene_tree, top.T, fine);
      top.T = top.icp.T_target_source;
      if (top.icp.overlap_fraction < params.min_model_overlap || top.icp.rmse_m > params.max_rmse_factor * res) break;
      RecognizedInstance found;
      found.model = library.model_name(m);
      found.model_index = m;
      found.T_scene_model = top.T;
      found.overlap_fraction = top.icp.overlap_fraction;
      found.rmse_m = top.icp.rmse_m;
      found.score = top.score;
      found.correspondences = top.size;
      for (size_t k = 1; k < verified.size(); ++k) {
        const auto& other = verified[k];
        if (other.score < top.score - params.ambiguity_margin) break;
        const Transform d = top.T.inverse() * other.T;
        if (rotation_angle(d) > 10.0 * std::numbers::pi / 180 && other.icp.rmse_m <= params.max_rmse_factor * res) {
          found.ambiguous = true;
          found.T_scene_model_alternative = other.T;
          break;
        }
      }
      result.instances.push_back(found);
      // The scene points this instance explains no longer support other instances.
      const Eigen::Isometry3f T = top.T.cast<float>();
      std::vector<size_t> near;
      for (const auto& p : model.points) {
        scene_tree.within(T * p, static_cast<float>(2.0 * res), near);
        for (size_t s : near) explained[s] = 1;
      }
      std::erase_if(candidates, [&](const detail::Correspondence& c) { return explained[c.target]; });
    }
  }
  result.seconds_verify = since(t0);
  return result;
}

}  // namespace artisan
