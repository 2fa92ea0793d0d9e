// `artisan teleop ...`: a sample teleoperation client of the world-model service (artisand):
// shows the scene (with the robots' joint values), lists grasp approaches of an object checked
// for collision, checks a shape at a pose or the robot at joint values, and sends the operator's
// edits. Everything goes over LCM; the workspace is not opened.
#include <cstdlib>
#include <iomanip>
#include <iostream>
#include <sstream>

#include "artisan/core/error.hpp"
#include "artisan/teleop_bridge/channels.hpp"
#include "artisan/teleop_bridge/client.hpp"
#include "commands.hpp"

namespace artisan::cli {
namespace {

using json = nlohmann::json;

struct TeleopOptions {
  std::string url = teleop::kDefaultLcmUrl;
  double timeout_s = 10.0;
  std::string author;
  std::string object, model, pose, link;
  std::vector<double> box, gripper = {0.08, 0.03, 0.10};
  std::string robot;
  std::vector<std::string> joints, allow;
  double sphere = 0.0, approach_m = 0.10;
};

artisan::pose_t to_pose(const Transform& T) {
  artisan::pose_t p;
  const Eigen::Quaterniond q(T.rotation());
  for (int k = 0; k < 3; ++k) p.position[k] = T.translation()[k];
  p.quaternion_xyzw[0] = q.x();
  p.quaternion_xyzw[1] = q.y();
  p.quaternion_xyzw[2] = q.z();
  p.quaternion_xyzw[3] = q.w();
  return p;
}

Transform teleop_pose(const artisan::pose_t& p) {
  Transform T = Transform::Identity();
  T.translation() = Eigen::Vector3d(p.position[0], p.position[1], p.position[2]);
  T.linear() = Eigen::Quaterniond(p.quaternion_xyzw[3], p.quaternion_xyzw[0], p.quaternion_xyzw[1], p.quaternion_xyzw[2]).normalized().toRotationMatrix();
  return T;
}

json pose_json(const Transform& T) {
  const Eigen::Quaterniond q(T.rotation());
  return {T.translation().x(), T.translation().y(), T.translation().z(), q.x(), q.y(), q.z(), q.w()};
}

std::string where(const Transform& T) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(3) << "(" << T.translation().x() << ", " << T.translation().y() << ", " << T.translation().z() << ") m";
  return s.str();
}

// The client and a connected scene (meshes not needed for the commands here).
struct Session {
  lcm::LCM lcm;
  teleop::SceneClient client;
  Session(const TeleopOptions& o) : lcm(o.url), client(lcm, "artisan-teleop-" + std::to_string(::getpid())) {
    if (!lcm.good()) throw Error("cannot open LCM at " + o.url);
    if (!client.wait_for_scene(o.timeout_s, false))
      throw Error("no world-model service answered on " + o.url + " within " + std::to_string(o.timeout_s) + " s (is artisand running?)");
  }
  const teleop::RemoteObject& object(const std::string& name) const {
    for (const auto& [id, o] : client.objects())
      if (std::to_string(id) == name || o.info.path == name) return o;
    throw Error("the scene has no object '" + name + "' (give its ID or path; `artisan teleop scene` lists them)");
  }
  std::string path_of(int64_t id) const {
    auto it = client.objects().find(id);
    return it == client.objects().end() ? std::to_string(id) : it->second.info.path;
  }
};

std::string author_of(const TeleopOptions& o) {
  if (!o.author.empty()) return o.author;
  const char* user = std::getenv("USER");
  return user ? user : "operator";
}

artisan::shape_t box_shape(const std::string& name, const std::vector<double>& size, const Transform& T) {
  artisan::shape_t s;
  s.name = name;
  s.kind = artisan::shape_t::BOX;
  for (int k = 0; k < 3; ++k) s.dims[k] = size[size_t(k)];
  s.pose = to_pose(T);
  return s;
}

}  // namespace

