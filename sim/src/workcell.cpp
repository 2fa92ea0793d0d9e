#include "artisan/sim/workcell.hpp"

#include <fstream>
#include <numbers>
#include <set>
#include <sstream>

#include <nlohmann/json.hpp>
#include <urdf_parser/urdf_parser.h>

#include "artisan/core/error.hpp"
#include "artisan/core/io/mesh_io.hpp"
#include "artisan/sim/shapes.hpp"
#include "json_util.hpp"

namespace artisan::sim {

namespace fs = std::filesystem;
using nlohmann::json;

const char* to_string(BodyRole role) {
  switch (role) {
    case BodyRole::structure: return "structure";
    case BodyRole::object: return "object";
    case BodyRole::robot_link: return "robot_link";
  }
  return "?";
}

double ScalarField::value_at(const Eigen::Vector3d& p_world) const {
  double v = base + gradient.dot(p_world);
  for (const auto& s : spots) v += s.amplitude * std::exp(-(p_world - s.position_world).squaredNorm() / (2 * s.sigma_m * s.sigma_m));
  return v;
}

const JointSpec& Robot::joint(const std::string& joint_name) const {
  for (const auto& j : joints)
    if (j.name == joint_name) return j;
  throw Error("robot '" + name + "' (" + urdf.string() + ") has no joint '" + joint_name + "'");
}

std::map<std::string, Transform> Robot::link_poses() const {
  std::map<std::string, Transform> poses{{root_link, T_world_root}};
  // Joints in URDF order need not be topological: repeat until every child is placed.
  std::set<std::string> done;
  for (size_t pass = 0; pass <= joints.size() && done.size() < joints.size(); ++pass) {
    for (const auto& j : joints) {
      if (done.count(j.name) || !poses.count(j.parent_link)) continue;
      const auto it = joint_values.find(j.name);
      const double q = it == joint_values.end() ? 0.0 : it->second;
      Transform T_joint_child = Transform::Identity();
      if (j.type == JointSpec::Type::revolute || j.type == JointSpec::Type::continuous)
        T_joint_child.linear() = Eigen::AngleAxisd(q, j.axis).toRotationMatrix();
      else if (j.type == JointSpec::Type::prismatic)
        T_joint_child.translation() = q * j.axis;
      poses[j.child_link] = poses[j.parent_link] * j.T_parent_joint * T_joint_child;
      done.insert(j.name);
    }
  }
  return poses;
}

const SensorSpec& Workcell::sensor(const std::string& sensor_name) const {
  std::string known;
  for (const auto& s : sensors) {
    if (s.name == sensor_name) return s;
    known += (known.empty() ? "" : ", ") + s.name;
  }
  throw Error(source.string() + ": no sensor named '" + sensor_name + "' (sensors: " + (known.empty() ? "none" : known) + ")");
}

Robot& Workcell::robot(const std::string& robot_name) {
  return const_cast<Robot&>(static_cast<const Workcell&>(*this).robot(robot_name));
}

const Robot& Workcell::robot(const std::string& robot_name) const {
  for (const auto& r : robots)
    if (r.name == robot_name) return r;
  throw Error(source.string() + ": no robot named '" + robot_name + "'");
}

void Workcell::set_joint(const std::string& robot_name, const std::string& joint_name, double value) {
  Robot& r = robot(robot_name);
  const JointSpec& j = r.joint(joint_name);
  if (!std::isfinite(value)) throw Error("joint '" + joint_name + "' of '" + robot_name + "': value is not finite");
  if (j.type == JointSpec::Type::revolute || j.type == JointSpec::Type::prismatic) {
    if (value < j.lower - 1e-12 || value > j.upper + 1e-12) {
      std::ostringstream os;
      os << "joint '" << joint_name << "' of '" << robot_name << "': value " << value << " is beyond the limits ["
         << j.lower << ", " << j.upper << "] (" << r.urdf.string() << ")";
      throw Error(os.str());
    }
  }
  r.joint_values[joint_name] = value;
}

void Workcell::update_robot_poses() {
  std::map<std::string, std::map<std::string, Transform>> poses;
  for (const auto& r : robots) poses[r.name] = r.link_poses();
  for (auto& b : bodies) {
    if (b.role != BodyRole::robot_link) continue;
    b.T_world_body = poses.at(b.robot).at(b.link) * b.T_link_body;
  }
}

Transform Workcell::T_world_sensor(const SensorSpec& s) const {
  if (s.mount == "world") return s.T_mount_sensor;
  const auto slash = s.mount.find('/');
  if (slash == std::string::npos)
    throw Error(source.string() + ": sensor '" + s.name + "': mount '" + s.mount + "' is neither 'world' nor 'ROBOT/LINK'");
  const Robot& r = robot(s.mount.substr(0, slash));
  const auto poses = r.link_poses();
  const auto it = poses.find(s.mount.substr(slash + 1));
  if (it == poses.end()) throw Error(source.string() + ": sensor '" + s.name + "': robot has no link '" + s.mount + "'");
  return it->second * s.T_mount_sensor;
}

int Workcell::body_index(int instance_id) const {
  for (size_t i = 0; i < bodies.size(); ++i)
    if (bodies[i].instance_id == instance_id) return static_cast<int>(i);
  return -1;
}

namespace {

Transform urdf_pose(const urdf::Pose& p) {
  Transform T = Transform::Identity();
  T.translation() = Eigen::Vector3d(p.position.x, p.position.y, p.position.z);
  T.linear() = Eigen::Quaterniond(p.rotation.w, p.rotation.x, p.rotation.y, p.rotation.z).normalized().toRotationMatrix();
  return T;
}

struct Loader {
  fs::path file;
  fs::path dir;
  std::vector<fs::path> package_paths;
  std::map<std::string, TriangleMesh> mesh_cache;

