// IMU synthesis from a continuous trajectory. Ideal gyro = omega_b, ideal accelerometer =
// R_w_b^T (a_w - g_w). Kalibr's discrete-time noise model, for a sample period dt:
//   measurement_k = ideal_k + b_k + (sigma / sqrt(dt)) n_k,     b_{k+1} = b_k + sigma_b sqrt(dt) m_k
// with n_k, m_k independent N(0, I3) draws from one seeded generator, drawn per sample in the
// order gyro white, accel white, gyro bias step, accel bias step.
#include "evio/simulator/imu.h"
#include "evio/calib/error.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "random.h"

namespace evio::simulator {
namespace {

bool finite_non_negative(double x) { return std::isfinite(x) && x >= 0.0; }

}  // namespace

bool ImuSimOptions::Validate(std::string* why) const {
  if (!std::isfinite(rate_hz) || rate_hz <= 0.0 || rate_hz > 1e9)
    return validation_failed(why, "rate_hz must be finite, > 0 and at most 1e9 (a period of at least 1 ns)");
  if (enable_noise) {
    if (!finite_non_negative(noise.accelerometer_noise_density) || !finite_non_negative(noise.gyroscope_noise_density) ||
        !finite_non_negative(noise.accelerometer_random_walk) || !finite_non_negative(noise.gyroscope_random_walk))
      return validation_failed(why, "noise densities and random walks must be finite and >= 0");
  }
  if (!gravity_w.allFinite()) return validation_failed(why, "gravity_w must be finite");
  if (!initial_bias_gyro_radps.allFinite() || !initial_bias_accel_mps2.allFinite())
    return validation_failed(why, "initial biases must be finite");
  for (const auto& [b, e] : gaps_ns) {
    if (e <= b) return validation_failed(why, "each IMU gap must end after it begins");
  }
  return true;
}

ImuSample ideal_imu(const TrajectoryState& state, const Eigen::Vector3d& gravity_w) {
  ImuSample s;
  s.t_ns = state.t_ns;
  s.gyro = state.omega_b;
  s.accel = state.T_w_b.rotation.conjugate() * (state.a_w - gravity_w);
  return s;
}

std::vector<ImuSample> simulate_imu(const ContinuousTrajectory& trajectory, int64_t t0_ns, int64_t t1_ns,
                                    const ImuSimOptions& options, std::vector<ImuBiasSample>* biases) {
  std::string why;
  if (!options.Validate(&why)) throw std::invalid_argument("simulate_imu: " + why);
  if (t1_ns < t0_ns) throw std::invalid_argument("simulate_imu: t1_ns is before t0_ns");
  if (t0_ns < trajectory.t_begin_ns() || t1_ns > trajectory.t_end_ns())
    throw std::out_of_range("simulate_imu: [" + std::to_string(t0_ns) + ", " + std::to_string(t1_ns) +
                            "] is not inside the trajectory's valid range [" + std::to_string(trajectory.t_begin_ns()) +
                            ", " + std::to_string(trajectory.t_end_ns()) + "]");
  const int64_t period_ns = std::max<int64_t>(1, std::llround(1e9 / options.rate_hz));
  const double dt = static_cast<double>(period_ns) * 1e-9;
  const int64_t count = (t1_ns - t0_ns) / period_ns + 1;

  const double sigma_g = options.noise.gyroscope_noise_density / std::sqrt(dt);
  const double sigma_a = options.noise.accelerometer_noise_density / std::sqrt(dt);
  const double sigma_bg = options.noise.gyroscope_random_walk * std::sqrt(dt);
  const double sigma_ba = options.noise.accelerometer_random_walk * std::sqrt(dt);

  internal::NormalSampler rng(options.seed);
  Eigen::Vector3d bg = options.initial_bias_gyro_radps;
  Eigen::Vector3d ba = options.initial_bias_accel_mps2;

  std::vector<ImuSample> out;
  out.reserve(static_cast<size_t>(count));
  if (biases) {
    biases->clear();
    biases->reserve(static_cast<size_t>(count));
  }
  for (int64_t i = 0; i < count; ++i) {
    const int64_t t = t0_ns + i * period_ns;
    ImuSample s = ideal_imu(trajectory.evaluate(t), options.gravity_w);
    s.gyro += bg;
    s.accel += ba;
    if (biases) biases->push_back({t, bg, ba});
    if (options.enable_noise) {
      s.gyro += sigma_g * rng.next3();
      s.accel += sigma_a * rng.next3();
      bg += sigma_bg * rng.next3();
      ba += sigma_ba * rng.next3();
    }
    bool in_gap = false;
    for (const auto& [b, e] : options.gaps_ns) in_gap |= t >= b && t < e;
    if (!in_gap) out.push_back(s);
  }
  return out;
}

}  // namespace evio::simulator
