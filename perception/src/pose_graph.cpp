#include "artisan/perception/pose_graph.hpp"

#include <cmath>
#include <numbers>
#include <string>

#include <Eigen/Dense>

#include "artisan/core/error.hpp"

namespace artisan {

namespace {

using Vector6 = Eigen::Matrix<double, 6, 1>;

// Rotation vector and translation of a (small) relative transform: a first-order log map.
Vector6 residual(const Transform& E, double translation_weight) {
  const Eigen::AngleAxisd aa(E.linear());
  Vector6 r;
  r.head<3>() = aa.angle() * aa.axis();
  r.tail<3>() = translation_weight * E.translation();
  return r;
}

Transform exp6(const Vector6& x) {
  Transform T = Transform::Identity();
  const double angle = x.head<3>().norm();
  if (angle > 0) T.linear() = Eigen::AngleAxisd(angle, x.head<3>() / angle).toRotationMatrix();
  T.translation() = x.tail<3>();
  return T;
}

void rms(const std::vector<Transform>& T, const std::vector<PoseGraphEdge>& edges, double& rot_deg, double& trans_m) {
  double r = 0, t = 0;
  for (const auto& e : edges) {
    const Transform E = e.T_from_to.inverse() * T[e.from].inverse() * T[e.to];
    r += std::pow(Eigen::AngleAxisd(E.linear()).angle(), 2);
    t += E.translation().squaredNorm();
  }
  const double n = std::max<size_t>(1, edges.size());
  rot_deg = std::sqrt(r / n) * 180.0 / std::numbers::pi;
  trans_m = std::sqrt(t / n);
}

}  // namespace

PoseGraphResult optimize_pose_graph(const std::vector<Transform>& T_root_node, const std::vector<PoseGraphEdge>& edges,
                                    const PoseGraphSettings& settings) {
  const int n = static_cast<int>(T_root_node.size());
  for (const auto& e : edges)
    if (e.from < 0 || e.to < 0 || e.from >= n || e.to >= n || e.from == e.to)
      throw Error("pose graph: edge " + std::to_string(e.from) + " -> " + std::to_string(e.to) + " does not join two of the " + std::to_string(n) + " nodes");
  PoseGraphResult result;
  result.T_root_node = T_root_node;
  result.T_root_node[0] = Transform::Identity();
  rms(result.T_root_node, edges, result.rms_rotation_deg_before, result.rms_translation_m_before);
  const int unknowns = 6 * (n - 1);
  if (unknowns == 0 || edges.empty()) {
    result.rms_rotation_deg_after = result.rms_rotation_deg_before;
    result.rms_translation_m_after = result.rms_translation_m_before;
    return result;
  }
  auto& T = result.T_root_node;
  constexpr double kStep = 1e-6;
  for (int it = 0; it < settings.max_iterations; ++it) {
    Eigen::MatrixXd H = Eigen::MatrixXd::Zero(unknowns, unknowns);
    Eigen::VectorXd g = Eigen::VectorXd::Zero(unknowns);
    for (const auto& e : edges) {
      const Vector6 r0 = residual(e.T_from_to.inverse() * T[e.from].inverse() * T[e.to], settings.translation_weight);
      // Numerical Jacobians w.r.t. left perturbations of the two node poses (small graphs).
      Eigen::Matrix<double, 6, 12> J = Eigen::Matrix<double, 6, 12>::Zero();
      for (int side = 0; side < 2; ++side) {
        const int node = side == 0 ? e.from : e.to;
        if (node == 0) continue;
        for (int k = 0; k < 6; ++k) {
          Vector6 d = Vector6::Zero();
          d[k] = kStep;
          Transform Ti = T[e.from], Tj = T[e.to];
          (side == 0 ? Ti : Tj) = exp6(d) * (side == 0 ? Ti : Tj);
          J.col(side * 6 + k) = (residual(e.T_from_to.inverse() * Ti.inverse() * Tj, settings.translation_weight) - r0) / kStep;
        }
      }
      const int idx[2] = {e.from, e.to};
      for (int a = 0; a < 2; ++a) {
        if (idx[a] == 0) continue;
        const int ra = 6 * (idx[a] - 1);
        g.segment<6>(ra) += e.weight * J.block<6, 6>(0, 6 * a).transpose() * r0;
        for (int b = 0; b < 2; ++b) {
          if (idx[b] == 0) continue;
          H.block<6, 6>(ra, 6 * (idx[b] - 1)) += e.weight * J.block<6, 6>(0, 6 * a).transpose() * J.block<6, 6>(0, 6 * b);
        }
      }
    }
    H.diagonal().array() += 1e-9;  // nodes no edge reaches stay put
    const Eigen::VectorXd dx = H.ldlt().solve(-g);
    for (int node = 1; node < n; ++node) T[node] = exp6(dx.segment<6>(6 * (node - 1))) * T[node];
    result.iterations = it + 1;
    if (dx.norm() < 1e-10) break;
  }
  rms(T, edges, result.rms_rotation_deg_after, result.rms_translation_m_after);
  return result;
}

}  // namespace artisan