  [[noreturn]] void fail(const std::string& field, const std::string& what) const {
    throw Error(file.string() + ": " + field + ": " + what);
  }

  TriangleMesh mesh_file(const fs::path& path, const std::string& field) {
    const auto key = path.lexically_normal().string();
    if (auto it = mesh_cache.find(key); it != mesh_cache.end()) return it->second;
    if (!fs::exists(path)) fail(field, "mesh file '" + path.string() + "' does not exist");
    TriangleMesh m = io::read_mesh(path);
    if (m.normals.size() != m.vertices.size()) m.compute_vertex_normals();
    mesh_cache[key] = m;
    return m;
  }

  fs::path resolve_package(const std::string& uri, const fs::path& base, const std::string& field) const {
    const std::string prefix = "package://";
    if (uri.rfind(prefix, 0) != 0) {
      fs::path p = uri.rfind("file://", 0) == 0 ? fs::path(uri.substr(7)) : fs::path(uri);
      return p.is_absolute() ? p : base / p;
    }
    const std::string rest = uri.substr(prefix.size());
    std::string tried;
    for (const auto& root : package_paths) {
      const fs::path candidate = root / rest;
      if (fs::exists(candidate)) return candidate;
      tried += " " + root.string();
    }
    fail(field, "cannot resolve '" + uri + "' in the package search path (" + (tried.empty() ? " empty" : tried) + ")");
  }

  Material material(const json& j, const std::string& field, Material m = {}) const {
    if (j.is_null()) return m;
    if (!j.is_object()) fail(field, "must be an object");
    if (j.contains("color")) m.color = vec3(j["color"], field + ".color", *this).cast<float>();
    if (j.contains("specular")) m.specular = static_cast<float>(number(j["specular"], field + ".specular", *this));
    if (j.contains("texture")) {
      const auto t = string(j["texture"], field + ".texture", *this);
      if (t != "noise" && t != "none") fail(field + ".texture", "'" + t + "' is not one of: noise, none");
      m.noise_texture = t == "noise";
    }
    if (j.contains("texture_scale_m")) m.texture_scale_m = static_cast<float>(positive(j["texture_scale_m"], field + ".texture_scale_m", *this));
    if (j.contains("use_vertex_colors")) m.use_vertex_colors = boolean(j["use_vertex_colors"], field + ".use_vertex_colors", *this);
    for (auto it = j.begin(); it != j.end(); ++it)
      if (!std::set<std::string>{"color", "specular", "texture", "texture_scale_m", "use_vertex_colors"}.count(it.key()))
        fail(field + "." + it.key(), "unknown field");
    return m;
  }

