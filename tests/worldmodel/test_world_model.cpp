// World model over the workspace: the scene (environment with recognized objects cut out,
// objects with poses and grasps), its collision scene, operator edits stored as versions, a robot
// from URDF at its joint values (collision and distance for the robot at any joints, against
// analytic obstacles and brute force over its link hulls), and the world frame taken from the
// sensor pose of a MultiMesh's root image.
#include <gtest/gtest.h>

#include "artisan/core/error.hpp"
#include "artisan/worldmodel/multimesh.hpp"
#include "artisan/worldmodel/robot_store.hpp"
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

// An object the recognizer reported ambiguous carries the alternative's model and pose (in the
// world; the merged scene here is the world frame); one that is not carries none.
TEST_F(WorldModelTest, AnAmbiguousObjectCarriesItsAlternative) {
  const Transform T_world_alternative = Transform(Eigen::Translation3d(0.3, 0.01, 0)) * Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitZ());
  const auto id = test::add_ambiguous_bunny(ws, f, "tee", T_world_alternative);
  WorldModel wm(ws, "/cell");
  const auto* ambiguous = wm.find(id);
  ASSERT_NE(ambiguous, nullptr);
  EXPECT_TRUE(ambiguous->ambiguous);
  EXPECT_EQ(ambiguous->alternative_model, "tee");
  EXPECT_TRUE(ambiguous->T_world_alternative.isApprox(T_world_alternative, 1e-9));
  const auto* bunny = wm.find(f.bunny);
  ASSERT_NE(bunny, nullptr);
  EXPECT_FALSE(bunny->ambiguous);
  EXPECT_TRUE(bunny->alternative_model.empty());
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

