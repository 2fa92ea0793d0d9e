#pragma once
// The artisan command line: each group of subcommands registers itself on the app.
#include <functional>
#include <map>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "artisan/worldmodel/workspace.hpp"

namespace artisan::cli {

/// Options every subcommand shares.
struct GlobalOptions {
  bool json = false;   ///< machine-readable output on stdout
  bool quiet = false;  ///< no human messages on stderr
  std::string db = "artisan.db";  ///< workspace file (--db, or ARTISAN_DB)
  bool db_given = false;           ///< --db or ARTISAN_DB was given (not the default)
};

/// A subcommand's action; returns the process exit code (0 ok, 1 bad input).
using Action = std::function<int()>;

/// Everything about one object, as `show --json` prints it, and its human form.
nlohmann::json show_json(const worldmodel::Workspace& ws, const worldmodel::ObjectInfo& object);
void print_show(const nlohmann::json& j);

/// Registers `info` and `convert`.
void add_file_commands(CLI::App& app, const GlobalOptions& options, Action& action);
/// Registers the workspace commands: init, mkdir, ls, show, rm, mv, import, export, check.
void add_workspace_commands(CLI::App& app, const GlobalOptions& options, Action& action);
/// Registers the commands that derive objects: mesh, reprocess.
void add_pipeline_commands(CLI::App& app, const GlobalOptions& options, Action& action);
/// Registers the simulated workcell: sim scan, sim render, sim sensors, sim models.
void add_sim_commands(CLI::App& app, const GlobalOptions& options, Action& action);
/// Registers the sensor server's client commands: acquire, sensors, ptu, zoom.
void add_sensor_commands(CLI::App& app, const GlobalOptions& options, Action& action);

/// Where an acquisition goes in the workspace, checked before the (slow) acquisition: the
/// workspace opens, the folder exists, the name is valid.
struct ImageDestination {
  worldmodel::Workspace workspace;
  std::string folder;  ///< workspace path
  std::string name;
};
ImageDestination open_image_destination(const GlobalOptions& options, const std::string& folder, const std::string& name);
/// Stores a range image as an image object in the destination; `metadata` is merged into the
/// object's metadata (e.g. environmental readings, pan/tilt state).
worldmodel::ObjectId import_range_image(ImageDestination& destination, const RangeImage& range, const worldmodel::Provenance& provenance,
                                        const nlohmann::json& metadata = nlohmann::json::object());

/// Registers `teleop ...`: the sample client of the world-model service.
void add_teleop_commands(CLI::App& app, const GlobalOptions& options, Action& action);

/// Registers the merging commands: grid new/add/extract, merge.
void add_grid_commands(CLI::App& app, const GlobalOptions& options, Action& action);

/// Registers `robot set` and `robot show`: a robot (URDF, pose, joints) in a folder's world model.
void add_robot_commands(CLI::App& app, const GlobalOptions& options, Action& action);
/// Joint values from "NAME=VALUE" arguments of `option`; throws naming the argument when one is
/// malformed, not finite or repeated.
std::map<std::string, double> parse_joint_values(const std::vector<std::string>& assignments, const std::string& option);

/// Registers `evaluate`: a folder's recognized objects against ground truth.
void add_evaluate_command(CLI::App& app, const GlobalOptions& options, Action& action);

/// Registers `render`: pictures of meshes, multimeshes, recognized models and world models.
void add_render_command(CLI::App& app, const GlobalOptions& options, Action& action);

}  // namespace artisan::cli
