#include "artisan/perception/recognition.hpp"

#include <algorithm>
#include <array>
#include <chrono>
#include <deque>
#include <cmath>
#include <limits>
#include <memory>
#include <numbers>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <nanoflann.hpp>

#include "artisan/core/error.hpp"
#include "artisan/perception/icp.hpp"
#include "artisan/perception/kdtree.hpp"
#include "axis_proposals.hpp"
#include "correspondence_grouping.hpp"
#include "free_space.hpp"
#include "pose_hypotheses.hpp"
#include "point_pair_voting.hpp"
#include "slippage.hpp"

namespace artisan {

namespace detail {
// The model's principal directions (of its points' covariance), each with a point of the axis
// along it that the surface is most nearly one of revolution about (RecognitionParams::turn_steps).
struct TurnAxes {
  Eigen::Matrix3d directions;  ///< columns
  std::array<Eigen::Vector3d, 3> points;
};
}  // namespace detail

namespace {
using Clock = std::chrono::steady_clock;
using detail::FreeSpace;
using detail::LibraryModel;
using detail::PoseHypothesis;
using detail::SameSurface;
using detail::SurfaceSupport;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// A model of the library as its poses are fitted and checked (FreeSpace::check).
LibraryModel library_model(const SpinImageLibrary& library, size_t m) { return {library.model_points(m), library.model_tree(m)}; }

// A point of the line parallel to `direction` that the model's normals point at most: the axis
// of a surface of revolution (every normal of one meets its axis), found robustly for parts that
// are one only in part (a valve's body and ends about their run, but not its stem). Least squares
// over the normal lines projected on the plane across `direction`, reweighted (Cauchy, a twentieth
// of the model's size) so that the normals of other pieces drop out; starts at `start`.
Eigen::Vector3d near_symmetry_axis(const PointCloud& model, const Eigen::Vector3d& start, const Eigen::Vector3d& direction) {
  const Eigen::Vector3d d = direction.normalized();
  const Eigen::Matrix3d across = Eigen::Matrix3d::Identity() - d * d.transpose();
  const double scale2 = std::pow(0.05 * static_cast<double>(model.bounds().diagonal().norm()), 2);
  Eigen::Vector3d c = start;
  for (int iteration = 0; iteration < 10; ++iteration) {
    Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
    Eigen::Vector3d b = Eigen::Vector3d::Zero();
    for (size_t i = 0; i < model.points.size(); ++i) {
      const Eigen::Vector3d n = across * model.normals[i].cast<double>();
      const double length2 = n.squaredNorm();
      if (length2 < 0.25) continue;  // normals along the axis say nothing about where it is
      const Eigen::Vector3d u = n / std::sqrt(length2);
      const Eigen::Matrix3d off_line = across - u * u.transpose();  // to the normal's line, across the axis
      const Eigen::Vector3d p = model.points[i].cast<double>();
      const double w = 1.0 / (1.0 + (off_line * (c - p)).squaredNorm() / scale2);
      A += w * off_line;
      b += w * off_line * p;
    }
    // A is singular along the axis: a small pull towards the current point fixes that.
    const Eigen::Vector3d next = (A + 1e-9 * d * d.transpose()).ldlt().solve(b + 1e-9 * d * d.dot(c));
    if (!next.allFinite()) break;
    const bool settled = (next - c).norm() < 1e-6;
    c = next;
    if (settled) break;
  }
  return c;
}

// The model's turn axes.
detail::TurnAxes find_turn_axes(const PointCloud& model) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : model.points) mean += p.cast<double>();
  mean /= static_cast<double>(std::max<size_t>(model.points.size(), 1));
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  for (const auto& p : model.points) covariance += (p.cast<double>() - mean) * (p.cast<double>() - mean).transpose();
  detail::TurnAxes axes;
  axes.directions = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(covariance).eigenvectors();
  for (int a = 0; a < 3; ++a) axes.points[static_cast<size_t>(a)] = near_symmetry_axis(model, mean, axes.directions.col(a));
  return axes;
}

// A coarse pose's score (the coarse ICP's result): the model's share on the scene less half the
// RMSE in resolutions.
double coarse_score(const IcpResult& r, double res) { return r.overlap_fraction - 0.5 * r.rmse_m / res; }

// The tests a pose must pass, each loosened by a slack (none: `passes`).
struct Slack {
  double overlap = 1;     ///< share of the required overlap
  double rmse = 1;        ///< times the residual limit
  double free_space = 1;  ///< times the free-space limit
  double explained = 0;   ///< below the explained-surface limit
  double planarity = 0;   ///< above the planarity limit
  double continued = 1;   ///< times the continued-surface limit
};
// What something hid is not held against the overlap either; but what is seen must be more
// than one plane (a part's flat face "found" on a wall or box, the rest hidden in it). `slides`:
// whether the model slides along itself (SpinImageLibrary::slides), which sets the
// continued-surface limit of the unslackened test; a slackened one is a multiple of the looser.
bool meets_tests(const IcpResult& icp, const FreeSpace::Check& seen, const RecognitionParams& params, double res, const Slack& slack, bool slides) {
  const double required_overlap = std::max(params.min_model_overlap * (1 - seen.occluded), params.min_overlap_floor);
  const double continued_limit =
      slack.continued != 1 || slides ? slack.continued * params.max_continued_fraction : params.max_continued_fraction_fixed;
  return icp.overlap_fraction >= slack.overlap * required_overlap && icp.rmse_m <= slack.rmse * params.max_rmse_factor * res &&
         seen.free_space <= slack.free_space * params.max_free_space_fraction && seen.explained >= params.min_visible_explained - slack.explained &&
         seen.planarity <= params.max_support_planarity + slack.planarity && seen.continued <= continued_limit &&
         seen.through <= params.max_through_fraction;
}

// The tests on the ICP's own figures, which no check loosens: the residual, and the overlap floor
// (what something hid lowers the required overlap to the floor, never below). A pose that fails
// them fails `meets_tests` (with the same slack) whatever its check: it needs none.
bool may_pass(const IcpResult& icp, const RecognitionParams& params, double res, const Slack& slack = {}) {
  return icp.overlap_fraction >= slack.overlap * params.min_overlap_floor && icp.rmse_m <= slack.rmse * params.max_rmse_factor * res;
}

// A pose's figures as a tried pose (diagnosis); `seen` null where it was not checked.
RecognitionCandidate candidate_of(size_t model_index, const Transform& T_scene_model, const IcpResult& icp, const FreeSpace::Check* seen) {
  RecognitionCandidate c;
  c.model_index = model_index;
  c.T_scene_model = T_scene_model;
  c.overlap_fraction = icp.overlap_fraction;
  c.rmse_m = icp.rmse_m;
  if (seen) {
    c.free_space_fraction = seen->free_space;
    c.visible_explained = seen->explained;
    c.occluded_fraction = seen->occluded;
    c.continued_fraction = seen->continued;
    c.support_planarity = seen->planarity;
    c.through_fraction = seen->through;
  }
  return c;
}

void check_inputs(const TriangleMesh& scene, const SpinImageLibrary& library, const RecognitionParams& params) {
  if (scene.faces.empty()) throw Error("recognition: the scene mesh has no faces");
  if (library.model_count() == 0) throw Error("recognition: the model library is empty");
  if (!(params.axis_step_factor > 0)) throw Error("recognition: axis_step_factor " + std::to_string(params.axis_step_factor) + " must be positive");
  for (const auto& [name, limit] : {std::pair{"max_continued_fraction", params.max_continued_fraction},
                                    std::pair{"max_continued_fraction_fixed", params.max_continued_fraction_fixed}})
    if (!(limit >= 0)) throw Error(std::string("recognition: ") + name + " " + std::to_string(limit) + " must not be negative");
  if (!(params.min_correlation >= -1 && params.min_correlation <= 1))
    throw Error("recognition: min_correlation " + std::to_string(params.min_correlation) + " must lie in [-1, 1]");
  if (!(params.max_incidence_deg > 0 && params.max_incidence_deg <= 90))
    throw Error("recognition: max_incidence_deg " + std::to_string(params.max_incidence_deg) + " must lie in (0, 90]");
  if (!(params.own_bin_min_incidence_deg > 0 && params.own_bin_min_incidence_deg <= 90))
    throw Error("recognition: own_bin_min_incidence_deg " + std::to_string(params.own_bin_min_incidence_deg) + " must lie in (0, 90]");
}

// The scene's points against the views that saw them (its background and support planes too).
FreeSpace scene_free_space(const PointCloud& scene_points, const KdTree3& scene_tree, const SpinImageLibrary& library, const RecognitionParams& params) {
  const double res = library.params().resolution_m;
  size_t largest_model = 0, largest_planar_part = 0;
  for (size_t m = 0; m < library.model_count(); ++m) {
    largest_model = std::max(largest_model, library.model_points(m).points.size());
    largest_planar_part = std::max(largest_planar_part, library.planar_points(m));
  }
  // Support planes are looked for only when they are used (else only the background planes).
  const size_t smallest_support = params.no_votes_on_support ? 2 * largest_planar_part : 0;
  return FreeSpace(scene_points, scene_tree, params.views, res, params.free_space_tolerance_factor * res, params.max_incidence_deg * std::numbers::pi / 180,
                   largest_model, smallest_support, params.free_space_own_bin, params.own_bin_min_incidence_deg * std::numbers::pi / 180);
}

