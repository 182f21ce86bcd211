#include "evio/backend/imu_error.h"

#include <stdexcept>

#include <Eigen/Cholesky>
#include <Eigen/Geometry>

#include "evio/backend/pose_manifold.h"
#include "evio/calib/geometry.h"

namespace evio::backend {

namespace {

using Mat3 = Eigen::Matrix3d;
using Vec3 = Eigen::Vector3d;

}  // namespace

ImuError::ImuError(const ImuPreintegration& preintegration, const Eigen::Vector3d& gravity_w)
    : pre_(preintegration), g_w_(gravity_w) {
  if (!(pre_.dt_s() > 0)) throw std::invalid_argument("ImuError: preintegration interval must be > 0 s");
  if (!g_w_.allFinite()) throw std::invalid_argument("ImuError: gravity must be finite");
  const double dt = pre_.dt_s();
  const auto& n = pre_.noise();
  covariance_.setZero();
  covariance_.topLeftCorner<9, 9>() = pre_.covariance();
  covariance_.block<3, 3>(9, 9) = n.gyroscope_random_walk * n.gyroscope_random_walk * dt * Mat3::Identity();
  covariance_.block<3, 3>(12, 12) = n.accelerometer_random_walk * n.accelerometer_random_walk * dt * Mat3::Identity();
  const Eigen::LLT<Mat15> llt_cov(covariance_);
  if (llt_cov.info() != Eigen::Success || !covariance_.allFinite())
    throw std::invalid_argument(
        "ImuError: 15x15 covariance is not positive definite (noise densities and random walks must be > 0)");
  Mat15 information = llt_cov.solve(Mat15::Identity());
  information = 0.5 * (information + information.transpose());
  const Eigen::LLT<Mat15> llt_info(information);
  if (llt_info.info() != Eigen::Success)
    throw std::invalid_argument("ImuError: information matrix is not positive definite (ill-conditioned covariance)");
  sqrt_information_ = llt_info.matrixL().transpose();
}

ImuError::Vec15 ImuError::raw_residual(double const* const* parameters) const {
  const Eigen::Quaterniond qi = Eigen::Map<const Eigen::Quaterniond>(parameters[0]).normalized();
  const Eigen::Quaterniond qj = Eigen::Map<const Eigen::Quaterniond>(parameters[2]).normalized();
  const Eigen::Map<const Vec3> pi(parameters[0] + 4), pj(parameters[2] + 4);
  const Eigen::Map<const Vec3> vi(parameters[1]), bgi(parameters[1] + 3), bai(parameters[1] + 6);
  const Eigen::Map<const Vec3> vj(parameters[3]), bgj(parameters[3] + 3), baj(parameters[3] + 6);
  const double dt = pre_.dt_s();
  const Mat3 RiT = qi.toRotationMatrix().transpose();
  Vec15 r;
  const Eigen::Quaterniond dq_c = pre_.corrected_delta_q(bgi);
  r.segment<3>(0) = calib::so3_log(dq_c.conjugate() * qi.conjugate() * qj);
  r.segment<3>(3) = RiT * (vj - vi - g_w_ * dt) - pre_.corrected_delta_v(bgi, bai);
  r.segment<3>(6) = RiT * (pj - pi - vi * dt - 0.5 * g_w_ * dt * dt) - pre_.corrected_delta_p(bgi, bai);
  r.segment<3>(9) = bgj - bgi;
  r.segment<3>(12) = baj - bai;
  return r;
}

bool ImuError::Evaluate(double const* const* parameters, double* residuals, double** jacobians) const {
  const Vec15 r = raw_residual(parameters);
  Eigen::Map<Vec15> res(residuals);
  res = sqrt_information_ * r;
  if (jacobians == nullptr) return true;

  const Eigen::Quaterniond qi = Eigen::Map<const Eigen::Quaterniond>(parameters[0]).normalized();
  const Eigen::Quaterniond qj = Eigen::Map<const Eigen::Quaterniond>(parameters[2]).normalized();
  const Eigen::Map<const Vec3> pi(parameters[0] + 4), pj(parameters[2] + 4);
  const Eigen::Map<const Vec3> vi(parameters[1]), bgi(parameters[1] + 3);
  const Eigen::Map<const Vec3> vj(parameters[3]);
  const double dt = pre_.dt_s();
  const Mat3 Ri = qi.toRotationMatrix();
  const Mat3 Rj = qj.toRotationMatrix();
  const Mat3 RiT = Ri.transpose();
  const Vec3 r_R = r.segment<3>(0);
  const Mat3 Jr_inv = calib::so3_right_jacobian_inv(r_R);
  const Mat3 E = calib::so3_exp(r_R);
  const Mat3 J_R_bg = pre_.d_R_d_bg();
  const Vec3 dbg = bgi - pre_.bias_gyro();
  const Vec3 dv_w = vj - vi - g_w_ * dt;
  const Vec3 dp_w = pj - pi - vi * dt - 0.5 * g_w_ * dt * dt;

  using Mat15x6 = Eigen::Matrix<double, 15, 6>;
  using Mat15x9 = Eigen::Matrix<double, 15, 9>;
  if (jacobians[0] != nullptr) {
    Mat15x6 J = Mat15x6::Zero();
    J.block<3, 3>(0, 0) = -Jr_inv * Rj.transpose() * Ri;
    J.block<3, 3>(3, 0) = calib::hat(RiT * dv_w);
    J.block<3, 3>(6, 0) = calib::hat(RiT * dp_w);
    J.block<3, 3>(6, 3) = -RiT;
    Eigen::Map<Eigen::Matrix<double, 15, 7, Eigen::RowMajor>> Ja(jacobians[0]);
    Ja = sqrt_information_ * J * PoseManifold::minus_jacobian(parameters[0]);
  }
  if (jacobians[1] != nullptr) {
    Mat15x9 J = Mat15x9::Zero();
    J.block<3, 3>(0, 3) = -Jr_inv * E.transpose() * calib::so3_right_jacobian(J_R_bg * dbg) * J_R_bg;
    J.block<3, 3>(3, 0) = -RiT;
    J.block<3, 3>(3, 3) = -pre_.d_v_d_bg();
    J.block<3, 3>(3, 6) = -pre_.d_v_d_ba();
    J.block<3, 3>(6, 0) = -RiT * dt;
    J.block<3, 3>(6, 3) = -pre_.d_p_d_bg();
    J.block<3, 3>(6, 6) = -pre_.d_p_d_ba();
    J.block<3, 3>(9, 3) = -Mat3::Identity();
    J.block<3, 3>(12, 6) = -Mat3::Identity();
    Eigen::Map<Eigen::Matrix<double, 15, 9, Eigen::RowMajor>> Ja(jacobians[1]);
    Ja = sqrt_information_ * J;
  }
  if (jacobians[2] != nullptr) {
    Mat15x6 J = Mat15x6::Zero();
    J.block<3, 3>(0, 0) = Jr_inv;
    J.block<3, 3>(6, 3) = RiT;
    Eigen::Map<Eigen::Matrix<double, 15, 7, Eigen::RowMajor>> Ja(jacobians[2]);
    Ja = sqrt_information_ * J * PoseManifold::minus_jacobian(parameters[2]);
  }
  if (jacobians[3] != nullptr) {
    Mat15x9 J = Mat15x9::Zero();
    J.block<3, 3>(3, 0) = RiT;
    J.block<3, 3>(9, 3) = Mat3::Identity();
    J.block<3, 3>(12, 6) = Mat3::Identity();
    Eigen::Map<Eigen::Matrix<double, 15, 9, Eigen::RowMajor>> Ja(jacobians[3]);
    Ja = sqrt_information_ * J;
  }
  return true;
}

}  // namespace evio::backend
