// The world-model service and its client in one process over LCM's memq:// transport: scene from
// LCM alone (late joiners too), queries, commands, malformed messages, restart; a robot's joint
// values in the scene and queries for the robot at given joints; environmental readings placed
// where the rig was.
#include <gtest/gtest.h>

#include "artisan/core/error.hpp"
#include "artisan/environment_reading_t.hpp"
#include "artisan/service_error_t.hpp"
#include "artisan/teleop_bridge/channels.hpp"
#include "artisan/teleop_bridge/client.hpp"
#include "artisan/teleop_bridge/service.hpp"
#include "artisan/worldmodel/robot_store.hpp"
#include "worldmodel/world_fixture.hpp"

namespace artisan::teleop {
namespace {

artisan::pose_t pose(const Transform& T) {
  artisan::pose_t p;
  const Eigen::Quaterniond q(T.rotation());
  for (int k = 0; k < 3; ++k) p.position[k] = T.translation()[k];
  p.quaternion_xyzw[0] = q.x();
  p.quaternion_xyzw[1] = q.y();
  p.quaternion_xyzw[2] = q.z();
  p.quaternion_xyzw[3] = q.w();
  return p;
}

artisan::shape_t sphere(const Eigen::Vector3d& c, double r, const std::string& name = "probe") {
  artisan::shape_t s;
  s.name = name;
  s.kind = artisan::shape_t::SPHERE;
  s.dims[0] = r;
  s.dims[1] = s.dims[2] = 0;
  s.pose = pose(Transform(Eigen::Translation3d(c)));
  return s;
}

class ServiceTest : public ::testing::Test {
 protected:
  test::TempDir dir;
  worldmodel::Workspace ws = worldmodel::Workspace::create(dir / "ws.db");
  test::WorldFixture f = test::make_world_fixture(ws);
  lcm::LCM lcm{"memq://"};
  std::unique_ptr<Service> service;

