#include "evio/backend/pose_manifold.h"

#include <cmath>

#include <Eigen/Geometry>

#include "evio/calib/geometry.h"

namespace evio::backend {

namespace {

// Log of a (not necessarily unit) quaternion without folding the angle into [0, pi]:
// 2 atan2(|v|, w) * v / |v|, so Exp(Log(q)) = q / |q| exactly on the double cover.
Eigen::Vector3d quat_log_no_flip(const Eigen::Quaterniond& q_in) {
  const Eigen::Quaterniond q = q_in.normalized();
  const Eigen::Vector3d v = q.vec();
  const double s = v.norm();
  const double w = q.w();
  if (s == 0.0) return Eigen::Vector3d::Zero();  // q = +-1 (for -1 a 2 pi turn: not representable)
  if (s < 1e-8 && w > 0) {
    // atan2(s, w) / s = (1/w) (1 - s^2 / (3 w^2) + ...)
    return 2.0 * v / w * (1.0 - s * s / (3.0 * w * w));
  }
  return 2.0 * std::atan2(s, w) / s * v;
}

}  // namespace

bool PoseManifold::Plus(const double* x, const double* delta, double* x_plus_delta) const {
  const Eigen::Map<const Eigen::Quaterniond> q(x);
  const Eigen::Map<const Eigen::Vector3d> p(x + 4);
  const Eigen::Map<const Eigen::Vector3d> dtheta(delta);
  const Eigen::Map<const Eigen::Vector3d> dp(delta + 3);
  Eigen::Map<Eigen::Quaterniond> q_out(x_plus_delta);
  Eigen::Map<Eigen::Vector3d> p_out(x_plus_delta + 4);
  q_out = q * calib::so3_exp_quat(dtheta);
  p_out = p + dp;
  return true;
}

Eigen::Matrix<double, 7, 6> PoseManifold::plus_jacobian(const double* x) {
  // d(q * Exp(d)) / dd at d = 0 = q (x) [d / 2; 0]: vector rows 0.5 (w I + [u]x), scalar row -0.5 u^T.
  const Eigen::Vector3d u(x[0], x[1], x[2]);
  const double w = x[3];
  Eigen::Matrix<double, 7, 6> J = Eigen::Matrix<double, 7, 6>::Zero();
  J.block<3, 3>(0, 0) = 0.5 * (w * Eigen::Matrix3d::Identity() + calib::hat(u));
  J.block<1, 3>(3, 0) = -0.5 * u.transpose();
  J.block<3, 3>(4, 3).setIdentity();
  return J;
}

Eigen::Matrix<double, 6, 7> PoseManifold::minus_jacobian(const double* x) {
  // d Log(normalize(q_x^* y)) / dy at y = x = 2 / |q|^2 [w I - [u]x, -u] = (P^T P)^-1 P^T for the
  // quaternion block P of PlusJacobian (P^T P = |q|^2 / 4 I).
  const Eigen::Vector3d u(x[0], x[1], x[2]);
  const double w = x[3];
  const double n2 = u.squaredNorm() + w * w;
  Eigen::Matrix<double, 6, 7> J = Eigen::Matrix<double, 6, 7>::Zero();
  J.block<3, 3>(0, 0) = (2.0 / n2) * (w * Eigen::Matrix3d::Identity() - calib::hat(u));
  J.block<3, 1>(0, 3) = (-2.0 / n2) * u;
  J.block<3, 3>(3, 4).setIdentity();
  return J;
}

bool PoseManifold::PlusJacobian(const double* x, double* jacobian) const {
  Eigen::Map<Eigen::Matrix<double, 7, 6, Eigen::RowMajor>> J(jacobian);
  J = plus_jacobian(x);
  return true;
}

bool PoseManifold::Minus(const double* y, const double* x, double* y_minus_x) const {
  const Eigen::Map<const Eigen::Quaterniond> qy(y);
  const Eigen::Map<const Eigen::Quaterniond> qx(x);
  Eigen::Map<Eigen::Vector3d> dtheta(y_minus_x);
  Eigen::Map<Eigen::Vector3d> dp(y_minus_x + 3);
  dtheta = quat_log_no_flip(qx.conjugate() * qy);
  dp = Eigen::Map<const Eigen::Vector3d>(y + 4) - Eigen::Map<const Eigen::Vector3d>(x + 4);
  return true;
}

bool PoseManifold::MinusJacobian(const double* x, double* jacobian) const {
  Eigen::Map<Eigen::Matrix<double, 6, 7, Eigen::RowMajor>> J(jacobian);
  J = minus_jacobian(x);
  return true;
}

}  // namespace evio::backend
