#pragma once
// Offscreen rendering of a workcell (OSMesa, no display): metric depth, colour and per-pixel
// instance ids from any pinhole camera.
//
// Exactness: the projection puts pixel (u, v) of PinholeCamera (origin at the centre of the
// top-left pixel) exactly on the centre of window pixel (u, v), where the rasteriser samples.
// Depth is read back from the depth buffer and converted with the same near/far planes, so
// camera.unproject((u, v), depth) is the surface point seen through that pixel centre, up to
// the depth buffer's quantisation (24 bits: about z^2 / near * 6e-8 m).
#include <cstdint>
#include <memory>
#include <vector>

#include "artisan/core/camera.hpp"
#include "artisan/core/image.hpp"
#include "artisan/core/pose.hpp"
#include "artisan/sim/workcell.hpp"

namespace artisan::sim {

struct RenderOptions {
  bool color = true;              ///< render the lit, textured colour image
  bool depth = true;              ///< read back metric depth
  bool instances = true;          ///< render the instance-id image
  double near_m = 0.1;            ///< near clipping plane [m]
  double far_m = 20.0;            ///< far clipping plane [m]
  int only_instance = 0;          ///< > 0: draw only this body (for unoccluded renders)
  Eigen::Vector3f background{0.08f, 0.08f, 0.1f};  ///< colour where nothing is hit, RGB [0, 1]
};

struct RenderResult {
  int width = 0;
  int height = 0;
  std::vector<float> depth_m;          ///< z along the optical axis [m], row-major; 0 where nothing is hit
  ColorImage color;                    ///< RGB, rows top to bottom (empty unless requested)
  std::vector<uint16_t> instance_ids;  ///< Body::instance_id per pixel; 0 = nothing (empty unless requested)
};

/// Whether the camera of a render (with depth) sees `p_camera`, a point in its frame: it projects
/// into the image, in front of the camera, and lies no farther than the farthest depth seen in
/// the 2 x 2 pixels around it (lenient on slopes; a pixel that saw nothing is infinitely far) by
/// more than `tolerance_m` plus 0.2% of its depth. Whether another camera (a scanner's laser, a
/// stereo partner) sees what this one does.
bool sees_point(const RenderResult& render, const PinholeCamera& camera, const Eigen::Vector3d& p_camera, double tolerance_m);

class Renderer {
 public:
  /// Uploads the workcell's meshes (the workcell's body list must not change afterwards; poses
  /// may). Throws artisan::Error when no OSMesa context can be made.
  explicit Renderer(const Workcell& cell);
  ~Renderer();
  Renderer(const Renderer&) = delete;
  Renderer& operator=(const Renderer&) = delete;

  /// Renders `cell` at its current poses through `camera` placed at T_world_camera
  /// (camera frame: x right, y down, z forward).
  RenderResult render(const Workcell& cell, const PinholeCamera& camera, const Transform& T_world_camera,
                      const RenderOptions& options = {});

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

/// A pinhole camera of the given size and horizontal field of view [rad], square pixels,
/// principal point at the image centre.
PinholeCamera camera_from_fov(int width, int height, double horizontal_fov_rad);

/// Points in the camera frame for every pixel (row-major): camera.unproject((u, v), z);
/// (0, 0, 0) where depth is 0.
std::vector<Eigen::Vector3f> unproject_depth(const PinholeCamera& camera, const std::vector<float>& depth_m);

}  // namespace artisan::sim
