// artisan: the command line. Exit codes: 0 success, 1 bad input, 2 usage error.
#include <cstdlib>
#include <iostream>

#include "artisan/core/error.hpp"
#include "commands.hpp"

int main(int argc, char** argv) {
  CLI::App app{"Artisan: 3-D sensor data to a world model a robot operator can act on."};
  app.set_version_flag("--version", "artisan 0.1.0");
  app.require_subcommand(1);
  artisan::cli::GlobalOptions options;
  app.add_flag("--json", options.json, "Machine-readable JSON on stdout");
  app.add_flag("-q,--quiet", options.quiet, "No messages on stderr");
  auto* db_option = app.add_option("--db", options.db, "Workspace file")->envname("ARTISAN_DB")->capture_default_str();
  artisan::cli::Action action;
  artisan::cli::add_file_commands(app, options, action);
  artisan::cli::add_workspace_commands(app, options, action);
  artisan::cli::add_pipeline_commands(app, options, action);
  artisan::cli::add_sim_commands(app, options, action);
  artisan::cli::add_sensor_commands(app, options, action);
  artisan::cli::add_teleop_commands(app, options, action);
  artisan::cli::add_robot_commands(app, options, action);
  artisan::cli::add_evaluate_command(app, options, action);
  artisan::cli::add_render_command(app, options, action);
  artisan::cli::add_grid_commands(app, options, action);
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    app.exit(e);
    return 2;
  }
  options.db_given = db_option->count() > 0 || std::getenv("ARTISAN_DB") != nullptr;
  try {
    return action ? action() : 2;
  } catch (const artisan::Error& e) {
    std::cerr << "artisan: error: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "artisan: error: " << e.what() << "\n";
    return 1;
  }
}
