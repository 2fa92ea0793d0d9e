// Range image -> triangle mesh by constrained Delaunay refinement in the image plane.
//
// 1. Domain. Pixel centres sit at integer image coordinates. Each unit cell between four pixel
//    centres contributes a piece of the valid region: the whole square when its four pixels are
//    valid and its four sides are no depth jumps; else, only where it covers a pixel that no
//    square covers, one triangle of three valid pixels whose three sides (two cell sides and a
//    diagonal) are no jumps and which faces the sensor within half_cell_max_inclination_deg;
//    else nothing. The domain is the union of the pieces; its boundary (cell sides used by one
//    piece only, and the diagonals of triangle pieces) runs around holes, along every depth jump
//    and along the image (ROI) border. Input angles are multiples of 45 degrees, so the
//    refinement below never meets an input angle under 45 degrees.
// 2. Thinning. An adaptive quadtree (Von Herzen & Barr 1987; Sequeira et al. 1999 for range
//    images) keeps a block of pixels as one coarse cell, represented by its four corner pixels,
//    when every cell in it is a full square and every point in it lies within
//    thinning_tolerance * (sample spacing) of the block's least-squares plane. The corners lie
//    within that distance of the plane too, so the coarse triangles stay within twice the
//    tolerance of the measured points while flat regions lose nearly all their pixels. Leaves are
//    then balanced 2:1 (restricted quadtree, as in Pajarola 1998) so the density grades smoothly
//    and the Delaunay triangles stay local.
// 3. Triangulation. The kept pixels and the boundary segments go into a CGAL
//    Constrained_Delaunay_triangulation_2; each face is marked in or out of the domain by testing
//    its centroid against the pieces (exact, since every boundary segment is a constraint).
// 4. Refinement. CGAL Delaunay_mesher_2 (Ruppert 1995, Shewchuk 2002) splits encroached
//    constraints and inserts circumcentres until every in-domain face has its smallest image-plane
//    angle at least min_angle_deg and, while it spans more than 1.5 pixels, its longest 3-D edge
//    at most max_edge_length_m and its smallest 3-D angle at least min_angle_3d_deg.
// 5. Depth. Every vertex gets its 3-D point and uv from the piece that contains it: bilinear in a
//    square piece, barycentric in a triangle piece, on the measured points only. Pixel vertices
//    therefore keep their measured points exactly.
// 6. Shape in 3-D. Edge flips by the 3-D max-min angle criterion that keep the image-plane bound
//    (flip_for_3d_shape), then faces are oriented toward the sensor and vertex normals computed.
#include "artisan/perception/meshing.hpp"

#include <algorithm>
#include <array>
#include <cassert>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <sstream>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include <CGAL/Constrained_Delaunay_triangulation_2.h>
#include <CGAL/Delaunay_mesh_face_base_2.h>
#include <CGAL/Delaunay_mesh_vertex_base_2.h>
#include <CGAL/Delaunay_mesher_2.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_vertex_base_with_info_2.h>
#include <Eigen/Eigenvalues>

#include "artisan/core/error.hpp"

