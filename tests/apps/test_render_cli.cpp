// `artisan render`: pictures of a folder's world model, a mesh and a recognized model; bad
// targets and outputs refused.
#include <gtest/gtest.h>

#include <fstream>

#include "worldmodel/world_fixture.hpp"

namespace artisan {
namespace {

// The share of pixels that are not the white background, from the PNG via the renderer's own
// writer's counterpart: we only check the signature and that the file is not trivially small.
bool looks_like_png(const std::filesystem::path& p) {
  std::ifstream in(p, std::ios::binary);
  char sig[8] = {};
  in.read(sig, 8);
  return in && std::string(sig + 1, 3) == "PNG" && std::filesystem::file_size(p) > 5000;
}

TEST(RenderCli, DrawsWorldModelsMeshesAndRecognizedModels) {
  test::TempDir dir;
  test::WorldFixture f;
  {
    auto ws = worldmodel::Workspace::create(dir / "ws.db");
    f = test::make_world_fixture(ws);
  }
  const std::string cli = std::string(ARTISAN_CLI) + " --db " + (dir / "ws.db").string() + " render ";
  for (const std::string target : {"/cell", "/cell/merged", "/cell/bunny-in-merged-1", "/bunny"}) {
    const auto out = dir / "picture.png";
    std::filesystem::remove(out);
    const auto r = test::run_command(cli + target + " --out " + out.string() + " --width 320 --height 240");
    ASSERT_EQ(r.exit_code, 0) << target << ": " << r.err;
    EXPECT_TRUE(looks_like_png(out)) << target;
  }
  auto r = test::run_command(cli + "/cell --out " + (dir / "x.jpg").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find(".png"), std::string::npos) << r.err;
  r = test::run_command(cli + "/nowhere --out " + (dir / "x.png").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_FALSE(std::filesystem::exists(dir / "x.png"));
}

}  // namespace
}  // namespace artisan
