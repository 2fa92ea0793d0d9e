// World-model service: collision-query latency (median, p99) for a gripper and for a six-joint
// arm (the UR5 of the pipework workcell, convex hulls of its collision meshes) against a
// 1-million-triangle environment with 20 recognized objects; sustained queries per second; and
// over LCM (memq://, in process): query round trip, the time from an operator's change to a
// client seeing it, and to the client seeing the environment re-cut around it (the second diff).
// Also ray casts, the arm's boolean check (stop at first) and its distance. JSON on stdout.
#include <algorithm>
#include <chrono>
#include <iostream>
#include <random>

#include <nlohmann/json.hpp>

#include "artisan/core/io/mesh_io.hpp"
#include "artisan/core/scheduling.hpp"
#include "artisan/sim/workcell.hpp"
#include "artisan/teleop_bridge/client.hpp"
#include "artisan/teleop_bridge/service.hpp"
#include "artisan/worldmodel/collision_scene.hpp"
#include "artisan/worldmodel/world_model.hpp"

namespace {

using namespace artisan;
using Clock = std::chrono::steady_clock;
using nlohmann::json;

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

json latency(std::vector<double> s) {
  std::sort(s.begin(), s.end());
  const auto at = [&](double q) { return s[std::min(s.size() - 1, size_t(q * double(s.size())))] * 1e3; };
  return {{"n", s.size()}, {"median_ms", at(0.5)}, {"p99_ms", at(0.99)}, {"max_ms", s.back() * 1e3}};
}

// A bumpy floor of about 1 million triangles over [-1.5, 1.5]² m.
TriangleMesh environment_mesh() {
  const int n = 707;
  TriangleMesh m;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const float x = -1.5f + 3.0f * float(i) / float(n), y = -1.5f + 3.0f * float(j) / float(n);
      m.vertices.emplace_back(x, y, 0.01f * std::sin(7 * x) * std::cos(5 * y));
    }
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i;
      m.faces.emplace_back(a, a + 1, a + n + 2);
      m.faces.emplace_back(a, a + n + 2, a + n + 1);
    }
  m.compute_vertex_normals();
  return m;
}

}  // namespace