namespace artisan {
namespace {

using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Vb = CGAL::Delaunay_mesh_vertex_base_2<K, CGAL::Triangulation_vertex_base_with_info_2<int, K>>;
using Fb = CGAL::Delaunay_mesh_face_base_2<K>;
using Tds = CGAL::Triangulation_data_structure_2<Vb, Fb>;
using Cdt = CGAL::Constrained_Delaunay_triangulation_2<K, Tds>;
using Point2 = K::Point_2;

constexpr int kMaxBlockCells = 64;  // largest quadtree block [cells]
constexpr double kPi = 3.14159265358979323846;
// The smallest angle for CGAL's bound B = sqrt(2): asin(1 / (2 sqrt 2)) = 20.7048 degrees.
const double kMaxMinAngleDeg = std::asin(1.0 / (2.0 * std::sqrt(2.0))) * 180.0 / kPi;

std::string num(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

// Corners of cell (x, y) in counter-clockwise order of the image (y down): c0 (x, y), c1 (x+1, y),
// c2 (x+1, y+1), c3 (x, y+1). Side e joins corners e and e+1 (mod 4).
constexpr std::array<std::array<int, 2>, 4> kCorner = {{{0, 0}, {1, 0}, {1, 1}, {0, 1}}};
// Piece of a cell: none, the full square, or the triangle without corner k (kTri + k).
constexpr uint8_t kNone = 0, kFull = 1, kTri = 2;

// Interpolation weights of a point on the measured surface.
struct Sample {
  std::array<size_t, 4> pixel{};
  std::array<double, 4> weight{};
  int n = 0;
};

// The range image seen as a piecewise bilinear surface over the valid domain.
class RangeSurface {
 public:
  RangeSurface(const RangeImage& image, const MeshingParams& params, bool parallel_rays,
               const Eigen::Vector3d& ray_direction)
      : image_(image),
        w_(image.width),
        h_(image.height),
        cw_(std::max(w_ - 1, 0)),
        ch_(std::max(h_ - 1, 0)),
        k_(params.depth_jump_ratio),
        half_cell_tan_(std::tan(params.half_cell_max_inclination_deg * kPi / 180.0)),
        parallel_(parallel_rays),
        ray_direction_(ray_direction) {
    valid_.assign(image.pixel_count(), 0);
    int x0 = 0, y0 = 0, x1 = w_ - 1, y1 = h_ - 1;
    if (params.roi_pixels) {
      x0 = params.roi_pixels->min().x();
      y0 = params.roi_pixels->min().y();
      x1 = params.roi_pixels->max().x();
      y1 = params.roi_pixels->max().y();
    }
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x) valid_[image.index(x, y)] = image.valid[image.index(x, y)] != 0;
    // Sides between 4-neighbours: ok when both are valid and they are no depth jump.
    h_ok_.assign(image.pixel_count(), 0);
    v_ok_.assign(image.pixel_count(), 0);
    for (int y = 0; y < h_; ++y) {
      for (int x = 0; x < w_; ++x) {
        const size_t i = image.index(x, y);
        if (!valid_[i]) continue;
        ++valid_count_;
        if (x + 1 < w_ && valid_[i + 1]) {
          h_ok_[i] = !is_jump(i, i + 1);
          jump_count_ += !h_ok_[i];
        }
        if (y + 1 < h_ && valid_[i + w_]) {
          v_ok_[i] = !is_jump(i, i + w_);
          jump_count_ += !v_ok_[i];
        }
      }
    }
    // Full squares first; then triangles, only where they cover a pixel no piece covers yet.
    piece_.assign(static_cast<size_t>(cw_) * ch_, kNone);
    std::vector<uint8_t> covered(image.pixel_count(), 0);
    for (int y = 0; y < ch_; ++y)
      for (int x = 0; x < cw_; ++x)
        if (side_ok(x, y, 0) && side_ok(x, y, 1) && side_ok(x, y, 2) && side_ok(x, y, 3)) {
          piece_[cell(x, y)] = kFull;
          for (int c = 0; c < 4; ++c) covered[corner_pixel(x, y, c)] = 1;
        }
    for (int y = 0; y < ch_; ++y)
      for (int x = 0; x < cw_; ++x)
        if (piece_[cell(x, y)] == kNone) piece_[cell(x, y)] = triangle_piece(x, y, covered);
  }

  int width() const { return w_; }
  int height() const { return h_; }
  int cells_x() const { return cw_; }
  int cells_y() const { return ch_; }
  size_t cell(int x, int y) const { return static_cast<size_t>(y) * cw_ + x; }
  uint8_t piece(int x, int y) const { return piece_[cell(x, y)]; }
  size_t valid_count() const { return valid_count_; }
  size_t jump_count() const { return jump_count_; }
  const Eigen::Vector3f& point(size_t pixel) const { return image_.points_sensor[pixel]; }
  bool valid(size_t pixel) const { return valid_[pixel] != 0; }

  Eigen::Vector3d ray(const Eigen::Vector3d& p) const {
    if (parallel_) return ray_direction_;
    const double n = p.norm();
    return n > 0 ? Eigen::Vector3d(p / n) : ray_direction_;
  }

  // The discontinuity rule of MeshingParams::depth_jump_ratio.
  bool is_jump(size_t a, size_t b) const {
    const Eigen::Vector3d p = point(a).cast<double>(), q = point(b).cast<double>();
    const Eigen::Vector3d d = q - p;
    const Eigen::Vector3d v = ray(0.5 * (p + q));
    const double along = d.dot(v);
    return std::abs(along) > k_ * (d - along * v).norm();
  }

  // Lateral (across the ray) length of p -> q.
  double lateral(const Eigen::Vector3d& p, const Eigen::Vector3d& q) const {
    const Eigen::Vector3d d = q - p;
    const Eigen::Vector3d v = ray(0.5 * (p + q));
    return (d - d.dot(v) * v).norm();
  }

  size_t corner_pixel(int x, int y, int c) const { return image_.index(x + kCorner[c][0], y + kCorner[c][1]); }

  // Bit e set when the piece of cell (x, y) includes cell side e.
  int side_mask(int x, int y) const {
    const uint8_t p = piece(x, y);
    if (p == kFull) return 0xF;
    if (p >= kTri) {
      const int k = p - kTri;
      return (1 << ((k + 1) % 4)) | (1 << ((k + 2) % 4));
    }
    return 0;
  }

  // Where (x, y) lies on the measured surface; false when it is outside the domain (by more
  // than eps pixels).
  bool locate(double x, double y, Sample& s, double eps = 1e-7) const {
    const int fx = static_cast<int>(std::floor(x)), fy = static_cast<int>(std::floor(y));
    for (int cy : {fy, fy - 1, fy + 1}) {
      if (cy < 0 || cy >= ch_) continue;
      for (int cx : {fx, fx - 1, fx + 1}) {
        if (cx < 0 || cx >= cw_) continue;
        if (in_piece(cx, cy, x - cx, y - cy, s, eps)) return true;
      }
    }
    return false;
  }

  // The measured surface point at image position (x, y), NaN outside the domain.
  Eigen::Vector3d position(double x, double y) const {
    Sample s;
    if (!locate(x, y, s)) return Eigen::Vector3d::Constant(NAN);
    Eigen::Vector3d p = Eigen::Vector3d::Zero();
    for (int k = 0; k < s.n; ++k) p += s.weight[k] * point(s.pixel[k]).cast<double>();
    return p;
  }

  // Least-squares plane test of the (sx+1) x (sy+1) pixels of a block at (bx, by); all valid.
  bool planar(int bx, int by, int sx, int sy, double tolerance, double noise_per_m2) const {
    const int n = (sx + 1) * (sy + 1);
    const Eigen::Vector3d origin = point(image_.index(bx, by)).cast<double>();
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    Eigen::Matrix3d sum_sq = Eigen::Matrix3d::Zero();
    for (int y = by; y <= by + sy; ++y) {
      for (int x = bx; x <= bx + sx; ++x) {
        const Eigen::Vector3d p = point(image_.index(x, y)).cast<double>() - origin;
        sum += p;
        sum_sq += p * p.transpose();
      }
    }
    const Eigen::Vector3d mean = sum / n;
    const Eigen::Matrix3d cov = sum_sq / n - mean * mean.transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig;
    eig.computeDirect(cov);
    const Eigen::Vector3d normal = eig.eigenvectors().col(0);  // smallest eigenvalue first
    // Sample spacing: the lateral length of the block's sides per pixel, the smaller of the two.
    const double spacing = std::min(lateral(origin, point(image_.index(bx + sx, by)).cast<double>()) / sx,
                                    lateral(origin, point(image_.index(bx, by + sy)).cast<double>()) / sy);
    const Eigen::Vector3d centre = origin + mean;
    // Noisy sensors (stereo): never demand more flatness than the noise allows.
    const double limit = std::max(tolerance * spacing, noise_per_m2 * centre.squaredNorm());
    for (int y = by; y <= by + sy; ++y)
      for (int x = bx; x <= bx + sx; ++x)
        if (std::abs(normal.dot(point(image_.index(x, y)).cast<double>() - centre)) > limit) return false;
    return true;
  }

 private:
  bool side_ok(int x, int y, int e) const {
    switch (e) {
      case 0: return h_ok_[image_.index(x, y)];
      case 1: return v_ok_[image_.index(x + 1, y)];
      case 2: return h_ok_[image_.index(x, y + 1)];
      default: return v_ok_[image_.index(x, y)];
    }
  }

  // The triangle piece of a cell that is not a full square (see MeshingParams::
  // half_cell_max_inclination_deg): three valid corners whose three sides (two cell sides, one
  // diagonal) are no depth jumps, one of them covered by no piece yet, facing the sensor within
  // the limit.
  uint8_t triangle_piece(int x, int y, std::vector<uint8_t>& covered) const {
    for (int k = 0; k < 4; ++k) {
      const int a = (k + 1) % 4, b = (k + 2) % 4, c = (k + 3) % 4;
      if (!side_ok(x, y, a) || !side_ok(x, y, b)) continue;  // sides a-b and b-c
      const size_t pa = corner_pixel(x, y, a), pb = corner_pixel(x, y, b), pc = corner_pixel(x, y, c);
      if ((covered[pa] && covered[pb] && covered[pc]) || !valid_[pc] || !valid_[pa] || is_jump(pc, pa)) continue;
      // Facing the sensor within the inclination limit: |n x v| <= tan(limit) |n . v|.
      const Eigen::Vector3d qa = point(pa).cast<double>(), qb = point(pb).cast<double>(), qc = point(pc).cast<double>();
      const Eigen::Vector3d n = (qb - qa).cross(qc - qa);
      const Eigen::Vector3d v = ray((qa + qb + qc) / 3);
      if (n.cross(v).norm() > half_cell_tan_ * std::abs(n.dot(v))) continue;
      covered[pa] = covered[pb] = covered[pc] = 1;
      return static_cast<uint8_t>(kTri + k);
    }
    return kNone;
  }

  // (u, v): position relative to the cell's corner c0.
  bool in_piece(int cx, int cy, double u, double v, Sample& s, double eps) const {
    const uint8_t p = piece(cx, cy);
    if (p == kNone) return false;
    if (u < -eps || u > 1 + eps || v < -eps || v > 1 + eps) return false;
    u = std::clamp(u, 0.0, 1.0);
    v = std::clamp(v, 0.0, 1.0);
    if (p == kFull) {
      s.n = 4;
      const std::array<double, 4> w = {(1 - u) * (1 - v), u * (1 - v), u * v, (1 - u) * v};
      for (int c = 0; c < 4; ++c) {
        s.pixel[c] = corner_pixel(cx, cy, c);
        s.weight[c] = w[c];
      }
      return true;
    }
    // Triangle without corner k: barycentric coordinates in corners a, b, c.
    const int k = p - kTri;
    const int a = (k + 1) % 4, b = (k + 2) % 4, c = (k + 3) % 4;
    const Eigen::Vector2d pa(kCorner[a][0], kCorner[a][1]), pb(kCorner[b][0], kCorner[b][1]),
        pc(kCorner[c][0], kCorner[c][1]), q(u, v);
    auto cross = [](const Eigen::Vector2d& e, const Eigen::Vector2d& f) { return e.x() * f.y() - e.y() * f.x(); };
    const double area = cross(pb - pa, pc - pa);
    std::array<double, 3> w = {cross(pb - q, pc - q) / area, cross(pc - q, pa - q) / area, cross(pa - q, pb - q) / area};
    for (double wi : w)
      if (wi < -eps) return false;
    double total = 0;
    for (double& wi : w) total += (wi = std::max(wi, 0.0));
    s.n = 3;
    const std::array<int, 3> corners = {a, b, c};
    for (int i = 0; i < 3; ++i) {
      s.pixel[i] = corner_pixel(cx, cy, corners[i]);
      s.weight[i] = w[i] / total;
    }
    return true;
  }

  const RangeImage& image_;
  int w_, h_, cw_, ch_;
  double k_, half_cell_tan_;
  bool parallel_;
  Eigen::Vector3d ray_direction_;
  std::vector<uint8_t> valid_, h_ok_, v_ok_, piece_;
  size_t valid_count_ = 0, jump_count_ = 0;
};

// Refinement criteria for Delaunay_mesher_2, modelled on CGAL's Delaunay_mesh_size_criteria_2
// with sizes and shapes also measured on the surface. A face is
// - imperatively bad when its longest 3-D edge exceeds max_edge_length_m,
// - bad when its smallest image-plane angle is under min_angle_deg, or its smallest 3-D angle is
//   under min_angle_3d_deg,
// where the two 3-D tests apply only while the face spans more than kMinSplitPixels in the image
// (finer than the pixels there is nothing left to resolve, and this bound keeps the refinement
// finite).
constexpr double kMinSplitPixels = 1.5;

class RangeMeshCriteria {
 public:
  struct Quality {
    double sine = 1;      // squared sine of the smallest image-plane angle
    double size = 0;      // (longest 3-D edge / max_edge_length_m)^2
    double sine_3d = 1;   // squared sine of the smallest 3-D angle (1 when not tested)
    // q1 < q2 means q1 is refined first: too-long faces (longest first), then the worst shapes.
    bool operator<(const Quality& q) const {
      if (size > 1) return q.size > 1 ? size > q.size : true;
      if (q.size > 1) return false;
      return std::min(sine, sine_3d) < std::min(q.sine, q.sine_3d);
    }
  };

