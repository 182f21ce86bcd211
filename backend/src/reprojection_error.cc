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

namespace evio::backend {

RotationOnlyError::RotationOnlyError(const Eigen::Vector3d& bearing_i, const Eigen::Vector3d& bearing_j,
                                     const calib::SE3& T_c_b, double focal_px, double sigma_px)
    : R_c_b_(T_c_b.rotation.toRotationMatrix()) {
  if (!bearing_i.allFinite() || !(bearing_j.z() > 1e-9) || !bearing_j.allFinite()) {
    throw std::invalid_argument("rotation-only error: bearings must be finite, the second with z > 0");
  }
  if (!(focal_px > 0) || !(sigma_px > 0) || !std::isfinite(focal_px) || !std::isfinite(sigma_px)) {
    throw std::invalid_argument("rotation-only error: focal_px and sigma_px must be finite and > 0");
  }
  b_i_b_ = R_c_b_.transpose() * bearing_i.normalized();
  measurement_ = bearing_j.head<2>() / bearing_j.z();
  scale_ = focal_px / sigma_px;
}

StaticCentreError::StaticCentreError(const calib::SE3& T_c_b, double sigma_m)
    : StaticCentreError(Eigen::Vector3d(-(T_c_b.rotation.conjugate() * T_c_b.translation)), sigma_m) {}

StaticCentreError::StaticCentreError(const Eigen::Vector3d& c_b, double sigma_m) : c_b_(c_b), inv_sigma_(1.0 / sigma_m) {}

bool StaticCentreError::Evaluate(double const* const* parameters, double* residuals, double** jacobians) const {
  const Eigen::Matrix3d R_i = Eigen::Map<const Eigen::Quaterniond>(parameters[0]).normalized().toRotationMatrix();
  const Eigen::Matrix3d R_j = Eigen::Map<const Eigen::Quaterniond>(parameters[1]).normalized().toRotationMatrix();
  const Eigen::Map<const Eigen::Vector3d> p_i(parameters[0] + 4), p_j(parameters[1] + 4);
  Eigen::Map<Eigen::Vector3d> r(residuals);
  r = inv_sigma_ * (p_j + R_j * c_b_ - p_i - R_i * c_b_);
  if (jacobians == nullptr) return true;
  // Tangent [dtheta (body), dp (world)]: R Exp(dtheta) c = R c - R [c]x dtheta.
  if (jacobians[0] != nullptr) {
    Eigen::Matrix<double, 3, 6> J;
    J.leftCols<3>() = inv_sigma_ * R_i * calib::hat(c_b_);
    J.rightCols<3>() = -inv_sigma_ * Eigen::Matrix3d::Identity();
    Eigen::Map<Eigen::Matrix<double, 3, 7, Eigen::RowMajor>> out(jacobians[0]);
    out = J * PoseManifold::minus_jacobian(parameters[0]);
  }
  if (jacobians[1] != nullptr) {
    Eigen::Matrix<double, 3, 6> J;
    J.leftCols<3>() = -inv_sigma_ * R_j * calib::hat(c_b_);
    J.rightCols<3>() = inv_sigma_ * Eigen::Matrix3d::Identity();
    Eigen::Map<Eigen::Matrix<double, 3, 7, Eigen::RowMajor>> out(jacobians[1]);
    out = J * PoseManifold::minus_jacobian(parameters[1]);
  }
  return true;
}

bool RotationOnlyError::Evaluate(double const* const* parameters, double* residuals, double** jacobians) const {
  const Eigen::Matrix3d R_i = Eigen::Map<const Eigen::Quaterniond>(parameters[0]).normalized().toRotationMatrix();
  const Eigen::Matrix3d R_j = Eigen::Map<const Eigen::Quaterniond>(parameters[1]).normalized().toRotationMatrix();
  const Eigen::Vector3d w = R_j.transpose() * R_i * b_i_b_;  // in body j
  const Eigen::Vector3d u = R_c_b_ * w;                      // in camera j
  if (!(u.z() > 1e-6)) return false;
  const double iz = 1.0 / u.z();
  Eigen::Map<Eigen::Vector2d> r(residuals);
  r = scale_ * (Eigen::Vector2d(u.x() * iz, u.y() * iz) - measurement_);
  if (jacobians == nullptr) return true;
  Eigen::Matrix<double, 2, 3> d_pi;
  d_pi << iz, 0, -u.x() * iz * iz, 0, iz, -u.y() * iz * iz;
  const Eigen::Matrix<double, 2, 3> d_r_d_u = scale_ * d_pi;
  if (jacobians[0] != nullptr) {
    // R_i Exp(d): u = R_c_b R_j^T R_i (I + [d]x) b  ->  du/dd = -R_c_b R_j^T R_i [b]x
    Eigen::Matrix<double, 2, 6> J = Eigen::Matrix<double, 2, 6>::Zero();
    J.leftCols<3>() = -d_r_d_u * R_c_b_ * R_j.transpose() * R_i * calib::hat(b_i_b_);
    Eigen::Map<Eigen::Matrix<double, 2, 7, Eigen::RowMajor>> out(jacobians[0]);
    out = J * PoseManifold::minus_jacobian(parameters[0]);
  }
  if (jacobians[1] != nullptr) {
    // R_j Exp(d): u = R_c_b Exp(-d) w  ->  du/dd = R_c_b [w]x
    Eigen::Matrix<double, 2, 6> J = Eigen::Matrix<double, 2, 6>::Zero();
    J.leftCols<3>() = d_r_d_u * R_c_b_ * calib::hat(w);
    Eigen::Map<Eigen::Matrix<double, 2, 7, Eigen::RowMajor>> out(jacobians[1]);
    out = J * PoseManifold::minus_jacobian(parameters[1]);
  }
  return true;
}

TimeOffsetReprojectionError::TimeOffsetReprojectionError(const Eigen::Vector3d& bearing_c, const Eigen::Vector2d& velocity,
                                                         const calib::SE3& T_c_b, double focal_px, double sigma_px)
    : reprojection_(bearing_c, T_c_b, focal_px, sigma_px), velocity_(velocity), scale_(focal_px / sigma_px) {
  if (!velocity.allFinite()) throw std::invalid_argument("time-offset reprojection error: velocity must be finite");
}

bool TimeOffsetReprojectionError::Evaluate(double const* const* parameters, double* residuals, double** jacobians) const {
  double* base_jacobians[2] = {jacobians ? jacobians[0] : nullptr, jacobians ? jacobians[1] : nullptr};
  if (!reprojection_.Evaluate(parameters, residuals, jacobians ? base_jacobians : nullptr)) return false;
  const double td = parameters[2][0];
  residuals[0] += scale_ * td * velocity_.x();
  residuals[1] += scale_ * td * velocity_.y();
  if (jacobians && jacobians[2]) {
    jacobians[2][0] = scale_ * velocity_.x();
    jacobians[2][1] = scale_ * velocity_.y();
  }
  return true;
}

RelativeRotationError::RelativeRotationError(const Eigen::Quaterniond& R_ci_cj, const Eigen::Matrix3d& cov_c,
                                             const calib::SE3& T_c_b) {
  const Eigen::Matrix3d R_c_b = T_c_b.rotation.toRotationMatrix();
  dR_ = R_c_b.transpose() * R_ci_cj.normalized().toRotationMatrix() * R_c_b;
  const Eigen::Matrix3d cov_b = R_c_b.transpose() * cov_c * R_c_b;
  const Eigen::LLT<Eigen::Matrix3d> llt(cov_b.inverse());
  if (!cov_c.allFinite() || !R_ci_cj.coeffs().allFinite() || llt.info() != Eigen::Success || !(cov_c.determinant() > 0))
    throw std::invalid_argument("relative rotation error: the rotation must be finite and the covariance positive definite");
  S_ = llt.matrixU();
}

Eigen::Vector3d RelativeRotationError::error(const double* pose_i, const double* pose_j) const {
  const Eigen::Matrix3d R_i = Eigen::Map<const Eigen::Quaterniond>(pose_i).normalized().toRotationMatrix();
  const Eigen::Matrix3d R_j = Eigen::Map<const Eigen::Quaterniond>(pose_j).normalized().toRotationMatrix();
  return calib::so3_log(Eigen::Matrix3d(dR_.transpose() * R_i.transpose() * R_j));
}

bool RelativeRotationError::Evaluate(double const* const* parameters, double* residuals, double** jacobians) const {
  const Eigen::Matrix3d R_i = Eigen::Map<const Eigen::Quaterniond>(parameters[0]).normalized().toRotationMatrix();
  const Eigen::Matrix3d R_j = Eigen::Map<const Eigen::Quaterniond>(parameters[1]).normalized().toRotationMatrix();
  const Eigen::Matrix3d R_ij = R_i.transpose() * R_j;
  const Eigen::Vector3d e = calib::so3_log(Eigen::Matrix3d(dR_.transpose() * R_ij));
  Eigen::Map<Eigen::Vector3d> r(residuals);
  r = S_ * e;
  if (jacobians == nullptr) return true;
  const Eigen::Matrix3d Jr_inv = calib::so3_right_jacobian_inv(e);
  if (jacobians[0] != nullptr) {
    // R_i Exp(d): dR^T Exp(-d) R_ij = dR^T R_ij Exp(-R_ij^T d)  ->  de/dd = -Jr^-1(e) R_ij^T
    Eigen::Matrix<double, 3, 6> J = Eigen::Matrix<double, 3, 6>::Zero();
    J.leftCols<3>() = -S_ * Jr_inv * R_ij.transpose();
    Eigen::Map<Eigen::Matrix<double, 3, 7, Eigen::RowMajor>> out(jacobians[0]);
    out = J * PoseManifold::minus_jacobian(parameters[0]);
  }
  if (jacobians[1] != nullptr) {
    // R_j Exp(d): de/dd = Jr^-1(e)
    Eigen::Matrix<double, 3, 6> J = Eigen::Matrix<double, 3, 6>::Zero();
    J.leftCols<3>() = S_ * Jr_inv;
    Eigen::Map<Eigen::Matrix<double, 3, 7, Eigen::RowMajor>> out(jacobians[1]);
    out = J * PoseManifold::minus_jacobian(parameters[1]);
  }
  return true;
}

}  // namespace evio::backend
