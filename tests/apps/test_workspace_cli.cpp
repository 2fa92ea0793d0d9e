// The workspace from the command line, end to end: import, ls, show, export; bad input leaves
// the workspace unchanged; SIGKILL at random moments leaves no partial object; concurrent
// writers do not corrupt it.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <fstream>
#include <iostream>
#include <random>
#include <thread>

#include <nlohmann/json.hpp>

#include "artisan/core/io/blob_container.hpp"
#include "artisan/worldmodel/database.hpp"
#include "test_support.hpp"

namespace artisan {
namespace {

using test::run_command;

const std::string kCli = ARTISAN_CLI;

std::string q(const std::filesystem::path& p) { return "'" + p.string() + "'"; }

std::string all_scans() {
  std::string s;
  for (const auto& name : test::bunny_scans()) s += " " + q(test::bunny_dir() / (name + ".ply"));
  return s;
}

// Every row of every table, blobs by size and checksum: equal dumps mean an unchanged workspace.
std::string dump(const std::filesystem::path& db_path) {
  auto db = worldmodel::open_sqlite(db_path);
  std::string out;
  for (const std::string table : {"meta", "objects", "blobs", "provenance", "provenance_inputs", "multimesh_members"}) {
    out += "[" + table + "]\n";
    for (const auto& row : db->query("SELECT * FROM " + table + " ORDER BY 1, 2")) {
      for (const auto& v : row) {
        if (const auto* i = std::get_if<int64_t>(&v)) out += std::to_string(*i);
        else if (const auto* d = std::get_if<double>(&v)) out += std::to_string(*d);
        else if (const auto* s = std::get_if<std::string>(&v)) out += *s;
        else if (const auto* b = std::get_if<worldmodel::SqlBlob>(&v)) out += "blob:" + std::to_string(b->size()) + ":" + std::to_string(io::crc32_of(*b));
        else out += "NULL";
        out += "|";
      }
      out += "\n";
    }
  }
  return out;
}

class WorkspaceCli : public ::testing::Test {
 protected:
  void SetUp() override {
    db_ = dir_ / "ws.db";
    ASSERT_EQ(run("init").exit_code, 0);
  }
  test::CommandResult run(const std::string& args) { return run_command(kCli + " --db " + q(db_) + " " + args); }
  test::TempDir dir_;
  std::filesystem::path db_;
};

TEST_F(WorkspaceCli, ImportTenScansListShowAndExport) {
  ASSERT_EQ(run("mkdir /cell/bunny").exit_code, 0);
  auto r = run("--json import --folder /cell/bunny" + all_scans());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("\"objects\""), std::string::npos);
  EXPECT_NE(r.out.find("\"path\": \"/cell/bunny/top3\""), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("\"kind\": \"image\""), std::string::npos);

  r = run("ls -r");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const auto& name : test::bunny_scans()) EXPECT_NE(r.out.find(name), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("512 x 400, 40256 valid pixels"), std::string::npos) << r.out;

  r = run("--json show /cell/bunny/bun045");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const std::string field : {"\"provenance\"", "\"operation\": \"import\"", "\"parameters\"", "\"inputs\"", "\"versions\"",
                                  "\"metadata\"", "\"valid_pixels\": 40097", "\"source\""})
    EXPECT_NE(r.out.find(field), std::string::npos) << field << "\n" << r.out;

  // Export round trip: the exported .ari describes the same scan.
  r = run("export /cell/bunny/bun045 --out " + q(dir_ / "out.ari"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = run_command(kCli + " info " + q(dir_ / "out.ari"));
  EXPECT_NE(r.out.find("40097 valid"), std::string::npos) << r.out;

  // A model with a grasp and a pose on an imported mesh.
  r = run("--json import " + q(test::bunny_dir() / "reconstruction" / "bun_zipper.ply") +
          " --as model --name bunny-model --grasp '0 0 0.1 0 0 0 1' --folder /cell");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("\"kind\": \"model\""), std::string::npos) << r.out;
  r = run("--json show /cell/bunny-missing");
  EXPECT_EQ(r.exit_code, 1);
  r = run("check");
  EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
}

