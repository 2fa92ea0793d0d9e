#include "artisan/core/pose.hpp"

#include <charconv>
#include <cmath>
#include <vector>

#include "artisan/core/error.hpp"

namespace artisan {

Transform transform_from_tq(const Eigen::Vector3d& t, double qx, double qy, double qz, double qw) {
  Eigen::Quaterniond q(qw, qx, qy, qz);
  const double norm = q.norm();
  if (!std::isfinite(norm) || std::abs(norm - 1.0) > 1e-3) {
    throw Error("quaternion (" + std::to_string(qx) + ", " + std::to_string(qy) + ", " + std::to_string(qz) +
                ", " + std::to_string(qw) + ") is not unit length (norm " + std::to_string(norm) + ")");
  }
  if (!t.allFinite()) throw Error("translation is not finite");
  Transform T = Transform::Identity();
  T.linear() = q.normalized().toRotationMatrix();
  T.translation() = t;
  return T;
}

Transform parse_transform(const std::string& text) {
  std::vector<double> v;
  const char* p = text.data();
  const char* end = p + text.size();
  while (p < end) {
    while (p < end && (*p == ' ' || *p == ',' || *p == '\t' || *p == '\n')) ++p;
    if (p >= end) break;
    double x = 0;
    auto [next, ec] = std::from_chars(p, end, x);
    if (ec != std::errc() || (next < end && !(*next == ' ' || *next == ',' || *next == '\t' || *next == '\n'))) {
      throw Error("pose \"" + text + "\": \"" + std::string(p, std::min<size_t>(end - p, 16)) + "\" is not a number");
    }
    if (!std::isfinite(x)) throw Error("pose \"" + text + "\": non-finite value");
    v.push_back(x);
    p = next;
  }
  if (v.size() == 7) {
    try {
      return transform_from_tq({v[0], v[1], v[2]}, v[3], v[4], v[5], v[6]);
    } catch (const Error& e) {
      throw Error("pose \"" + text + "\": " + e.what());
    }
  }
  if (v.size() == 16) {
    std::array<double, 16> m{};
    std::copy(v.begin(), v.end(), m.begin());
    try {
      return from_row_major(m);
    } catch (const Error& e) {
      throw Error("pose \"" + text + "\": " + e.what());
    }
  }
  throw Error("pose \"" + text + "\" has " + std::to_string(v.size()) +
              " numbers; expected 7 (tx ty tz qx qy qz qw) or 16 (row-major 4x4)");
}

std::array<double, 16> to_row_major(const Transform& T) {
  std::array<double, 16> m{};
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) m[r * 4 + c] = T.matrix()(r, c);
  return m;
}

Transform from_row_major(const std::array<double, 16>& m) {
  Eigen::Matrix4d M;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) M(r, c) = m[r * 4 + c];
  if (!M.allFinite()) throw Error("matrix has non-finite entries");
  const Eigen::Matrix3d R = M.topLeftCorner<3, 3>();
  const double orth = (R.transpose() * R - Eigen::Matrix3d::Identity()).norm();
  // Matrices typed with six decimals are orthonormal to about 1e-6; accept 1e-4 and snap to
  // the nearest rotation.
  if (orth > 1e-4) throw Error("rotation part is not orthonormal (|RᵀR - I| = " + std::to_string(orth) + ")");
  if (R.determinant() < 0) throw Error("rotation part is a reflection (determinant -1)");
  if ((M.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).norm() > 1e-9) throw Error("last row is not 0 0 0 1");
  Transform T = Transform::Identity();
  T.matrix() = M;
  if (orth > 1e-10) T.linear() = Eigen::Quaterniond(R).normalized().toRotationMatrix();
  return T;
}

double rotation_angle(const Transform& T) {
  const double c = std::clamp((T.linear().trace() - 1.0) / 2.0, -1.0, 1.0);
  return std::acos(c);
}

}  // namespace artisan