// The coarse ICP ranks starting poses, the fine one places and measures the few verified; on
// the clutter bench halving their samples (from 1500 and 4000) found the same instances
// (55 against 54 in 16 scenes) in two thirds of the time.
IcpSettings coarse_icp(double res) {
  IcpSettings coarse = detail::verification_icp(res, 15);
  coarse.max_source_points = 750;
  return coarse;
}
IcpSettings fine_icp(double res) {
  IcpSettings fine = coarse_icp(res);
  fine.max_iterations = 40;
  fine.max_correspondence_distance_m = 1.0 * res;
  fine.max_source_points = 2000;
  return fine;
}

// What a model's poses are refined against and checked by: the scene's points and their tree,
// what the sensors saw of it, the coarse and the fine ICP, the parameters and the resolution.
struct SceneFit {
  const PointCloud& scene;
  const KdTree3& scene_tree;
  const FreeSpace& free_space;
  const IcpSettings& coarse;
  const IcpSettings& fine;
  const RecognitionParams& params;
  double res;
};

// A pose moved from another (turned about an axis, slid along one), refined and checked.
struct Moved {
  IcpResult icp;
  FreeSpace::Check seen;    ///< when checked
  bool checked = false;     ///< false: its ICP alone failed (may_pass), no check needed
  bool passed = false;      ///< it passes every test
  double coarse_score = 0;  ///< of its coarse pose (turns)
};

// The model refined by the fine ICP from T_scene_model, and checked there unless the ICP's own
// figures already fail.
template <typename Passes>
Moved refined_from(const LibraryModel& model, const Transform& T_scene_model, const SceneFit& fit, const Passes& passes) {
  Moved m;
  m.icp = icp_point_to_plane(model.points, fit.scene, fit.scene_tree, T_scene_model, fit.fine);
  if (!may_pass(m.icp, fit.params, fit.res)) return m;
  m.seen = fit.free_space.check(model, m.icp.T_target_source);
  m.checked = true;
  m.passed = passes(m.icp, m.seen);
  return m;
}

// The fine ICP's figures of the model where T_scene_model puts it, not moved: its first
// iteration's correspondences (share on the scene, residual), its pose T_scene_model itself.
IcpResult figures_at(const PointCloud& model, const Transform& T_scene_model, const SceneFit& fit) {
  IcpSettings at_pose = fit.fine;
  at_pose.max_iterations = 1;
  IcpResult icp = icp_point_to_plane(model, fit.scene, fit.scene_tree, T_scene_model, at_pose);
  icp.T_target_source = T_scene_model;
  return icp;
}

// A pose of the model turned from T_scene_model about one of its turn axes (RecognitionParams::
// turn_steps) that passes every test (`passes`, and not on an accepted instance: `taken`) and
// scores more than `score` (T_scene_model's own: the model's share on the scene, less its share
// in free space) by turn_margin; the best one, refined, or none. And every turn's coarse pose, for
// the ambiguity test. `coarse_overlap`: the coarse ICP's from T_scene_model.
struct Turns {
  std::optional<Moved> better;
  std::vector<IcpResult> coarse;
};
template <typename Passes, typename Taken>
Turns turns_of(const LibraryModel& model, const detail::TurnAxes& axes, const Transform& T_scene_model, double score, double coarse_overlap,
               const SceneFit& fit, const Passes& passes, const Taken& taken) {
  const RecognitionParams& params = fit.params;
  Turns out;
  if (params.turn_steps < 2) return out;
  const auto steps = static_cast<size_t>(params.turn_steps);
  std::vector<Moved> turned(3 * (steps - 1));
  // Coarse ICP from every turn; the few that put most of the model on the scene, and more than
  // the coarse ICP does from the pose itself, are refined and checked.
#pragma omp parallel for schedule(dynamic, 1)
  for (size_t k = 0; k < turned.size(); ++k) {
    const size_t a = k / (steps - 1);
    const double angle = 2 * std::numbers::pi * static_cast<double>(k % (steps - 1) + 1) / static_cast<double>(steps);
    const Transform T = T_scene_model * Eigen::Translation3d(axes.points[a]) *
                        Eigen::AngleAxisd(angle, axes.directions.col(static_cast<Eigen::Index>(a))) * Eigen::Translation3d(-axes.points[a]);
    turned[k].icp = icp_point_to_plane(model.points, fit.scene, fit.scene_tree, T, fit.coarse);
    turned[k].coarse_score = coarse_score(turned[k].icp, fit.res);
  }
  for (const auto& t : turned) out.coarse.push_back(t.icp);
  std::erase_if(turned, [&](const Moved& t) { return t.icp.overlap_fraction <= coarse_overlap + params.turn_margin; });
  std::sort(turned.begin(), turned.end(), [](const Moved& a, const Moved& b) { return a.icp.overlap_fraction > b.icp.overlap_fraction; });
  if (turned.size() > 3) turned.resize(3);
#pragma omp parallel for schedule(dynamic, 1)
  for (size_t k = 0; k < turned.size(); ++k) {
    Moved refined = refined_from(model, turned[k].icp.T_target_source, fit, passes);
    refined.coarse_score = turned[k].coarse_score;  // the coarse pose's, which the winner keeps as its score
    turned[k] = refined;
  }
  for (const auto& t : turned) {
    const double s = t.icp.overlap_fraction - t.seen.free_space;
    if (t.passed && s > score + params.turn_margin && !taken(t.icp.T_target_source)) score = s, out.better = t;
  }
  return out;
}

// A pose of a model that slides along itself (detail::Slide: a straight pipe along its axis, an
// elbow about its bend; a flange along its neck's) slid by every whole number of resolutions up
// to axis_slide_steps either way, each refined by the fine ICP; of those that pass every test
// (`passes`), the one with the most of the model on the scene less its share in free space, or
// none. Point-to-plane ICP hardly holds such a pose along its slide (only its rims do): a pipe a
// few millimetres short of the seen end leaves the scene's pipe carrying on past the model's
// outline, one beyond it puts the end in free space.
template <typename Passes>
std::optional<Moved> slid_along(const LibraryModel& model, const detail::Slide& slide, const Transform& T_scene_model, const SceneFit& fit,
                                const Passes& passes) {
  const RecognitionParams& params = fit.params;
  const double res = fit.res;
  if (params.axis_slide_steps < 1) return std::nullopt;
  std::vector<Moved> slid(2 * static_cast<size_t>(params.axis_slide_steps));
#pragma omp parallel for schedule(dynamic, 1)
  for (size_t k = 0; k < slid.size(); ++k) {
    const int shift = (k % 2 ? -1 : 1) * static_cast<int>(k / 2 + 1);
    slid[k] = refined_from(model, T_scene_model * slide.by(shift * res), fit, passes);
  }
  std::optional<Moved> best;
  for (const auto& m : slid)
    if (m.passed && (!best || m.icp.overlap_fraction - m.seen.free_space > best->icp.overlap_fraction - best->seen.free_space)) best = m;
  return best;
}

// A pose of a model that slides along itself (a straight pipe, an elbow) slid by every axis step
// up to half its extent along the slide either way, where the whole seen part could lie (when both
// a pipe's ends are hidden, the ICP and the tests leave its place along the run open): each with
// how far it was slid and its score, its share of the model on the scene at the slid pose (the
// fine ICP's figures there) less its share in free space (-infinity when the share on the scene
// is below `min_overlap`).
struct Slid {
  Transform T;
  double shift = 0;  ///< [m] along the slide
  double score = -std::numeric_limits<double>::infinity();
};
std::vector<Slid> slides_of(const LibraryModel& model, const detail::Slide& slide, const Transform& T_scene_model, double min_overlap,
                            const SceneFit& fit) {
  const double step = fit.params.axis_step_factor * fit.res;
  const auto steps = static_cast<int>(0.5 * slide.extent / step);
  if (steps < 1) return {};
  std::vector<Slid> slides(2 * static_cast<size_t>(steps));
#pragma omp parallel for schedule(dynamic, 4)
  for (size_t k = 0; k < slides.size(); ++k) {
    Slid& slid = slides[k];
    slid.shift = (k % 2 ? -1 : 1) * static_cast<double>(k / 2 + 1) * step;
    slid.T = T_scene_model * slide.by(slid.shift);
    const double on_scene = figures_at(model.points, slid.T, fit).overlap_fraction;
    if (on_scene < min_overlap) continue;
    // Its share in free space alone: the seen surface carried on past it is not measured.
    slid.score = on_scene - fit.free_space.check(model, slid.T, [](const FreeSpace::Check&) { return false; }).free_space;
  }
  return slides;
}

