#pragma once
// Object recognition with spin images (Johnson & Hebert, PAMI 1999, section 6): a library of
// model spin images, compressed by PCA onto the leading eigen-spin-images (Johnson & Hebert,
// CVPR 1998) and searched in the compressed space; correspondences grouped per model, poses
// estimated, refined by ICP and verified. Several models and several instances of one model.
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "artisan/core/pose.hpp"
#include "artisan/core/triangle_mesh.hpp"
#include "artisan/perception/integration.hpp"
#include "artisan/perception/spin_image.hpp"

namespace artisan {

namespace detail {
class PairFeatureModel;
struct TurnAxes;
struct ModelCylinder;
struct Slide;
}

struct ModelLibraryParams {
  double resolution_m = 0.003;  ///< [m] models and scenes are resampled to this before spin images
  SpinImageParams spin;
  double pca_variance = 0.95;   ///< [1] share of the spin-image variance the compressed space keeps
  /// Point-pair-feature tables (RecognitionParams::voting_pool): each model's sampling step is
  /// this share of its diameter (Drost et al. use 0.025-0.05), but at least
  /// pair_min_step_factor resolutions. The votes cast fall roughly as the seventh power of the
  /// step. Clutter bench, 0.05 against 0.03: voting 0.10 s per scene against 0.87, and on the 50
  /// scenes the other parameters were tuned on 193 of 203 found below 70% occlusion with 7 false
  /// positives against 196 and 3, but on 50 scenes never used for tuning (50-99) 199 of 220 with
  /// 8 false positives against 197 and 10.
  double pair_step_fraction = 0.05;
  double pair_min_step_factor = 2.0;  ///< [resolutions]
  /// [1] a table cell holding more than this share of the model's pairs is not voted for
  /// (detail::PairVotingParams::max_cell_share)
  double pair_max_cell_share = 0.005;
  /// [1] every n-th scene sample (at the model's step) is a voting reference point
  /// (detail::PairVotingParams::reference_stride; Drost et al. use every fifth). Clutter bench
  /// (50 scenes): every eighth votes in 0.87 s per scene instead of 1.49, but finds 191 of 203
  /// instead of 193 with 8 false positives instead of 4
  int pair_reference_stride = 5;
  /// A model with at least this share of its points on cylinders about one of its turn axes (a
  /// straight pipe: its outside and bore) is also proposed on the scene's cylinder axes of its
  /// radius (RecognitionParams::axis_hypotheses).
  double cylinder_min_share = 0.8;
  /// A model that is not mostly one cylinder but round about one of its turn axes, with a
  /// cylinder about it holding at least this share of its points and at least its radius long
  /// (a flange's neck), is also proposed on the scene's cylinder axes of that radius
  /// (RecognitionParams::round_part_hypotheses).
  double round_part_min_share = 0.1;
};

class SpinImageLibrary {
 public:
  explicit SpinImageLibrary(const ModelLibraryParams& params = {});

  /// Adds a model (its mesh in the model frame). Only the new model's spin images are computed;
  /// the compression is redone on the next compress() or recognition.
  void add_model(const std::string& name, const TriangleMesh& mesh);
  /// Adds a model whose resampled points and normalised spin images (bins x points) were
  /// computed before with the same params (by add_model), e.g. stored with a workspace model.
  void add_precomputed_model(const std::string& name, PointCloud points, Eigen::MatrixXf images);
  /// PCA of every model's spin images; a no-op when nothing changed since the last call.
  void compress();

  const ModelLibraryParams& params() const { return params_; }
  size_t model_count() const { return models_.size(); }
  const std::string& model_name(size_t m) const { return models_[m].name; }
  const PointCloud& model_points(size_t m) const { return models_[m].points; }
  /// A k-d tree over model m's points, in the model's frame (made by compress()).
  const KdTree3& model_tree(size_t m) const { return *models_[m].tree; }
  int components() const { return static_cast<int>(basis_.cols()); }  ///< eigen-spin-images kept
  size_t bins() const { return static_cast<size_t>(params_.spin.image_width * params_.spin.image_width); }

