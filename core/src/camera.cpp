#include "artisan/core/camera.hpp"

#include <cmath>
#include <string>

#include "artisan/core/error.hpp"

namespace artisan {

std::optional<Eigen::Vector2d> PinholeCamera::project(const Eigen::Vector3d& p_camera) const {
  if (p_camera.z() <= 0) return std::nullopt;
  return Eigen::Vector2d(fx * p_camera.x() / p_camera.z() + cx, fy * p_camera.y() / p_camera.z() + cy);
}

Eigen::Vector3d PinholeCamera::unproject(const Eigen::Vector2d& uv, double z) const {
  return {(uv.x() - cx) / fx * z, (uv.y() - cy) / fy * z, z};
}

void PinholeCamera::validate() const {
  auto positive = [](double x) { return std::isfinite(x) && x > 0; };
  if (width <= 0 || height <= 0 || !positive(fx) || !positive(fy) || !std::isfinite(cx) || !std::isfinite(cy)) {
    throw Error("pinhole camera: invalid intrinsics (width " + std::to_string(width) + ", height " +
                std::to_string(height) + ", fx " + std::to_string(fx) + ", fy " + std::to_string(fy) + ", cx " +
                std::to_string(cx) + ", cy " + std::to_string(cy) + ")");
  }
}

}  // namespace artisan
