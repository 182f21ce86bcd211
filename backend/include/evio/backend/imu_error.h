// IMU residual between two keyframe states from a preintegrated measurement (Forster et al.,
// T-RO 2017, eq. 45 with first-order bias correction, plus the bias random walk).
//
// Parameter blocks (in this order): pose_i (7: [qx qy qz qw px py pz] of T_w_b, PoseManifold),
// speed_bias_i (9: [v_w, b_g, b_a], Euclidean), pose_j (7), speed_bias_j (9).
// Residual r = S * [r_R, r_v, r_p, r_bg, r_ba] with, for db_g = b_g_i - b_g_lin, db_a = b_a_i - b_a_lin,
//   r_R  = Log( (dR Exp(J_R_bg db_g))^T R_i^T R_j )
//   r_v  = R_i^T (v_j - v_i - g_w dt) - (dv + J_v_bg db_g + J_v_ba db_a)
//   r_p  = R_i^T (p_j - p_i - v_i dt - 0.5 g_w dt^2) - (dp + J_p_bg db_g + J_p_ba db_a)
//   r_bg = b_g_j - b_g_i,   r_ba = b_a_j - b_a_i
// g_w is gravity in the world frame (the simulator's convention, evio::simulator::ImuSimOptions:
// g_w = (0, 0, -9.81) m/s^2 and accel = R_w_b^T (a_w - g_w), so a body at rest measures +9.81 on z).
// S is the upper Cholesky factor of the information (S^T S = Sigma^-1) of the 15x15 covariance
// Sigma = blockdiag(preintegration covariance (9x9), sigma_bgw^2 dt I, sigma_baw^2 dt I) with the
// Kalibr random-walk densities.
// Jacobians are analytic in the tangent space of each block (PoseManifold: right rotation
// perturbation, additive position). The 7 ambient pose columns returned to Ceres are
// J_tangent * PoseManifold::minus_jacobian(x) (the pseudo-inverse of PlusJacobian), so that
// J_ambient * PlusJacobian(x) = J_tangent exactly: use this cost only with PoseManifold on the poses.
#pragma once

#include <Eigen/Core>

#include "ceres/sized_cost_function.h"
#include "evio/backend/imu_preintegration.h"

namespace evio::backend {

class ImuError final : public ceres::SizedCostFunction<15, 7, 9, 7, 9> {
 public:
  using Mat15 = Eigen::Matrix<double, 15, 15>;
  using Vec15 = Eigen::Matrix<double, 15, 1>;

  // Copies the preintegration. Throws std::invalid_argument when dt <= 0, gravity is not finite or
  // the 15x15 covariance is not positive definite (e.g. zero random walks).
  ImuError(const ImuPreintegration& preintegration, const Eigen::Vector3d& gravity_w);

  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override;

  // Unwhitened residual [r_R, r_v, r_p, r_bg, r_ba] (units rad, m/s, m, rad/s, m/s^2).
  Vec15 raw_residual(double const* const* parameters) const;

  const Mat15& covariance() const { return covariance_; }
  const Mat15& sqrt_information() const { return sqrt_information_; }
  const ImuPreintegration& preintegration() const { return pre_; }

 private:
  ImuPreintegration pre_;
  Eigen::Vector3d g_w_;
  Mat15 covariance_;
  Mat15 sqrt_information_;
};

}  // namespace evio::backend
