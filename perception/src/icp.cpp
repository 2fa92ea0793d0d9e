#include "artisan/perception/icp.hpp"

#include <cmath>
#include <string>

#include <Eigen/Cholesky>
#include <omp.h>

#include "artisan/core/error.hpp"

namespace artisan {

PointCloud oriented_points(const TriangleMesh& mesh) {
  PointCloud cloud;
  cloud.points = mesh.vertices;
  if (mesh.normals.size() == mesh.vertices.size()) {
    cloud.normals = mesh.normals;
  } else {
    TriangleMesh copy = mesh;
    copy.compute_vertex_normals();
    cloud.normals = std::move(copy.normals);
  }
  return cloud;
}

IcpResult icp_point_to_plane(const PointCloud& source, const PointCloud& target, const KdTree3& target_tree,
                             const Transform& T_target_source_init, const IcpSettings& settings) {
  if (source.points.empty() || target.points.empty()) throw Error("icp: empty point cloud (source " + std::to_string(source.points.size()) + ", target " + std::to_string(target.points.size()) + " points)");
  if (target.normals.size() != target.points.size() || source.normals.size() != source.points.size())
    throw Error("icp: both clouds need one normal per point");
  if (target_tree.size() != target.points.size()) throw Error("icp: the k-d tree does not index the target");
  if (!(settings.max_correspondence_distance_m > 0) || settings.max_iterations < 1 || !(settings.huber_delta_m > 0))
    throw Error("icp: max_correspondence_distance_m, huber_delta_m and max_iterations must be positive");

  const size_t step = std::max<size_t>(1, source.points.size() / std::max<size_t>(1, settings.max_source_points));
  std::vector<size_t> samples;
  for (size_t i = 0; i < source.points.size(); i += step) samples.push_back(i);
  const auto max_d = static_cast<float>(settings.max_correspondence_distance_m);
  const float min_cos = static_cast<float>(std::cos(settings.max_normal_angle_deg * M_PI / 180.0));

  IcpResult result;
  result.samples = samples.size();
  Transform T = T_target_source_init;
  for (int it = 0; it < settings.max_iterations; ++it) {
    const Eigen::Matrix3f R = T.linear().cast<float>();
    const Eigen::Vector3f t = T.translation().cast<float>();
    // The normal equations, summed over the samples that have a partner.
    struct Sums {
      Eigen::Matrix<double, 6, 6> H = Eigen::Matrix<double, 6, 6>::Zero();
      Eigen::Matrix<double, 6, 1> g = Eigen::Matrix<double, 6, 1>::Zero();
      double sq_sum = 0;
      size_t inliers = 0;
      void add(const Sums& o) { H += o.H, g += o.g, sq_sum += o.sq_sum, inliers += o.inliers; }
    };
    const auto add_sample = [&](size_t k, Sums& sums) {
      const size_t i = samples[k];
      const Eigen::Vector3f p = R * source.points[i] + t;
      const auto near = target_tree.nearest_within(p, max_d);
      if (!near) return;
      const size_t j = near->first;
      const Eigen::Vector3f& n = target.normals[j];
      if ((R * source.normals[i]).dot(n) < min_cos) return;
      // Residual along the target normal; linearised rotation: (p x n) . w + n . dt.
      const double r = static_cast<double>((p - target.points[j]).dot(n));
      Eigen::Matrix<double, 6, 1> J;
      J << p.cross(n).cast<double>(), n.cast<double>();
      const double abs_r = std::abs(r);
      const double w = abs_r <= settings.huber_delta_m ? 1.0 : settings.huber_delta_m / abs_r;  // Huber weight
      sums.H += w * J * J.transpose();
      sums.g += w * r * J;
      sums.sq_sum += r * r;
      ++sums.inliers;
    };
    Sums sums;
    if (omp_in_parallel()) {
      // Called from a thread of a parallel region (one ICP per thread): a nested region would run
      // on this thread alone and cost more to open than a coarse ICP's iteration takes.
      for (size_t k = 0; k < samples.size(); ++k) add_sample(k, sums);
    } else {
#pragma omp parallel
      {
        Sums local;
#pragma omp for nowait
        for (size_t k = 0; k < samples.size(); ++k) add_sample(k, local);
#pragma omp critical
        sums.add(local);
      }
    }
    const auto& [H, g, sq_sum, inliers] = sums;
    result.iterations = it + 1;
    result.inliers = inliers;
    result.rmse_m = inliers ? std::sqrt(sq_sum / inliers) : 0.0;
    if (inliers < 6) break;
    const Eigen::Matrix<double, 6, 1> x = H.ldlt().solve(-g);
    if (!x.allFinite()) break;
    Transform dT = Transform::Identity();
    const double angle = x.head<3>().norm();
    if (angle > 0) dT.linear() = Eigen::AngleAxisd(angle, x.head<3>() / angle).toRotationMatrix();
    dT.translation() = x.tail<3>();
    T = dT * T;
    if (angle < settings.convergence_rotation_rad && x.tail<3>().norm() < settings.convergence_translation_m) {
      result.converged = true;
      break;
    }
  }
  result.T_target_source = T;
  result.overlap_fraction = samples.empty() ? 0.0 : static_cast<double>(result.inliers) / samples.size();
  return result;
}

}  // namespace artisan