  // A primitive {"box": [sx, sy, sz]} | {"sphere": r} | {"cylinder": [r, length]} | a pipework
  // model {"pipe": length} | {"elbow": bend_radius} | {"tee": [run, branch]} |
  // {"flange": [diameter, thickness, neck]} | {"valve": length}; "outer_diameter_m", "wall_m".
  void primitive(const json& j, const std::string& field, Body& b) const {
    if (!j.is_object()) fail(field, "must be an object such as {\"box\": [1, 1, 1]}");
    PipeSize pipe;
    if (j.contains("outer_diameter_m")) pipe.outer_diameter_m = positive(j["outer_diameter_m"], field + ".outer_diameter_m", *this);
    if (j.contains("wall_m")) pipe.wall_m = positive(j["wall_m"], field + ".wall_m", *this);
    auto nums = [&](const std::string& key, size_t n) {
      std::vector<double> v;
      if (j[key].is_number()) v.push_back(j[key].get<double>());
      else if (j[key].is_array()) for (const auto& x : j[key]) v.push_back(number(x, field + "." + key, *this));
      if (v.size() != n) fail(field + "." + key, "expects " + std::to_string(n) + " number(s), got " + j[key].dump());
      for (double x : v) if (!(x > 0)) fail(field + "." + key, "sizes must be positive, got " + j[key].dump());
      return v;
    };
    if (j.contains("box")) {
      const auto v = nums("box", 3);
      b.shape.kind = CollisionShape::Kind::box;
      b.shape.size = {v[0], v[1], v[2]};
      b.mesh = make_box(b.shape.size);
    } else if (j.contains("sphere")) {
      b.shape.kind = CollisionShape::Kind::sphere;
      b.shape.radius_m = nums("sphere", 1)[0];
      b.mesh = make_sphere(b.shape.radius_m, 48);
    } else if (j.contains("cylinder")) {
      const auto v = nums("cylinder", 2);
      b.shape.kind = CollisionShape::Kind::cylinder;
      b.shape.radius_m = v[0];
      b.shape.length_m = v[1];
      b.mesh = make_cylinder(v[0], v[1], 48);
    } else if (j.contains("pipe")) {
      b.mesh = make_pipe(nums("pipe", 1)[0], pipe);
    } else if (j.contains("elbow")) {
      b.mesh = make_elbow(nums("elbow", 1)[0], pipe);
    } else if (j.contains("tee")) {
      const auto v = nums("tee", 2);
      b.mesh = make_tee(v[0], v[1], pipe);
    } else if (j.contains("flange")) {
      const auto v = nums("flange", 3);
      b.mesh = make_flange(v[0], v[1], v[2], pipe);
    } else if (j.contains("valve")) {
      b.mesh = make_valve(nums("valve", 1)[0], pipe);
    } else {
      fail(field, "unknown primitive " + j.dump() + " (box, sphere, cylinder, pipe, elbow, tee, flange, valve)");
    }
  }

