#include "evio/backend/reprojection_error.h"

#include <cmath>
#include <stdexcept>

#include "evio/backend/pose_manifold.h"

namespace evio::backend {

ReprojectionError::ReprojectionError(const Eigen::Vector3d& bearing_c, const calib::SE3& T_c_b, double focal_px,
                                     double sigma_px)
    : R_c_b_(T_c_b.rotation.toRotationMatrix()), t_c_b_(T_c_b.translation) {
  if (!(bearing_c.z() > 1e-9) || !bearing_c.allFinite()) {
    throw std::invalid_argument("reprojection error: bearing must be finite with z > 0");
  }
  if (!(focal_px > 0) || !(sigma_px > 0) || !std::isfinite(focal_px) || !std::isfinite(sigma_px)) {
    throw std::invalid_argument("reprojection error: focal_px and sigma_px must be finite and > 0");
  }
  measurement_ = bearing_c.head<2>() / bearing_c.z();
  scale_ = focal_px / sigma_px;
}

Eigen::Vector3d ReprojectionError::point_in_camera(const double* pose, const double* landmark) const {
  const Eigen::Map<const Eigen::Quaterniond> q(pose);
  const Eigen::Map<const Eigen::Vector3d> p(pose + 4);
  const Eigen::Map<const Eigen::Vector3d> l(landmark);
  return R_c_b_ * (q.conjugate() * (l - p)) + t_c_b_;
}

bool ReprojectionError::Evaluate(double const* const* parameters, double* residuals, double** jacobians) const {
  const Eigen::Map<const Eigen::Quaterniond> q(parameters[0]);
  const Eigen::Map<const Eigen::Vector3d> p(parameters[0] + 4);
  const Eigen::Map<const Eigen::Vector3d> l(parameters[1]);
  // Quaternion blocks are kept unit by the manifold; normalise for robustness to drift.
  const Eigen::Matrix3d R_w_b = q.normalized().toRotationMatrix();
  const Eigen::Vector3d p_b = R_w_b.transpose() * (l - p);
  const Eigen::Vector3d p_c = R_c_b_ * p_b + t_c_b_;
  if (!(p_c.z() > 1e-6)) return false;
  const double iz = 1.0 / p_c.z();
  Eigen::Map<Eigen::Vector2d> r(residuals);
  r = scale_ * (Eigen::Vector2d(p_c.x() * iz, p_c.y() * iz) - measurement_);
  if (jacobians == nullptr) return true;
  Eigen::Matrix<double, 2, 3> d_pi;
  d_pi << iz, 0, -p_c.x() * iz * iz, 0, iz, -p_c.y() * iz * iz;
  const Eigen::Matrix<double, 2, 3> d_r_d_pb = scale_ * d_pi * R_c_b_;
  if (jacobians[0] != nullptr) {
    // p_b(R Exp(dtheta), p + dp) = Exp(-dtheta) R^T (l - p - dp) ~ p_b + [p_b]x dtheta - R^T dp.
    Eigen::Matrix<double, 2, 6> J_tangent;
    J_tangent.leftCols<3>() = d_r_d_pb * calib::hat(p_b);
    J_tangent.rightCols<3>() = -d_r_d_pb * R_w_b.transpose();
    Eigen::Map<Eigen::Matrix<double, 2, 7, Eigen::RowMajor>> J(jacobians[0]);
    J = J_tangent * PoseManifold::minus_jacobian(parameters[0]);
  }
  if (jacobians[1] != nullptr) {
    Eigen::Map<Eigen::Matrix<double, 2, 3, Eigen::RowMajor>> J(jacobians[1]);
    J = d_r_d_pb * R_w_b.transpose();
  }
  return true;
}

}  // namespace evio::backend
