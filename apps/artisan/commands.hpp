#pragma once
// The artisan command line: each group of subcommands registers itself on the app.
#include <functional>
#include <string>

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

/// Registers `teleop ...`: the sample client of the world-model service.
void add_teleop_commands(CLI::App& app, const GlobalOptions& options, Action& action);

}  // namespace artisan::cli