  Body body(const json& j, const std::string& field, BodyRole role) {
    if (!j.is_object()) fail(field, "must be an object");
    Body b;
    b.role = role;
    b.name = string(j.value("name", json()), field + ".name", *this);
    const std::set<std::string> known{"name", "model", "primitive", "mesh", "scale", "pose", "look_at", "material", "drop", "mass_kg"};
    for (auto it = j.begin(); it != j.end(); ++it)
      if (!known.count(it.key())) fail(field + "." + it.key(), "unknown field");
    if (j.contains("primitive") == j.contains("mesh")) fail(field, "needs exactly one of 'primitive' and 'mesh'");
    if (j.contains("primitive")) {
      primitive(j["primitive"], field + ".primitive", b);
    } else {
      const fs::path p = resolve_package(string(j["mesh"], field + ".mesh", *this), dir, field + ".mesh");
      b.mesh = mesh_file(p, field + ".mesh");
      if (!j.contains("scale")) b.model = p.stem().string();
      b.shape.kind = CollisionShape::Kind::mesh;
    }
    if (j.contains("scale")) {
      Eigen::Vector3d s;
      if (j["scale"].is_number()) s.setConstant(positive(j["scale"], field + ".scale", *this));
      else s = vec3(j["scale"], field + ".scale", *this);
      if (!(s.array() > 0).all()) fail(field + ".scale", "must be positive, got " + j["scale"].dump());
      if (b.shape.kind != CollisionShape::Kind::mesh) fail(field + ".scale", "applies to meshes; give a primitive its size instead");
      for (auto& v : b.mesh.vertices) v = v.cwiseProduct(s.cast<float>());
      b.mesh.compute_vertex_normals();
    }
    if (j.contains("model")) b.model = string(j["model"], field + ".model", *this);
    b.T_world_body = pose(j, field, *this);
    b.material = material(j.value("material", json()), field + ".material");
    if (j.contains("drop")) b.drop = boolean(j["drop"], field + ".drop", *this);
    if (b.drop && role != BodyRole::object) fail(field + ".drop", "only objects can be dropped");
    if (j.contains("mass_kg")) b.mass_kg = positive(j["mass_kg"], field + ".mass_kg", *this);
    b.mesh.validate();
    if (b.mesh.faces.empty()) fail(field, "has no triangles");
    return b;
  }

  JointSpec::Type joint_type(int t, const std::string& field) const {
    switch (t) {
      case urdf::Joint::REVOLUTE: return JointSpec::Type::revolute;
      case urdf::Joint::CONTINUOUS: return JointSpec::Type::continuous;
      case urdf::Joint::PRISMATIC: return JointSpec::Type::prismatic;
      case urdf::Joint::FIXED: return JointSpec::Type::fixed;
      default: fail(field, "joint type " + std::to_string(t) + " (floating/planar) is not supported");
    }
  }

