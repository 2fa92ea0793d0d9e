#include "artisan/worldmodel/evaluation.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numbers>

#include "artisan/core/error.hpp"
#include "artisan/core/pose.hpp"
#include "artisan/perception/kdtree.hpp"
#include "artisan/perception/spin_image.hpp"

namespace artisan::worldmodel {

namespace {

struct PoseError {
  double rotation_deg = 0, translation_m = 0, mean_m = 0, centre_m = 0;
};

// The model's surface samples, a tree over them and their centroid (object frame).
struct ModelSamples {
  std::vector<Eigen::Vector3f> points;
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
};

PoseError pose_error(const ModelSamples& m, const Transform& T_found, const Transform& T_true) {
  PoseError e;
  const Transform d = T_true.inverse() * T_found;
  e.rotation_deg = rotation_angle(d) * 180.0 / std::numbers::pi;
  e.translation_m = (T_found.translation() - T_true.translation()).norm();
  e.centre_m = (T_found * m.centre - T_true * m.centre).norm();
  // ADI: every sample at the found pose to the nearest sample at the true pose; in the true
  // object frame, the true samples are the model's own.
  const KdTree3 tree(m.points);
  double sum = 0;
  for (const auto& p : m.points) sum += std::sqrt(tree.nearest((d * p.cast<double>()).cast<float>()).second);
  e.mean_m = m.points.empty() ? 0.0 : sum / double(m.points.size());
  return e;
}

}  // namespace

EvaluationResult evaluate_recognition(const WorldModel& world, const std::vector<TrueObject>& truth,
                                      const std::vector<std::string>& library, const EvaluationParams& params) {
  if (!(params.sample_spacing_m > 0 && std::isfinite(params.sample_spacing_m)))
    throw Error("evaluation: sample_spacing_m = " + std::to_string(params.sample_spacing_m) + " must be positive");
  for (const auto& t : truth)
    if (!t.T_world_object.matrix().allFinite()) throw Error("evaluation: the true pose of '" + t.name + "' is not finite");
  EvaluationResult out;
  std::map<std::string, ModelSamples> samples;  // by model name
  struct Candidate {
    size_t detection, truth;
    PoseError error;
    bool correct;
  };
  std::vector<Candidate> candidates;
  for (const auto& o : world.objects()) {
    if (o.kind != SceneObject::Kind::object) continue;
    const size_t d = out.detections.size();
    out.detections.push_back({o.path, o.model, "", 0, 0, 0, 0, false});
    auto it = samples.find(o.model);
    if (it == samples.end()) {
      ModelSamples m;
      if (o.mesh) m.points = sample_surface(*o.mesh, params.sample_spacing_m).points;
      for (const auto& p : m.points) m.centre += p.cast<double>();
      if (!m.points.empty()) m.centre /= double(m.points.size());
      it = samples.emplace(o.model, std::move(m)).first;
    }
    for (size_t t = 0; t < truth.size(); ++t) {
      if (truth[t].model != o.model) continue;
      const PoseError e = pose_error(it->second, o.T_world_object, truth[t].T_world_object);
      candidates.push_back({d, t, e, e.mean_m <= params.max_mean_distance_m && e.centre_m <= params.max_centre_distance_m});
    }
  }
  // Each detection's error against its nearest true instance; then correct pairs assigned
  // greedily, best first, one detection per true object.
  std::vector<double> nearest(out.detections.size(), std::numeric_limits<double>::infinity());
  for (const auto& c : candidates)
    if (c.error.mean_m < nearest[c.detection]) {
      nearest[c.detection] = c.error.mean_m;
      auto& d = out.detections[c.detection];
      d.rotation_deg = c.error.rotation_deg;
      d.translation_m = c.error.translation_m;
      d.mean_distance_m = c.error.mean_m;
      d.centre_distance_m = c.error.centre_m;
    }
  std::sort(candidates.begin(), candidates.end(), [](const Candidate& a, const Candidate& b) { return a.error.mean_m < b.error.mean_m; });
  std::vector<std::string> found_as(truth.size());
  for (const auto& c : candidates) {
    auto& d = out.detections[c.detection];
    if (!c.correct || d.correct || !found_as[c.truth].empty()) continue;
    d.correct = true;
    d.matched = truth[c.truth].name;
    d.rotation_deg = c.error.rotation_deg;
    d.translation_m = c.error.translation_m;
    d.mean_distance_m = c.error.mean_m;
    d.centre_distance_m = c.error.centre_m;
    found_as[c.truth] = d.path;
    out.max_rotation_deg = std::max(out.max_rotation_deg, d.rotation_deg);
    out.max_translation_m = std::max(out.max_translation_m, d.translation_m);
    out.max_mean_distance_m = std::max(out.max_mean_distance_m, d.mean_distance_m);
  }
  for (const auto& d : out.detections) out.false_positives += d.correct ? 0 : 1;
  for (size_t t = 0; t < truth.size(); ++t) {
    const auto& o = truth[t];
    const bool known = !o.model.empty() && std::find(library.begin(), library.end(), o.model) != library.end();
    TruthScore s{o.name, o.model, o.visible_fraction, found_as[t], known && o.visible_fraction >= params.min_visible_fraction};
    if (s.counted) {
      ++out.expected;
      s.found_as.empty() ? ++out.missed : ++out.found;
    }
    out.truth.push_back(s);
  }
  return out;
}

}  // namespace artisan::worldmodel
