// `artisan evaluate FOLDER --truth truth.json ...`: a folder's recognized objects against the
// ground truth that `artisan sim scan` writes beside each simulated acquisition (or any file of
// that form: objects with name, model, role and T_world_object). Prints, per recognized object,
// the true instance it matches and its pose error, then the true objects missed.
#include <algorithm>
#include <array>
#include <fstream>
#include <iomanip>
#include <iostream>

#include "artisan/core/error.hpp"
#include "artisan/core/pose.hpp"
#include "artisan/worldmodel/evaluation.hpp"
#include "artisan/worldmodel/world_model.hpp"
#include "commands.hpp"

namespace artisan::cli {
namespace {

using nlohmann::json;

Transform transform_from_json(const json& a, const std::string& where) {
  if (!a.is_array() || a.size() != 16) throw Error(where + ": expected a row-major 4x4 array of 16 numbers");
  std::array<double, 16> m{};
  for (size_t i = 0; i < 16; ++i) {
    if (!a[i].is_number()) throw Error(where + ": element " + std::to_string(i) + " is not a number");
    m[i] = a[i].get<double>();
  }
  try {
    return from_row_major(m);  // checks finite, rigid, last row 0 0 0 1
  } catch (const Error& e) {
    throw Error(where + ": " + e.what());
  }
}

// The objects of every truth file (role "object"), each once, with its best visible fraction.
std::vector<worldmodel::TrueObject> read_truth(const std::vector<std::string>& files) {
  std::vector<worldmodel::TrueObject> out;
  for (const auto& file : files) {
    std::ifstream in(file);
    if (!in) throw Error(file + ": cannot be read");
    json j;
    try {
      j = json::parse(in);
    } catch (const json::exception& e) {
      throw Error(file + ": not JSON (" + std::string(e.what()) + ")");
    }
    if (!j.is_object() || !j.contains("objects") || !j["objects"].is_array()) throw Error(file + ": no 'objects' array (not a ground-truth file)");
    for (size_t i = 0; i < j["objects"].size(); ++i) {
      const auto& o = j["objects"][i];
      const std::string where = file + ": objects[" + std::to_string(i) + "]";
      if (!o.is_object() || !o.contains("name") || !o["name"].is_string()) throw Error(where + ": no name");
      if (o.value("role", std::string("object")) != "object") continue;
      worldmodel::TrueObject t;
      t.name = o["name"].get<std::string>();
      t.model = o.value("model", std::string());
      if (!o.contains("T_world_object")) throw Error(where + ".T_world_object: missing");
      t.T_world_object = transform_from_json(o["T_world_object"], where + ".T_world_object");
      t.visible_fraction = o.value("visible_fraction", 1.0);
      auto same = std::find_if(out.begin(), out.end(), [&](const auto& x) { return x.name == t.name; });
      if (same == out.end()) out.push_back(t);
      else same->visible_fraction = std::max(same->visible_fraction, t.visible_fraction);
    }
  }
  return out;
}

void collect_model_names(const worldmodel::Workspace& ws, worldmodel::ObjectId folder, std::vector<std::string>& out) {
  for (const auto& o : ws.children(folder)) {
    if (o.kind == worldmodel::ObjectKind::kModel) out.push_back(o.name);
    if (o.kind == worldmodel::ObjectKind::kFolder) collect_model_names(ws, o.id, out);
  }
}

struct EvaluateOptions {
  std::string folder;
  std::vector<std::string> truth;
  worldmodel::EvaluationParams params;
};

}  // namespace

void add_evaluate_command(CLI::App& app, const GlobalOptions& options, Action& action) {
  auto o = std::make_shared<EvaluateOptions>();
  auto* cmd = app.add_subcommand("evaluate", "A folder's recognized objects against ground truth (the truth.json of simulated scans)");
  cmd->add_option("folder", o->folder, "Workcell folder")->required();
  cmd->add_option("--truth", o->truth, "Ground-truth file (repeatable: one per view; visibility is the best over them)")->required();
  cmd->add_option("--max-mean-distance", o->params.max_mean_distance_m, "A correct pose: mean surface distance at most this [m]")
      ->capture_default_str()->check(CLI::PositiveNumber);
  cmd->add_option("--max-centre-distance", o->params.max_centre_distance_m, "A correct pose: centroid within this [m]")
      ->capture_default_str()->check(CLI::PositiveNumber);
  cmd->add_option("--min-visible", o->params.min_visible_fraction, "True objects seen less than this fraction are not expected")
      ->capture_default_str()->check(CLI::Range(0.0, 1.0));
  cmd->callback([&options, &action, o] {
    action = [&options, o] {
      const auto truth = read_truth(o->truth);
      auto ws = worldmodel::Workspace::open(options.db);
      const worldmodel::WorldModel world(ws, o->folder);
      std::vector<std::string> library;
      collect_model_names(ws, ws.root(), library);
      const auto r = worldmodel::evaluate_recognition(world, truth, library, o->params);
      if (options.json) {
        json dets = json::array(), objs = json::array();
        for (const auto& d : r.detections)
          dets.push_back({{"path", d.path}, {"model", d.model}, {"matched", d.matched.empty() ? json(nullptr) : json(d.matched)},
                          {"correct", d.correct}, {"rotation_deg", d.rotation_deg}, {"translation_m", d.translation_m},
                          {"mean_distance_m", d.mean_distance_m}, {"centre_distance_m", d.centre_distance_m}});
        for (const auto& t : r.truth)
          objs.push_back({{"name", t.name}, {"model", t.model}, {"visible_fraction", t.visible_fraction}, {"expected", t.counted},
                          {"found_as", t.found_as.empty() ? json(nullptr) : json(t.found_as)}});
        std::cout << json{{"folder", world.folder()}, {"expected", r.expected}, {"found", r.found}, {"missed", r.missed},
                          {"false_positives", r.false_positives}, {"max_rotation_deg", r.max_rotation_deg},
                          {"max_translation_m", r.max_translation_m}, {"max_mean_distance_m", r.max_mean_distance_m},
                          {"detections", dets}, {"truth", objs}}
                         .dump(2)
                  << "\n";
        return 0;
      }
      if (options.quiet) return 0;
      auto& out = std::cout;
      out << std::fixed;
      for (const auto& d : r.detections) {
        out << (d.correct ? "correct  " : "WRONG    ") << d.path << " (" << d.model << ")";
        if (d.correct) out << " = " << d.matched;
        if (d.mean_distance_m > 0 || d.correct)
          out << ": pose error (strict) " << std::setprecision(2) << d.rotation_deg << " deg, " << d.translation_m * 1e3 << " mm; surface "
              << d.mean_distance_m * 1e3 << " mm, centre " << d.centre_distance_m * 1e3 << " mm";
        else
          out << ": no true instance of " << d.model;
        out << "\n";
      }
      for (const auto& t : r.truth)
        if (t.found_as.empty() && !t.model.empty())
          out << (t.counted ? "MISSED   " : "not seen ") << t.name << " (" << t.model << ", " << std::setprecision(0) << 100 * t.visible_fraction
              << "% visible)\n";
      out << r.found << " of " << r.expected << " library objects seen at least " << std::setprecision(0) << 100 * o->params.min_visible_fraction
          << "% found at their pose, " << r.false_positives << " false positive(s)";
      if (r.found > 0) out << "; worst surface error " << std::setprecision(2) << r.max_mean_distance_m * 1e3 << " mm";
      out << "\n";
      return 0;
    };
  });
}

}  // namespace artisan::cli
