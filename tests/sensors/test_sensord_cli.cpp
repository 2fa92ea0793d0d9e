// artisan-sensord as a real process and the artisan command line as its client, over
// 127.0.0.1: sensors, acquire (into a workspace), ptu, error exit codes, SIGTERM shutdown.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <fcntl.h>

#include <chrono>
#include <fstream>
#include <thread>

#include <nlohmann/json.hpp>

#include "artisan/core/io/range_image_format.hpp"
#include "artisan/sensors/drivers.hpp"
#include "artisan/sensors/simulated.hpp"
#include "artisan/worldmodel/workspace.hpp"
#include "test_support.hpp"

namespace artisan::sensors {
namespace {

const std::string kCli = ARTISAN_CLI;
const std::string kSensord = ARTISAN_SENSORD;
const std::filesystem::path kCell = artisan::test::data_dir() / "workcells" / "pipework.json";

/// artisan-sensord in a child process; the bound address read from its first stdout line.
class Daemon {
 public:
  explicit Daemon(const std::vector<std::string>& args, const std::filesystem::path& err_file) {
    int out[2];
    if (::pipe(out) != 0) throw std::runtime_error("pipe");
    pid_ = ::fork();
    if (pid_ == 0) {
      ::dup2(out[1], 1);
      const int err = ::open(err_file.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      ::dup2(err, 2);
      ::close(out[0]);
      std::vector<char*> argv{const_cast<char*>(kSensord.c_str())};
      for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
      argv.push_back(nullptr);
      ::execv(kSensord.c_str(), argv.data());
      ::_exit(127);
    }
    ::close(out[1]);
    std::string line;
    char c;
    while (::read(out[0], &c, 1) == 1 && c != '\n') line += c;
    ::close(out[0]);
    address_ = line;
  }
  ~Daemon() {
    if (pid_ > 0 && !reaped_) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
  }
  const std::string& address() const { return address_; }
  /// Sends `sig`; the exit status (or 128 + signal), or -1 when it has not exited within `timeout_s`.
  int stop(int sig, double timeout_s) {
    ::kill(pid_, sig);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
    int status = 0;
    while (std::chrono::steady_clock::now() < deadline) {
      if (::waitpid(pid_, &status, WNOHANG) == pid_) {
        reaped_ = true;
        return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    return -1;
  }

 private:
  pid_t pid_ = -1;
  bool reaped_ = false;
  std::string address_;
};

std::string slurp(const std::filesystem::path& p) {
  std::ifstream in(p);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Method: start artisan-sensord on an ephemeral loopback port with the pipework workcell and the
// bunny scans as a replay sensor; list the sensors; acquire from each driver with the command
// line into a workspace (the address once by --server, otherwise from ARTISAN_SENSORD); the
// stored range images equal, byte for byte once encoded, direct driver calls made in the same
// order on a fresh simulator; the environmental readings and pan/tilt state are in the images'
// metadata. Errors exit 1 with the code and the offending value. SIGTERM stops it cleanly (exit
// 0) within seconds.
TEST(SensordCli, AcquireListMoveAndShutDown) {
  artisan::test::TempDir dir;
  Daemon d({"--workcell", kCell.string(), "--listen", "127.0.0.1:0", "--replay", "bunny=" + artisan::test::bunny_dir().string()},
           dir / "sensord.err");
  ASSERT_EQ(d.address().rfind("127.0.0.1:", 0), 0u) << d.address() << slurp(dir / "sensord.err");
  const std::string env = "ARTISAN_SENSORD=" + d.address() + " ";
  const std::string db = " --db " + (dir / "ws.db").string();

  auto r = artisan::test::run_command(kCli + " --json sensors --server " + d.address());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto list = nlohmann::json::parse(r.out);
  ASSERT_EQ(list["sensors"].size(), 4u);
  EXPECT_EQ(list["sensors"][1]["name"], "pioneer");
  EXPECT_EQ(list["sensors"][1]["pan_tilt"]["tilt_max_rad"], 0.52);
  EXPECT_EQ(list["sensors"][3]["kind"], "replay");

  ASSERT_EQ(artisan::test::run_command(kCli + db + " init").exit_code, 0);
  ASSERT_EQ(artisan::test::run_command(kCli + db + " mkdir /cell").exit_code, 0);
  r = artisan::test::run_command(env + kCli + db + " --json acquire vivid --param seed=4 --folder /cell");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(nlohmann::json::parse(r.out)["image"]["path"], "/cell/vivid-1");
  r = artisan::test::run_command(env + kCli + db + " acquire pioneer --pan 30 --tilt -15 --param seed=1 --folder /cell --name head");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = artisan::test::run_command(env + kCli + db + " --json acquire rig_environment");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto reading = nlohmann::json::parse(r.out);
  EXPECT_TRUE(reading["image"].is_null());
  EXPECT_GT(reading["environment"]["temperature_C"].get<double>(), 0.0);
  r = artisan::test::run_command(env + kCli + db + " acquire bunny --param file=bun000 --folder /cell");
  ASSERT_EQ(r.exit_code, 0) << r.err;

  // The same sequence, direct.
  auto cell = std::make_shared<SimulatedWorkcell>(kCell);
  SensorSet direct;
  add_workcell_sensors(direct, builtin_drivers(), cell);
  direct.add(builtin_drivers().create({"bunny", "replay", nullptr, artisan::test::bunny_dir()}));
  AcquireRequest vivid, pioneer, bun;
  vivid.params["seed"] = "4";
  pioneer.params["seed"] = "1";
  pioneer.pan_rad = 30 * M_PI / 180;
  pioneer.tilt_rad = -15 * M_PI / 180;
  bun.params["file"] = "bun000";
  const auto v = direct.get("vivid").acquire(vivid);
  const auto p = direct.get("pioneer").acquire(pioneer);
  const auto b = direct.get("bunny").acquire(bun);

  auto ws = worldmodel::Workspace::open(dir / "ws.db");
  const auto vivid_obj = ws.resolve("/cell/vivid-1");
  const auto head_obj = ws.resolve("/cell/head");
  EXPECT_TRUE(io::encode_range_image(ws.load_image(vivid_obj.id)) == io::encode_range_image(*v.range));
  EXPECT_TRUE(io::encode_range_image(ws.load_image(head_obj.id)) == io::encode_range_image(*p.range));
  EXPECT_TRUE(io::encode_range_image(ws.load_image(ws.resolve("/cell/bunny-1").id)) == io::encode_range_image(*b.range));
  EXPECT_EQ(head_obj.metadata["pan_tilt"]["pan_rad"].get<double>(), 30 * M_PI / 180);
  EXPECT_EQ(head_obj.metadata["environment"]["dose_rate_uSv_per_h"].get<double>(), p.environment->dose_rate_uSv_per_h);
  EXPECT_EQ(vivid_obj.metadata["environment"]["temperature_C"].get<double>(), v.environment->temperature_C);
  EXPECT_EQ(ws.provenance(head_obj.id)->operation, "sensor-acquire");

  // ptu in degrees; beyond the limits, unknown sensors and parameters: exit 1 naming the problem.
  r = artisan::test::run_command(env + kCli + " --json ptu pioneer --pan -45");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NEAR(nlohmann::json::parse(r.out)["pan_deg"].get<double>(), -45.0, 1e-9);
  EXPECT_NEAR(nlohmann::json::parse(r.out)["tilt_deg"].get<double>(), -15.0, 1e-9);
  r = artisan::test::run_command(env + kCli + " ptu pioneer --tilt 40");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("out-of-limits"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("0.52"), std::string::npos) << r.err;
  r = artisan::test::run_command(env + kCli + db + " acquire kinect");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("kinect"), std::string::npos) << r.err;
  r = artisan::test::run_command(env + kCli + db + " acquire vivid --param zoom=2");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("zoom"), std::string::npos) << r.err;

  EXPECT_EQ(d.stop(SIGTERM, 10.0), 0);
  EXPECT_NE(slurp(dir / "sensord.err").find("stopped after"), std::string::npos) << slurp(dir / "sensord.err");
  // Nobody listens any more: the command line says so and exits 2.
  r = artisan::test::run_command(env + kCli + " sensors");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("cannot connect"), std::string::npos) << r.err;
}

// Method: bad daemon arguments exit 1 with the reason; a workcell that cannot load likewise.
TEST(SensordCli, BadArguments) {
  artisan::test::TempDir dir;
  auto r = artisan::test::run_command(kSensord + " --listen 127.0.0.1:0");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("nothing to serve"), std::string::npos) << r.err;
  r = artisan::test::run_command(kSensord + " --listen 127.0.0.1:0 --replay x=" + (dir / "missing").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("missing"), std::string::npos) << r.err;
  r = artisan::test::run_command(kSensord + " --listen nowhere:0 --replay b=" + artisan::test::bunny_dir().string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("nowhere"), std::string::npos) << r.err;
  r = artisan::test::run_command(kSensord + " --workcell " + (dir / "none.json").string() + " --listen 127.0.0.1:0");
  EXPECT_EQ(r.exit_code, 1);
}

}  // namespace
}  // namespace artisan::sensors
