// The .conf convention p_world = R(q)^T p_scan + t, checked on the real bunny scans.
#include <gtest/gtest.h>

#include <fstream>

#include "artisan/core/error.hpp"
#include "artisan/core/io/ply.hpp"
#include "artisan/core/io/stanford_conf.hpp"
#include "test_support.hpp"

namespace artisan::io {
namespace {

std::vector<Eigen::Vector3f> scan_in_world(const StanfordConf& conf, const std::string& name) {
  const auto path = test::bunny_dir() / (name + ".ply");
  const auto image = ply_to_range_image(read_ply(path), path);
  const Eigen::Isometry3f T_world_scan = conf.scan(name + ".ply").T_world_scan.cast<float>();
  std::vector<Eigen::Vector3f> points_world;
  for (size_t i = 0; i < image.pixel_count(); ++i)
    if (image.valid[i]) points_world.push_back(T_world_scan * image.points_sensor[i]);
  return points_world;
}

// Median distance from each point of `a` to its nearest point of `b`, over the points of `a`
// that have a neighbour within 5 mm (the overlap).
double median_overlap_distance(const std::vector<Eigen::Vector3f>& a, const std::vector<Eigen::Vector3f>& b,
                               double* overlap_fraction) {
  test::NearestNeighbours nn(b, 0.005f);
  std::vector<double> d;
  for (const auto& p : a) {
    const float x = nn.distance(p);
    if (std::isfinite(x)) d.push_back(x);
  }
  *overlap_fraction = static_cast<double>(d.size()) / a.size();
  return d.empty() ? INFINITY : test::median(d);
}

TEST(StanfordConf, ReadsAllTenScansAndTheCamera) {
  const auto conf = read_stanford_conf(test::bunny_dir() / "bun.conf");
  EXPECT_EQ(conf.scans.size(), 10u);
  EXPECT_TRUE(conf.T_world_camera.has_value());
  EXPECT_TRUE(conf.scan("bun000.ply").T_world_scan.isApprox(Transform::Identity()));
  EXPECT_THROW(conf.scan("nope.ply"), Error);
}

TEST(StanfordConf, WithTheConjugateConventionNeighbouringScansOverlap) {
  // Method: bun000 and bun045 see much of the same surface; at their ground-truth poses the
  // overlapping points lie within the scanner noise of each other (median < 1 mm).
  const auto conf = read_stanford_conf(test::bunny_dir() / "bun.conf");
  const auto a = scan_in_world(conf, "bun000");
  const auto b = scan_in_world(conf, "bun045");
  double overlap = 0;
  const double d = median_overlap_distance(b, a, &overlap);
  EXPECT_LT(d, 0.001);
  EXPECT_GT(overlap, 0.3);

  // The opposite convention (R(q) instead of R(q)^T) must not fit: the test can fail.
  auto wrong = conf;
  for (auto& s : wrong.scans) s.T_world_scan.linear() = s.T_world_scan.linear().transpose().eval();
  double wrong_overlap = 0;
  const double wrong_d = median_overlap_distance(scan_in_world(wrong, "bun045"), a, &wrong_overlap);
  EXPECT_TRUE(wrong_d > 0.002 || wrong_overlap < 0.1) << wrong_d << " " << wrong_overlap;
}

TEST(StanfordConf, EveryScanLandsOnTheReconstruction) {
  const auto conf = read_stanford_conf(test::bunny_dir() / "bun.conf");
  const auto ref = ply_to_mesh(read_ply(test::bunny_dir() / "reconstruction" / "bun_zipper.ply"), "zipper");
  for (const auto& name : test::bunny_scans()) {
    double overlap = 0;
    // Vertex-to-vertex against a ~1.5 mm-resolution reference: the median stays near 0.5 mm.
    const double d = median_overlap_distance(scan_in_world(conf, name), ref.vertices, &overlap);
    EXPECT_LT(d, 0.001) << name;
    EXPECT_GT(overlap, 0.95) << name;
  }
}

TEST(StanfordConf, MalformedLinesThrowWithLineNumbers) {
  test::TempDir dir;
  for (const auto& [text, fragment] : std::vector<std::pair<std::string, std::string>>{
           {"bmesh a.ply 0 0 0 0 0 0\n", "line 1"},
           {"camera 0 0 0 0 0 0 1\nbmesh a.ply 0 0 0 0 0 0 5\n", "line 2"},
           {"mesh a.ply 0 0 0 0 0 0 1\n", "unknown keyword"},
           {"", "no bmesh"}}) {
    std::ofstream(dir / "x.conf") << text;
    try {
      read_stanford_conf(dir / "x.conf");
      ADD_FAILURE() << text;
    } catch (const FileError& e) {
      EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace artisan::io