  class Is_bad {
   public:
    Is_bad(double b, double b_3d, double sq_max_edge, const RangeSurface* surface)
        : b_(b), b_3d_(b_3d), sq_max_edge_(sq_max_edge), surface_(surface) {}

    CGAL::Mesh_2::Face_badness operator()(const Quality& q) const {
      if (q.size > 1) return CGAL::Mesh_2::IMPERATIVELY_BAD;
      return q.sine < b_ || q.sine_3d < b_3d_ ? CGAL::Mesh_2::BAD : CGAL::Mesh_2::NOT_BAD;
    }

    CGAL::Mesh_2::Face_badness operator()(const Cdt::Face_handle& fh, Quality& q) const {
      const Point2& pa = fh->vertex(0)->point();
      const Point2& pb = fh->vertex(1)->point();
      const Point2& pc = fh->vertex(2)->point();
      const double a = CGAL::squared_distance(pb, pc), b = CGAL::squared_distance(pc, pa),
                   c = CGAL::squared_distance(pa, pb);
      const double twice_area = CGAL::area(pa, pb, pc) * 2;
      q = Quality();
      q.sine = squared_min_sine(a, b, c, twice_area * twice_area);
      if (std::max({a, b, c}) > kMinSplitPixels * kMinSplitPixels) {
        const Eigen::Vector3d p = surface_->position(pa.x(), pa.y());
        const Eigen::Vector3d r = surface_->position(pb.x(), pb.y());
        const Eigen::Vector3d t = surface_->position(pc.x(), pc.y());
        const double a3 = (r - t).squaredNorm(), b3 = (t - p).squaredNorm(), c3 = (p - r).squaredNorm();
        if (std::isfinite(a3 + b3 + c3)) {
          q.size = std::max({a3, b3, c3}) / sq_max_edge_;
          q.sine_3d = squared_min_sine(a3, b3, c3, (r - p).cross(t - p).squaredNorm());
        }
      }
      return operator()(q);
    }