  /// Normalised spin images (zero mean, unit norm) of model m, one column per point.
  const Eigen::MatrixXf& model_images(size_t m) const { return models_[m].images; }
  /// The same, projected on the eigen-spin-images (components x points).
  const Eigen::MatrixXf& model_coefficients(size_t m) const { return models_[m].coefficients; }
  /// Projects normalised spin images (bins x n) into the compressed space (components x n).
  Eigen::MatrixXf project(const Eigen::MatrixXf& images) const;
  bool compressed() const { return compressed_; }
  /// Model m's point-pair-feature table (made by compress()).
  const detail::PairFeatureModel& pair_features(size_t m) const { return *models_[m].pairs; }
  /// Model m's turn axes (RecognitionParams::turn_steps; made by compress()).
  const detail::TurnAxes& turn_axes(size_t m) const { return *models_[m].turns; }
  /// Model m's cylinder (ModelLibraryParams::cylinder_min_share), or null (made by compress()).
  const detail::ModelCylinder* cylinder(size_t m) const { return models_[m].cylinder.get(); }
  /// Model m's round parts (ModelLibraryParams::round_part_min_share), largest first (made by compress()).
  const std::vector<detail::ModelCylinder>& round_parts(size_t m) const { return *models_[m].round_parts; }
  /// Whether model m's surface slides along itself by a motion that is no symmetry of it (a pipe
  /// along its axis, an elbow about its bend: detail::slide_along_itself; made by compress(),
  /// true before).
  bool slides(size_t m) const { return !models_[m].turns || models_[m].slide; }
  /// That motion, or null (none, or not made yet).
  const detail::Slide* slide(size_t m) const { return models_[m].slide.get(); }
  /// Points of model m on its largest plane (a flange's face; made by compress()).
  size_t planar_points(size_t m) const { return models_[m].planar_points; }

  struct Match {
    float d2;  ///< squared distance between normalised images (2 - 2 x correlation)
    size_t model, point;
  };
  /// The k nearest library images of each query column (normalised spin images, bins x n), over
  /// all models, nearest first: in the compressed space through a k-d tree over every model's
  /// coefficients, or (compressed = false) by brute force over the full images. Only images
  /// nearer than sqrt(max_d2) are returned (a query may have fewer than k); the k-d tree prunes
  /// what lies beyond, so a query far from every library image (clutter) costs less.
  std::vector<std::vector<Match>> nearest(const Eigen::MatrixXf& images, int k, bool compressed,
                                          float max_d2 = std::numeric_limits<float>::infinity());

