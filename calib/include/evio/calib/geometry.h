// Rotation and rigid-motion helpers on plain Eigen types (Sophus is not packaged in Debian).
// SO(3) exp/log, hat/vee, left/right Jacobians (Barfoot, "State Estimation for Robotics", 2017;
// Forster et al. 2017 for the right Jacobian convention) and SE(3) as (unit quaternion, translation).
// Conventions: perturbations are right-multiplicative, R * Exp(delta); T_a_b maps points from b to a.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace evio::calib {

using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;
using Vec6 = Eigen::Matrix<double, 6, 1>;
using Quat = Eigen::Quaterniond;

// [w]_x such that hat(w) * v = w.cross(v).
Mat3 hat(const Vec3& w);
// Inverse of hat; reads the skew part (W - W^T)/2 so small asymmetric noise is averaged.
Vec3 vee(const Mat3& W);

// Exp: rotation vector (axis * angle, rad) -> rotation. Exact Taylor branch for small angles.
Mat3 so3_exp(const Vec3& phi);
Quat so3_exp_quat(const Vec3& phi);
// Log: rotation -> rotation vector with angle in [0, pi]. Stable at 0 and at pi (axis from the
// symmetric part of R when the angle is near pi).
Vec3 so3_log(const Mat3& R);
Vec3 so3_log(const Quat& q);

// Right Jacobian Jr(phi): Exp(phi + d) ~= Exp(phi) * Exp(Jr(phi) d); left Jl(phi) = Jr(-phi).
Mat3 so3_right_jacobian(const Vec3& phi);
Mat3 so3_right_jacobian_inv(const Vec3& phi);
Mat3 so3_left_jacobian(const Vec3& phi);
Mat3 so3_left_jacobian_inv(const Vec3& phi);

// Geodesic interpolation R0 * Exp(s * Log(R0^T R1)), s in [0, 1] (extrapolates outside).
Quat so3_interpolate(const Quat& q0, const Quat& q1, double s);

// Rigid transform T_a_b: p_a = rotation * p_b + translation. The quaternion is kept normalised.
struct SE3 {
  Quat rotation = Quat::Identity();
  Vec3 translation = Vec3::Zero();

  SE3() = default;
  SE3(const Quat& q, const Vec3& t) : rotation(q.normalized()), translation(t) {}
  SE3(const Mat3& R, const Vec3& t) : rotation(Quat(R).normalized()), translation(t) {}
  static SE3 identity() { return SE3(); }
  // From a 4x4 homogeneous matrix (rotation block re-orthonormalised through the quaternion).
  static SE3 from_matrix(const Eigen::Matrix4d& T);

  SE3 inverse() const;
  SE3 operator*(const SE3& o) const;
  Vec3 operator*(const Vec3& p) const { return rotation * p + translation; }
  Eigen::Matrix4d matrix() const;
  Mat3 rotation_matrix() const { return rotation.toRotationMatrix(); }
};

// SE(3) exp/log with twist xi = (rho [translation part], phi [rotation part]).
SE3 se3_exp(const Vec6& xi);
Vec6 se3_log(const SE3& T);

// Trajectory interpolation between two poses: rotation by so3_interpolate, translation linear
// (the decoupled scheme used by trajectory evaluation tools; s in [0, 1]).
SE3 se3_interpolate(const SE3& a, const SE3& b, double s);

}  // namespace evio::calib
