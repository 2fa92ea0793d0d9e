// Recognition against ground truth: the bunny model (Stanford's reconstruction, in the bun000
// frame) found in each of the ten real bunny scans at the pose bun.conf gives; not found in a
// simulated scan of a pipework cell that holds no bunny; compressed and full search agree; a
// half-hidden tee found; pipework found from pairs of ambiguous matches; a face flush with a
// larger surface is no instance; a valve found turned about its run is turned back; a pipe
// proposed on the scene's cylinder axes.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <numbers>
#include <vector>

#include <nlohmann/json.hpp>
#include <omp.h>

#include "artisan/core/error.hpp"
#include "artisan/core/io/ply.hpp"
#include "artisan/core/io/range_image_format.hpp"
#include "artisan/core/io/stanford_conf.hpp"
#include "artisan/perception/kdtree.hpp"
#include "artisan/perception/meshing.hpp"
#include "artisan/perception/recognition.hpp"
#include "artisan/perception/spin_image.hpp"
#include "artisan/sim/look_at.hpp"
#include "artisan/sim/simulator.hpp"
#include "artisan/sim/workcell.hpp"
#include "test_support.hpp"

namespace artisan {
namespace {

SpinImageLibrary& bunny_library() {
  static SpinImageLibrary library = [] {
    SpinImageLibrary lib;
    const auto path = test::bunny_dir() / "reconstruction" / "bun_zipper.ply";
    lib.add_model("bunny", io::ply_to_mesh(io::read_ply(path), path));
    return lib;
  }();
  return library;
}

// One simulated Vivid view, from the front and above, of a table (on a floor) with `extra`
// boxes of structure and `objects` dropped on it (workcell JSON entries).
sim::Acquisition scan_table(const std::filesystem::path& dir, int seed, const nlohmann::json& extra, const nlohmann::json& objects) {
  nlohmann::json cell = nlohmann::json::parse(R"({
    "name": "table", "start_time_s": 946684800,
    "structure": [
      {"name": "floor", "primitive": {"box": [4, 4, 0.02]}, "pose": "0 0 -0.01 0 0 0 1"},
      {"name": "table_top", "primitive": {"box": [0.8, 0.6, 0.04]}, "pose": "0 0 0.78 0 0 0 1"}
    ],
    "sensors": [{"name": "vivid", "kind": "minolta-vivid-700", "look_at": {"eye": [0, -0.8, 1.6], "target": [0, 0, 0.82]}}],
    "lights": [{"position": [1.0, -1.2, 2.6], "diffuse": [0.85, 0.85, 0.82], "ambient": [0.3, 0.3, 0.3]}]
  })");
  cell["seed"] = seed;
  for (const auto& e : extra) cell["structure"].push_back(e);
  cell["objects"] = objects;
  std::ofstream(dir / "cell.json") << cell.dump(1);
  sim::Simulator simulator(sim::load_workcell(dir / "cell.json"));
  sim::ScanRequest request;
  request.sensor = "vivid";
  return simulator.scan(request);
}

TriangleMesh scan_mesh(const std::string& name) {
  const auto path = test::bunny_dir() / (name + ".ply");
  return mesh_range_image(io::ply_to_range_image(io::read_ply(path), path)).mesh;
}

TEST(Recognition, TheBunnyIsFoundInEveryRealScanAtItsTruePose) {
  const auto conf = io::read_stanford_conf(test::bunny_dir() / "bun.conf");
  int found = 0;
  for (const auto& name : test::bunny_scans()) {
    const auto result = recognize(scan_mesh(name), bunny_library());
    ASSERT_FALSE(result.instances.empty()) << name << ": not found";
    // The model frame is the bun000 frame, whose pose in bun.conf is the identity.
    const Transform truth = conf.scan(name + ".ply").T_world_scan.inverse();
    const auto& best = result.instances.front();
    const Transform d = truth.inverse() * best.T_scene_model;
    const double deg = rotation_angle(d) * 180 / std::numbers::pi, mm = d.translation().norm() * 1e3;
    EXPECT_LT(deg, 3.0) << name;
    EXPECT_LT(mm, 3.0) << name;
    EXPECT_EQ(result.instances.size(), 1u) << name << ": a second, false instance";
    found += deg < 3 && mm < 3;
    std::printf("%-9s %.2f deg %.2f mm overlap %.2f rmse %.2f mm  (%.2f + %.2f + %.2f s)\n", name.c_str(), deg, mm, best.overlap_fraction,
                best.rmse_m * 1e3, result.seconds_spin_images, result.seconds_search, result.seconds_verify);
  }
  std::printf("found %d of 10 within 3 deg and 3 mm; library: %d eigen-spin-images of %zu bins\n", found, bunny_library().components(),
              bunny_library().bins());
}

TEST(Recognition, NoBunnyInAScanOfSomethingElse) {
  // Method: a simulated Vivid scan of the sample pipework cell (pipes, fittings, a valve, a
  // table) contains no bunny; recognition must report nothing.
  sim::Simulator simulator(sim::load_workcell(test::data_dir() / "workcells" / "pipework.json"));
  sim::ScanRequest request;
  request.sensor = "vivid";
  const auto acquisition = simulator.scan(request);
  const auto scene = mesh_range_image(acquisition.range).mesh;
  const auto result = recognize(scene, bunny_library());
  EXPECT_TRUE(result.instances.empty()) << result.instances.size() << " false instances, first overlap "
                                        << result.instances.front().overlap_fraction;
}

TEST(Recognition, CompressedSearchAgreesWithTheFullSearch) {
  auto& library = bunny_library();
  library.compress();
  EXPECT_LT(library.components(), static_cast<int>(library.bins()) / 2);  // PCA compresses
  const auto scene = scan_mesh("bun045");
  RecognitionParams full;
  full.compressed_search = false;
  const auto a = recognize(scene, library);
  const auto b = recognize(scene, library, full);
  ASSERT_FALSE(a.instances.empty());
  ASSERT_FALSE(b.instances.empty());
  const Transform d = a.instances[0].T_scene_model.inverse() * b.instances[0].T_scene_model;
  EXPECT_LT(rotation_angle(d) * 180 / std::numbers::pi, 1.0);
  EXPECT_LT(d.translation().norm(), 0.001);
}

// A search bounded by a distance returns, of each query's k nearest, exactly those within it:
// in the compressed space (where the k-d tree prunes beyond the bound) and in the full one.
TEST(Recognition, ASearchBoundedByADistanceKeepsTheNearestWithinIt) {
  auto& library = bunny_library();
  library.compress();
  // Queries between two model images each (each mixed with one a third of the model away),
  // normalised again: some near a library image, some far from all.
  const Eigen::MatrixXf& images = library.model_images(0);
  const Eigen::Index n = images.cols();
  Eigen::MatrixXf queries(images.rows(), 200);
  for (Eigen::Index i = 0; i < queries.cols(); ++i) {
    const Eigen::Index a = i * (n / queries.cols());
    const float mix = static_cast<float>(i % 10) / 10.0f;
    Eigen::VectorXf q = (1 - mix) * images.col(a) + mix * images.col((a + n / 3) % n);
    q.array() -= q.mean();
    queries.col(i) = q.normalized();
  }
  constexpr int kK = 5;
  for (const bool compressed : {true, false}) {
    SCOPED_TRACE(compressed ? "compressed" : "full");
    const auto all = library.nearest(queries, kK, compressed);
    std::vector<float> d2;
    for (const auto& matches : all) d2.push_back(matches.back().d2);
    std::nth_element(d2.begin(), d2.begin() + static_cast<long>(d2.size() / 2), d2.end());
    const float bound = d2[d2.size() / 2];  // the median query's k-th distance: about half are cut
    const auto within = library.nearest(queries, kK, compressed, bound);
    ASSERT_EQ(within.size(), all.size());
    size_t cut = 0;
    for (size_t i = 0; i < all.size(); ++i) {
      std::vector<SpinImageLibrary::Match> expected;
      for (const auto& m : all[i])
        if (m.d2 < bound) expected.push_back(m);
      cut += expected.size() < all[i].size();
      ASSERT_EQ(within[i].size(), expected.size()) << "query " << i;
      for (size_t r = 0; r < expected.size(); ++r) {
        EXPECT_EQ(within[i][r].model, expected[r].model);
        EXPECT_EQ(within[i][r].point, expected[r].point);
        EXPECT_FLOAT_EQ(within[i][r].d2, expected[r].d2);
      }
    }
    EXPECT_GT(cut, 50u);  // the bound cuts
    EXPECT_LT(cut, 150u);
  }
}

// The free-space test asks the model's own tree, in the model's frame, whether a scene point lies
// on the model: the tree must index exactly the model's points.
TEST(Recognition, TheLibrarysModelTreeIndexesTheModelsPoints) {
  auto& library = bunny_library();
  library.compress();
  const PointCloud& points = library.model_points(0);
  const KdTree3& tree = library.model_tree(0);
  ASSERT_EQ(tree.size(), points.points.size());
  for (size_t i = 0; i < points.points.size(); i += 97) {
    const auto [nearest, d_sq] = tree.nearest(points.points[i]);
    EXPECT_EQ(d_sq, 0.0f) << i;
    EXPECT_EQ(points.points[nearest], points.points[i]) << i;
  }
  const float res = static_cast<float>(library.params().resolution_m);
  EXPECT_FALSE(tree.nearest_within(points.points[0] + Eigen::Vector3f(1, 0, 0), 1.5f * res).has_value());
}

// A tee lying on a table with a wall-like box between it and the sensor: the part of the tee
// the box hides is no evidence against it. (Counting hidden surface as unexplained refused
// every instance more than a third occluded, and its overlap is held to less the hidden share.)
TEST(Recognition, AnInstanceHalfHiddenBehindAnotherObjectIsFound) {
  const test::TempDir dir;
  const auto models = test::data_dir() / "workcells" / "models";
  const auto wall = nlohmann::json::parse(R"([{"name": "wall", "primitive": {"box": [0.3, 0.03, 0.12]}, "pose": "0 -0.1 0.86 0 0 0 1"}])");
  const auto objects = nlohmann::json::array({
      {{"name", "tee#1"}, {"mesh", (models / "tee.ply").string()}, {"pose", "0 0.02 0.9 0.5 0.5 0.5 0.5"}, {"drop", true}, {"mass_kg", 1.0}}});
  const auto acquisition = scan_table(dir.path(), 3, wall, objects);
  const auto& truth = *std::find_if(acquisition.truth.objects.begin(), acquisition.truth.objects.end(),
                                    [](const auto& o) { return o.name == "tee#1"; });
  const double occlusion = 1 - truth.visible_fraction;
  ASSERT_GT(occlusion, 0.3) << "the wall should hide a good part of the tee";
  ASSERT_LT(occlusion, 0.7);
  const Transform T_sensor_tee = acquisition.truth.T_world_sensor.inverse() * truth.T_world_object;

  SpinImageLibrary library;
  for (const auto* name : {"tee", "elbow_90", "flange"}) {
    const auto path = models / (std::string(name) + ".ply");
    library.add_model(name, io::ply_to_mesh(io::read_ply(path), path));
  }
  RecognitionParams params;
  params.views = {SensorView::perspective(Eigen::Vector3d::Zero())};
  const auto result = recognize(mesh_range_image(acquisition.range).mesh, library, params);
  // Only the tee is checked here: a flange is also "found" on the wall box (its face on the
  // wall's, the rest hidden in it), a known false positive that bench_recognition counts.
  const auto tee = std::find_if(result.instances.begin(), result.instances.end(), [](const auto& i) { return i.model == "tee"; });
  ASSERT_NE(tee, result.instances.end()) << "the tee was not found";
  EXPECT_EQ(std::count_if(result.instances.begin(), result.instances.end(), [](const auto& i) { return i.model == "tee"; }), 1);
  const auto& found = *tee;
  // The tee is symmetric (a half turn about its run): either pose is right.
  const Transform d = T_sensor_tee.inverse() * found.T_scene_model;
  EXPECT_LT(d.translation().norm(), 0.005);
  const double deg = rotation_angle(d) * 180 / std::numbers::pi;
  EXPECT_TRUE(deg < 5 || deg > 175) << deg << " degrees";
  EXPECT_GT(found.occluded_fraction, 0.1) << "the hidden part was seen as hidden";
  std::printf("tee %.0f%% occluded: found at %.2f mm, %.1f deg; explained %.2f, occluded %.2f, free space %.3f\n", 100 * occlusion,
              d.translation().norm() * 1e3, deg, found.visible_explained, found.occluded_fraction, found.free_space_fraction);
}

// BOP's MSSD: the largest distance of the model's surface points at pose T from its surface at
// the true pose (a symmetric part turned onto itself is at distance 0).
float surface_distance(const PointCloud& surface, const KdTree3& tree, const Transform& truth, const Transform& T) {
  const Transform e = truth.inverse() * T;
  float worst = 0;
  for (const auto& p : surface.points) worst = std::max(worst, std::sqrt(tree.nearest((e * p.cast<double>()).cast<float>()).second));
  return worst;
}

// Pipes and fittings are nearly surfaces of revolution: a scene point's spin image matches many
// model points equally well, and its right model point is rarely the nearest. Method: a 350 mm
// pipe and an elbow dropped on a table, seen by a simulated Vivid; recognized with one source of
// pose hypotheses alone (`only`), which must find each at its true pose up to its symmetries
// (BOP's MSSD: every model point at the found pose within 10% of the diameter of the model
// surface at the true pose, so a pipe turned about or flipped end for end counts), and nothing else.
RecognitionResult expect_pipework_found(RecognitionParams params) {
  const test::TempDir dir;
  const auto models = test::data_dir() / "workcells" / "models";
  const auto objects = nlohmann::json::array({
      {{"name", "pipe_350#1"}, {"mesh", (models / "pipe_350.ply").string()}, {"pose", "-0.05 0.0 0.86 0.30107070 0.60214141 0.10035690 0.73260538"}, {"drop", true}, {"mass_kg", 1.0}},
      {{"name", "elbow_90#1"}, {"mesh", (models / "elbow_90.ply").string()}, {"pose", "0.15 0.1 0.9 0.19971063 0.09985531 0.59913189 0.76888592"}, {"drop", true}, {"mass_kg", 0.6}}});
  const auto acquisition = scan_table(dir.path(), 5, nlohmann::json::array(), objects);

  SpinImageLibrary library;
  std::map<std::string, PointCloud> surfaces;
  for (const auto* name : {"tee", "elbow_90", "flange", "valve", "pipe_350"}) {
    const auto path = models / (std::string(name) + ".ply");
    const auto mesh = io::ply_to_mesh(io::read_ply(path), path);
    library.add_model(name, mesh);
    surfaces[name] = sample_surface(mesh, 0.002);
  }
  params.views = {SensorView::perspective(Eigen::Vector3d::Zero())};
  params.group_hypotheses = false;
  const auto result = recognize(mesh_range_image(acquisition.range).mesh, library, params);
  for (const auto* name : {"pipe_350", "elbow_90"}) {
    const auto& truth = *std::find_if(acquisition.truth.objects.begin(), acquisition.truth.objects.end(),
                                      [&](const auto& o) { return o.name == std::string(name) + "#1"; });
    const Transform T_sensor_object = acquisition.truth.T_world_sensor.inverse() * truth.T_world_object;
    const PointCloud& surface = surfaces.at(name);
    const KdTree3 tree(surface.points);
    const float diameter = surface.bounds().diagonal().norm();
    int found = 0;
    for (const auto& inst : result.instances) {
      if (inst.model != name) continue;
      const float worst = surface_distance(surface, tree, T_sensor_object, inst.T_scene_model);
      found += worst < 0.1f * diameter;
      std::printf("%s (visible %.2f): found, surface distance at most %.1f mm\n", name, truth.visible_fraction, worst * 1e3);
    }
    EXPECT_EQ(found, 1) << name << " (visible " << truth.visible_fraction << ") not found at its pose exactly once";
  }
  EXPECT_EQ(result.instances.size(), 2u) << "false instances";
  return result;
}

// Poses from pairs of spin-image matches alone (no grouping, no voting, no cylinder axes).
TEST(Recognition, PairsOfAmbiguousMatchesFindPipework) {
  RecognitionParams params;
  params.voting_pool = 0;
  params.axis_hypotheses = false;
  expect_pipework_found(params);
}

// Another pair seed is another draw of anchors and partners (other poses proposed) that finds
// the same parts: the seed moves the answers only by chance, which is what the clutter bench
// uses it to measure.
TEST(Recognition, AnotherPairSeedProposesOtherPosesAndFindsTheSameParts) {
  RecognitionParams params;
  params.voting_pool = 0;
  params.axis_hypotheses = false;
  params.keep_candidates = true;
  const auto first = expect_pipework_found(params);
  params.pair_seed = 7;
  const auto second = expect_pipework_found(params);
  const auto proposed = [](const RecognitionResult& r) {
    std::vector<Eigen::Matrix4d> poses;
    for (const auto& c : r.candidates) poses.push_back(c.T_scene_model.matrix());
    return poses;
  };
  const auto a = proposed(first), b = proposed(second);
  ASSERT_FALSE(a.empty());
  ASSERT_FALSE(b.empty());
  const auto among = [](const Eigen::Matrix4d& T, const std::vector<Eigen::Matrix4d>& poses) {
    return std::any_of(poses.begin(), poses.end(), [&](const Eigen::Matrix4d& U) { return T == U; });
  };
  EXPECT_FALSE(std::all_of(b.begin(), b.end(), [&](const Eigen::Matrix4d& T) { return among(T, a); })) << "the seed changed no proposed pose";
}

// Poses from point-pair-feature voting alone (no spin-image match used at all).
TEST(Recognition, PointPairVotingFindsPipework) {
  RecognitionParams params;
  params.pair_partners = 0;
  params.axis_hypotheses = false;
  expect_pipework_found(params);
}

// Where an object's seen surface ends, the scene steps away or turns: its silhouette. Method:
// synthetic scenes of the flange model's own mesh (axis along z, the upper face of its disc at
// z = 20 mm) and a plane around it, seen from above at an angle. On a table (the plane at z = 0)
// the flange is found at its pose; sunk up to its face in a larger surface (the plane at z = 20
// mm: the scene carries its face on past its outline, as when a flange is "found" flush on a
// box's face) it is no instance - nor at its pose with the silhouette test turned off, as it
// then goes through the plane's face - unless the through test is turned off too, which shows
// the pose is otherwise accepted.
TEST(Recognition, AFaceFlushWithALargerSurfaceHasNoSilhouetteAndIsNoInstance) {
  const auto path = test::data_dir() / "workcells" / "models" / "flange.ply";
  const auto flange = io::ply_to_mesh(io::read_ply(path), path);
  SpinImageLibrary library;
  library.add_model("flange", flange);
  // The plane z = height outside the flange's disc (radius 82.5 mm), out to 0.13 m, facing +z:
  // smaller than the flange's whole surface, so not a background plane (which explains nothing).
  const auto plane_around = [](float height) {
    TriangleMesh m;
    const int n = 96;
    for (int k = 0; k < n; ++k) {
      const float a = 2.0f * std::numbers::pi_v<float> * static_cast<float>(k) / n;
      m.vertices.emplace_back(0.0826f * std::cos(a), 0.0826f * std::sin(a), height);
      m.vertices.emplace_back(0.13f * std::cos(a), 0.13f * std::sin(a), height);
    }
    for (int k = 0; k < n; ++k) {
      const int i0 = 2 * k, o0 = i0 + 1, i1 = 2 * ((k + 1) % n), o1 = i1 + 1;
      m.faces.emplace_back(i0, o0, o1);
      m.faces.emplace_back(i0, o1, i1);
    }
    m.compute_vertex_normals();
    return m;
  };
  RecognitionParams params;
  params.views = {SensorView::perspective(Eigen::Vector3d(0.0, -0.35, 0.6))};
  const auto found_at_pose = [&](const TriangleMesh& scene, const RecognitionParams& p) {
    const auto result = recognize(scene, library, p);
    int at_pose = 0;
    for (const auto& inst : result.instances) {
      // The flange is symmetric about its axis: the found pose must keep the axis and the centre.
      const Eigen::Vector3d axis = inst.T_scene_model.linear() * Eigen::Vector3d::UnitZ();
      at_pose += inst.T_scene_model.translation().norm() < 0.005 && axis.z() > std::cos(5.0 * std::numbers::pi / 180);
      std::printf("flange at %.1f mm, axis %.1f deg off; continued %.3f, explained %.2f\n", inst.T_scene_model.translation().norm() * 1e3,
                  std::acos(std::clamp(axis.z(), -1.0, 1.0)) * 180 / std::numbers::pi, inst.continued_fraction, inst.visible_explained);
    }
    return std::pair<size_t, int>(result.instances.size(), at_pose);
  };
  TriangleMesh on_table = flange;
  on_table.append(plane_around(0.0f));
  TriangleMesh flush = flange;
  flush.append(plane_around(0.02f));
  EXPECT_EQ(found_at_pose(on_table, params), std::make_pair(size_t{1}, 1)) << "the flange on a table";
  EXPECT_EQ(found_at_pose(flush, params).first, 0u) << "the flange sunk up to its face";
  RecognitionParams no_silhouette = params;
  // A flange does not slide along itself: max_continued_fraction_fixed is its limit.
  no_silhouette.max_continued_fraction = no_silhouette.max_continued_fraction_fixed = 1.0;
  // Sunk 20 mm at its pose, its hub above the plane and its disc under it, it also goes through
  // the plane's face (max_through_fraction): refused at its pose by that alone.
  EXPECT_EQ(found_at_pose(flush, no_silhouette).second, 0) << "without the silhouette test, through the plane";
  no_silhouette.max_through_fraction = 1.0;
  EXPECT_EQ(found_at_pose(flush, no_silhouette).second, 1) << "without the silhouette and through tests";
}

TEST(Recognition, BadInputThrows) {
  SpinImageLibrary empty;
  EXPECT_THROW(recognize(scan_mesh("bun000"), empty), Error);
  EXPECT_THROW(recognize(TriangleMesh{}, bunny_library()), Error);
  RecognitionParams no_step;
  no_step.axis_step_factor = 0;
  EXPECT_THROW(recognize(scan_mesh("bun000"), bunny_library(), no_step), Error);
  // One parameter set to a bad value (`set`), the rest the defaults.
  const auto expect_refused = [](double value, void (*set)(RecognitionParams&, double)) {
    RecognitionParams bad;
    set(bad, value);
    EXPECT_THROW(recognize(scan_mesh("bun000"), bunny_library(), bad), Error) << value;
  };
  for (const double incidence : {0.0, 95.0, std::numeric_limits<double>::quiet_NaN()}) {
    expect_refused(incidence, [](RecognitionParams& p, double v) { p.max_incidence_deg = v; });
    expect_refused(incidence, [](RecognitionParams& p, double v) { p.own_bin_min_incidence_deg = v; });
  }
  for (const double correlation : {-1.5, 1.01, std::numeric_limits<double>::quiet_NaN()})
    expect_refused(correlation, [](RecognitionParams& p, double v) { p.min_correlation = v; });
  for (const double limit : {-0.01, std::numeric_limits<double>::quiet_NaN()}) {
    expect_refused(limit, [](RecognitionParams& p, double v) { p.max_continued_fraction = v; });
    expect_refused(limit, [](RecognitionParams& p, double v) { p.max_continued_fraction_fixed = v; });
  }
  SpinImageLibrary lib;
  lib.add_model("bunny", scan_mesh("bun000"));
  EXPECT_THROW(lib.add_model("bunny", scan_mesh("bun000")), Error);  // duplicate name
}

// A scene bench_recognition kept (data/recognition/clutter-sceneN: the range image and the
// simulator's truth): its mesh and the library objects in it, with their poses in the sensor frame.
struct KeptScene {
  TriangleMesh mesh;
  struct Object {
    std::string name, model;
    Transform T_sensor_object;
    double visible_fraction;
  };
  std::vector<Object> objects;
  /// The object of that name (model#n), or nullptr.
  const Object* object(const std::string& name) const {
    const auto it = std::find_if(objects.begin(), objects.end(), [&](const Object& o) { return o.name == name; });
    return it == objects.end() ? nullptr : &*it;
  }
};
KeptScene kept_scene(const std::string& name) {
  const auto dir = test::data_dir() / "recognition" / name;
  KeptScene scene;
  scene.mesh = mesh_range_image(io::read_range_image(dir / "range.ari")).mesh;
  const auto truth = nlohmann::json::parse(std::ifstream(dir / "truth.json"));
  const auto matrix = [](const nlohmann::json& v) {
    Transform T = Transform::Identity();
    for (int k = 0; k < 16; ++k) T.matrix()(k / 4, k % 4) = v.at(static_cast<size_t>(k)).get<double>();
    return T;
  };
  const Transform T_sensor_world = matrix(truth.at("T_world_sensor")).inverse();
  for (const auto& o : truth.at("objects")) {
    const auto object = o.at("name").get<std::string>();
    if (object.find('#') == std::string::npos || object.starts_with("distractor")) continue;
    scene.objects.push_back({object, object.substr(0, object.find('#')), T_sensor_world * matrix(o.at("T_world_object")), o.at("visible_fraction").get<double>()});
  }
  return scene;
}

// A library model: its mesh, and its surface every 2 mm for the surface distance.
struct LibraryModel {
  TriangleMesh mesh;
  PointCloud surface;
  std::unique_ptr<KdTree3> tree;
  float diameter;
};
LibraryModel library_model(const std::string& name) {
  const auto path = test::data_dir() / "workcells" / "models" / (name + ".ply");
  LibraryModel m;
  m.mesh = io::ply_to_mesh(io::read_ply(path), path);
  m.surface = sample_surface(m.mesh, 0.002);
  m.tree = std::make_unique<KdTree3>(m.surface.points);
  m.diameter = m.surface.bounds().diagonal().norm();
  return m;
}

// A kept scene recognized with a library of the named models, as the bench does (one
// perspective view at the sensor).
struct KeptRecognition {
  std::map<std::string, LibraryModel> models;
  RecognitionResult result;
  /// How far (MSSD) an instance lies from the nearest true object of its model in `kept`.
  float nearest_true(const KeptScene& kept, const RecognizedInstance& inst) const {
    const auto& m = models.at(inst.model);
    float nearest = std::numeric_limits<float>::infinity();
    for (const auto& o : kept.objects)
      if (o.model == inst.model) nearest = std::min(nearest, surface_distance(m.surface, *m.tree, o.T_sensor_object, inst.T_scene_model));
    return nearest;
  }
  /// Whether an instance of the object's model lies at its pose (MSSD within 10% of the diameter).
  bool found(const KeptScene::Object& o) const {
    const auto& m = models.at(o.model);
    return std::any_of(result.instances.begin(), result.instances.end(), [&](const RecognizedInstance& inst) {
      return inst.model == o.model && surface_distance(m.surface, *m.tree, o.T_sensor_object, inst.T_scene_model) < 0.1f * m.diameter;
    });
  }
};
// Every instance lies at a true object of its model (MSSD within 10% of the diameter).
void expect_every_instance_true(const KeptRecognition& run, const KeptScene& kept) {
  for (const auto& inst : run.result.instances) {
    EXPECT_LT(run.nearest_true(kept, inst), 0.1f * run.models.at(inst.model).diameter) << "false " << inst.model;
  }
}
// The bench's five-part library.
const std::vector<std::string> kBenchLibrary = {"tee", "elbow_90", "flange", "valve", "pipe_350"};
// Most kept scenes that test one change were chosen where the change was needed with the
// point-pair voting of its day: a table sampled at 3% of each model's diameter. With the
// default 5% (2026-12-05) the proposals differ, and in those scenes the parts are found without
// the change too, which leaves the scene testing nothing; their tests keep the finer step.
ModelLibraryParams chosen_voting() {
  ModelLibraryParams params;
  params.pair_step_fraction = 0.03;
  return params;
}
KeptRecognition recognize_kept(const KeptScene& kept, const std::vector<std::string>& names, RecognitionParams params = {},
                               const ModelLibraryParams& library_params = {}) {
  KeptRecognition run;
  SpinImageLibrary library(library_params);
  for (const auto& name : names) {
    run.models[name] = library_model(name);
    library.add_model(name, run.models[name].mesh);
  }
  params.views = {SensorView::perspective(Eigen::Vector3d::Zero())};
  run.result = recognize(kept.mesh, library, params);
  return run;
}

// A change tested on a kept scene (the five-part library, as the bench recognizes it): without
// it (`without`) the object `missed` must be missed - the test fails if it is found, as the
// scene would no longer test the change; with it (`with`) every object in `found` must be found
// at its pose (MSSD within 10% of the diameter), and every instance must be a true one.
void expect_found_only_with(const std::string& scene, const std::string& missed, const std::vector<std::string>& found, const std::string& change,
                            const RecognitionParams& without, const RecognitionParams& with, const ModelLibraryParams& library = {}) {
  const auto kept = kept_scene(scene);
  for (const auto& name : found) ASSERT_NE(kept.object(name), nullptr) << name;
  ASSERT_NE(kept.object(missed), nullptr) << missed;
  const auto describe = [&](const KeptRecognition& run, const std::string& name) {
    const auto& o = *kept.object(name);
    return name + " (" + std::to_string(std::lround(100 * (1 - o.visible_fraction))) + "% occluded) " + (run.found(o) ? "found" : "missed");
  };
  const auto before = recognize_kept(kept, kBenchLibrary, without, library);
  std::printf("%s, without: %s, %zu instances\n", scene.c_str(), describe(before, missed).c_str(), before.result.instances.size());
  EXPECT_FALSE(before.found(*kept.object(missed))) << missed << " found without " << change << ": the scene no longer tests it";
  const auto after = recognize_kept(kept, kBenchLibrary, with, library);
  std::printf("%s, with %s:", scene.c_str(), change.c_str());
  for (const auto& name : found) std::printf(" %s;", describe(after, name).c_str());
  std::printf(" %zu instances\n", after.result.instances.size());
  for (const auto& name : found) {
    EXPECT_TRUE(after.found(*kept.object(name))) << name << " was not found at its pose";
  }
  expect_every_instance_true(after, kept);
}

// A valve's body and ends are nearly a surface of revolution about its run; only its stem and
// hand wheel say how far it is turned about it. Method: bench_recognition's scene 9
// (data/recognition/clutter-scene9: eight parts and distractors piled on a table, one simulated
// Vivid view), where the valve is 8% occluded. Without the turn search (turn_steps 0) the valve
// is "found" turned 127.5 degrees about its run, the wheel where nothing contradicts it - which
// this test expects, so that the scene keeps testing the search; with it, the valve must be found
// at its pose (MSSD within 10% of its diameter; its half turn about the stem is a symmetry).
TEST(Recognition, AValveFoundTurnedAboutItsRunIsTurnedBack) {
  const auto kept = kept_scene("clutter-scene9");
  const TriangleMesh& scene = kept.mesh;
  Transform T_sensor_valve = Transform::Identity();
  for (const auto& o : kept.objects)
    if (o.name == "valve#1") T_sensor_valve = o.T_sensor_object;
  const auto valve = library_model("valve");
  SpinImageLibrary library(chosen_voting());
  library.add_model("valve", valve.mesh);
  const PointCloud& surface = valve.surface;
  const KdTree3& tree = *valve.tree;
  const float diameter = valve.diameter;

  RecognitionParams params;
  params.views = {SensorView::perspective(Eigen::Vector3d::Zero())};
  // The turn search alone, in the pool it was needed in: with the support plane's votes left out
  // (the default) or the default voting step the valve is found at its pose without it, rivals or not.
  params.no_votes_on_support = false;
  params.rivals = 0;
  for (const int turn_steps : {0, params.turn_steps}) {
    params.turn_steps = turn_steps;
    const auto result = recognize(scene, library, params);
    float nearest = std::numeric_limits<float>::infinity();
    for (const auto& inst : result.instances) nearest = std::min(nearest, surface_distance(surface, tree, T_sensor_valve, inst.T_scene_model));
    std::printf("turn steps %d: %zu valves, the nearest %.1f mm (MSSD) from the true pose\n", turn_steps, result.instances.size(), nearest * 1e3);
    if (turn_steps == 0) {
      EXPECT_GT(nearest, 0.1f * diameter) << "found without the turn search: the scene no longer tests it";
    } else {
      EXPECT_LT(nearest, 0.1f * diameter) << "the valve was not found at its pose";
      EXPECT_EQ(result.instances.size(), 1u);
    }
  }
}

// One interpretation of the scene across models: a tee's run fits any pipe of its bore, and in a
// pile of pipes and tees the tee's best-supported poses lie on the pipes; once the pipes are
// accepted (they explain more of the scene than a tee's run on them), those poses lose their
// support and the true tees rank first. Method: bench_recognition's scene 2
// (data/recognition/clutter-scene2: four tees and three pipes piled on a table with distractors,
// one simulated Vivid view), recognized with a library of the tee and the pipe. Before the
// interpretation was joint (each model searched alone, in library order) the two tees 2% and 42%
// occluded were not found: their true poses ranked 123rd and 126th. Every tee and pipe less than
// 70% occluded must be found at its pose (MSSD within 10% of its diameter), and nothing else.
TEST(Recognition, PartsHiddenByFitsOnOtherPartsAreFoundOnceThoseAreExplained) {
  const auto kept = kept_scene("clutter-scene2");
  const auto run = recognize_kept(kept, {"tee", "pipe_350"});
  int expected = 0;
  for (const auto& o : kept.objects) {
    const bool found = run.found(o);
    std::printf("%s (%.0f%% occluded): %s\n", o.name.c_str(), 100 * (1 - o.visible_fraction), found ? "found" : "missed");
    if (o.visible_fraction > 0.3) {
      ++expected;
      EXPECT_TRUE(found) << o.name << " (" << 100 * (1 - o.visible_fraction) << "% occluded) was not found at its pose";
    }
  }
  EXPECT_EQ(expected, 6);  // the scene's four tees, one of them 78% occluded, and three pipes
  for (const auto& inst : run.result.instances) {
    const float nearest = run.nearest_true(kept, inst);
    EXPECT_LT(nearest, 0.1f * run.models.at(inst.model).diameter)
        << "false " << inst.model << " (overlap " << inst.overlap_fraction << ", the nearest true one " << 1e3 * nearest << " mm away by MSSD)";
  }
}

// The detections do not depend on how many threads recognition runs on: the ICP's sums, split
// among the threads, are rounded differently, and nothing else may depend on the split (a
// reduction in the order threads finish would make a scene's answer change from run to run).
// Method: clutter scene 2 (four tees and three pipes among distractors) with the tee and pipe
// library, on one thread and on two; the same instances, with the same models and poses to a
// micrometre and a microradian.
TEST(Recognition, TheSameDetectionsOnOneThreadAsOnTwo) {
  const auto kept = kept_scene("clutter-scene2");
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  const auto one = recognize_kept(kept, {"tee", "pipe_350"});
  omp_set_num_threads(2);
  const auto two = recognize_kept(kept, {"tee", "pipe_350"});
  omp_set_num_threads(threads);
  ASSERT_GE(one.result.instances.size(), 6u);
  ASSERT_EQ(one.result.instances.size(), two.result.instances.size());
  for (size_t k = 0; k < one.result.instances.size(); ++k) {
    const auto &a = one.result.instances[k], &b = two.result.instances[k];
    EXPECT_EQ(a.model, b.model) << "instance " << k;
    EXPECT_LT((a.T_scene_model.translation() - b.T_scene_model.translation()).norm(), 1e-6) << "instance " << k << " (" << a.model << ")";
    EXPECT_LT(rotation_angle(a.T_scene_model.inverse() * b.T_scene_model), 1e-6) << "instance " << k;
  }
}

// A search verifies at most five poses with the fine ICP and the visibility tests; in a crowded
// scene the five best coarse poses of a part were often fits far from passing (a flange's face
// on a valve's end flange, an elbow's bend on a pipe), and the true pose, sixth or later, was
// never tried. A coarse pose far from passing is now refused before the fine ICP and does not
// count, and poses that put the model's surface in the same place (a flange's turns about its
// axis) are verified once. Method: bench_recognition's scene 21 (data/recognition/
// clutter-scene21: three flanges, two valves, an elbow and a pipe with distractors, one
// simulated Vivid view), recognized with the five-part library as the bench does. Before the
// change the elbow, 68% occluded, was not found. It and the flange 28% occluded must be found at
// their poses (MSSD within 10% of the diameter), with at most one false instance (the bench's
// figure for this scene).
TEST(Recognition, CoarsePosesFarFromPassingDoNotUseUpTheVerifications) {
  const auto kept = kept_scene("clutter-scene21");
  const auto run = recognize_kept(kept, kBenchLibrary);
  size_t true_instances = 0;
  for (const auto& o : kept.objects) {
    const bool found = run.found(o);
    true_instances += found;
    std::printf("%s (%.0f%% occluded): %s\n", o.name.c_str(), 100 * (1 - o.visible_fraction), found ? "found" : "missed");
    if (o.name == "flange#1" || o.name == "elbow_90#1") {
      EXPECT_TRUE(found) << o.name << " was not found at its pose";
    }
  }
  EXPECT_LE(run.result.instances.size(), true_instances + 1) << "more than one false instance";
}

// A result is ambiguous when another pose that puts the model's surface elsewhere fits the scene
// about as well; a turn about the part's own symmetry (a flange about its axis) is not one.
// Method: bench_recognition's scene 40 (data/recognition/clutter-scene40: two tees, two valves,
// two elbows and a flange with distractors, one simulated Vivid view). The valve 49% occluded has
// its stem and hand wheel hidden: it is found turned about its run, and must be reported
// ambiguous. The flange, unoccluded and found at its pose, must not be (before this change every
// instance in the scene was: the flange's turns about its axis counted as other poses). Every
// ambiguous instance's alternative must lie more than a tenth of the diameter (MSSD) from it.
TEST(Recognition, AmbiguousOnlyWhenAnotherSurfaceFitsAsWell) {
  const auto kept = kept_scene("clutter-scene40");
  const auto run = recognize_kept(kept, kBenchLibrary);
  bool valve_seen = false, flange_seen = false;
  for (const auto& inst : run.result.instances) {
    const auto& m = run.models.at(inst.model);
    std::printf("%s%s at MSSD %.1f mm from the nearest true one\n", inst.model.c_str(), inst.ambiguous ? " (ambiguous)" : "",
                1e3 * run.nearest_true(kept, inst));
    if (inst.ambiguous) {
      EXPECT_GT(surface_distance(m.surface, *m.tree, inst.T_scene_model, inst.T_scene_model_alternative), 0.1f * m.diameter)
          << inst.model << "'s alternative pose puts its surface in the same place";
    }
    for (const auto& o : kept.objects) {
      const bool here = o.model == inst.model && (o.T_sensor_object.translation() - inst.T_scene_model.translation()).norm() < 0.005;
      if (here && o.name == "valve#2") {
        valve_seen = true;
        EXPECT_TRUE(inst.ambiguous) << "the valve with its stem hidden is not reported ambiguous";
      }
      if (here && o.name == "flange#1" && run.found(o)) {
        flange_seen = true;
        EXPECT_FALSE(inst.ambiguous) << "the unoccluded flange is reported ambiguous";
      }
    }
  }
  EXPECT_TRUE(valve_seen) << "no valve instance at the valve's place";
  EXPECT_TRUE(flange_seen) << "the flange was not found at its pose";
}

// A straight pipe's body gives neither spin images nor point pairs that place it (its points
// and pairs all look alike; only its rims fix the shift), so it is also proposed on the scene's
// cylinder axes of its radius, at every shift along them. Method: bench_recognition's scene 27
// (data/recognition/clutter-scene27: a pipe 29% occluded, a tee and two elbows with distractors,
// one simulated Vivid view), recognized with the five-part library as the bench does. Without
// the axis proposals the pipe is not found (no pose near it); with them it must be, at its pose
// (MSSD within 10% of its diameter), and every instance must be a true one. Point-pair voting
// is off in both runs: since its table changed (2026-12-04: one word per pair, rotations in
// 65536ths of a turn) one of its vote clusters also lands near this pipe, and the scene would
// no longer tell the axis proposals' part.
TEST(Recognition, APipeIsProposedOnTheSceneCylinderAxes) {
  RecognitionParams with;
  with.voting_pool = 0;
  RecognitionParams without = with;
  without.axis_hypotheses = false;
  expect_found_only_with("clutter-scene27", "pipe_350#1", {"pipe_350#1"}, "axis proposals", without, with);
}

// A flange's face fits any flat surface at every slide and turn; in a crowded scene such fits
// (on a box top, refused each time because the box's face carries on past the flange's outline)
// took every search's verifications while the true flanges, with less support, were never
// refined. A pose refused as lying on one plane, or flush with a larger surface, now takes the
// surface under it (and that plane as far as the model reaches) out of the model's support.
// Method: bench_recognition's scene 21 (data/recognition/clutter-scene21), recognized with the
// five-part library as the bench does, without and with RecognitionParams::drop_refused_planes.
// Without it the flange 32% occluded is missed (the test fails if it is found: the scene must
// keep testing the change); with it the flange and the pipe, missed before, must be found at
// their poses (MSSD within 10% of the diameter), and every instance must be a true one.
// The second search round (RecognitionParams::search_rounds) also finds that flange, by
// refining the starting poses the box top's fits had kept out, and so do the proposals on its
// neck's axis (round_part_hypotheses): both runs hold them off.
TEST(Recognition, ARefusedPlaneNoLongerSupportsTheModel) {
  RecognitionParams with;
  with.search_rounds = 1;
  with.round_part_hypotheses = false;
  RecognitionParams without = with;
  without.drop_refused_planes = false;
  expect_found_only_with("clutter-scene21", "flange#3", {"flange#3", "pipe_350#1"}, "dropping refused planes", without, with, chosen_voting());
}

// A table top seen between the parts on it is a plane, and every pair of its points fits a
// flange's face anywhere on it: its vote clusters fill the voting pool, and an unoccluded flange
// is never proposed. Points on a support plane (a connected region of a plane larger than twice
// any model's largest planar part) need not vote (RecognitionParams::no_votes_on_support).
// Method: bench_recognition's scene 25 (data/recognition/clutter-scene25: three flanges and two
// valves with distractors, one simulated Vivid view), recognized with the five-part library as
// the bench does, without and with the option. Without it the flange 15% occluded must be missed
// (no pose near it; the test fails if it is found, as the scene would no longer test the
// option); with it (the default) that flange and the other flange and valve in view must be found at their
// poses (MSSD within 10% of the diameter), and every instance must be a true one. The proposals
// on the flange's neck's axis (round_part_hypotheses) find it too: both runs hold them off.
TEST(Recognition, TheTableTopNeedNotVote) {
  RecognitionParams with;
  with.round_part_hypotheses = false;
  RecognitionParams without = with;
  without.no_votes_on_support = false;
  expect_found_only_with("clutter-scene25", "flange#2", {"flange#1", "flange#2", "valve#1"}, "no votes on the support plane", without, with);
}

// A part seen edge-on is not held against its pose where its surface meets the sensor's rays at
// grazing incidence: the scanner returns nothing there (the simulated Vivid drops points from
// 60 degrees and all of them from 80), so "the sensor saw through it" is no evidence.
// Method: bench_recognition's scene 21 (data/recognition/clutter-scene21), whose flange#2 is
// unoccluded (2% in the laser's shadow) but seen edge-on (its faces at about 88 degrees to the
// rays: the ground truth counts 25% of it as hidden, beyond the scanner's 80-degree limit), recognized with the
// five-part library without an incidence limit (the default) and with one of 70 degrees
// (RecognitionParams::max_incidence_deg). Without it the flange must be missed (its true pose
// leaves a tenth of its sensor-facing surface "in free space"; the test fails if it is found,
// as the scene would no longer test the limit); with it the flange must be found at its pose
// (MSSD within 10% of the diameter), and every instance must be a true one.
// Both tests below hold each other's change off: either finds the flange. So do turning refused
// poses (RecognitionParams::refused_turns: a turn of a refused pose of it passes) and the
// proposals on its neck's axis (round_part_hypotheses), which both hold off too.
TEST(Recognition, ASurfaceAtGrazingIncidenceIsNoEvidenceAgainstAPose) {
  ASSERT_GT(kept_scene("clutter-scene21").object("flange#2")->visible_fraction, 0.7);
  RecognitionParams without;
  without.free_space_own_bin = false;
  without.refused_turns = 0;
  without.round_part_hypotheses = false;
  RecognitionParams with = without;
  with.max_incidence_deg = 70;
  expect_found_only_with("clutter-scene21", "flange#2", {"flange#2"}, "an incidence limit of 70 deg", without, with, chosen_voting());
}

// Where the scanner returned nothing along a ray (a face at grazing incidence, whose returns it
// dropped), the sensor saw nothing through it either: a model point there is no evidence of free
// space, whatever the neighbouring bins saw (behind an edge-on flange, the table), nor was it
// expected to be seen unless something seen hides it. The free-space test had taken the nearest
// depth seen in the 3 x 3 bins around each model point's; it now counts a point only when its
// own bin holds a return (RecognitionParams::free_space_own_bin, the default). Method:
// bench_recognition's scene 21, whose flange#2 is unoccluded but seen edge-on, as above,
// recognized with the five-part library as the bench does, with the 3 x 3 bins alone and with
// the default. With the 3 x 3 bins the flange must be missed (its true pose leaves a tenth of its
// sensor-facing surface "in free space"; the test fails if it is found, as the scene would no
// longer test the change); with the own-bin test it must be found at its pose (MSSD within 10%
// of the diameter), and every instance must be a true one.
TEST(Recognition, WhereTheSensorReturnedNothingItSawNoFreeSpace) {
  RecognitionParams with;
  with.refused_turns = 0;
  with.round_part_hypotheses = false;
  RecognitionParams without = with;
  without.free_space_own_bin = false;
  expect_found_only_with("clutter-scene21", "flange#2", {"flange#2"}, "the own-bin free-space test", without, with, chosen_voting());
}

// A flange lying neck down with its face turned from the sensor shows it the face edge on, a
// strip of rim and the neck: spin images and point-pair voting put no pose near it, but its neck
// is a cylinder of the pipe's radius whose axis the scene shows (RecognitionParams::
// round_part_hypotheses). Method: bench_recognition's scene 75 (data/recognition/clutter-scene75,
// held out), whose flange#1 (21% occluded) lies so, recognized with the five-part library as the
// bench does, without and with the proposals on round parts' axes. Without them the flange must
// be missed (the test fails if it is found, as the scene would no longer test them); with them
// (the default) it and the other flange must be found at their poses (MSSD within 10% of the
// diameter), and every instance must be a true one.
TEST(Recognition, AFlangeSeenEdgeOnIsProposedOnItsNecksAxis) {
  RecognitionParams without;
  without.round_part_hypotheses = false;
  expect_found_only_with("clutter-scene75", "flange#1", {"flange#1", "flange#2"}, "proposals on round parts' axes", without, {});
}

// A search refines the five best starting poses (by their support on the scene) with the fine
// ICP; in a crowded scene a part's true pose can rank behind more than five others that are
// refused. When a search ends without an instance, a second round ranks the starting poses not
// tried yet and refines the best of them (RecognitionParams::search_rounds, 2 by default).
// Method: bench_recognition's scene 3 (data/recognition/clutter-scene3), whose flange#1 is 58%
// occluded, recognized with the five-part library as the bench does, with one round and with
// the default. With one round the flange must be missed (the test fails if it is found, as the
// scene would no longer test the rounds); with two it must be found at its pose (MSSD within
// 10% of the diameter), and every instance must be a true one.
TEST(Recognition, ASearchWithoutAnInstanceTriesTheNextStartingPoses) {
  RecognitionParams without;
  without.search_rounds = 1;
  expect_found_only_with("clutter-scene3", "flange#1", {"flange#1"}, "a second search round", without, {});
}

// A straight pipe's place along its axis is what the ICP holds least (only its rims fix it): a
// pose refined a few millimetres short of the seen end leaves the scene's pipe carrying on past
// the model's outline and is refused by the continued-surface test. Such a pose, refused by a
// small margin, is now also tried slid along the axis. Method: bench_recognition's scene 44
// (data/recognition/clutter-scene44), whose pipe_350#1 is unoccluded (3% in the laser's shadow,
// 5% at grazing incidence beyond the scanner's limit), recognized with the
// five-part library as the bench does, without slides (RecognitionParams::axis_slide_steps 0)
// and with them. Without them the pipe must be missed (refused with 3.3% of its surface
// continued against the 3% limit; the test fails if it is found, as the scene would no longer
// test the slides); with them it must be found at its pose (MSSD within 10% of the diameter),
// and every instance must be a true one.
TEST(Recognition, APipeRefusedShortOfItsEndIsSlidAlongItsAxis) {
  ASSERT_GT(kept_scene("clutter-scene44").object("pipe_350#1")->visible_fraction, 0.9);
  // The slides alone, in the pool they were needed in: with the support plane's votes left out
  // (the default) the pipe is found without them, rivals or not.
  RecognitionParams with;
  with.no_votes_on_support = false;
  with.rivals = 0;
  RecognitionParams without = with;
  without.axis_slide_steps = 0;
  expect_found_only_with("clutter-scene44", "pipe_350#1", {"pipe_350#1"}, "slides along the axis", without, with, chosen_voting());
}

// A search takes the first pose that passes in the order of the coarse ICP's score, and a pipe
// slid along its axis (its end hidden), or a valve turned about its run, passes as well as the
// true pose, which ranks behind it and is never refined. The winner's rivals (poses at its place
// whose coarse ICP put about as much of the model on the scene, RecognitionParams::rivals) are
// now refined too, and one that passes and fits better takes its place. Method:
// bench_recognition's scene 44 (data/recognition/clutter-scene44), whose pipe_350#2 is 26%
// occluded, recognized with the five-part library as the bench does, without rivals and with the
// default. Without them the pipe must be missed ("found" 57 mm along its axis, a false positive;
// the test fails if it is found, as the scene would no longer test the rivals); with them it must
// be found at its pose (MSSD within 10% of the diameter), and every instance must be a true one.
TEST(Recognition, ARivalThatFitsBetterTakesTheWinnersPlace) {
  // The rivals alone: the winner's slides along its axis (RecognitionParams::winner_slides,
  // below) find this pipe too.
  RecognitionParams with;
  with.winner_slides = false;
  RecognitionParams without = with;
  without.rivals = 0;
  expect_found_only_with("clutter-scene44", "pipe_350#2", {"pipe_350#1", "pipe_350#2"}, "rivals", without, with, chosen_voting());
}

// The winner's rivals are the poses within half the model's diameter of it, and two tees lying
// side by side are that close: the second tee, refined as a rival, passed every test and lost
// (the first fits better), and was closed with the poses tried, so the search after the first
// was accepted never tried it again. A rival that passes and loses now stays open
// (RecognitionParams::losing_rivals_stay_open). Method: bench_recognition's scene 33
// (data/recognition/clutter-scene33: two tees, two valves, a pipe and a flange with distractors),
// whose tee#2 (53% occluded) lies about 19 cm from tee#1 (45% occluded), recognized with the
// five-part library as the bench does, with the rivals closed and with the default. Closed,
// tee#2 must be missed (the test fails if it is found, as the scene would no longer test the
// change); open, both tees must be found at their poses (MSSD within 10% of the diameter), and
// every instance must be a true one.
TEST(Recognition, ARivalThatPassesAndLosesIsTriedAgainAfterTheWinner) {
  RecognitionParams without;
  without.losing_rivals_stay_open = false;
  expect_found_only_with("clutter-scene33", "tee#2", {"tee#1", "tee#2"}, "losing rivals left open", without, {});
}

// A rival that fits better takes the winner's place, and the rivals are the poses within half the
// model's diameter of the winner: two tees side by side are that close. When the rival is the
// second tee, the displaced winner (the first) was closed with the poses tried, and no later
// search found it again. A displaced winner whose centre lies at least displaced_winner_distance
// of the diameter from the rival's now stays open (a better placement of the same object lies
// nearer: in scene 33 the displaced false tee lay 0.295 diameters from the true one). Method:
// bench_recognition's scene 699 (data/recognition/clutter-scene699, held out: two tees 8% and 6%
// occluded, 12 cm apart (0.5 diameters), among six more parts and distractors), recognized
// with the five-part library as the bench does. Closed (negative), tee#1 must be missed (the
// test fails if it is found, as the scene would no longer test the change); open, both tees must
// be found at their poses (MSSD within 10% of the diameter), and every instance must be a true one.
TEST(Recognition, AWinnerDisplacedByASecondInstanceIsTriedAgain) {
  RecognitionParams without;
  without.displaced_winner_distance = -1;
  expect_found_only_with("clutter-scene699", "tee#1", {"tee#1", "tee#2"}, "displaced winners left open", without, {});
}

// A pipe along a tee's run and the tee explain mostly the same scene surface: accepting either
// refuses the other (more than max_shared_support of what each explains is the other's), so they
// are two readings of one object. Instances were accepted by the surface they explain alone, and
// the pipe, longer than the tee's run, explains more though the sensor's evidence is more against
// it; now of two such readings the one the evidence is less against (its share in seen free space
// plus the share of what the sensor should have seen of it that it did not) by more than
// conflict_margin is accepted. Method: bench_recognition's scene 6 (data/recognition/
// clutter-scene6, tuned half: two tees, a pipe and an elbow with distractors), whose tee#1 is 41%
// occluded, recognized with the five-part library as the bench does, by the surface alone
// (conflict_margin negative) and with the default. By the surface alone the tee must be missed
// (a pipe "found" on its run with 2.8% of it in free space and 13% of what should be seen of it
// unseen, against the tee's 0 and 5%; the test fails if the tee is found, as the scene would no
// longer test the change); with the default, both tees and the pipe must be found at their poses
// (MSSD within 10% of the diameter), and every instance must be a true one.
TEST(Recognition, OfAPipeAndATeeReadingOneObjectTheOneTheEvidenceIsLessAgainstIsAccepted) {
  RecognitionParams without;
  without.conflict_margin = -1;
  expect_found_only_with("clutter-scene6", "tee#1", {"tee#1", "tee#2", "pipe_350#1"}, "conflicts settled by the evidence", without, {});
}

// A pipe whose ends are both hidden fits its seen part at any place along its run that covers
// it, and one that carries on into space the sensor saw through passes the free-space test as
// long as less than its limit (10%) of the surface facing the sensor lies there. The winner's
// rivals are the poses the search happened to start from; a pipe's winner is now also tried
// slid along its axis up to half its length either way, and the slide that puts about as much
// of it on the scene with the least in free space takes its place when it scores more
// (RecognitionParams::winner_slides). Method: bench_recognition's scene 92 (data/recognition/
// clutter-scene92, held out from tuning: three pipes, a flange, a valve, a tee and an elbow with
// distractors), whose pipe_350#1 is 42% occluded, recognized with the five-part library as the
// bench does, without the winner's slides and with the default. Without them the pipe must be
// missed ("found" 81 mm along its run with 3.6% of it in free space, a false positive; the test
// fails if it is found, as the scene would no longer test the slides); with them it must be
// found at its pose (MSSD within 10% of the diameter), and every instance must be a true one.
TEST(Recognition, APipeSlidAlongItsRunIntoSeenFreeSpaceIsSlidBack) {
  RecognitionParams without;
  without.winner_slides = false;
  expect_found_only_with("clutter-scene92", "pipe_350#1", {"pipe_350#1", "pipe_350#2", "flange#1", "tee#1"}, "the winner's slides", without, {});
}

// An elbow's surface slides along itself by a turn about its bend's centre (detail::Slide): the
// point-to-plane ICP hardly holds its place along the bend, and a pose turned some way about it,
// with one end where the sensor saw nothing, passes the visibility tests as a pipe slid along its
// run does. A winning elbow is now also tried slid about its bend, as a pipe's winner is along
// its axis, and a refused one is slid as a refused pipe is (RecognitionParams::bend_slides).
// Method: bench_recognition's scene 57 (data/recognition/clutter-scene57, held out from tuning:
// two elbows, a tee, a flange and a valve with distractors), whose elbow_90#2 is 31% occluded,
// recognized with the five-part library as the bench does, without the bend slides and with the
// default. Without them the elbow must be missed (the search's winner is the elbow turned about
// its bend, 2.2% of it in seen free space, a false positive; the test fails if it is found, as
// the scene would no longer test the slides); with them it must be found at its pose (MSSD within
// 10% of the diameter), and every instance must be a true one.
TEST(Recognition, AnElbowTurnedAboutItsBendIsSlidBack) {
  RecognitionParams without;
  without.bend_slides = false;
  expect_found_only_with("clutter-scene57", "elbow_90#2", {"elbow_90#1", "elbow_90#2", "flange#1", "valve#1"}, "the bend slides", without, {});
}

// The ICP does not hold a pipe or an elbow along its slide (only its rims say where it ends), so
// an accepted one is set along the slide where the sensor's evidence is least against it
// (RecognitionParams::evidence_slides). Method: bench_recognition's scene 687
// (data/recognition/clutter-scene687, held out: five elbows, a tee and two pipes with
// distractors), recognized with the five-part library as the bench does, without the evidence
// slides and with the default. Each true elbow or pipe at most 30% occluded that is found (MSSD
// within 10% of the diameter) is scored by how far the found pose puts the model's centroid from
// where the true one does (a point every symmetry of the model keeps). Without the slides the
// worst of them must be more than 3 mm off (the test fails otherwise, as the scene would no
// longer test them); with them every one must be within 3 mm, and the objects found without
// must be found with them too.
TEST(Recognition, AnAcceptedElbowIsSetAlongItsBendWhereTheEvidenceIsLeastAgainstIt) {
  const auto kept = kept_scene("clutter-scene687");
  const auto worst_centroid_error = [&](const KeptRecognition& run, std::vector<std::string>& found) {
    double worst = 0;
    for (const auto& o : kept.objects) {
      if ((o.model != "elbow_90" && o.model != "pipe_350") || o.visible_fraction < 0.7) continue;
      const auto& m = run.models.at(o.model);
      Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
      for (const auto& p : m.surface.points) centroid += p.cast<double>();
      centroid /= static_cast<double>(m.surface.points.size());
      for (const auto& inst : run.result.instances) {
        if (inst.model != o.model || surface_distance(m.surface, *m.tree, o.T_sensor_object, inst.T_scene_model) >= 0.1f * m.diameter) continue;
        const double error = (inst.T_scene_model * centroid - o.T_sensor_object * centroid).norm();
        std::printf("  %s (%ld%% occluded): centroid %.1f mm off\n", o.name.c_str(), std::lround(100 * (1 - o.visible_fraction)), 1e3 * error);
        worst = std::max(worst, error);
        found.push_back(o.name);
      }
    }
    return worst;
  };
  RecognitionParams without;
  without.evidence_slides = false;
  std::vector<std::string> found_without, found_with;
  std::printf("without the evidence slides:\n");
  EXPECT_GT(worst_centroid_error(recognize_kept(kept, kBenchLibrary, without), found_without), 0.003)
      << "every part within 3 mm without the evidence slides: the scene no longer tests them";
  std::printf("with them:\n");
  EXPECT_LT(worst_centroid_error(recognize_kept(kept, kBenchLibrary), found_with), 0.003);
  for (const auto& name : found_without) {
    EXPECT_NE(std::find(found_with.begin(), found_with.end(), name), found_with.end()) << name << " is no longer found";
  }
}

// A tee whose branch is hidden and a pipe on its run explain the same seen surface, and both pass
// the visibility tests: nothing the sensor saw tells them apart, and the result must say so
// rather than pick one silently. Method: bench_recognition's scene 85 (data/recognition/
// clutter-scene85, held out from tuning: two tees, a pipe, a flange and two elbows with
// distractors), whose pipe_350#1 (48% occluded) is recognized as a tee with its branch where
// nothing was seen (it explains 54 scene points more). That instance must be reported ambiguous
// with pipe_350 as the alternative model, at the pipe's true pose (MSSD within 10% of the
// diameter); before, it was reported ambiguous with another pose of the tee only. An instance
// ambiguous with another model names a model of the library; one ambiguous with another pose of
// its own names its own model. Instances unoccluded or nearly (tee#1, elbow_90#2, 8-9% occluded)
// found at their poses must not be ambiguous.
TEST(Recognition, ATeeOnAPipesRunWithItsBranchHiddenIsAmbiguousWithThePipe) {
  const auto kept = kept_scene("clutter-scene85");
  const auto run = recognize_kept(kept, kBenchLibrary);
  const auto& pipe = *kept.object("pipe_350#1");
  const auto& pipe_model = run.models.at("pipe_350");
  bool reported = false;
  for (const auto& inst : run.result.instances) {
    std::printf("%s at MSSD %.1f mm from the nearest true one%s%s\n", inst.model.c_str(), 1e3 * run.nearest_true(kept, inst),
                inst.ambiguous ? ", ambiguous with " : "", inst.ambiguous ? inst.alternative_model.c_str() : "");
    if (!inst.ambiguous) continue;
    EXPECT_NE(std::find(kBenchLibrary.begin(), kBenchLibrary.end(), inst.alternative_model), kBenchLibrary.end()) << inst.alternative_model;
    if (inst.model == "tee" && inst.alternative_model == "pipe_350" &&
        surface_distance(pipe_model.surface, *pipe_model.tree, pipe.T_sensor_object, inst.T_scene_model_alternative) < 0.1f * pipe_model.diameter)
      reported = true;
    for (const auto* name : {"tee#1", "elbow_90#2"}) {
      const auto& o = *kept.object(name);
      const auto& m = run.models.at(o.model);
      if (inst.model == o.model && surface_distance(m.surface, *m.tree, o.T_sensor_object, inst.T_scene_model) < 0.1f * m.diameter)
        ADD_FAILURE() << name << ", " << std::lround(100 * (1 - o.visible_fraction)) << "% occluded, is reported ambiguous with " << inst.alternative_model;
    }
  }
  EXPECT_TRUE(reported) << "no tee reported ambiguous with pipe_350 at pipe_350#1's pose";
}

// A pipe whose ends are hidden fits the scene about as well anywhere along the seen run: the
// result must say so rather than pick a place silently. Method: bench_recognition's scene 603
// (data/recognition/clutter-scene603, held out: four pipes, two flanges, an elbow and a tee with
// distractors), whose pipe_350#1 (28% occluded) is found 42 mm along its run (12% of the pipe's
// diameter, so not at its pose), 0.159 of the model on the scene there against 0.153 at the true
// pose. That instance must be reported ambiguous with another pose of pipe_350 at pipe_350#1's
// (MSSD within 10% of the diameter); before the slide ambiguities it was reported unambiguous.
// The pipes with both ends in view (pipe_350#2 and #3, 4-6% occluded) found at their poses must
// not be ambiguous.
TEST(Recognition, APipeWhosePlaceAlongItsRunIsOpenIsAmbiguous) {
  const auto kept = kept_scene("clutter-scene603");
  const auto run = recognize_kept(kept, kBenchLibrary);
  const auto& pipe_model = run.models.at("pipe_350");
  const auto at = [&](const char* name, const Transform& T) {
    return surface_distance(pipe_model.surface, *pipe_model.tree, kept.object(name)->T_sensor_object, T) < 0.1f * pipe_model.diameter;
  };
  bool reported = false;
  for (const auto& inst : run.result.instances) {
    std::printf("%s at MSSD %.1f mm from the nearest true one%s%s\n", inst.model.c_str(), 1e3 * run.nearest_true(kept, inst),
                inst.ambiguous ? ", ambiguous with " : "", inst.ambiguous ? inst.alternative_model.c_str() : "");
    if (inst.model != "pipe_350") continue;
    if (inst.ambiguous && inst.alternative_model == "pipe_350" && at("pipe_350#1", inst.T_scene_model_alternative)) reported = true;
    for (const auto* name : {"pipe_350#2", "pipe_350#3"}) {
      EXPECT_FALSE(at(name, inst.T_scene_model) && inst.ambiguous) << name << ", in full view, is reported ambiguous";
    }
  }
  EXPECT_TRUE(reported) << "no pipe reported ambiguous with another pose of pipe_350 at pipe_350#1's";
}

// check_pose measures a given pose as recognize measures the poses it verifies. Method: the
// kept scene 38, its flange#3 (6% occluded): at its true pose it must pass (refined, within 1 mm
// of it); moved 3 cm toward the sensor, in space the sensor saw through, it must be refused with
// more than the free-space limit of its surface there; a model index beyond the library, and a
// pose that is not finite, must throw.
// A flange's face fits the table's near rim (a 20 by 60 mm bar) with the bar carrying on past
// its outline, 2.5% of its explained surface, under the 3% limit that holds for parts that
// slide along themselves (a pipe, an elbow: their refined poses may sit a little off along the
// slide); a flange does not slide (its turn about its axis is a symmetry) and is held to 1.5%
// (max_continued_fraction_fixed). Method: bench_recognition's scene 311
// (data/recognition/clutter-scene311, held out). Held to 3% the false flange is accepted - this
// test expects it, so that the scene keeps testing the limit; held to its own, every instance
// must be true, and every part found before must still be found.
TEST(Recognition, AFlangeOnTheTablesRimIsHeldToTheLimitOfPartsThatDoNotSlide) {
  const auto kept = kept_scene("clutter-scene311");
  RecognitionParams as_sliding;
  as_sliding.max_continued_fraction_fixed = as_sliding.max_continued_fraction;
  const auto before = recognize_kept(kept, kBenchLibrary, as_sliding);
  const auto is_false = [&](const KeptRecognition& run, const RecognizedInstance& inst) {
    return run.nearest_true(kept, inst) >= 0.1f * run.models.at(inst.model).diameter;
  };
  EXPECT_TRUE(std::any_of(before.result.instances.begin(), before.result.instances.end(),
                          [&](const RecognizedInstance& inst) { return inst.model == "flange" && is_false(before, inst); }))
      << "no false flange at the sliding parts' limit: the scene no longer tests the limit";
  const auto after = recognize_kept(kept, kBenchLibrary);
  expect_every_instance_true(after, kept);
  size_t found_before = 0;
  for (const auto& o : kept.objects) {
    if (!before.found(o)) continue;
    ++found_before;
    EXPECT_TRUE(after.found(o)) << o.name << " found at the sliding parts' limit, not at its own";
  }
  EXPECT_GE(found_before, 5u);
}

TEST(Recognition, CheckPoseMeasuresAGivenPose) {
  const auto kept = kept_scene("clutter-scene38");
  const auto& flange = *kept.object("flange#3");
  SpinImageLibrary library;
  for (const auto& name : kBenchLibrary) library.add_model(name, library_model(name).mesh);
  const size_t index = std::find(kBenchLibrary.begin(), kBenchLibrary.end(), "flange") - kBenchLibrary.begin();
  RecognitionParams params;
  params.views = {SensorView::perspective(Eigen::Vector3d::Zero())};
  const auto at_truth = check_pose(kept.mesh, library, index, flange.T_sensor_object, params);
  std::printf("at the true pose: overlap %.3f, free space %.3f, explained %.3f, through %.3f, moved %.2f mm\n", at_truth.overlap_fraction,
              at_truth.free_space_fraction, at_truth.visible_explained, at_truth.through_fraction,
              1e3 * (at_truth.T_scene_model.translation() - flange.T_sensor_object.translation()).norm());
  EXPECT_EQ(at_truth.stage, RecognitionCandidate::Stage::accepted);
  EXPECT_LT((at_truth.T_scene_model.translation() - flange.T_sensor_object.translation()).norm(), 0.001);
  Transform nearer = flange.T_sensor_object;
  nearer.translation() -= 0.03 * flange.T_sensor_object.translation().normalized();
  const auto in_front = check_pose(kept.mesh, library, index, nearer, params, false);
  std::printf("3 cm nearer: overlap %.3f, free space %.3f\n", in_front.overlap_fraction, in_front.free_space_fraction);
  EXPECT_EQ(in_front.stage, RecognitionCandidate::Stage::refused);
  EXPECT_GT(in_front.free_space_fraction, params.max_free_space_fraction);
  EXPECT_THROW(check_pose(kept.mesh, library, kBenchLibrary.size(), flange.T_sensor_object, params), Error);
  Transform broken = flange.T_sensor_object;
  broken.translation().x() = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(check_pose(kept.mesh, library, index, broken, params), Error);
}

// A part stands on the table; it does not go through it. A tee whose run lies on a pipe lying on
// the table, its branch down in the table top, fits the scene: the table hides where its branch
// would be, so nothing the sensor saw contradicts it, and as it explains more of the scene than
// the pipe does it is accepted first and the pipe is lost. Such a pose now leaves a share of the
// model on each side of a solid's face (a background or support plane; its region the convex
// hull of its seen points, and beyond it under what hides the plane) and is refused
// (RecognitionParams::max_through_fraction). Method: bench_recognition's scene 38
// (data/recognition/clutter-scene38: three flanges, a pipe and an elbow with distractors),
// whose pipe_350#1 is 42% occluded, recognized with the five-part library as the bench does,
// without the test (a limit of 1) and with it. Without it the pipe must be missed (a false tee
// 73 mm along it, its lowest point 30 mm under the table top; the test fails if the pipe is
// found, as the scene would no longer test the change); with it the pipe must be found at its
// pose (MSSD within 10% of the diameter), and every instance must be a true one.
// Turning refused poses (RecognitionParams::refused_turns) is held off in both runs: it turns
// that tee's refused pose to one with its branch above the table, where nothing the sensor saw
// contradicts it either, and it is accepted ahead of the pipe again (1,909 scene points
// explained against the pipe's 1,896): the false positive that change brings to this scene.
TEST(Recognition, APoseThroughTheTableTopIsNoInstance) {
  RecognitionParams with;
  with.refused_turns = 0;
  RecognitionParams without = with;
  without.max_through_fraction = 1;
  expect_found_only_with("clutter-scene38", "pipe_350#1", {"pipe_350#1", "flange#3"}, "the through test", without, with, chosen_voting());
}

// With refused poses tried turned (the default), a tee's refused pose on the pipe of scene 38
// turns to one with its run on the pipe and its branch above the table, which nothing the sensor
// saw contradicts, and which explained a little more of the scene than the pipe (1,909 points
// against 1,896): the pipe was lost to it. 1.9% of that tee lies in the table top, which the
// through test allowed up to 2%; a part resting on a face has none of it beyond the tolerance.
// Method: scene 38 as above, with the through test's limit at 2% and at the default (1%): the
// pipe must be missed at 2% (the scene no longer tests the limit otherwise), found at 1%, and
// every instance true.
TEST(Recognition, APoseTwoPercentThroughTheTableTopIsNoInstance) {
  RecognitionParams two_percent;
  two_percent.max_through_fraction = 0.02;
  expect_found_only_with("clutter-scene38", "pipe_350#1", {"pipe_350#1", "flange#3"}, "a 1% through limit", two_percent, {}, chosen_voting());
}

// A tee nearly in plain view whose run the ICP fits was refused with its branch turned where the
// sensor saw through it (15% of its surface in free space), and its true turn never proposed.
// A refined pose that fits the scene (overlap and residual pass) but that the visibility tests
// refuse is now tried turned about its turn axes, and a turn that passes takes its place
// (RecognitionParams::refused_turns). Method: bench_recognition's scene 18
// (data/recognition/clutter-scene18: a tee and three elbows with distractors on a table), whose
// tee#1 is 6% occluded, recognized with the five-part library as the bench does, without turning
// refused poses and with the default. Without it the tee must be missed (the test fails if it is
// found, as the scene would no longer test the change); with it the tee and the elbows must be
// found at their poses (MSSD within 10% of the diameter), and every instance must be a true one.
TEST(Recognition, ARefusedPoseIsTriedTurned) {
  RecognitionParams without;
  without.refused_turns = 0;
  expect_found_only_with("clutter-scene18", "tee#1", {"tee#1", "elbow_90#1", "elbow_90#2", "elbow_90#3"}, "turning refused poses", without, {},
                         chosen_voting());
}
}  // namespace
}  // namespace artisan
