// The workspace commands: init, mkdir, ls, show, rm, mv, import, export, check.
#include <algorithm>
#include <filesystem>
#include <iostream>
#include <map>

#include <nlohmann/json.hpp>

#include "artisan/core/error.hpp"
#include "artisan/core/io/geometry_file.hpp"
#include "artisan/worldmodel/multimesh.hpp"
#include "artisan/worldmodel/recognition_store.hpp"
#include "artisan/worldmodel/workspace.hpp"
#include "commands.hpp"
#include "progress.hpp"

namespace artisan::cli {

namespace {

using nlohmann::json;
using worldmodel::ObjectId;
using worldmodel::ObjectInfo;
using worldmodel::ObjectKind;
using worldmodel::Workspace;

json object_json(const ObjectInfo& o) {
  return {{"id", o.id}, {"kind", to_string(o.kind)}, {"subkind", o.subkind}, {"name", o.name}, {"path", o.path},
          {"version", o.version}, {"created_at", o.created_at}, {"metadata", o.metadata}};
}

std::string summary(const Workspace& ws, const ObjectInfo& o) {
  const auto& m = o.metadata;
  char buf[160];
  switch (o.kind) {
    case ObjectKind::kFolder: return std::to_string(ws.children(o.id).size()) + " items";
    case ObjectKind::kImage:
      std::snprintf(buf, sizeof buf, "%s range image %d x %d, %d valid pixels", o.subkind.empty() ? "unknown-sensor" : o.subkind.c_str(),
                    m.value("width", 0), m.value("height", 0), m.value("valid_pixels", 0));
      return buf;
    case ObjectKind::kMesh:
    case ObjectKind::kModel:
      std::snprintf(buf, sizeof buf, "%s%s%d vertices, %d triangles, resolution %.2f mm", o.subkind.c_str(), o.subkind.empty() ? "" : ", ",
                    m.value("vertices", 0), m.value("faces", 0), m.value("resolution_m", 0.0) * 1e3);
      return buf;
    case ObjectKind::kMultiMesh: return std::to_string(ws.members(o.id).size()) + " members";
    case ObjectKind::kRecognizedModel:
      std::snprintf(buf, sizeof buf, "%s, overlap %.2f, residual %.2f mm%s", m.value("model", std::string("?")).c_str(),
                    m.contains("figures") ? m["figures"].value("overlap", 0.0) : 0.0,
                    m.contains("figures") ? m["figures"].value("rmse_m", 0.0) * 1e3 : 0.0,
                    m.contains("figures") && m["figures"].value("ambiguous", false) ? ", ambiguous" : "");
      return buf;
    case ObjectKind::kRobot:
      return "robot '" + o.subkind + "', " + std::to_string(m.value("joint_names", json::array()).size()) + " joints" +
             (m.contains("edit") ? ", set by " + m["edit"].value("author", std::string("?")) : "");
    default: return o.subkind;
  }
}

void print_tree(const Workspace& ws, const ObjectInfo& folder, const std::string& prefix, bool recursive) {
  const auto items = ws.children(folder.id);
  for (size_t i = 0; i < items.size(); ++i) {
    const auto& o = items[i];
    const bool last = i + 1 == items.size();
    std::string label = o.name + (o.kind == ObjectKind::kFolder ? "/" : "");
    if (o.version > 1) label += "  (v" + std::to_string(o.version) + ")";
    const std::string head = prefix + (last ? "└── " : "├── ") + label;
    // Pad by displayed characters: the tree lines are multi-byte UTF-8.
    const auto width = std::count_if(head.begin(), head.end(), [](char c) { return (static_cast<unsigned char>(c) & 0xC0) != 0x80; });
    char rest[256];
    std::snprintf(rest, sizeof rest, " %-10s #%-5lld %s", to_string(o.kind).c_str(), static_cast<long long>(o.id), summary(ws, o).c_str());
    std::cout << head << std::string(width < 40 ? 40 - width : 1, ' ') << rest << "\n";
    if (recursive && o.kind == ObjectKind::kFolder) print_tree(ws, o, prefix + (last ? "    " : "│   "), true);
  }
}

json tree_json(const Workspace& ws, const ObjectInfo& folder, bool recursive) {
  json items = json::array();
  for (const auto& o : ws.children(folder.id)) {
    auto j = object_json(o);
    if (recursive && o.kind == ObjectKind::kFolder) j["children"] = tree_json(ws, o, true);
    items.push_back(std::move(j));
  }
  return items;
}

}  // namespace

json show_json(const Workspace& ws, const ObjectInfo& o) {
  json j = object_json(o);
  if (const auto p = ws.provenance(o.id)) {
    json inputs = json::array();
    for (ObjectId in : p->inputs) {
      std::string path = "(removed)";
      try {
        path = ws.get(in).path;
      } catch (const Error&) {
      }
      inputs.push_back({{"id", in}, {"path", path}});
    }
    j["provenance"] = {{"operation", p->operation}, {"parameters", p->parameters}, {"inputs", inputs}};
  } else {
    j["provenance"] = nullptr;
  }
  json versions = json::array();
  for (const auto& v : ws.versions(o.id)) versions.push_back({{"id", v.id}, {"version", v.version}, {"created_at", v.created_at}});
  j["versions"] = versions;
  json derived = json::array();
  for (const auto& d : ws.derived_from(o.id)) derived.push_back({{"id", d.id}, {"path", d.path}, {"kind", to_string(d.kind)}});
  j["derived"] = derived;
  json blobs = json::array();
  for (const auto& b : ws.blobs(o.id)) blobs.push_back({{"role", b.role}, {"encoding", b.encoding}, {"bytes", b.data.size()}});
  j["data"] = blobs;
  if (o.kind == ObjectKind::kFolder) j["children"] = tree_json(ws, o, false);
  if (o.kind == ObjectKind::kMultiMesh) {
    json members = json::array();
    const auto all = ws.members(o.id);
    const auto T_root = worldmodel::root_transforms(all);
    // Where the sensor was, when the member's image knows it (simulated or tracked sensors): the
    // registration can then be checked against it.
    std::map<int64_t, Transform> T_world_sensor;
    for (const auto& m : all) {
      const auto prov = ws.provenance(m.mesh);
      if (!prov || prov->inputs.empty() || ws.get(prov->inputs.front()).kind != ObjectKind::kImage) continue;
      if (const auto pose = ws.load_image(prov->inputs.front()).sensor.T_world_sensor) T_world_sensor[m.member_id] = *pose;
    }
    const auto root = all.empty() ? T_world_sensor.end() : T_world_sensor.find(all.front().member_id);
    for (const auto& m : all) {
      json member = {{"member", m.member_id}, {"mesh", m.mesh}, {"path", ws.get(m.mesh).path},
                     {"parent_member", m.parent_member ? json(*m.parent_member) : json(nullptr)},
                     {"T_parent_member", to_row_major(m.T_parent_member)}, {"T_root_member", to_row_major(T_root.at(m.member_id))},
                     {"method", m.method}, {"quality", m.quality}};
      if (auto it = T_world_sensor.find(m.member_id); it != T_world_sensor.end() && root != T_world_sensor.end()) {
        const Transform error = (root->second.inverse() * it->second).inverse() * T_root.at(m.member_id);
        member["error_vs_sensor_pose"] = {{"rotation_deg", rotation_angle(error) * 180 / M_PI}, {"translation_mm", error.translation().norm() * 1e3}};
      }
      members.push_back(member);
    }
    j["members"] = members;
  }
  return j;
}

// Nested objects as "a.b: value" lines; arrays (transforms, lists) on one line.
static void print_flat(const json& j, const std::string& prefix) {
  for (const auto& [key, value] : j.items()) {
    if (value.is_object() && !value.empty()) print_flat(value, prefix + key + ".");
    else if (value.is_array() && !value.empty() && value[0].is_object())
      std::cout << "  " << prefix << key << ": " << value.size() << " entries (see --json)\n";
    else std::cout << "  " << prefix << key << ": " << (value.is_string() ? value.get<std::string>() : value.dump()) << "\n";
  }
}

void print_show(const json& j) {
  std::cout << j["path"].get<std::string>() << "  (ID " << j["id"] << ", " << j["kind"].get<std::string>();
  if (!j["subkind"].get<std::string>().empty()) std::cout << " / " << j["subkind"].get<std::string>();
  std::cout << ", version " << j["version"] << ", created " << j["created_at"].get<std::string>() << ")\n";
  if (!j["metadata"].empty()) {
    std::cout << "metadata:\n";
    print_flat(j["metadata"], "");
  }
  if (j["provenance"].is_null()) {
    std::cout << "made by: nothing recorded\n";
  } else {
    std::cout << "made by: " << j["provenance"]["operation"].get<std::string>() << "\n  parameters: " << j["provenance"]["parameters"].dump() << "\n";
    for (const auto& in : j["provenance"]["inputs"]) std::cout << "  input: " << in["path"].get<std::string>() << " (ID " << in["id"] << ")\n";
  }
  if (j["versions"].size() > 1) {
    std::cout << "versions:\n";
    for (const auto& v : j["versions"]) std::cout << "  v" << v["version"] << "  ID " << v["id"] << "  " << v["created_at"].get<std::string>() << "\n";
  }
  for (const auto& d : j["derived"]) std::cout << "derived: " << d["path"].get<std::string>() << " (ID " << d["id"] << ", " << d["kind"].get<std::string>() << ")\n";
  for (const auto& b : j["data"]) std::cout << "data: " << b["role"].get<std::string>() << ", " << b["bytes"] << " bytes (" << b["encoding"].get<std::string>() << ")\n";
  if (j.contains("children")) {
    for (const auto& c : j["children"]) std::cout << "  " << c["name"].get<std::string>() << (c["kind"] == "folder" ? "/" : "") << "  (" << c["kind"].get<std::string>() << ", ID " << c["id"] << ")\n";
  }
  if (j.contains("members")) {
    std::cout << "members:\n";
    for (const auto& m : j["members"]) {
      const auto& T = m["T_root_member"];
      std::printf("  %-3lld %-34s %-7s parent %-4s t_root [%7.4f %7.4f %7.4f] m", static_cast<long long>(m["member"].get<int64_t>()),
                  m["path"].get<std::string>().c_str(), m["method"].get<std::string>().c_str(),
                  m["parent_member"].is_null() ? "-" : std::to_string(m["parent_member"].get<int64_t>()).c_str(), T[3].get<double>(),
                  T[7].get<double>(), T[11].get<double>());
      if (m["quality"].contains("overlap"))
        std::printf("  overlap %.2f  rmse %.2f mm", m["quality"]["overlap"].get<double>(), m["quality"]["rmse_m"].get<double>() * 1e3);
      if (m.contains("error_vs_sensor_pose"))
        std::printf("  error vs sensor pose %.2f deg %.1f mm", m["error_vs_sensor_pose"]["rotation_deg"].get<double>(),
                    m["error_vs_sensor_pose"]["translation_mm"].get<double>());
      std::printf("\n");
    }
    std::fflush(stdout);
  }
}

namespace {

void say(const GlobalOptions& options, const std::string& message) {
  if (!options.quiet && !options.json) std::cerr << message << "\n";
}

struct ImportOptions {
  std::vector<std::string> files;
  std::string folder = "/";
  std::string as;
  std::string name;
  std::string pose;
  double scale = 1.0;
  std::vector<std::string> grasps;
};

}  // namespace

void add_workspace_commands(CLI::App& app, const GlobalOptions& options, Action& action) {
  auto* init = app.add_subcommand("init", "Create a new, empty workspace (--db PATH)");
  init->callback([&options, &action] {
    action = [&options] {
      Workspace::create(options.db);
      if (options.json) std::cout << json{{"workspace", options.db}, {"schema_version", Workspace::kSchemaVersion}}.dump(2) << "\n";
      say(options, "created workspace " + options.db);
      return 0;
    };
  });

  static std::string mkdir_path;
  auto* mkdir = app.add_subcommand("mkdir", "Make a folder (and its missing parents), e.g. /cell/east");
  mkdir->add_option("path", mkdir_path, "Folder path")->required();
  mkdir->callback([&options, &action] {
    action = [&options] {
      auto ws = Workspace::open(options.db);
      const auto id = ws.mkdir(mkdir_path);
      if (options.json) std::cout << json{{"objects", {object_json(ws.get(id))}}}.dump(2) << "\n";
      say(options, "folder " + mkdir_path + " (ID " + std::to_string(id) + ")");
      return 0;
    };
  });

  static std::string ls_path = "/";
  static bool ls_recursive = false;
  auto* ls = app.add_subcommand("ls", "List a folder like a file explorer");
  ls->add_option("path", ls_path, "Folder path or ID")->capture_default_str();
  ls->add_flag("-r,--recursive", ls_recursive, "Descend into folders");
  ls->callback([&options, &action] {
    action = [&options] {
      auto ws = Workspace::open(options.db);
      const auto target = ws.resolve(ls_path);
      if (options.json) {
        auto j = object_json(target);
        if (target.kind == ObjectKind::kFolder) j["children"] = tree_json(ws, target, ls_recursive);
        std::cout << j.dump(2) << "\n";
      } else if (target.kind != ObjectKind::kFolder) {
        std::cout << target.path << "  " << to_string(target.kind) << " #" << target.id << "  " << summary(ws, target) << "\n";
      } else {
        std::cout << target.path << "\n";
        print_tree(ws, target, "", ls_recursive);
      }
      return 0;
    };
  });

  static std::string show_id;
  auto* show = app.add_subcommand("show", "Everything about one object: kind, metadata, parameters, inputs, versions");
  show->add_option("object", show_id, "Object ID or path (path@N for version N)")->required();
  show->callback([&options, &action] {
    action = [&options] {
      auto ws = Workspace::open(options.db);
      const auto j = show_json(ws, ws.resolve(show_id));
      if (options.json) std::cout << j.dump(2) << "\n";
      else print_show(j);
      return 0;
    };
  });

  static std::string rm_id;
  static bool rm_recursive = false;
  auto* rm = app.add_subcommand("rm", "Remove an object (every version); refused when others were derived from it");
  rm->add_option("object", rm_id, "Object ID or path")->required();
  rm->add_flag("-r,--recursive", rm_recursive, "Also remove folder contents and everything derived from it");
  rm->callback([&options, &action] {
    action = [&options] {
      auto ws = Workspace::open(options.db);
      const auto target = ws.resolve(rm_id);
      ws.remove(target.id, rm_recursive);
      if (options.json) std::cout << json{{"removed", target.id}, {"path", target.path}}.dump(2) << "\n";
      say(options, "removed " + target.path);
      return 0;
    };
  });

  static std::string mv_id, mv_dest;
  auto* mv = app.add_subcommand("mv", "Move an object into a folder, or rename it");
  mv->add_option("object", mv_id, "Object ID or path")->required();
  mv->add_option("destination", mv_dest, "An existing folder, or a new path")->required();
  mv->callback([&options, &action] {
    action = [&options] {
      auto ws = Workspace::open(options.db);
      const auto target = ws.resolve(mv_id);
      ws.move(target.id, mv_dest);
      const auto moved = ws.get(target.id);
      if (options.json) std::cout << json{{"objects", {object_json(moved)}}}.dump(2) << "\n";
      say(options, "moved " + target.path + " to " + moved.path);
      return 0;
    };
  });

  static ImportOptions imp;
  auto* import = app.add_subcommand("import", "Import range images, meshes or models into the workspace (one transaction)");
  import->add_option("files", imp.files, "Files (PLY range grids, organized PCD, .ari; meshes in PLY/OBJ/STL/DAE/glTF)")->required();
  import->add_option("--folder", imp.folder, "Destination folder (must exist)")->capture_default_str();
  import->add_option("--as", imp.as, "image, mesh or model (default: what the file holds)")->check(CLI::IsMember({"image", "mesh", "model"}));
  import->add_option("--name", imp.name, "Object name (one file only; default: the file name without extension)");
  import->add_option("--pose", imp.pose, "T_world_object: \"tx ty tz qx qy qz qw\" or 16 numbers (row-major 4x4)");
  import->add_option("--scale", imp.scale, "Multiply mesh coordinates (CAD units to metres, e.g. 0.001)")->check(CLI::PositiveNumber);
  import->add_option("--grasp", imp.grasps, "Grasp frame T_model_grasp of a model (repeatable)");
  import->callback([&options, &action] {
    action = [&options] {
      if (!imp.name.empty() && imp.files.size() != 1) throw Error("--name needs exactly one file (" + std::to_string(imp.files.size()) + " given)");
      if (!imp.grasps.empty() && imp.as != "model") throw Error("--grasp is for models (add --as model)");
      const std::optional<Transform> pose = imp.pose.empty() ? std::nullopt : std::optional(parse_transform(imp.pose));
      std::vector<Transform> grasps;
      for (const auto& g : imp.grasps) grasps.push_back(parse_transform(g));
      auto ws = Workspace::open(options.db);
      const auto folder = ws.folder(imp.folder);
      // Read and check every file before writing anything.
      struct Item {
        std::string file, name;
        io::Geometry geometry;
      };
      std::vector<Item> items;
      Progress reading("reading", imp.files.size(), options.quiet || options.json);
      for (const auto& f : imp.files) {
        const std::string name = imp.name.empty() ? std::filesystem::path(f).stem().string() : imp.name;
        try {
          worldmodel::validate_name(name);
        } catch (const Error& e) {
          throw Error(f + ": " + e.what() + " (choose one with --name)");
        }
        items.push_back({f, name, io::load_geometry(f)});
        reading.update(items.size(), f);
      }
      std::vector<ObjectId> ids;
      Progress storing("storing", items.size(), options.quiet || options.json);
      ws.write([&] {
        for (auto& item : items) {
          storing.update(ids.size(), item.name);
          json params = {{"source", std::filesystem::absolute(item.file).lexically_normal().string()},
                         {"source_bytes", std::filesystem::file_size(item.file)},
                         {"as", imp.as.empty() ? "auto" : imp.as}, {"scale", imp.scale}};
          if (pose) params["pose"] = to_row_major(*pose);
          const worldmodel::Provenance prov{"import", params, {}};
          if (auto* image = std::get_if<RangeImage>(&item.geometry)) {
            if (imp.as == "mesh" || imp.as == "model") throw Error(item.file + " holds a range image; import it as an image and mesh it (artisan mesh)");
            if (pose) image->sensor.T_world_sensor = *pose;
            if (image->sensor.name.empty()) image->sensor.name = std::filesystem::path(item.file).stem().string();
            ids.push_back(ws.add(folder.id, worldmodel::make_image_object(item.name, *image, prov)));
          } else if (auto* mesh = std::get_if<TriangleMesh>(&item.geometry)) {
            if (imp.as == "image") throw Error(item.file + " holds a mesh, not a range image");
            if (imp.scale != 1.0)
              for (auto& v : mesh->vertices) v *= static_cast<float>(imp.scale);
            json meta = json::object();
            if (pose) meta["T_world_mesh"] = to_row_major(*pose);
            const bool model = imp.as == "model";
            if (model) {
              json g = json::array();
              for (const auto& T : grasps) g.push_back(to_row_major(T));
              meta["T_model_grasps"] = g;
            }
            ids.push_back(ws.add(folder.id, model ? worldmodel::make_model_object(item.name, *mesh, prov, meta)
                                                  : worldmodel::make_mesh_object(ObjectKind::kMesh, "original", item.name, *mesh, prov, meta)));
          } else {
            throw Error(item.file + " holds a point cloud without a grid; only range images and meshes can be imported");
          }
        }
        storing.update(items.size());
      });
      json out = json::array();
      for (ObjectId id : ids) {
        const auto o = ws.get(id);
        out.push_back({{"id", o.id}, {"kind", to_string(o.kind)}, {"path", o.path}});
        say(options, "imported " + o.path + " (ID " + std::to_string(o.id) + ", " + summary(ws, o) + ")");
      }
      if (options.json) std::cout << json{{"objects", out}}.dump(2) << "\n";
      return 0;
    };
  });

  static std::string export_id, export_out;
  auto* exp = app.add_subcommand("export", "Write an object to a file (meshes: .ply .obj .gltf .glb; images: .ari .ply .pcd)");
  exp->add_option("object", export_id, "Object ID or path")->required();
  exp->add_option("--out", export_out, "Output file")->required();
  exp->callback([&options, &action] {
    action = [&options] {
      auto ws = Workspace::open(options.db);
      const auto o = ws.resolve(export_id);
      io::format_for_output(export_out);
      if (o.kind == ObjectKind::kImage) io::save_geometry(ws.load_image(o.id), export_out);
      else if (o.kind == ObjectKind::kMesh || o.kind == ObjectKind::kModel) io::save_geometry(ws.load_mesh(o.id), export_out);
      else throw Error(o.path + " is a " + to_string(o.kind) + "; only images, meshes and models can be exported");
      if (options.json) std::cout << json{{"id", o.id}, {"path", o.path}, {"output", export_out}}.dump(2) << "\n";
      say(options, "wrote " + o.path + " to " + export_out);
      return 0;
    };
  });

  auto* check = app.add_subcommand("check", "Verify the workspace: SQLite integrity, references, data checksums");
  check->callback([&options, &action] {
    action = [&options] {
      auto ws = Workspace::open(options.db);
      const auto report = ws.check();
      if (options.json) {
        std::cout << json{{"ok", report.problems.empty()}, {"schema_version", report.schema_version}, {"objects", report.objects},
                          {"blobs", report.blobs}, {"problems", report.problems}}
                         .dump(2)
                  << "\n";
      } else {
        for (const auto& p : report.problems) std::cerr << "problem: " << p << "\n";
        std::cout << options.db << ": " << (report.problems.empty() ? "ok" : std::to_string(report.problems.size()) + " problems")
                  << " (schema " << report.schema_version << ", " << report.objects << " objects, " << report.blobs << " data blobs checked)\n";
      }
      return report.problems.empty() ? 0 : 1;
    };
  });
}

}  // namespace artisan::cli