  void robot(const json& j, const std::string& field, Workcell& cell) {
    if (!j.is_object()) fail(field, "must be an object");
    const std::set<std::string> known{"name", "urdf", "pose", "look_at", "joints", "geometry", "material"};
    for (auto it = j.begin(); it != j.end(); ++it)
      if (!known.count(it.key())) fail(field + "." + it.key(), "unknown field");
    Robot r;
    r.name = string(j.value("name", json()), field + ".name", *this);
    if (r.name.find('/') != std::string::npos) fail(field + ".name", "'" + r.name + "' must not contain '/'");
    r.urdf = resolve_package(string(j.value("urdf", json()), field + ".urdf", *this), dir, field + ".urdf");
    if (!fs::exists(r.urdf)) fail(field + ".urdf", "file '" + r.urdf.string() + "' does not exist");
    const auto model = urdf::parseURDFFile(r.urdf.string());
    if (!model) fail(field + ".urdf", "'" + r.urdf.string() + "' is not a valid URDF");
    r.root_link = model->getRoot()->name;
    r.T_world_root = pose(j, field, *this);
    for (const auto& [jname, jp] : model->joints_) {
      JointSpec js;
      js.name = jname;
      js.type = joint_type(jp->type, field + ".urdf joint " + jname);
      js.parent_link = jp->parent_link_name;
      js.child_link = jp->child_link_name;
      js.T_parent_joint = urdf_pose(jp->parent_to_joint_origin_transform);
      js.axis = Eigen::Vector3d(jp->axis.x, jp->axis.y, jp->axis.z);
      if (js.type != JointSpec::Type::fixed) {
        if (js.axis.norm() < 1e-9) fail(field + ".urdf joint " + jname, "zero axis");
        js.axis.normalize();
      }
      if (jp->limits) {
        js.lower = jp->limits->lower;
        js.upper = jp->limits->upper;
        js.velocity = jp->limits->velocity;
      }
      r.joints.push_back(js);
    }
    const std::string geometry = j.contains("geometry") ? string(j["geometry"], field + ".geometry", *this) : "visual";
    if (geometry != "visual" && geometry != "collision") fail(field + ".geometry", "'" + geometry + "' is not visual or collision");
    const Material override_material = material(j.value("material", json()), field + ".material");
    const bool has_override = j.contains("material");
    const fs::path urdf_dir = r.urdf.parent_path();
    for (const auto& [lname, link] : model->links_) {
      std::vector<std::pair<urdf::GeometrySharedPtr, urdf::Pose>> parts;
      std::vector<urdf::MaterialSharedPtr> materials;
      if (geometry == "visual") {
        for (const auto& v : link->visual_array) { parts.emplace_back(v->geometry, v->origin); materials.push_back(v->material); }
      } else {
        for (const auto& c : link->collision_array) { parts.emplace_back(c->geometry, c->origin); materials.push_back(nullptr); }
      }
      for (size_t k = 0; k < parts.size(); ++k) {
        const auto& [geom, origin] = parts[k];
        if (!geom) continue;
        const std::string gfield = field + ".urdf link " + lname;
        Body b;
        b.role = BodyRole::robot_link;
        b.robot = r.name;
        b.link = lname;
        b.name = r.name + "/" + lname + (parts.size() > 1 ? "#" + std::to_string(k) : "");
        b.T_link_body = urdf_pose(origin);
        switch (geom->type) {
          case urdf::Geometry::MESH: {
            const auto* m = static_cast<const urdf::Mesh*>(geom.get());
            b.mesh = mesh_file(resolve_package(m->filename, urdf_dir, gfield), gfield);
            const Eigen::Vector3f s(static_cast<float>(m->scale.x), static_cast<float>(m->scale.y), static_cast<float>(m->scale.z));
            if (s != Eigen::Vector3f::Ones()) {
              for (auto& v : b.mesh.vertices) v = v.cwiseProduct(s);
              b.mesh.compute_vertex_normals();
            }
            break;
          }
          case urdf::Geometry::BOX: {
            const auto* bx = static_cast<const urdf::Box*>(geom.get());
            b.mesh = make_box({bx->dim.x, bx->dim.y, bx->dim.z});
            break;
          }
          case urdf::Geometry::CYLINDER: {
            const auto* c = static_cast<const urdf::Cylinder*>(geom.get());
            b.mesh = make_cylinder(c->radius, c->length);
            break;
          }
          case urdf::Geometry::SPHERE:
            b.mesh = make_sphere(static_cast<const urdf::Sphere*>(geom.get())->radius);
            break;
          default: fail(gfield, "unsupported geometry type");
        }
        b.shape.kind = CollisionShape::Kind::mesh;
        if (has_override) {
          b.material = override_material;
        } else if (materials[k]) {
          const auto& c = materials[k]->color;
          b.material.color = Eigen::Vector3f(c.r, c.g, c.b);
          b.material.use_vertex_colors = false;
        }
        cell.bodies.push_back(std::move(b));
      }
    }
    cell.robots.push_back(std::move(r));
    Robot& placed = cell.robots.back();
    if (j.contains("joints")) {
      if (!j["joints"].is_object()) fail(field + ".joints", "must be an object {joint: value}");
      for (auto it = j["joints"].begin(); it != j["joints"].end(); ++it) {
        placed.joint(it.key());  // throws for an unknown joint
        cell.set_joint(placed.name, it.key(), number(it.value(), field + ".joints." + it.key(), *this));
      }
    }
  }

