#pragma once
// Bullet physics for the workcell: dropped objects fall and come to rest on what is below them.
// Dynamics use each object's convex hull (primitives keep their exact shape); rendering keeps
// the exact mesh. The settled poses are the ground truth.
#include <string>
#include <vector>

#include "artisan/sim/workcell.hpp"

namespace artisan::sim {

struct SettleParams {
  double time_step_s = 1.0 / 240.0;     ///< fixed integration step [s]
  double max_time_s = 8.0;              ///< give up after this much simulated time [s]
  double rest_linear_m_per_s = 0.004;   ///< "at rest" below this speed [m/s]
  double rest_angular_rad_per_s = 0.03; ///< ... and below this turn rate [rad/s]
  double rest_duration_s = 0.5;         ///< ... for this long, every object [s]
  double friction = 0.8;                ///< Coulomb friction coefficient [-]
  double restitution = 0.05;            ///< bounciness [-]
  double collision_margin_m = 0.001;    ///< Bullet collision margin [m]
  double max_initial_tilt_rad = 0.6;    ///< dropped objects start tilted by up to this, about a random axis [rad]
  double initial_jitter_m = 0.01;       ///< ... and shifted horizontally by up to this [m]
};

struct SettleResult {
  int dropped = 0;                        ///< number of dropped objects
  int steps = 0;                          ///< integration steps taken
  double simulated_time_s = 0.0;          ///< [s]
  bool at_rest = false;                   ///< every object came to rest before max_time_s
  std::vector<std::string> still_moving;  ///< names of objects that did not
};

/// Drops the workcell's "drop" objects from their given poses (perturbed by the workcell's seed)
/// and writes the settled poses back into the bodies. Deterministic for a given workcell file.
SettleResult settle(Workcell& cell, const SettleParams& params = {});

struct ContactReport {
  double max_penetration_m = 0.0;  ///< deepest overlap between any two bodies' collision shapes [m]
  std::string deepest_pair;        ///< "A / B", empty when nothing overlaps
};
/// Overlap between the collision shapes (the ones settle() used) at the current poses.
ContactReport check_contacts(const Workcell& cell, const SettleParams& params = {});

}  // namespace artisan::sim
