#pragma once
// JSON field readers for the workcell loader: each names the file and field when it throws.
#include <array>
#include <cmath>
#include <string>

#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

#include "artisan/sim/look_at.hpp"
#include "artisan/core/error.hpp"
#include "artisan/core/pose.hpp"

namespace artisan::sim {

template <class L>
double number(const nlohmann::json& j, const std::string& field, const L& l) {
  if (j.is_null()) l.fail(field, "is missing");
  if (!j.is_number()) l.fail(field, "must be a number, got " + j.dump());
  const double v = j.get<double>();
  if (!std::isfinite(v)) l.fail(field, "must be finite");
  return v;
}

template <class L>
double positive(const nlohmann::json& j, const std::string& field, const L& l) {
  const double v = number(j, field, l);
  if (!(v > 0)) l.fail(field, "must be positive, got " + j.dump());
  return v;
}

template <class L>
bool boolean(const nlohmann::json& j, const std::string& field, const L& l) {
  if (!j.is_boolean()) l.fail(field, "must be true or false, got " + j.dump());
  return j.get<bool>();
}

template <class L>
std::string string(const nlohmann::json& j, const std::string& field, const L& l) {
  if (j.is_null()) l.fail(field, "is missing");
  if (!j.is_string()) l.fail(field, "must be a string, got " + j.dump());
  return j.get<std::string>();
}

template <class L>
Eigen::Vector3d vec3(const nlohmann::json& j, const std::string& field, const L& l) {
  if (j.is_null()) l.fail(field, "is missing");
  if (!j.is_array() || j.size() != 3) l.fail(field, "must be an array of 3 numbers, got " + j.dump());
  return {number(j[0], field, l), number(j[1], field, l), number(j[2], field, l)};
}

/// "pose": "tx ty tz qx qy qz qw" | 7 or 16 numbers; or "look_at": {"eye", "target", "up"}.
/// Identity when neither is given.
template <class L>
Transform pose(const nlohmann::json& obj, const std::string& field, const L& l) {
  if (obj.contains("pose") && obj.contains("look_at")) l.fail(field, "give 'pose' or 'look_at', not both");
  if (obj.contains("look_at")) {
    const auto& la = obj["look_at"];
    const Eigen::Vector3d eye = vec3(la.value("eye", nlohmann::json()), field + ".look_at.eye", l);
    const Eigen::Vector3d target = vec3(la.value("target", nlohmann::json()), field + ".look_at.target", l);
    const Eigen::Vector3d up = la.contains("up") ? vec3(la["up"], field + ".look_at.up", l) : Eigen::Vector3d::UnitZ();
    if ((target - eye).norm() < 1e-9) l.fail(field + ".look_at", "eye and target coincide");
    return look_at(eye, target, up);
  }
  if (!obj.contains("pose")) return Transform::Identity();
  const auto& p = obj["pose"];
  try {
    if (p.is_string()) return parse_transform(p.get<std::string>());
    if (p.is_array() && p.size() == 7) {
      std::array<double, 7> v{};
      for (size_t i = 0; i < 7; ++i) v[i] = number(p[i], field + ".pose", l);
      return transform_from_tq({v[0], v[1], v[2]}, v[3], v[4], v[5], v[6]);
    }
    if (p.is_array() && p.size() == 16) {
      std::array<double, 16> m{};
      for (size_t i = 0; i < 16; ++i) m[i] = number(p[i], field + ".pose", l);
      return from_row_major(m);
    }
  } catch (const Error& e) {
    l.fail(field + ".pose", e.what());
  }
  l.fail(field + ".pose", "must be a string or an array of 7 or 16 numbers");
}

}  // namespace artisan::sim
