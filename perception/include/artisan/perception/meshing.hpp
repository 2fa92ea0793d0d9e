#pragma once
// Range image -> triangle mesh: a constrained Delaunay triangulation of the range image in the
// image plane with a minimum-angle guarantee (Ruppert's Delaunay refinement as in Shewchuk's
// Triangle; CGAL Delaunay_mesher_2). Constraints follow the boundary of the valid region, which
// includes every depth discontinuity, so no triangle bridges a jump or covers a hole. Flat
// regions are thinned by an adaptive quadtree before triangulation; edge flips then improve the
// triangles' shape in 3-D without breaking the image-plane bound. The method in full is in
// perception/src/meshing.cpp.
#include <cstddef>
#include <optional>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "artisan/core/range_image.hpp"
#include "artisan/core/triangle_mesh.hpp"

namespace artisan {

struct MeshingParams {
  /// How the range sensor's viewing rays run in the sensor frame.
  enum class Rays {
    kAuto,         ///< kParallel when sensor.kind starts with "cyberware", else kPerspective
    kPerspective,  ///< rays from the sensor-frame origin (pinhole, Vivid, stereo rigs)
    kParallel,     ///< parallel rays along parallel_ray_direction_sensor (linear-translation scanners)
  };
  Rays rays = Rays::kAuto;
  /// [unit vector, sensor frame] viewing direction for Rays::kParallel. The Stanford Cyberware
  /// range grids look along -z (their silhouettes bend away from +z).
  Eigen::Vector3d parallel_ray_direction_sensor{0.0, 0.0, -1.0};

  /// [1] k of the discontinuity rule. Two neighbouring pixels P, Q are a depth jump when their
  /// range difference along the viewing ray v exceeds k times their spacing across the ray:
  ///   |(Q - P).v| > k * |(Q - P) - ((Q - P).v) v|,
  /// i.e. |r_P - r_Q| > k * r * (pixel angle), with the pixel spacing r * (pixel angle) measured
  /// from the two points themselves, so the rule holds for any range and sensor geometry. It cuts
  /// every surface inclined more than atan(k) from facing the sensor (4 -> 76 degrees).
  double depth_jump_ratio = 4.0;
  /// [deg] a half cell (a triangle of three valid pixels, where the fourth is missing or across a
  /// depth jump) is meshed only when it covers a pixel that no full cell covers and faces the
  /// sensor within this angle. Steeper half cells sit on noisy silhouettes, and Delaunay
  /// refinement around their 45-degree corners makes sub-pixel triangles that are slivers in 3-D.
  double half_cell_max_inclination_deg = 70.0;
  /// [deg] smallest triangle angle in the image plane after refinement. At most 20.7 (CGAL's
  /// bound B = sqrt(2), the largest for which Delaunay refinement is proven to terminate).
  double min_angle_deg = 20.7;
  /// [deg] smallest triangle angle in 3-D: an image-plane triangle stretched on a steep surface
  /// is refined while it spans more than 1.5 pixels. 0 turns the test off.
  double min_angle_3d_deg = 10.0;
  /// [m] longest 3-D edge: longer triangles are refined while they span more than 1.5 pixels.
  double max_edge_length_m = 0.1;
  /// [1] thinning tolerance as a fraction of the local sample spacing (the 3-D distance across
  /// the ray between neighbouring pixels). A quadtree block of pixels becomes one coarse cell
  /// when every point in it lies within tolerance * spacing of the block's least-squares plane,
  /// so the mesh stays within about twice that of the measured points. 0 keeps every pixel.
  double thinning_tolerance = 0.5;
  /// [1/m] thinning floor for noisy sensors: the flatness limit is at least this times the
  /// squared distance from the sensor origin (triangulation noise grows with range squared;
  /// for the simulated Pioneer stereo head ~0.005, three times its noise). 0: off.
  double thinning_noise_per_m2 = 0.0;
  /// [pixels] region of interest, inclusive min and max (x, y) corners; unset: the whole image.
  std::optional<Eigen::AlignedBox2i> roi_pixels;
};

struct MeshingResult {
  /// Sensor frame; faces counter-clockwise seen from the sensor, per-vertex normals toward the
  /// sensor, uv from the range image's uv (normalised by images[0]'s size, else by the range
  /// image's size) and images[0].image as texture when present.
  TriangleMesh mesh;
  std::vector<Eigen::Vector2d> vertex_pixels;  ///< [pixels] per mesh vertex, its position in the range image
  size_t vertex_count = 0;
  size_t face_count = 0;
  size_t valid_pixel_count = 0;          ///< measured pixels inside the ROI
  size_t full_grid_face_count = 0;       ///< faces of the full-resolution grid mesh: 2 per 2x2 block of valid pixels
  size_t discontinuity_edge_count = 0;   ///< 4-neighbour pixel pairs, both valid, that are depth jumps
  size_t constraint_edge_count = 0;      ///< boundary segments given to the triangulation (straight runs merged)
  size_t steiner_vertex_count = 0;       ///< vertices added by refinement (depth interpolated)
  double resolution_m = 0.0;             ///< median 3-D edge length [m]
  double min_angle_image_deg = 0.0;      ///< smallest triangle angle in the image plane [deg]
  size_t faces_below_min_angle = 0;      ///< faces under min_angle_deg in the image plane (forced by the input constraints)
  double seconds = 0.0;                  ///< wall time of mesh_range_image [s]
};

/// Meshes one range image (see MeshingParams for the rules). Throws artisan::Error on an empty
/// image, an image without valid pixels (in the ROI), bad parameters or an ROI outside the image.
MeshingResult mesh_range_image(const RangeImage& image, const MeshingParams& params = {});

/// The mesh resolution: median edge length [m].
double mesh_resolution(const TriangleMesh& mesh);

/// Resamples a mesh to edges of about target_edge_m [m] with CGAL isotropic remeshing (Botsch &
/// Kobbelt 2004: split, collapse, flip, tangential relaxation with projection onto the input,
/// 3 iterations). Borders are remeshed too (their vertices slide along them), so a pixel
/// staircase becomes a straighter border within about half a target edge of the input's. The
/// result has vertices, faces (orientation kept) and normals; uv, colours and texture are
/// dropped. Throws artisan::Error on an empty or invalid mesh or a target that is not positive.
TriangleMesh remesh_to_resolution(const TriangleMesh& mesh, double target_edge_m);

}  // namespace artisan
