// The sensor server's client commands: acquire (an acquisition into the workspace), sensors
// (what a server offers), ptu (move a pan/tilt head). The server is --server HOST:PORT, else
// $ARTISAN_SENSORD, else 127.0.0.1:7610. Exit codes: 0 ok, 1 bad input (unknown sensor, bad
// parameter, beyond the limits, ...), 2 the server or the sensor failed (unreachable, timeout,
// sensor failure).
#include <cmath>
#include <iostream>
#include <map>
#include <optional>
#include <set>

#include <nlohmann/json.hpp>

#include "artisan/core/error.hpp"
#include "artisan/sensors/client.hpp"
#include "commands.hpp"
#include "progress.hpp"

namespace artisan::cli {

namespace {

using nlohmann::json;

struct SensorArgs {
  std::string server;
  std::string sensor;
  std::vector<double> pan_deg, tilt_deg;          ///< acquire: the sweep
  std::optional<double> ptu_pan_deg, ptu_tilt_deg;  ///< ptu: the target
  std::optional<double> fov_deg;                    ///< zoom: the target
  std::vector<std::string> params;
  std::string folder = "/";
  std::string name;
};

double rad(double deg) { return deg * M_PI / 180.0; }
double deg(double rad) { return rad * 180.0 / M_PI; }

json transform_json(const Transform& T) {
  const auto m = to_row_major(T);
  return json(std::vector<double>(m.begin(), m.end()));
}

json environment_json(const sensors::EnvironmentReading& e) {
  return {{"time_s", e.time_s},
          {"dose_rate_uSv_per_h", e.dose_rate_uSv_per_h},
          {"temperature_C", e.temperature_C},
          {"humidity_percent", e.humidity_percent},
          {"T_world_rig", transform_json(e.T_world_rig)}};
}

json pan_tilt_json(const sensors::PanTiltState& p) {
  return {{"pan_rad", p.pan_rad}, {"tilt_rad", p.tilt_rad}, {"pan_deg", deg(p.pan_rad)}, {"tilt_deg", deg(p.tilt_rad)}};
}

json description_json(const sensors::SensorDescription& d) {
  json j{{"name", d.name}, {"kind", d.kind}, {"description", d.description}, {"range", d.range}, {"environment", d.environment},
         {"pan_tilt", nullptr}, {"zoom", nullptr}};
  if (d.pan_tilt)
    j["pan_tilt"] = {{"pan_min_rad", d.pan_tilt->pan_min_rad},   {"pan_max_rad", d.pan_tilt->pan_max_rad},
                     {"tilt_min_rad", d.pan_tilt->tilt_min_rad}, {"tilt_max_rad", d.pan_tilt->tilt_max_rad},
                     {"speed_rad_per_s", d.pan_tilt->speed_rad_per_s}};
  if (d.zoom) j["zoom"] = {{"min_fov_rad", d.zoom->min_fov_rad}, {"max_fov_rad", d.zoom->max_fov_rad}};
  json params = json::array();
  for (const auto& p : d.parameters)
    params.push_back({{"name", p.name}, {"type", p.type}, {"default", p.default_value}, {"unit", p.unit}, {"description", p.description}});
  j["parameters"] = params;
  return j;
}

std::map<std::string, std::string> parse_params(const std::vector<std::string>& list) {
  std::map<std::string, std::string> out;
  for (const auto& kv : list) {
    const auto eq = kv.find('=');
    if (eq == std::string::npos || eq == 0) throw Error("--param '" + kv + "': expected NAME=VALUE");
    if (!out.emplace(kv.substr(0, eq), kv.substr(eq + 1)).second) throw Error("--param '" + kv.substr(0, eq) + "' given twice");
  }
  return out;
}

/// Runs a command's body; a sensor error is reported with its code, exit 1 when the request was
/// at fault, 2 when the server or the sensor was.
int reporting(const GlobalOptions& options, const std::function<int()>& body) {
  try {
    return body();
  } catch (const sensors::SensorError& e) {
    using sensors::ErrorCode;
    const ErrorCode c = e.code();
    const bool bad_input = c == ErrorCode::kUnknownSensor || c == ErrorCode::kBadParameter || c == ErrorCode::kOutOfLimits ||
                           c == ErrorCode::kNotSupported || c == ErrorCode::kRequestTooLarge || c == ErrorCode::kMalformedRequest;
    if (!options.quiet) std::cerr << "artisan: error (" << sensors::to_string(c) << "): " << e.what() << "\n";
    return bad_input ? 1 : 2;
  }
}

/// The first "SENSOR-N" not taken in the folder.
std::string free_name(const worldmodel::Workspace& ws, const std::string& folder, const std::string& stem) {
  std::set<std::string> taken;
  for (const auto& o : ws.children(ws.folder(folder).id)) taken.insert(o.name);
  for (int n = 1;; ++n)
    if (!taken.count(stem + "-" + std::to_string(n))) return stem + "-" + std::to_string(n);
}

}  // namespace

void add_sensor_commands(CLI::App& app, const GlobalOptions& options, Action& action) {
  static SensorArgs a;
  const auto server_option = [](CLI::App* c) {
    c->add_option("--server", a.server, "Sensor server HOST:PORT (default: $ARTISAN_SENSORD, else 127.0.0.1:7610)");
    c->fallthrough();  // global options (--json, --db) may also follow the subcommand
  };

  auto* acquire = app.add_subcommand("acquire", "Take an acquisition through the sensor server and store it as an image in the workspace");
  acquire->add_option("sensor", a.sensor, "Sensor name (see 'artisan sensors')")->required();
  server_option(acquire);
  acquire->add_option("--pan", a.pan_deg, "Move the pan/tilt head first: pan [degrees]; a list (40,45,50) sweeps")->delimiter(',');
  acquire->add_option("--tilt", a.tilt_deg, "Move the pan/tilt head first: tilt [degrees]; a list sweeps (every pan at every tilt)")->delimiter(',');
  acquire->add_option("--param", a.params, "Acquisition parameter NAME=VALUE (repeatable; see 'artisan sensors')");
  acquire->add_option("--folder", a.folder, "Workspace folder the image goes into (must exist)")->capture_default_str();
  acquire->add_option("--name", a.name, "The image's name (default: SENSOR-N, the first free N); a sweep: NAME-1, NAME-2, ...");
  acquire->callback([&options, &action] {
    action = [&options] {
      return reporting(options, [&options] {
        // The head's poses: every pan at every tilt (none: where it is).
        std::vector<std::pair<std::optional<double>, std::optional<double>>> poses;
        const std::vector<std::optional<double>> pans = a.pan_deg.empty() ? std::vector<std::optional<double>>{std::nullopt}
                                                                           : std::vector<std::optional<double>>(a.pan_deg.begin(), a.pan_deg.end());
        const std::vector<std::optional<double>> tilts = a.tilt_deg.empty() ? std::vector<std::optional<double>>{std::nullopt}
                                                                             : std::vector<std::optional<double>>(a.tilt_deg.begin(), a.tilt_deg.end());
        for (const auto& t : tilts)
          for (const auto& p : pans) poses.emplace_back(p, t);
        const bool sweep = poses.size() > 1;
        // Check the destination before the (slow) acquisitions.
        ImageDestination dest = open_image_destination(options, a.folder, a.name.empty() ? "unnamed" : sweep ? a.name + "-1" : a.name);
        const std::string address = sensors::SensorClient::resolve_address(a.server);
        sensors::SensorClient client(address);
        // Acquire everything first, then store it all in one transaction (the workspace is not
        // held while the sensor works).
        struct Taken {
          sensors::AcquireRequest request;
          sensors::Acquisition acquisition;
          size_t bytes = 0;
        };
        std::vector<Taken> taken;
        Progress progress("acquiring from " + a.sensor, poses.size(), options.quiet || options.json);
        for (const auto& [pan, tilt] : poses) {
          sensors::AcquireRequest req;
          req.params = parse_params(a.params);
          if (pan) req.pan_rad = rad(*pan);
          if (tilt) req.tilt_rad = rad(*tilt);
          const auto encoded = client.acquire_encoded(a.sensor, req);
          taken.push_back({req, sensors::decode_acquisition(encoded, "sensor '" + a.sensor + "' via " + address), encoded.range_ari.size()});
          char where[96] = "";
          if (pan || tilt) std::snprintf(where, sizeof where, "pan %.1f, tilt %.1f deg", pan.value_or(0.0), tilt.value_or(0.0));
          progress.update(taken.size(), where);
        }
        json outs = json::array();
        std::vector<std::optional<worldmodel::ObjectId>> ids(taken.size());
        dest.workspace.write([&] {
          for (size_t k = 0; k < taken.size(); ++k) {
            const auto& acq = taken[k].acquisition;
            const auto& req = taken[k].request;
            if (!acq.range) continue;
            dest.name = !a.name.empty() ? (sweep ? a.name + "-" + std::to_string(k + 1) : a.name) : free_name(dest.workspace, a.folder, a.sensor);
            json metadata = json::object();
            if (acq.environment) metadata["environment"] = environment_json(*acq.environment);
            if (acq.pan_tilt) metadata["pan_tilt"] = pan_tilt_json(*acq.pan_tilt);
            json params{{"server", address}, {"sensor", a.sensor}, {"params", req.params}};
            if (req.pan_rad) params["pan_rad"] = *req.pan_rad;
            if (req.tilt_rad) params["tilt_rad"] = *req.tilt_rad;
            ids[k] = import_range_image(dest, *acq.range, {"sensor-acquire", params, {}}, metadata);
          }
        });
        for (size_t k = 0; k < taken.size(); ++k) {
          const auto& acq = taken[k].acquisition;
          json out{{"server", address}, {"sensor", a.sensor}, {"image", nullptr}, {"environment", nullptr}, {"pan_tilt", nullptr}};
          if (acq.environment) out["environment"] = environment_json(*acq.environment);
          if (acq.pan_tilt) out["pan_tilt"] = pan_tilt_json(*acq.pan_tilt);
          if (acq.range) {
            out["image"] = {{"id", *ids[k]}, {"path", dest.workspace.get(*ids[k]).path}};
            out["kind"] = acq.range->sensor.kind;
            out["width"] = acq.range->width;
            out["height"] = acq.range->height;
            out["valid_pixels"] = acq.range->valid_count();
            out["bytes"] = taken[k].bytes;
          }
          outs.push_back(out);
          if (options.json || options.quiet) continue;
          if (acq.range)
            std::cerr << "acquired " << acq.range->sensor.kind << " " << acq.range->width << " x " << acq.range->height << ", "
                      << acq.range->valid_count() << " valid pixels from " << a.sensor << " at " << address << "; stored as "
                      << out["image"]["path"].get<std::string>() << " (ID " << *ids[k] << ")\n";
          else
            std::cerr << "sensor '" << a.sensor << "' gives no range image: its reading is printed, nothing is stored\n";
          if (acq.environment)
            std::cerr << "environment: " << acq.environment->dose_rate_uSv_per_h << " uSv/h, " << acq.environment->temperature_C
                      << " C, " << acq.environment->humidity_percent << " % RH\n";
          if (acq.pan_tilt)
            std::cerr << "pan/tilt: " << deg(acq.pan_tilt->pan_rad) << ", " << deg(acq.pan_tilt->tilt_rad) << " degrees\n";
        }
        if (options.json) std::cout << (sweep ? json{{"acquisitions", outs}} : outs[0]).dump(2) << "\n";
        return 0;
      });
    };
  });

  auto* list = app.add_subcommand("sensors", "List the sensor server's sensors and their capabilities");
  server_option(list);
  list->callback([&options, &action] {
    action = [&options] {
      return reporting(options, [&options] {
        const std::string address = sensors::SensorClient::resolve_address(a.server);
        sensors::SensorClient client(address);
        const auto all = client.list();
        if (options.json) {
          json j = json::array();
          for (const auto& d : all) j.push_back(description_json(d));
          std::cout << json{{"server", address}, {"sensors", j}}.dump(2) << "\n";
          return 0;
        }
        for (const auto& d : all) {
          std::string caps;
          if (d.range) caps += " range";
          if (d.environment) caps += " environment";
          if (d.pan_tilt) {
            caps += " pan/tilt[pan " + std::to_string(deg(d.pan_tilt->pan_min_rad)) + ".." + std::to_string(deg(d.pan_tilt->pan_max_rad)) +
                    " deg, tilt " + std::to_string(deg(d.pan_tilt->tilt_min_rad)) + ".." + std::to_string(deg(d.pan_tilt->tilt_max_rad)) +
                    " deg]";
          }
          if (d.zoom) caps += " zoom";
          std::string params;
          for (const auto& p : d.parameters) params += (params.empty() ? " params:" : ",") + std::string(" ") + p.name;
          std::cout << d.name << "\t" << d.kind << "\t" << caps.substr(caps.empty() ? 0 : 1) << "\t" << params << "\n";
        }
        return 0;
      });
    };
  });

  auto* ptu = app.add_subcommand("ptu", "Move a sensor's pan/tilt head (or, without --pan/--tilt, read its position)");
  ptu->add_option("sensor", a.sensor, "Sensor name (one with pan/tilt; see 'artisan sensors')")->required();
  server_option(ptu);
  ptu->add_option("--pan", a.ptu_pan_deg, "Pan [degrees] (default: keep)");
  ptu->add_option("--tilt", a.ptu_tilt_deg, "Tilt [degrees] (default: keep)");
  ptu->callback([&options, &action] {
    action = [&options] {
      return reporting(options, [&options] {
        const std::string address = sensors::SensorClient::resolve_address(a.server);
        sensors::SensorClient client(address);
        auto reply = client.pan_tilt(a.sensor);
        if (a.ptu_pan_deg || a.ptu_tilt_deg) {
          sensors::PanTiltState target = reply.state;
          if (a.ptu_pan_deg) target.pan_rad = rad(*a.ptu_pan_deg);
          if (a.ptu_tilt_deg) target.tilt_rad = rad(*a.ptu_tilt_deg);
          reply = client.move_pan_tilt(a.sensor, target);
        }
        if (options.json) {
          json j = pan_tilt_json(reply.state);
          j["sensor"] = a.sensor;
          j["limits"] = {{"pan_min_rad", reply.limits.pan_min_rad},   {"pan_max_rad", reply.limits.pan_max_rad},
                         {"tilt_min_rad", reply.limits.tilt_min_rad}, {"tilt_max_rad", reply.limits.tilt_max_rad}};
          std::cout << j.dump(2) << "\n";
        } else {
          std::cout << a.sensor << "\tpan " << deg(reply.state.pan_rad) << "\ttilt " << deg(reply.state.tilt_rad) << "\t(degrees)\n";
        }
        return 0;
      });
    };
  });

  auto* zoom = app.add_subcommand("zoom", "Set a sensor's zoom (horizontal field of view), or, without --fov, read it");
  zoom->add_option("sensor", a.sensor, "Sensor name (one with a zoom; see 'artisan sensors')")->required();
  server_option(zoom);
  zoom->add_option("--fov", a.fov_deg, "Horizontal field of view [degrees], within the lens's zoom range");
  zoom->callback([&options, &action] {
    action = [&options] {
      return reporting(options, [&options] {
        const std::string address = sensors::SensorClient::resolve_address(a.server);
        sensors::SensorClient client(address);
        const auto state = a.fov_deg ? client.set_zoom(a.sensor, rad(*a.fov_deg)) : client.zoom(a.sensor);
        if (options.json)
          std::cout << json{{"sensor", a.sensor}, {"fov_rad", state.fov_rad}, {"fov_deg", deg(state.fov_rad)},
                            {"limits", {{"min_fov_rad", state.limits.min_fov_rad}, {"max_fov_rad", state.limits.max_fov_rad}}}}
                           .dump(2)
                    << "\n";
        else
          std::cout << a.sensor << "\tfov " << deg(state.fov_rad) << "\t(degrees; zoom range " << deg(state.limits.min_fov_rad) << " to "
                    << deg(state.limits.max_fov_rad) << ")\n";
        return 0;
      });
    };
  });
}

}  // namespace artisan::cli
