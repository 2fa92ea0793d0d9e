#include "artisan/sim/environment.hpp"

#include <algorithm>
#include <cmath>

#include "params_util.hpp"
#include "random.hpp"

namespace artisan::sim {

EnvironmentSensorParams environment_params(const std::map<std::string, double>& overrides) {
  EnvironmentSensorParams p;
  apply_overrides("environment", overrides,
                  {{"dose_relative_sigma", &p.dose_relative_sigma}, {"temperature_sigma_C", &p.temperature_sigma_C},
                   {"humidity_sigma_percent", &p.humidity_sigma_percent}});
  return p;
}

double path_length_in_bodies(const Workcell& cell, const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  const Eigen::Vector3d d = b - a;
  const double len = d.norm();
  if (len <= 0) return 0.0;
  double inside = 0.0;
  for (const auto& body : cell.bodies) {
    // In the body frame; skip bodies whose box the segment misses.
    const Transform T_body_world = body.T_world_body.inverse();
    const Eigen::Vector3d o = T_body_world * a, dir = T_body_world.linear() * d;
    const Eigen::AlignedBox3d box = body.mesh.bounds().cast<double>();
    double t0 = 0, t1 = 1;
    bool miss = false;
    for (int k = 0; k < 3 && !miss; ++k) {
      if (std::abs(dir[k]) < 1e-15) {
        miss = o[k] < box.min()[k] || o[k] > box.max()[k];
        continue;
      }
      double ta = (box.min()[k] - o[k]) / dir[k], tb = (box.max()[k] - o[k]) / dir[k];
      if (ta > tb) std::swap(ta, tb);
      t0 = std::max(t0, ta);
      t1 = std::min(t1, tb);
      miss = t0 > t1;
    }
    if (miss) continue;
    // Every crossing of the surface (Moller-Trumbore); a closed surface alternates in/out.
    std::vector<double> ts;
    const auto& V = body.mesh.vertices;
    for (const auto& f : body.mesh.faces) {
      const Eigen::Vector3d v0 = V[f[0]].cast<double>(), e1 = V[f[1]].cast<double>() - v0, e2 = V[f[2]].cast<double>() - v0;
      const Eigen::Vector3d pv = dir.cross(e2);
      const double det = e1.dot(pv);
      if (std::abs(det) < 1e-18) continue;
      const Eigen::Vector3d tv = o - v0;
      const double u = tv.dot(pv) / det;
      if (u < -1e-12 || u > 1 + 1e-12) continue;
      const Eigen::Vector3d qv = tv.cross(e1);
      const double v = dir.dot(qv) / det;
      if (v < -1e-12 || u + v > 1 + 1e-12) continue;
      const double t = e2.dot(qv) / det;
      if (t > 0 && t < 1) ts.push_back(t);
    }
    std::sort(ts.begin(), ts.end());
    // A crossing through a shared edge or vertex is found once per triangle: count it once.
    ts.erase(std::unique(ts.begin(), ts.end(), [&](double x, double y) { return (y - x) * len < 1e-9; }), ts.end());
    // Crossings pair up (enter, leave); an odd count means an end lies inside: close at 1.
    for (size_t k = 0; k < ts.size(); k += 2) inside += ((k + 1 < ts.size() ? ts[k + 1] : 1.0) - ts[k]) * len;
  }
  return inside;
}

double dose_rate_uSv_per_h(const Workcell& cell, const Eigen::Vector3d& p) {
  double total = 0.0;
  const auto& env = cell.environment;
  for (const auto& s : env.gamma_sources) {
    const double r = std::max((p - s.position_world).norm(), 0.01);  // 1 cm: the source's own size
    const double L = path_length_in_bodies(cell, s.position_world, p);
    total += s.dose_rate_at_1m_uSv_per_h / (r * r) * std::exp(-env.air_attenuation_per_m * r - env.solid_attenuation_per_m * L);
  }
  return total;
}

EnvironmentReading read_environment(const Workcell& cell, const Transform& T_world_rig, double time_s,
                                    const EnvironmentSensorParams& params, uint64_t seed) {
  Rng rng(seed ^ 0x656e76ull);
  const Eigen::Vector3d p = T_world_rig.translation();
  EnvironmentReading r;
  r.time_s = time_s;
  r.T_world_rig = T_world_rig;
  r.dose_rate_uSv_per_h = std::max(0.0, dose_rate_uSv_per_h(cell, p) * (1 + params.dose_relative_sigma * rng.normal()));
  r.temperature_C = cell.environment.temperature_C.value_at(p) + params.temperature_sigma_C * rng.normal();
  r.humidity_percent = std::clamp(cell.environment.humidity_percent.value_at(p) + params.humidity_sigma_percent * rng.normal(), 0.0, 100.0);
  return r;
}

}  // namespace artisan::sim
