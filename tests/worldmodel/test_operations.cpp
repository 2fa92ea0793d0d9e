// Operations with recorded parameters: defaults written out, overrides checked, reprocessing
// makes a new version beside the old, on a real scan.
#include <gtest/gtest.h>

#include "artisan/core/error.hpp"
#include "artisan/core/io/ply.hpp"
#include "artisan/worldmodel/operations.hpp"
#include "test_support.hpp"

namespace artisan::worldmodel {
namespace {

using nlohmann::json;

TEST(Operations, DefaultsAreCompleteAndOverridesAreChecked) {
  const auto defaults = default_parameters("mesh");
  EXPECT_EQ(defaults["min_angle_deg"], 20.7);
  EXPECT_TRUE(defaults.contains("roi_pixels"));
  const auto p = apply_overrides(defaults, {{"min_angle_deg", 15}, {"roi_pixels", {0, 0, 9, 9}}}, "mesh");
  EXPECT_EQ(p["min_angle_deg"], 15);
  EXPECT_EQ(p["thinning_tolerance"], defaults["thinning_tolerance"]);  // untouched
  EXPECT_THROW(apply_overrides(defaults, {{"min_angel_deg", 15}}, "mesh"), Error);       // typo
  EXPECT_THROW(apply_overrides(defaults, {{"min_angle_deg", "steep"}}, "mesh"), Error);  // wrong type
  EXPECT_THROW(default_parameters("frobnicate"), Error);
}

TEST(Operations, SettingsParseAsJsonOrString) {
  const auto s = parse_settings({"a=25", "b=true", "c=parallel", "d=[1,2]", "e=null"});
  EXPECT_EQ(s["a"], 25);
  EXPECT_EQ(s["b"], true);
  EXPECT_EQ(s["c"], "parallel");
  EXPECT_EQ(s["d"], json::array({1, 2}));
  EXPECT_TRUE(s["e"].is_null());
  EXPECT_THROW(parse_settings({"novalue"}), Error);
  EXPECT_THROW(parse_settings({"=5"}), Error);
}

TEST(Operations, MeshThenReprocessKeepsBothVersionsWithTheirParameters) {
  test::TempDir dir;
  auto ws = Workspace::create(dir / "ws.db");
  const auto folder = ws.mkdir("/bunny");
  const auto path = test::bunny_dir() / "bun045.ply";
  const auto image = ws.add(folder, make_image_object("bun045", io::ply_to_range_image(io::read_ply(path), path), {"import", {}, {}}));
  const auto v1 = run_operation(ws, "mesh", {image}, json::object(), folder, "bun045-mesh");
  const auto v2 = reprocess(ws, v1, {{"thinning_tolerance", 0.0}});
  EXPECT_EQ(ws.get(v2).version, 2);
  EXPECT_EQ(ws.get(v2).path, "/bunny/bun045-mesh");
  EXPECT_EQ(ws.provenance(v1)->parameters["thinning_tolerance"], default_parameters("mesh")["thinning_tolerance"]);
  EXPECT_EQ(ws.provenance(v2)->parameters["thinning_tolerance"], 0.0);
  EXPECT_EQ(ws.provenance(v2)->inputs, std::vector<ObjectId>{image});
  // No thinning keeps every pixel: more triangles than the thinned first version.
  EXPECT_GT(ws.load_mesh(v2).faces.size(), ws.load_mesh(v1).faces.size());
  EXPECT_THROW(reprocess(ws, image, json::object()), Error);  // an import is not reprocessable
  EXPECT_THROW(reprocess(ws, v1, {{"no_such", 1}}), Error);
  EXPECT_EQ(ws.versions(v1).size(), 2u);
  EXPECT_TRUE(ws.check().problems.empty());
}

}  // namespace
}  // namespace artisan::worldmodel