  void start() {
    ServiceOptions options;
    options.folder = "/cell";
    options.poll_period_s = 0.05;
    service = std::make_unique<Service>(ws, lcm, options);
  }
  std::function<void(int)> pump() {
    return [this](int ms) {
      lcm.handleTimeout(ms);
      if (service) service->tick();
    };
  }
  Eigen::Vector3d bunny_centre() const { return f.T_world_bunny * f.bunny_mesh.bounds().center().cast<double>(); }
};

// An object reported ambiguous reaches the client with its alternative's model and pose.
TEST_F(ServiceTest, TheClientSeesAnAmbiguousObjectsAlternative) {
  const Transform T_world_alternative = Transform(Eigen::Translation3d(0.3, 0.01, 0)) * Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitZ());
  const auto id = test::add_ambiguous_bunny(ws, f, "tee", T_world_alternative);
  start();
  SceneClient client(lcm, "operator", pump());
  ASSERT_TRUE(client.wait_for_scene(10));
  ASSERT_TRUE(client.objects().contains(id));
  const auto& o = client.objects().at(id);
  EXPECT_TRUE(o.info.ambiguous);
  EXPECT_EQ(o.info.alternative_model, "tee");
  EXPECT_TRUE(o.T_world_alternative.isApprox(T_world_alternative, 1e-9));
  EXPECT_FALSE(client.objects().at(f.bunny).info.ambiguous);
  EXPECT_EQ(client.objects().at(f.bunny).info.alternative_model, "");
}

TEST_F(ServiceTest, ClientRebuildsTheSceneAndQueriesIt) {
  start();
  SceneClient client(lcm, "operator", pump());
  ASSERT_TRUE(client.wait_for_scene(10));
  EXPECT_EQ(client.folder(), "/cell");
  ASSERT_EQ(client.objects().size(), 2u);
  const auto& bunny = client.objects().at(f.bunny);
  EXPECT_EQ(bunny.info.model, "bunny");
  EXPECT_TRUE(bunny.T_world_object.isApprox(f.T_world_bunny, 1e-9));
  ASSERT_EQ(bunny.T_world_grasps.size(), 1u);
  ASSERT_TRUE(bunny.mesh);
  EXPECT_TRUE(*bunny.mesh == f.bunny_mesh);  // bit for bit through the chunks
  const auto& env = client.objects().at(f.environment);
  ASSERT_TRUE(env.mesh);
  EXPECT_EQ(env.mesh->faces.size(), service->world().objects()[0].mesh->faces.size());
  EXPECT_GT(bunny.info.mesh.n_bytes, kMeshChunkBytes);  // came in several chunks

  artisan::query_t q;
  q.type = artisan::query_t::COLLISION;
  q.shapes = {sphere(bunny_centre(), 0.02)};
  auto r = client.query(q);
  ASSERT_TRUE(r.ok) << r.error;
  EXPECT_TRUE(r.in_collision);
  ASSERT_GE(r.n_contacts, 1);
  EXPECT_EQ(r.contacts[0].object_id, f.bunny);
  // The gripper may touch what it grasps.
  artisan::allowed_pair_t allow;
  allow.shape = "probe";
  allow.object_id = f.bunny;
  q.allowed = {allow};
  EXPECT_FALSE(client.query(q).in_collision);

  artisan::query_t d;
  d.type = artisan::query_t::DISTANCE;
  d.max_distance = 1.0;
  d.shapes = {sphere({-0.3, 0.3, 0.25}, 0.05)};
  r = client.query(d);
  ASSERT_TRUE(r.ok) << r.error;
  EXPECT_NEAR(r.min_distance, 0.20, 1e-3);  // the floor, 0.25 below the centre
  EXPECT_EQ(r.n_contacts, 1);

  artisan::query_t rays;
  rays.type = artisan::query_t::RAYCAST;
  artisan::ray_t down;
  const Eigen::Vector3d c = bunny_centre();
  for (int k = 0; k < 3; ++k) down.direction[k] = k == 2 ? -1 : 0;
  down.origin[0] = c.x();
  down.origin[1] = c.y();
  down.origin[2] = 1.0;
  down.max_range = 2.0;
  rays.rays = {down};
  r = client.query(rays);
  ASSERT_TRUE(r.ok) << r.error;
  ASSERT_EQ(r.n_hits, 1);
  EXPECT_TRUE(r.hits[0].hit);
  EXPECT_EQ(r.hits[0].object_id, f.bunny);
}

TEST_F(ServiceTest, MalformedMessagesAreAnsweredAndTheServiceGoesOn) {
  start();
  std::vector<std::string> errors;
  struct Sink {
    std::vector<std::string>* errors;
    void on(const lcm::ReceiveBuffer*, const std::string&, const artisan::service_error_t* e) { errors->push_back(e->message); }
  } sink{&errors};
  lcm.subscribe(kServiceErrorChannel, &Sink::on, &sink);
  SceneClient client(lcm, "operator", pump());
  ASSERT_TRUE(client.wait_for_scene(10, false));
  const std::vector<uint8_t> garbage = {1, 2, 3, 4, 5, 6, 7};
  lcm.publish(kQueryChannel, garbage.data(), unsigned(garbage.size()));
  lcm.publish(kCommandChannel, garbage.data(), unsigned(garbage.size()));
  lcm.publish(kMeshRequestChannel, garbage.data(), unsigned(garbage.size()));
  for (int i = 0; i < 10; ++i) client.pump(10);
  EXPECT_EQ(errors.size(), 3u);
  EXPECT_GE(service->stats().malformed_messages, 3);

  artisan::query_t q;
  q.type = artisan::query_t::COLLISION;
  auto bad = sphere({0, 0, NAN}, 0.1);
  q.shapes = {bad};
  auto r = client.query(q);
  EXPECT_FALSE(r.ok);
  EXPECT_NE(r.error.find("probe"), std::string::npos) << r.error;
  q.shapes = {sphere({0, 0, 0.5}, 0.1)};
  q.shapes[0].pose.quaternion_xyzw[3] = 3;  // not a unit quaternion
  EXPECT_FALSE(client.query(q).ok);
  q.type = 42;
  EXPECT_FALSE(client.query(q).ok);
  q.type = artisan::query_t::COLLISION;
  q.shapes = {sphere({0, 0, 0.5}, 0.1)};
  q.shapes[0].kind = 99;
  EXPECT_FALSE(client.query(q).ok);

  artisan::command_t c;
  c.type = artisan::command_t::CORRECT_POSE;
  c.author = "alice";
  c.object_id = 99999;  // no such object
  c.pose = pose(Transform::Identity());
  auto result = client.command(c);
  EXPECT_FALSE(result.ok);
  EXPECT_NE(result.message.find("99999"), std::string::npos) << result.message;
  c.object_id = f.bunny;
  c.author = "";
  EXPECT_FALSE(client.command(c).ok);
  EXPECT_EQ(ws.versions(f.bunny).size(), 1u);  // nothing stored

  // And it still answers good requests.
  q.shapes = {sphere(bunny_centre(), 0.02)};
  r = client.query(q);
  EXPECT_TRUE(r.ok);
  EXPECT_TRUE(r.in_collision);
}

TEST_F(ServiceTest, CommandsChangeTheSceneForEveryClientAndSurviveARestart) {
  start();
  SceneClient alice(lcm, "alice", pump());
  ASSERT_TRUE(alice.wait_for_scene(10));
  const int64_t r0 = alice.revision();

  artisan::command_t c;
  c.type = artisan::command_t::CORRECT_POSE;
  c.author = "alice";
  c.object_id = f.bunny;
  const Transform moved = Transform(Eigen::Translation3d(-0.2, 0.2, 0)) * f.T_world_bunny;
  c.pose = pose(moved);
  auto result = alice.command(c);
  ASSERT_TRUE(result.ok) << result.message;
  EXPECT_GT(result.revision, r0);
  ASSERT_TRUE(alice.wait_for_revision(result.revision, 5));
  EXPECT_TRUE(alice.objects().at(f.bunny).T_world_object.isApprox(moved, 1e-6));
  EXPECT_EQ(ws.resolve(std::to_string(f.bunny)).version, 1);
  EXPECT_EQ(ws.versions(f.bunny).back().metadata["edit"]["author"], "alice");

  artisan::command_t add;
  add.type = artisan::command_t::ADD;
  add.author = "alice";
  add.model = "bunny";
  add.pose = pose(Transform(Eigen::Translation3d(0.3, 0.3, 0)));
  result = alice.command(add);
  ASSERT_TRUE(result.ok) << result.message;
  ASSERT_TRUE(alice.wait_for_revision(result.revision, 5));
  EXPECT_EQ(alice.objects().size(), 3u);

  // A client that joins late rebuilds the same scene from LCM alone.
  SceneClient bob(lcm, "bob", pump());
  ASSERT_TRUE(bob.wait_for_scene(10));
  EXPECT_EQ(bob.revision(), alice.revision());
  ASSERT_EQ(bob.objects().size(), 3u);
  for (const auto& [id, o] : alice.objects()) {
    EXPECT_EQ(bob.objects().at(id).info.mesh.hash, o.info.mesh.hash);
    EXPECT_TRUE(bob.objects().at(id).T_world_object.isApprox(o.T_world_object, 1e-12));
  }

  // Restart: a new service over the same workspace publishes the same scene.
  const auto before = alice.objects();
  const int64_t revision = alice.revision();
  service.reset();
  start();
  SceneClient carol(lcm, "carol", pump());
  ASSERT_TRUE(carol.wait_for_scene(10));
  EXPECT_GE(carol.revision(), revision);
  ASSERT_EQ(carol.objects().size(), before.size());
  for (const auto& [id, o] : before) EXPECT_TRUE(carol.objects().at(id).T_world_object.isApprox(o.T_world_object, 1e-12));

  // Someone else changes the workspace: the service notices and sends a diff.
  worldmodel::WorldModel other(ws, "/cell");
  other.remove_object(f.bunny, "dave");
  const int64_t seen = carol.revision();
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (carol.objects().count(f.bunny) && std::chrono::steady_clock::now() < end) carol.pump(20);
  EXPECT_FALSE(carol.objects().count(f.bunny));
  EXPECT_GT(carol.revision(), seen);
}

// Method: the service polls every 0.05 s. Idle, and after its own edits, it does not re-read
// the workspace (the change stamp is as it left it); a commit through another connection (the
// command line, another process) is re-read once and reaches the client.
TEST_F(ServiceTest, ThePollReReadsOnlyWhatOthersCommitted) {
  start();
  SceneClient client(lcm, "operator", pump());
  ASSERT_TRUE(client.wait_for_scene(10));
  const auto pump_for = [&](double s) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(s);
    while (std::chrono::steady_clock::now() < end) client.pump(10);
  };
  pump_for(0.3);
  EXPECT_EQ(service->stats().workspace_rereads, 0);

