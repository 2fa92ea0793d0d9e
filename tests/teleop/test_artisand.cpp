// artisand as a process, its clients in other processes, over real UDP multicast inside a
// private network namespace (nothing can leave the machine): scene from LCM alone, the
// `artisan teleop` client (with a robot checked at joint values, and an object reported ambiguous
// shown with its alternative), malformed messages, lcm-logger/lcm-logplayer, SIGTERM and restart.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <thread>

#include <nlohmann/json.hpp>

#include "artisan/teleop_bridge/channels.hpp"
#include "artisan/teleop_bridge/client.hpp"
#include "worldmodel/world_fixture.hpp"

namespace artisan::teleop {
namespace {

// A small receive buffer, as on many CI machines: mesh transfers must survive dropped datagrams.
const std::string kUrl = "udpm://239.255.76.67:7667?ttl=0&recv_buf_size=120000";

bool in_netns() { return std::getenv("ARTISAN_IN_NETNS") != nullptr; }

// Starts `argv` in the background; returns its pid.
pid_t spawn(const std::vector<std::string>& argv) {
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);  // never outlive the test
    std::vector<char*> a;
    for (const auto& s : argv) a.push_back(const_cast<char*>(s.c_str()));
    a.push_back(nullptr);
    ::execvp(a[0], a.data());
    ::_exit(127);
  }
  return pid;
}

