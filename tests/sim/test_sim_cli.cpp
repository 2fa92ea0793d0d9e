// artisan sim scan / render / sensors end to end, through the real executable.
#include <gtest/gtest.h>

#include <fstream>

#include <nlohmann/json.hpp>

#include "artisan/core/io/range_image_format.hpp"
#include "artisan/sim/acquisition.hpp"
#include "test_support.hpp"

namespace artisan::sim {
namespace {

const std::string kCli = ARTISAN_CLI;
const std::string kCell = (artisan::test::data_dir() / "workcells" / "pipework.json").string();

// Method: list the sample's sensors as JSON; scan with the Vivid and check every file is there,
// the range image reads back in the internal format with 200 x 200 pixels and a 400 x 400
// colour image, and truth.json's instance ids agree with instances.png; the same seed gives
// identical range files.
TEST(SimCli, SensorsAndScan) {
  artisan::test::TempDir dir;
  const auto s = artisan::test::run_command(kCli + " --json sim sensors " + kCell);
  ASSERT_EQ(s.exit_code, 0) << s.err;
  const auto j = nlohmann::json::parse(s.out);
  ASSERT_EQ(j["sensors"].size(), 3u);
  EXPECT_EQ(j["sensors"][0]["kind"], "minolta-vivid-700");
  EXPECT_EQ(j["sensors"][1]["pan_tilt"]["tilt"]["upper_rad"], 0.52);

  for (const char* out : {"a", "b"}) {
    const auto r = artisan::test::run_command(kCli + " sim scan " + kCell + " --sensor vivid --seed 4 --out " + (dir / out).string());
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  for (const char* f : {"range.ari", "range.png", "color.png", "instances.png", "depth_truth.png", "truth.ari", "truth.json"})
    EXPECT_TRUE(std::filesystem::exists(dir / "a" / f)) << f;
  const auto range = io::read_range_image(dir / "a" / "range.ari");
  EXPECT_EQ(range.width, 200);
  ASSERT_EQ(range.images.size(), 1u);
  EXPECT_EQ(range.images[0].image.width, 400);
  EXPECT_GT(range.valid_count(), 5000u);
  EXPECT_TRUE(range == io::read_range_image(dir / "b" / "range.ari"));
  int w = 0, h = 0;
  const auto ids = read_png16(dir / "a" / "instances.png", w, h);
  std::ifstream in(dir / "a" / "truth.json");
  const auto truth = nlohmann::json::parse(in);
  // Visible: the instance's pixels that the scanner can measure (in range, lit by its laser) -
  // at most those the camera shows, at least those with a measurement (dropouts aside).
  ASSERT_EQ(ids.size(), range.pixel_count());
  for (const auto& o : truth["objects"]) {
    const int id = o["instance_id"];
    int measured = 0;
    for (size_t i = 0; i < ids.size(); ++i) measured += ids[i] == id && range.valid[i];
    EXPECT_LE(o["visible_pixels"].get<int>(), std::count(ids.begin(), ids.end(), id)) << o["name"];
    EXPECT_GE(o["visible_pixels"].get<int>(), measured) << o["name"];
  }
}

// Method: bad input exits with 1 and a message naming the problem; pan/tilt on the Pioneer
// works, beyond the limits it is refused; render writes a PNG.
TEST(SimCli, ErrorsAndRender) {
  artisan::test::TempDir dir;
  auto r = artisan::test::run_command(kCli + " sim scan " + kCell + " --sensor kinect --out " + (dir / "x").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("kinect"), std::string::npos);
  r = artisan::test::run_command(kCli + " sim scan " + kCell + " --sensor pioneer --pan 2.9 --out " + (dir / "x").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("2.775"), std::string::npos) << r.err;
  r = artisan::test::run_command(kCli + " sim scan " + kCell + " --sensor pioneer --pan 0.6 --tilt -0.3 --out " + (dir / "p").string());
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(std::filesystem::exists(dir / "p" / "top.png"));
  r = artisan::test::run_command(kCli + " sim render " + kCell + " --look-at 0.3 -3 2.6 0 0.8 0.9 --width 320 --height 240 --out " +
                                 (dir / "x.png").string());
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(std::filesystem::exists(dir / "x.png"));
  r = artisan::test::run_command(kCli + " sim sensors " + (dir / "missing.json").string());
  EXPECT_EQ(r.exit_code, 1);
}

}  // namespace
}  // namespace artisan::sim

namespace artisan::sim {
namespace {

TEST(SimCli, ScanWithDbImportsTheAcquisitionAsAnImage) {
  // Method: a Vivid scan with --db lands in the workspace as an image whose range data is the
  // file written beside it, bit for bit, with the environmental readings and the sensor pose.
  artisan::test::TempDir dir;
  const std::string db = " --db " + (dir / "ws.db").string();
  ASSERT_EQ(artisan::test::run_command(kCli + db + " init").exit_code, 0);
  ASSERT_EQ(artisan::test::run_command(kCli + db + " mkdir /cell").exit_code, 0);
  auto r = artisan::test::run_command(kCli + db + " --json sim scan " + kCell + " --sensor vivid --seed 3 --folder /cell --name view1 --out " +
                                      (dir / "view1").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("\"path\": \"/cell/view1\""), std::string::npos) << r.out;
  r = artisan::test::run_command(kCli + db + " export /cell/view1 --out " + (dir / "back.ari").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(artisan::io::read_range_image(dir / "back.ari") == artisan::io::read_range_image(dir / "view1" / "range.ari"));
  r = artisan::test::run_command(kCli + db + " --json show /cell/view1");
  EXPECT_NE(r.out.find("dose_rate_uSv_per_h"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("T_world_sensor"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("\"operation\": \"sim-scan\""), std::string::npos) << r.out;
  // A missing folder is refused before scanning, and nothing is written.
  r = artisan::test::run_command(kCli + db + " sim scan " + kCell + " --sensor vivid --folder /nowhere --out " + (dir / "view2").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_FALSE(std::filesystem::exists(dir / "view2"));
}

}  // namespace
}  // namespace artisan::sim