TEST_F(WorkspaceCli, BadInputExitsOneAndLeavesTheWorkspaceUnchanged) {
  ASSERT_EQ(run("mkdir /a").exit_code, 0);
  ASSERT_EQ(run("import --folder /a " + q(test::bunny_dir() / "bun000.ply")).exit_code, 0);
  { std::ofstream(dir_ / "corrupt.ply") << "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n"; }
  const auto before = dump(db_);
  for (const auto& [args, fragment] : std::vector<std::pair<std::string, std::string>>{
           // A good file with a bad one imports neither: one transaction per operation.
           {"import --folder /a " + q(test::bunny_dir() / "bun045.ply") + " " + q(dir_ / "missing.ply"), "missing.ply"},
           {"import --folder /a " + q(test::bunny_dir() / "bun045.ply") + " " + q(dir_ / "corrupt.ply"), "corrupt.ply"},
           {"import --folder /nowhere " + q(test::bunny_dir() / "bun045.ply"), "/nowhere"},
           {"import --folder /a " + q(test::bunny_dir() / "bun000.ply"), "already exists"},
           {"import --folder /a --pose '1 2 3' " + q(test::bunny_dir() / "bun045.ply"), "pose"},
           {"import --folder /a --as mesh " + q(test::bunny_dir() / "bun045.ply"), "range image"},
           {"mkdir relative/path", "not absolute"},
           {"mkdir /a/bun000/x", "is a image"},
           {"rm 9999", "no object with ID 9999"},
           {"rm /a", "inside it"},
           {"mv /a/bun000 /zzz/yyy", "/zzz"},
           {"show /a/nope", "no object at /a/nope"},
           {"export /a --out " + q(dir_ / "x.ply"), "only images, meshes"},
           {"export /a/bun000 --out " + q(dir_ / "x.obj"), "cannot write a range image"},
           {"reprocess /a/bun000 --set min_angle_deg=10", "can be reprocessed"},
           {"reprocess /a/bun000 --set novalue", "not key=value"},
           {"mesh /a", "not an image"},
           {"mesh /a/bun000 --min-angle 40", "40"},
           {"mesh /a/bun000 --roi 1,2,3", "--roi"},
           {"mesh /a/bun000 --set bogus=1", "no parameter \"bogus\""},
       }) {
    const auto r = run(args);
    EXPECT_EQ(r.exit_code, 1) << args << "\n" << r.err;
    EXPECT_NE(r.err.find(fragment), std::string::npos) << args << "\n" << r.err;
    EXPECT_EQ(dump(db_), before) << args;
  }
  EXPECT_FALSE(std::filesystem::exists(dir_ / "x.obj"));
  // Usage errors exit 2.
  EXPECT_EQ(run("import").exit_code, 2);
  EXPECT_EQ(run("import --as banana x.ply").exit_code, 2);
  EXPECT_EQ(dump(db_), before);
  // A missing workspace is named.
  const auto r = run_command(kCli + " --db " + q(dir_ / "none.db") + " ls");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("does not exist"), std::string::npos) << r.err;
}

TEST_F(WorkspaceCli, MeshRegisterRecognizeAndReprocessFromTheCommandLine) {
  // Method: the pipeline's commands on two real scans: mesh both, register them into a
  // multimesh (bun045's pose relative to bun000 must match bun.conf's translation), recognize the
  // bunny model in bun045 with its grasp, and reprocess a mesh with one parameter changed.
  ASSERT_EQ(run("mkdir /b").exit_code, 0);
  ASSERT_EQ(run("import --folder /b " + q(test::bunny_dir() / "bun000.ply") + " " + q(test::bunny_dir() / "bun045.ply")).exit_code, 0);
  auto r = run("--json mesh /b/bun000");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const std::string field : {"\"faces\"", "\"vertices\"", "\"resolution_m\"", "\"min_angle_image_deg\"", "\"id\""})
    EXPECT_NE(r.out.find(field), std::string::npos) << field << r.out;
  ASSERT_EQ(run("mesh /b/bun045 --min-angle 20").exit_code, 0);
  ASSERT_EQ(run("multimesh new views --folder /b").exit_code, 0);
  ASSERT_EQ(run("multimesh add /b/views /b/bun000-mesh").exit_code, 0);
  r = run("--json multimesh add /b/views /b/bun045-mesh");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = run("--json multimesh show /b/views");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto members = nlohmann::json::parse(r.out)["members"];
  ASSERT_EQ(members.size(), 2u);
  const auto& T = members[1]["T_root_member"];
  EXPECT_NEAR(T[3].get<double>(), -0.0520211, 0.002);   // bun.conf: bun045 at (-0.0520, -0.0004, -0.0109)
  EXPECT_NEAR(T[7].get<double>(), -0.000384, 0.002);
  EXPECT_NEAR(T[11].get<double>(), -0.0109223, 0.002);
  ASSERT_EQ(run("import --as model --name bunny --grasp '0 0 0.1 0 0 0 1' " + q(test::bunny_dir() / "reconstruction" / "bun_zipper.ply")).exit_code, 0);
  r = run("--json recognize /b/bun045-mesh --models /bunny");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto instances = nlohmann::json::parse(r.out)["instances"];
  ASSERT_EQ(instances.size(), 1u) << r.out;
  r = run("--json show " + instances[0]["path"].get<std::string>());
  EXPECT_NE(r.out.find("T_scene_grasps"), std::string::npos) << r.out;
  r = run("--json reprocess /b/bun000-mesh --set thinning_tolerance=0");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("\"version\": 2"), std::string::npos) << r.out;
  EXPECT_EQ(run("check").exit_code, 0);
}

