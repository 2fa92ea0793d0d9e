// artisand: the world-model service. Serves the world model of one workcell folder over LCM
// (see teleop_bridge/ and lcm_types/). Exit codes: 0 stopped by SIGTERM/SIGINT, 1 bad input
// (no workspace, no such folder, LCM unavailable), 2 usage error.
#include <csignal>
#include <cstdlib>
#include <iostream>

#include <CLI/CLI.hpp>

#include "artisan/core/error.hpp"
#include "artisan/core/scheduling.hpp"
#include "artisan/teleop_bridge/channels.hpp"
#include "artisan/teleop_bridge/service.hpp"

namespace {
std::atomic<bool> g_stop{false};
void on_signal(int) { g_stop = true; }
}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"artisand: the Artisan world-model service (LCM)."};
  std::string db = "artisan.db", url = artisan::teleop::kDefaultLcmUrl;
  artisan::teleop::ServiceOptions options;
  bool quiet = false;
  int realtime_priority = 0;
  app.add_option("--db", db, "Workspace file")->envname("ARTISAN_DB")->capture_default_str();
  app.add_option("--folder", options.folder, "Workcell folder to serve")->capture_default_str();
  app.add_option("--lcm-url", url, "LCM URL")->envname("LCM_DEFAULT_URL")->capture_default_str();
  app.add_option("--snapshot-period", options.snapshot_period_s, "Seconds between full snapshots")->capture_default_str()->check(CLI::PositiveNumber);
  app.add_option("--poll-period", options.poll_period_s, "Seconds between looks for workspace changes")->capture_default_str()->check(CLI::PositiveNumber);
  app.add_option("--margin", options.world.object_margin_m, "Collision margin of recognized objects [m]")->capture_default_str()->check(CLI::NonNegativeNumber);
  app.add_option("--cutout", options.world.cutout_distance_m, "Environment within this of an object is its surface [m]")->capture_default_str()->check(CLI::NonNegativeNumber);
  app.add_option("--realtime", realtime_priority,
                 "Serve under SCHED_FIFO at this priority (1-99) with memory locked, so that no ordinary thread, the kernel's "
                 "included, delays an answer (needs root or CAP_SYS_NICE and CAP_IPC_LOCK)")
      ->check(CLI::Range(1, 99));
  app.add_flag("-q,--quiet", quiet, "No messages on stderr");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? 0 : 2;
  }
  try {
    if (!std::filesystem::exists(db)) throw artisan::Error("no workspace at " + db + " (create one with `artisan init`)");
    if (realtime_priority) artisan::run_in_realtime(realtime_priority);
    auto ws = artisan::worldmodel::Workspace::open(db);
    lcm::LCM lcm(url);
    if (!lcm.good()) throw artisan::Error("cannot open LCM at " + url);
    artisan::teleop::Service service(ws, lcm, options);
    std::signal(SIGTERM, on_signal);
    std::signal(SIGINT, on_signal);
    if (!quiet)
      std::cerr << "artisand: serving " << service.world().folder() << " of " << db << " (" << service.world().objects().size()
                << " objects, revision " << service.world().revision() << ") on " << url << std::endl;
    service.run(g_stop);
    if (!quiet)
      std::cerr << "artisand: stopped after " << service.stats().queries_answered << " queries, " << service.stats().commands_applied
                << " commands, " << service.stats().malformed_messages << " malformed messages" << std::endl;
    return 0;
  } catch (const std::exception& e) {
    std::cerr << "artisand: error: " << e.what() << "\n";
    return 1;
  }
}
