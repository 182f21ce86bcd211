// SO(3)/SE(3) helpers on Eigen types. Closed forms follow Barfoot (2017), ch. 7; every
// coefficient that is 0/0 at the identity switches to its Taylor series below a small angle, and
// the logarithm goes through a Shepperd quaternion so that it stays accurate up to angle pi.
#include "evio/calib/geometry.h"

#include <cmath>

namespace evio::calib {
namespace {

// Below these angles (rad) the series truncated after the theta^4 term is exact to double
// precision (the first dropped term is < 1e-20).
constexpr double kSmallAngleExp = 1e-4;
constexpr double kSmallAngleJacobian = 1e-3;
constexpr double kSmallAngleJacobianInv = 1e-2;

// sin(theta) / theta.
double sinc(double theta) {
  const double t2 = theta * theta;
  if (theta < kSmallAngleExp) return 1.0 - t2 / 6.0 + t2 * t2 / 120.0;
  return std::sin(theta) / theta;
}

// (1 - cos(theta)) / theta^2, written as 2 sin^2(theta/2) / theta^2 to avoid cancellation.
double one_minus_cos_over_t2(double theta) {
  const double t2 = theta * theta;
  if (theta < kSmallAngleExp) return 0.5 - t2 / 24.0 + t2 * t2 / 720.0;
  const double s = std::sin(0.5 * theta);
  return 2.0 * s * s / t2;
}

// (theta - sin(theta)) / theta^3.
double theta_minus_sin_over_t3(double theta) {
  const double t2 = theta * theta;
  if (theta < kSmallAngleJacobian) return 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0;
  return (theta - std::sin(theta)) / (t2 * theta);
}

// 1/theta^2 - (1 + cos(theta)) / (2 theta sin(theta)) = (1 - (theta/2) cot(theta/2)) / theta^2;
// the cot form is finite at theta = pi.
double jacobian_inv_coeff(double theta) {
  const double t2 = theta * theta;
  if (theta < kSmallAngleJacobianInv) return 1.0 / 12.0 + t2 / 720.0 + t2 * t2 / 30240.0;
  const double half = 0.5 * theta;
  return (1.0 - half * std::cos(half) / std::sin(half)) / t2;
}

// Log of a unit quaternion with w >= 0 enforced: angle = 2 atan2(|v|, w) in [0, pi].
Vec3 quat_log(Quat q) {
  q.normalize();
  if (q.w() < 0.0) q.coeffs() = -q.coeffs();
  const Vec3 v = q.vec();
  const double n = v.norm();
  const double w = q.w();
  if (n < 1e-8 * w) {
    // theta / n = 2 atan(n/w) / n = (2/w) (1 - n^2/(3 w^2) + ...); the n^2 term is below 1e-16.
    return (2.0 / w) * (1.0 - n * n / (3.0 * w * w)) * v;
  }
  const double theta = 2.0 * std::atan2(n, w);
  return (theta / n) * v;
}

}  // namespace

Mat3 hat(const Vec3& w) {
  Mat3 W;
  W << 0.0, -w.z(), w.y(),
       w.z(), 0.0, -w.x(),
       -w.y(), w.x(), 0.0;
  return W;
}

Vec3 vee(const Mat3& W) {
  return Vec3(0.5 * (W(2, 1) - W(1, 2)), 0.5 * (W(0, 2) - W(2, 0)), 0.5 * (W(1, 0) - W(0, 1)));
}

Mat3 so3_exp(const Vec3& phi) {
  const double theta = phi.norm();
  const Mat3 W = hat(phi);
  return Mat3::Identity() + sinc(theta) * W + one_minus_cos_over_t2(theta) * (W * W);
}

Quat so3_exp_quat(const Vec3& phi) {
  const double theta = phi.norm();
  const double half = 0.5 * theta;
  // sin(theta/2) / theta = 0.5 * sinc(theta/2).
  const Vec3 v = 0.5 * sinc(half) * phi;
  return Quat(std::cos(half), v.x(), v.y(), v.z());
}

Vec3 so3_log(const Mat3& R) {
  // Eigen's matrix-to-quaternion conversion is Shepperd's method: when the trace is small (angle
  // near pi) it takes the axis from the largest diagonal entry of the symmetric part of R, so the
  // quaternion, and with it the logarithm, is accurate at every angle.
  return quat_log(Quat(R));
}

Vec3 so3_log(const Quat& q) { return quat_log(q); }

Mat3 so3_right_jacobian(const Vec3& phi) {
  const double theta = phi.norm();
  const Mat3 W = hat(phi);
  return Mat3::Identity() - one_minus_cos_over_t2(theta) * W + theta_minus_sin_over_t3(theta) * (W * W);
}

Mat3 so3_right_jacobian_inv(const Vec3& phi) {
  const double theta = phi.norm();
  const Mat3 W = hat(phi);
  return Mat3::Identity() + 0.5 * W + jacobian_inv_coeff(theta) * (W * W);
}

Mat3 so3_left_jacobian(const Vec3& phi) { return so3_right_jacobian(-phi); }

Mat3 so3_left_jacobian_inv(const Vec3& phi) { return so3_right_jacobian_inv(-phi); }

Quat so3_interpolate(const Quat& q0, const Quat& q1, double s) {
  const Quat n0 = q0.normalized();
  const Vec3 delta = so3_log(n0.conjugate() * q1.normalized());
  return (n0 * so3_exp_quat(s * delta)).normalized();
}

SE3 SE3::from_matrix(const Eigen::Matrix4d& T) {
  return SE3(Mat3(T.topLeftCorner<3, 3>()), Vec3(T.topRightCorner<3, 1>()));
}

SE3 SE3::inverse() const {
  const Quat q_inv = rotation.conjugate();
  return SE3(q_inv, -(q_inv * translation));
}

SE3 SE3::operator*(const SE3& o) const {
  return SE3(rotation * o.rotation, rotation * o.translation + translation);
}

Eigen::Matrix4d SE3::matrix() const {
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T.topLeftCorner<3, 3>() = rotation_matrix();
  T.topRightCorner<3, 1>() = translation;
  return T;
}

SE3 se3_exp(const Vec6& xi) {
  const Vec3 rho = xi.head<3>();
  const Vec3 phi = xi.tail<3>();
  return SE3(so3_exp_quat(phi), so3_left_jacobian(phi) * rho);
}

Vec6 se3_log(const SE3& T) {
  const Vec3 phi = so3_log(T.rotation);
  Vec6 xi;
  xi.head<3>() = so3_left_jacobian_inv(phi) * T.translation;
  xi.tail<3>() = phi;
  return xi;
}

SE3 se3_interpolate(const SE3& a, const SE3& b, double s) {
  return SE3(so3_interpolate(a.rotation, b.rotation, s), (1.0 - s) * a.translation + s * b.translation);
}

}  // namespace evio::calib
