// Pairwise registration with no initial pose on the 23 overlapping pairs of the real bunny
// scans, scored against bun.conf: Artisan (spin images + ICP) beside PCL's ICP from the
// identity and PCL's FPFH + SampleConsensusPrerejective + ICP, on the same meshes and machine.
// Output: JSON on stdout.
#include <sys/utsname.h>

#include <algorithm>
#include <map>

#include <chrono>
#include <filesystem>
#include <iostream>
#include <numbers>

#include <nlohmann/json.hpp>
#include <pcl/features/fpfh_omp.h>
#include <pcl/filters/voxel_grid.h>
#include <pcl/point_types.h>
#include <pcl/registration/icp.h>
#include <pcl/registration/sample_consensus_prerejective.h>

#include "artisan/core/io/ply.hpp"
#include "artisan/core/io/stanford_conf.hpp"
#include "artisan/perception/meshing.hpp"
#include "artisan/perception/registration.hpp"

namespace fs = std::filesystem;
using namespace artisan;
using Clock = std::chrono::steady_clock;
using PointN = pcl::PointNormal;
using Cloud = pcl::PointCloud<PointN>;

namespace {

double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

Cloud::Ptr to_pcl(const TriangleMesh& mesh) {
  const PointCloud oriented = oriented_points(mesh);
  Cloud::Ptr cloud(new Cloud);
  for (size_t i = 0; i < oriented.points.size(); ++i) {
    PointN p;
    p.x = oriented.points[i].x();
    p.y = oriented.points[i].y();
    p.z = oriented.points[i].z();
    p.normal_x = oriented.normals[i].x();
    p.normal_y = oriented.normals[i].y();
    p.normal_z = oriented.normals[i].z();
    cloud->push_back(p);
  }
  return cloud;
}

Cloud::Ptr downsample(const Cloud::Ptr& in, float voxel) {
  Cloud::Ptr out(new Cloud);
  pcl::VoxelGrid<PointN> grid;
  grid.setInputCloud(in);
  grid.setLeafSize(voxel, voxel, voxel);
  grid.filter(*out);
  return out;
}

Transform from_matrix(const Eigen::Matrix4f& m) {
  Transform T = Transform::Identity();
  T.matrix() = m.cast<double>();
  return T;
}

Transform pcl_icp(const Cloud::Ptr& target, const Cloud::Ptr& source, const Eigen::Matrix4f& init, float max_distance) {
  pcl::IterativeClosestPoint<PointN, PointN> icp;
  icp.setInputSource(source);
  icp.setInputTarget(target);
  icp.setMaxCorrespondenceDistance(max_distance);
  icp.setMaximumIterations(60);
  icp.setTransformationEpsilon(1e-10);
  Cloud aligned;
  icp.align(aligned, init);
  return from_matrix(icp.getFinalTransformation());
}

Transform pcl_fpfh(const Cloud::Ptr& target, const Cloud::Ptr& source, float voxel) {
  const auto tgt = downsample(target, voxel), src = downsample(source, voxel);
  auto features = [voxel](const Cloud::Ptr& c) {
    pcl::PointCloud<pcl::FPFHSignature33>::Ptr f(new pcl::PointCloud<pcl::FPFHSignature33>);
    pcl::FPFHEstimationOMP<PointN, PointN, pcl::FPFHSignature33> est;
    est.setInputCloud(c);
    est.setInputNormals(c);
    est.setRadiusSearch(5 * voxel);
    est.compute(*f);
    return f;
  };
  const auto ft = features(tgt), fsrc = features(src);
  pcl::SampleConsensusPrerejective<PointN, PointN, pcl::FPFHSignature33> align;
  align.setInputSource(src);
  align.setSourceFeatures(fsrc);
  align.setInputTarget(tgt);
  align.setTargetFeatures(ft);
  align.setMaximumIterations(50000);
  align.setNumberOfSamples(3);
  align.setCorrespondenceRandomness(5);
  align.setSimilarityThreshold(0.9f);
  align.setMaxCorrespondenceDistance(1.5f * voxel);
  align.setInlierFraction(0.25f);
  Cloud aligned;
  align.align(aligned);
  return pcl_icp(target, source, align.getFinalTransformation(), 2 * voxel / 3);
}

nlohmann::json score(const Transform& estimate, const Transform& truth, double seconds) {
  const Transform d = truth.inverse() * estimate;
  const double rot = rotation_angle(d) * 180 / std::numbers::pi, trans = d.translation().norm() * 1e3;
  return {{"rotation_error_deg", rot}, {"translation_error_mm", trans}, {"success", rot < 2 && trans < 2}, {"seconds", seconds}};
}

}  // namespace

