// Recognition against ground truth: the bunny model (Stanford's reconstruction, in the bun000
// frame) found in each of the ten real bunny scans at the pose bun.conf gives; not found in a
// simulated scan of a pipework cell that holds no bunny; compressed and full search agree.
#include <gtest/gtest.h>

#include <numbers>

#include "artisan/core/error.hpp"
#include "artisan/core/io/ply.hpp"
#include "artisan/core/io/stanford_conf.hpp"
#include "artisan/perception/meshing.hpp"
#include "artisan/perception/recognition.hpp"
#include "artisan/sim/simulator.hpp"
#include "artisan/sim/workcell.hpp"
#include "test_support.hpp"

namespace artisan {
namespace {

SpinImageLibrary& bunny_library() {
  static SpinImageLibrary library = [] {
    SpinImageLibrary lib;
    const auto path = test::bunny_dir() / "reconstruction" / "bun_zipper.ply";
    lib.add_model("bunny", io::ply_to_mesh(io::read_ply(path), path));
    return lib;
  }();
  return library;
}

TriangleMesh scan_mesh(const std::string& name) {
  const auto path = test::bunny_dir() / (name + ".ply");
  return mesh_range_image(io::ply_to_range_image(io::read_ply(path), path)).mesh;
}

TEST(Recognition, TheBunnyIsFoundInEveryRealScanAtItsTruePose) {
  const auto conf = io::read_stanford_conf(test::bunny_dir() / "bun.conf");
  int found = 0;
  for (const auto& name : test::bunny_scans()) {
    const auto result = recognize(scan_mesh(name), bunny_library());
    ASSERT_FALSE(result.instances.empty()) << name << ": not found";
    // The model frame is the bun000 frame, whose pose in bun.conf is the identity.
    const Transform truth = conf.scan(name + ".ply").T_world_scan.inverse();
    const auto& best = result.instances.front();
    const Transform d = truth.inverse() * best.T_scene_model;
    const double deg = rotation_angle(d) * 180 / std::numbers::pi, mm = d.translation().norm() * 1e3;
    EXPECT_LT(deg, 3.0) << name;
    EXPECT_LT(mm, 3.0) << name;
    EXPECT_EQ(result.instances.size(), 1u) << name << ": a second, false instance";
    found += deg < 3 && mm < 3;
    std::printf("%-9s %.2f deg %.2f mm overlap %.2f rmse %.2f mm  (%.2f + %.2f + %.2f s)\n", name.c_str(), deg, mm, best.overlap_fraction,
                best.rmse_m * 1e3, result.seconds_spin_images, result.seconds_search, result.seconds_verify);
  }
  std::printf("found %d of 10 within 3 deg and 3 mm; library: %d eigen-spin-images of %zu bins\n", found, bunny_library().components(),
              bunny_library().bins());
}

TEST(Recognition, NoBunnyInAScanOfSomethingElse) {
  // Method: a simulated Vivid scan of the sample pipework cell (pipes, fittings, a valve, a
  // table) contains no bunny; recognition must report nothing.
  sim::Simulator simulator(sim::load_workcell(test::data_dir() / "workcells" / "pipework.json"));
  sim::ScanRequest request;
  request.sensor = "vivid";
  const auto acquisition = simulator.scan(request);
  const auto scene = mesh_range_image(acquisition.range).mesh;
  const auto result = recognize(scene, bunny_library());
  EXPECT_TRUE(result.instances.empty()) << result.instances.size() << " false instances, first overlap "
                                        << result.instances.front().overlap_fraction;
}

TEST(Recognition, CompressedSearchAgreesWithTheFullSearch) {
  auto& library = bunny_library();
  library.compress();
  EXPECT_LT(library.components(), static_cast<int>(library.bins()) / 2);  // PCA compresses
  const auto scene = scan_mesh("bun045");
  RecognitionParams full;
  full.compressed_search = false;
  const auto a = recognize(scene, library);
  const auto b = recognize(scene, library, full);
  ASSERT_FALSE(a.instances.empty());
  ASSERT_FALSE(b.instances.empty());
  const Transform d = a.instances[0].T_scene_model.inverse() * b.instances[0].T_scene_model;
  EXPECT_LT(rotation_angle(d) * 180 / std::numbers::pi, 1.0);
  EXPECT_LT(d.translation().norm(), 0.001);
}

TEST(Recognition, BadInputThrows) {
  SpinImageLibrary empty;
  EXPECT_THROW(recognize(scan_mesh("bun000"), empty), Error);
  EXPECT_THROW(recognize(TriangleMesh{}, bunny_library()), Error);
  SpinImageLibrary lib;
  lib.add_model("bunny", scan_mesh("bun000"));
  EXPECT_THROW(lib.add_model("bunny", scan_mesh("bun000")), Error);  // duplicate name
}

}  // namespace
}  // namespace artisan
