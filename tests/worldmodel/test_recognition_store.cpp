// Recognition over the workspace: a model keeps its spin-image stack from import, recognition
// uses it and stores each instance with its pose (checked against bun.conf) and provenance.
#include <gtest/gtest.h>

#include <numbers>

#include "artisan/core/error.hpp"
#include "artisan/core/io/ply.hpp"
#include "artisan/core/io/stanford_conf.hpp"
#include "artisan/worldmodel/operations.hpp"
#include "artisan/worldmodel/recognition_store.hpp"
#include "test_support.hpp"

namespace artisan::worldmodel {
namespace {

TEST(RecognitionStore, StoredSpinImagesAreUsedAndInstancesStoredWithTheirPose) {
  test::TempDir dir;
  auto ws = Workspace::create(dir / "ws.db");
  const auto folder = ws.mkdir("/b");
  const auto zipper = test::bunny_dir() / "reconstruction" / "bun_zipper.ply";
  const auto model = ws.add(ws.root(), make_model_object("bunny", io::ply_to_mesh(io::read_ply(zipper), zipper), {"import", {}, {}}));
  bool has_stack = false;
  for (const auto& b : ws.blobs(model)) has_stack |= b.role == "spin_images";
  EXPECT_TRUE(has_stack);
  EXPECT_GT(ws.get(model).metadata["spin_images"]["points"].get<int>(), 1000);

  const auto scan = test::bunny_dir() / "chin.ply";
  const auto image = ws.add(folder, make_image_object("chin", io::ply_to_range_image(io::read_ply(scan), scan), {"import", {}, {}}));
  const auto mesh = run_operation(ws, "mesh", {image}, nlohmann::json::object(), folder, "chin-mesh");
  const auto found = recognize_models(ws, mesh, {});  // every model: the bunny
  ASSERT_EQ(found.size(), 1u);
  const Transform truth = io::read_stanford_conf(test::bunny_dir() / "bun.conf").scan("chin.ply").T_world_scan.inverse();
  const Transform d = truth.inverse() * found[0].T_scene_model;
  EXPECT_LT(rotation_angle(d) * 180 / std::numbers::pi, 3.0);
  EXPECT_LT(d.translation().norm(), 0.003);
  const auto stored = ws.get(found[0].id);
  EXPECT_EQ(stored.kind, ObjectKind::kRecognizedModel);
  EXPECT_EQ(ws.provenance(found[0].id)->inputs, (std::vector<ObjectId>{mesh, model}));
  // The model cannot be removed while an instance refers to it.
  EXPECT_THROW(ws.remove(model, false), Error);
  // Again: a new version of the same instance, not a second object.
  const auto again = recognize_models(ws, mesh, {model});
  ASSERT_EQ(again.size(), 1u);
  EXPECT_EQ(ws.get(again[0].id).version, 2);
  EXPECT_THROW(recognize_models(ws, image, {}), Error);  // an image is not a mesh
  EXPECT_TRUE(ws.check().problems.empty());
}

}  // namespace
}  // namespace artisan::worldmodel