TEST_F(WorkspaceCli, RecognizeNamesTheOtherModelOfAnAmbiguousInstance) {
  // Method: bench_recognition's scene 85 (data/recognition/clutter-scene85, one simulated Vivid
  // view) imported and meshed, the tee and the straight pipe imported as models: its pipe_350#1
  // (48% occluded) is found as a tee with its branch hidden, which a pipe on its run explains as
  // well. The JSON must name the pipe as the alternative model, with its pose; the plain report
  // must say it.
  ASSERT_EQ(run("mkdir /s").exit_code, 0);
  ASSERT_EQ(run("import --folder /s --name scene85 " + q(test::data_dir() / "recognition" / "clutter-scene85" / "range.ari")).exit_code, 0);
  ASSERT_EQ(run("mesh /s/scene85").exit_code, 0);
  for (const std::string name : {"tee", "pipe_350"})
    ASSERT_EQ(run("import --as model --name " + name + " " + q(test::data_dir() / "workcells" / "models" / (name + ".ply"))).exit_code, 0);
  auto r = run("--json recognize /s/scene85-mesh --models /tee,/pipe_350");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto result = nlohmann::json::parse(r.out);
  bool named = false;
  for (const auto& i : result["instances"])
    if (i["ambiguous"].get<bool>() && i["model"] == "tee" && i["alternative_model"] == "pipe_350") named = i["T_scene_model_alternative"].size() == 16;
  EXPECT_TRUE(named) << r.out;
  r = run("recognize /s/scene85-mesh --models /tee,/pipe_350");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("(ambiguous: pipe_350 fits the same surface almost as well)"), std::string::npos) << r.err;
}

pid_t spawn(const std::vector<std::string>& args) {
  const pid_t pid = fork();
  if (pid == 0) {
    std::vector<char*> argv;
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    // Quiet child: its messages are not part of the test.
    freopen("/dev/null", "w", stderr);
    freopen("/dev/null", "w", stdout);
    execv(argv[0], argv.data());
    _exit(127);
  }
  return pid;
}

std::vector<std::string> import_args(const std::filesystem::path& db, const std::string& folder) {
  std::vector<std::string> args = {kCli, "--db", db.string(), "import", "--folder", folder};
  for (const auto& name : test::bunny_scans()) args.push_back((test::bunny_dir() / (name + ".ply")).string());
  return args;
}

size_t count_children(const std::filesystem::path& db, const std::string& folder) {
  const auto r = run_command(kCli + " --db " + q(db) + " --json ls " + folder);
  size_t n = 0;
  for (size_t pos = 0; (pos = r.out.find("\"kind\": \"image\"", pos)) != std::string::npos; ++pos) ++n;
  return n;
}

TEST_F(WorkspaceCli, KilledImportsLeaveNoPartialObject) {
  // Method: start an import of ten scans, SIGKILL it after a random delay (before, during or
  // after its single transaction), repeatedly; every time the workspace must pass `check` and
  // the folder must hold either all ten scans or none.
  std::mt19937 rng(42);
  int complete = 0, empty = 0;
  for (int i = 0; i < 12; ++i) {
    const std::string folder = "/k" + std::to_string(i);
    ASSERT_EQ(run("mkdir " + folder).exit_code, 0);
    const pid_t pid = spawn(import_args(db_, folder));
    // A sweep from 0 to ~0.9 s with jitter: the first kills land before the commit on any machine.
    std::this_thread::sleep_for(std::chrono::milliseconds(75 * i + std::uniform_int_distribution<int>(0, 40)(rng)));
    kill(pid, SIGKILL);
    int status = 0;
    waitpid(pid, &status, 0);
    const auto r = run("check");
    ASSERT_EQ(r.exit_code, 0) << "after kill " << i << ": " << r.out << r.err;
    const size_t n = count_children(db_, folder);
    EXPECT_TRUE(n == 0 || n == 10) << "kill " << i << " left " << n << " scans";
    (n == 10 ? complete : empty)++;
  }
  // The delays must have hit both sides of the commit for the test to mean anything.
  EXPECT_GT(empty, 0);
  std::cout << "killed imports: " << complete << " complete, " << empty << " empty\n";
}

TEST_F(WorkspaceCli, ConcurrentWritersDoNotCorruptTheWorkspace) {
  // Method: two processes import ten scans each into their own folders at the same time,
  // three rounds; both must succeed (waiting for the write lock) and everything must be there.
  for (int round = 0; round < 3; ++round) {
    const std::string a = "/a" + std::to_string(round), b = "/b" + std::to_string(round);
    ASSERT_EQ(run("mkdir " + a).exit_code, 0);
    ASSERT_EQ(run("mkdir " + b).exit_code, 0);
    const pid_t pa = spawn(import_args(db_, a));
    const pid_t pb = spawn(import_args(db_, b));
    int sa = 0, sb = 0;
    waitpid(pa, &sa, 0);
    waitpid(pb, &sb, 0);
    EXPECT_TRUE(WIFEXITED(sa) && WEXITSTATUS(sa) == 0) << "round " << round;
    EXPECT_TRUE(WIFEXITED(sb) && WEXITSTATUS(sb) == 0) << "round " << round;
    EXPECT_EQ(count_children(db_, a), 10u);
    EXPECT_EQ(count_children(db_, b), 10u);
  }
  EXPECT_EQ(run("check").exit_code, 0);
}

}  // namespace
}  // namespace artisan