int main(int argc, char** argv) {
  // --changes N: operator changes timed through the service; --realtime P: the service's thread
  // under SCHED_FIFO at priority P with memory locked (artisand --realtime P); --lcm-only: skip
  // the collision scene's own benchmarks.
  int n_changes = 300, realtime_priority = 0;
  bool lcm_only = false;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--changes" && i + 1 < argc) n_changes = std::stoi(argv[++i]);
    else if (a == "--realtime" && i + 1 < argc) realtime_priority = std::stoi(argv[++i]);
    else if (a == "--lcm-only") lcm_only = true;
    else {
      std::cerr << "bench_worldmodel: unknown argument '" << a << "' (expected --changes N, --realtime P, --lcm-only)\n";
      return 2;
    }
  }
  const std::string data = ARTISAN_DATA_DIR;
  json out;
  const auto bunny = io::read_mesh(data + "/stanford-bunny/reconstruction/bun_zipper.ply");
  const float base = bunny.bounds().min().y();
  std::vector<Transform> poses;
  for (int k = 0; k < 20; ++k)
    poses.push_back(Transform(Eigen::Translation3d(-1.2 + 0.6 * (k % 5), -1.2 + 0.8 * (k / 5), 0.0)) *
                    Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitX()) * Eigen::AngleAxisd(0.3 * k, Eigen::Vector3d::UnitY()) *
                    Eigen::Translation3d(0, -base, 0));

  // --- the collision scene alone ---------------------------------------------------------------
  auto env = std::make_shared<const TriangleMesh>(environment_mesh());
  auto model = std::make_shared<const TriangleMesh>(bunny);
  worldmodel::CollisionScene scene;
  auto t0 = Clock::now();
  scene.set_body(0, env, Transform::Identity());
  const double env_build_s = seconds_since(t0);
  t0 = Clock::now();
  for (int k = 0; k < 20; ++k) scene.set_body(k + 1, model, poses[size_t(k)]);
  const double objects_build_s = seconds_since(t0);
  out["scene"] = {{"environment_triangles", env->faces.size()}, {"objects", 20}, {"object_triangles", model->faces.size()},
                  {"total_triangles", scene.triangle_count()}, {"environment_bvh_build_s", env_build_s},
                  {"objects_build_s", objects_build_s}};

  std::mt19937 rng(7);
  std::uniform_real_distribution<double> ux(-1.4, 1.4), uz(0.0, 0.3), ua(-M_PI, M_PI);
  auto gripper_at_random = [&] {
    worldmodel::QueryShape g;
    g.name = "gripper";
    g.kind = worldmodel::QueryShape::Kind::box;
    g.size = {0.08, 0.03, 0.10};
    g.T_world_shape = Transform(Eigen::Translation3d(ux(rng), ux(rng), uz(rng))) *
                      Eigen::AngleAxisd(ua(rng), Eigen::Vector3d(ux(rng), ux(rng), 1).normalized());
    return g;
  };
  if (!lcm_only) {
    std::vector<double> check_s, distance_s;
    int collisions = 0;
    for (int i = 0; i < 2000; ++i) {
      const auto g = gripper_at_random();
      auto t = Clock::now();
      collisions += scene.check({g}).in_collision;
      check_s.push_back(seconds_since(t));
      t = Clock::now();
      scene.distance({g}, 0.2);
      distance_s.push_back(seconds_since(t));
    }
    out["gripper"] = {{"collision", latency(check_s)}, {"distance_0.2m", latency(distance_s)}, {"in_collision_fraction", collisions / 2000.0}};

    // Sustained collision queries per second, one core.
    // (its own random numbers, so the arm's configurations below do not depend on the timing)
    const auto rng_state = rng;
    t0 = Clock::now();
    int queries = 0;
    while (seconds_since(t0) < 2.0) {
      scene.check({gripper_at_random()});
      ++queries;
    }
    out["gripper"]["queries_per_s"] = queries / seconds_since(t0);
    rng = rng_state;

    // Ray casts straight down onto the scene.
    std::vector<double> ray_s;
    for (int i = 0; i < 2000; ++i) {
      const Eigen::Vector3d o(ux(rng), ux(rng), 0.5);
      const auto t = Clock::now();
      scene.raycast(o, {0, 0, -1}, 2.0);
      ray_s.push_back(seconds_since(t));
    }
    out["raycast"] = latency(ray_s);

    // The UR5: convex hulls of its collision meshes at random joint values within limits.
    auto cell = sim::load_workcell(data + "/workcells/pipework.json");
    auto& robot = cell.robot("ur5");
    std::vector<const sim::Body*> links;
    for (const auto& b : cell.bodies)
      if (b.role == sim::BodyRole::robot_link && b.robot == "ur5") links.push_back(&b);
    const Transform T_world_root = Transform(Eigen::Translation3d(0, 0, 0.02));
    std::vector<double> arm_s, arm_any_s, arm_distance_s;
    int arm_collisions = 0, arm_disagree = 0;
    size_t hull_points = 0;
    for (int i = 0; i < 1000; ++i) {
      for (auto& j : robot.joints)
        if (j.type == sim::JointSpec::Type::revolute)
          robot.joint_values[j.name] = std::uniform_real_distribution<double>(std::max(j.lower, -M_PI), std::min(j.upper, M_PI))(rng);
      const auto link_poses = robot.link_poses();
      std::vector<worldmodel::QueryShape> shapes;
      for (const auto* b : links) {
        worldmodel::QueryShape s;
        s.name = b->link;
        s.kind = worldmodel::QueryShape::Kind::convex_hull;
        s.points = b->mesh.vertices;
        s.T_world_shape = T_world_root * robot.T_world_root.inverse() * link_poses.at(b->link) * b->T_link_body;
        hull_points += s.points.size();
        shapes.push_back(std::move(s));
      }
      // The base stands on the floor: that contact is allowed.
      const std::vector<worldmodel::AllowedPair> allowed = {{"base_link", 0}, {"shoulder_link", 0}};
      auto t = Clock::now();
      const bool hit = scene.check(shapes, allowed).in_collision;
      arm_s.push_back(seconds_since(t));
      arm_collisions += hit;
      // A planner's boolean check: stop at the first colliding link.
      t = Clock::now();
      const bool any = scene.check(shapes, allowed, {.deepest_contacts = false, .stop_at_first = true}).in_collision;
      arm_any_s.push_back(seconds_since(t));
      if (any != hit) ++arm_disagree;
      t = Clock::now();
      scene.distance(shapes, 0.2, allowed);
      arm_distance_s.push_back(seconds_since(t));
    }
    out["arm"] = {{"robot", "ur5"}, {"links", links.size()}, {"hull_points_per_link", hull_points / 1000 / std::max<size_t>(1, links.size())},
                  {"collision", latency(arm_s)}, {"collision_stop_at_first", latency(arm_any_s)},
                  {"distance_0.2m", latency(arm_distance_s)}, {"in_collision_fraction", arm_collisions / 1000.0},
                  {"stop_at_first_disagreements", arm_disagree}};
  }

  // --- through the service over LCM (memq://) -----------------------------------------------
  const auto dir = std::filesystem::temp_directory_path() / ("artisan-bench-wm-" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  {
    auto ws = worldmodel::Workspace::create(dir / "ws.db");
    TriangleMesh whole = *env;
    for (const auto& T : poses) {
      TriangleMesh b = bunny;
      b.transform(T);
      whole.append(b);
    }
    const auto cell_folder = ws.mkdir("/cell");
    const auto merged = ws.add(cell_folder, worldmodel::make_mesh_object(worldmodel::ObjectKind::kMesh, "merged", "merged", whole, {"merge", {}, {}}));
    const auto model_id = ws.add(ws.root(), worldmodel::make_mesh_object(worldmodel::ObjectKind::kModel, "", "bunny", bunny, {"import", {}, {}}));
    ws.write([&] {
      for (size_t k = 0; k < poses.size(); ++k) {
        worldmodel::NewObject r;
        r.kind = worldmodel::ObjectKind::kRecognizedModel;
        r.subkind = "bunny";
        r.name = "bunny-" + std::to_string(k + 1);
        r.metadata = {{"model_id", model_id}, {"T_scene_model", to_row_major(poses[k])}, {"figures", {{"score", 1.0}}}};
        r.provenance = worldmodel::Provenance{"recognize", {}, {merged, model_id}};
        ws.add(cell_folder, r);
      }
    });
    lcm::LCM lcm("memq://");
    if (realtime_priority) run_in_realtime(realtime_priority);
    t0 = Clock::now();
    teleop::ServiceOptions options;
    options.folder = "/cell";
    teleop::Service service(ws, lcm, options);
    const double start_s = seconds_since(t0);
    teleop::SceneClient client(lcm, "bench", [&](int ms) {
      lcm.handleTimeout(ms);
      service.tick();
    });
    t0 = Clock::now();
    const bool got = client.wait_for_scene(60);
    const double join_s = seconds_since(t0);
    std::vector<double> rtt;
    for (int i = 0; i < 500; ++i) {
      const auto g = gripper_at_random();
      artisan::query_t q;
      q.type = artisan::query_t::COLLISION;
      artisan::shape_t s;
      s.name = g.name;
      s.kind = artisan::shape_t::BOX;
      for (int k = 0; k < 3; ++k) s.dims[k] = g.size[k];
      const Eigen::Quaterniond qr(g.T_world_shape.rotation());
      for (int k = 0; k < 3; ++k) s.pose.position[k] = g.T_world_shape.translation()[k];
      s.pose.quaternion_xyzw[0] = qr.x(), s.pose.quaternion_xyzw[1] = qr.y(), s.pose.quaternion_xyzw[2] = qr.z(), s.pose.quaternion_xyzw[3] = qr.w();
      q.shapes = {s};
      const auto t = Clock::now();
      client.query(q);
      rtt.push_back(seconds_since(t));
    }
    // An operator moves an object: time until another client has the diff.
    std::vector<double> change_s, environment_s;
    const auto first = client.objects().rbegin()->first;
    // After every 10th change the client also waits for the environment's re-cut (the other
    // changes land while a re-cut runs in the background, as they would in use).
    for (int i = 0; i < n_changes; ++i) {
      artisan::command_t c;
      c.type = artisan::command_t::CORRECT_POSE;
      c.author = "bench";
      c.object_id = first;
      const Transform T = Transform(Eigen::Translation3d(0.002 * (i % 30), 0, 0)) * poses.back();
      const Eigen::Quaterniond qr(T.rotation());
      for (int k = 0; k < 3; ++k) c.pose.position[k] = T.translation()[k];
      c.pose.quaternion_xyzw[0] = qr.x(), c.pose.quaternion_xyzw[1] = qr.y(), c.pose.quaternion_xyzw[2] = qr.z(), c.pose.quaternion_xyzw[3] = qr.w();
      const auto t = Clock::now();
      const auto r = client.command(c, 120);
      client.wait_for_revision(r.revision, 60);
      change_s.push_back(seconds_since(t));
      // The environment's re-cut follows as a diff of its own (the next revision).
      if (i % 10 != 9) continue;
      while (client.revision() <= r.revision && seconds_since(t) < 60) client.pump(5);
      environment_s.push_back(seconds_since(t));
    }
    out["lcm_memq"] = {{"service_start_s", start_s}, {"late_join_with_meshes_s", join_s}, {"scene_complete", got},
                       {"meshes_fetched", client.meshes_fetched()}, {"query_round_trip", latency(rtt)},
                       {"realtime_priority", realtime_priority}, {"change_to_client", latency(change_s)},
                       {"changes_over_5ms", std::count_if(change_s.begin(), change_s.end(), [](double x) { return x > 5e-3; })}, {"environment_recut_to_client", latency(environment_s)}};
  }
  std::filesystem::remove_all(dir);
  out["goals"] = {{"collision_p99_ms", 1.0}, {"change_to_client_ms", 5.0}};
  std::cout << out.dump(2) << "\n";
  return 0;
}
