// Merging commands: grid new / add / extract (persistent occupancy grids in the workspace) and
// merge (all three for a MultiMesh).
#include <cmath>
#include <iostream>
#include <optional>

#include <nlohmann/json.hpp>

#include "artisan/core/error.hpp"
#include "artisan/worldmodel/grid_store.hpp"
#include "artisan/worldmodel/workspace.hpp"
#include "commands.hpp"
#include "progress.hpp"

namespace artisan::cli {

namespace {

using nlohmann::json;
using worldmodel::ObjectKind;
using worldmodel::Workspace;

void say(const GlobalOptions& options, const std::string& line) {
  if (!options.quiet && !options.json) std::cerr << line << "\n";
}


size_t budget_bytes(double megabytes) {
  if (!(std::isfinite(megabytes) && megabytes > 0 && megabytes < 1e7))
    throw Error("--budget-mb " + std::to_string(megabytes) + " must be a positive number of MiB");
  return static_cast<size_t>(megabytes * 1048576.0);
}

std::string default_budget_mb() { return std::to_string(GridDefinition{}.memory_budget_bytes >> 20); }

json merged_json(const Workspace& ws, const worldmodel::ExtractGridReport& r) {
  const auto o = ws.get(r.merged);
  return {{"id", o.id},           {"kind", to_string(o.kind)}, {"subkind", o.subkind}, {"path", o.path},
          {"version", o.version}, {"vertices", r.vertices},    {"faces", r.faces},     {"blocks", r.blocks},
          {"extract_seconds", r.seconds}};
}

json add_json(const worldmodel::AddToGridReport& r) {
  json j = grid_mesh_entry_to_json(r.entry);
  j["skipped_oblique"] = r.distribute.skipped_oblique;
  j["skipped_outside"] = r.distribute.skipped_outside;
  j["voxel_updates"] = r.distribute.voxel_updates;
  j["distribute_seconds"] = r.distribute.seconds;
  j["grid_blocks"] = r.blocks;
  j["grid_block_bytes"] = r.block_bytes;
  j["cache_peak_bytes"] = r.cache.peak_resident_bytes;
  return j;
}

struct GridNewOptions {
  std::string name, folder = "/", channels = "shared", sensor = "laser";
  double voxel = 0.0;
  std::optional<double> budget_mb;
};

struct MergeOptions {
  std::string multimesh;
  std::optional<double> voxel, budget_mb;
};

}  // namespace

void add_grid_commands(CLI::App& app, const GlobalOptions& options, Action& action) {
  auto* grid = app.add_subcommand("grid", "Persistent occupancy grids: new, add, extract (merging meshes)");
  grid->require_subcommand(1);

  static GridNewOptions gn;
  auto* gnew = grid->add_subcommand("new", "Define an empty grid");
  gnew->add_option("name", gn.name, "Name")->required();
  gnew->add_option("--voxel", gn.voxel, "Voxel edge [m], e.g. 0.0005")->required();
  gnew->add_option("--budget-mb", gn.budget_mb, "Block cache memory budget [MiB] (default " + default_budget_mb() + ")");
  gnew->add_option("--channels", gn.channels, "Texture channels: shared, or per-mesh")
      ->check(CLI::IsMember({"shared", "per-mesh"}))
      ->capture_default_str();
  gnew->add_option("--sensor", gn.sensor, "Sensor error model: laser or stereo")->check(CLI::IsMember({"laser", "stereo"}))->capture_default_str();
  gnew->add_option("--folder", gn.folder, "Folder (must exist)")->capture_default_str();
  gnew->callback([&options, &action] {
    action = [&options] {
      GridDefinition def;
      def.voxel_size_m = gn.voxel;
      if (gn.budget_mb) def.memory_budget_bytes = budget_bytes(*gn.budget_mb);
      def.channels = gn.channels == "shared" ? ChannelMode::kShared : ChannelMode::kPerMesh;
      def.sensor = gn.sensor == "laser" ? SensorModel::laser() : SensorModel::stereo();
      auto ws = Workspace::open(options.db);
      const auto id = worldmodel::create_grid(ws, ws.folder(gn.folder).id, gn.name, def);
      const auto o = ws.get(id);
      if (options.json)
        std::cout << json{{"objects", {{{"id", o.id}, {"kind", "grid"}, {"path", o.path}}}}, {"definition", o.metadata["definition"]}}.dump(2)
                  << "\n";
      say(options, "grid " + o.path + " (ID " + std::to_string(o.id) + "): voxel " + std::to_string(def.voxel_size_m * 1e3) + " mm, " +
                       gn.sensor + " sensor model, " + gn.channels + " texture channels, budget " +
                       std::to_string(def.memory_budget_bytes >> 20) + " MiB");
      return 0;
    };
  });

  static std::string ga_grid, ga_mesh, ga_pose;
  auto* gadd = grid->add_subcommand("add", "Distribute a mesh into a grid (once per mesh, in any order, at any later time)");
  gadd->add_option("grid", ga_grid, "Grid ID or path")->required();
  gadd->add_option("mesh", ga_mesh, "Mesh ID or path")->required();
  gadd->add_option("--pose", ga_pose,
                   "T_grid_mesh: \"tx ty tz qx qy qz qw\" or 16 numbers (default: the mesh's T_world_mesh when it has one, else the identity)");
  gadd->callback([&options, &action] {
    action = [&options] {
      const std::optional<Transform> pose = ga_pose.empty() ? std::nullopt : std::optional(parse_transform(ga_pose));
      auto ws = Workspace::open(options.db);
      const auto g = ws.resolve(ga_grid);
      const auto m = ws.resolve(ga_mesh);
      if (!options.quiet) std::cerr << "distributing " << m.path << " into " << g.path << "\n";
      const auto r = worldmodel::add_to_grid(ws, g.id, m.id, pose);
      if (options.json) std::cout << add_json(r).dump(2) << "\n";
      say(options, "added " + r.entry.path + " to " + g.path + " as mesh " + std::to_string(r.entry.mesh_index) + ": " +
                       std::to_string(r.distribute.points) + " samples in " + std::to_string(r.distribute.seconds) + " s; the grid holds " +
                       std::to_string(r.blocks) + " blocks (" + std::to_string(r.block_bytes >> 20) + " MiB); view: " + r.entry.view_source);
      return 0;
    };
  });

  static std::string ge_grid, ge_name, ge_color = "blend";
  static std::optional<double> ge_min_likelihood;
  auto* gext = grid->add_subcommand("extract", "Extract the merged surface (Marching Cubes) as a merged mesh beside the grid");
  gext->add_option("grid", ge_grid, "Grid ID or path")->required();
  gext->add_option("--name", ge_name, "Mesh name (default: GRID-merged; an existing merged mesh of that name gets a new version)");
  gext->add_option("--min-likelihood", ge_min_likelihood,
                   "Smallest surface likelihood kept (about the summed view cosines; default " + json(ExtractParams{}.min_likelihood).dump() + ")");
  gext->add_option("--color", ge_color, "Colour from several channels: blend or best-viewed")
      ->check(CLI::IsMember({"blend", "best-viewed"}))
      ->capture_default_str();
  gext->callback([&options, &action] {
    action = [&options] {
      auto ws = Workspace::open(options.db);
      const auto g = ws.resolve(ge_grid);
      if (g.kind != ObjectKind::kGrid) throw Error(g.path + " (ID " + std::to_string(g.id) + ") is a " + to_string(g.kind) + ", not a grid");
      ExtractParams params;
      if (ge_min_likelihood) params.min_likelihood = *ge_min_likelihood;
      params.color = ge_color == "blend" ? ExtractParams::Color::kBlend : ExtractParams::Color::kBestViewed;
      if (!options.quiet) std::cerr << "extracting the surface of " << g.path << "\n";
      const auto r = worldmodel::extract_grid(ws, g.id, *g.folder, ge_name.empty() ? g.name + "-merged" : ge_name, params);
      const auto j = merged_json(ws, r);
      if (options.json) std::cout << j.dump(2) << "\n";
      say(options, "merged " + j["path"].get<std::string>() + " (ID " + std::to_string(r.merged) + ", version " + j["version"].dump() +
                       "): " + std::to_string(r.vertices) + " vertices, " + std::to_string(r.faces) + " triangles in " +
                       std::to_string(r.seconds) + " s");
      return 0;
    };
  });

  static MergeOptions mo;
  auto* merge = app.add_subcommand("merge", "Merge a MultiMesh into one surface: a grid beside it, every member at its T_root_member, "
                                            "the merged mesh MM-merged");
  merge->add_option("multimesh", mo.multimesh, "Multimesh ID or path")->required();
  merge->add_option("--voxel", mo.voxel, "Voxel edge [m] (default " + json(GridDefinition{}.voxel_size_m).dump() + ")");
  merge->add_option("--budget-mb", mo.budget_mb, "Block cache memory budget [MiB] (default " + default_budget_mb() + ")");
  merge->callback([&options, &action] {
    action = [&options] {
      GridDefinition def;
      if (mo.voxel) def.voxel_size_m = *mo.voxel;
      if (mo.budget_mb) def.memory_budget_bytes = budget_bytes(*mo.budget_mb);
      auto ws = Workspace::open(options.db);
      const auto mm = ws.resolve(mo.multimesh);
      Progress progress("merging " + mm.path, 0, options.quiet);  // on stderr also with --json, as before
      const auto r = worldmodel::merge_multimesh(ws, mm.id, def, {}, progress.callback());
      json added = json::array();
      size_t points = 0;
      double distribute_s = 0;
      for (const auto& a : r.added) {
        added.push_back(add_json(a));
        points += a.distribute.points;
        distribute_s += a.distribute.seconds;
      }
      const auto grid_object = ws.get(r.grid);
      json j = merged_json(ws, r.extract);
      j["multimesh"] = mm.path;
      j["grid"] = {{"id", grid_object.id}, {"path", grid_object.path}, {"version", grid_object.version}, {"blocks", grid_object.metadata["blocks"]},
                   {"block_bytes", grid_object.metadata["block_bytes"]}, {"definition", grid_object.metadata["definition"]}};
      j["meshes"] = added;
      j["distribute_seconds"] = distribute_s;
      j["distribute_points_per_s"] = distribute_s > 0 ? points / distribute_s : 0.0;
      j["seconds"] = r.seconds;
      if (options.json) std::cout << j.dump(2) << "\n";
      say(options, "merged " + std::to_string(r.added.size()) + " meshes of " + mm.path + " into " + j["path"].get<std::string>() + " (ID " +
                       std::to_string(r.extract.merged) + "): " + std::to_string(r.extract.vertices) + " vertices, " +
                       std::to_string(r.extract.faces) + " triangles; grid " + grid_object.path + " kept (" + grid_object.metadata["blocks"].dump() +
                       " blocks); " + std::to_string(r.seconds) + " s");
      return 0;
    };
  });
}

}  // namespace artisan::cli
