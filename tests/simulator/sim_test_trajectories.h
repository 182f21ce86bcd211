// Trajectory fixtures shared by the simulator tests.
#pragma once

#include <cstdint>

#include <Eigen/Geometry>

#include "evio/simulator/trajectory.h"

namespace evio::simulator::test {

constexpr int64_t kLargeT0 = 1700000000000000000LL;  // 2023 in ns since the epoch

// A sinusoid that moves and turns about every axis with different frequencies and phases, a
// drift and constant angular rates (no derivative vanishes identically), 10 s from t0.
inline SinusoidTrajectoryOptions lively_sinusoid(int64_t t0) {
  using V = Eigen::Vector3d;
  SinusoidTrajectoryOptions o;
  o.t_begin_ns = t0;
  o.duration_s = 10.0;
  o.position_m = V(1.0, -2.0, 1.5);
  o.q_w_b0 = Eigen::Quaterniond(Eigen::AngleAxisd(0.7, V(1, 2, 3).normalized()));
  o.velocity_mps = V(0.1, -0.05, 0.02);
  o.amplitude_m = V(0.5, 0.3, 0.2);
  o.frequency_hz = V(0.5, 0.8, 1.3);
  o.phase_rad = V(0.1, 1.0, -0.4);
  o.angle_rate_radps = V(0.2, -0.1, 0.3);
  o.angle_amplitude_rad = V(0.6, 0.4, 0.8);
  o.angle_frequency_hz = V(0.7, 1.1, 0.4);
  o.angle_phase_rad = V(0.3, -0.2, 1.2);
  return o;
}

}  // namespace evio::simulator::test
