// Pipeline commands that derive objects: mesh, reprocess.
#include <iostream>

#include <nlohmann/json.hpp>

#include "artisan/core/error.hpp"
#include "artisan/worldmodel/multimesh.hpp"
#include "artisan/worldmodel/operations.hpp"
#include "artisan/worldmodel/recognition_store.hpp"
#include "artisan/worldmodel/scene_export.hpp"
#include "artisan/worldmodel/world_model.hpp"
#include "artisan/worldmodel/workspace.hpp"
#include "commands.hpp"
#include "progress.hpp"

namespace artisan::cli {

namespace {

using nlohmann::json;
using worldmodel::ObjectKind;
using worldmodel::Workspace;

json derived_json(const Workspace& ws, worldmodel::ObjectId id) {
  const auto o = ws.get(id);
  json j = {{"id", o.id}, {"kind", to_string(o.kind)}, {"path", o.path}, {"version", o.version}};
  for (const char* key : {"vertices", "faces", "resolution_m", "meshing"})
    if (o.metadata.contains(key)) j[key] = o.metadata[key];
  return j;
}

void report(const GlobalOptions& options, const Workspace& ws, worldmodel::ObjectId id, const std::string& verb) {
  const auto j = derived_json(ws, id);
  if (options.json) {
    std::cout << j.dump(2) << "\n";
    return;
  }
  if (options.quiet) return;
  std::cerr << verb << " " << j["path"].get<std::string>() << " (ID " << j["id"] << ", version " << j["version"] << ")";
  if (j.contains("faces")) {
    std::cerr << ": " << j["vertices"] << " vertices, " << j["faces"] << " triangles, resolution " << j["resolution_m"].get<double>() * 1e3 << " mm";
    if (j.contains("meshing"))
      std::cerr << ", min angle " << j["meshing"]["min_angle_image_deg"].get<double>() << " deg, " << j["meshing"]["seconds"].get<double>() << " s";
  }
  std::cerr << "\n";
}

struct MultiMeshAddOptions {
  std::string multimesh, mesh, parent, method = "auto", init;
  bool no_refine = false;
};

struct MeshOptions {
  std::vector<std::string> images;
  std::string name, roi;
  std::optional<double> min_angle, max_edge, thinning, jump_ratio;
  std::vector<std::string> settings;
};

}  // namespace

void add_pipeline_commands(CLI::App& app, const GlobalOptions& options, Action& action) {
  static MeshOptions m;
  auto* mesh = app.add_subcommand("mesh", "Triangulate images into original meshes (constrained Delaunay, minimum angle); all in one transaction");
  mesh->add_option("image", m.images, "Image IDs or paths")->required();
  mesh->add_option("--name", m.name, "Mesh name (default: IMAGE-mesh), in the image's folder; one image only");
  mesh->add_option("--roi", m.roi, "Region of interest in pixels: x,y,w,h");
  mesh->add_option("--min-angle", m.min_angle, "Smallest triangle angle in the image plane [deg], at most 20.7");
  mesh->add_option("--max-edge", m.max_edge, "Longest 3-D edge [m]");
  mesh->add_option("--thinning", m.thinning, "Thinning tolerance, fraction of the sample spacing (0: keep every pixel)");
  mesh->add_option("--jump-ratio", m.jump_ratio, "Depth-discontinuity ratio k (a jump: range step > k x spacing)");
  mesh->add_option("--set", m.settings, "Any meshing parameter as key=value (see artisan show of a mesh)");
  mesh->callback([&options, &action] {
    action = [&options] {
      auto ws = Workspace::open(options.db);
      if (!m.name.empty() && m.images.size() > 1) throw Error("--name names one mesh; " + std::to_string(m.images.size()) + " images were given");
      std::vector<worldmodel::ObjectInfo> images;
      for (const auto& i : m.images) {
        images.push_back(ws.resolve(i));
        if (images.back().kind != ObjectKind::kImage)
          throw Error(images.back().path + " is a " + to_string(images.back().kind) + ", not an image");
      }
      json overrides = worldmodel::parse_settings(m.settings);
      if (m.min_angle) overrides["min_angle_deg"] = *m.min_angle;
      if (m.max_edge) overrides["max_edge_length_m"] = *m.max_edge;
      if (m.thinning) overrides["thinning_tolerance"] = *m.thinning;
      if (m.jump_ratio) overrides["depth_jump_ratio"] = *m.jump_ratio;
      if (!m.roi.empty()) {
        int x, y, w, h;
        char tail;
        if (std::sscanf(m.roi.c_str(), "%d,%d,%d,%d%c", &x, &y, &w, &h, &tail) != 4 || w <= 0 || h <= 0)
          throw Error("--roi \"" + m.roi + "\" is not x,y,w,h with a positive width and height");
        overrides["roi_pixels"] = {x, y, x + w - 1, y + h - 1};
      }
      std::vector<worldmodel::ObjectId> made;
      Progress progress("meshing", images.size(), options.quiet || options.json);
      ws.write([&] {
        for (const auto& image : images) {
          made.push_back(worldmodel::run_operation(ws, "mesh", {image.id}, overrides, *image.folder,
                                                   m.name.empty() ? image.name + "-mesh" : m.name));
          progress.update(made.size(), ws.get(made.back()).path);
        }
      });
      if (options.json && made.size() > 1) {
        json list = json::array();
        for (auto id : made) list.push_back(derived_json(ws, id));
        std::cout << json{{"objects", list}}.dump(2) << "\n";
      } else {
        for (auto id : made) report(options, ws, id, "meshed");
      }
      return 0;
    };
  });

  auto* mm = app.add_subcommand("multimesh", "Assemble registered meshes: new, add, show");
  mm->require_subcommand(1);
  static std::string mm_name, mm_folder = "/";
  auto* mm_new = mm->add_subcommand("new", "Make an empty multimesh");
  mm_new->add_option("name", mm_name, "Name")->required();
  mm_new->add_option("--folder", mm_folder, "Folder (must exist)")->capture_default_str();
  mm_new->callback([&options, &action] {
    action = [&options] {
      auto ws = Workspace::open(options.db);
      const auto id = worldmodel::create_multimesh(ws, ws.folder(mm_folder).id, mm_name);
      const auto o = ws.get(id);
      if (options.json) std::cout << json{{"objects", {{{"id", o.id}, {"kind", "multimesh"}, {"path", o.path}}}}}.dump(2) << "\n";
      else if (!options.quiet) std::cerr << "multimesh " << o.path << " (ID " << o.id << ")\n";
      return 0;
    };
  });
  static std::string mm_show;
  auto* mm_show_cmd = mm->add_subcommand("show", "Every member with T_parent_member and T_root_member, method and quality");
  mm_show_cmd->add_option("multimesh", mm_show, "Multimesh ID or path")->required();
  mm_show_cmd->callback([&options, &action] {
    action = [&options] {
      auto ws = Workspace::open(options.db);
      const auto o = ws.resolve(mm_show);
      if (o.kind != ObjectKind::kMultiMesh) throw Error(o.path + " is a " + to_string(o.kind) + ", not a multimesh");
      const auto j = show_json(ws, o);
      if (options.json) std::cout << j.dump(2) << "\n";
      else print_show(j);
      return 0;
    };
  });
  static MultiMeshAddOptions add;
  auto* mm_add = mm->add_subcommand("add", "Add a mesh: registered with no prior pose (auto/spin), from --init (icp), or placed (manual)");
  mm_add->add_option("multimesh", add.multimesh, "Multimesh ID or path")->required();
  mm_add->add_option("mesh", add.mesh, "Mesh ID or path")->required();
  mm_add->add_option("--parent", add.parent, "Register against this member's mesh only (ID or path)");
  mm_add->add_option("--method", add.method, "auto, spin, icp or manual")->check(CLI::IsMember({"auto", "spin", "icp", "manual"}))->capture_default_str();
  mm_add->add_option("--init", add.init, "T_parent_member for icp/manual: \"tx ty tz qx qy qz qw\" or 16 numbers");
  mm_add->add_flag("--no-refine", add.no_refine, "manual: store --init as given, without ICP");
  mm_add->callback([&options, &action] {
    action = [&options] {
      auto ws = Workspace::open(options.db);
      worldmodel::AddMemberRequest request;
      const auto target = ws.resolve(add.multimesh);
      request.mesh = ws.resolve(add.mesh).id;
      if (!add.parent.empty()) request.parent_mesh = ws.resolve(add.parent).id;
      request.method = add.method;
      if (!add.init.empty()) request.T_parent_member_init = parse_transform(add.init);
      request.refine = !add.no_refine;
      const auto r = worldmodel::add_to_multimesh(ws, target.id, request);
      const auto T_root = worldmodel::root_transforms(ws.members(target.id)).at(r.member);
      json j = {{"member", r.member}, {"mesh", request.mesh}, {"path", ws.get(request.mesh).path},
                {"parent_member", r.parent_member ? json(*r.parent_member) : json(nullptr)}, {"method", r.method},
                {"T_parent_member", to_row_major(r.T_parent_member)}, {"T_root_member", to_row_major(T_root)},
                {"quality", r.quality}, {"registered_members", r.registered_members}, {"loop_closure", r.loop_closure}};
      if (options.json) {
        std::cout << j.dump(2) << "\n";
      } else if (!options.quiet) {
        std::cerr << "added " << j["path"].get<std::string>() << " as member " << r.member << " (" << r.method << ")";
        if (r.quality.contains("overlap"))
          std::cerr << ": overlap " << r.quality["overlap"].get<double>() << ", residual " << r.quality["rmse_m"].get<double>() * 1e3 << " mm";
        if (r.registered_members > 1)
          std::cerr << "; matched " << r.registered_members << " members, loop closed (rms " << r.loop_closure["rms_rotation_deg_before"].get<double>()
                    << " -> " << r.loop_closure["rms_rotation_deg_after"].get<double>() << " deg)";
        std::cerr << "\n";
      }
      return 0;
    };
  });

  static std::vector<std::string> rec_meshes;
  static std::vector<std::string> rec_models;
  auto* rec = app.add_subcommand("recognize", "Find known models in meshes; each instance becomes a recognized_model object; all in one transaction");
  rec->add_option("mesh", rec_meshes, "Scene mesh IDs or paths")->required();
  rec->add_option("--models", rec_models, "Model IDs or paths (comma-separated; default: every model, as --all)")->delimiter(',');
  static bool rec_all = false;
  rec->add_flag("--all", rec_all, "Every model in the workspace (the default)");
  rec->callback([&options, &action] {
    action = [&options] {
      auto ws = Workspace::open(options.db);
      std::vector<worldmodel::ObjectInfo> scenes;
      for (const auto& s : rec_meshes) scenes.push_back(ws.resolve(s));
      std::vector<worldmodel::ObjectId> models;
      if (rec_all && !rec_models.empty()) throw Error("give --models or --all, not both");
      for (const auto& name : rec_models) models.push_back(ws.resolve(name).id);
      json results = json::array();
      Progress progress("recognizing", scenes.size(), options.quiet || options.json);
      ws.write([&] {
        for (const auto& scene : scenes) {
          const auto found = worldmodel::recognize_models(ws, scene.id, models);
          json list = json::array();
          for (const auto& f : found) {
            const auto object = ws.get(f.id);
            json& i = list.emplace_back(json{{"id", f.id}, {"path", object.path}, {"model", f.model}, {"T_scene_model", to_row_major(f.T_scene_model)},
                                             {"score", f.figures["score"]}, {"overlap", f.figures["overlap"]}, {"rmse_m", f.figures["rmse_m"]},
                                             {"ambiguous", f.figures["ambiguous"]}});
            if (f.figures["ambiguous"].get<bool>()) {  // the alternative: another pose of the model, or another model on the same surface
              i["alternative_model"] = f.figures.at("alternative_model");
              i["T_scene_model_alternative"] = object.metadata.at("T_scene_model_alternative");
            }
          }
          results.push_back({{"scene", scene.path}, {"instances", list}});
          progress.update(results.size(), scene.path + ": " + std::to_string(found.size()) + " found");
        }
      });
      if (options.json) {
        std::cout << (results.size() == 1 ? results[0] : json{{"scenes", results}}).dump(2) << "\n";
      } else if (!options.quiet) {
        for (const auto& r : results) {
          const std::string scene = r["scene"];
          if (r["instances"].empty()) std::cerr << "no model found in " << scene << "\n";
          for (const auto& f : r["instances"])
            std::cerr << "found " << f["model"].get<std::string>() << " in " << scene << ": " << f["path"].get<std::string>() << ", overlap "
                      << f["overlap"].get<double>() << ", residual " << f["rmse_m"].get<double>() * 1e3 << " mm"
                      << (!f["ambiguous"].get<bool>() ? ""
                          : f["alternative_model"] == f["model"] ? " (ambiguous: another pose fits almost as well)"
                          : " (ambiguous: " + f["alternative_model"].get<std::string>() + " fits the same surface almost as well)")
                      << "\n";
        }
      }
      return 0;
    };
  });

  static std::string re_id;
  static std::vector<std::string> re_settings;
  auto* re = app.add_subcommand("reprocess", "Re-run the operation that made an object with some parameters changed (a new version)");
  re->add_option("object", re_id, "Object ID or path")->required();
  re->add_option("--set", re_settings, "key=value, repeatable (the parameter names are in artisan show)");
  re->callback([&options, &action] {
    action = [&options] {
      auto ws = Workspace::open(options.db);
      const auto id = worldmodel::reprocess(ws, ws.resolve(re_id).id, worldmodel::parse_settings(re_settings));
      report(options, ws, id, "reprocessed");
      return 0;
    };
  });

  static std::string scene_folder, scene_format = "urdf", scene_out;
  auto* exp = app.add_subcommand("export-scene", "Write a folder's world model as URDF, SDF or glTF for other robot software");
  exp->add_option("folder", scene_folder, "Workcell folder")->required();
  exp->add_option("--format", scene_format, "urdf, sdf or gltf")->check(CLI::IsMember({"urdf", "sdf", "gltf"}))->capture_default_str();
  exp->add_option("--out", scene_out, "Output folder")->required();
  exp->callback([&options, &action] {
    action = [&options] {
      auto ws = Workspace::open(options.db);
      const worldmodel::WorldModel world(ws, scene_folder);
      const auto files = worldmodel::export_scene(world, worldmodel::scene_format_from_string(scene_format), scene_out);
      json j = {{"folder", world.folder()}, {"revision", world.revision()}, {"objects", world.objects().size()}, {"files", json::array()}};
      for (const auto& f : files) j["files"].push_back(f.string());
      if (options.json) std::cout << j.dump(2) << "\n";
      else if (!options.quiet)
        std::cerr << "exported " << world.objects().size() << " object(s) of " << world.folder() << " as " << scene_format << " to " << scene_out << " ("
                  << files.size() << " files)\n";
      return 0;
    };
  });
}

}  // namespace artisan::cli
