// Ceres manifold for a rigid pose T_w_b stored as 7 doubles [qx qy qz qw px py pz] (Eigen
// quaternion coefficient order, then the position in w), tangent [dtheta (rad), dp (m)]:
//   Plus(x, d) = (q * Exp(dtheta), p + dp)          right (body-frame) rotation perturbation
//   Minus(y, x) = (Log(q_x^-1 q_y), p_y - p_x)       the inverse of Plus for ||dtheta|| < 2 pi
// Plus keeps the quaternion's norm (unit in, unit out); Minus normalises q_x^-1 q_y and takes the
// angle 2 atan2(|vec|, w) without sign flip, so Plus(x, Minus(y, x)) = y on the double cover.
// PlusJacobian / MinusJacobian are analytic at d = 0 / y = x; MinusJacobian(x) is the
// pseudo-inverse of PlusJacobian(x) (MinusJacobian * PlusJacobian = I_6, also for non-unit q).
#pragma once

#include "ceres/manifold.h"

#include <Eigen/Core>

namespace evio::backend {

// Layout of a pose parameter block (ambient) and its tangent.
constexpr int kPoseAmbientSize = 7;
constexpr int kPoseTangentSize = 6;
// Layout of a speed-and-bias block: [v_w (m/s), b_g (rad/s), b_a (m/s^2)], Euclidean.
constexpr int kSpeedBiasSize = 9;

class PoseManifold final : public ceres::Manifold {
 public:
  int AmbientSize() const override { return kPoseAmbientSize; }
  int TangentSize() const override { return kPoseTangentSize; }
  bool Plus(const double* x, const double* delta, double* x_plus_delta) const override;
  // 7x6, row-major.
  bool PlusJacobian(const double* x, double* jacobian) const override;
  bool Minus(const double* y, const double* x, double* y_minus_x) const override;
  // 6x7, row-major.
  bool MinusJacobian(const double* x, double* jacobian) const override;

  // The same Jacobians as Eigen matrices (rows/cols as above).
  static Eigen::Matrix<double, 7, 6> plus_jacobian(const double* x);
  static Eigen::Matrix<double, 6, 7> minus_jacobian(const double* x);
};

}  // namespace evio::backend