// Method: with the environment re-cut in the background, an edit updates only the object it
// made (read back from its new row, not the whole folder). After every kind of edit the objects
// must be exactly what a full reload of the folder gives, and a full refresh finds nothing new.
TEST_F(WorldModelTest, AnEditUpdatesItsObjectAsAFullReloadWould) {
  WorldModelOptions options;
  options.environment_in_background = true;
  WorldModel wm(ws, "/cell", options);
  const auto same_as_reload = [&](const std::string& step) {
    WorldModel fresh(ws, "/cell", options);
    std::map<ObjectId, const SceneObject*> reloaded;
    for (const auto& o : fresh.objects()) reloaded[o.object_id] = &o;
    ASSERT_EQ(wm.objects().size(), fresh.objects().size()) << step;
    for (const auto& o : wm.objects()) {
      ASSERT_TRUE(reloaded.count(o.object_id)) << step << ": " << o.path;
      const auto& r = *reloaded[o.object_id];
      if (o.kind == SceneObject::Kind::environment) continue;  // re-cut later, in the background
      EXPECT_EQ(o.version_id, r.version_id) << step;
      EXPECT_EQ(o.version, r.version) << step;
      EXPECT_EQ(o.path, r.path) << step;
      EXPECT_EQ(o.status, r.status) << step;
      EXPECT_EQ(o.attached_to, r.attached_to) << step;
      EXPECT_EQ(o.mesh_hash, r.mesh_hash) << step;
      EXPECT_EQ(o.model, r.model) << step;
      EXPECT_TRUE(o.T_world_object.isApprox(r.T_world_object, 1e-12)) << step;
      ASSERT_EQ(o.T_world_grasps.size(), r.T_world_grasps.size()) << step;
      for (size_t g = 0; g < o.T_world_grasps.size(); ++g) EXPECT_TRUE(o.T_world_grasps[g].isApprox(r.T_world_grasps[g], 1e-9)) << step;
      EXPECT_EQ(wm.collision().contains(o.object_id), o.attached_to.empty()) << step;
    }
    const auto revision = wm.revision();
    EXPECT_TRUE(wm.refresh().empty()) << step;
    EXPECT_EQ(wm.revision(), revision) << step;
  };
  const Transform moved = Transform(Eigen::Translation3d(-0.3, 0.2, 0)) * f.T_world_bunny;
  auto r = wm.revision();
  wm.correct_pose(f.bunny, moved, "alice");
  EXPECT_EQ(wm.last_changes().changed, std::vector<ObjectId>{f.bunny});
  EXPECT_GT(wm.revision(), r);
  EXPECT_TRUE(wm.collision().check({ball(moved * f.bunny_mesh.bounds().center().cast<double>(), 0.02)}).in_collision);
  same_as_reload("correct");
  wm.accept_pose(f.bunny, "alice");
  same_as_reload("accept");
  wm.attach(f.bunny, "ur5/tool0", Transform::Identity(), "bob");
  same_as_reload("attach");
  wm.detach(f.bunny, "bob");
  same_as_reload("detach");
  r = wm.revision();
  const ObjectId added = wm.add_object("bunny", Transform(Eigen::Translation3d(0.3, 0.3, 0.0)), "carol");
  EXPECT_EQ(wm.last_changes().changed, std::vector<ObjectId>{added});
  EXPECT_GT(wm.revision(), r);
  same_as_reload("add");
  wm.remove_object(f.bunny, "dave");
  EXPECT_EQ(wm.last_changes().removed, std::vector<ObjectId>{f.bunny});
  EXPECT_FALSE(wm.collision().contains(f.bunny));
  same_as_reload("delete");
  // The environment's re-cut follows, for the objects as they are now.
  SceneChanges env_changes;
  for (int i = 0; i < 3 && env_changes.empty(); ++i) env_changes = wm.poll_environment(true);
  EXPECT_EQ(env_changes.changed, std::vector<ObjectId>{f.environment});
  EXPECT_EQ(WorldModel(ws, "/cell").objects()[0].mesh_hash, wm.objects()[0].mesh_hash);
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

// --- robots ---------------------------------------------------------------------------------

// A UR5 standing at the world origin, folded upright (its current joints), in front of a wall
// whose face is the plane x = kWallX (a 2 cm slab, 6 m x 4 m: larger than the arm's reach, so the
// distance from a convex hull to it is the smallest x-gap of the hull's vertices); a 10 cm block
// (a recognized object) placed so that its bottom face cuts through the wrist at `q_hit`.
class RobotWorldTest : public ::testing::Test {
 protected:
  static constexpr double kWallX = 0.6;
  test::TempDir dir;
  Workspace ws = Workspace::create(dir / "ws.db");
  ObjectId environment = 0, block_model = 0, block = 0, robot_id = 0;
  std::map<std::string, double> q_up = {{"shoulder_lift_joint", -M_PI / 2}, {"wrist_1_joint", -M_PI / 2}};
  std::map<std::string, double> q_hit = {{"shoulder_pan_joint", M_PI}, {"shoulder_lift_joint", -0.3}, {"elbow_joint", 0.6}};
  RobotModel ur5 = RobotModel::load(test::ur5_urdf(), {test::robot_packages()});
  Transform T_world_block = Transform::Identity();

  void SetUp() override {
    const ObjectId arm = ws.mkdir("/arm");
    TriangleMesh wall = test::box_mesh({0.02f, 6.0f, 4.0f});
    wall.transform(Transform(Eigen::Translation3d(kWallX + 0.01, 0, 1.0)));
    environment = ws.add(arm, make_mesh_object(ObjectKind::kMesh, "merged", "merged", wall, {"merge", {}, {}}));
    block_model = ws.add(ws.root(), make_mesh_object(ObjectKind::kModel, "", "block", test::box_mesh({0.1f, 0.1f, 0.1f}), {"import", {}, {}}));
    const Eigen::Vector3d wrist = ur5.link_poses(q_hit, Transform::Identity()).at("wrist_3_link").translation();
    T_world_block = Transform(Eigen::Translation3d(wrist + Eigen::Vector3d(0, 0, 0.05)));
    NewObject r;
    r.kind = ObjectKind::kRecognizedModel;
    r.subkind = "block";
    r.name = "block-1";
    r.metadata = {{"model", "/block"}, {"model_id", block_model}, {"T_scene_model", to_row_major(T_world_block)}};
    r.provenance = Provenance{"recognize", {}, {environment, block_model}};
    block = ws.add(arm, r);
    RobotSetRequest set;
    set.folder = "/arm";
    set.urdf = test::ur5_urdf();
    set.package_paths = {test::robot_packages()};
    set.T_world_root = Transform::Identity();
    set.joints = q_up;
    set.author = "alice";
    robot_id = set_robot(ws, set);
  }

  // Brute force: the smallest gap between the wall's face and the vertices of `shapes` (hulls).
  static double wall_gap(const std::vector<QueryShape>& shapes) {
    double gap = INFINITY;
    for (const auto& s : shapes)
      for (const auto& p : s.points) gap = std::min(gap, kWallX - (s.T_world_shape * p.cast<double>()).x());
    return gap;
  }
  std::map<std::string, double> with(std::map<std::string, double> q, const std::map<std::string, double>& more) const {
    for (const auto& [k, v] : more) q[k] = v;
    return q;
  }
};

TEST_F(RobotWorldTest, TheRobotIsInTheSceneAtItsJoints) {
  WorldModel wm(ws, "/arm");
  ASSERT_EQ(wm.robots().size(), 1u);
  const auto& r = wm.robot();
  EXPECT_EQ(&wm.robot("ur5"), &r);
  EXPECT_EQ(r.name, "ur5");
  EXPECT_EQ(r.object_id, robot_id);
  EXPECT_EQ(r.model->joint_names(), ur5.joint_names());
  EXPECT_EQ(r.joints.at("shoulder_lift_joint"), -M_PI / 2);
  EXPECT_EQ(r.joints.at("elbow_joint"), 0.0);
  const auto truth = ur5.link_poses(q_up, Transform::Identity());
  for (const auto& [link, T] : truth) EXPECT_TRUE(r.T_world_links.at(link).isApprox(T, 1e-12)) << link;
  // The robot is not a static body: queries for it are made at the joints asked for.
  EXPECT_EQ(wm.collision().bodies().size(), 2u);  // the wall and the block
}

// Method: the wrist in the block (its face through the wrist centre) collides, and with the
// block allowed nothing does; folded upright nothing collides, and the distance to the wall is
// the brute-force smallest x-gap over the vertices of every link hull (the block excluded).
TEST_F(RobotWorldTest, WristInABoxCollidesFoldedAwayIsClearAtTheBruteForceDistance) {
  WorldModel wm(ws, "/arm");
  const auto hit = wm.check_robot({"", q_hit});
  ASSERT_TRUE(hit.in_collision);
  bool wrist = false;
  for (const auto& c : hit.contacts) {
    EXPECT_EQ(c.body, block) << c.shape;
    wrist |= c.shape.rfind("ur5/wrist_", 0) == 0;
  }
  EXPECT_TRUE(wrist);
  EXPECT_FALSE(wm.check_robot({"", q_hit}, {{"*", block}}).in_collision);
  // Allowing exactly the links that touch it, by name, also clears it.
  std::vector<AllowedPair> touching;
  for (const auto& c : hit.contacts) touching.push_back({c.shape, block});
  EXPECT_FALSE(wm.check_robot({"", q_hit}, touching).in_collision);
  // Stopping at the first contact agrees.
  EXPECT_TRUE(wm.check_robot({"", q_hit}, {}, {.stop_at_first = true}).in_collision);

  // Folded upright (the current joints): clear, at the brute-force distance from the wall.
  EXPECT_FALSE(wm.check_robot({}).in_collision);
  const std::vector<AllowedPair> not_block = {{"*", block}};
  const auto d = wm.robot_distance({}, 2.0, not_block);
  const double truth = wall_gap(ur5.collision_shapes(q_up, Transform::Identity()));
  EXPECT_GT(truth, 0.3);
  EXPECT_NEAR(d.distance_m, truth, 1e-4);
  ASSERT_TRUE(d.closest);
  EXPECT_EQ(d.closest->body, environment);
  EXPECT_NEAR(d.closest->point_on_body.x(), kWallX, 1e-4);
  // Other configurations reaching towards the wall: the same agreement.
  for (double pan : {0.0, 0.3, -0.4})
    for (double lift : {-1.2, -0.6}) {
      const auto q = with(q_up, {{"shoulder_pan_joint", pan}, {"shoulder_lift_joint", lift}});
      const double bf = wall_gap(ur5.collision_shapes(q, Transform::Identity()));
      if (bf <= 0.001) continue;  // into the wall: not a distance
      EXPECT_NEAR(wm.robot_distance({"", q}, 2.0, not_block).distance_m, bf, 1e-4) << pan << " " << lift;
    }
}

// Method: the block attached to tool0 is where tool0 is (T_world_tool0 * T_link_object), moves
// with the joints asked for in a query, and makes the robot collide with the wall where the
// links alone would not (found by brute force over a sweep of the shoulder); detached, it stays
// where the robot left it, as a static obstacle.
TEST_F(RobotWorldTest, AnAttachedObjectMovesWithItsLink) {
  WorldModel wm(ws, "/arm");
  const Transform T_link_object(Eigen::Translation3d(0, 0, 0.04));  // its near face 1 cm into the flange
  wm.attach(block, "ur5/tool0", T_link_object, "bob");
  const auto* carried = wm.find(block);
  ASSERT_NE(carried, nullptr);
  EXPECT_TRUE(carried->T_world_object.isApprox(ur5.link_poses(q_up, Transform::Identity()).at("tool0") * T_link_object, 1e-9));
  EXPECT_FALSE(wm.collision().contains(block));
  // In the query shapes, at the joints asked for.
  const auto q = with(q_up, {{"shoulder_pan_joint", 0.2}, {"shoulder_lift_joint", -1.0}});
  const auto shapes = wm.robot_shapes({"", q});
  const auto it = std::find_if(shapes.begin(), shapes.end(), [&](const QueryShape& s) { return s.name == carried->path; });
  ASSERT_NE(it, shapes.end());
  EXPECT_TRUE(it->T_world_shape.isApprox(ur5.link_poses(q, Transform::Identity()).at("tool0") * T_link_object, 1e-9));
  // Distance with the block carried: brute force over the link hulls and the block's corners.
  EXPECT_NEAR(wm.robot_distance({"", q}, 2.0).distance_m, wall_gap(shapes), 1e-4);
  // A configuration where the block crosses the wall's face and no link comes within 2 cm of it
  // (the tool pointing at the wall, the shoulder lowered until the block reaches it).
  bool found = false;
  for (double lift = -1.5; lift < 0 && !found; lift += 0.02) {
    const auto qq = with(q_up, {{"shoulder_pan_joint", 0.0}, {"shoulder_lift_joint", lift}, {"wrist_1_joint", -lift},
                                {"wrist_2_joint", M_PI / 2}});
    const auto all = wm.robot_shapes({"", qq});
    std::vector<QueryShape> links, carried_only;
    for (const auto& s : all) (s.name == carried->path ? carried_only : links).push_back(s);
    if (wall_gap(carried_only) > -0.01 || wall_gap(links) < 0.02) continue;
    found = true;
    const auto c = wm.check_robot({"", qq});
    ASSERT_TRUE(c.in_collision) << lift;
    for (const auto& x : c.contacts) EXPECT_EQ(x.shape, carried->path);
  }
  EXPECT_TRUE(found);
  // Detached: a static obstacle where the robot left it.
  wm.detach(block, "bob");
  EXPECT_TRUE(wm.collision().contains(block));
  EXPECT_TRUE(wm.find(block)->T_world_object.isApprox(ur5.link_poses(q_up, Transform::Identity()).at("tool0") * T_link_object, 1e-9));
  EXPECT_TRUE(wm.check_robot({}).in_collision);  // it hangs where the tool was
}

TEST_F(RobotWorldTest, ChangesOfTheRobotAreSeenByRefresh) {
  WorldModel wm(ws, "/arm");
  wm.attach(block, "ur5/tool0", Transform::Identity(), "bob");
  const auto r0 = wm.revision();
  RobotSetRequest set;
  set.folder = "/arm";
  set.joints = {{"shoulder_pan_joint", 1.0}};
  set.author = "carol";
  set_robot(ws, set);  // another process moves the arm
  const auto changes = wm.refresh();
  EXPECT_TRUE(changes.robots);
  EXPECT_EQ(changes.changed, std::vector<ObjectId>{block});  // carried along
  EXPECT_GT(wm.revision(), r0);
  EXPECT_EQ(wm.robot().joints.at("shoulder_pan_joint"), 1.0);
  EXPECT_EQ(wm.robot().version, 2);
  EXPECT_TRUE(wm.find(block)->T_world_object.isApprox(ur5.link_poses(with(q_up, {{"shoulder_pan_joint", 1.0}}), Transform::Identity()).at("tool0"), 1e-9));
  EXPECT_TRUE(wm.refresh().empty());
}

TEST_F(RobotWorldTest, BadRobotQueriesAreRefusedNamingWhatIsWrong) {
  WorldModel wm(ws, "/arm");
  auto e = test::error_of([&] { wm.robot_shapes({"", {{"elbow", 1.0}}}); });
  EXPECT_NE(e.find("'elbow'"), std::string::npos) << e;
  EXPECT_NE(e.find("elbow_joint"), std::string::npos) << e;
  e = test::error_of([&] { wm.check_robot({"", {{"elbow_joint", NAN}}}); });
  EXPECT_NE(e.find("elbow_joint"), std::string::npos) << e;
  EXPECT_NE(e.find("not finite"), std::string::npos) << e;
  e = test::error_of([&] { wm.robot_distance({"", {{"elbow_joint", 7.0}}}, 1.0); });
  EXPECT_NE(e.find("limits"), std::string::npos) << e;
  e = test::error_of([&] { wm.check_robot({"ur10", {}}); });
  EXPECT_NE(e.find("ur10"), std::string::npos) << e;
  EXPECT_NE(e.find("ur5"), std::string::npos) << e;
  e = test::error_of([&] { wm.joint_values("", {}, {0.1, 0.2, 0.3}); });
  EXPECT_NE(e.find("6 joints"), std::string::npos) << e;
  EXPECT_NE(e.find("got 3"), std::string::npos) << e;
  e = test::error_of([&] { wm.joint_values("", {"elbow_joint", "wrist_1_joint"}, {0.1}); });
  EXPECT_NE(e.find("2 joint name(s) but 1"), std::string::npos) << e;
  e = test::error_of([&] { wm.joint_values("", {"elbow_joint", "elbow_joint"}, {0.1, 0.2}); });
  EXPECT_NE(e.find("twice"), std::string::npos) << e;
  const auto q = wm.joint_values("", {}, {0.1, 0.2, 0.3, 0.4, 0.5, 0.6});
  EXPECT_EQ(q.at("wrist_3_joint"), 0.6);
  EXPECT_EQ(wm.joint_values("", {"elbow_joint"}, {0.5}), (std::map<std::string, double>{{"elbow_joint", 0.5}}));
  WorldModel none(ws, "/");  // the workspace root holds /arm, so its robot too
  EXPECT_EQ(none.robots().size(), 1u);
}

// Method: the environment holds the arm's own scanned surface (its link meshes at the current
// joints merged into it, as a sensor sees the cell): the robot at those joints collides with its
// own scan unless the world model cuts the robot out, which it does by default.
TEST_F(RobotWorldTest, TheRobotsOwnScannedSurfaceIsCutOut) {
  TriangleMesh scanned = test::box_mesh({0.02f, 6.0f, 4.0f});
  scanned.transform(Transform(Eigen::Translation3d(kWallX + 0.01, 0, 1.0)));
  const auto poses = ur5.link_poses(q_up, Transform::Identity());
  for (const auto& [link, mesh] : ur5.link_meshes()) {
    TriangleMesh m = *mesh;
    m.transform(poses.at(link));
    scanned.append(m);
  }
  ws.add_version(environment, make_mesh_object(ObjectKind::kMesh, "merged", "merged", scanned, {"merge", {}, {}}));
  WorldModelOptions keep;
  keep.cut_out_robots = false;
  WorldModel raw(ws, "/arm", keep);
  EXPECT_TRUE(raw.check_robot({}).in_collision);
  WorldModel wm(ws, "/arm");
  EXPECT_FALSE(wm.check_robot({}).in_collision);
  // The wall is still there.
  EXPECT_NEAR(wm.robot_distance({}, 2.0, {{"*", block}}).distance_m, wall_gap(ur5.collision_shapes(q_up, Transform::Identity())), 1e-4);
}

// --- the world frame --------------------------------------------------------------------------

// Method: a CAD-like model with few, large triangles (a 0.2 m box: 12 triangles, vertices only at
// its corners) recognized where a dense scan of it lies (its top face sampled every 2 mm, on a
// floor of 10 mm cells). Every scanned triangle on the box's top face is cut out of the
// environment, not only those near its corners, and the floor a little away from the box stays.
TEST(WorldModelCutOut, ASparseModelsWholeSurfaceIsCutOut) {
  test::TempDir dir;
  Workspace ws = Workspace::create(dir / "ws.db");
  const TriangleMesh box = test::box_mesh(Eigen::Vector3f(0.2f, 0.2f, 0.2f));
  const Transform T_world_box(Eigen::Translation3d(0, 0, 0.1));  // standing on the floor
  TriangleMesh environment = test::floor_mesh(100);
  const size_t floor_faces = environment.faces.size();
  TriangleMesh top = test::floor_mesh(100);  // 1 m at 10 mm cells, scaled to the 0.2 m top face at 2 mm
  for (auto& v : top.vertices) v = Eigen::Vector3f(0.2f * v.x(), 0.2f * v.y(), 0.2f);
  environment.append(top);
  const auto cell = ws.mkdir("/cell");
  const auto env = ws.add(cell, make_mesh_object(ObjectKind::kMesh, "merged", "merged", environment, {"merge", {}, {}}));
  const auto model = ws.add(ws.root(), make_mesh_object(ObjectKind::kModel, "", "box", box, {"import", {}, {}}));
  NewObject r;
  r.kind = ObjectKind::kRecognizedModel;
  r.subkind = "box";
  r.name = "box-in-merged-1";
  r.metadata = {{"model", "/box"},
                {"model_id", model},
                {"T_scene_model", to_row_major(T_world_box)},
                {"figures", {{"score", 0.9}, {"overlap", 0.6}, {"rmse_m", 0.0004}, {"ambiguous", false}}}};
  r.provenance = Provenance{"recognize", {}, {env, model}};
  ws.add(cell, r);
  WorldModel wm(ws, "/cell");
  const auto& cut = *wm.objects()[0].mesh;
  size_t on_top = 0, floor_far = 0;
  for (const auto& f : cut.faces) {
    const Eigen::Vector3f c = (cut.vertices[f[0]] + cut.vertices[f[1]] + cut.vertices[f[2]]) / 3;
    on_top += c.z() > 0.15f;
    floor_far += c.z() < 0.01f && (std::abs(c.x()) > 0.13f || std::abs(c.y()) > 0.13f);
  }
  EXPECT_EQ(on_top, 0u) << "scanned triangles of the box's top face left in the environment";
  size_t floor_far_before = 0;
  for (size_t k = 0; k < floor_faces; ++k) {
    const auto& f = environment.faces[k];
    const Eigen::Vector3f c = (environment.vertices[f[0]] + environment.vertices[f[1]] + environment.vertices[f[2]]) / 3;
    floor_far_before += std::abs(c.x()) > 0.13f || std::abs(c.y()) > 0.13f;
  }
  EXPECT_EQ(floor_far, floor_far_before);
}

// Method: two floor patches meshed from images, the root image with a known sensor pose, the
// other registered to it by a known T_parent_member, and a block recognized in the second: the
// environment's bounds, the block's pose and a merge of the MultiMesh (in the root's frame) all
// come out at T_world_sensor times their MultiMesh poses. A MultiMesh whose root image knows no
// pose stays at the identity.
TEST(WorldFrame, AMultiMeshIsPlacedByItsRootImagesSensorPose) {
  test::TempDir dir;
  auto ws = Workspace::create(dir / "ws.db");
  const Transform T_world_sensor = Transform(Eigen::Translation3d(1.0, -2.0, 1.5)) * Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized());
  const Transform T_root_b = Transform(Eigen::Translation3d(0.3, 0.1, 0.0)) * Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitZ());
  const Transform T_b_block(Eigen::Translation3d(0.1, 0.1, 0.3));
  const auto model = ws.add(ws.root(), make_mesh_object(ObjectKind::kModel, "", "block", test::box_mesh({0.1f, 0.1f, 0.1f}), {"import", {}, {}}));
  const TriangleMesh patch = test::floor_mesh(4);

  const auto build = [&](const std::string& folder, bool pose_known) {
    const ObjectId f = ws.mkdir(folder);
    ObjectId meshes[2];
    for (int k = 0; k < 2; ++k) {
      RangeImage image = RangeImage::empty_of_size(2, 2);
      image.sensor.kind = "simulated";
      if (pose_known && k == 0) image.sensor.T_world_sensor = T_world_sensor;
      if (k == 1) image.sensor.T_world_sensor = Transform(Eigen::Translation3d(9, 9, 9));  // not the root: not used
      const auto id = ws.add(f, make_image_object("view" + std::to_string(k), image, {"sim-scan", {}, {}}));
      meshes[k] = ws.add(f, make_mesh_object(ObjectKind::kMesh, "original", "view" + std::to_string(k) + "-mesh", patch, {"mesh", {}, {id}}));
    }
    const auto mm = create_multimesh(ws, f, "views");
    const auto root = ws.add_member(mm, {0, meshes[0], std::nullopt, Transform::Identity(), "root", {}});
    ws.add_member(mm, {0, meshes[1], root, T_root_b, "manual", {}});
    NewObject r;
    r.kind = ObjectKind::kRecognizedModel;
    r.subkind = "block";
    r.name = "block-in-view1";
    r.metadata = {{"model", "/block"}, {"model_id", model}, {"T_scene_model", to_row_major(T_b_block)}};
    r.provenance = Provenance{"recognize", {}, {meshes[1], model}};
    return std::make_pair(ws.add(f, r), mm);
  };
  const auto expected_bounds = [&](const Transform& T_world_root) {
    Eigen::AlignedBox3d box;
    for (const auto& v : patch.vertices) {
      box.extend(T_world_root * v.cast<double>());
      box.extend(T_world_root * T_root_b * v.cast<double>());
    }
    return box;
  };
  const auto [block, mm] = build("/posed", true);
  {
    WorldModel wm(ws, "/posed");
    ASSERT_EQ(wm.objects().size(), 2u);
    const auto box = expected_bounds(T_world_sensor);
    const auto env = wm.objects()[0].mesh->bounds();
    EXPECT_LT((env.min().cast<double>() - box.min()).norm(), 1e-5);
    EXPECT_LT((env.max().cast<double>() - box.max()).norm(), 1e-5);
    EXPECT_TRUE(wm.find(block)->T_world_object.isApprox(T_world_sensor * T_root_b * T_b_block, 1e-9));
  }
  // Merged (in the root member's frame, as `artisan merge` makes it): placed the same way, and so
  // is an object recognized in it.
  TriangleMesh merged = patch;
  merged.append([&] { TriangleMesh b = patch; b.transform(T_root_b); return b; }());
  const ObjectId f = ws.folder("/posed").id;
  const auto merged_id = ws.add(f, make_mesh_object(ObjectKind::kMesh, "merged", "views-merged", merged, {"merge", {{"multimesh", mm}}, {mm}}));
  NewObject r;
  r.kind = ObjectKind::kRecognizedModel;
  r.subkind = "block";
  r.name = "block-in-merged";
  r.metadata = {{"model", "/block"}, {"model_id", model}, {"T_scene_model", to_row_major(T_root_b * T_b_block)}};
  r.provenance = Provenance{"recognize", {}, {merged_id, model}};
  const auto in_merged = ws.add(f, r);
  {
    WorldModel wm(ws, "/posed");
    const auto box = expected_bounds(T_world_sensor);
    const auto env = wm.objects()[0].mesh->bounds();
    EXPECT_EQ(wm.objects()[0].object_id, merged_id);
    EXPECT_LT((env.min().cast<double>() - box.min()).norm(), 1e-5);
    EXPECT_LT((env.max().cast<double>() - box.max()).norm(), 1e-5);
    EXPECT_TRUE(wm.find(in_merged)->T_world_object.isApprox(T_world_sensor * T_root_b * T_b_block, 1e-9));
    EXPECT_TRUE(wm.find(block)->T_world_object.isApprox(T_world_sensor * T_root_b * T_b_block, 1e-9));
    // Collision in the world frame: a ball on the patch's centre in the world.
    EXPECT_TRUE(wm.collision().check({ball(T_world_sensor * Eigen::Vector3d(0.1, 0.1, 0), 0.01)}).in_collision);
    EXPECT_FALSE(wm.collision().check({ball(Eigen::Vector3d(0.1, 0.1, 0), 0.01)}).in_collision);
    // Accepting the pose keeps it where it is in the world (the edit's version is not derived
    // from the mesh the pose is relative to), now and after a restart.
    wm.accept_pose(in_merged, "alice");
    EXPECT_TRUE(wm.find(in_merged)->T_world_object.isApprox(T_world_sensor * T_root_b * T_b_block, 1e-9));
    WorldModel again(ws, "/posed");
    EXPECT_TRUE(again.find(in_merged)->T_world_object.isApprox(T_world_sensor * T_root_b * T_b_block, 1e-9));
  }
  // The root image knows no pose: the MultiMesh's own frame, as before.
  const auto [block2, mm2] = build("/unposed", false);
  (void)mm2;
  WorldModel wm(ws, "/unposed");
  const auto box = expected_bounds(Transform::Identity());
  const auto env = wm.objects()[0].mesh->bounds();
  EXPECT_LT((env.min().cast<double>() - box.min()).norm(), 1e-5);
  EXPECT_LT((env.max().cast<double>() - box.max()).norm(), 1e-5);
  EXPECT_TRUE(wm.find(block2)->T_world_object.isApprox(T_root_b * T_b_block, 1e-9));
}

}  // namespace
}  // namespace artisan::worldmodel