  SensorSpec sensor(const json& j, const std::string& field) const {
    if (!j.is_object()) fail(field, "must be an object");
    const std::set<std::string> known{"name", "kind", "mount", "pose", "look_at", "pan_tilt", "pan_joint", "tilt_joint", "params"};
    for (auto it = j.begin(); it != j.end(); ++it)
      if (!known.count(it.key())) fail(field + "." + it.key(), "unknown field");
    SensorSpec s;
    s.name = string(j.value("name", json()), field + ".name", *this);
    s.kind = string(j.value("kind", json()), field + ".kind", *this);
    if (s.kind != "minolta-vivid-700" && s.kind != "pioneer-trinocular" && s.kind != "environment")
      fail(field + ".kind", "'" + s.kind + "' is not one of: minolta-vivid-700, pioneer-trinocular, environment");
    if (j.contains("mount")) s.mount = string(j["mount"], field + ".mount", *this);
    s.T_mount_sensor = pose(j, field, *this);
    if (j.contains("pan_tilt")) s.pan_tilt_robot = string(j["pan_tilt"], field + ".pan_tilt", *this);
    if (j.contains("pan_joint")) s.pan_joint = string(j["pan_joint"], field + ".pan_joint", *this);
    if (j.contains("tilt_joint")) s.tilt_joint = string(j["tilt_joint"], field + ".tilt_joint", *this);
    if (j.contains("params")) {
      if (!j["params"].is_object()) fail(field + ".params", "must be an object {field: number}");
      for (auto it = j["params"].begin(); it != j["params"].end(); ++it)
        s.params[it.key()] = number(it.value(), field + ".params." + it.key(), *this);
    }
    return s;
  }

