// World model over the workspace: the scene (environment with recognized objects cut out,
// objects with poses and grasps), its collision scene, and operator edits stored as versions.
#include <gtest/gtest.h>

#include "artisan/core/error.hpp"
#include "artisan/worldmodel/world_model.hpp"
#include "world_fixture.hpp"

namespace artisan::worldmodel {
namespace {

QueryShape ball(const Eigen::Vector3d& c, double r) {
  QueryShape s;
  s.name = "ball";
  s.kind = QueryShape::Kind::sphere;
  s.radius_m = r;
  s.T_world_shape = Transform(Eigen::Translation3d(c));
  return s;
}

class WorldModelTest : public ::testing::Test {
 protected:
  test::TempDir dir;
  Workspace ws = Workspace::create(dir / "ws.db");
  test::WorldFixture f = test::make_world_fixture(ws);
  Eigen::Vector3d bunny_centre() const { return f.T_world_bunny * f.bunny_mesh.bounds().center().cast<double>(); }
};

TEST_F(WorldModelTest, SceneHasTheEnvironmentCutAndTheObjectWithItsGrasps) {
  WorldModel wm(ws, "/cell");
  ASSERT_EQ(wm.objects().size(), 2u);
  const auto& env = wm.objects()[0];
  EXPECT_EQ(env.kind, SceneObject::Kind::environment);
  EXPECT_EQ(env.object_id, f.environment);
  // The bunny's surface is cut out of the environment; the floor away from it stays.
  EXPECT_LT(env.mesh->faces.size(), f.floor_triangles + 50);
  EXPECT_GT(env.mesh->faces.size(), f.floor_triangles - 400);
  const auto* bunny = wm.find(f.bunny);
  ASSERT_NE(bunny, nullptr);
  EXPECT_EQ(bunny->model, "bunny");
  EXPECT_TRUE(bunny->T_world_object.isApprox(f.T_world_bunny, 1e-9));
  ASSERT_EQ(bunny->T_world_grasps.size(), 1u);
  EXPECT_TRUE(bunny->T_world_grasps[0].isApprox(f.T_world_bunny * f.T_model_grasp, 1e-9));
  EXPECT_EQ(bunny->mesh_hash.size(), 16u);
  EXPECT_NE(bunny->mesh_hash, env.mesh_hash);
  EXPECT_FALSE(wm.encoded_mesh(bunny->mesh_hash).empty());
  EXPECT_THROW(wm.encoded_mesh("0000000000000000"), Error);
  // Collision: a ball inside the bunny hits the bunny (not the floor), one above it nothing.
  const auto hit = wm.collision().check({ball(bunny_centre(), 0.02)});
  ASSERT_TRUE(hit.in_collision);
  EXPECT_EQ(hit.contacts[0].body, f.bunny);
  EXPECT_FALSE(wm.collision().check({ball({-0.3, 0.3, 0.1}, 0.05)}).in_collision);
  EXPECT_TRUE(wm.collision().check({ball({-0.3, 0.3, 0.02}, 0.05)}).in_collision);
  // Nothing changed: refreshing changes nothing.
  const auto revision = wm.revision();
  EXPECT_TRUE(wm.refresh().empty());
  EXPECT_EQ(wm.revision(), revision);
}

TEST_F(WorldModelTest, EditsAreStoredAsVersionsAndUpdateTheScene) {
  WorldModel wm(ws, "/cell");
  const auto r0 = wm.revision();
  const Transform moved = Transform(Eigen::Translation3d(-0.3, 0.2, 0)) * f.T_world_bunny;
  const ObjectId v2 = wm.correct_pose(f.bunny, moved, "alice");
  EXPECT_GT(wm.revision(), r0);
  const auto info = ws.get(v2);
  EXPECT_EQ(info.version, 2);
  EXPECT_EQ(info.metadata["edit"]["author"], "alice");
  EXPECT_EQ(info.metadata["status"], "corrected");
  EXPECT_EQ(ws.provenance(v2)->inputs, std::vector<ObjectId>{f.bunny});
  const auto* bunny = wm.find(f.bunny);  // the same object, by its first version's ID
  ASSERT_NE(bunny, nullptr);
  EXPECT_EQ(bunny->version, 2);
  EXPECT_TRUE(bunny->T_world_object.isApprox(moved, 1e-9));
  EXPECT_TRUE(bunny->T_world_grasps[0].isApprox(moved * f.T_model_grasp, 1e-9));
  // The collision body moved with it.
  const Eigen::Vector3d new_centre = moved * f.bunny_mesh.bounds().center().cast<double>();
  EXPECT_TRUE(wm.collision().check({ball(new_centre, 0.02)}).in_collision);
  // The scanned surface at the old place is no longer cut out: there the ball meets the
  // environment (the sensor did see something there).
  const auto old_place = wm.collision().check({ball(bunny_centre(), 0.03)});
  ASSERT_TRUE(old_place.in_collision);
  for (const auto& c : old_place.contacts) EXPECT_EQ(c.body, f.environment);

  wm.accept_pose(f.bunny, "alice");
  EXPECT_EQ(wm.find(f.bunny)->status, "accepted");

  // Attached: listed, but no longer a static obstacle.
  wm.attach(f.bunny, "ur5/tool0", Transform::Identity(), "bob");
  EXPECT_EQ(wm.find(f.bunny)->attached_to, "ur5/tool0");
  EXPECT_FALSE(wm.collision().contains(f.bunny));
  wm.detach(f.bunny, "bob");
  EXPECT_TRUE(wm.collision().contains(f.bunny));
  EXPECT_THROW(wm.detach(f.bunny, "bob"), Error);

  // Added by hand, by model name.
  const ObjectId added = wm.add_object("bunny", Transform(Eigen::Translation3d(0.3, 0.3, 0.0)), "carol");
  EXPECT_NE(wm.find(added), nullptr);
  EXPECT_EQ(wm.find(added)->status, "added");
  EXPECT_EQ(wm.objects().size(), 3u);

  // Deleted: gone from the scene, kept in the workspace as a version; the environment no longer
  // has the floor under the bunny cut out, so it regains those triangles.
  const size_t env_before = wm.objects()[0].mesh->faces.size();
  wm.remove_object(f.bunny, "dave");
  EXPECT_EQ(wm.find(f.bunny), nullptr);
  EXPECT_FALSE(wm.collision().contains(f.bunny));
  EXPECT_GT(wm.objects()[0].mesh->faces.size(), env_before + 20);
  EXPECT_EQ(ws.versions(f.bunny).size(), 6u);

  // Restart: the same scene from the workspace.
  WorldModel again(ws, "/cell");
  ASSERT_EQ(again.objects().size(), wm.objects().size());
  for (size_t i = 0; i < wm.objects().size(); ++i) {
    EXPECT_EQ(again.objects()[i].object_id, wm.objects()[i].object_id);
    EXPECT_EQ(again.objects()[i].mesh_hash, wm.objects()[i].mesh_hash);
    EXPECT_TRUE(again.objects()[i].T_world_object.isApprox(wm.objects()[i].T_world_object, 1e-12));
  }
  EXPECT_GE(again.revision(), wm.revision());
  EXPECT_TRUE(ws.check().problems.empty());
}

// Method: the same edit with the environment re-cut in the background ends in the same scene as
// the synchronous one (same environment hash), in two steps: the object at once, the environment
// as a change of its own with a higher revision.
TEST_F(WorldModelTest, EnvironmentIsRecutInTheBackgroundAfterAnEdit) {
  WorldModelOptions options;
  options.environment_in_background = true;
  WorldModel wm(ws, "/cell", options);
  const std::string env_before = wm.objects()[0].mesh_hash;
  const Transform moved = Transform(Eigen::Translation3d(-0.3, 0.2, 0)) * f.T_world_bunny;
  wm.correct_pose(f.bunny, moved, "alice");
  // At once: the object moved (scene and collision), the environment not yet.
  EXPECT_EQ(wm.last_changes().changed, std::vector<ObjectId>{f.bunny});
  EXPECT_TRUE(wm.find(f.bunny)->T_world_object.isApprox(moved, 1e-9));
  EXPECT_TRUE(wm.collision().check({ball(moved * f.bunny_mesh.bounds().center().cast<double>(), 0.02)}).in_collision);
  EXPECT_EQ(wm.objects()[0].mesh_hash, env_before);
  const auto r1 = wm.revision();
  // The first poll starts the worker, a later one installs its cut.
  SceneChanges env_changes;
  for (int i = 0; i < 3 && env_changes.empty(); ++i) env_changes = wm.poll_environment(true);
  EXPECT_EQ(env_changes.changed, std::vector<ObjectId>{f.environment});
  EXPECT_FALSE(wm.environment_pending());
  EXPECT_NE(wm.objects()[0].mesh_hash, env_before);
  EXPECT_GT(wm.revision(), r1);
  EXPECT_NO_THROW(wm.encoded_mesh(wm.objects()[0].mesh_hash));
  EXPECT_THROW(wm.encoded_mesh(env_before), Error);  // no longer used
  // The old place is no longer cut out: the ball meets the environment there.
  const auto old_place = wm.collision().check({ball(bunny_centre(), 0.03)});
  ASSERT_TRUE(old_place.in_collision);
  for (const auto& c : old_place.contacts) EXPECT_EQ(c.body, f.environment);
  // The same environment as a synchronous world model makes from the workspace.
  WorldModel sync(ws, "/cell");
  EXPECT_EQ(sync.objects()[0].mesh_hash, wm.objects()[0].mesh_hash);
  EXPECT_GE(sync.revision(), wm.revision());
  // Nothing more to do.
  EXPECT_TRUE(wm.poll_environment().empty());
  EXPECT_TRUE(wm.refresh().empty());
}

TEST_F(WorldModelTest, ChangesFromOtherProcessesAreSeenByRefresh) {
  WorldModel wm(ws, "/cell");
  // Someone else (e.g. `artisan recognize`) adds an instance.
  NewObject r;
  r.kind = ObjectKind::kRecognizedModel;
  r.subkind = "bunny";
  r.name = "bunny-in-merged-2";
  r.metadata = {{"model_id", f.model}, {"T_scene_model", to_row_major(Transform(Eigen::Translation3d(-0.2, -0.2, 0)) * f.T_world_bunny)}};
  r.provenance = Provenance{"recognize", {}, {f.environment, f.model}};
  const ObjectId second = ws.add(ws.folder("/cell").id, r);
  const auto changes = wm.refresh();
  // The new object, and the environment (more of it is cut out now).
  EXPECT_EQ(changes.changed.size(), 2u);
  EXPECT_NE(wm.find(second), nullptr);
  EXPECT_TRUE(changes.removed.empty());
}

TEST_F(WorldModelTest, BadRequestsAreRefusedAndChangeNothing) {
  WorldModel wm(ws, "/cell");
  const auto versions = ws.versions(f.bunny).size();
  EXPECT_THROW(wm.correct_pose(424242, Transform::Identity(), "alice"), Error);
  EXPECT_THROW(wm.correct_pose(f.environment, Transform::Identity(), "alice"), Error);  // the environment
  Transform nan = Transform::Identity();
  nan.translation().x() = NAN;
  EXPECT_THROW(wm.correct_pose(f.bunny, nan, "alice"), Error);
  EXPECT_THROW(wm.correct_pose(f.bunny, Transform::Identity(), ""), Error);
  EXPECT_THROW(wm.add_object("teapot", Transform::Identity(), "alice"), Error);
  EXPECT_THROW(wm.add_object("/cell/merged", Transform::Identity(), "alice"), Error);
  EXPECT_THROW(wm.attach(f.bunny, "", Transform::Identity(), "alice"), Error);
  EXPECT_THROW(WorldModel(ws, "/nowhere"), Error);
  EXPECT_EQ(ws.versions(f.bunny).size(), versions);
}

}  // namespace
}  // namespace artisan::worldmodel
