#include "slippage.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <vector>

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

Transform Slide::by(double s) const {
  if (radius <= 0) return Transform(Eigen::Translation3d(direction * s));
  return Eigen::Translation3d(point) * Eigen::AngleAxisd(s / radius, direction) * Eigen::Translation3d(-point);
}

Slide shift_along(const Eigen::Vector3d& point, const Eigen::Vector3d& direction, double extent) {
  return {.point = point, .direction = direction.normalized(), .radius = 0, .extent = extent};
}

namespace {

// The slide a twist (w, t) of the points about `centre` (a point p moves by w x (p - c) + t) makes.
Slide slide_of(const PointCloud& model, const Eigen::Vector3d& centre, const Eigen::Vector3d& w, const Eigen::Vector3d& t, double scale) {
  const double turn = w.norm();
  if (turn * scale < 0.05 * t.norm()) {
    const Eigen::Vector3d d = t.normalized();
    double lo = std::numeric_limits<double>::infinity(), hi = -lo;
    for (const auto& p : model.points) {
      const double x = d.dot(p.cast<double>() - centre);
      lo = std::min(lo, x), hi = std::max(hi, x);
    }
    return shift_along(centre, d, hi - lo);
  }
  // The screw axis: the points on it move along it alone.
  Slide slide;
  slide.direction = w / turn;
  slide.point = centre + w.cross(t) / (turn * turn);
  const Eigen::Vector3d u = slide.direction.unitOrthogonal(), v = slide.direction.cross(u);
  std::vector<double> angles;
  angles.reserve(model.points.size());
  double sum2 = 0;
  for (const auto& p : model.points) {
    const Eigen::Vector3d r = p.cast<double>() - slide.point;
    angles.push_back(std::atan2(v.dot(r), u.dot(r)));
    sum2 += (r - slide.direction * slide.direction.dot(r)).squaredNorm();
  }
  slide.radius = std::sqrt(sum2 / static_cast<double>(model.points.size()));
  // The arc the points span: the full turn less the widest gap between their angles.
  std::sort(angles.begin(), angles.end());
  double gap = angles.front() + 2 * std::numbers::pi - angles.back();
  for (size_t i = 1; i < angles.size(); ++i) gap = std::max(gap, angles[i] - angles[i - 1]);
  slide.extent = (2 * std::numbers::pi - gap) * slide.radius;
  return slide;
}

}  // namespace

std::optional<Slide> slide_along_itself(const PointCloud& model, double res, double max_ratio) {
  const size_t n = model.points.size();
  if (n == 0 || model.normals.size() != n) return std::nullopt;
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (const auto& p : model.points) centre += p.cast<double>();
  centre /= static_cast<double>(n);
  double scale = 0;
  for (const auto& p : model.points) scale += (p.cast<double>() - centre).squaredNorm();
  scale = std::sqrt(scale / static_cast<double>(n));
  if (!(scale > 0)) return std::nullopt;
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
    if (share_moved_off(model, tree, motion.cast<float>(), 1.5 * res) > 0.01) return slide_of(model, centre, w, t, scale);
  }
  return std::nullopt;
}

}  // namespace artisan::detail