  artisan::command_t c;
  c.type = artisan::command_t::CORRECT_POSE;
  c.author = "alice";
  c.object_id = f.bunny;
  c.pose = pose(Transform(Eigen::Translation3d(-0.1, 0, 0)) * f.T_world_bunny);
  ASSERT_TRUE(client.command(c).ok);
  pump_for(0.3);
  EXPECT_EQ(service->stats().workspace_rereads, 0) << "its own edit is in the world model already";

  {
    auto other = worldmodel::Workspace::open(dir / "ws.db");
    worldmodel::WorldModel(other, "/cell").remove_object(f.bunny, "dave");
  }
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (client.objects().count(f.bunny) && std::chrono::steady_clock::now() < end) client.pump(10);
  EXPECT_FALSE(client.objects().count(f.bunny));
  pump_for(0.3);
  EXPECT_EQ(service->stats().workspace_rereads, 1);
}

// The UR5 standing 5 cm above the floor of the fixture, beside the bunny, its arm out straight.
class RobotServiceTest : public ServiceTest {
 protected:
  const Transform T_world_root = Transform(Eigen::Translation3d(-0.2, 0.3, 0.05));
  worldmodel::ObjectId robot = 0;
  void SetUp() override {
    worldmodel::RobotSetRequest set;
    set.folder = "/cell";
    set.urdf = test::ur5_urdf();
    set.package_paths = {test::robot_packages()};
    set.T_world_root = T_world_root;
    set.joints = {{"shoulder_pan_joint", 0.2}};
    set.author = "alice";
    robot = worldmodel::set_robot(ws, set);
  }
};

