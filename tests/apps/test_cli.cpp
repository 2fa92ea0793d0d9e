// End-to-end tests of the artisan command line: output, exit codes, bad input.
#include <gtest/gtest.h>

#include "test_support.hpp"

namespace artisan {
namespace {

using test::run_command;

const std::string kCli = ARTISAN_CLI;

std::string quoted(const std::filesystem::path& p) { return "'" + p.string() + "'"; }

TEST(Cli, InfoDescribesEveryBunnyScan) {
  std::string files;
  for (const auto& name : test::bunny_scans()) files += " " + quoted(test::bunny_dir() / (name + ".ply"));
  const auto r = run_command(kCli + " info" + files);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("bun000.ply: range image (PLY"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("512 x 400 pixels, 40256 valid"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("36023 valid"), std::string::npos) << r.out;  // top3
}

TEST(Cli, InfoJsonIsMachineReadable) {
  const auto r = run_command(kCli + " --json info " + quoted(test::bunny_dir() / "reconstruction" / "bun_zipper.ply"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out.front(), '{');
  EXPECT_NE(r.out.find("\"faces\": 69451"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("\"kind\": \"mesh\""), std::string::npos) << r.out;
  EXPECT_TRUE(r.err.empty()) << r.err;
}

TEST(Cli, ConvertRangeImageToEveryImageFormatKeepsItsPixels) {
  test::TempDir dir;
  for (const std::string ext : {".ari", ".pcd", ".ply"}) {
    const auto out = dir / ("scan" + ext);
    auto r = run_command(kCli + " convert " + quoted(test::bunny_dir() / "bun090.ply") + " " + quoted(out));
    ASSERT_EQ(r.exit_code, 0) << r.err;
    r = run_command(kCli + " info " + quoted(out));
    EXPECT_NE(r.out.find("512 x 400 pixels, 30379 valid"), std::string::npos) << ext << ": " << r.out;
  }
}

TEST(Cli, BadInputExitsOneAndLeavesNothingBehind) {
  test::TempDir dir;
  auto r = run_command(kCli + " info " + quoted(dir / "missing.ply"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("missing.ply: no such file"), std::string::npos) << r.err;

  r = run_command(kCli + " convert " + quoted(test::bunny_dir() / "bun000.ply") + " " + quoted(dir / "scan.obj"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("cannot write a range image as OBJ"), std::string::npos) << r.err;
  r = run_command(kCli + " convert " + quoted(test::bunny_dir() / "bun000.ply") + " " + quoted(dir / "scan.xyz"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find(".xyz"), std::string::npos) << r.err;
  EXPECT_TRUE(std::filesystem::is_empty(dir.path()));
}

TEST(Cli, UsageErrorsExitTwoAndHelpExitsZero) {
  EXPECT_EQ(run_command(kCli).exit_code, 2);
  EXPECT_EQ(run_command(kCli + " frobnicate").exit_code, 2);
  EXPECT_EQ(run_command(kCli + " convert onlyone.ply").exit_code, 2);
  const auto help = run_command(kCli + " info --help");
  EXPECT_EQ(help.exit_code, 0);
  EXPECT_NE(help.out.find("Describe"), std::string::npos);
  EXPECT_EQ(run_command(kCli + " --help").exit_code, 0);
}

}  // namespace
}  // namespace artisan
