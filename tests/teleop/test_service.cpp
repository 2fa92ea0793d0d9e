// The world-model service and its client in one process over LCM's memq:// transport: scene from
// LCM alone (late joiners too), queries, commands, malformed messages, restart.
#include <gtest/gtest.h>

#include "artisan/core/error.hpp"
#include "artisan/service_error_t.hpp"
#include "artisan/teleop_bridge/channels.hpp"
#include "artisan/teleop_bridge/client.hpp"
#include "artisan/teleop_bridge/service.hpp"
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

}  // namespace
}  // namespace artisan::teleop