// A winning pose of a model that slides along itself, slid (slides_of): of the slides that put
// about as much of the model on the scene (less rival_coarse_slack), the one with the most on the
// scene less its share in free space, refined; it replaces the winner when it passes and scores
// more than `score` by rival_margin (a slide by a turn, as the winner's turns, by turn_margin). A
// pipe that carries on into space the sensor saw through is wrong however well its seen part fits.
template <typename Passes, typename Taken>
std::optional<Moved> best_slide(const LibraryModel& model, const detail::Slide& slide, const Transform& T_scene_model, double overlap,
                                double score, const SceneFit& fit, const Passes& passes, const Taken& taken) {
  const RecognitionParams& params = fit.params;
  if (!params.winner_slides) return std::nullopt;
  const auto slides = slides_of(model, slide, T_scene_model, overlap - params.rival_coarse_slack, fit);
  if (slides.empty()) return std::nullopt;
  const auto best = std::max_element(slides.begin(), slides.end(), [](const Slid& a, const Slid& b) { return a.score < b.score; });
  // A slide by a turn (an elbow about its bend) is held to the margin of the winner's turns.
  const double margin = slide.radius > 0 ? params.turn_margin : params.rival_margin;
  if (!(best->score > score + margin)) return std::nullopt;
  Moved moved = refined_from(model, best->T, fit, passes);
  if (!moved.passed || !(moved.icp.overlap_fraction - moved.seen.free_space > score + margin) || taken(moved.icp.T_target_source))
    return std::nullopt;
  return moved;
}

// An accepted pose of a model that slides along itself, slid by every third of a resolution up to
// axis_step_factor resolutions either way (the pose itself among them), each measured where it is
// (a one-iteration ICP's figures at its start): of those that pass, the one the sensor's evidence
// is least against and most for (its share on the scene, less its shares in seen free space, not
// seen where it should have been, and carried on past its outline) when it beats the pose itself
// by rival_margin (or the pose itself, measured so, does not pass), else none: near the right
// place the evidence is flat, and a slide within it would only move the pose by chance. The ICP
// leaves such a pose where it came to rest along the slide, which only the rims decide: a pipe
// short of its seen end leaves the scene carrying on past its outline, one past it puts its end
// where the sensor saw through or saw nothing.
template <typename Passes>
std::optional<Moved> evidence_slide(const LibraryModel& model, const detail::Slide& slide, const Transform& T_scene_model, const SceneFit& fit,
                                    const Passes& passes) {
  const RecognitionParams& params = fit.params;
  const double res = fit.res;
  const auto steps = static_cast<int>(std::lround(3 * params.axis_step_factor));
  if (!params.evidence_slides || steps < 1) return std::nullopt;
  std::vector<Moved> slid(2 * static_cast<size_t>(steps) + 1);
#pragma omp parallel for schedule(dynamic, 1)
  for (size_t k = 0; k < slid.size(); ++k) {
    const Transform T = T_scene_model * slide.by((static_cast<double>(k) - steps) * res / 3);
    Moved& m = slid[k];
    m.icp = figures_at(model.points, T, fit);
    m.seen = fit.free_space.check(model, T);
    m.checked = true;
    m.passed = passes(m.icp, m.seen);
  }
  const auto evidence = [](const Moved& m) { return m.icp.overlap_fraction - m.seen.free_space - (1 - m.seen.explained) - m.seen.continued; };
  const Moved* best = nullptr;
  for (const auto& m : slid)
    if (m.passed && (!best || evidence(m) > evidence(*best))) best = &m;
  const Moved& itself = slid[static_cast<size_t>(steps)];
  if (!best || best == &itself || (itself.passed && !(evidence(*best) > evidence(itself) + params.rival_margin))) return std::nullopt;
  return *best;
}

// A coarse pose far from passing is refused without the fine ICP, which moves a pose by a
// fraction of a resolution (on the clutter bench's first 12 scenes this screen let through all
// 48 coarse poses that went on to pass, and stopped 482 of the 688 that failed).
constexpr double kUnlimited = std::numeric_limits<double>::infinity();  // a slack that lifts its test
constexpr Slack kPromising{.overlap = 0.5, .rmse = kUnlimited, .free_space = 2, .explained = 0.15, .planarity = 0.03, .continued = 3};
// A screened pose whose coarse residual is more than this many times the limit is refused as
// refined, without the fine ICP: in 50 scenes the coarse residual of the 219 poses that passed
// after the fine ICP was at most 1.8 times the limit (1.2 mm), while 1,900 of the 2,283 fine
// ICPs that failed began above 2.5 times it.
constexpr double kRefinedRmse = 2.5;
// Refused by a small margin on the visibility tests alone (a pose a few millimetres off
// along a pipe's axis: its end in free space, or short of the seen end).
constexpr Slack kNearPassing{.free_space = 2, .explained = 0.1, .continued = 3};
// Fits the scene (overlap, residual), whatever the free-space and seen-surface tests say (the
// plane, silhouette and through tests still hold).
constexpr Slack kFitsOnly{.free_space = kUnlimited, .explained = kUnlimited};

// One interpretation of the scene across all models: every model's next instance is searched
// for (starting poses ranked, refined by ICP, verified); of those found, the one that explains
// the most scene surface not yet explained is accepted and its surface marked explained; the
// searches that acceptance affects are redone; until no model finds one more. A tee's run
// "found" on a pipe explains less of it than the pipe does, so the pipe is accepted first, and
// the tee's hypotheses there lose their support to it.
class Interpretation {
 public:
  /// `no_votes`: the scene points that do not vote for poses (nor are fitted for cylinder axes).
  Interpretation(const SceneFit& fit, SpinImageLibrary& library, const std::vector<char>& no_votes, RecognitionResult& result)
      : fit_(fit), params_(fit.params), library_(library), no_votes_(no_votes), result_(result), explained_(fit.scene.points.size(), 0) {
    grouping_.similarity_ratio = 0.0;  // the correlation threshold already filtered
    grouping_.geometric_consistency = params_.geometric_consistency;
    grouping_.gamma_m = params_.gamma_factor * fit_.res;
    grouping_.max_groups = params_.max_groups;
    grouping_.max_candidates = params_.max_matches_grouped;
  }

  /// Each model's search begun with its spin-image matches (`per_model`) and its pose hypotheses.
  void begin(std::vector<std::vector<detail::Correspondence>> per_model);
  /// Instances accepted until no model finds one more (RecognitionResult::instances), and with
  /// keep_candidates every pose tried or proposed (RecognitionResult::candidates).
  void run();

 private:
  struct Verified {
    Transform T;
    IcpResult icp;
    double score;
    size_t size;
    std::optional<FreeSpace::Check> seen;  ///< once screened or refined
    PoseHypothesis* origin;                ///< the hypothesis it came from
    /// Moved to a pose refined from it (slid along its axis, turned, or itself), and checked there
    /// unless its ICP alone failed.
    void move_to(const Moved& moved) {
      icp = moved.icp;
      T = moved.icp.T_target_source;
      if (moved.checked) seen = moved.seen;
      else seen.reset();
    }
  };
  // A model's search for its next instance, kept between rounds.
  struct Search {
    size_t m = 0;
    std::vector<detail::Correspondence> candidates;  ///< spin-image matches on surface not yet explained
    size_t grouped = 0;  ///< how many candidates there were when last grouped (they are only ever removed)
    detail::PairAgreements agreements;  ///< of the last grouping
    /// pair and voting hypotheses, then the groups' poses as they come (a deque: Verified points into it)
    std::deque<PoseHypothesis> hypotheses;
    std::unique_ptr<SurfaceSupport> surface_support;
    std::unique_ptr<SameSurface> same;
    int instances = 0;
    bool stale = true;                ///< to be searched (again)
    std::vector<Verified> verified;   ///< of the last search, best first
    std::optional<size_t> winner;     ///< into verified: the instance that search found
    std::vector<size_t> gain;         ///< the scene points the winner explains that no accepted instance does
    std::vector<IcpResult> coarse_poses;  ///< of the last search and the winner's turns, symmetric ones too: for the ambiguity test
    /// Scene points that no longer support this model: explained by an accepted instance, or under
    /// a pose of it refused because what it lies on is one plane or carries on past its outline.
    std::vector<char> unusable;
  };
  // A starting pose: a hypothesis, and its support on the scene surface not yet explained.
  struct Start {
    size_t support;
    PoseHypothesis* origin;
  };

