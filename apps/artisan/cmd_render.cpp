// `artisan render`: offscreen pictures of what the workspace holds (the simulator's OSMesa
// renderer): a mesh in its colours, a MultiMesh with each member in its own colour at its
// registered pose, a recognized model drawn in red over the mesh it was found in, or a folder's
// world model (environment grey, each recognized object in its own warm colour).
#include <algorithm>
#include <array>
#include <cmath>
#include <iostream>

#include "artisan/core/error.hpp"
#include "artisan/core/io/atomic_file.hpp"
#include "artisan/sim/acquisition.hpp"
#include "artisan/sim/look_at.hpp"
#include "artisan/sim/renderer.hpp"
#include "artisan/worldmodel/multimesh.hpp"
#include "artisan/worldmodel/world_model.hpp"
#include "commands.hpp"

namespace artisan::cli {
namespace {

using worldmodel::ObjectKind;

struct RenderArgs {
  std::string target, out, up = "z";
  std::vector<double> view = {30.0, 25.0};
  int width = 960, height = 720;
};

const Eigen::Vector3f kPalette[] = {{0.35f, 0.55f, 0.85f}, {0.95f, 0.65f, 0.2f}, {0.45f, 0.75f, 0.4f}, {0.75f, 0.45f, 0.8f},
                                    {0.3f, 0.75f, 0.75f},  {0.85f, 0.8f, 0.3f},  {0.6f, 0.4f, 0.3f},  {0.5f, 0.5f, 0.95f}};
const Eigen::Vector3f kObjectColours[] = {{0.9f, 0.15f, 0.1f}, {0.95f, 0.5f, 0.05f}, {0.85f, 0.1f, 0.45f}, {0.95f, 0.8f, 0.1f}};

void add_body(sim::Workcell& cell, TriangleMesh mesh, const Transform& T, const Eigen::Vector3f& colour, bool use_vertex_colours) {
  sim::Body b;
  b.name = "body" + std::to_string(cell.bodies.size() + 1);
  b.instance_id = int(cell.bodies.size()) + 1;
  if (mesh.normals.size() != mesh.vertices.size()) mesh.compute_vertex_normals();
  b.mesh = std::move(mesh);
  b.material.color = colour;
  b.material.specular = 0.15f;
  b.material.use_vertex_colors = use_vertex_colours;
  b.T_world_body = T;
  cell.bodies.push_back(std::move(b));
}

}  // namespace

void add_render_command(CLI::App& app, const GlobalOptions& options, Action& action) {
  auto a = std::make_shared<RenderArgs>();
  auto* render = app.add_subcommand("render", "Draw a mesh, MultiMesh, recognized model or a folder's world model (PNG)");
  render->add_option("target", a->target, "Object ID or path, or a folder")->required();
  render->add_option("--out", a->out, "Output PNG")->required();
  render->add_option("--view", a->view, "Azimuth and elevation of the viewpoint [degrees]")->expected(2)->capture_default_str();
  render->add_option("--up", a->up, "Up axis of the data: z (workcells) or y (Stanford scans)")->check(CLI::IsMember({"y", "z"}))->capture_default_str();
  render->add_option("--width", a->width, "Image width [pixels]")->capture_default_str()->check(CLI::Range(16, 8192));
  render->add_option("--height", a->height, "Image height [pixels]")->capture_default_str()->check(CLI::Range(16, 8192));
  render->callback([&options, &action, a] {
    action = [&options, a] {
      if (io::lower_extension(a->out) != ".png") throw Error("render: the output must be a .png file (got " + a->out + ")");
      auto ws = worldmodel::Workspace::open(options.db);
      const auto target = ws.resolve(a->target);
      sim::Workcell cell;
      cell.name = "render";
      std::string what;
      switch (target.kind) {
        case ObjectKind::kFolder: {
          const worldmodel::WorldModel world(ws, target.path);
          size_t k = 0;
          for (const auto& o : world.objects()) {
            if (o.kind == worldmodel::SceneObject::Kind::environment) add_body(cell, *o.mesh, o.T_world_object, {0.72f, 0.72f, 0.7f}, false);
            else add_body(cell, *o.mesh, o.T_world_object, kObjectColours[k++ % 4], false);
          }
          what = "the world model of " + target.path + " (" + std::to_string(k) + " recognized objects)";
          break;
        }
        case ObjectKind::kMultiMesh: {
          const auto members = ws.members(target.id);
          const auto T_root = worldmodel::root_transforms(members);
          size_t k = 0;
          for (const auto& m : members) add_body(cell, ws.load_mesh(m.mesh), T_root.at(m.member_id), kPalette[k++ % 8], false);
          what = target.path + " (" + std::to_string(members.size()) + " members, one colour each)";
          break;
        }
        case ObjectKind::kRecognizedModel: {
          const auto prov = ws.provenance(target.id);
          if (!prov || prov->inputs.empty()) throw Error(target.path + " does not name the mesh it was found in");
          add_body(cell, ws.load_mesh(prov->inputs.front()), Transform::Identity(), {0.75f, 0.75f, 0.72f}, false);
          std::array<double, 16> m{};
          if (target.metadata.contains("T_world_object"))
            for (size_t i = 0; i < 16; ++i) m[i] = target.metadata["T_world_object"][i].get<double>();
          else
            for (size_t i = 0; i < 16; ++i) m[i] = target.metadata.at("T_scene_model")[i].get<double>();
          add_body(cell, ws.load_mesh(target.metadata.at("model_id").get<worldmodel::ObjectId>()), from_row_major(m), kObjectColours[0], false);
          what = target.path + " in red over " + ws.get(prov->inputs.front()).path;
          break;
        }
        case ObjectKind::kMesh:
        case ObjectKind::kModel: {
          auto mesh = ws.load_mesh(target.id);
          const bool coloured = !mesh.colors.empty();
          add_body(cell, std::move(mesh), Transform::Identity(), {0.78f, 0.72f, 0.62f}, coloured);
          what = target.path;
          break;
        }
        default: throw Error(target.path + " is a " + to_string(target.kind) + "; render draws meshes, multimeshes, recognized models and folders");
      }
      if (cell.bodies.empty()) throw Error("render: " + target.path + " holds nothing to draw");
      // Fit the view to what is drawn: the box of the 0.5th to 99.5th percentile of the vertices
      // along each axis, so a few stray fragments of a scan (floor seen under a table) do not push
      // the subject into a corner of the picture.
      std::array<std::vector<double>, 3> coords;
      for (const auto& b : cell.bodies)
        for (const auto& v : b.mesh.vertices) {
          const Eigen::Vector3d p = b.T_world_body * v.cast<double>();
          for (int k = 0; k < 3; ++k) coords[k].push_back(p[k]);
        }
      if (coords[0].empty()) throw Error("render: " + target.path + " has no vertices to draw");
      Eigen::AlignedBox3d box;
      for (int k = 0; k < 3; ++k) {
        auto& c = coords[k];
        const size_t lo = c.size() / 200, hi = c.size() - 1 - c.size() / 200;
        std::nth_element(c.begin(), c.begin() + static_cast<long>(lo), c.end());
        box.min()[k] = c[lo];
        std::nth_element(c.begin(), c.begin() + static_cast<long>(hi), c.end());
        box.max()[k] = c[hi];
      }
      const Eigen::Vector3d centre = box.center();
      const double radius = std::max(1e-3, 0.5 * box.diagonal().norm());
      const Eigen::Vector3d up = a->up == "z" ? Eigen::Vector3d::UnitZ() : Eigen::Vector3d::UnitY();
      const Eigen::Vector3d side = a->up == "z" ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitZ();
      const double az = a->view[0] * M_PI / 180, el = a->view[1] * M_PI / 180;
      const Eigen::Vector3d ahead = up.cross(side);
      const Eigen::Vector3d dir = (std::cos(el) * (std::cos(az) * side + std::sin(az) * ahead) + std::sin(el) * up).normalized();
      const double fov = 0.7;
      const double distance = radius / std::sin(fov / 2) * 1.05;
      const Eigen::Vector3d eye = centre + dir * distance;
      const Transform T_world_camera = sim::look_at(eye, centre, up, side);
      const Eigen::Vector3d right = T_world_camera.linear().col(0);
      sim::Light light;
      light.position_world = eye + up * distance * 0.5 + right * distance * 0.3;
      cell.lights.push_back(light);
      sim::Renderer renderer(cell);
      sim::RenderOptions ro;
      ro.depth = false;
      ro.instances = false;
      ro.near_m = std::max(1e-3, distance - 2 * radius);
      ro.far_m = distance + 2 * radius;
      ro.background = Eigen::Vector3f(1, 1, 1);
      const auto image = renderer.render(cell, sim::camera_from_fov(a->width, a->height, fov * a->width / std::max(a->width, a->height)),
                                         T_world_camera, ro);
      sim::write_png(image.color, a->out);
      if (!options.quiet) std::cerr << "rendered " << what << " to " << a->out << "\n";
      return 0;
    };
  });
}

}  // namespace artisan::cli