void add_teleop_commands(CLI::App& app, const GlobalOptions& options, Action& action) {
  auto o = std::make_shared<TeleopOptions>();
  auto* teleop = app.add_subcommand("teleop", "Sample teleoperation client of the world-model service (artisand)");
  teleop->require_subcommand(1);
  teleop->add_option("--lcm-url", o->url, "LCM URL")->envname("LCM_DEFAULT_URL")->capture_default_str();
  teleop->add_option("--timeout", o->timeout_s, "Seconds to wait for the service")->capture_default_str();
  teleop->add_option("--author", o->author, "Who makes an edit (default: $USER)");

  auto* scene = teleop->add_subcommand("scene", "Show the scene: environment and recognized objects with poses");
  scene->callback([&, o] {
    action = [&, o] {
      Session s(*o);
      json out = {{"service", s.client.service_id()}, {"folder", s.client.folder()}, {"revision", s.client.revision()}, {"objects", json::array()}};
      for (const auto& [id, obj] : s.client.objects()) {
        const auto& i = obj.info;
        json grasps = json::array();
        for (const auto& g : obj.T_world_grasps) grasps.push_back(pose_json(g));
        out["objects"].push_back({{"id", id}, {"path", i.path}, {"kind", i.kind}, {"model", i.model}, {"version", i.version},
                                  {"status", i.status}, {"T_world_object", pose_json(obj.T_world_object)}, {"score", i.score},
                                  {"overlap", i.overlap}, {"ambiguous", i.ambiguous != 0}, {"triangles", i.mesh.n_triangles},
                                  {"grasps", grasps}, {"attached_to", i.attached_to}});
        if (i.ambiguous) {
          out["objects"].back()["alternative_model"] = i.alternative_model;
          out["objects"].back()["T_world_alternative"] = pose_json(obj.T_world_alternative);
        }
      }
      out["robots"] = json::array();
      for (const auto& r : s.client.robots()) {
        json joints = json::object();
        for (size_t k = 0; k < r.joint_names.size(); ++k) joints[r.joint_names[k]] = r.joint_values[k];
        json links = json::object();
        for (size_t k = 0; k < r.link_names.size(); ++k) links[r.link_names[k]] = pose_json(teleop_pose(r.link_poses[k]));
        out["robots"].push_back({{"id", r.object_id}, {"name", r.name}, {"path", r.path}, {"version", r.version},
                                 {"T_world_root", pose_json(teleop_pose(r.root_pose))}, {"joints", joints}, {"T_world_links", links}});
      }
      if (options.json) {
        std::cout << out.dump(2) << "\n";
        return 0;
      }
      std::cout << "scene of " << s.client.folder() << " (revision " << s.client.revision() << ", " << s.client.objects().size() << " objects)\n";
      for (const auto& [id, obj] : s.client.objects()) {
        const auto& i = obj.info;
        std::cout << "  " << std::setw(6) << id << "  " << i.path << "  ";
        if (i.kind == "environment") std::cout << "environment, " << i.mesh.n_triangles << " triangles\n";
        else
          std::cout << i.model << " at " << where(obj.T_world_object) << ", " << i.status << ", score " << std::setprecision(3) << i.score
                    << ", " << obj.T_world_grasps.size() << " grasp(s)" << (!i.ambiguous ? ""
                        : i.alternative_model == i.model || i.alternative_model.empty() ? ", AMBIGUOUS (another pose fits as well)"
                        : ", AMBIGUOUS (" + i.alternative_model + " fits as well)")
                    << (i.attached_to.empty() ? "" : ", attached to " + i.attached_to) << "\n";
      }
      for (const auto& r : s.client.robots()) {
        std::cout << "  " << std::setw(6) << r.object_id << "  " << r.path << "  robot " << r.name << " (version " << r.version << ") at "
                  << where(teleop_pose(r.root_pose)) << ":";
        for (size_t k = 0; k < r.joint_names.size(); ++k) std::cout << " " << r.joint_names[k] << "=" << std::setprecision(4) << r.joint_values[k];
        std::cout << "\n";
      }
      return 0;
    };
  });

  auto* grasps = teleop->add_subcommand("grasps", "Grasp approaches of an object, each checked for collision");
  grasps->add_option("object", o->object, "Object ID or path")->required();
  grasps->add_option("--gripper", o->gripper, "Gripper box size x y z [m]; it reaches back along -z of the grasp frame")->expected(3);
  grasps->add_option("--approach", o->approach_m, "Pre-grasp distance back along the approach axis [m]")->capture_default_str();
  grasps->callback([&, o] {
    action = [&, o] {
      Session s(*o);
      const auto& obj = s.object(o->object);
      if (obj.T_world_grasps.empty()) throw Error(obj.info.path + " has no grasp frames (import its model with --grasp)");
      json out = json::array();
      int usable = 0;
      for (size_t k = 0; k < obj.T_world_grasps.size(); ++k) {
        const Transform T_grasp = obj.T_world_grasps[k];
        const Transform T_body = T_grasp * Eigen::Translation3d(0, 0, -o->gripper[2] / 2);
        const Transform T_pre = T_grasp * Eigen::Translation3d(0, 0, -o->approach_m);
        artisan::query_t q;
        q.type = artisan::query_t::COLLISION;
        q.shapes = {box_shape("gripper", o->gripper, T_body)};
        artisan::allowed_pair_t touch;  // the gripper may touch what it grasps
        touch.shape = "gripper";
        touch.object_id = obj.info.object_id;
        q.allowed = {touch};
        const auto at_grasp = s.client.query(q, o->timeout_s);
        q.shapes = {box_shape("pregrasp", o->gripper, T_pre * Eigen::Translation3d(0, 0, -o->gripper[2] / 2))};
        q.allowed.clear();
        const auto at_pre = s.client.query(q, o->timeout_s);
        artisan::query_t d;
        d.type = artisan::query_t::DISTANCE;
        d.max_distance = 1.0;
        d.shapes = {box_shape("pregrasp", o->gripper, T_pre * Eigen::Translation3d(0, 0, -o->gripper[2] / 2))};
        const auto clearance = s.client.query(d, o->timeout_s);
        if (!at_grasp.ok || !at_pre.ok || !clearance.ok) throw Error("the service refused the query: " + at_grasp.error + at_pre.error + clearance.error);
        std::vector<std::string> blockers;
        for (const auto& c : at_grasp.contacts) blockers.push_back(s.path_of(c.object_id));
        for (const auto& c : at_pre.contacts) blockers.push_back(s.path_of(c.object_id) + " (approach)");
        const bool ok = blockers.empty();
        usable += ok;
        out.push_back({{"grasp", k}, {"T_world_grasp", pose_json(T_grasp)}, {"free", ok}, {"blocked_by", blockers},
                       {"approach_clearance_m", clearance.min_distance}});
        if (!options.json) {
          std::cout << "grasp " << k << " at " << where(T_grasp) << ": " << (ok ? "free" : "BLOCKED");
          for (const auto& b : blockers) std::cout << " by " << b;
          std::cout << ", approach clearance " << std::fixed << std::setprecision(1) << clearance.min_distance * 1000 << " mm\n";
        }
      }
      if (options.json) std::cout << out.dump(2) << "\n";
      else std::cout << usable << " of " << obj.T_world_grasps.size() << " grasp(s) of " << obj.info.path << " are free\n";
      return 0;
    };
  });

  auto* check = teleop->add_subcommand("check", "Check a box or sphere at a pose, or a robot at joint values, for collision and clearance");
  auto* box_opt = check->add_option("--box", o->box, "Box size x y z [m]")->expected(3);
  auto* sphere_opt = check->add_option("--sphere", o->sphere, "Sphere radius [m]");
  box_opt->excludes(sphere_opt);
  check->add_option("--pose", o->pose, "T_world_shape of the box or sphere: \"tx ty tz qx qy qz qw\" or 16 numbers");
  check->add_option("--joints", o->joints, "The robot at these joint values: NAME=VALUE ... [rad or m]; joints not given keep their current values");
  check->add_option("--robot", o->robot, "Which robot (default: the scene's only robot); alone: the robot at its current joints");
  check->add_option("--allow", o->allow, "A contact that does not count: SHAPE[@OBJECT] (SHAPE e.g. ur5/base_link or *, OBJECT an ID or path)");
  check->callback([&, o] {
    action = [&, o] {
      const bool with_shape = !o->box.empty() || o->sphere > 0, with_robot = !o->joints.empty() || !o->robot.empty();
      if (!with_shape && !with_robot) throw Error("give --box SX SY SZ or --sphere R (with --pose), or --joints NAME=VALUE ... for the robot");
      if (with_shape && o->pose.empty()) throw Error("--box and --sphere need --pose");
      const auto joints = parse_joint_values(o->joints, "--joints");
      const Transform T = o->pose.empty() ? Transform::Identity() : parse_transform(o->pose);
      Session s(*o);
      artisan::query_t q;
      q.type = artisan::query_t::COLLISION;
      if (!o->box.empty()) q.shapes = {box_shape("shape", o->box, T)};
      else if (o->sphere > 0) {
        artisan::shape_t shape;
        shape.name = "shape";
        shape.kind = artisan::shape_t::SPHERE;
        shape.dims[0] = o->sphere;
        shape.pose = to_pose(T);
        q.shapes = {shape};
      }
      if (with_robot) teleop::SceneClient::set_robot(q, o->robot, joints);
      for (const auto& a : o->allow) {
        artisan::allowed_pair_t pair;
        const auto at = a.find('@');
        pair.shape = a.substr(0, at);
        pair.object_id = at == std::string::npos ? -1 : s.object(a.substr(at + 1)).info.object_id;
        if (pair.shape.empty()) throw Error("--allow '" + a + "': name the shape (or *) before @");
        q.allowed.push_back(pair);
      }
      const auto c = s.client.query(q, o->timeout_s);
      if (!c.ok) throw Error("the service refused the query: " + c.error);
      q.type = artisan::query_t::DISTANCE;
      q.max_distance = 1.0;
      const auto d = s.client.query(q, o->timeout_s);
      if (!d.ok) throw Error("the service refused the query: " + d.error);
      std::vector<std::string> hits;
      json contacts = json::array();
      for (const auto& x : c.contacts) {
        hits.push_back(s.path_of(x.object_id));
        contacts.push_back({{"shape", x.shape}, {"object", s.path_of(x.object_id)}, {"object_id", x.object_id}, {"depth_m", -x.distance}});
      }
      if (options.json) {
        json closest = nullptr;
        if (d.n_contacts)
          closest = {{"shape", d.contacts[0].shape}, {"object", s.path_of(d.contacts[0].object_id)}, {"object_id", d.contacts[0].object_id}};
        json out = {{"in_collision", c.in_collision != 0}, {"colliding_with", hits}, {"contacts", contacts}, {"clearance_m", d.min_distance},
                    {"closest", closest}, {"revision", c.revision}, {"service_seconds", c.seconds}};
        if (with_robot) {
          json j = json::object();
          for (const auto& [k, v] : joints) j[k] = v;
          out["robot"] = {{"name", o->robot.empty() ? json(nullptr) : json(o->robot)}, {"joints", j}};
        }
        std::cout << out.dump(2) << "\n";
      } else if (c.in_collision) {
        std::cout << "COLLISION:";
        for (const auto& x : c.contacts) std::cout << " " << x.shape << " with " << s.path_of(x.object_id) << ";";
        std::cout << "\n";
      } else {
        std::cout << "free, clearance " << std::fixed << std::setprecision(1) << d.min_distance * 1000 << " mm"
                  << (d.n_contacts ? " (" + d.contacts[0].shape + " to " + s.path_of(d.contacts[0].object_id) + ")" : "") << "\n";
      }
      return 0;
    };
  });

  // Edits: each is stored by the service as a new version with author and time.
  struct Edit {
    const char* name;
    const char* help;
    int8_t type;
    bool needs_object, needs_pose, needs_link, needs_model;
  };
  static const Edit edits[] = {
      {"correct", "Correct an object's pose", artisan::command_t::CORRECT_POSE, true, true, false, false},
      {"accept", "Accept a recognized pose", artisan::command_t::ACCEPT_POSE, true, false, false, false},
      {"delete", "Delete an object from the scene (kept as a version)", artisan::command_t::DELETE, true, false, false, false},
      {"attach", "Attach an object to a robot link", artisan::command_t::ATTACH, true, false, true, false},
      {"detach", "Detach an object", artisan::command_t::DETACH, true, false, false, false},
      {"add", "Add an object of a model at a pose", artisan::command_t::ADD, false, true, false, true},
      {"rerecognize", "Run recognition again on the environment", artisan::command_t::RERECOGNIZE, false, false, false, false},
  };
  for (const auto& e : edits) {
    auto* cmd = teleop->add_subcommand(e.name, e.help);
    if (e.needs_object) cmd->add_option("object", o->object, "Object ID or path")->required();
    if (e.needs_model) cmd->add_option("model", o->model, "Model name or path")->required();
    if (e.needs_pose) cmd->add_option("--pose", o->pose, "T_world_object: \"tx ty tz qx qy qz qw\" or 16 numbers")->required();
    if (e.needs_link) {
      cmd->add_option("--link", o->link, "The link, e.g. ur5/tool0")->required();
      cmd->add_option("--pose", o->pose, "T_link_object (default: identity)");
    }
    cmd->callback([&, o, e] {
      action = [&, o, e] {
        Session s(*o);
        artisan::command_t c;
        c.type = e.type;
        c.author = author_of(*o);
        c.object_id = e.needs_object ? s.object(o->object).info.object_id : -1;
        c.model = o->model;
        c.attach_to = o->link;
        c.pose = to_pose(o->pose.empty() ? Transform::Identity() : parse_transform(o->pose));
        const auto r = s.client.command(c, std::max(o->timeout_s, 60.0));
        if (!r.ok) throw Error("the world-model service refused: " + r.message);
        if (options.json) std::cout << json{{"ok", true}, {"message", r.message}, {"object_id", r.object_id}, {"revision", r.revision}}.dump(2) << "\n";
        else if (!options.quiet) std::cerr << r.message << " (scene revision " << r.revision << ")\n";
        return 0;
      };
    });
  }
}

}  // namespace artisan::cli