  // The scene surface the model at T lies on: the scene points within 2 resolutions of it.
  std::vector<size_t> lies_on(const PointCloud& model, const Transform& T_scene_model) const {
    const Eigen::Isometry3f T = T_scene_model.cast<float>();
    std::vector<size_t> near, out;
    std::vector<char> counted(fit_.scene.points.size(), 0);
    for (const auto& p : model.points) {
      fit_.scene_tree.within(T * p, static_cast<float>(2.0 * fit_.res), near);
      for (const size_t s : near)
        if (!counted[s]) counted[s] = 1, out.push_back(s);
    }
    return out;
  }
  std::vector<size_t> newly_explained(const PointCloud& model, const Transform& T_scene_model) const {
    auto on = lies_on(model, T_scene_model);
    std::erase_if(on, [&](size_t s) { return explained_[s]; });
    return on;
  }
  // A pose that lies on an accepted instance (the ICP brought it back there from a start on the
  // surface around it, or it is another model fitted to part of it): more than
  // max_shared_support of the scene surface it lies on is explained already.
  bool on_accepted(const PointCloud& model, const Transform& T_scene_model) const {
    if (result_.instances.empty()) return false;
    const auto on = lies_on(model, T_scene_model);
    const auto taken = std::count_if(on.begin(), on.end(), [&](size_t s) { return explained_[s]; });
    return static_cast<double>(taken) > params_.max_shared_support * static_cast<double>(on.size());
  }
  // The tests for model m, and the unslackened ones.
  bool meets(size_t m, const IcpResult& icp, const FreeSpace::Check& seen, const Slack& slack) const {
    return meets_tests(icp, seen, params_, fit_.res, slack, library_.slides(m));
  }
  auto passes_of(size_t m) const {
    return [this, m](const IcpResult& icp, const FreeSpace::Check& seen) { return meets(m, icp, seen, {}); };
  }
  // How a winning pose of model m is slid: along a pipe's axis, or (with bend_slides) by the
  // model's own slide (an elbow about its bend); or not at all.
  static detail::Slide along(const detail::ModelCylinder& c) { return detail::shift_along(c.point, c.direction, c.end - c.start); }
  std::optional<detail::Slide> winner_slide(size_t m) const {
    if (const auto* c = library_.cylinder(m)) return along(*c);
    if (const auto* slide = library_.slide(m); slide && params_.bend_slides) return *slide;
    return std::nullopt;
  }
  // How a refused pose of model m is slid: as a winner is, or else (with round_part_hypotheses)
  // along its largest round part's axis (a flange's neck); or not at all.
  std::optional<detail::Slide> refused_slide(size_t m) const {
    if (auto slide = winner_slide(m)) return slide;
    const auto& parts = library_.round_parts(m);
    if (!params_.round_part_hypotheses || parts.empty()) return std::nullopt;
    return along(parts.front());
  }
  // The scene's cylinder axes of a radius of the library's cylinder models, found once.
  const std::vector<detail::SceneAxis>& scene_axes(double radius) {
    for (const auto& [r, axes] : axes_of_radius_)
      if (std::abs(r - radius) < 0.25 * fit_.res) return axes;
    auto axes = detail::scene_axes(fit_.scene, fit_.scene_tree, radius, fit_.res, no_votes_, params_.axis_min_points);
    return axes_of_radius_.emplace_back(radius, std::move(axes)).second;
  }

  void refused_on_plane(Search& s, const Transform& T_scene_model, const FreeSpace::Check& seen);
  std::vector<Start> ranked_starts(Search& s, bool regroup);
  void search(Search& s);
  void refine_starts(Search& s);
  void settle_winner(Search& s);
  void record(const Search& s, bool accepted);
  std::vector<char> gain_flags(const Search& s) const;
  static size_t shared_gain(const std::vector<char>& flags, const Search& other);
  Search* next_to_accept();
  void accept(Search& next);
  void mark_ambiguity(RecognizedInstance& found, const Search& next, const std::optional<detail::Slide>& slide) const;
  void explain(Search& next);

  const SceneFit& fit_;
  const RecognitionParams& params_;
  SpinImageLibrary& library_;
  const std::vector<char>& no_votes_;
  RecognitionResult& result_;
  detail::GroupingParams grouping_;
  std::vector<char> explained_;  ///< by an accepted instance
  std::vector<Search> searches_;
  std::vector<std::pair<double, std::vector<detail::SceneAxis>>> axes_of_radius_;
};

void Interpretation::begin(std::vector<std::vector<detail::Correspondence>> per_model) {
  searches_.resize(library_.model_count());
  for (size_t m = 0; m < searches_.size(); ++m) {
    auto& s = searches_[m];
    s.m = m;
    s.candidates = std::move(per_model[m]);
    s.unusable = explained_;
    const PointCloud& model = library_.model_points(m);
    s.surface_support = std::make_unique<SurfaceSupport>(model, params_.pair_score_points, fit_.scene, fit_.scene_tree);
    s.same = std::make_unique<SameSurface>(model, library_.model_tree(m));
    auto made = detail::pair_hypotheses(model, fit_.scene, *s.surface_support, s.candidates, fit_.res, params_);
    const auto t_voting = Clock::now();
    auto voted = detail::voting_hypotheses(library_.pair_features(m), fit_.scene, no_votes_, *s.surface_support, fit_.res, params_);
    result_.seconds_voting += since(t_voting);
    made.insert(made.end(), std::make_move_iterator(voted.begin()), std::make_move_iterator(voted.end()));
    if (const auto* cylinder = library_.cylinder(m); cylinder && params_.axis_hypotheses) {
      auto on_axes = detail::axis_hypotheses(*cylinder, scene_axes(cylinder->radius), *s.surface_support, fit_.res, params_);
      made.insert(made.end(), std::make_move_iterator(on_axes.begin()), std::make_move_iterator(on_axes.end()));
    }
    for (auto& h : detail::best_distinct(std::move(made), *s.same, static_cast<size_t>(std::max(params_.pair_pool, 0))))
      s.hypotheses.push_back(std::move(h));
    // Round parts' hypotheses are ranked apart (ranked_starts), so none is crowded out of the pool.
    if (params_.round_part_hypotheses)
      for (const auto& part : library_.round_parts(m))
        for (auto& h :
             detail::axis_hypotheses(part, scene_axes(part.radius), *s.surface_support, fit_.res, params_, RecognitionCandidate::Source::round_part))
          s.hypotheses.push_back(std::move(h));
  }
}

// A pose whose check finds that what it lies on is one plane, or carries on past its outline
// (refused for it; with drop_refused_planes): the scene surface under it, and when that is mostly
// one plane, the plane as far as the model reaches, no longer support the model (its face would
// slide or turn there).
// (The continued surface counts here above max_continued_fraction for every model: a pose of a
// part that does not slide refused between its own limit and that one keeps its surface.)
void Interpretation::refused_on_plane(Search& s, const Transform& T_scene_model, const FreeSpace::Check& seen) {
  if (!params_.drop_refused_planes || !(seen.planarity > params_.max_support_planarity || seen.continued > params_.max_continued_fraction)) return;
  const double planarity = seen.planarity;
  const auto on = lies_on(library_.model_points(s.m), T_scene_model);
  for (const size_t p : on) s.unusable[p] = 1;
  if (planarity < 0.85) return;
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (const size_t p : on) scatter += fit_.scene.normals[p].cast<double>() * fit_.scene.normals[p].cast<double>().transpose();
  const Eigen::Vector3f n = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(scatter).eigenvectors().col(2).cast<float>();
  Eigen::Vector3f centre = Eigen::Vector3f::Zero();
  size_t in_plane = 0;
  for (const size_t p : on)
    if (std::abs(n.dot(fit_.scene.normals[p])) > 0.9f) centre += fit_.scene.points[p], ++in_plane;
  if (in_plane == 0) return;
  centre /= static_cast<float>(in_plane);
  std::vector<size_t> near;
  fit_.scene_tree.within(T_scene_model.translation().cast<float>(), static_cast<float>(s.same->diameter()), near);
  for (const size_t p : near)
    if (std::abs(n.dot(fit_.scene.points[p] - centre)) < static_cast<float>(2 * fit_.res) && std::abs(n.dot(fit_.scene.normals[p])) > 0.9f)
      s.unusable[p] = 1;
}

// Starting poses: the groups' and the pair and voting hypotheses still open (one that lost half
// its support to the surface accepted instances explain was on such an instance), ranked by
// their support on the scene surface not yet explained (a cheap verification); the best of
// each kind. With `regroup`, the spin-image matches are grouped again first.
std::vector<Interpretation::Start> Interpretation::ranked_starts(Search& s, bool regroup) {
  const PointCloud& model = library_.model_points(s.m);
  // The same candidates group the same way: grouped again only when some were removed.
  if (regroup && params_.group_hypotheses && s.candidates.size() >= 3 && s.candidates.size() != std::exchange(s.grouped, s.candidates.size()))
    for (const auto& g : detail::group_correspondences(model, fit_.scene, s.candidates, grouping_, &s.agreements).groups) {
      const auto same = [&](const PoseHypothesis& h) { return h.T_scene_model.matrix() == g.T_target_source.matrix(); };
      if (std::any_of(s.hypotheses.begin(), s.hypotheses.end(), same)) continue;
      PoseHypothesis& h = s.hypotheses.emplace_back();
      h.T_scene_model = g.T_target_source;
      h.source = RecognitionCandidate::Source::grouping;
      h.size = g.size;
      h.lies_on = s.surface_support->lies_on(h.T_scene_model, 2.0 * fit_.res);
      h.first_support = SurfaceSupport::count(*h.lies_on, s.unusable);
    }
  // Groups are scored with a wider margin: their coarser first pose only the ICP brings onto the
  // surface. What each lies on is found once (200 nearest-point queries, in parallel), then
  // counted, and the hypotheses taken in order.
#pragma omp parallel for schedule(dynamic, 8)
  for (size_t k = 0; k < s.hypotheses.size(); ++k)
    if (PoseHypothesis& h = s.hypotheses[k]; !h.done) {
      if (!h.lies_on)
        h.lies_on = s.surface_support->lies_on(h.T_scene_model, (h.source == RecognitionCandidate::Source::grouping ? 2.0 : 1.5) * fit_.res);
      h.support = SurfaceSupport::count(*h.lies_on, s.unusable);
    }
  std::vector<Start> groups, pairs, parts;
  for (auto& h : s.hypotheses) {
    if (h.done) continue;
    if (2 * h.support < h.first_support) h.done = true;
    else if (h.source == RecognitionCandidate::Source::grouping) groups.push_back({h.support, &h});
    else (h.source == RecognitionCandidate::Source::round_part ? parts : pairs).push_back({h.support, &h});
  }
  // Groups, pair hypotheses and round parts' are ranked apart: the pairs were chosen for their
  // support and would crowd out the groups; a flange's neck has less support than the flange's
  // face on a box top.
  const auto keep_best = [&](std::vector<Start>& v) {
    std::stable_sort(v.begin(), v.end(), [](const Start& a, const Start& b) { return a.support > b.support; });
    v.resize(std::min(v.size(), static_cast<size_t>(std::max(params_.coarse_refined, 0))));
  };
  keep_best(groups);
  keep_best(pairs);
  keep_best(parts);
  groups.insert(groups.end(), pairs.begin(), pairs.end());
  groups.insert(groups.end(), parts.begin(), parts.end());
  return groups;
}