 private:
  struct Model {
    std::string name;
    PointCloud points;
    Eigen::MatrixXf images;
    Eigen::MatrixXf coefficients;
    std::shared_ptr<const detail::PairFeatureModel> pairs;
    std::shared_ptr<const detail::TurnAxes> turns;
    std::shared_ptr<const KdTree3> tree;
    std::shared_ptr<const detail::ModelCylinder> cylinder;
    std::shared_ptr<const std::vector<detail::ModelCylinder>> round_parts;
    size_t planar_points = 0;
    std::shared_ptr<const detail::Slide> slide;
  };
  ModelLibraryParams params_;
  std::vector<Model> models_;
  Eigen::VectorXf mean_;
  Eigen::MatrixXf basis_;  ///< bins x components
  bool compressed_ = false;
  struct SearchIndex;  ///< k-d tree over every model's coefficients, made by compress()
  std::shared_ptr<SearchIndex> index_;
};

/// Spin images normalised so that a dot product is their correlation coefficient.
Eigen::MatrixXf normalised_spin_images(const SpinImageStack& stack);

struct RecognitionParams {
  double scene_point_fraction = 0.25;  ///< [1] share of the scene's resampled points whose spin images are matched
  bool skip_flat_basis_points = true;  ///< [1] no spin images for points whose neighbourhood is a plane
  int neighbours = 3;                  ///< [1] library matches kept per scene point (nearest in the search space)
  bool compressed_search = true;       ///< search the PCA space (false: the full spin images)
  double min_correlation = 0.6;        ///< [1] matches below this estimated correlation are dropped
  size_t max_matches_grouped = 1500;   ///< strongest matches per model that the grouping considers
  double geometric_consistency = 0.25; ///< [1] T_gc
  double gamma_factor = 4.0;           ///< [1] grouping gamma, in resolutions
  int max_groups = 30;                 ///< [1] per model and instance search
  bool group_hypotheses = true;        ///< poses from Johnson & Hebert's grouping (geometric consistency, eq. 9-10)
  /// Poses from pairs of matches, which tolerate ambiguous spin images (pipes and fittings are
  /// nearly surfaces of revolution: a scene point's right model point is rarely its nearest
  /// match, but often among its k nearest). Two scene points and one model match of each whose
  /// point-pair features agree (distance, and the angles between the normals and the line
  /// joining the points; Drost et al., "Model Globally, Match Locally", CVPR 2010) fix a pose
  /// from the two oriented points; each pose is scored by how many sampled model points it puts
  /// on the scene surface (a cheap verification), and the best distinct ones go on to ICP.
  int pair_partners = 8;               ///< [1] partner scene points tried per anchor scene point (0: no pair hypotheses)
  int pair_anchors = 1500;             ///< [1] anchor scene points tried per model, at most
  /// Seed of the pseudo-random order of anchors and draw of partners: a scene gives the same
  /// hypotheses for a seed. Another seed is as good a draw: on the clutter bench it measures how
  /// far the rate moves by chance (see docs/recognition-clutter-log.md).
  uint32_t pair_seed = 20101;
  double pair_distance_tolerance_factor = 2.0;  ///< [resolutions] |scene distance - model distance| allowed
  double pair_angle_tolerance_deg = 20.0;       ///< [deg] per point-pair-feature angle
  double pair_min_distance_factor = 5.0;        ///< [resolutions] closer pairs fix no stable pose
  int pair_score_points = 200;         ///< [1] model points (evenly subsampled) that score a hypothesis
  double pair_min_support = 0.05;      ///< [1] share of those that must land on the scene surface
  /// Poses from point-pair-feature voting (Drost et al. 2010: every scene pair within a model's
  /// diameter votes, through a table of the model's pairs, for a model point and a rotation
  /// about its normal), which needs no spin-image match at all: the best pose clusters of each
  /// model join the pair hypotheses, scored the same way.
  int voting_pool = 100;               ///< [1] best vote clusters per model that become hypotheses (0: no voting)
  int pair_pool = 200;                 ///< [1] best distinct pair and voting hypotheses kept per model
  /// A model made mostly of one cylinder (SpinImageLibrary::cylinder, a pipe) is also put on
  /// each axis of the scene's cylindrical surfaces of its radius, at every shift along it that
  /// overlaps the seen extent (axis_step_factor resolutions apart; and, when it is not round,
  /// at turn_steps turns about it); per axis the poses with nearly the best support (90%), the
  /// best distinct of them joining the pair hypotheses. Spin images and point-pair voting seldom
  /// place a pipe: its body's points and pairs all look alike, and only its rims fix the shift.
  bool axis_hypotheses = true;
  double axis_step_factor = 2.0;       ///< [resolutions]
  /// [resolutions] a straight pipe's refined pose that the visibility tests alone refuse, by a
  /// small margin (free space up to twice its limit, continued surface three times, explained
  /// surface 0.1 short), is also tried slid along its axis by every whole number of resolutions
  /// up to this either way, each refined; the best that passes replaces it (0: no slides). The ICP
  /// hardly holds a pipe's place along its axis: two unoccluded pipes in the clutter bench were
  /// refused a few millimetres short of their seen ends, with 3.1% and 3.3% of their surface
  /// continued past the model's outline against the 3% limit.
  int axis_slide_steps = 5;
  size_t axis_min_points = 60;         ///< [1] scene points a cylinder axis needs
  /// A model round about an axis with a cylindrical part (SpinImageLibrary::round_parts, a
  /// flange's neck) is also put with that part on each of the scene's cylinder axes of its
  /// radius, as a pipe is; those poses are ranked apart from the pair hypotheses (up to
  /// coarse_refined of them), which outnumber them; and a refused pose of it that the
  /// visibility tests alone refuse by a small margin is slid along that axis as a pipe's is
  /// (axis_slide_steps). A flange lying neck down with its face
  /// turned from the sensor shows the sensor its face edge on, a strip of rim and its neck: of
  /// the 8 flanges the held-out clutter scenes missed, 6 lay so, and neither spin images nor
  /// point-pair voting put any pose within a third of its diameter of them.
  bool round_part_hypotheses = true;
  /// [1] starting poses refined by the coarse ICP per instance search, of the groups and of the
  /// pair hypotheses each: those that put the most sampled model points on scene surface not yet
  /// explained
  int coarse_refined = 30;
  /// [1] share of the model's points that must lie on the scene (less the share occluded). Low:
  /// a tee seen along its branch shows a tenth of its surface even when nothing hides it (0.07
  /// to 0.11 in the clutter bench); whether what a sensor should see of it is there is
  /// min_visible_explained's test.
  double min_model_overlap = 0.10;
  /// [1] but never less than this, however much is hidden: a pose that hides nearly all of a
  /// large part (a pipe 78% occluded along a tee's run end, 2.7% of it on the scene) can be put
  /// wherever a little of its surface fits. True instances in the clutter bench showed at least
  /// 0.077 (an elbow 60% occluded; 50 scenes, 177 found).
  double min_overlap_floor = 0.05;
  /// [1] largest accepted residual, in resolutions. True instances in the simulated clutter bench
  /// fit within 0.61 mm (0.2 resolutions; 348 found in two 50-scene runs); a pipe fitted to
  /// another part's or a distractor's cylinder of a slightly different radius leaves 1.0-1.3 mm,
  /// and 5 of the 13 false instances of 2026-12-03's run (at 0.3) 0.69-0.84 mm.
  double max_rmse_factor = 0.22;
  int max_instances = 5;               ///< [1] per model
  /// [1] a pose on scene surface more than this share of which an accepted instance explains is
  /// refused: the same instance again, or another model fitted to part of it (instances are
  /// accepted in the order of how much scene surface they explain, across models)
  double max_shared_support = 0.3;
  /// [1] two models' instances that would each refuse the other (the scene surface both newly
  /// explain is more than max_shared_support of what each does: a pipe along a tee's run) are
  /// one object: of the two, the one the sensors' evidence is less against (its share in seen
  /// free space plus the share of what they should have seen of it that they did not) by more
  /// than this margin is accepted, not the one that explains more surface (negative: by the
  /// surface alone)
  double conflict_margin = 0.1;
  /// [1] a different pose at the same place (RecognizedInstance::ambiguous) that puts at least
  /// 1 - ambiguity_margin of the found one's share of the model on the scene, and passes the
  /// tests, is an ambiguity; so is another model's pose that passes the tests and explains at
  /// least 1 - ambiguity_margin of the scene surface the found one newly explains; and so is the
  /// model slid along itself that keeps 1 - ambiguity_margin of the found one's share on the
  /// scene, and of that share less its share in free space, and passes the tests
  double ambiguity_margin = 0.1;
  /// Where the sensors that saw the scene were, in the scene frame (one view for a single scan,
  /// one per merged scan). With views, a pose is refused when more than
  /// max_free_space_fraction of the model's surface facing a sensor lies in front of what that
  /// sensor saw: in space the sensor saw through, where the object cannot be. Empty: no such test.
  std::vector<SensorView> views;
  double max_free_space_fraction = 0.1;  ///< [1]
  /// With perspective views: the share of the model surface a sensor should have seen (facing
  /// it, not hidden by the model itself) that lies on the scene surface must reach this.
  double min_visible_explained = 0.85;
  /// With perspective views: the explained surface's normals may not all be one plane's (the
  /// largest eigenvalue of their mean outer product, 1 for a plane, must stay below this).
  double max_support_planarity = 0.95;
  double free_space_tolerance_factor = 3.0;  ///< [resolutions] how far in front of the seen surface counts
  /// [deg] model surface meeting a sensor's rays at a larger angle (between its normal and the
  /// ray) is no evidence either way: a scanner returns little or nothing there (the Vivid 700
  /// drops points from 60 degrees of incidence and all of them from 80), so the surface is
  /// neither expected to be seen nor, where the sensor saw past it, in free space. At 90 (the
  /// default, every sensor-facing point counts) a flange seen edge-on leaves a tenth of its
  /// surface "in free space" at its true pose and is refused. Clutter bench (50 scenes) at 70:
  /// 181 found instead of 180 (5 found that were missed, among them edge-on flanges; 3 lost,
  /// not yet diagnosed), 10 false positives instead of 9; not yet the default.
  double max_incidence_deg = 90.0;
  /// Scene points on a support plane (a connected region of a plane larger than twice any
  /// model's largest planar part: a table top seen between the parts on it) do not vote in the
  /// point-pair voting: their pairs fit a model's planar part (a flange's face) anywhere on the
  /// table, and their clusters fill the voting pool. Clutter bench (50 scenes): the flanges of
  /// scenes 25 and 41 (2-15% occluded, never proposed before) and an elbow found, voting 1.83 ->
  /// 1.20 s per scene; alone it lost a tee, two valves and a pipe to wrong poses of the richer
  /// pool (188 found instead of 189, 12 false positives instead of 10); with `rivals` (below),
  /// which takes those back, 191 and 9 against 190 and 9 without it, 3.5 s per scene against 4.1.
  /// Nor are they fitted for the scene's cylinder axes (axis_hypotheses): clutter bench, the same
  /// detections on scenes 0-99 and 600-699, the axes found in about three quarters of the time.
  bool no_votes_on_support = true;
  /// With perspective views: the largest share of the explained model surface whose tangent
  /// plane the scene continues beyond the model's outline (no silhouette there: the model's
  /// face lies flush on a larger surface, such as a flange's face on a box's).
  /// This limit holds for a model whose surface slides along itself (SpinImageLibrary::slides: a
  /// pipe, an elbow), whose refined pose may sit a little off along the slide; for any other
  /// model, max_continued_fraction_fixed. The looser tests that screen and slide poses before
  /// the last (their slack) are multiples of this one for every model.
  double max_continued_fraction = 0.03;
  /// The continued-surface limit of a model that does not slide along itself (a flange, a tee, a
  /// valve). Clutter bench, scenes 300-499 (twenty-third session): of the 229 true flanges found
  /// none had more than 0.6% of its explained surface continued, true tees 1.3%, valves 0.1%,
  /// where 14 of 15 false flanges (11 on the table's rim) had 2.3-3.0%; true pipes and elbows
  /// up to 2.9%, from refined poses a little off along their slide.
  double max_continued_fraction_fixed = 0.015;
  /// [1] the largest share of the model that may lie on each side of a solid's face (a background
  /// or support plane: a table top, the floor), more than the free-space tolerance from it and
  /// over the face's region (the convex hull of its seen points, and up to the model's size
  /// beyond it where something in front hides the plane, not where the sensor saw past it): a
  /// part stands on a table, it does not go through it, though the table hides what would lie
  /// under it. Clutter bench (50 scenes): 193 of 203 found and 4 false positives against 191 and
  /// 9 without it (false tees whose run lay on a pipe, their branch down in the table top; a valve
  /// turned with its stem in it; flanges standing half in it). It takes such faces for solid over
  /// their hull: a pipe through an opening in a wall would be refused (1: no such test). 1% rather
  /// than 2% (tenth session): 196 of 203 and 3 false positives against 194 and 5 (a tee with its
  /// run on a pipe, 1.9% of it in the table top, had won against the pipe; a false pipe 54 mm
  /// along another); a part resting on a face has none of it farther than the tolerance beyond.
  double max_through_fraction = 0.01;
  /// A pose refused by either of the two tests above lies where no pose of the model would pass:
  /// the scene surface under it, and when that is mostly one plane (planarity 0.85), the plane as
  /// far as the model's diameter reaches, no longer support the model's other poses (they are
  /// neither ranked among its starting poses nor refined). Without it a flange's face slid and
  /// turned about a box top took every search's refinements, refused each time (clutter bench,
  /// 50 scenes: 180 found instead of 177, the same 9 false positives, 12.5 s instead of 13.6).
  bool drop_refused_planes = true;
  /// [1] an accepted pose is also tried turned about each of the model's principal directions
  /// (through the axis its surface is most nearly one of revolution about) by every multiple of
  /// 360/turn_steps degrees; a turn that passes every test and puts more of the model on the
  /// scene, less its share in free space, replaces it (0 or 1: no turns). A valve's body and
  /// ends, or a tee's run, fit the scene at any turn about their axis, with the stem or branch
  /// where nothing contradicts it.
  int turn_steps = 12;
  double turn_margin = 0.01;           ///< [1] by how much more (overlap, less free-space share)
  /// [1] per instance search, up to this many refined poses that fit the scene (overlap and
  /// residual pass) but that the visibility tests refuse are also tried turned (turn_steps); a
  /// turn that passes every test takes the pose's place. A tee at the right place with its branch
  /// turned into seen free space, or down through the table, is refused however well its run fits.
  int refused_turns = 1;
  /// [1] once a search has a pose that passes, up to this many of its poses not refined yet at the
  /// same place (centre within half the model's diameter) whose coarse ICP put at least as much of
  /// the model on the scene as the coarse ICP does from the winner (less rival_coarse_slack) are
  /// refined and verified, most overlap first; the one that passes and scores most, by more than
  /// rival_margin over the winner (the model's share on the scene less its share in free space),
  /// takes its place (0: none). The search takes the first pose that passes in the coarse score's
  /// order, and a valve turned about its run or a pipe slid along its axis passes as well as the
  /// true pose. Clutter bench, 50 scenes, with no_votes_on_support: 191 found and 9 false
  /// positives against 188 and 12 without rivals (a valve turned about its run, two pipes slid);
  /// 1 rival: 189 and 11; 6: 190 and 10.
  int rivals = 3;
  /// A rival that passes and loses to the winner stays open for the model's next search instead
  /// of being closed with the poses tried: "at the same place" (half a diameter) also takes in a
  /// second instance beside the winner, two tees side by side. Once the winner is accepted its
  /// surface takes a rival's support (and the tests refuse a pose on it) if it was the same
  /// instance. Clutter bench, 100 scenes: tuned half 196 of 203 found below 70% occlusion
  /// against 195 (scene 33's second tee, 53% occluded), held out 207 of 220 either way, 13 false
  /// positives either way.
  bool losing_rivals_stay_open = true;
  /// A winner that a rival displaces (rivals) stays open for the model's next search when the
  /// rival's centre lies at least this share of the model's diameter from its own: the rival is
  /// then taken to be a second instance beside it, not a better placement of the same one.
  /// Negative: a displaced winner is closed, as every pose tried is. Clutter bench: scenes 0-99
  /// unchanged (in scene 33 a displaced false tee lies 0.295 diameters from the true one, which
  /// reopened became a false positive); 100-199 one part more and one false positive fewer
  /// (displaced at 0.367); 600-699 two parts more (0.331 and 0.496), the same false positives.
  double displaced_winner_distance = 0.3;
  /// A straight pipe's winner (a model with a cylinder) is also tried slid along its axis by
  /// every axis step up to half its length either way; the slide that scores most (as a rival
  /// does), refined, takes its place when it passes and scores more by rival_margin. With both
  /// ends hidden a pipe fits its seen part anywhere along the run that covers it, and a place
  /// partly in seen free space (under the limit) passes. Clutter bench, 100 scenes: 395 of 423
  /// found below 70% occlusion with 13 false positives, against 392 and 15 without.
  bool winner_slides = true;
  /// A model that slides along itself by a turn (SpinImageLibrary::slide: an elbow about its
  /// bend) is slid so too, its winner as a pipe's (winner_slides) and a refused pose of it as a
  /// pipe's is (axis_slide_steps), by the distance its surface moves at the slide's radius. A
  /// winner's slide takes its place only when it scores more by turn_margin, as its turns must
  /// (at rival_margin two held-out elbows were lost to slides scoring 0.006 more). Clutter bench,
  /// scenes 0-699: 8 parts more and 4 false positives fewer, in 9 scenes changed, 8 for the better.
  bool bend_slides = true;
  /// An accepted pose of a model that slides along itself (a pipe, an elbow) is set along its
  /// slide, within axis_step_factor resolutions either way by steps of a third of one, where the
  /// sensor's evidence is least against it and most for it (its share on the scene, less its
  /// shares in seen free space, not seen where it should have been, and of its explained surface
  /// the scene carries on past its outline), among the poses that pass, when it beats the pose
  /// itself by rival_margin: the ICP does not hold it along the slide, where only its rims say
  /// where it ends. Clutter bench, scenes 600-699: 21 more parts within 5 degrees and 5 mm (up to
  /// symmetry), one more by MSSD, one false positive fewer.
  bool evidence_slides = true;
  double rival_coarse_slack = 0.01;  ///< [1]
  /// [1] 0.003 also took a tee's true pose back from one turned 180 degrees (scene 6), but lost
  /// a pipe to one slid 38 mm along its axis (scene 22)
  double rival_margin = 0.005;
  /// [1] poses refined by the fine ICP and verified, in score order, per instance search before
  /// giving up (a coarse pose far from passing the visibility tests is refused without it, and
  /// does not count)
  int max_candidates_verified = 5;
  /// [1] rounds of an instance search: when one ends without an instance, the next ranks the
  /// starting poses not tried yet (after the surface its refused poses lay flush on was dropped)
  /// and refines the best of them as the first did. Two: on the clutter bench (with the own-bin
  /// test below) a second round found a flange in scene 3 and a tee in 33 that ranked behind
  /// others; a third found nothing more
  int search_rounds = 2;
  /// a model point met by the rays beyond own_bin_min_incidence_deg whose own bin of a view holds
  /// no return is no evidence of free space (where the scanner dropped the returns of a face at
  /// grazing incidence it saw nothing through it either), whatever the bins around it saw, and
  /// is not expected to have been seen unless something seen hides it (false: the nearest depth
  /// of the 3 x 3 bins around it, the table seen beside an edge-on flange, counts against the
  /// pose). A point facing the sensor more squarely that returned nothing lay in a shadow: it
  /// still counts (without that limit, flanges "found" in shadows were false positives)
  bool free_space_own_bin = true;
  /// [deg] the incidence from which free_space_own_bin holds: where the sensor starts dropping
  /// returns (60 for the Vivid 700); in (0, 90]
  double own_bin_min_incidence_deg = 60.0;
  bool keep_candidates = false;        ///< fill RecognitionResult::candidates (diagnosis)
};

struct RecognizedInstance {
  std::string model;
  size_t model_index = 0;
  Transform T_scene_model = Transform::Identity();
  double overlap_fraction = 0.0;  ///< [1] share of the model's points on the scene surface
  double rmse_m = 0.0;            ///< [m]
  double score = 0.0;             ///< [1] overlap - residual penalty; higher is better
  size_t correspondences = 0;     ///< in the winning group (a pose from a pair of matches: the sampled model points it put on the scene)
  double free_space_fraction = 0.0;  ///< [1] share of the model's sensor-facing surface in seen free space
  double visible_explained = 1.0;    ///< [1] share of the model surface the sensors should have seen, and nothing hid, that they saw
  double occluded_fraction = 0.0;    ///< [1] share of the model surface the sensors should have seen that something hid
  double continued_fraction = 0.0;   ///< [1] share of the explained surface the scene continues past the model's outline
  /// Another model explains about the same scene surface (ambiguity_margin) and passes the
  /// visibility tests (a pipe on the run of a tee whose branch is hidden); or, failing that,
  /// another pose that puts the model's surface elsewhere (somewhere more than a tenth of its
  /// diameter from it; a turn about the part's own symmetry, a flange's about its axis, is the same
  /// surface) fits the scene almost as well (ambiguity_margin) and passes the visibility tests: a
  /// coarse pose of the search at the same place, or a turn about one of its turn axes (a valve
  /// whose stem and hand wheel are hidden); or, failing that, the model slid along itself (a pipe
  /// along its run, an elbow about its bend) by more than a tenth of its diameter fits almost as
  /// well, less its share in free space, and passes the tests (a pipe whose ends are hidden: the
  /// farthest such slide that passes, so the alternative shows how far its place is open).
  bool ambiguous = false;
  std::string alternative_model;                                ///< the alternative's model, when ambiguous (`model` for another pose of it)
  size_t alternative_model_index = 0;                           ///< its index in the library
  Transform T_scene_model_alternative = Transform::Identity();  ///< the alternative's pose, when ambiguous
};

/// A pose that was tried, with its figures and how far it got (diagnosis).
struct RecognitionCandidate {
  size_t model_index = 0;
  Transform T_scene_model = Transform::Identity();
  /// continued_fraction is NaN where not measured: a coarse pose refused by the screen before
  /// the fine ICP on its other tests (the silhouette test is most of a check's work); so are the
  /// visibility figures of one refused for its share through a solid's face (measured first)
  double overlap_fraction = 0, rmse_m = 0, free_space_fraction = 0, visible_explained = 1, occluded_fraction = 0, continued_fraction = 0;
  double support_planarity = 0;   ///< 1: the scene surface it explains is one plane
  double through_fraction = 0;    ///< [1] share of it on the less of the two sides of a solid's face it goes through (max_through_fraction)
  size_t correspondences = 0;     ///< in its group; for a pair or voting hypothesis, the sampled model points it put on the scene
  enum class Source { grouping, pairs, voting, axis, round_part } source = Source::grouping;
  /// proposed: a pair or voting hypothesis in the pool that no coarse ICP refined; coarse: not
  /// checked at its pose (refined by the coarse ICP only; refused by the screen for its overlap
  /// alone; or a rival whose fine ICP failed the residual or the overlap floor)
  enum class Stage { proposed, coarse, refused, accepted } stage = Stage::coarse;
};

struct RecognitionResult {
  std::vector<RecognizedInstance> instances;
  std::vector<RecognitionCandidate> candidates;  ///< with RecognitionParams::keep_candidates
  struct Match {
    size_t model_index, model_point;  ///< into SpinImageLibrary::model_points
    Eigen::Vector3f scene_point;
    float correlation;
  };
  std::vector<Match> matches;  ///< the correspondences kept, with RecognitionParams::keep_candidates
  size_t scene_points = 0;
  double seconds_spin_images = 0.0, seconds_search = 0.0, seconds_verify = 0.0;
  /// Of seconds_verify: the scene's visibility maps and background planes, and every model's pose
  /// hypotheses (pairs of matches, point-pair voting, cylinder axes) with their ranking support;
  /// the rest is the searches (ICP, visibility tests, turns, ambiguity)
  double seconds_hypotheses = 0.0;
  double seconds_voting = 0.0;  ///< of seconds_hypotheses: the point-pair voting
};

/// Finds every instance of the library's models in `scene`. A scene with none gives none.
RecognitionResult recognize(const TriangleMesh& scene, SpinImageLibrary& library, const RecognitionParams& params = {});

/// Model `model_index` at one pose in `scene` (refined from it by recognize's fine ICP when
/// `refine`), measured as recognize measures the poses it verifies: stage `accepted` when it
/// passes recognize's tests (whether an accepted instance explains its surface already, or
/// another pose fits better, is not asked), else `refused`. Diagnosis: why a known pose - the
/// ground truth's, the world model's last - was not found.
RecognitionCandidate check_pose(const TriangleMesh& scene, SpinImageLibrary& library, size_t model_index, const Transform& T_scene_model,
                                const RecognitionParams& params = {}, bool refine = true);

}  // namespace artisan