   private:
    // Squared sine of a triangle's smallest angle from its squared sides and (2 area)^2:
    // sin(smallest) = 2 area / (product of the two longer sides).
    static double squared_min_sine(double a, double b, double c, double twice_area_sq) {
      const double shortest = std::min({a, b, c});
      const double product = a * b * c / std::max(shortest, 1e-300);
      return product > 0 ? twice_area_sq / product : 0.0;
    }
    double b_, b_3d_, sq_max_edge_;
    const RangeSurface* surface_;
  };

  RangeMeshCriteria(const MeshingParams& params, const RangeSurface* surface)
      : b_(std::pow(std::sin(params.min_angle_deg * kPi / 180.0), 2)),
        b_3d_(std::pow(std::sin(params.min_angle_3d_deg * kPi / 180.0), 2)),
        sq_max_edge_(params.max_edge_length_m * params.max_edge_length_m),
        surface_(surface) {}
  Is_bad is_bad_object() const { return Is_bad(b_, b_3d_, sq_max_edge_, surface_); }

 private:
  double b_, b_3d_, sq_max_edge_;
  const RangeSurface* surface_;
};

void check_params(const RangeImage& image, const MeshingParams& params) {
  if (image.width <= 0 || image.height <= 0) {
    throw Error("mesh_range_image: the range image is empty (" + std::to_string(image.width) + " x " +
                std::to_string(image.height) + ")");
  }
  image.validate();
  if (!(params.depth_jump_ratio > 0) || !std::isfinite(params.depth_jump_ratio))
    throw Error("mesh_range_image: depth_jump_ratio " + num(params.depth_jump_ratio) + " is not positive and finite");
  if (!(params.min_angle_deg > 0) || params.min_angle_deg > kMaxMinAngleDeg)
    throw Error("mesh_range_image: min_angle_deg " + num(params.min_angle_deg) + " is outside (0, " +
                num(kMaxMinAngleDeg) + "]; larger bounds are not guaranteed to terminate");
  if (!(params.half_cell_max_inclination_deg >= 0) || params.half_cell_max_inclination_deg >= 90)
    throw Error("mesh_range_image: half_cell_max_inclination_deg " + num(params.half_cell_max_inclination_deg) +
                " is outside [0, 90)");
  if (!(params.min_angle_3d_deg >= 0) || params.min_angle_3d_deg >= 60)
    throw Error("mesh_range_image: min_angle_3d_deg " + num(params.min_angle_3d_deg) + " is outside [0, 60)");
  if (!(params.max_edge_length_m > 0))
    throw Error("mesh_range_image: max_edge_length_m " + num(params.max_edge_length_m) + " is not positive");
  if (!(params.thinning_noise_per_m2 >= 0) || !std::isfinite(params.thinning_noise_per_m2))
    throw Error("mesh_range_image: thinning_noise_per_m2 " + num(params.thinning_noise_per_m2) + " must be finite and >= 0");
  if (!(params.thinning_tolerance >= 0) || !std::isfinite(params.thinning_tolerance))
    throw Error("mesh_range_image: thinning_tolerance " + num(params.thinning_tolerance) +
                " is not a non-negative finite number");
  const Eigen::Vector3d& d = params.parallel_ray_direction_sensor;
  if (!d.allFinite() || d.norm() < 1e-9)
    throw Error("mesh_range_image: parallel_ray_direction_sensor (" + num(d.x()) + ", " + num(d.y()) + ", " +
                num(d.z()) + ") is not a finite non-zero vector");
  if (params.roi_pixels) {
    const auto& roi = *params.roi_pixels;
    if (roi.min().x() < 0 || roi.min().y() < 0 || roi.max().x() >= image.width || roi.max().y() >= image.height ||
        roi.min().x() > roi.max().x() || roi.min().y() > roi.max().y()) {
      throw Error("mesh_range_image: ROI x [" + std::to_string(roi.min().x()) + ", " + std::to_string(roi.max().x()) +
                  "] y [" + std::to_string(roi.min().y()) + ", " + std::to_string(roi.max().y()) +
                  "] is empty or not inside the " + std::to_string(image.width) + " x " +
                  std::to_string(image.height) + " range image");
    }
  }
}

// Smallest angle of a triangle [deg], in 2-D or 3-D: sin(smallest) = 2 area / (product of the
// two longer sides); the smallest angle is at most 60 degrees, so asin is unambiguous.
double twice_area(const Eigen::Vector2d& e, const Eigen::Vector2d& f) { return std::abs(e.x() * f.y() - e.y() * f.x()); }
double twice_area(const Eigen::Vector3d& e, const Eigen::Vector3d& f) { return e.cross(f).norm(); }

template <class Vec>
double min_angle_deg(const Vec& a, const Vec& b, const Vec& c) {
  const double ab = (b - a).squaredNorm(), bc = (c - b).squaredNorm(), ca = (a - c).squaredNorm();
  const double longer_product = std::sqrt(ab * bc * ca / std::max(std::min({ab, bc, ca}), 1e-300));
  if (!(longer_product > 0)) return 0.0;
  return std::asin(std::min(1.0, twice_area(Vec(b - a), Vec(c - a)) / longer_product)) * 180.0 / kPi;
}

// Data-dependent edge flips (Dyn, Levin & Rippa, "Data dependent triangulations for piecewise
// linear interpolation", IMA J. Numer. Anal. 1990) with the max-min angle criterion measured in
// 3-D: an interior edge is flipped when that raises the smaller 3-D angle of its two faces by more
// than kFlipGainDeg and both new faces keep at least min_angle_deg in the image plane. On a steep
// surface the image-plane Delaunay choice of a cell diagonal can run along the slope and make a
// sliver in 3-D; the flip takes the diagonal across the slope. The two faces' union is unchanged,
// so no flip can cover a hole or a jump. Each flip raises the sorted vector of face angles, so the
// loop ends.
constexpr double kFlipGainDeg = 0.5;

void flip_for_3d_shape(const std::vector<Eigen::Vector2d>& pixels, const std::vector<Eigen::Vector3f>& points,
                       double min_angle_image_deg, std::vector<Eigen::Vector3i>& faces) {
  auto key = [](int a, int b) { return a < b ? (uint64_t(a) << 32) | uint32_t(b) : (uint64_t(b) << 32) | uint32_t(a); };
  auto angle_3d = [&](const Eigen::Vector3i& f) {
    const Eigen::Vector3d a = points[f[0]].cast<double>(), b = points[f[1]].cast<double>(), c = points[f[2]].cast<double>();
    return min_angle_deg(a, b, c);
  };
  auto orient = [&](int a, int b, int c) {
    const Eigen::Vector2d e = pixels[b] - pixels[a], g = pixels[c] - pixels[a];
    return e.x() * g.y() - e.y() * g.x();
  };
  std::unordered_map<uint64_t, std::array<int, 2>> edge_faces;
  edge_faces.reserve(faces.size() * 2);
  for (int f = 0; f < static_cast<int>(faces.size()); ++f)
    for (int k = 0; k < 3; ++k) {
      auto [it, fresh] = edge_faces.try_emplace(key(faces[f][k], faces[f][(k + 1) % 3]), std::array<int, 2>{f, -1});
      if (!fresh) it->second[1] = f;
    }
  std::vector<uint64_t> queue;
  for (const auto& [e, fs] : edge_faces)
    if (fs[1] >= 0) queue.push_back(e);
  auto replace = [&](uint64_t e, int from, int to) {
    auto& fs = edge_faces[e];
    (fs[0] == from ? fs[0] : fs[1]) = to;
  };
  while (!queue.empty()) {
    const uint64_t e = queue.back();
    queue.pop_back();
    const auto it = edge_faces.find(e);
    if (it == edge_faces.end() || it->second[1] < 0) continue;
    const int f1 = it->second[0], f2 = it->second[1];
    const int u = static_cast<int>(e >> 32), v = static_cast<int>(e & 0xffffffffu);
    // Opposite vertices, and the faces written as (u, v, p) and (v, u, q), counter-clockwise.
    auto third = [&](int f) {
      for (int k = 0; k < 3; ++k)
        if (faces[f][k] != u && faces[f][k] != v) return faces[f][k];
      return -1;
    };
    int p = third(f1), q = third(f2);
    int a = u, b = v;
    if (orient(a, b, p) < 0) std::swap(a, b);  // now (a, b, p) and (b, a, q) are counter-clockwise
    if (orient(p, a, q) <= 0 || orient(q, b, p) <= 0) continue;  // quad not strictly convex
    const Eigen::Vector3i n1(p, a, q), n2(q, b, p);
    if (min_angle_deg(pixels[p], pixels[a], pixels[q]) < min_angle_image_deg ||
        min_angle_deg(pixels[q], pixels[b], pixels[p]) < min_angle_image_deg)
      continue;
    if (std::min(angle_3d(n1), angle_3d(n2)) <= std::min(angle_3d(faces[f1]), angle_3d(faces[f2])) + kFlipGainDeg)
      continue;
    // Flip: edge a-b becomes p-q. Face f1 takes (p, a, q), face f2 takes (q, b, p).
    edge_faces.erase(it);
    replace(key(a, q), f2, f1);
    replace(key(b, p), f1, f2);
    edge_faces[key(p, q)] = {f1, f2};
    faces[f1] = n1;
    faces[f2] = n2;
    for (uint64_t outer : {key(p, a), key(a, q), key(q, b), key(b, p)}) queue.push_back(outer);
  }
}

// Quadtree thinning (see the file comment): the pixels to keep. Blocks are aligned to multiples
// of their size; leaf_size holds, per cell, the size of the leaf that contains it.
std::vector<uint8_t> thin(const RangeSurface& surface, double tolerance, double noise_per_m2) {
  const int cw = surface.cells_x(), ch = surface.cells_y(), w = surface.width();
  // Integral image of full cells, to test "every cell of the block is full" in O(1).
  std::vector<int> full((cw + 1) * static_cast<size_t>(ch + 1), 0);
  auto at = [cw](int x, int y) { return static_cast<size_t>(y) * (cw + 1) + x; };
  for (int y = 0; y < ch; ++y)
    for (int x = 0; x < cw; ++x)
      full[at(x + 1, y + 1)] = full[at(x, y + 1)] + full[at(x + 1, y)] - full[at(x, y)] + (surface.piece(x, y) == kFull);
  // A block is aligned to a multiple of its size s; at the right and bottom image borders it is
  // clipped to the cells there are, and accepted only if at least half of it remains.
  struct Block {
    int x, y, s;
    int sx(int cells_x) const { return std::min(s, cells_x - x); }
    int sy(int cells_y) const { return std::min(s, cells_y - y); }
  };
  auto all_full = [&](const Block& b) {
    const int x1 = b.x + b.sx(cw), y1 = b.y + b.sy(ch);
    return full[at(x1, y1)] - full[at(b.x, y1)] - full[at(x1, b.y)] + full[at(b.x, b.y)] == b.sx(cw) * b.sy(ch);
  };
  auto children = [](const Block& b, std::vector<Block>& out) {
    const int h = b.s / 2;
    for (const auto& [dx, dy] : {std::pair{0, 0}, {h, 0}, {0, h}, {h, h}}) out.push_back({b.x + dx, b.y + dy, h});
  };

  std::vector<uint8_t> leaf_size(static_cast<size_t>(cw) * ch, 1);
  auto set_size = [&](const Block& b, int size) {
    for (int y = b.y; y < b.y + b.sy(ch); ++y)
      for (int x = b.x; x < b.x + b.sx(cw); ++x) leaf_size[surface.cell(x, y)] = static_cast<uint8_t>(size);
  };
  std::vector<Block> leaves;  // coarse leaves (size >= 2)
  std::vector<Block> stack;
  if (tolerance > 0) {
    for (int by = 0; by < ch; by += kMaxBlockCells)
      for (int bx = 0; bx < cw; bx += kMaxBlockCells) stack.push_back({bx, by, kMaxBlockCells});
  }
  while (!stack.empty()) {
    const Block b = stack.back();
    stack.pop_back();
    if (b.x >= cw || b.y >= ch) continue;
    if (2 * b.sx(cw) >= b.s && 2 * b.sy(ch) >= b.s && all_full(b) &&
        surface.planar(b.x, b.y, b.sx(cw), b.sy(ch), tolerance, noise_per_m2)) {
      leaves.push_back(b);
      set_size(b, b.s);
    } else if (b.s > 2) {
      children(b, stack);
    }
  }
  // 2:1 balance: split a leaf while a cell beside it belongs to a leaf less than half its size.
  for (bool changed = true; changed;) {
    changed = false;
    std::vector<Block> next;
    for (const Block& b : leaves) {
      const int sx = b.sx(cw), sy = b.sy(ch);
      int smallest = b.s;
      for (int i = 0; i < sx; ++i) {
        if (b.y > 0) smallest = std::min<int>(smallest, leaf_size[surface.cell(b.x + i, b.y - 1)]);
        if (b.y + sy < ch) smallest = std::min<int>(smallest, leaf_size[surface.cell(b.x + i, b.y + sy)]);
      }
      for (int i = 0; i < sy; ++i) {
        if (b.x > 0) smallest = std::min<int>(smallest, leaf_size[surface.cell(b.x - 1, b.y + i)]);
        if (b.x + sx < cw) smallest = std::min<int>(smallest, leaf_size[surface.cell(b.x + sx, b.y + i)]);
      }
      if (2 * smallest >= b.s) {
        next.push_back(b);
        continue;
      }
      changed = true;
      set_size(b, b.s / 2);
      if (b.s / 2 < 2) continue;
      std::vector<Block> parts;
      children(b, parts);
      for (const Block& c : parts)
        if (c.x < cw && c.y < ch) next.push_back(c);
    }
    leaves.swap(next);
  }

  std::vector<uint8_t> keep(static_cast<size_t>(w) * surface.height(), 0);
  for (const Block& b : leaves)
    for (int c = 0; c < 4; ++c) keep[static_cast<size_t>(b.y + kCorner[c][1] * b.sy(ch)) * w + b.x + kCorner[c][0] * b.sx(cw)] = 1;
  for (int y = 0; y < ch; ++y) {
    for (int x = 0; x < cw; ++x) {
      const uint8_t p = surface.piece(x, y);
      if (leaf_size[surface.cell(x, y)] > 1 || p == kNone) continue;
      for (int c = 0; c < 4; ++c)
        if (p == kFull || c != p - kTri) keep[surface.corner_pixel(x, y, c)] = 1;
    }
  }
  return keep;
}

}  // namespace

MeshingResult mesh_range_image(const RangeImage& image, const MeshingParams& params) {
  const auto start = std::chrono::steady_clock::now();
  check_params(image, params);
  const bool parallel =
      params.rays == MeshingParams::Rays::kParallel ||
      (params.rays == MeshingParams::Rays::kAuto && image.sensor.kind.rfind("cyberware", 0) == 0);
  const RangeSurface surface(image, params, parallel, params.parallel_ray_direction_sensor.normalized());
  if (surface.valid_count() == 0) {
    throw Error("mesh_range_image: the " + std::to_string(image.width) + " x " + std::to_string(image.height) +
                " range image has no valid pixels" + (params.roi_pixels ? " in the ROI" : ""));
  }
  MeshingResult result;
  result.valid_pixel_count = surface.valid_count();
  result.discontinuity_edge_count = surface.jump_count();
  const int w = image.width, cw = surface.cells_x(), ch = surface.cells_y();
  for (int y = 0; y < ch; ++y)
    for (int x = 0; x < cw; ++x) {
      bool all = true;
      for (int c = 0; c < 4; ++c) all = all && surface.valid(surface.corner_pixel(x, y, c));
      result.full_grid_face_count += all ? 2 : 0;
    }

  if (cw == 0 || ch == 0) {
    result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return result;
  }

  // Boundary of the domain: cell sides used by exactly one piece (flagged at their top or left
  // pixel), and triangle diagonals.
  const size_t n = image.pixel_count();
  std::vector<uint8_t> h_side(n, 0), v_side(n, 0), degree(n, 0);
  std::vector<std::pair<size_t, size_t>> diagonals;  // pixel index pairs
  auto mask = [&](int x, int y) { return (x >= 0 && y >= 0 && x < cw && y < ch) ? surface.side_mask(x, y) : 0; };
  for (int y = 0; y <= ch; ++y) {
    for (int x = 0; x <= cw; ++x) {
      const size_t i = image.index(x, y);
      // Horizontal side (x, y)-(x+1, y): bottom side (2) of the cell above, top side (0) of the cell below.
      if (x < cw && (((mask(x, y - 1) >> 2) ^ mask(x, y)) & 1)) {
        h_side[i] = 1;
        ++degree[i];
        ++degree[i + 1];
      }
      // Vertical side (x, y)-(x, y+1): right side (1) of the cell to the left, left side (3) of the cell.
      if (y < ch && (((mask(x - 1, y) >> 1) ^ (mask(x, y) >> 3)) & 1)) {
        v_side[i] = 1;
        ++degree[i];
        ++degree[i + w];
      }
      if (x < cw && y < ch && surface.piece(x, y) >= kTri) {
        const int k = surface.piece(x, y) - kTri;
        diagonals.emplace_back(surface.corner_pixel(x, y, (k + 3) % 4), surface.corner_pixel(x, y, (k + 1) % 4));
      }
    }
  }

  // Pixels to triangulate: the quadtree's choice and the boundary's. A boundary pixel inside a
  // straight run of sides is left out when the quadtree does not need it (it lies on the side of a
  // coarse, planar block): the run becomes one constraint, which the refinement splits as needed.
  std::vector<uint8_t> keep = thin(surface, params.thinning_tolerance, params.thinning_noise_per_m2);
  for (const auto& [a, b] : diagonals) degree[a] = degree[b] = 4;  // never inside a straight run
  auto inner = [&](size_t i, const std::vector<uint8_t>& side, size_t step) {
    return !keep[i] && degree[i] == 2 && side[i] && i >= step && side[i - step];
  };
  std::vector<std::pair<size_t, size_t>> segments;  // pixel index pairs
  for (const auto& [side, step] : {std::pair{&h_side, size_t{1}}, std::pair{&v_side, static_cast<size_t>(w)}}) {
    for (size_t i = 0; i < n; ++i) {
      if (!(*side)[i] || inner(i, *side, step)) continue;
      size_t j = i + step;
      while (inner(j, *side, step)) j += step;
      segments.emplace_back(i, j);
    }
  }
  for (const auto& [a, b] : segments) keep[a] = keep[b] = 1;
  for (const auto& [a, b] : diagonals) keep[a] = keep[b] = 1;
  std::vector<Point2> points;
  std::vector<int> point_of_pixel(image.pixel_count(), -1);
  for (size_t i = 0; i < keep.size(); ++i) {
    if (!keep[i]) continue;
    point_of_pixel[i] = static_cast<int>(points.size());
    points.emplace_back(static_cast<double>(i % w), static_cast<double>(i / w));
  }
  std::vector<std::pair<size_t, size_t>> constraints;
  constraints.reserve(segments.size());
  for (const auto& [a, b] : segments) constraints.emplace_back(point_of_pixel[a], point_of_pixel[b]);
  for (const auto& [a, b] : diagonals) constraints.emplace_back(point_of_pixel[a], point_of_pixel[b]);
  result.constraint_edge_count = constraints.size();
  if (points.size() < 3) {
    result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return result;
  }

  Cdt cdt;
  cdt.insert_constraints(points.begin(), points.end(), constraints.begin(), constraints.end());
  const size_t inserted = cdt.number_of_vertices();
  // Domain marking: every boundary segment is a constraint, so a face is wholly in or out, and
  // its centroid decides. Delaunay_mesher_2 keeps the marks (init(true)) as it refines.
  Sample sample;
  for (auto f = cdt.finite_faces_begin(); f != cdt.finite_faces_end(); ++f) {
    const Point2 c = CGAL::centroid(f->vertex(0)->point(), f->vertex(1)->point(), f->vertex(2)->point());
    f->set_in_domain(surface.locate(c.x(), c.y(), sample, 0.0));
  }
  CGAL::Delaunay_mesher_2<Cdt, RangeMeshCriteria> mesher(cdt, RangeMeshCriteria(params, &surface));
  mesher.init(true);
  mesher.refine_mesh();
  result.steiner_vertex_count = cdt.number_of_vertices() - inserted;

  // Output: in-domain faces, their vertices on the measured surface.
  TriangleMesh& mesh = result.mesh;
  for (auto v = cdt.finite_vertices_begin(); v != cdt.finite_vertices_end(); ++v) v->info() = -1;
  std::vector<Eigen::Vector2f> uv_pixels;
  for (auto f = cdt.finite_faces_begin(); f != cdt.finite_faces_end(); ++f) {
    if (!f->is_in_domain()) continue;
    Eigen::Vector3i face;
    for (int k = 0; k < 3; ++k) {
      auto v = f->vertex(k);
      if (v->info() < 0) {
        v->info() = static_cast<int>(mesh.vertices.size());
        const double x = v->point().x(), y = v->point().y();
        const bool found = surface.locate(x, y, sample) || surface.locate(x, y, sample, 1e-3);
        assert(found && "a vertex of an in-domain face lies outside the domain");
        Eigen::Vector3d p = Eigen::Vector3d::Zero();
        Eigen::Vector2d uv = Eigen::Vector2d::Zero();
        for (int j = 0; found && j < sample.n; ++j) {
          p += sample.weight[j] * surface.point(sample.pixel[j]).cast<double>();
          uv += sample.weight[j] * image.uv[sample.pixel[j]].cast<double>();
        }
        mesh.vertices.push_back(p.cast<float>());
        uv_pixels.push_back(uv.cast<float>());
        result.vertex_pixels.emplace_back(x, y);
      }
      face[k] = v->info();
    }
    mesh.faces.push_back(face);
  }

  flip_for_3d_shape(result.vertex_pixels, mesh.vertices, params.min_angle_deg, mesh.faces);

  // Orientation: the faces are counter-clockwise in the image plane, which maps to one side of
  // the surface for the whole image (the projection has one handedness); turn them so they are
  // counter-clockwise seen from the sensor (area-weighted vote against the viewing rays).
  double facing = 0;
  for (const auto& f : mesh.faces) {
    const Eigen::Vector3d a = mesh.vertices[f[0]].cast<double>(), b = mesh.vertices[f[1]].cast<double>(),
                          c = mesh.vertices[f[2]].cast<double>();
    facing -= (b - a).cross(c - a).dot(surface.ray((a + b + c) / 3));
  }
  if (facing < 0)
    for (auto& f : mesh.faces) std::swap(f[1], f[2]);
  mesh.compute_vertex_normals();

  // Texture coordinates: pixel centres (origin at the centre of the top-left pixel) to [0, 1]
  // with the origin at the texture's top-left corner.
  const bool textured = !image.images.empty() && !image.images[0].image.empty();
  const double tex_w = textured ? image.images[0].image.width : image.width;
  const double tex_h = textured ? image.images[0].image.height : image.height;
  mesh.uv.reserve(uv_pixels.size());
  for (const auto& t : uv_pixels)
    mesh.uv.emplace_back(static_cast<float>((t.x() + 0.5) / tex_w), static_cast<float>((t.y() + 0.5) / tex_h));
  if (textured) mesh.texture = image.images[0].image;

  // Figures.
  result.vertex_count = mesh.vertices.size();
  result.face_count = mesh.faces.size();
  result.resolution_m = mesh.median_edge_length();
  result.min_angle_image_deg = 180.0;
  for (const auto& f : mesh.faces) {
    const double angle = min_angle_deg(result.vertex_pixels[f[0]], result.vertex_pixels[f[1]], result.vertex_pixels[f[2]]);
    result.min_angle_image_deg = std::min(result.min_angle_image_deg, angle);
    result.faces_below_min_angle += angle < params.min_angle_deg - 1e-6;
  }
  if (mesh.faces.empty()) result.min_angle_image_deg = 0;
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

double mesh_resolution(const TriangleMesh& mesh) { return mesh.median_edge_length(); }

}  // namespace artisan