// A model's search for its next instance: its best starting poses refined, and the first that
// passes settled against its rivals, slides and turns.
void Interpretation::search(Search& s) {
  s.verified.clear();
  s.winner.reset();
  s.coarse_poses.clear();
  refine_starts(s);
  if (s.winner) settle_winner(s);
}

// The best starting poses are refined by the coarse ICP; in score order, the first that passes
// the fine ICP and the visibility tests wins (Search::winner).
void Interpretation::refine_starts(Search& s) {
  const LibraryModel model = library_model(library_, s.m);
  const auto passes = passes_of(s.m);
  const auto taken = [&](const Transform& T) { return on_accepted(model.points, T); };
  int turned_refused = 0;
  for (int round = 0; round < std::max(params_.search_rounds, 1) && !s.winner; ++round) {
    std::vector<Verified> batch;
    const auto starts = ranked_starts(s, round == 0);
    // One coarse ICP per thread: each is too short (750 points) to share well.
#pragma omp parallel for schedule(dynamic, 1)
    for (size_t k = 0; k < starts.size(); ++k)
      if (PoseHypothesis& h = *starts[k].origin; !h.coarse)
        h.coarse = icp_point_to_plane(model.points, fit_.scene, fit_.scene_tree, h.T_scene_model, fit_.coarse);
    for (const auto& st : starts) {
      PoseHypothesis& h = *st.origin;
      const IcpResult& r = *h.coarse;
      batch.push_back({r.T_target_source, r, coarse_score(r, fit_.res), h.source == RecognitionCandidate::Source::grouping ? h.size : h.support,
                       std::nullopt, &h});
    }
    if (batch.empty()) break;
    std::sort(batch.begin(), batch.end(), [](const Verified& a, const Verified& b) { return a.score > b.score; });
    // Poses the coarse ICP brought together (the model's surface within 2 resolutions of where a
    // better one, or one of an earlier round, puts it) are refined once. All of them stay
    // candidates for the ambiguity test.
    for (const auto& v : batch) s.coarse_poses.push_back(v.icp);
    const size_t first = s.verified.size();
    for (auto& v : batch) {
      const bool same = std::any_of(s.verified.begin(), s.verified.end(), [&](const Verified& d) { return (*s.same)(v.T, d.T, 2 * fit_.res); });
      if (same) v.origin->done = true;
      else s.verified.push_back(std::move(v));
    }
    size_t refined = 0;
    for (size_t k = first; k < s.verified.size() && refined < static_cast<size_t>(std::max(params_.max_candidates_verified, 0)); ++k) {
      auto& v = s.verified[k];
      v.origin->done = true;
      // The screen's tests that need no check first: the overlap (the occlusion lowers what is
      // required, down to the floor), then the share through a solid's face (the check's first
      // measure). The silhouette is measured only for a pose that passes the screen's other tests.
      if (!may_pass(v.icp, params_, fit_.res, kPromising)) continue;
      // A pose mostly on surface where refused poses of the model lay flush (a flange's face slid
      // or turned on a box top) would be refused again: not refined.
      const double margin = 2.0 * fit_.res;
      if (params_.drop_refused_planes && 2 * (*s.surface_support)(v.T, margin, s.unusable) < (*s.surface_support)(v.T, margin, explained_)) continue;
      const auto screened = [&](const FreeSpace::Check& rest) { return meets(s.m, v.icp, rest, kPromising); };
      if (!meets(s.m, v.icp, v.seen.emplace(fit_.free_space.check(model, v.T, screened, params_.max_through_fraction)), kPromising)) continue;
      ++refined;
      if (v.icp.rmse_m > kRefinedRmse * params_.max_rmse_factor * fit_.res) {
        refused_on_plane(s, v.T, *v.seen);  // its coarse figures stand for the refined pose's (below)
        continue;
      }
      v.icp = icp_point_to_plane(model.points, fit_.scene, fit_.scene_tree, v.T, fit_.fine);
      v.T = v.icp.T_target_source;
      v.seen.emplace(fit_.free_space.check(model, v.T));
      // A pipe's place along its axis, which the ICP hardly holds, is searched when that is
      // what keeps the pose from passing; so is a flange's along its neck's.
      if (const auto slide = refused_slide(s.m); slide && !passes(v.icp, *v.seen) && meets(s.m, v.icp, *v.seen, kNearPassing))
        if (auto slid = slid_along(model, *slide, v.T, fit_, passes))
          v.move_to(*slid);
      // A part the ICP fits to the scene (its overlap and residual pass) that the visibility tests
      // refuse may lie at the right place turned wrong about its run: a tee's branch or a valve's
      // stem where the sensor saw through it. Its turns are tried; one that passes takes its place
      // when it leaves less than half of what the sensor should have seen of it hidden (on a part
      // mostly hidden, a turn that puts the rest where nothing contradicts it proves little).
      if (turned_refused < params_.refused_turns && !passes(v.icp, *v.seen) && meets(s.m, v.icp, *v.seen, kFitsOnly)) {
        ++turned_refused;
        constexpr double kAny = -std::numeric_limits<double>::infinity();
        auto turns = turns_of(model, library_.turn_axes(s.m), v.T, kAny, kAny, fit_, passes, taken);
        if (turns.better && turns.better->seen.occluded < 0.5) v.move_to(*turns.better);
      }
      const auto& seen = *v.seen;
      refused_on_plane(s, v.T, seen);
      if (!passes(v.icp, seen) || taken(v.T)) continue;
      s.winner = k;
      break;
    }
  }
}

// Poses at the winner's place that the coarse ICP put about as much of the model on the scene
// with were never refined: the winner passed first. A valve turned about its run or a pipe slid
// along its axis passes as well as the true pose; the best of those rivals that passes and
// fits better (the model's share on the scene, less its share in free space) takes its place.
// One that passes and loses may be a second instance beside the winner: with
// losing_rivals_stay_open the next search tries it again. Then the winner is slid and turned.
void Interpretation::settle_winner(Search& s) {
  const LibraryModel model = library_model(library_, s.m);
  const auto passes = passes_of(s.m);
  const auto taken = [&](const Transform& T) { return on_accepted(model.points, T); };
  const auto coarse_overlap = [&](const Transform& T) {
    return icp_point_to_plane(model.points, fit_.scene, fit_.scene_tree, T, fit_.coarse).overlap_fraction;
  };
  const size_t first_winner = *s.winner;
  double winner_coarse = coarse_overlap(s.verified[first_winner].T);
  if (params_.rivals > 0) {
    const auto& w = s.verified[first_winner];
    const double bar = winner_coarse - params_.rival_coarse_slack;
    std::vector<size_t> rivals;
    for (size_t k = *s.winner + 1; k < s.verified.size(); ++k)
      if (s.verified[k].icp.overlap_fraction >= bar && s.same->centre_distance(s.verified[k].T, w.T) < 0.5 * s.same->diameter()) rivals.push_back(k);
    std::stable_sort(rivals.begin(), rivals.end(),
                     [&](size_t a, size_t b) { return s.verified[a].icp.overlap_fraction > s.verified[b].icp.overlap_fraction; });
    rivals.resize(std::min(rivals.size(), static_cast<size_t>(params_.rivals)));
    std::vector<char> ok(rivals.size(), 0);
#pragma omp parallel for schedule(dynamic, 1)
    for (size_t j = 0; j < rivals.size(); ++j) {
      auto& v = s.verified[rivals[j]];
      const Moved refined = refined_from(model, v.T, fit_, passes);
      v.move_to(refined);
      ok[j] = refined.passed;
    }
    double to_beat = w.icp.overlap_fraction - w.seen->free_space + params_.rival_margin;
    for (size_t j = 0; j < rivals.size(); ++j) {
      if (!ok[j]) continue;
      const auto& v = s.verified[rivals[j]];
      const double score = v.icp.overlap_fraction - v.seen->free_space;
      if (score > to_beat && !taken(v.T)) to_beat = score, s.winner = rivals[j];
    }
    // The rivals tried are closed, but for one that passes and loses (losing_rivals_stay_open).
    for (size_t j = 0; j < rivals.size(); ++j)
      s.verified[rivals[j]].origin->done = !(params_.losing_rivals_stay_open && ok[j] && rivals[j] != *s.winner);
    if (*s.winner != first_winner) {
      // The winner a rival displaced stays open when the two lie far enough apart to be two instances.
      if (params_.displaced_winner_distance >= 0 &&
          s.same->centre_distance(s.verified[first_winner].T, s.verified[*s.winner].T) >= params_.displaced_winner_distance * s.same->diameter())
        s.verified[first_winner].origin->done = false;
      winner_coarse = coarse_overlap(s.verified[*s.winner].T);
    }
  }
  if (const auto slide = winner_slide(s.m)) {
    auto& w = s.verified[*s.winner];
    if (auto slid = best_slide(model, *slide, w.T, w.icp.overlap_fraction, w.icp.overlap_fraction - w.seen->free_space, fit_, passes, taken)) {
      w.move_to(*slid);
      winner_coarse = coarse_overlap(w.T);
    }
  }
  // A part whose distinguishing piece is small (a valve's stem and hand wheel, a tee's branch)
  // also fits the scene with its large, nearly symmetric body (the run) turned about its axis
  // and the piece where nothing contradicts it: the winner's turns compete with it, and one
  // that fits about as well makes it ambiguous.
  auto& w = s.verified[*s.winner];
  auto turns = turns_of(model, library_.turn_axes(s.m), w.T, w.icp.overlap_fraction - w.seen->free_space, winner_coarse, fit_, passes, taken);
  if (turns.better) {
    w.move_to(*turns.better);
    w.score = turns.better->coarse_score;
  }
  s.coarse_poses.insert(s.coarse_poses.end(), turns.coarse.begin(), turns.coarse.end());
  s.gain = newly_explained(model.points, w.T);
}

