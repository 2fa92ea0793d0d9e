#pragma once
// Spin images (Johnson & Hebert, "Using Spin Images for Efficient Object Recognition in
// Cluttered 3D Scenes", PAMI 1999). An oriented point (p, n) spins a 2-D histogram of the
// support points x around its normal: alpha = radial distance from the line through p along n,
// beta = signed height along n (eq. 1); each point is spread bilinearly over four bins.
#include <cstddef>
#include <vector>

#include <Eigen/Core>

#include "artisan/core/triangle_mesh.hpp"
#include "artisan/perception/kdtree.hpp"

namespace artisan {

struct SpinImageParams {
  int image_width = 15;             ///< [bins] rows and columns of each image
  double bin_size_factor = 1.0;     ///< [1] bin size as a multiple of the mesh resolution
  double support_angle_deg = 60.0;  ///< [deg] support points whose normals differ more from n are left out
};

/// Spin images of several basis points, row-major, one image after another.
struct SpinImageStack {
  int width = 0;              ///< [bins]
  double bin_size_m = 0.0;    ///< [m]
  std::vector<size_t> basis;  ///< index of each image's oriented point in the cloud
  std::vector<float> values;  ///< basis.size() * width * width

  size_t size() const { return basis.size(); }
  const float* image(size_t i) const { return values.data() + i * width * width; }
};

/// The spin-map coordinates (alpha, beta) of x in the basis of the oriented point (p, n).
inline Eigen::Vector2f spin_coordinates(const Eigen::Vector3f& p, const Eigen::Vector3f& n, const Eigen::Vector3f& x) {
  const Eigen::Vector3f d = x - p;
  const float beta = n.dot(d);
  return {std::sqrt(std::max(0.0f, d.squaredNorm() - beta * beta)), beta};
}

/// Spin images of cloud points `basis` (all points when empty) over the support `cloud`, indexed
/// by `tree`. `resolution_m` is the mesh resolution that sets the bin size. Parallel over basis
/// points. Throws artisan::Error on a cloud without normals or bad parameters.
SpinImageStack compute_spin_images(const PointCloud& cloud, const KdTree3& tree, const std::vector<size_t>& basis,
                                   double resolution_m, const SpinImageParams& params = {});

/// Oriented points resampled on a voxel grid of edge `resolution_m` [m]: the mean point and
/// mean (renormalised) normal of each occupied voxel. Gives the uniform sampling spin images
/// assume.
PointCloud resample_oriented_points(const PointCloud& cloud, double resolution_m);

/// Oriented points spread over the surface of `mesh` (not only its vertices: a CAD model's long
/// thin triangles carry most of its area), then resampled on a voxel grid of edge
/// `resolution_m`. Each triangle is split into sub-triangles no longer than half the resolution
/// whose centroids are sampled; a sample's normal interpolates the vertex normals, or is the
/// face's own normal where they disagree with it by more than 45 degrees (a sharp edge).
PointCloud sample_surface(const TriangleMesh& mesh, double resolution_m);

}  // namespace artisan
