#include "slippage.hpp"

#include <algorithm>
#include <cmath>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include "artisan/core/pose.hpp"
#include "artisan/perception/kdtree.hpp"

namespace artisan::detail {

bool slides_along_itself(const PointCloud& model, double res, double max_ratio) {
  const size_t n = model.points.size();
  if (n == 0 || model.normals.size() != n) return false;
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (const auto& p : model.points) centre += p.cast<double>();
  centre /= static_cast<double>(n);
  double scale = 0;
  for (const auto& p : model.points) scale += (p.cast<double>() - centre).squaredNorm();
  scale = std::sqrt(scale / static_cast<double>(n));
  if (!(scale > 0)) return false;
  // A twist (w, t) moves point p by w x (p - c) + t, along its normal by ((p - c) x n) . w + n . t.
  Eigen::Matrix<double, 6, 6> normal_equations = Eigen::Matrix<double, 6, 6>::Zero();
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d normal = model.normals[i].cast<double>();
    Eigen::Matrix<double, 6, 1> row;
    row << ((model.points[i].cast<double>() - centre) / scale).cross(normal), normal;
    normal_equations += row * row.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> eig(normal_equations);
  const KdTree3 tree(model.points);
  const auto tolerance2 = static_cast<float>(std::pow(1.5 * res, 2));
  for (int k = 0; k < 6 && eig.eigenvalues()[k] <= max_ratio * eig.eigenvalues()[5]; ++k) {
    const Eigen::Vector3d w = eig.eigenvectors().col(k).head<3>() / scale, t = eig.eigenvectors().col(k).tail<3>();
    double largest = 0;  // the largest move per unit of the twist
    for (const auto& p : model.points) largest = std::max(largest, (w.cross(p.cast<double>() - centre) + t).norm());
    if (!(largest > 0)) continue;
    const double amount = 3 * res / largest;
    Transform motion = Transform::Identity();
    if (const double angle = amount * w.norm(); angle > 0) motion.linear() = Eigen::AngleAxisd(angle, w.normalized()).toRotationMatrix();
    motion.translation() = centre - motion.linear() * centre + amount * t;
    const Eigen::Isometry3f moved = motion.cast<float>();
    const auto off = std::count_if(model.points.begin(), model.points.end(),
                                   [&](const Eigen::Vector3f& p) { return tree.nearest(moved * p).second > tolerance2; });
    if (static_cast<double>(off) > 0.01 * static_cast<double>(n)) return true;
  }
  return false;
}

}  // namespace artisan::detail
