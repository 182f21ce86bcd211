// IMU synthesis for the simulator: the ideal accelerometer (specific force a_b = R_w_b^T (a_w - g_w))
// and gyroscope (omega_b) from a continuous trajectory's exact derivatives, plus the Kalibr noise
// model (github.com/ethz-asl/kalibr/wiki/IMU-Noise-Model): white noise with discrete standard
// deviation sigma / sqrt(dt) and biases driven by random walks sigma_b * sqrt(dt), all seeded.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "evio/calib/calibration_io.h"
#include "evio/sensors/measurements.h"
#include "evio/simulator/trajectory.h"

namespace evio::simulator {

struct ImuSimOptions {
  double rate_hz = 1000.0;                                          // sample rate, Hz, > 0
  calib::ImuNoise noise;                                            // Kalibr densities (continuous time)
  bool enable_noise = true;                                         // false: ideal samples, constant biases
  Eigen::Vector3d gravity_w = Eigen::Vector3d(0, 0, -9.81);         // m/s^2, world frame
  Eigen::Vector3d initial_bias_gyro_radps = Eigen::Vector3d::Zero();   // rad/s
  Eigen::Vector3d initial_bias_accel_mps2 = Eigen::Vector3d::Zero();   // m/s^2
  uint64_t seed = 1;
  // Body-clock spans [begin, end) without samples (a stalled IMU driver), ns, sorted or not; the
  // noise and bias processes run on through a gap, so the samples outside it do not change.
  std::vector<std::pair<int64_t, int64_t>> gaps_ns;

  bool Validate(std::string* why) const;
};

// True IMU biases at one sample (gyro rad/s, accel m/s^2).
struct ImuBiasSample {
  int64_t t_ns = 0;
  Eigen::Vector3d gyro = Eigen::Vector3d::Zero();
  Eigen::Vector3d accel = Eigen::Vector3d::Zero();
};

// Noise-free, bias-free measurement for one state.
ImuSample ideal_imu(const TrajectoryState& state, const Eigen::Vector3d& gravity_w);

// Samples at t0_ns + i * round(1e9 / rate_hz) for all i with t <= t1_ns. `biases`, when given,
// receives the true bias at every sample. Same options and seed give identical samples.
std::vector<ImuSample> simulate_imu(const ContinuousTrajectory& trajectory, int64_t t0_ns, int64_t t1_ns,
                                    const ImuSimOptions& options, std::vector<ImuBiasSample>* biases = nullptr);

}  // namespace evio::simulator
