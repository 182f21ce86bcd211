// IMU preintegration on the manifold between two keyframe times (Forster, Carlone, Dellaert,
// Scaramuzza, "On-Manifold Preintegration for Real-Time Visual-Inertial Odometry", T-RO 2017):
// relative rotation, velocity and position deltas, their 9x9 covariance and bias Jacobians.
//
// Model and conventions
// - Measurements: gyro_meas = omega_b + b_g + n_g, accel_meas = R_w_b^T (a_w - g_w) + b_a + n_a
//   (evio::simulator::ideal_imu, Kalibr noise model). Body = IMU frame, SI units.
// - Between consecutive knots the measurements are LINEAR in time (linear interpolation of the
//   samples). Knots are t_i, every sample strictly inside (t_i, t_j), and t_j; the measurement at
//   t_i and t_j is linearly interpolated between the samples that bracket it (a sample exactly at
//   t_i or t_j is used as is). A gap without samples inside (t_i, t_j) therefore integrates one
//   segment between the two interpolated end values. `between` throws std::invalid_argument when
//   there is no sample at or before t_i, or none at or after t_j (it never extrapolates).
// - Each segment [t_k, t_k+1] of length h (seconds, from the int64 ns difference) is integrated
//   with the midpoint/trapezoidal rule (second order in h):
//     dR_k+1 = dR_k Exp((0.5 (w_k + w_k+1) - b_g) h)
//     a_k = dR_k (f_k - b_a),  a_k+1 = dR_k+1 (f_k+1 - b_a)
//     dv_k+1 = dv_k + 0.5 h (a_k + a_k+1)
//     dp_k+1 = dp_k + h dv_k + 0.25 h^2 (a_k + a_k+1)
//   so the deltas satisfy R_j = R_i dR, v_j = v_i + g_w dt + R_i dv,
//   p_j = p_i + v_i dt + 0.5 g_w dt^2 + R_i dp (dt = t_j - t_i).
// - Error state [dtheta, dv, dp] with the rotation error on the right: dR_true = dR Exp(dtheta).
//   Per segment the gyro and accelerometer noise are each one white vector with discrete
//   covariance sigma^2 / h (continuous Kalibr density sigma; Kalibr's sigma / sqrt(dt) per sample,
//   with dt the segment length), entering the gyro midpoint and both accelerometer ends.
// - Bias Jacobians are the exact derivatives of the discrete scheme at the linearisation biases;
//   first-order correction for new biases (b_g + db_g, b_a + db_a):
//     dR(b) = dR Exp(J_R_bg db_g), dv(b) = dv + J_v_bg db_g + J_v_ba db_a, dp likewise.
// - Time: int64 ns; every interval length is an int64 difference converted to seconds, so absolute
//   times near 1.7e18 ns integrate exactly like times near 0.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "evio/calib/calibration_io.h"
#include "evio/sensors/measurements.h"

namespace evio::backend {

class ImuPreintegration {
 public:
  using Vec3 = Eigen::Vector3d;
  using Mat3 = Eigen::Matrix3d;
  using Mat9 = Eigen::Matrix<double, 9, 9>;
  using Mat96 = Eigen::Matrix<double, 9, 6>;

  // Empty preintegration (dt = 0, identity deltas, zero covariance) at the linearisation biases
  // bias_gyro (rad/s) and bias_accel (m/s^2). Throws std::invalid_argument when the biases are not
  // finite or noise.Validate fails (densities and rate > 0, random walks >= 0; the rate is not used,
  // segment lengths come from the timestamps).
  ImuPreintegration(const Vec3& bias_gyro, const Vec3& bias_accel, const calib::ImuNoise& noise);

  // Preintegration over [t_i_ns, t_j_ns] (t_i_ns <= t_j_ns) from time-sorted samples, with the knot
  // rule above. t_i == t_j gives the empty preintegration. Throws std::invalid_argument when
  // t_j < t_i, samples are not sorted by time, or the interval is not bracketed by samples.
  static ImuPreintegration between(const std::vector<ImuSample>& samples, int64_t t_i_ns, int64_t t_j_ns,
                                   const Vec3& bias_gyro, const Vec3& bias_accel, const calib::ImuNoise& noise);

  // Measurement at t_ns, linearly interpolated between the bracketing samples of a sorted vector.
  // Throws std::invalid_argument when t_ns is outside [front.t_ns, back.t_ns] or samples is empty.
  static ImuSample interpolate(const std::vector<ImuSample>& samples, int64_t t_ns);

  // Appends a knot: integrates the segment from the previous knot (linear measurements in between).
  // The first knot only sets t_i. Throws std::invalid_argument when sample.t_ns is before the
  // previous knot or the values are not finite. A knot at the same time as the previous one adds
  // nothing (the previous value is kept).
  void add_knot(const ImuSample& sample);

  // Integrates the stored knots again at new linearisation biases (exact, not first order).
  void reintegrate(const Vec3& bias_gyro, const Vec3& bias_accel);

  int64_t t_i_ns() const { return knots_.empty() ? 0 : knots_.front().t_ns; }
  int64_t t_j_ns() const { return knots_.empty() ? 0 : knots_.back().t_ns; }
  double dt_s() const { return dt_s_; }  // t_j - t_i, s
  const std::vector<ImuSample>& knots() const { return knots_; }
  const calib::ImuNoise& noise() const { return noise_; }
  const Vec3& bias_gyro() const { return bg_; }   // linearisation bias, rad/s
  const Vec3& bias_accel() const { return ba_; }  // linearisation bias, m/s^2

  Eigen::Quaterniond delta_q() const { return dq_; }
  Mat3 delta_R() const { return dq_.toRotationMatrix(); }
  const Vec3& delta_v() const { return dv_; }  // m/s
  const Vec3& delta_p() const { return dp_; }  // m
  // Covariance of [dtheta (rad), dv (m/s), dp (m)] from the measurement white noise.
  const Mat9& covariance() const { return cov_; }
  // d[dtheta, dv, dp] / d[b_g, b_a] (rows 0-2 rotation, 3-5 velocity, 6-8 position).
  const Mat96& bias_jacobian() const { return jac_; }
  Mat3 d_R_d_bg() const { return jac_.block<3, 3>(0, 0); }
  Mat3 d_v_d_bg() const { return jac_.block<3, 3>(3, 0); }
  Mat3 d_v_d_ba() const { return jac_.block<3, 3>(3, 3); }
  Mat3 d_p_d_bg() const { return jac_.block<3, 3>(6, 0); }
  Mat3 d_p_d_ba() const { return jac_.block<3, 3>(6, 3); }

  // First-order bias-corrected deltas for biases (bias_gyro, bias_accel).
  Eigen::Quaterniond corrected_delta_q(const Vec3& bias_gyro) const;
  Vec3 corrected_delta_v(const Vec3& bias_gyro, const Vec3& bias_accel) const;
  Vec3 corrected_delta_p(const Vec3& bias_gyro, const Vec3& bias_accel) const;

 private:
  void reset_state();
  void integrate_segment(const ImuSample& a, const ImuSample& b);

  Vec3 bg_, ba_;
  calib::ImuNoise noise_;
  std::vector<ImuSample> knots_;
  double dt_s_ = 0;
  Eigen::Quaterniond dq_ = Eigen::Quaterniond::Identity();
  Vec3 dv_ = Vec3::Zero(), dp_ = Vec3::Zero();
  Mat9 cov_ = Mat9::Zero();
  Mat96 jac_ = Mat96::Zero();
};

}  // namespace evio::backend
