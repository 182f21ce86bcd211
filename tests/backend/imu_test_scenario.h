// Shared scenario of the IMU back-end tests: noise densities, a brisk sinusoid trajectory
// (rotation about all axes up to ~1.5 rad/s, accelerations of a few m/s^2) and its ideal IMU.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Geometry>

#include "evio/calib/calibration_io.h"
#include "evio/simulator/imu.h"
#include "evio/simulator/trajectory.h"

namespace evio::backend::test_scenario {

inline const Eigen::Vector3d kGravity(0, 0, -9.81);

inline calib::ImuNoise test_noise() {
  calib::ImuNoise n;
  n.gyroscope_noise_density = 1e-3;
  n.accelerometer_noise_density = 1e-2;
  n.gyroscope_random_walk = 1e-4;
  n.accelerometer_random_walk = 1e-3;
  n.update_rate_hz = 1000;
  return n;
}

// `phased`: the preintegration tests' variant with position and angle phases.
inline simulator::SinusoidTrajectory make_trajectory(int64_t t_begin_ns, double duration_s, bool phased) {
  using Eigen::Vector3d;
  simulator::SinusoidTrajectoryOptions o;
  o.t_begin_ns = t_begin_ns;
  o.duration_s = duration_s;
  o.position_m = Vector3d(1, -2, 0.5);
  o.q_w_b0 = Eigen::Quaterniond(Eigen::AngleAxisd(0.4, Vector3d(1, 2, 3).normalized()));
  o.velocity_mps = Vector3d(0.3, -0.1, 0.05);
  o.amplitude_m = Vector3d(0.4, 0.3, 0.2);
  o.frequency_hz = Vector3d(0.7, 0.5, 0.9);
  o.angle_rate_radps = Vector3d(0.2, -0.1, 0.3);
  o.angle_amplitude_rad = Vector3d(0.3, 0.2, 0.5);
  o.angle_frequency_hz = Vector3d(0.6, 0.4, 0.3);
  if (phased) {
    o.phase_rad = Vector3d(0.1, 1.0, 2.0);
    o.angle_phase_rad = Vector3d(0.5, 0.0, 1.0);
  }
  return simulator::SinusoidTrajectory(o);
}

// Ideal IMU samples every period_ns over [t0, t1], plus constant biases.
inline std::vector<ImuSample> ideal_samples(const simulator::ContinuousTrajectory& traj, int64_t t0, int64_t t1, int64_t period_ns,
                                            const Eigen::Vector3d& bg = Eigen::Vector3d::Zero(),
                                            const Eigen::Vector3d& ba = Eigen::Vector3d::Zero()) {
  std::vector<ImuSample> out;
  for (int64_t t = t0; t <= t1; t += period_ns) {
    ImuSample s = simulator::ideal_imu(traj.evaluate(t), kGravity);
    s.gyro += bg;
    s.accel += ba;
    out.push_back(s);
  }
  return out;
}

}  // namespace evio::backend::test_scenario
