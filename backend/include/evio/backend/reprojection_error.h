// Reprojection residual of a world landmark in a keyframe, on the undistorted normalised image
// plane scaled to pixels: r = (f / sigma) (pi(p_c) - pi(b)), pi(x) = (x/z, y/z), with
//   p_c = R_c_b R_w_b^T (p_w - p_w_b) + t_c_b
// the landmark in the camera, b the observed unit bearing (z > 0) and f the focal length (px), so a
// residual of 1 is one pixel-sigma of undistorted image error. Parameter blocks: pose T_w_b
// (7, PoseManifold, ambient columns = J_tangent * PoseManifold::minus_jacobian) and landmark p_w
// (3, m). Evaluate returns false for a landmark at depth <= 1e-6 m (Ceres then shortens the step).
#pragma once

#include <Eigen/Core>

#include "ceres/sized_cost_function.h"
#include "evio/calib/geometry.h"

namespace evio::backend {

class ReprojectionError final : public ceres::SizedCostFunction<2, 7, 3> {
 public:
  // bearing_c: observed unit bearing (z > 0); focal_px > 0; sigma_px > 0. Throws
  // std::invalid_argument otherwise.
  ReprojectionError(const Eigen::Vector3d& bearing_c, const calib::SE3& T_c_b, double focal_px, double sigma_px);

  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override;

  // Landmark in the camera frame for a pose block and a landmark block.
  Eigen::Vector3d point_in_camera(const double* pose, const double* landmark) const;

 private:
  Eigen::Vector2d measurement_;  // pi(b)
  Eigen::Matrix3d R_c_b_;
  Eigen::Vector3d t_c_b_;
  double scale_;                 // f / sigma
};

}  // namespace evio::backend

namespace evio::backend {

// ReprojectionError with an unknown camera-IMU time offset td (s, parameter block of size 1, in the
// sense of Kalibr's timeshift_cam_imu: a correction added to the calibrated shift). The observation
// stamped t shows the scene at t + td, so at t the feature was where it was seen minus td times its
// image velocity v (undistorted normalised plane, 1/s; from the track's previous frame), as in
// VINS-Mono's online temporal calibration (Qin and Shen, IROS 2018):
//   r = (f / sigma) (pi(p_c) - (pi(b) - td v)).
// Parameter blocks: pose (7), landmark (3), td (1).
class TimeOffsetReprojectionError final : public ceres::SizedCostFunction<2, 7, 3, 1> {
 public:
  // As ReprojectionError; velocity: finite. Throws std::invalid_argument otherwise.
  TimeOffsetReprojectionError(const Eigen::Vector3d& bearing_c, const Eigen::Vector2d& velocity, const calib::SE3& T_c_b,
                              double focal_px, double sigma_px);
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override;

 private:
  ReprojectionError reprojection_;
  Eigen::Vector2d velocity_;
  double scale_;  // f / sigma
};

// Rotation-only residual between two keyframes observing the same (untriangulated) track, for
// motion without parallax: the bearing of keyframe i, rotated into keyframe j's camera by the
// relative rotation of the two poses (translation ignored: landmarks at infinity), against the
// bearing observed in j, on the undistorted image plane in pixel sigmas:
//   r = (f / sigma) (pi(R_c_b R_w_bj^T R_w_bi R_b_c b_i) - pi(b_j)).
// Parameter blocks: pose_i, pose_j (7, PoseManifold); the position columns are zero.
class RotationOnlyError final : public ceres::SizedCostFunction<2, 7, 7> {
 public:
  RotationOnlyError(const Eigen::Vector3d& bearing_i, const Eigen::Vector3d& bearing_j, const calib::SE3& T_c_b,
                    double focal_px, double sigma_px);
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override;

 private:
  Eigen::Vector3d b_i_b_;        // R_b_c b_i
  Eigen::Vector2d measurement_;  // pi(b_j)
  Eigen::Matrix3d R_c_b_;
  double scale_;
};

// A rotation in place between two keyframes (the rotation-only model): its centre does not move,
// r = (p_j + R_j c - p_i - R_i c) / sigma_m with c the centre in the body frame (the camera centre
// of T_c_b, or a given point such as the IMU origin),
// so the IMU alone does not carry the position away while no landmark can be triangulated.
// Parameters: the two poses [qx qy qz qw px py pz] (PoseManifold). 3 residuals.
class StaticCentreError final : public ceres::SizedCostFunction<3, 7, 7> {
 public:
  StaticCentreError(const calib::SE3& T_c_b, double sigma_m);
  // Any body-frame point c instead of the camera centre (e.g. the IMU origin, c = 0).
  StaticCentreError(const Eigen::Vector3d& c_b, double sigma_m);
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override;

 private:
  Eigen::Vector3d c_b_;  // the static point in the body frame (the camera centre by default)
  double inv_sigma_;
};

// A relative-rotation measurement between two keyframes (a rotation tracker's orientations of
// the camera against its panorama at both times, issue 37): with the body-frame measurement
// dR = R_b_c R_ci_cj R_c_b,
//   r = S Log(dR^T R_w_bi^T R_w_bj),
// S the upper Cholesky factor of the inverse covariance of Log (body frame j tangent, rad^2).
// Parameters: the two poses (7, PoseManifold); the position columns are zero.
class RelativeRotationError final : public ceres::SizedCostFunction<3, 7, 7> {
 public:
  // R_ci_cj: the camera's rotation from i to j; cov_c: its covariance on the right (camera j
  // tangent), symmetric positive definite. Throws std::invalid_argument otherwise.
  RelativeRotationError(const Eigen::Quaterniond& R_ci_cj, const Eigen::Matrix3d& cov_c, const calib::SE3& T_c_b);
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override;
  // The rotation error Log(dR^T R_i^T R_j) (rad, body j) at two poses, unwhitened.
  Eigen::Vector3d error(const double* pose_i, const double* pose_j) const;

 private:
  Eigen::Matrix3d dR_;  // measured body rotation i -> j
  Eigen::Matrix3d S_;   // whitening
};

}  // namespace evio::backend