int main() {
  const fs::path bunny = fs::path(ARTISAN_DATA_DIR) / "stanford-bunny";
  const auto conf = io::read_stanford_conf(bunny / "bun.conf");
  const std::vector<std::pair<std::string, std::string>> pairs = {
      {"bun000", "bun045"}, {"bun180", "top2"},   {"bun180", "ear_back"}, {"bun000", "bun315"}, {"bun045", "top3"},
      {"ear_back", "top2"}, {"bun270", "bun315"}, {"bun000", "top3"},     {"bun045", "bun315"}, {"bun045", "bun090"},
      {"bun090", "top3"},   {"bun315", "chin"},   {"bun000", "chin"},     {"bun090", "ear_back"}, {"bun090", "top2"},
      {"bun180", "bun270"}, {"bun000", "bun090"}, {"top2", "top3"},       {"bun270", "chin"},   {"bun045", "chin"},
      {"bun315", "top3"},   {"bun090", "bun180"}, {"bun000", "bun270"}};
  std::map<std::string, TriangleMesh> meshes;
  for (const auto& [a, b] : pairs)
    for (const auto& name : {a, b})
      if (!meshes.count(name)) meshes[name] = mesh_range_image(io::ply_to_range_image(io::read_ply(bunny / (name + ".ply")), name)).mesh;

  nlohmann::json rows = nlohmann::json::array();
  int ok_artisan = 0, ok_icp = 0, ok_fpfh = 0;
  std::vector<double> artisan_seconds, fpfh_seconds;
  for (const auto& [a, b] : pairs) {
    const Transform truth = conf.scan(a + ".ply").T_world_scan.inverse() * conf.scan(b + ".ply").T_world_scan;
    auto t0 = Clock::now();
    const auto r = register_meshes(meshes[a], meshes[b]);
    const double t_artisan = since(t0);
    auto artisan = score(r.T_target_source, truth, t_artisan);
    artisan["success"] = artisan["success"].get<bool>() && r.success;
    artisan["seconds_spin_images"] = r.seconds_spin_images;
    artisan["seconds_matching"] = r.seconds_matching;
    artisan["seconds_icp"] = r.seconds_icp;
    const auto target = to_pcl(meshes[a]), source = to_pcl(meshes[b]);
    const float voxel = static_cast<float>(3 * std::max(meshes[a].median_edge_length(), meshes[b].median_edge_length()));
    t0 = Clock::now();
    const Transform T_icp = pcl_icp(target, source, Eigen::Matrix4f::Identity(), 2 * voxel / 3);
    const auto icp = score(T_icp, truth, since(t0));
    t0 = Clock::now();
    const Transform T_fpfh = pcl_fpfh(target, source, voxel);
    const auto fpfh = score(T_fpfh, truth, since(t0));
    ok_artisan += artisan["success"].get<bool>();
    ok_icp += icp["success"].get<bool>();
    ok_fpfh += fpfh["success"].get<bool>();
    artisan_seconds.push_back(t_artisan);
    fpfh_seconds.push_back(fpfh["seconds"].get<double>());
    rows.push_back({{"target", a}, {"source", b}, {"artisan", artisan}, {"pcl_icp_from_identity", icp}, {"pcl_fpfh_ransac_icp", fpfh}});
  }
  auto median = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v[v.size() / 2];
  };
  utsname host{};
  uname(&host);
  nlohmann::json out = {{"benchmark", "registration_pairs"},
                        {"data", "23 overlapping pairs of the Stanford bunny scans, meshed with default parameters, no initial pose"},
                        {"machine", std::string(host.machine) + " " + host.release},
                        {"success_criterion", "rotation < 2 deg and translation < 2 mm from bun.conf"},
                        {"summary",
                         {{"artisan_successes", ok_artisan},
                          {"pcl_icp_successes", ok_icp},
                          {"pcl_fpfh_successes", ok_fpfh},
                          {"artisan_median_seconds", median(artisan_seconds)},
                          {"pcl_fpfh_median_seconds", median(fpfh_seconds)},
                          {"goal", "every pair; median under 0.2 s on two cores"}}},
                        {"pairs", rows}};
  std::cout << out.dump(2) << "\n";
}