  ScalarField field_of(const json& j, const std::string& field, ScalarField f) const {
    if (j.is_null()) return f;
    if (j.contains("base")) f.base = number(j["base"], field + ".base", *this);
    if (j.contains("gradient")) f.gradient = vec3(j["gradient"], field + ".gradient", *this);
    if (j.contains("spots")) {
      for (size_t i = 0; i < j["spots"].size(); ++i) {
        const auto& s = j["spots"][i];
        const std::string sf = field + ".spots[" + std::to_string(i) + "]";
        ScalarField::Spot spot;
        spot.position_world = vec3(s.value("position", json()), sf + ".position", *this);
        spot.amplitude = number(s.value("amplitude", json()), sf + ".amplitude", *this);
        spot.sigma_m = positive(s.value("sigma_m", json()), sf + ".sigma_m", *this);
        f.spots.push_back(spot);
      }
    }
    return f;
  }
};

}  // namespace

Workcell load_workcell(const fs::path& path, const LoadOptions& options) {
  std::ifstream in(path);
  if (!in) throw FileError(path, "cannot open the workcell file");
  json j;
  try {
    j = json::parse(in);
  } catch (const json::parse_error& e) {
    throw FileError(path, std::string("not valid JSON: ") + e.what());
  }
  Loader L;
  L.file = path;
  L.dir = path.parent_path();
  if (!j.is_object()) L.fail("(top level)", "must be a JSON object");
  const std::set<std::string> known{"name", "seed", "start_time_s", "package_paths", "structure", "objects", "robots",
                                    "sensors", "lights", "environment", "description"};
  for (auto it = j.begin(); it != j.end(); ++it)
    if (!known.count(it.key())) L.fail(it.key(), "unknown field");
  if (j.contains("package_paths"))
    for (const auto& p : j["package_paths"]) L.package_paths.push_back(L.dir / string(p, "package_paths", L));
  for (const auto& p : options.package_paths) L.package_paths.push_back(p);

  Workcell cell;
  cell.source = path;
  cell.name = j.contains("name") ? string(j["name"], "name", L) : path.stem().string();
  if (j.contains("seed")) cell.drop_seed = static_cast<uint64_t>(number(j["seed"], "seed", L));
  if (j.contains("start_time_s")) cell.start_time_s = number(j["start_time_s"], "start_time_s", L);
  auto list = [&](const char* key) {
    if (!j.contains(key)) return json::array();
    if (!j[key].is_array()) L.fail(key, "must be an array");
    return j[key];
  };
  const auto structure = list("structure");
  for (size_t i = 0; i < structure.size(); ++i)
    cell.bodies.push_back(L.body(structure[i], "structure[" + std::to_string(i) + "]", BodyRole::structure));
  const auto objects = list("objects");
  for (size_t i = 0; i < objects.size(); ++i)
    cell.bodies.push_back(L.body(objects[i], "objects[" + std::to_string(i) + "]", BodyRole::object));
  const auto robots = list("robots");
  for (size_t i = 0; i < robots.size(); ++i) L.robot(robots[i], "robots[" + std::to_string(i) + "]", cell);
  const auto sensors = list("sensors");
  for (size_t i = 0; i < sensors.size(); ++i) cell.sensors.push_back(L.sensor(sensors[i], "sensors[" + std::to_string(i) + "]"));
  const auto lights = list("lights");
  for (size_t i = 0; i < lights.size(); ++i) {
    const std::string f = "lights[" + std::to_string(i) + "]";
    Light l;
    l.position_world = vec3(lights[i].value("position", json()), f + ".position", L);
    if (lights[i].contains("diffuse")) l.diffuse = vec3(lights[i]["diffuse"], f + ".diffuse", L).cast<float>();
    if (lights[i].contains("ambient")) l.ambient = vec3(lights[i]["ambient"], f + ".ambient", L).cast<float>();
    cell.lights.push_back(l);
  }
  if (cell.lights.size() > 8) L.fail("lights", "at most 8 lights");
  if (j.contains("environment")) {
    const auto& e = j["environment"];
    if (!e.is_object()) L.fail("environment", "must be an object");
    if (e.contains("gamma_sources")) {
      for (size_t i = 0; i < e["gamma_sources"].size(); ++i) {
        const auto& s = e["gamma_sources"][i];
        const std::string f = "environment.gamma_sources[" + std::to_string(i) + "]";
        GammaSource g;
        g.name = s.contains("name") ? string(s["name"], f + ".name", L) : "source" + std::to_string(i);
        g.position_world = vec3(s.value("position", json()), f + ".position", L);
        g.dose_rate_at_1m_uSv_per_h = number(s.value("dose_rate_at_1m_uSv_per_h", json()), f + ".dose_rate_at_1m_uSv_per_h", L);
        if (g.dose_rate_at_1m_uSv_per_h < 0) L.fail(f + ".dose_rate_at_1m_uSv_per_h", "must not be negative");
        cell.environment.gamma_sources.push_back(g);
      }
    }
    if (e.contains("solid_attenuation_per_m"))
      cell.environment.solid_attenuation_per_m = number(e["solid_attenuation_per_m"], "environment.solid_attenuation_per_m", L);
    if (e.contains("air_attenuation_per_m"))
      cell.environment.air_attenuation_per_m = number(e["air_attenuation_per_m"], "environment.air_attenuation_per_m", L);
    cell.environment.temperature_C = L.field_of(e.value("temperature_C", json()), "environment.temperature_C", cell.environment.temperature_C);
    cell.environment.humidity_percent =
        L.field_of(e.value("humidity_percent", json()), "environment.humidity_percent", cell.environment.humidity_percent);
  }
  // Names unique; instance ids in order of appearance.
  std::set<std::string> names;
  for (size_t i = 0; i < cell.bodies.size(); ++i) {
    if (!names.insert(cell.bodies[i].name).second) L.fail("name", "'" + cell.bodies[i].name + "' is used twice");
    cell.bodies[i].instance_id = static_cast<int>(i) + 1;
  }
  if (cell.bodies.size() > 65535) L.fail("structure", "more than 65535 bodies");
  std::set<std::string> sensor_names;
  for (const auto& s : cell.sensors) {
    if (!sensor_names.insert(s.name).second) L.fail("sensors", "sensor name '" + s.name + "' is used twice");
    if (s.kind == "pioneer-trinocular" && !s.pan_tilt_robot.empty()) {
      const Robot& ptu = cell.robot(s.pan_tilt_robot);
      ptu.joint(s.pan_joint);
      ptu.joint(s.tilt_joint);
    }
    cell.T_world_sensor(s);  // checks the mount
  }
  cell.update_robot_poses();
  return cell;
}

}  // namespace artisan::sim