// Method: the scene the client rebuilds carries the robot with the joint values stored in the
// workspace and its link poses (checked against RobotModel's kinematics); a query with the
// shoulder lowered into the floor collides (the links' shapes, against the environment), the arm
// out straight does not, and its distance is the world model's own answer; a change of the
// joints in the workspace reaches the client as a diff.
TEST_F(RobotServiceTest, TheRobotIsInTheSceneAndQueriesTakeItsJoints) {
  start();
  SceneClient client(lcm, "operator", pump());
  ASSERT_TRUE(client.wait_for_scene(10, false));
  ASSERT_EQ(client.robots().size(), 1u);
  const auto& r = client.robots()[0];
  EXPECT_EQ(r.name, "ur5");
  EXPECT_EQ(r.object_id, robot);
  ASSERT_EQ(r.n_joints, 6);
  EXPECT_EQ(r.joint_names[0], "shoulder_pan_joint");
  EXPECT_EQ(r.joint_values[0], 0.2);
  const auto ur5 = worldmodel::RobotModel::load(test::ur5_urdf(), {test::robot_packages()});
  const auto truth = ur5.link_poses({{"shoulder_pan_joint", 0.2}}, T_world_root);
  ASSERT_EQ(size_t(r.n_links), truth.size());
  for (size_t k = 0; k < size_t(r.n_links); ++k) {
    const Transform& T = truth.at(r.link_names[k]);
    const auto& p = r.link_poses[k];
    EXPECT_LT((Eigen::Vector3d(p.position[0], p.position[1], p.position[2]) - T.translation()).norm(), 1e-12) << r.link_names[k];
    const Eigen::Quaterniond q(p.quaternion_xyzw[3], p.quaternion_xyzw[0], p.quaternion_xyzw[1], p.quaternion_xyzw[2]);
    EXPECT_LT(q.angularDistance(Eigen::Quaterniond(T.rotation())), 1e-9) << r.link_names[k];
  }

  artisan::query_t q;
  q.type = artisan::query_t::COLLISION;
  SceneClient::set_robot(q, "", {{"shoulder_lift_joint", M_PI / 2}});  // the arm down through the floor
  auto reply = client.query(q);
  ASSERT_TRUE(reply.ok) << reply.error;
  EXPECT_TRUE(reply.in_collision);
  ASSERT_GE(reply.n_contacts, 1);
  for (const auto& c : reply.contacts) {
    EXPECT_EQ(c.shape.rfind("ur5/", 0), 0u) << c.shape;
    EXPECT_EQ(c.object_id, f.environment);
  }
  // Allowed: the robot's links may touch the environment.
  artisan::allowed_pair_t allow;
  allow.shape = "*";
  allow.object_id = f.environment;
  q.allowed = {allow};
  EXPECT_FALSE(client.query(q).in_collision);
  q.allowed.clear();
  SceneClient::set_robot(q, "ur5", {});  // at its current joints: out straight, above the floor
  reply = client.query(q);
  ASSERT_TRUE(reply.ok) << reply.error;
  EXPECT_FALSE(reply.in_collision);
  // Every joint by position, no names.
  q.robot = "";
  q.joint_names.clear();
  q.joint_values = {0.2, 0.0, 0.0, 0.0, 0.0, 0.0};
  EXPECT_FALSE(client.query(q).in_collision);
  q.type = artisan::query_t::DISTANCE;
  q.max_distance = 1.0;
  reply = client.query(q);
  ASSERT_TRUE(reply.ok) << reply.error;
  const auto d = service->world().robot_distance({"", {{"shoulder_pan_joint", 0.2}}}, 1.0);
  EXPECT_NEAR(reply.min_distance, d.distance_m, 1e-12);
  EXPECT_GT(reply.min_distance, 0.0);
  ASSERT_EQ(reply.n_contacts, 1);
  EXPECT_EQ(reply.contacts[0].shape.rfind("ur5/", 0), 0u);

  // Someone moves the arm in the workspace: the diff carries the robot.
  worldmodel::RobotSetRequest move;
  move.folder = "/cell";
  move.joints = {{"elbow_joint", 0.5}};
  move.author = "bob";
  worldmodel::set_robot(ws, move);
  const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (client.robots().at(0).version != 2 && std::chrono::steady_clock::now() < end) client.pump(20);
  ASSERT_EQ(client.robots().at(0).version, 2);
  EXPECT_EQ(client.robots().at(0).joint_values[2], 0.5);
  EXPECT_EQ(client.robots().at(0).joint_values[0], 0.2);
}

