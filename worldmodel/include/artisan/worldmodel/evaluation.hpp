#pragma once
// A world model's recognized objects against ground truth (a simulated workcell's, or a
// surveyed one): which true objects were found at their pose, which were missed, and which
// detections match nothing. Pose errors are reported both strictly (rotation and translation of
// T_true^-1 * T_found) and up to the object's symmetries (the mean distance from the model's
// surface at the found pose to its surface at the true pose, the ADI measure, and the distance
// between the two placements of the model's centroid), so a symmetric part found in an
// equivalent pose counts as found.
#include <string>
#include <vector>

#include "artisan/worldmodel/world_model.hpp"

namespace artisan::worldmodel {

struct TrueObject {
  std::string name;                 ///< e.g. "tee_1"
  std::string model;                ///< the model it is an instance of (e.g. "tee"); "" for a distractor
  Transform T_world_object = Transform::Identity();
  double visible_fraction = 1.0;    ///< the best over the views that saw it (0-1)
};

struct EvaluationParams {
  double max_mean_distance_m = 0.003;    ///< ADI: mean surface-to-surface distance of a correct pose [m]
  double max_centre_distance_m = 0.005;  ///< centroid displacement of a correct pose [m]
  double sample_spacing_m = 0.002;       ///< model surface samples for the ADI [m]
  double min_visible_fraction = 0.5;     ///< true objects seen less than this are not counted as missed
};

struct DetectionScore {
  std::string path, model;               ///< the recognized object
  std::string matched;                   ///< the true object it matches; "" for a false positive
  double rotation_deg = 0, translation_m = 0;   ///< strict error against the nearest true instance
  double mean_distance_m = 0, centre_distance_m = 0;  ///< symmetry-aware error against it
  bool correct = false;
};

struct TruthScore {
  std::string name, model;
  double visible_fraction = 0;
  std::string found_as;  ///< the recognized object's path; "" when missed
  bool counted = false;  ///< a library object seen enough to be expected (visible >= min_visible_fraction)
};

struct EvaluationResult {
  std::vector<DetectionScore> detections;
  std::vector<TruthScore> truth;
  int expected = 0, found = 0, missed = 0, false_positives = 0;
  double max_rotation_deg = 0, max_translation_m = 0, max_mean_distance_m = 0;  ///< over correct detections
};

/// Scores the recognized objects of `world` against `truth` (poses in the world frame). True
/// objects whose model is not among the workspace's models cannot be found and are not counted;
/// neither are distractors (no model). Each true object matches at most one detection (the best).
EvaluationResult evaluate_recognition(const WorldModel& world, const std::vector<TrueObject>& truth,
                                      const std::vector<std::string>& library, const EvaluationParams& params = {});

}  // namespace artisan::worldmodel
