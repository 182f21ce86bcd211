// Reference angular velocities for evaluating per-window rotation estimates (e.g. contrast
// maximisation's, `evio flow --model rotation`): the mean angular velocity of a pose trajectory
// over a window, or the mean of the gyro's samples in it, both turned into the camera frame with
// R_c_b (w_c = R_c_b w_b; w_b the body's angular velocity in its own frame, R_w_b' = R_w_b [w_b]x)
// and read on the body's clock (t_body = t_cam + time_shift, Kalibr's timeshift_cam_imu).
// The trajectory's rate is not Log(R(t0)^T R(t1)) / (t1 - t0) between interpolated poses: a window
// shorter than the pose period then gets the mean rate of the pose interval around it (slerp is
// constant-rate), off by the angular acceleration times up to half a pose period (2.4 deg/s at
// 17 rad/s^2 and 200 Hz poses). Instead the rate at each pose k is the central difference
// Log(R_{k-1}^T R_{k+1}) / (t_{k+1} - t_{k-1}) (second order, at the middle of t_{k-1}, t_{k+1}), and
// the window's mean is that of the piecewise-linear rate over the window. Errors in deg/s.
#pragma once

#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "evio/sensors/measurements.h"
#include "evio/sensors/trajectory.h"

namespace evio::evaluation {

// How the body frame of the references relates to the camera: R_c_b and the clock offset.
struct BodyToCamera {
  Eigen::Matrix3d R_c_b = Eigen::Matrix3d::Identity();
  int64_t time_shift_ns = 0;  // t_body = t_cam + time_shift_ns
};

// Mean angular velocity of the trajectory over the camera-time window [t0_ns, t1_ns], in the camera
// frame, rad/s (t1 == t0: the rate at t0); nullopt when the central differences do not cover the
// window (it must lie between the second and the second-to-last pose) or t1 < t0.
std::optional<Eigen::Vector3d> trajectory_angular_velocity(const Trajectory& T_w_b, int64_t t0_ns, int64_t t1_ns,
                                                            const BodyToCamera& b2c = {});

// Mean of the gyro samples (time-ordered) within the camera-time window, in the camera frame, rad/s;
// when none falls inside, the gyro interpolated at the window's middle; nullopt when the samples do
// not reach the window.
std::optional<Eigen::Vector3d> mean_gyro(const std::vector<ImuSample>& imu, int64_t t0_ns, int64_t t1_ns,
                                         const BodyToCamera& b2c = {});

// Error statistics of estimates against references (pairs with both finite).
struct AngularVelocityErrors {
  size_t count = 0;
  double rms_degps = 0;             // RMS of |w_est - w_ref|, deg/s
  Eigen::Vector3d rms_axis_degps = Eigen::Vector3d::Zero();  // RMS per camera axis, deg/s
  double max_degps = 0;             // largest |w_est - w_ref|, deg/s
  double median_degps = 0;          // median |w_est - w_ref|, deg/s
  double reference_rms_degps = 0;   // RMS of |w_ref|, deg/s
  double relative_rms = 0;          // rms_degps / reference_rms_degps (0 when the reference is 0)
};
AngularVelocityErrors angular_velocity_errors(const std::vector<Eigen::Vector3d>& estimate,
                                              const std::vector<Eigen::Vector3d>& reference);

}  // namespace evio::evaluation
