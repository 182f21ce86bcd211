#include "evio/backend/initialization.h"

#include <cmath>
#include <stdexcept>

#include <Eigen/Geometry>

namespace evio::backend {

bool StaticInitOptions::Validate(std::string* why) const {
  auto fail = [why](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (window_ns <= 0) return fail("window_ns must be > 0 ns");
  if (!(max_gyro_noise_ratio > 0) || !(max_accel_noise_ratio > 0)) return fail("noise ratios must be > 0");
  if (!(gravity_mps2 > 0)) return fail("gravity_mps2 must be > 0 m/s^2");
  if (!(max_gravity_error > 0)) return fail("max_gravity_error must be > 0 m/s^2");
  return true;
}

std::optional<VioState> static_initialization(const std::vector<ImuSample>& imu, int64_t t_begin_ns,
                                              const calib::ImuNoise& noise, const StaticInitOptions& o, std::string* why) {
  auto fail = [why](const std::string& m) -> std::optional<VioState> {
    if (why) *why = m;
    return std::nullopt;
  };
  std::string v;
  if (!o.Validate(&v)) throw std::invalid_argument("static initialisation options: " + v);
  if (!noise.Validate(&v)) throw std::invalid_argument("static initialisation IMU noise: " + v);
  const int64_t t_end = t_begin_ns + o.window_ns;
  Eigen::Vector3d sg = Eigen::Vector3d::Zero(), sa = Eigen::Vector3d::Zero();
  Eigen::Vector3d sg2 = Eigen::Vector3d::Zero(), sa2 = Eigen::Vector3d::Zero();
  int n = 0;
  int64_t t_last = t_begin_ns;
  for (const ImuSample& s : imu) {
    if (s.t_ns < t_begin_ns || s.t_ns > t_end) continue;
    sg += s.gyro;
    sa += s.accel;
    sg2 += s.gyro.cwiseProduct(s.gyro);
    sa2 += s.accel.cwiseProduct(s.accel);
    t_last = s.t_ns;
    ++n;
  }
  if (n < 10) return fail("only " + std::to_string(n) + " IMU samples in the window (need 10)");
  const Eigen::Vector3d mg = sg / n, ma = sa / n;
  const Eigen::Vector3d std_g = (sg2 / n - mg.cwiseProduct(mg)).cwiseMax(0.0).cwiseSqrt();
  const Eigen::Vector3d std_a = (sa2 / n - ma.cwiseProduct(ma)).cwiseMax(0.0).cwiseSqrt();
  const double rate = noise.update_rate_hz;
  const double gyro_sigma = noise.gyroscope_noise_density * std::sqrt(rate);
  const double accel_sigma = noise.accelerometer_noise_density * std::sqrt(rate);
  if (std_g.maxCoeff() > o.max_gyro_noise_ratio * gyro_sigma) {
    return fail("not still: gyro spread " + std::to_string(std_g.maxCoeff()) + " rad/s exceeds " +
                std::to_string(o.max_gyro_noise_ratio * gyro_sigma));
  }
  if (std_a.maxCoeff() > o.max_accel_noise_ratio * accel_sigma) {
    return fail("not still: accelerometer spread " + std::to_string(std_a.maxCoeff()) + " m/s^2 exceeds " +
                std::to_string(o.max_accel_noise_ratio * accel_sigma));
  }
  if (std::abs(ma.norm() - o.gravity_mps2) > o.max_gravity_error) {
    return fail("mean specific force " + std::to_string(ma.norm()) + " m/s^2 is not gravity (" +
                std::to_string(o.gravity_mps2) + ")");
  }
  VioState s;
  s.t_ns = t_last;
  // R_w_b maps the measured up direction (specific force at rest = -g) onto world +z; yaw 0.
  s.T_w_b = calib::SE3(Eigen::Quaterniond::FromTwoVectors(ma.normalized(), Eigen::Vector3d::UnitZ()), Eigen::Vector3d::Zero());
  s.bias_gyro = mg;
  return s;
}

}  // namespace evio::backend
