#pragma once
// Portable deterministic random numbers (std distributions differ between standard libraries).
#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>

namespace artisan::sim {

class Rng {
 public:
  explicit Rng(uint64_t seed) : engine_(seed ^ 0x9e3779b97f4a7c15ull) {}
  double uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }  ///< [0, 1)
  double normal() {  ///< standard normal, Box-Muller
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    double u1 = uniform();
    while (u1 <= 0.0) u1 = uniform();
    const double u2 = uniform();
    const double r = std::sqrt(-2.0 * std::log(u1));
    spare_ = r * std::sin(2 * std::numbers::pi * u2);
    has_spare_ = true;
    return r * std::cos(2 * std::numbers::pi * u2);
  }

 private:
  std::mt19937_64 engine_;
  bool has_spare_ = false;
  double spare_ = 0.0;
};

}  // namespace artisan::sim
