#include "evio/backend/imu_preintegration.h"

#include <algorithm>
#include <stdexcept>
#include <string>

#include "evio/calib/geometry.h"

namespace evio::backend {

namespace {

constexpr double kNsToS = 1e-9;

bool finite(const Eigen::Vector3d& v) { return v.allFinite(); }

std::string ns_str(int64_t t) { return std::to_string(t) + " ns"; }

}  // namespace

ImuPreintegration::ImuPreintegration(const Vec3& bias_gyro, const Vec3& bias_accel, const calib::ImuNoise& noise)
    : bg_(bias_gyro), ba_(bias_accel), noise_(noise) {
  std::string why;
  if (!noise.Validate(&why)) throw std::invalid_argument("ImuPreintegration: invalid IMU noise: " + why);
  if (!finite(bias_gyro) || !finite(bias_accel))
    throw std::invalid_argument("ImuPreintegration: linearisation biases must be finite");
}

ImuSample ImuPreintegration::interpolate(const std::vector<ImuSample>& samples, int64_t t_ns) {
  if (samples.empty()) throw std::invalid_argument("ImuPreintegration::interpolate: no IMU samples");
  if (t_ns < samples.front().t_ns || t_ns > samples.back().t_ns)
    throw std::invalid_argument("ImuPreintegration: time " + ns_str(t_ns) + " is outside the IMU samples [" +
                                ns_str(samples.front().t_ns) + ", " + ns_str(samples.back().t_ns) +
                                "]; preintegration does not extrapolate");
  // First sample with t >= t_ns.
  const auto hi = std::lower_bound(samples.begin(), samples.end(), t_ns,
                                   [](const ImuSample& s, int64_t t) { return s.t_ns < t; });
  if (hi->t_ns == t_ns) return *hi;
  const auto lo = hi - 1;  // exists: t_ns > front.t_ns here
  const double s = static_cast<double>(t_ns - lo->t_ns) / static_cast<double>(hi->t_ns - lo->t_ns);
  ImuSample out;
  out.t_ns = t_ns;
  out.gyro = (1.0 - s) * lo->gyro + s * hi->gyro;
  out.accel = (1.0 - s) * lo->accel + s * hi->accel;
  return out;
}

ImuPreintegration ImuPreintegration::between(const std::vector<ImuSample>& samples, int64_t t_i_ns, int64_t t_j_ns,
                                             const Vec3& bias_gyro, const Vec3& bias_accel,
                                             const calib::ImuNoise& noise) {
  if (t_j_ns < t_i_ns)
    throw std::invalid_argument("ImuPreintegration::between: t_j (" + ns_str(t_j_ns) + ") is before t_i (" +
                                ns_str(t_i_ns) + ")");
  // Sortedness is checked on the samples this interval uses (its bracket), not the whole vector:
  // callers pass a whole recording's IMU, and between() runs once per frame.
  if (!samples.empty()) {
    const auto first = std::lower_bound(samples.begin(), samples.end(), t_i_ns,
                                        [](const ImuSample& s, int64_t t) { return s.t_ns < t; });
    const auto last = std::upper_bound(first, samples.end(), t_j_ns,
                                       [](int64_t t, const ImuSample& s) { return t < s.t_ns; });
    const size_t k0 = static_cast<size_t>(std::max<std::ptrdiff_t>(1, first - samples.begin()));
    const size_t k1 = std::min(samples.size(), static_cast<size_t>(last - samples.begin()) + 1);
    for (size_t k = k0; k < k1; ++k)
      if (samples[k].t_ns < samples[k - 1].t_ns)
        throw std::invalid_argument("ImuPreintegration::between: IMU samples are not sorted by time (index " +
                                    std::to_string(k) + ")");
  }
  ImuPreintegration pre(bias_gyro, bias_accel, noise);
  pre.add_knot(interpolate(samples, t_i_ns));
  if (t_j_ns == t_i_ns) return pre;
  const ImuSample last = interpolate(samples, t_j_ns);  // checks the upper bracket before integrating
  auto it = std::upper_bound(samples.begin(), samples.end(), t_i_ns,
                             [](int64_t t, const ImuSample& s) { return t < s.t_ns; });
  for (; it != samples.end() && it->t_ns < t_j_ns; ++it) pre.add_knot(*it);
  pre.add_knot(last);
  return pre;
}

void ImuPreintegration::reset_state() {
  dt_s_ = 0;
  dq_ = Eigen::Quaterniond::Identity();
  dv_.setZero();
  dp_.setZero();
  cov_.setZero();
  jac_.setZero();
}

void ImuPreintegration::add_knot(const ImuSample& sample) {
  if (!finite(sample.gyro) || !finite(sample.accel))
    throw std::invalid_argument("ImuPreintegration: IMU sample at " + ns_str(sample.t_ns) + " is not finite");
  if (knots_.empty()) {
    knots_.push_back(sample);
    return;
  }
  const ImuSample& prev = knots_.back();
  if (sample.t_ns < prev.t_ns)
    throw std::invalid_argument("ImuPreintegration: knot at " + ns_str(sample.t_ns) + " is before the previous one at " +
                                ns_str(prev.t_ns));
  if (sample.t_ns == prev.t_ns) return;
  integrate_segment(prev, sample);
  knots_.push_back(sample);
  dt_s_ = static_cast<double>(knots_.back().t_ns - knots_.front().t_ns) * kNsToS;
}

void ImuPreintegration::reintegrate(const Vec3& bias_gyro, const Vec3& bias_accel) {
  if (!finite(bias_gyro) || !finite(bias_accel))
    throw std::invalid_argument("ImuPreintegration::reintegrate: biases must be finite");
  bg_ = bias_gyro;
  ba_ = bias_accel;
  reset_state();
  for (size_t k = 1; k < knots_.size(); ++k) integrate_segment(knots_[k - 1], knots_[k]);
  if (!knots_.empty()) dt_s_ = static_cast<double>(knots_.back().t_ns - knots_.front().t_ns) * kNsToS;
}

void ImuPreintegration::integrate_segment(const ImuSample& a, const ImuSample& b) {
  const double h = static_cast<double>(b.t_ns - a.t_ns) * kNsToS;
  const Vec3 w = 0.5 * (a.gyro + b.gyro) - bg_;
  const Vec3 f0 = a.accel - ba_;
  const Vec3 f1 = b.accel - ba_;
  const Vec3 phi = w * h;
  const Eigen::Quaterniond dq_step = calib::so3_exp_quat(phi);
  const Mat3 dR_step = dq_step.toRotationMatrix();
  const Mat3 Jr = calib::so3_right_jacobian(phi);

  const Mat3 R0 = dq_.toRotationMatrix();
  const Eigen::Quaterniond q1 = (dq_ * dq_step).normalized();
  const Mat3 R1 = q1.toRotationMatrix();
  const Vec3 acc_sum = R0 * f0 + R1 * f1;

  // Linearisation of the step: x_k+1 = A x_k + B u, x = [dtheta, dv, dp], u = [d b_g or n_g, d b_a or n_a]
  // (both enter the measurement with a plus sign; the deltas move with -u).
  const Mat3 R1_f1_hat = R1 * calib::hat(f1);
  Mat9 A = Mat9::Identity();
  A.block<3, 3>(0, 0) = dR_step.transpose();
  const Mat3 dacc_dtheta = -(R0 * calib::hat(f0) + R1_f1_hat * dR_step.transpose());  // d acc_sum / dtheta_k
  A.block<3, 3>(3, 0) = 0.5 * h * dacc_dtheta;
  A.block<3, 3>(6, 0) = 0.25 * h * h * dacc_dtheta;
  A.block<3, 3>(6, 3) = h * Mat3::Identity();

  Mat96 B = Mat96::Zero();
  const Mat3 dtheta1_du_g = -Jr * h;                        // d theta_k+1 / d u_g
  const Mat3 dacc_du_g = -R1_f1_hat * dtheta1_du_g;          // via R1 only
  const Mat3 dacc_du_a = -(R0 + R1);
  B.block<3, 3>(0, 0) = dtheta1_du_g;
  B.block<3, 3>(3, 0) = 0.5 * h * dacc_du_g;
  B.block<3, 3>(3, 3) = 0.5 * h * dacc_du_a;
  B.block<3, 3>(6, 0) = 0.25 * h * h * dacc_du_g;
  B.block<3, 3>(6, 3) = 0.25 * h * h * dacc_du_a;

  // Discrete white noise over the segment: continuous density^2 / h (Kalibr).
  Eigen::Matrix<double, 6, 1> q_diag;
  const double sg2 = noise_.gyroscope_noise_density * noise_.gyroscope_noise_density / h;
  const double sa2 = noise_.accelerometer_noise_density * noise_.accelerometer_noise_density / h;
  q_diag << sg2, sg2, sg2, sa2, sa2, sa2;

  // Update in order: deltas use the old velocity.
  dp_ += h * dv_ + 0.25 * h * h * acc_sum;
  dv_ += 0.5 * h * acc_sum;
  dq_ = q1;
  jac_ = A * jac_ + B;
  cov_ = A * cov_ * A.transpose() + B * q_diag.asDiagonal() * B.transpose();
  cov_ = 0.5 * (cov_ + cov_.transpose());
}

Eigen::Quaterniond ImuPreintegration::corrected_delta_q(const Vec3& bias_gyro) const {
  return (dq_ * calib::so3_exp_quat(d_R_d_bg() * (bias_gyro - bg_))).normalized();
}

ImuPreintegration::Vec3 ImuPreintegration::corrected_delta_v(const Vec3& bias_gyro, const Vec3& bias_accel) const {
  return dv_ + d_v_d_bg() * (bias_gyro - bg_) + d_v_d_ba() * (bias_accel - ba_);
}

ImuPreintegration::Vec3 ImuPreintegration::corrected_delta_p(const Vec3& bias_gyro, const Vec3& bias_accel) const {
  return dp_ + d_p_d_bg() * (bias_gyro - bg_) + d_p_d_ba() * (bias_accel - ba_);
}

}  // namespace evio::backend
