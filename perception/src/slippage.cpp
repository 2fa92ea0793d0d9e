#include "slippage.hpp"

#include <algorithm>
#include <cmath>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include "artisan/core/pose.hpp"

namespace artisan::detail {

double share_moved_off(const PointCloud& model, const KdTree3& tree, const Eigen::Isometry3f& motion, double tolerance, size_t step) {
  const auto tolerance2 = static_cast<float>(tolerance * tolerance);
  size_t tried = 0, off = 0;
  for (size_t i = 0; i < model.points.size(); i += std::max<size_t>(step, 1), ++tried)
    off += tree.nearest(motion * model.points[i]).second > tolerance2;
  return tried ? static_cast<double>(off) / static_cast<double>(tried) : 0.0;
}

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
  for (int k = 0; k < 6 && eig.eigenvalues()[k] <= max_ratio * eig.eigenvalues()[5]; ++k) {
    const Eigen::Vector3d w = eig.eigenvectors().col(k).head<3>() / scale, t = eig.eigenvectors().col(k).tail<3>();
    double largest = 0;  // the largest move per unit of the twist
    for (const auto& p : model.points) largest = std::max(largest, (w.cross(p.cast<double>() - centre) + t).norm());
    if (!(largest > 0)) continue;
    const double amount = 3 * res / largest;
    Transform motion = Transform::Identity();
    if (const double angle = amount * w.norm(); angle > 0) motion.linear() = Eigen::AngleAxisd(angle, w.normalized()).toRotationMatrix();
    motion.translation() = centre - motion.linear() * centre + amount * t;
    if (share_moved_off(model, tree, motion.cast<float>(), 1.5 * res) > 0.01) return true;
  }
  return false;
}

}  // namespace artisan::detail
