// artisan sim: the simulated workcell -- scan with a simulated sensor, render a picture, list
// the sensors, write the generated pipework models.
#include <filesystem>
#include <iostream>
#include <optional>

#include <nlohmann/json.hpp>

#include "artisan/core/error.hpp"
#include "artisan/core/io/mesh_io.hpp"
#include "artisan/sim/acquisition.hpp"
#include "artisan/sim/shapes.hpp"
#include "artisan/sim/simulator.hpp"
#include "artisan/worldmodel/workspace.hpp"
#include "commands.hpp"

namespace artisan::cli {

namespace {

using nlohmann::json;

struct SimArgs {
  std::string workcell;
  std::string sensor;
  std::string pose;
  std::optional<double> pan, tilt;
  uint64_t seed = 0;
  std::string out;
  std::string camera_pose;
  std::vector<double> look_at;
  int width = 640, height = 480;
  double fov_deg = 60.0;
  std::vector<std::string> package_paths;
  std::string folder = "/";
  std::string name;
};

std::vector<std::filesystem::path> paths(const std::vector<std::string>& v) { return {v.begin(), v.end()}; }

json pose_json(const Transform& T) {
  const auto m = to_row_major(T);
  return json(std::vector<double>(m.begin(), m.end()));
}

}  // namespace

ImageDestination open_image_destination(const GlobalOptions& options, const std::string& folder, const std::string& name) {
  ImageDestination d{worldmodel::Workspace::open(options.db), folder, name};
  d.workspace.folder(folder);  // throws when missing
  worldmodel::validate_name(name);
  return d;
}

worldmodel::ObjectId import_range_image(ImageDestination& destination, const RangeImage& range, const worldmodel::Provenance& provenance,
                                        const nlohmann::json& metadata) {
  worldmodel::NewObject object = worldmodel::make_image_object(destination.name, range, provenance);
  object.metadata.update(metadata);
  return destination.workspace.add(destination.workspace.folder(destination.folder).id, object);
}

void add_sim_commands(CLI::App& app, const GlobalOptions& options, Action& action) {
  static SimArgs a;
  auto* sim = app.add_subcommand("sim", "The simulated workcell: scan, render, sensors, models");
  sim->require_subcommand(1);

  auto* scan = sim->add_subcommand("scan", "Take an acquisition with a simulated sensor; writes the range image, PNGs and ground truth");
  scan->add_option("workcell", a.workcell, "Workcell file (JSON)")->required();
  scan->add_option("--sensor", a.sensor, "Sensor name (see 'artisan sim sensors')")->required();
  auto* pose_opt = scan->add_option("--pose", a.pose, "Sensor pose T_world_sensor: 'tx ty tz qx qy qz qw' or 16 numbers");
  auto* pan_opt = scan->add_option("--pan", a.pan, "Pan angle [rad] (sensors on a pan/tilt unit)");
  auto* tilt_opt = scan->add_option("--tilt", a.tilt, "Tilt angle [rad] (sensors on a pan/tilt unit)");
  pose_opt->excludes(pan_opt)->excludes(tilt_opt);
  scan->add_option("--seed", a.seed, "Noise seed")->capture_default_str();
  scan->add_option("--out", a.out, "Output folder")->required();
  scan->add_option("--package-path", a.package_paths, "Folders searched for package:// URIs");
  scan->add_option("--folder", a.folder, "With --db: the workspace folder the acquisition is imported into (must exist)")->capture_default_str();
  scan->add_option("--name", a.name, "With --db: the image's name (default: the --out folder's name)");
  scan->callback([&options, &action] {
    action = [&options] {
      sim::LoadOptions lo;
      lo.package_paths = paths(a.package_paths);
      sim::Simulator simulator(sim::load_workcell(a.workcell, lo));
      sim::ScanRequest req;
      req.sensor = a.sensor;
      if (!a.pose.empty()) req.T_world_sensor = parse_transform(a.pose);
      req.pan_rad = a.pan;
      req.tilt_rad = a.tilt;
      req.seed = a.seed;
      // With a workspace, check the destination before the (slow) scan.
      std::optional<ImageDestination> dest;
      std::string name = a.name.empty() ? std::filesystem::path(a.out).lexically_normal().filename().string() : a.name;
      if (name.empty()) name = std::filesystem::path(a.out).lexically_normal().parent_path().filename().string();
      if (options.db_given) dest.emplace(open_image_destination(options, a.folder, name));
      const auto acq = simulator.scan(req);
      sim::write_acquisition(acq, a.out);
      std::optional<worldmodel::ObjectId> image_id;
      if (dest) {
        json params = {{"workcell", std::filesystem::absolute(a.workcell).lexically_normal().string()}, {"sensor", a.sensor},
                       {"seed", a.seed}, {"out", std::filesystem::absolute(a.out).lexically_normal().string()}};
        if (!a.pose.empty()) params["pose"] = pose_json(*req.T_world_sensor);
        if (a.pan) params["pan_rad"] = *a.pan;
        if (a.tilt) params["tilt_rad"] = *a.tilt;
        image_id = import_range_image(*dest, acq.range, {"sim-scan", params, {}});
      }
      const auto& s = simulator.settle_result();
      if (options.json) {
        std::cout << json{{"out", a.out},
                          {"sensor", acq.range.sensor.name},
                          {"kind", acq.range.sensor.kind},
                          {"width", acq.range.width},
                          {"height", acq.range.height},
                          {"valid_pixels", acq.range.valid_count()},
                          {"time_s", acq.truth.time_s},
                          {"T_world_sensor", pose_json(acq.truth.T_world_sensor)},
                          {"settled", {{"dropped", s.dropped}, {"at_rest", s.at_rest}, {"simulated_time_s", s.simulated_time_s}}},
                          {"image", image_id ? json{{"id", *image_id}, {"path", dest->workspace.get(*image_id).path}} : json(nullptr)}}
                         .dump(2)
                  << "\n";
      } else if (!options.quiet) {
        std::cerr << "wrote " << a.out << ": " << acq.range.sensor.kind << " " << acq.range.width << " x " << acq.range.height
                  << ", " << acq.range.valid_count() << " valid pixels, ground truth in truth.json\n";
        if (image_id) std::cerr << "imported as " << dest->workspace.get(*image_id).path << " (ID " << *image_id << ")\n";
        if (!s.at_rest) std::cerr << "warning: " << s.still_moving.size() << " dropped object(s) had not come to rest\n";
      }
      return 0;
    };
  });

  auto* render = sim->add_subcommand("render", "Draw a picture of the workcell (PNG)");
  render->add_option("workcell", a.workcell, "Workcell file (JSON)")->required();
  render->add_option("--camera", a.camera_pose, "Camera pose T_world_camera ('tx ty tz qx qy qz qw' or 16 numbers; "
                                                "camera x right, y down, z forward), or the name of a sensor");
  auto* look_opt = render->add_option("--look-at", a.look_at, "Camera at EX EY EZ looking at TX TY TZ (z up)")->expected(6);
  render->get_option("--camera")->excludes(look_opt);
  render->add_option("--width", a.width, "Image width [pixels]")->capture_default_str()->check(CLI::PositiveNumber);
  render->add_option("--height", a.height, "Image height [pixels]")->capture_default_str()->check(CLI::PositiveNumber);
  render->add_option("--fov", a.fov_deg, "Horizontal field of view [degrees]")->capture_default_str()->check(CLI::Range(1.0, 170.0));
  render->add_option("--out", a.out, "Output PNG")->required();
  render->add_option("--package-path", a.package_paths, "Folders searched for package:// URIs");
  render->callback([&options, &action] {
    action = [&options] {
      sim::LoadOptions lo;
      lo.package_paths = paths(a.package_paths);
      sim::Simulator simulator(sim::load_workcell(a.workcell, lo));
      if (a.camera_pose.empty() && a.look_at.empty()) throw Error("sim render: give --camera or --look-at");
      Transform T_world_camera;
      bool is_sensor = false;
      for (const auto& s : simulator.workcell().sensors) is_sensor |= s.name == a.camera_pose;
      T_world_camera = is_sensor ? simulator.workcell().T_world_sensor(simulator.workcell().sensor(a.camera_pose))
                                 : a.camera_pose.empty() ? Transform::Identity() : parse_transform(a.camera_pose);
      if (!a.look_at.empty()) {
        const Eigen::Vector3d eye(a.look_at[0], a.look_at[1], a.look_at[2]), target(a.look_at[3], a.look_at[4], a.look_at[5]);
        if ((target - eye).norm() < 1e-9) throw Error("sim render: --look-at eye and target coincide");
        const Eigen::Vector3d z = (target - eye).normalized();
        Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitZ());
        if (x.norm() < 1e-9) x = Eigen::Vector3d::UnitX();
        x.normalize();
        T_world_camera.linear() << x, z.cross(x), z;
        T_world_camera.translation() = eye;
      }
      const auto cam = sim::camera_from_fov(a.width, a.height, a.fov_deg * M_PI / 180.0);
      sim::RenderOptions ro;
      ro.instances = false;
      ro.depth = false;
      const auto r = simulator.render(cam, T_world_camera, ro);
      sim::write_png(r.color, a.out);
      if (options.json) std::cout << json{{"out", a.out}, {"width", a.width}, {"height", a.height}}.dump(2) << "\n";
      else if (!options.quiet) std::cerr << "wrote " << a.out << "\n";
      return 0;
    };
  });