// The last search's poses, for diagnosis (`accepted`: its winner was).
void Interpretation::record(const Search& s, bool accepted) {
  if (!params_.keep_candidates) return;
  for (size_t k = 0; k < s.verified.size(); ++k) {
    const auto& v = s.verified[k];
    RecognitionCandidate c = candidate_of(s.m, v.T, v.icp, v.seen ? &*v.seen : nullptr);
    c.correspondences = v.size;
    c.source = v.origin->source;
    c.stage = accepted && s.winner == k ? RecognitionCandidate::Stage::accepted
              : v.seen                   ? RecognitionCandidate::Stage::refused
                                         : RecognitionCandidate::Stage::coarse;
    result_.candidates.push_back(c);
  }
}

void Interpretation::run() {
  while (true) {
    for (auto& s : searches_)
      if (s.stale && s.instances < params_.max_instances) {
        record(s, false);
        search(s);
        s.stale = false;
      }
    Search* next = next_to_accept();
    if (!next) break;
    accept(*next);
  }
  for (const auto& s : searches_) {
    record(s, false);
    if (params_.keep_candidates)
      for (const auto& h : s.hypotheses)
        if (!h.coarse && h.source != RecognitionCandidate::Source::grouping) {
          RecognitionCandidate c;
          c.model_index = s.m;
          c.T_scene_model = h.T_scene_model;
          c.correspondences = h.first_support;
          c.source = h.source;
          c.stage = RecognitionCandidate::Stage::proposed;
          result_.candidates.push_back(c);
        }
  }
}

// The scene points a search's winner newly explains, flagged; and how many of another's are among them.
std::vector<char> Interpretation::gain_flags(const Search& s) const {
  std::vector<char> flags(fit_.scene.points.size(), 0);
  for (const size_t p : s.gain) flags[p] = 1;
  return flags;
}
size_t Interpretation::shared_gain(const std::vector<char>& flags, const Search& other) {
  return static_cast<size_t>(std::count_if(other.gain.begin(), other.gain.end(), [&](size_t p) { return flags[p] != 0; }));
}

// The search whose winner explains the most scene surface not yet explained, or none. Another
// model's winner that this one's acceptance would refuse and whose acceptance would refuse this
// one is the other reading of the same object: the one the evidence is less against is accepted.
Interpretation::Search* Interpretation::next_to_accept() {
  Search* next = nullptr;
  for (auto& s : searches_)
    if (s.winner && s.instances < params_.max_instances && (!next || s.gain.size() > next->gain.size())) next = &s;
  if (!next || params_.conflict_margin < 0) return next;
  const auto against = [](const Search& s) {
    const auto& seen = *s.verified[*s.winner].seen;
    return seen.free_space + (1 - seen.explained);
  };
  const auto gained = gain_flags(*next);
  Search* better = next;
  for (auto& other : searches_) {
    if (&other == next || !other.winner || other.instances >= params_.max_instances) continue;
    const auto shared = static_cast<double>(shared_gain(gained, other));
    if (shared <= params_.max_shared_support * static_cast<double>(other.gain.size()) ||
        shared <= params_.max_shared_support * static_cast<double>(next->gain.size()))
      continue;
    if (against(other) + params_.conflict_margin < against(*better)) better = &other;
  }
  return better;
}

// The search's winner accepted as an instance (slid first where the evidence places it better),
// its ambiguities found, and the scene surface it explains marked.
void Interpretation::accept(Search& next) {
  record(next, true);
  auto& verified = next.verified;
  if (*next.winner != 0) std::swap(verified[*next.winner], verified.front());
  auto& top = verified.front();
  const LibraryModel found_model = library_model(library_, next.m);
  const auto slide = winner_slide(next.m);
  if (slide) {
    if (const auto slid = evidence_slide(found_model, *slide, top.T, fit_, passes_of(next.m))) {
      top.move_to(*slid);
      next.gain = newly_explained(found_model.points, top.T);
    }
  }
  RecognizedInstance found;
  found.model = library_.model_name(next.m);
  found.model_index = next.m;
  found.T_scene_model = top.T;
  found.overlap_fraction = top.icp.overlap_fraction;
  found.rmse_m = top.icp.rmse_m;
  found.score = top.score;
  found.correspondences = top.size;
  found.free_space_fraction = top.seen->free_space;
  found.visible_explained = top.seen->explained;
  found.occluded_fraction = top.seen->occluded;
  found.continued_fraction = top.seen->continued;
  mark_ambiguity(found, next, slide);
  result_.instances.push_back(found);
  explain(next);
}

// Whether the accepted winner of `next` (its first verified pose) is ambiguous, and with what.
void Interpretation::mark_ambiguity(RecognizedInstance& found, const Search& next, const std::optional<detail::Slide>& slide) const {
  const auto& top = next.verified.front();
  const LibraryModel found_model = library_model(library_, next.m);
  const auto ambiguous_with = [&](size_t m, const Transform& T) {
    found.ambiguous = true;
    found.alternative_model = library_.model_name(m);
    found.alternative_model_index = m;
    found.T_scene_model_alternative = T;
  };
  // Ambiguous with another model: its search's winner (which passes the tests and lies on no
  // accepted instance) explains nearly all of the scene surface this one newly explains; the one
  // that explains most of it. A tee whose branch is hidden and a pipe on its run are told apart
  // by nothing the sensor saw.
  {
    const auto gained = gain_flags(next);
    size_t most = 0;
    for (const auto& other : searches_) {
      if (&other == &next || !other.winner) continue;
      const size_t shared = shared_gain(gained, other);
      if (shared <= most || static_cast<double>(shared) < (1 - params_.ambiguity_margin) * static_cast<double>(next.gain.size())) continue;
      most = shared;
      ambiguous_with(other.m, other.verified[*other.winner].T);
    }
  }
  // Ambiguous, failing that: another pose at the same place that puts the model's surface
  // elsewhere (not a turn about the part's own symmetry) puts nearly as much of the model on the
  // scene (coarse ICP overlap) and passes the tests too; the best of the first three such.
  if (!found.ambiguous) {
    const double overlap = icp_point_to_plane(found_model.points, fit_.scene, fit_.scene_tree, top.T, fit_.coarse).overlap_fraction;
    std::vector<const IcpResult*> rivals;
    for (const auto& other : next.coarse_poses) {
      const Transform& T = other.T_target_source;
      if (other.overlap_fraction >= (1 - params_.ambiguity_margin) * overlap && other.rmse_m <= params_.max_rmse_factor * fit_.res &&
          next.same->centre_distance(top.T, T) < 0.1 * next.same->diameter() && !(*next.same)(top.T, T, 0.1 * next.same->diameter()))
        rivals.push_back(&other);
    }
    std::stable_sort(rivals.begin(), rivals.end(), [](const IcpResult* a, const IcpResult* b) { return a->overlap_fraction > b->overlap_fraction; });
    for (size_t k = 0; k < rivals.size() && k < 3 && !found.ambiguous; ++k) {
      const Transform& T = rivals[k]->T_target_source;
      if (passes_of(next.m)(*rivals[k], fit_.free_space.check(found_model, T)) && !on_accepted(found_model.points, T)) ambiguous_with(next.m, T);
    }
  }
  // Ambiguous, failing that: the model slid along itself (a pipe along its run, an elbow about
  // its bend) by more than a tenth of its diameter puts nearly as much of it on the scene, less
  // its share in free space (ambiguity_margin), and passes the tests there, refined: where both
  // of a pipe's ends are hidden, nothing the sensor saw places it along the run. Of the first
  // three such slides, farthest first, the first that passes: how far its place is open.
  if (slide && !found.ambiguous) {
    const double diameter = next.same->diameter();
    const double least = (1 - params_.ambiguity_margin) * (top.icp.overlap_fraction - top.seen->free_space);
    auto slides = slides_of(found_model, *slide, top.T, (1 - params_.ambiguity_margin) * top.icp.overlap_fraction, fit_);
    std::erase_if(slides, [&](const Slid& slid) { return slid.score < least || next.same->centre_distance(top.T, slid.T) < 0.1 * diameter; });
    std::stable_sort(slides.begin(), slides.end(), [](const Slid& a, const Slid& b) { return std::abs(a.shift) > std::abs(b.shift); });
    for (size_t k = 0; k < slides.size() && k < 3 && !found.ambiguous; ++k) {
      const Moved moved = refined_from(found_model, slides[k].T, fit_, passes_of(next.m));
      const Transform& T = moved.icp.T_target_source;
      if (moved.passed && moved.icp.overlap_fraction - moved.seen.free_space >= least && next.same->centre_distance(top.T, T) >= 0.1 * diameter &&
          !on_accepted(found_model.points, T))
        ambiguous_with(next.m, T);
    }
  }
}

