#pragma once
// Rigid transforms. Naming convention: T_a_b maps coordinates in frame b into frame a
// (p_a = T_a_b * p_b); compose as T_a_c = T_a_b * T_b_c.
#include <array>
#include <string>

#include <Eigen/Geometry>

namespace artisan {

using Transform = Eigen::Isometry3d;

/// T from a translation (metres) and a unit quaternion (x, y, z, w). Throws artisan::Error if
/// the quaternion is not unit length within 1e-3 (it is normalised when within tolerance).
Transform transform_from_tq(const Eigen::Vector3d& t, double qx, double qy, double qz, double qw);

/// Parses "tx ty tz qx qy qz qw" (unit quaternion, w last) or sixteen numbers (a row-major 4x4).
/// Commas are accepted as separators. Throws artisan::Error naming the text on any defect
/// (wrong count, non-numbers, non-finite values, non-rigid matrix).
Transform parse_transform(const std::string& text);

/// Row-major 4x4, the JSON form of a transform.
std::array<double, 16> to_row_major(const Transform& T);

/// Inverse of to_row_major; throws artisan::Error when the matrix is not a rigid transform
/// (rotation not orthonormal within 1e-4 -- it is snapped to the nearest rotation --, determinant not +1, last row not 0 0 0 1).
Transform from_row_major(const std::array<double, 16>& m);

/// Rotation angle of T in radians, in [0, pi].
double rotation_angle(const Transform& T);

}  // namespace artisan