int stop(pid_t pid, int sig = SIGTERM) {
  ::kill(pid, sig);
  int status = 0;
  ::waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

std::string bin_dir() { return std::filesystem::path(ARTISAN_CLI).parent_path().string(); }

// Runs this very test again inside `unshare -n` with loopback multicast, and checks it passed.
TEST(Artisand, AcrossProcessesInAPrivateNetworkNamespace) {
  if (!in_netns()) {
    if (test::run_command("unshare -n true").exit_code != 0)
      GTEST_SKIP() << "cannot make a private network namespace here (unshare -n needs root or user namespaces)";
    const std::string self = std::filesystem::read_symlink("/proc/self/exe").string();
    const auto r = test::run_command(
        "timeout 300 unshare -n sh -c 'ip link set lo up && ip link set lo multicast on && ip route add 224.0.0.0/4 dev lo && "
        "ARTISAN_IN_NETNS=1 exec \"$0\" --gtest_filter=Artisand.AcrossProcessesInAPrivateNetworkNamespace' " + self);
    EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
    return;
  }
  test::TempDir dir;
  const auto db = (dir / "ws.db").string();
  test::WorldFixture f;
  // And a second bunny, reported ambiguous with a pipe, away from where the robot reaches.
  const Transform T_world_alternative = Transform(Eigen::Translation3d(-0.5, -0.6, 0.02)) * Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY());
  worldmodel::ObjectId ambiguous = 0;
  {
    auto ws = worldmodel::Workspace::create(db);
    f = test::make_world_fixture(ws);
    ambiguous = test::add_ambiguous_bunny(ws, f, "pipe_350", T_world_alternative, {-0.6, -0.6, 0});
  }
  // A UR5 5 cm above the floor, its arm out straight (by the command line, as an operator would).
  const auto set = test::run_command(std::string(ARTISAN_CLI) + " --db " + db + " robot set /cell --urdf '" + test::ur5_urdf().string() +
                                     "' --package-path '" + test::robot_packages().string() + "' --pose '0.3 0.3 0.05 0 0 0 1' --author setup");
  ASSERT_EQ(set.exit_code, 0) << set.err;
  const std::string artisand = bin_dir() + "/artisand", cli = ARTISAN_CLI;
  pid_t service = spawn({artisand, "--db", db, "--folder", "/cell", "--lcm-url", kUrl, "--snapshot-period", "0.5", "--poll-period", "0.2"});

  lcm::LCM lcm(kUrl);
  ASSERT_TRUE(lcm.good());
  {
    SceneClient client(lcm, "netns-client");
    ASSERT_TRUE(client.wait_for_scene(20));
    ASSERT_EQ(client.objects().size(), 3u);
    ASSERT_TRUE(client.objects().at(f.bunny).mesh);
    EXPECT_TRUE(*client.objects().at(f.bunny).mesh == f.bunny_mesh);

    // Garbage on every request channel; the service keeps answering.
    const std::vector<uint8_t> garbage(100, 0xAB);
    for (const char* ch : {kQueryChannel, kCommandChannel, kMeshRequestChannel}) lcm.publish(ch, garbage.data(), unsigned(garbage.size()));
    artisan::query_t q;
    q.type = artisan::query_t::RAYCAST;
    artisan::ray_t ray;
    ray.origin[0] = -0.3, ray.origin[1] = 0.3, ray.origin[2] = 1.0;
    ray.direction[0] = 0, ray.direction[1] = 0, ray.direction[2] = -1;
    ray.max_range = 5;
    q.rays = {ray};
    const auto r = client.query(q);
    ASSERT_TRUE(r.ok) << r.error;
    ASSERT_EQ(r.n_hits, 1);
    EXPECT_NEAR(r.hits[0].distance, 1.0, 1e-4);  // the floor
    EXPECT_EQ(r.hits[0].object_id, f.environment);
  }

  // The command-line client, in its own process.
  auto scene = test::run_command(cli + " --json teleop --lcm-url '" + kUrl + "' scene");
  ASSERT_EQ(scene.exit_code, 0) << scene.err;
  const auto objects = nlohmann::json::parse(scene.out)["objects"];
  ASSERT_EQ(objects.size(), 3u);
  for (const auto& o : objects) {  // the ambiguous one names its alternative and where it would be
    if (o["id"] != ambiguous) {
      EXPECT_FALSE(o["ambiguous"].get<bool>()) << o;
      EXPECT_FALSE(o.contains("alternative_model")) << o;
      continue;
    }
    EXPECT_TRUE(o["ambiguous"].get<bool>()) << o;
    EXPECT_EQ(o["alternative_model"], "pipe_350");
    const auto at = o["T_world_alternative"].get<std::vector<double>>();
    ASSERT_EQ(at.size(), 7u);
    const Eigen::Quaterniond q(T_world_alternative.rotation());
    const std::vector<double> expected = {-0.5, -0.6, 0.02, q.x(), q.y(), q.z(), q.w()};
    for (size_t k = 0; k < 7; ++k) EXPECT_NEAR(at[k], expected[k], 1e-9) << k;
  }
  const auto plain = test::run_command(cli + " teleop --lcm-url '" + kUrl + "' scene");
  ASSERT_EQ(plain.exit_code, 0) << plain.err;
  EXPECT_NE(plain.out.find("AMBIGUOUS (pipe_350 fits as well)"), std::string::npos) << plain.out;
  auto grasps = test::run_command(cli + " --json teleop --lcm-url '" + kUrl + "' grasps " + std::to_string(f.bunny));
  ASSERT_EQ(grasps.exit_code, 0) << grasps.err;
  EXPECT_EQ(nlohmann::json::parse(grasps.out).size(), 1u);
  auto unknown = test::run_command(cli + " teleop --lcm-url '" + kUrl + "' grasps 4242");
  EXPECT_EQ(unknown.exit_code, 1);
  EXPECT_NE(unknown.err.find("4242"), std::string::npos) << unknown.err;

  // The robot: in the scene with its joints, checked at other joints by the command-line client.
  EXPECT_EQ(nlohmann::json::parse(scene.out)["robots"][0]["joints"]["shoulder_lift_joint"], 0.0);
  const std::string check = cli + " --json teleop --lcm-url '" + kUrl + "' check ";
  auto down = test::run_command(check + "--joints shoulder_lift_joint=1.5708");  // the arm down through the floor
  ASSERT_EQ(down.exit_code, 0) << down.err;
  auto j = nlohmann::json::parse(down.out);
  EXPECT_TRUE(j["in_collision"]);
  ASSERT_GE(j["contacts"].size(), 1u);
  EXPECT_EQ(j["contacts"][0]["shape"].get<std::string>().rfind("ur5/", 0), 0u) << down.out;
  EXPECT_EQ(j["contacts"][0]["object_id"], f.environment);
  auto allowed = test::run_command(check + "--joints shoulder_lift_joint=1.5708 --allow '*@" + std::to_string(f.environment) + "'");
  ASSERT_EQ(allowed.exit_code, 0) << allowed.err;
  EXPECT_FALSE(nlohmann::json::parse(allowed.out)["in_collision"]);
  auto straight = test::run_command(check + "--robot ur5");
  ASSERT_EQ(straight.exit_code, 0) << straight.err;
  j = nlohmann::json::parse(straight.out);
  EXPECT_FALSE(j["in_collision"]);
  EXPECT_GT(j["clearance_m"].get<double>(), 0.0);
  EXPECT_EQ(j["closest"]["shape"].get<std::string>().rfind("ur5/", 0), 0u) << straight.out;
  auto bad_joint = test::run_command(check + "--joints elbow=1");
  EXPECT_EQ(bad_joint.exit_code, 1);
  EXPECT_NE(bad_joint.err.find("'elbow'"), std::string::npos) << bad_joint.err;

  // Record a session with lcm-logger while the operator corrects a pose.
  const auto log = (dir / "session.lcm").string();
  pid_t logger = spawn({"lcm-logger", "-f", "--lcm-url=" + kUrl, log});
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  auto correct = test::run_command(cli + " teleop --lcm-url '" + kUrl + "' --author alice correct " + std::to_string(f.bunny) +
                                   " --pose '-0.2 0.2 0 0 0 0 1'");
  ASSERT_EQ(correct.exit_code, 0) << correct.err;
  {
    SceneClient late(lcm, "late-client");  // joins late: fetches the meshes too (recorded)
    ASSERT_TRUE(late.wait_for_scene(20));
    EXPECT_EQ(late.objects().at(f.bunny).info.status, "corrected");
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(700));
  EXPECT_EQ(stop(logger, SIGINT), 0);
  EXPECT_EQ(stop(service), 0);  // clean shutdown on SIGTERM

  // Replay the log into a client with no service running: it rebuilds the corrected scene.
  {
    SceneClient replayed(lcm, "replay-client");
    pid_t player = spawn({"lcm-logplayer", "--lcm-url=" + kUrl, log});
    ASSERT_TRUE(replayed.wait_for_scene(20, false));  // meshes too only if UDP did not drop chunks
    const auto end = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (replayed.objects().at(f.bunny).info.status != "corrected" && std::chrono::steady_clock::now() < end) replayed.pump(50);
    EXPECT_EQ(replayed.objects().at(f.bunny).info.status, "corrected");
    EXPECT_NEAR(replayed.objects().at(f.bunny).T_world_object.translation().x(), -0.2, 1e-9);
    stop(player);
  }

  // Restart: the same state from the workspace (in real time, as a robot cell would run it,
  // when this process may: the namespace test runs as root).
  std::vector<std::string> restart = {artisand, "--db", db, "--folder", "/cell", "--lcm-url", kUrl, "--snapshot-period", "0.5"};
  if (::geteuid() == 0) restart.insert(restart.end(), {"--realtime", "10"});
  service = spawn(restart);
  {
    SceneClient again(lcm, "after-restart");
    ASSERT_TRUE(again.wait_for_scene(20));
    EXPECT_EQ(again.objects().at(f.bunny).info.status, "corrected");
    EXPECT_NEAR(again.objects().at(f.bunny).T_world_object.translation().x(), -0.2, 1e-9);
  }
  EXPECT_EQ(stop(service), 0);

  // Bad input: no workspace, no folder.
  EXPECT_EQ(test::run_command(artisand + " --db " + (dir / "missing.db").string() + " --lcm-url '" + kUrl + "'").exit_code, 1);
  EXPECT_EQ(test::run_command(artisand + " --db " + db + " --folder /nowhere --lcm-url '" + kUrl + "'").exit_code, 1);
  const auto bad_priority = test::run_command(artisand + " --db " + db + " --realtime 100 --lcm-url '" + kUrl + "'");
  EXPECT_EQ(bad_priority.exit_code, 2);
  EXPECT_NE(bad_priority.err.find("--realtime"), std::string::npos) << bad_priority.err;
}

}  // namespace
}  // namespace artisan::teleop