// The scene surface the accepted winner of `next` newly explains marked. It no longer supports
// other instances: another model's instance found on it is refused; one that lost scene surface
// to it explains less; a search whose starting poses lost support to it would now rank others
// among its best.
void Interpretation::explain(Search& next) {
  for (const size_t p : next.gain) {
    explained_[p] = 1;
    for (auto& s : searches_) s.unusable[p] = 1;
  }
  ++next.instances;
  next.verified.clear();
  next.winner.reset();
  next.stale = true;
  for (auto& s : searches_) {
    std::erase_if(s.candidates, [&](const detail::Correspondence& c) { return explained_[c.target]; });
    if (s.stale) continue;
    const PointCloud& other = library_.model_points(s.m);
    if (s.winner) {
      if (on_accepted(other, s.verified[*s.winner].T)) s.stale = true;
      else s.gain = newly_explained(other, s.verified[*s.winner].T);
    } else {
      // Searched again only when a starting pose not refined yet is now among the best.
      const auto starts = ranked_starts(s, false);
      s.stale = std::any_of(starts.begin(), starts.end(), [](const Start& st) { return !st.origin->coarse; });
    }
  }
}

}  // namespace

struct SpinImageLibrary::SearchIndex {
  using Tree = nanoflann::KDTreeEigenMatrixAdaptor<Eigen::MatrixXf, -1, nanoflann::metric_L2_Simple, false>;
  Eigen::MatrixXf coefficients;                  ///< components x all points of all models
  std::vector<std::pair<size_t, size_t>> owner;  ///< column -> (model, point)
  std::unique_ptr<Tree> tree;
};

Eigen::MatrixXf normalised_spin_images(const SpinImageStack& stack) {
  const int bins = stack.width * stack.width;
  Eigen::MatrixXf z(bins, static_cast<Eigen::Index>(stack.size()));
  for (size_t k = 0; k < stack.size(); ++k) {
    Eigen::Map<const Eigen::VectorXf> v(stack.image(k), bins);
    Eigen::VectorXf c = v.array() - v.mean();
    const float norm = c.norm();
    z.col(static_cast<Eigen::Index>(k)) = norm > 0 ? Eigen::VectorXf(c / norm) : Eigen::VectorXf::Zero(bins);
  }
  return z;
}

SpinImageLibrary::SpinImageLibrary(const ModelLibraryParams& params) : params_(params) {
  if (!(params.resolution_m > 0) || !(params.pca_variance > 0 && params.pca_variance <= 1) || !(params.pair_step_fraction > 0) ||
      !(params.pair_min_step_factor > 0))
    throw Error("spin-image library: resolution " + std::to_string(params.resolution_m) + " m, pair_step_fraction " +
                std::to_string(params.pair_step_fraction) + " and pair_min_step_factor " + std::to_string(params.pair_min_step_factor) +
                " must be positive and pca_variance " + std::to_string(params.pca_variance) + " in (0, 1]");
}

void SpinImageLibrary::add_model(const std::string& name, const TriangleMesh& mesh) {
  if (mesh.faces.empty()) throw Error("spin-image library: model \"" + name + "\" has no faces");
  for (const auto& m : models_)
    if (m.name == name) throw Error("spin-image library: a model named \"" + name + "\" is already in it");
  Model model;
  model.name = name;
  model.points = sample_surface(mesh, params_.resolution_m);
  if (model.points.points.size() < 10) throw Error("spin-image library: model \"" + name + "\" has fewer than 10 points at the library resolution");
  const KdTree3 tree(model.points.points);
  model.images = normalised_spin_images(compute_spin_images(model.points, tree, {}, params_.resolution_m, params_.spin));
  models_.push_back(std::move(model));
  compressed_ = false;
}

void SpinImageLibrary::add_precomputed_model(const std::string& name, PointCloud points, Eigen::MatrixXf images) {
  for (const auto& m : models_)
    if (m.name == name) throw Error("spin-image library: a model named \"" + name + "\" is already in it");
  if (points.normals.size() != points.points.size() || images.rows() != static_cast<Eigen::Index>(bins()) ||
      images.cols() != static_cast<Eigen::Index>(points.points.size()))
    throw Error("spin-image library: precomputed model \"" + name + "\" has " + std::to_string(images.rows()) + " x " +
                std::to_string(images.cols()) + " spin images for " + std::to_string(points.points.size()) + " points; expected " +
                std::to_string(bins()) + " rows");
  models_.push_back({name, std::move(points), std::move(images), {}, {}, {}, {}, {}, {}, 0, {}});
  compressed_ = false;
}

void SpinImageLibrary::compress() {
  if (compressed_ || models_.empty()) return;
  const auto bins = static_cast<Eigen::Index>(this->bins());
  Eigen::Index total = 0;
  for (const auto& m : models_) total += m.images.cols();
  mean_ = Eigen::VectorXf::Zero(bins);
  for (const auto& m : models_) mean_ += m.images.rowwise().sum();
  mean_ /= static_cast<float>(total);
  Eigen::MatrixXd covariance = Eigen::MatrixXd::Zero(bins, bins);
  for (const auto& m : models_) {
    const Eigen::MatrixXd centred = (m.images.colwise() - mean_).cast<double>();
    covariance += centred * centred.transpose();
  }
  covariance /= static_cast<double>(total);
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(covariance);  // ascending eigenvalues
  const Eigen::VectorXd values = eig.eigenvalues().reverse();
  const double sum = values.sum();
  Eigen::Index k = 0;
  double kept = 0;
  while (k < bins && (sum <= 0 || kept / sum < params_.pca_variance)) kept += values[k++];
  k = std::max<Eigen::Index>(k, 1);
  basis_ = eig.eigenvectors().rowwise().reverse().leftCols(k).cast<float>();
  for (auto& m : models_) {
    m.coefficients = project(m.images);
    if (!m.turns) {
      // (Its grid answers the free-space test's queries of 1.5 resolutions.)
      m.tree = std::make_shared<const KdTree3>(m.points.points, static_cast<float>(1.5 * params_.resolution_m));
      m.turns = std::make_shared<const detail::TurnAxes>(find_turn_axes(m.points));
      // The turn axis most of the model is a cylinder about, if any.
      for (size_t a = 0; a < 3; ++a) {
        const auto c = detail::model_cylinder(m.points, m.turns->points[a], m.turns->directions.col(static_cast<Eigen::Index>(a)), params_.resolution_m,
                                              params_.cylinder_min_share);
        if (c && (!m.cylinder || c->share > m.cylinder->share)) m.cylinder = std::make_shared<const detail::ModelCylinder>(*c);
      }
      // Else, the round parts about its turn axes.
      std::vector<detail::ModelCylinder> parts;
      if (!m.cylinder)
        for (size_t a = 0; a < 3; ++a) {
          const auto p = detail::model_round_parts(m.points, m.turns->points[a], m.turns->directions.col(static_cast<Eigen::Index>(a)),
                                                   params_.resolution_m, params_.round_part_min_share);
          parts.insert(parts.end(), p.begin(), p.end());
        }
      m.round_parts = std::make_shared<const std::vector<detail::ModelCylinder>>(std::move(parts));
      uint64_t state = 0x9e3779b97f4a7c15ull;
      if (auto slide = detail::slide_along_itself(m.points, params_.resolution_m)) m.slide = std::make_shared<const detail::Slide>(*slide);
      m.planar_points = detail::largest_plane(m.points, std::vector<char>(m.points.points.size(), 0), params_.resolution_m, state).count;
    }
    if (m.pairs) continue;
    detail::PairVotingParams voting;
    voting.max_cell_share = params_.pair_max_cell_share;
    voting.reference_stride = params_.pair_reference_stride;
    voting.step_m = std::max(params_.pair_min_step_factor * params_.resolution_m,
                             params_.pair_step_fraction * static_cast<double>(m.points.bounds().diagonal().norm()));
    m.pairs = std::make_shared<const detail::PairFeatureModel>(m.points, voting);
  }
  auto index = std::make_shared<SearchIndex>();
  index->coefficients.resize(k, total);
  Eigen::Index column = 0;
  for (size_t m = 0; m < models_.size(); ++m)
    for (Eigen::Index j = 0; j < models_[m].coefficients.cols(); ++j) {
      index->coefficients.col(column++) = models_[m].coefficients.col(j);
      index->owner.emplace_back(m, static_cast<size_t>(j));
    }
  index->tree = std::make_unique<SearchIndex::Tree>(k, std::cref(index->coefficients), 16);
  index_ = std::move(index);
  compressed_ = true;
}