TEST_F(RobotServiceTest, BadRobotQueriesAreRefusedNamingWhatIsWrong) {
  start();
  SceneClient client(lcm, "operator", pump());
  ASSERT_TRUE(client.wait_for_scene(10, false));
  artisan::query_t q;
  q.type = artisan::query_t::COLLISION;
  const auto refused = [&](const std::string& what) {
    const auto r = client.query(q);
    EXPECT_FALSE(r.ok) << what;
    EXPECT_NE(r.error.find(what), std::string::npos) << r.error;
  };
  SceneClient::set_robot(q, "", {{"elbow", 1.0}});
  refused("'elbow'");
  SceneClient::set_robot(q, "", {{"elbow_joint", NAN}});
  refused("not finite");
  SceneClient::set_robot(q, "", {{"elbow_joint", 9.0}});
  refused("limits");
  SceneClient::set_robot(q, "ur10", {});
  refused("ur10");
  q.robot = "";
  q.joint_names.clear();
  q.joint_values = {0.1, 0.2, 0.3};
  refused("6 joints");
  q.joint_names = {"elbow_joint", "wrist_1_joint"};
  refused("2 joint name(s) but 3");
  q.type = artisan::query_t::RAYCAST;
  SceneClient::set_robot(q, "", {});
  refused("COLLISION and DISTANCE");
  // Still answering.
  q.type = artisan::query_t::COLLISION;
  SceneClient::set_robot(q, "", {});
  EXPECT_TRUE(client.query(q).ok);
}

// Method: two acquisitions stored with environmental readings (as `artisan acquire` stores them:
// T_world_rig row-major) are published once each, at the translation of T_world_rig.
TEST_F(ServiceTest, EnvironmentalReadingsArePublishedWhereTheRigWas) {
  struct Sink {
    std::vector<artisan::environment_reading_t> readings;
    void on(const lcm::ReceiveBuffer*, const std::string&, const artisan::environment_reading_t* r) { readings.push_back(*r); }
  } sink;
  lcm.subscribe(kEnvironmentChannel, &Sink::on, &sink);
  const Transform T_world_rig = Transform(Eigen::Translation3d(-1.2, -1.2, 1.45)) * Eigen::AngleAxisd(0.8, Eigen::Vector3d::UnitZ());
  for (int k = 0; k < 2; ++k) {
    RangeImage image = RangeImage::empty_of_size(2, 2);
    auto o = worldmodel::make_image_object("scan" + std::to_string(k), image, {"acquire", {}, {}});
    const auto m = to_row_major(Transform(Eigen::Translation3d(0, 0, 0.1 * k)) * T_world_rig);
    o.metadata["environment"] = {{"time_s", 1.0}, {"dose_rate_uSv_per_h", 0.5 + k}, {"temperature_C", 21.0}, {"humidity_percent", 40.0},
                                 {"T_world_rig", std::vector<double>(m.begin(), m.end())}};
    ws.add(ws.folder("/cell").id, o);
  }
  start();
  SceneClient client(lcm, "operator", pump());
  ASSERT_TRUE(client.wait_for_scene(10, false));
  for (int i = 0; i < 20; ++i) client.pump(10);
  ASSERT_EQ(sink.readings.size(), 2u);
  for (const auto& r : sink.readings) {
    const int k = r.image_path == "/cell/scan1" ? 1 : 0;
    EXPECT_NEAR(r.position[0], -1.2, 1e-12);
    EXPECT_NEAR(r.position[1], -1.2, 1e-12);
    EXPECT_NEAR(r.position[2], 1.45 + 0.1 * k, 1e-12);
    EXPECT_EQ(r.dose_rate_uSv_per_h, 0.5 + k);
  }
}

}  // namespace
}  // namespace artisan::teleop
