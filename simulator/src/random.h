// Seeded standard normal draws for the simulator: std::mt19937_64 (fully specified by the C++
// standard) with an explicit Box-Muller transform, so a seed gives the same numbers with every
// standard library (std::normal_distribution's algorithm is implementation-defined).
#pragma once

#include <cmath>
#include <cstdint>
#include <random>

#include <Eigen/Core>

namespace evio::simulator::internal {

class NormalSampler {
 public:
  explicit NormalSampler(uint64_t seed) : engine_(seed) {}

  // One N(0, 1) draw. Box-Muller yields pairs; the second value is kept for the next call.
  double next() {
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    // u1 in (0, 1] (53 random bits, never 0 so the log is finite), u2 in [0, 1).
    const double u1 = 1.0 - static_cast<double>(engine_() >> 11) * 0x1.0p-53;
    const double u2 = static_cast<double>(engine_() >> 11) * 0x1.0p-53;
    const double r = std::sqrt(-2.0 * std::log(u1));
    const double a = 2.0 * M_PI * u2;
    spare_ = r * std::sin(a);
    has_spare_ = true;
    return r * std::cos(a);
  }

  Eigen::Vector3d next3() {
    const double x = next();
    const double y = next();
    const double z = next();
    return Eigen::Vector3d(x, y, z);
  }

 private:
  std::mt19937_64 engine_;
  double spare_ = 0.0;
  bool has_spare_ = false;
};

}  // namespace evio::simulator::internal
