// Range image -> mesh (perception/meshing): the ten real Stanford bunny scans, synthetic range
// images of analytic surfaces, bad input, and isotropic remeshing.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <string>
#include <unordered_map>
#include <vector>

#include "artisan/core/error.hpp"
#include "artisan/core/io/ply.hpp"
#include "artisan/perception/meshing.hpp"
#include "perception/mesh_metrics.hpp"
#include "perception/synthetic_range.hpp"
#include "test_support.hpp"

namespace artisan {
namespace {

using test::min_triangle_angle_deg;

// ---- helpers ----

struct Meshed {
  RangeImage image;
  MeshingResult result;
};

// Each bunny scan is read and meshed once (default parameters) and shared by the tests.
const Meshed& bunny(const std::string& scan) {
  static std::map<std::string, Meshed> cache;
  auto it = cache.find(scan);
  if (it == cache.end()) {
    const auto path = test::bunny_dir() / (scan + ".ply");
    Meshed m;
    m.image = io::ply_to_range_image(io::read_ply(path), path);
    m.result = mesh_range_image(m.image);
    it = cache.emplace(scan, std::move(m)).first;
  }
  return it->second;
}

// The discontinuity rule of MeshingParams::depth_jump_ratio, written out again for checking.
bool is_depth_jump(const Eigen::Vector3d& p, const Eigen::Vector3d& q, const Eigen::Vector3d& ray, double k) {
  const Eigen::Vector3d d = q - p;
  const double along = d.dot(ray);
  return std::abs(along) > k * (d - along * ray).norm();
}

// Calls f(x, y) for every pixel centre inside the closed image-plane triangle abc.
template <class F>
void for_each_pixel_in(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c, F f) {
  const double area = (b - a).x() * (c - a).y() - (b - a).y() * (c - a).x();
  const int x0 = static_cast<int>(std::ceil(std::min({a.x(), b.x(), c.x()}) - 1e-9));
  const int x1 = static_cast<int>(std::floor(std::max({a.x(), b.x(), c.x()}) + 1e-9));
  const int y0 = static_cast<int>(std::ceil(std::min({a.y(), b.y(), c.y()}) - 1e-9));
  const int y1 = static_cast<int>(std::floor(std::max({a.y(), b.y(), c.y()}) + 1e-9));
  auto edge = [](const Eigen::Vector2d& p, const Eigen::Vector2d& q, const Eigen::Vector2d& r) {
    return (q - p).x() * (r - p).y() - (q - p).y() * (r - p).x();
  };
  const double eps = 1e-9 * std::abs(area);
  for (int y = y0; y <= y1; ++y)
    for (int x = x0; x <= x1; ++x) {
      const Eigen::Vector2d p(x, y);
      const double wa = edge(b, c, p) / area, wb = edge(c, a, p) / area, wc = edge(a, b, p) / area;
      if (wa >= -eps && wb >= -eps && wc >= -eps) f(x, y);
    }
}

// Pixel pairs (4-neighbours, both inside one closed face) that are depth jumps, and invalid
// pixels inside a face.
struct Bridges {
  size_t jumps = 0;
  size_t invalid = 0;
};

Bridges find_bridges(const RangeImage& image, const MeshingResult& r, double k, bool parallel_minus_z) {
  Bridges b;
  std::vector<int> stamp(image.pixel_count(), -1);
  for (int f = 0; f < static_cast<int>(r.mesh.faces.size()); ++f) {
    const auto& face = r.mesh.faces[f];
    std::vector<size_t> inside;
    for_each_pixel_in(r.vertex_pixels[face[0]], r.vertex_pixels[face[1]], r.vertex_pixels[face[2]], [&](int x, int y) {
      const size_t i = image.index(x, y);
      stamp[i] = f;
      inside.push_back(i);
    });
    for (size_t i : inside) {
      if (!image.valid[i]) {
        ++b.invalid;
        continue;
      }
      for (size_t j : {i + 1, i + static_cast<size_t>(image.width)}) {
        if (j >= image.pixel_count() || stamp[j] != f || (j == i + 1 && j % image.width == 0) || !image.valid[j]) continue;
        const Eigen::Vector3d p = image.points_sensor[i].cast<double>(), q = image.points_sensor[j].cast<double>();
        const Eigen::Vector3d ray = parallel_minus_z ? Eigen::Vector3d(0, 0, -1) : Eigen::Vector3d((p + q).normalized());
        b.jumps += is_depth_jump(p, q, ray, k);
      }
    }
  }
  return b;
}

// Share of the image's valid points within `radius` of the mesh (point-to-triangle distance).
double coverage(const RangeImage& image, const TriangleMesh& mesh, double radius) {
  const test::TriangleDistance distance(mesh.vertices, mesh.faces, radius);
  size_t covered = 0, valid = 0;
  for (size_t i = 0; i < image.pixel_count(); ++i) {
    if (!image.valid[i]) continue;
    ++valid;
    covered += distance.distance(image.points_sensor[i].cast<double>()) <= radius;
  }
  return static_cast<double>(covered) / static_cast<double>(valid);
}

// Faces of the full-resolution grid mesh: 2 per 2x2 block of valid pixels.
size_t full_grid_faces(const RangeImage& image) {
  size_t n = 0;
  for (int y = 0; y + 1 < image.height; ++y)
    for (int x = 0; x + 1 < image.width; ++x)
      n += 2 * (image.valid[image.index(x, y)] && image.valid[image.index(x + 1, y)] &&
                image.valid[image.index(x, y + 1)] && image.valid[image.index(x + 1, y + 1)]);
  return n;
}

double image_angle(const MeshingResult& r, const Eigen::Vector3i& f) {
  return min_triangle_angle_deg(r.vertex_pixels[f[0]], r.vertex_pixels[f[1]], r.vertex_pixels[f[2]]);
}

double angle_3d(const TriangleMesh& m, const Eigen::Vector3i& f) {
  const Eigen::Vector3d a = m.vertices[f[0]].cast<double>(), b = m.vertices[f[1]].cast<double>(),
                        c = m.vertices[f[2]].cast<double>();
  return min_triangle_angle_deg(a, b, c);
}

// Boundary loops: directed boundary edges (edges of one face) must pair up at every vertex
// (as many leaving as arriving); returns the number of connected loops, or -1 when unbalanced.
int boundary_loops(const TriangleMesh& m, std::vector<std::vector<int>>* loops_vertices = nullptr) {
  std::map<std::pair<int, int>, int> directed;
  for (const auto& f : m.faces)
    for (int k = 0; k < 3; ++k) ++directed[{f[k], f[(k + 1) % 3]}];
  std::vector<int> out(m.vertices.size(), 0), in(m.vertices.size(), 0);
  std::vector<std::pair<int, int>> boundary;
  for (const auto& [e, n] : directed)
    if (!directed.count({e.second, e.first})) {
      ++out[e.first];
      ++in[e.second];
      boundary.push_back(e);
    }
  for (size_t v = 0; v < out.size(); ++v)
    if (out[v] != in[v]) return -1;
  std::vector<int> parent(m.vertices.size());
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int v) {
    while (parent[v] != v) v = parent[v] = parent[parent[v]];
    return v;
  };
  for (const auto& [a, b] : boundary) parent[find(a)] = find(b);
  std::map<int, std::vector<int>> groups;
  for (const auto& [a, b] : boundary) groups[find(a)].push_back(a);
  if (loops_vertices)
    for (auto& [root, vs] : groups) loops_vertices->push_back(vs);
  return static_cast<int>(groups.size());
}

// ---- the ten real bunny scans (Cyberware, parallel rays along -z) ----

class BunnyMeshing : public ::testing::TestWithParam<std::string> {};

// Method: recompute every face's smallest angle from the image-plane vertex positions; faces
// under the bound must be exactly those the result reports as forced, and a tiny share.
TEST_P(BunnyMeshing, ImagePlaneAnglesMeetTheBound) {
  const auto& [image, r] = bunny(GetParam());
  const MeshingParams params;
  ASSERT_GT(r.face_count, 1000u);
  size_t below = 0;
  double smallest = 180;
  for (const auto& f : r.mesh.faces) {
    const double a = image_angle(r, f);
    smallest = std::min(smallest, a);
    below += a < params.min_angle_deg - 1e-6;
  }
  EXPECT_EQ(below, r.faces_below_min_angle);
  EXPECT_LE(static_cast<double>(below), 0.001 * r.face_count) << "forced faces under the bound";
  EXPECT_NEAR(smallest, r.min_angle_image_deg, 1e-9);
  RecordProperty("min_angle_image_deg", std::to_string(smallest));
}

// Method: rasterise every face in the image plane; no two 4-neighbour pixels inside one face may
// be a depth jump by the rule (re-implemented here), and no invalid pixel may lie inside a face.
TEST_P(BunnyMeshing, NoFaceSpansADepthJumpOrAHole) {
  const auto& [image, r] = bunny(GetParam());
  const auto bridges = find_bridges(image, r, MeshingParams{}.depth_jump_ratio, true);
  EXPECT_EQ(bridges.jumps, 0u);
  EXPECT_EQ(bridges.invalid, 0u);
  EXPECT_GT(r.discontinuity_edge_count, 0u);  // the scans do have jumps to avoid
}

// Method: exact point-to-triangle distance from every valid measured point to the mesh.
TEST_P(BunnyMeshing, CoversTheMeasuredPointsWithinHalfAMillimetre) {
  const auto& [image, r] = bunny(GetParam());
  const double share = coverage(image, r.mesh, 0.0005);
  EXPECT_GE(share, 0.98);
  RecordProperty("coverage_0_5mm", std::to_string(share));
}

// Method: pixel vertices must carry their measured point exactly; every vertex (pixel or
// refinement vertex) must lie within one depth quantisation step of these scans (0.127 mm) of
// the full-resolution surface of the measured points (all triangles of three valid corners of
// each 2x2 block).
TEST_P(BunnyMeshing, VerticesLieOnTheMeasuredSurface) {
  const auto& [image, r] = bunny(GetParam());
  std::vector<Eigen::Vector3i> reference;
  for (int y = 0; y + 1 < image.height; ++y)
    for (int x = 0; x + 1 < image.width; ++x) {
      const int c[4] = {static_cast<int>(image.index(x, y)), static_cast<int>(image.index(x + 1, y)),
                        static_cast<int>(image.index(x + 1, y + 1)), static_cast<int>(image.index(x, y + 1))};
      for (int skip = 0; skip < 4; ++skip) {
        Eigen::Vector3i t;
        int n = 0;
        for (int k = 0; k < 4; ++k)
          if (k != skip) t[n++] = c[k];
        if (image.valid[t[0]] && image.valid[t[1]] && image.valid[t[2]]) reference.push_back(t);
      }
    }
  const test::TriangleDistance surface(image.points_sensor, reference, 0.001);
  double worst = 0;
  for (size_t v = 0; v < r.mesh.vertices.size(); ++v) {
    const auto& px = r.vertex_pixels[v];
    if (px.x() == std::floor(px.x()) && px.y() == std::floor(px.y())) {
      const size_t i = image.index(static_cast<int>(px.x()), static_cast<int>(px.y()));
      ASSERT_TRUE(image.valid[i]);
      ASSERT_EQ(r.mesh.vertices[v], image.points_sensor[i]);
    }
    worst = std::max(worst, surface.distance(r.mesh.vertices[v].cast<double>()));
  }
  EXPECT_LE(worst, 0.000127);
  RecordProperty("worst_vertex_distance_mm", std::to_string(worst * 1e3));
}

// Method: count the faces of the full-resolution grid mesh independently (2 per 2x2 block of
// valid pixels) and compare.
TEST_P(BunnyMeshing, ThinsToAtMostAThirdOfTheFullGrid) {
  const auto& [image, r] = bunny(GetParam());
  const size_t full = full_grid_faces(image);
  EXPECT_EQ(full, r.full_grid_face_count);
  EXPECT_LE(3 * r.face_count, full) << r.face_count << " faces against " << full;
}

// Method: smallest 3-D angle of every face.
TEST_P(BunnyMeshing, FewerThanOnePercentSliversIn3D) {
  const auto& [image, r] = bunny(GetParam());
  size_t slivers = 0;
  for (const auto& f : r.mesh.faces) slivers += angle_3d(r.mesh, f) < 10.0;
  EXPECT_LT(static_cast<double>(slivers), 0.01 * r.face_count) << slivers << " of " << r.face_count;
}

// Method: the Cyberware looks along -z, so "toward the sensor" is +z: face normals (from the
// counter-clockwise order) and vertex normals must point there, up to grazing noise.
TEST_P(BunnyMeshing, FacesAndNormalsFaceTheSensor) {
  const auto& [image, r] = bunny(GetParam());
  const auto& m = r.mesh;
  ASSERT_EQ(m.normals.size(), m.vertices.size());
  size_t away_faces = 0, away_normals = 0;
  for (const auto& f : m.faces)
    away_faces += (m.vertices[f[1]] - m.vertices[f[0]]).cross(m.vertices[f[2]] - m.vertices[f[0]]).z() <= 0;
  for (const auto& n : m.normals) away_normals += n.z() <= 0;
  EXPECT_LT(static_cast<double>(away_faces), 0.001 * m.faces.size());
  EXPECT_LT(static_cast<double>(away_normals), 0.001 * m.normals.size());
  EXPECT_NO_THROW(m.validate());
}

INSTANTIATE_TEST_SUITE_P(TenScans, BunnyMeshing, ::testing::ValuesIn(test::bunny_scans()),
                         [](const auto& scan) { return scan.param; });

// ---- synthetic range images of analytic surfaces (pinhole, rays from the origin) ----

// Method: a tilted plane at 1.5 m fills a 640 x 480 image. Every vertex must satisfy the plane
// equation, the faces must tile the whole image rectangle (image-plane areas sum to 639 x 479),
// honour the 0.1 m edge bound, and be very few.
TEST(SyntheticMeshing, PlaneGivesFewFacesAtExactDepth) {
  test::AnalyticScene scene;
  const Eigen::Vector3d normal = Eigen::Vector3d(0.2, -0.1, -1).normalized();
  scene.planes.push_back({normal, -1.5, nullptr});
  const auto image = test::render_range_image(test::vga_camera(), scene);
  ASSERT_EQ(image.valid_count(), image.pixel_count());
  const auto r = mesh_range_image(image);
  double area = 0, longest = 0;
  for (const auto& f : r.mesh.faces) {
    const Eigen::Vector2d e = r.vertex_pixels[f[1]] - r.vertex_pixels[f[0]], g = r.vertex_pixels[f[2]] - r.vertex_pixels[f[0]];
    area += 0.5 * std::abs(e.x() * g.y() - e.y() * g.x());
    for (int k = 0; k < 3; ++k) longest = std::max<double>(longest, (r.mesh.vertices[f[k]] - r.mesh.vertices[f[(k + 1) % 3]]).norm());
  }
  EXPECT_NEAR(area, 639.0 * 479.0, 1e-6);
  for (const auto& v : r.mesh.vertices) EXPECT_NEAR(normal.dot(v.cast<double>()), -1.5, 2e-6);
  EXPECT_LE(longest, 0.1 + 1e-6);
  EXPECT_LT(r.face_count, full_grid_faces(image) / 200) << r.face_count << " faces";
  EXPECT_EQ(r.discontinuity_edge_count, 0u);
  for (const auto& n : r.mesh.normals) EXPECT_GT(n.cast<double>().dot(normal), 0.9999);  // toward the sensor (origin)
  // Without the edge bound the plane is a handful of quadtree blocks.
  MeshingParams coarse;
  coarse.max_edge_length_m = 10.0;
  EXPECT_LT(mesh_range_image(image, coarse).face_count, 300u);
}

// Method: a sphere of radius 0.3 m at 1.2 m on an empty background. Every vertex must lie on the
// sphere (pixel vertices are exact; interpolated ones sit on chords of a pixel), vertex normals
// must match the sphere's outward normal (which faces the sensor), and every measured point where
// the sphere faces the camera within 70 degrees (the jump rule cuts the rim beyond 76 degrees) must
// lie within twice the thinning tolerance times the sample spacing at its range (z / f) of the mesh.
TEST(SyntheticMeshing, SphereVerticesLieOnTheSphere) {
  const test::AnalyticSphere sphere{Eigen::Vector3d(0.05, -0.03, 1.2), 0.3};
  test::AnalyticScene scene;
  scene.spheres.push_back(sphere);
  const auto camera = test::vga_camera();
  const auto image = test::render_range_image(camera, scene);
  const MeshingParams params;
  const auto r = mesh_range_image(image, params);
  ASSERT_GT(r.face_count, 100u);
  size_t bad_normals = 0;
  for (size_t v = 0; v < r.mesh.vertices.size(); ++v) {
    const Eigen::Vector3d p = r.mesh.vertices[v].cast<double>();
    EXPECT_NEAR((p - sphere.centre).norm(), sphere.radius, 5e-5);
    const Eigen::Vector3d outward = (p - sphere.centre).normalized();
    bad_normals += r.mesh.normals[v].cast<double>().dot(outward) < std::cos(5.0 * M_PI / 180);
  }
  EXPECT_LT(static_cast<double>(bad_normals), 0.01 * r.mesh.vertices.size());
  const test::TriangleDistance distance(r.mesh.vertices, r.mesh.faces, 0.01);
  size_t checked = 0, beyond = 0;
  for (size_t i = 0; i < image.pixel_count(); ++i) {
    if (!image.valid[i]) continue;
    const Eigen::Vector3d p = image.points_sensor[i].cast<double>();
    if (std::abs((p - sphere.centre).normalized().dot(p.normalized())) < std::cos(70.0 * M_PI / 180)) continue;
    ++checked;
    beyond += distance.distance(p) > 2 * params.thinning_tolerance * p.z() / camera.fx;
  }
  EXPECT_GT(checked, image.valid_count() * 8 / 10);
  EXPECT_EQ(beyond, 0u) << "of " << checked;
  EXPECT_LE(3 * r.face_count, full_grid_faces(image));
}

// Method: a wall at z = 1 m on the left of x = 0 and one at z = 1.3 m on the right: every face must
// have all its vertices on one of the two planes, both planes must be meshed, and rasterised faces
// must not contain a jump.
TEST(SyntheticMeshing, StepHasNoFaceAcrossTheJump) {
  test::AnalyticScene scene;
  scene.planes.push_back({Eigen::Vector3d(0, 0, 1), 1.0, [](const Eigen::Vector3d& p) { return p.x() < 0; }});
  scene.planes.push_back({Eigen::Vector3d(0, 0, 1), 1.3, [](const Eigen::Vector3d& p) { return p.x() >= 0; }});
  const auto image = test::render_range_image(test::vga_camera(), scene);
  ASSERT_EQ(image.valid_count(), image.pixel_count());
  const auto r = mesh_range_image(image);
  size_t near_faces = 0, far_faces = 0;
  for (const auto& f : r.mesh.faces) {
    int near = 0, far = 0;
    for (int k = 0; k < 3; ++k) {
      const float z = r.mesh.vertices[f[k]].z();
      near += std::abs(z - 1.0f) < 1e-5f;
      far += std::abs(z - 1.3f) < 1e-5f;
    }
    ASSERT_TRUE(near == 3 || far == 3) << "a face bridges the step";
    near_faces += near == 3;
    far_faces += far == 3;
  }
  EXPECT_GT(near_faces, 0u);
  EXPECT_GT(far_faces, 0u);
  EXPECT_EQ(r.discontinuity_edge_count, static_cast<size_t>(image.height));  // one jump per row
  EXPECT_EQ(find_bridges(image, r, MeshingParams{}.depth_jump_ratio, false).jumps, 0u);
}

// Method: a plane with a rectangular and a round hole of invalid pixels. No invalid pixel may lie
// inside a face, the mesh boundary must consist of closed loops (every vertex has as many boundary
// edges leaving as arriving), exactly three of them (image border and the two holes), and each
// hole's loop must run within 1.5 pixels of the hole's rim.
TEST(SyntheticMeshing, HolesAreNotCoveredAndHaveClosedBoundaries) {
  test::AnalyticScene scene;
  scene.planes.push_back({Eigen::Vector3d(0.1, 0.1, -1).normalized(), -2.0, nullptr});
  auto in_rect = [](int x, int y) { return x >= 100 && x <= 180 && y >= 200 && y <= 260; };
  auto in_disc = [](int x, int y) { return (x - 420) * (x - 420) + (y - 150) * (y - 150) <= 45 * 45; };
  const auto image = test::render_range_image(test::vga_camera(), scene, [&](int x, int y) { return in_rect(x, y) || in_disc(x, y); });
  const auto r = mesh_range_image(image);
  EXPECT_EQ(find_bridges(image, r, MeshingParams{}.depth_jump_ratio, false).invalid, 0u);
  std::vector<std::vector<int>> loops;
  ASSERT_EQ(boundary_loops(r.mesh, &loops), 3);
  int rect_loops = 0, disc_loops = 0;
  for (const auto& loop : loops) {
    bool rect = true, disc = true;
    for (int v : loop) {
      const Eigen::Vector2d p = r.vertex_pixels[v];
      const double dx = std::max({100 - p.x(), p.x() - 180, 0.0}), dy = std::max({200 - p.y(), p.y() - 260, 0.0});
      rect = rect && std::hypot(dx, dy) <= 1.5 && !(p.x() > 100 && p.x() < 180 && p.y() > 200 && p.y() < 260);
      disc = disc && std::abs(std::hypot(p.x() - 420, p.y() - 150) - 45.5) <= 1.5;
    }
    rect_loops += rect;
    disc_loops += disc;
  }
  EXPECT_EQ(rect_loops, 1);
  EXPECT_EQ(disc_loops, 1);
}

// Method: with an ROI every vertex lies inside it; uv follow the range image's uv, normalised by
// the camera image's size (pixel centres), and the camera image becomes the texture.
TEST(SyntheticMeshing, RoiAndTextureCoordinates) {
  test::AnalyticScene scene;
  scene.planes.push_back({Eigen::Vector3d(0, 0, -1), -1.0, nullptr});
  auto image = test::render_range_image(test::vga_camera(), scene);
  MeshingParams params;
  params.roi_pixels = Eigen::AlignedBox2i(Eigen::Vector2i(100, 50), Eigen::Vector2i(300, 200));
  auto r = mesh_range_image(image, params);
  ASSERT_GT(r.face_count, 0u);
  for (const auto& p : r.vertex_pixels) {
    EXPECT_GE(p.x(), 100);
    EXPECT_LE(p.x(), 300);
    EXPECT_GE(p.y(), 50);
    EXPECT_LE(p.y(), 200);
  }
  EXPECT_EQ(r.valid_pixel_count, 201u * 151u);
  // No camera image: normalised by the range image size.
  for (size_t v = 0; v < r.vertex_pixels.size(); ++v)
    EXPECT_TRUE(r.mesh.uv[v].isApprox(((r.vertex_pixels[v].array() + 0.5) / Eigen::Array2d(640, 480)).matrix().cast<float>(), 1e-5f));
  EXPECT_TRUE(r.mesh.texture.empty());
  // A 1280 x 960 camera image seeing pixel (x, y) at (2x + 10, 2y + 20).
  CameraImage colour;
  colour.name = "color";
  colour.image.width = 1280;
  colour.image.height = 960;
  colour.image.pixels.assign(1280 * 960 * 3, 7);
  image.images.push_back(colour);
  for (int y = 0; y < image.height; ++y)
    for (int x = 0; x < image.width; ++x) image.uv[image.index(x, y)] = Eigen::Vector2f(2 * x + 10, 2 * y + 20);
  r = mesh_range_image(image, params);
  for (size_t v = 0; v < r.vertex_pixels.size(); ++v) {
    const Eigen::Vector2d expected((2 * r.vertex_pixels[v].x() + 10.5) / 1280, (2 * r.vertex_pixels[v].y() + 20.5) / 960);
    EXPECT_TRUE(r.mesh.uv[v].isApprox(expected.cast<float>(), 1e-5f));
  }
  EXPECT_TRUE(r.mesh.texture == colour.image);
}

// ---- bad input ----

void expect_error_naming(const std::function<void()>& f, const std::string& needle) {
  try {
    f();
    ADD_FAILURE() << "no artisan::Error; expected one naming \"" << needle << "\"";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
  }
}

// Method: each defect on its own must throw artisan::Error whose message names the value.
TEST(MeshingBadInput, ThrowsNamingTheValue) {
  expect_error_naming([] { mesh_range_image(RangeImage{}); }, "0 x 0");
  const auto empty = RangeImage::empty_of_size(8, 6);
  expect_error_naming([&] { mesh_range_image(empty); }, "no valid pixels");
  auto image = RangeImage::empty_of_size(8, 6);
  for (size_t i = 0; i < image.pixel_count(); ++i) {
    image.points_sensor[i] = Eigen::Vector3f(0.01f * (i % 8), 0.01f * (i / 8), 1.0f);
    image.valid[i] = 1;
  }
  EXPECT_NO_THROW(mesh_range_image(image));
  auto with = [&](auto set) {
    return [&image, set] {
      MeshingParams p;
      set(p);
      mesh_range_image(image, p);
    };
  };
  expect_error_naming(with([](MeshingParams& p) { p.depth_jump_ratio = -2; }), "depth_jump_ratio -2");
  expect_error_naming(with([](MeshingParams& p) { p.depth_jump_ratio = NAN; }), "depth_jump_ratio nan");
  expect_error_naming(with([](MeshingParams& p) { p.min_angle_deg = 25; }), "min_angle_deg 25");
  expect_error_naming(with([](MeshingParams& p) { p.min_angle_3d_deg = 70; }), "min_angle_3d_deg 70");
  expect_error_naming(with([](MeshingParams& p) { p.max_edge_length_m = 0; }), "max_edge_length_m 0");
  expect_error_naming(with([](MeshingParams& p) { p.thinning_tolerance = -1; }), "thinning_tolerance -1");
  expect_error_naming(with([](MeshingParams& p) { p.half_cell_max_inclination_deg = 90; }), "half_cell_max_inclination_deg 90");
  expect_error_naming(with([](MeshingParams& p) { p.parallel_ray_direction_sensor.setZero(); }), "parallel_ray_direction_sensor (0, 0, 0)");
  expect_error_naming(with([](MeshingParams& p) { p.roi_pixels = Eigen::AlignedBox2i(Eigen::Vector2i(2, 1), Eigen::Vector2i(8, 3)); }),
                      "ROI x [2, 8] y [1, 3]");
  expect_error_naming(with([](MeshingParams& p) { p.roi_pixels = Eigen::AlignedBox2i(Eigen::Vector2i(-1, 0), Eigen::Vector2i(3, 3)); }),
                      "ROI x [-1, 3]");
  auto hidden = image;
  std::fill(hidden.valid.begin(), hidden.valid.begin() + 16, 0);  // rows 0 and 1
  expect_error_naming([&] {
    MeshingParams p;
    p.roi_pixels = Eigen::AlignedBox2i(Eigen::Vector2i(0, 0), Eigen::Vector2i(7, 1));
    mesh_range_image(hidden, p);
  }, "no valid pixels in the ROI");
}

// ---- remeshing ----

// Method: remesh the bun000 mesh to 2 mm edges. The median edge must be within 20% of the target;
// interior vertices must lie on the input surface (within 0.05 mm); border vertices may cut the
// input's pixel staircase, so within half the target; the area may shrink by that corner cutting
// only, under 3%; normals keep facing the sensor (+z).
TEST(Remeshing, BunnyToTwoMillimetreEdges) {
  const auto& input = bunny("bun000").result.mesh;
  const double target = 0.002;
  const auto output = remesh_to_resolution(input, target);
  EXPECT_NO_THROW(output.validate());
  ASSERT_EQ(output.normals.size(), output.vertices.size());
  EXPECT_NEAR(mesh_resolution(output), target, 0.2 * target);
  std::map<std::pair<int, int>, int> edges;
  for (const auto& f : output.faces)
    for (int k = 0; k < 3; ++k) ++edges[std::minmax(f[k], f[(k + 1) % 3])];
  std::vector<uint8_t> border(output.vertices.size(), 0);
  for (const auto& [e, count] : edges)
    if (count == 1) border[e.first] = border[e.second] = 1;
  const test::TriangleDistance surface(input.vertices, input.faces, target);
  double worst_interior = 0, worst_border = 0;
  for (size_t v = 0; v < output.vertices.size(); ++v) {
    const double d = surface.distance(output.vertices[v].cast<double>());
    (border[v] ? worst_border : worst_interior) = std::max(border[v] ? worst_border : worst_interior, d);
  }
  EXPECT_LE(worst_interior, 0.00005);
  EXPECT_LE(worst_border, 0.5 * target);
  auto area = [](const TriangleMesh& m) {
    double a = 0;
    for (const auto& f : m.faces) a += 0.5 * (m.vertices[f[1]] - m.vertices[f[0]]).cross(m.vertices[f[2]] - m.vertices[f[0]]).norm();
    return a;
  };
  EXPECT_GT(area(output) / area(input), 0.97);
  EXPECT_LE(area(output) / area(input), 1.0);
  size_t toward = 0;
  for (const auto& n : output.normals) toward += n.z() > 0;
  EXPECT_GT(static_cast<double>(toward), 0.99 * output.normals.size());
}

// Method: a non-positive target and an empty mesh throw naming the value; a flat unit square
// remeshed to 0.1 m stays flat and gets refined.
TEST(Remeshing, BadInputThrowsAndAFlatSquareStaysFlat) {
  TriangleMesh square;
  square.vertices = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  square.faces = {{0, 1, 2}, {0, 2, 3}};
  expect_error_naming([&] { remesh_to_resolution(square, 0); }, "target edge length 0");
  expect_error_naming([&] { remesh_to_resolution(square, -1); }, "target edge length -1");
  expect_error_naming([&] { remesh_to_resolution(TriangleMesh{}, 0.1); }, "no faces");
  const auto flat = remesh_to_resolution(square, 0.1);
  for (const auto& v : flat.vertices) EXPECT_NEAR(v.z(), 0.0f, 1e-6f);
  EXPECT_GT(flat.faces.size(), 100u);
}

}  // namespace
}  // namespace artisan