std::vector<std::vector<SpinImageLibrary::Match>> SpinImageLibrary::nearest(const Eigen::MatrixXf& images, int k, bool compressed, float max_d2) {
  compress();
  const auto n = images.cols();
  std::vector<std::vector<Match>> best(static_cast<size_t>(n));
  if (k < 1 || models_.empty()) return best;
  if (compressed) {
    const Eigen::MatrixXf query = project(images);
    const size_t kk = std::min<size_t>(static_cast<size_t>(k), index_->owner.size());
    if (kk == 0) return best;
#pragma omp parallel for schedule(dynamic, 64)
    for (Eigen::Index i = 0; i < n; ++i) {
      std::vector<Eigen::Index> idx(kk);
      std::vector<float> d2(kk);
      const Eigen::VectorXf q = query.col(i);
      nanoflann::KNNResultSet<float, Eigen::Index> found(kk);
      found.init(idx.data(), d2.data());
      d2[kk - 1] = max_d2;  // the worst distance kept until k are found: the search prunes beyond it
      index_->tree->index->findNeighbors(found, q.data(), nanoflann::SearchParams());
      auto& b = best[static_cast<size_t>(i)];
      for (size_t r = 0; r < found.size(); ++r) {
        const auto& [m, p] = index_->owner[static_cast<size_t>(idx[r])];
        b.push_back({d2[r], m, p});
      }
    }
    return best;
  }
  const Eigen::VectorXf query_sq = images.colwise().squaredNorm();
  for (size_t m = 0; m < models_.size(); ++m) {
    const Eigen::MatrixXf& lib = models_[m].images;
    const Eigen::VectorXf lib_sq = lib.colwise().squaredNorm();
    const Eigen::MatrixXf dot = images.transpose() * lib;
#pragma omp parallel for schedule(static)
    for (Eigen::Index i = 0; i < dot.rows(); ++i) {
      auto& b = best[static_cast<size_t>(i)];
      for (Eigen::Index j = 0; j < dot.cols(); ++j) {
        const float d2 = query_sq[i] + lib_sq[j] - 2 * dot(i, j);
        if (!(d2 < max_d2)) continue;
        if (static_cast<int>(b.size()) < k || d2 < b.back().d2) {
          if (static_cast<int>(b.size()) == k) b.pop_back();
          b.insert(std::upper_bound(b.begin(), b.end(), d2, [](float v, const Match& h) { return v < h.d2; }), Match{d2, m, static_cast<size_t>(j)});
        }
      }
    }
  }
  return best;
}

Eigen::MatrixXf SpinImageLibrary::project(const Eigen::MatrixXf& images) const {
  return basis_.transpose() * (images.colwise() - mean_);
}

RecognitionResult recognize(const TriangleMesh& scene, SpinImageLibrary& library, const RecognitionParams& params) {
  check_inputs(scene, library, params);
  library.compress();
  RecognitionResult result;
  const double res = library.params().resolution_m;
  auto t0 = Clock::now();
  const PointCloud scene_points = sample_surface(scene, res);
  const KdTree3 scene_tree(scene_points.points, static_cast<float>(2.0 * res));
  // Basis points: a share of the scene's points, leaving out those whose neighbourhood (half the
  // spin-image support) is flat within a bin: a plane's spin image matches any model's flat
  // parts equally well and only feeds the grouping with wrong matches (tables, walls, floors).
  std::vector<size_t> basis;
  const size_t step = std::max<size_t>(1, static_cast<size_t>(std::lround(1.0 / std::clamp(params.scene_point_fraction, 1e-3, 1.0))));
  {
    const double bin = res * library.params().spin.bin_size_factor;
    const float radius = static_cast<float>(0.5 * library.params().spin.image_width * bin);
    std::vector<char> flat(scene_points.points.size(), 0);
#pragma omp parallel for schedule(dynamic, 256)
    for (size_t i = 0; i < scene_points.points.size(); ++i) {
      if (!params.skip_flat_basis_points) continue;
      const auto off_plane = [&](size_t j) {
        return !(std::abs(scene_points.normals[i].dot(scene_points.points[j] - scene_points.points[i])) < static_cast<float>(bin));
      };
      flat[i] = !scene_tree.any_within(scene_points.points[i], radius, off_plane);
    }
    size_t k = 0;
    for (size_t i = 0; i < scene_points.points.size(); ++i)
      if (!flat[i] && k++ % step == 0) basis.push_back(i);
  }
  result.scene_points = basis.size();
  const auto stack = compute_spin_images(scene_points, scene_tree, basis, res, library.params().spin);
  const Eigen::MatrixXf scene_images = normalised_spin_images(stack);
  result.seconds_spin_images = since(t0);

  // Nearest library images of each scene image, over all models, in the compressed (or full)
  // space. For unit vectors |a - b|^2 = 2 - 2 r, so a distance estimates the correlation r.
  t0 = Clock::now();
  // (Matches below the least correlation are dropped below, on their estimate as it stands: the
  // search need not look farther than that, and a little more.)
  const auto farthest = static_cast<float>(2.0 * (1.0 - params.min_correlation) * (1 + 1e-4) + 1e-6);
  const auto best = library.nearest(scene_images, params.neighbours, params.compressed_search, farthest);
  std::vector<std::vector<detail::Correspondence>> per_model(library.model_count());
  for (size_t i = 0; i < best.size(); ++i)
    for (const auto& h : best[i]) {
      const float r = 1.0f - 0.5f * h.d2;
      if (r < params.min_correlation) continue;
      per_model[h.model].push_back({h.point, basis[i], r});
      if (params.keep_candidates) result.matches.push_back({h.model, h.point, scene_points.points[basis[i]], r});
    }
  result.seconds_search = since(t0);

  // One interpretation of the scene across all models (Interpretation).
  t0 = Clock::now();
  const FreeSpace free_space = scene_free_space(scene_points, scene_tree, library, params);
  // Scene points that do not vote (neither as reference points nor as partners): those on a
  // background plane, and with no_votes_on_support on a support plane too, whose pairs fit any
  // planar part of a model anywhere on them. Nor are they fitted for cylinder axes: a plane
  // holds none.
  const std::vector<char>& no_votes = params.no_votes_on_support ? free_space.support() : free_space.background();
  const IcpSettings coarse = coarse_icp(res), fine = fine_icp(res);
  const SceneFit fit{scene_points, scene_tree, free_space, coarse, fine, params, res};
  Interpretation interpretation(fit, library, no_votes, result);
  interpretation.begin(std::move(per_model));
  result.seconds_hypotheses = since(t0);
  interpretation.run();
  result.seconds_verify = since(t0);
  return result;
}

RecognitionCandidate check_pose(const TriangleMesh& scene, SpinImageLibrary& library, size_t model_index, const Transform& T_scene_model,
                                const RecognitionParams& params, bool refine) {
  check_inputs(scene, library, params);
  if (model_index >= library.model_count())
    throw Error("recognition: model index " + std::to_string(model_index) + " out of range (the library has " + std::to_string(library.model_count()) +
                " models)");
  if (!T_scene_model.matrix().allFinite()) throw Error("recognition: the pose to check is not finite");
  library.compress();
  const double res = library.params().resolution_m;
  const PointCloud scene_points = sample_surface(scene, res);
  const KdTree3 scene_tree(scene_points.points, static_cast<float>(2.0 * res));
  const FreeSpace free_space = scene_free_space(scene_points, scene_tree, library, params);
  const LibraryModel model = library_model(library, model_index);
  const IcpSettings coarse = coarse_icp(res), fine = fine_icp(res);
  const SceneFit fit{scene_points, scene_tree, free_space, coarse, fine, params, res};
  const IcpResult icp =
      refine ? icp_point_to_plane(model.points, scene_points, scene_tree, T_scene_model, fine) : figures_at(model.points, T_scene_model, fit);
  const FreeSpace::Check seen = free_space.check(model, icp.T_target_source);
  RecognitionCandidate c = candidate_of(model_index, icp.T_target_source, icp, &seen);
  const bool passed = meets_tests(icp, seen, params, res, {}, library.slides(model_index));
  c.stage = passed ? RecognitionCandidate::Stage::accepted : RecognitionCandidate::Stage::refused;
  return c;
}

}  // namespace artisan