  auto* sensors = sim->add_subcommand("sensors", "List the workcell's sensors and their kinds");
  sensors->add_option("workcell", a.workcell, "Workcell file (JSON)")->required();
  sensors->add_option("--package-path", a.package_paths, "Folders searched for package:// URIs");
  sensors->callback([&options, &action] {
    action = [&options] {
      sim::LoadOptions lo;
      lo.package_paths = paths(a.package_paths);
      const auto cell = sim::load_workcell(a.workcell, lo);
      json list = json::array();
      for (const auto& s : cell.sensors) {
        json j{{"name", s.name}, {"kind", s.kind}, {"mount", s.mount}, {"T_world_sensor", pose_json(cell.T_world_sensor(s))}};
        if (!s.pan_tilt_robot.empty()) {
          const auto& ptu = cell.robot(s.pan_tilt_robot);
          const auto& pan = ptu.joint(s.pan_joint);
          const auto& tilt = ptu.joint(s.tilt_joint);
          j["pan_tilt"] = {{"unit", ptu.name},
                           {"pan", {{"joint", pan.name}, {"lower_rad", pan.lower}, {"upper_rad", pan.upper}, {"speed_rad_per_s", pan.velocity}}},
                           {"tilt", {{"joint", tilt.name}, {"lower_rad", tilt.lower}, {"upper_rad", tilt.upper}, {"speed_rad_per_s", tilt.velocity}}}};
        }
        list.push_back(j);
      }
      if (options.json) {
        std::cout << json{{"workcell", cell.name}, {"sensors", list}}.dump(2) << "\n";
      } else {
        for (const auto& s : list) std::cout << s["name"].get<std::string>() << "\t" << s["kind"].get<std::string>() << "\n";
      }
      return 0;
    };
  });

  auto* models = sim->add_subcommand("models", "Write the generated pipework models (PLY) into a folder");
  models->add_option("--out", a.out, "Output folder")->required();
  models->callback([&options, &action] {
    action = [&options] {
      std::filesystem::create_directories(a.out);
      const std::vector<std::pair<std::string, TriangleMesh>> list = {
          {"pipe_350.ply", sim::make_pipe(0.35)},        {"elbow_90.ply", sim::make_elbow(0.076)},
          {"tee.ply", sim::make_tee(0.22, 0.11)},        {"flange.ply", sim::make_flange(0.165, 0.02, 0.06)},
          {"valve.ply", sim::make_valve(0.24)}};
      for (const auto& [name, mesh] : list) io::write_mesh(mesh, std::filesystem::path(a.out) / name);
      if (options.json) std::cout << json{{"out", a.out}, {"models", list.size()}}.dump(2) << "\n";
      else if (!options.quiet) std::cerr << "wrote " << list.size() << " models to " << a.out << "\n";
      return 0;
    };
  });
}

}  // namespace artisan::cli
