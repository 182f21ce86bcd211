// Per-window angular-velocity estimates (one per event window, e.g. contrast maximisation's in
// `evio flow --model rotation`) against the references of angular_velocity.h: the ground truth's
// mean rate over each window and the gyro's mean in it, both in the camera frame. A reference that
// does not cover a window (the trajectory's or the gyro's ends) is NaN there, and that window is
// left out of the statistics that use it. Rates in rad/s, errors in deg/s.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "evio/evaluation/angular_velocity.h"
#include "evio/sensors/measurements.h"
#include "evio/sensors/trajectory.h"

namespace evio::evaluation {

// One estimate: the camera's angular velocity over the camera-time window [t_start_ns, t_end_ns].
struct AngularVelocityWindow {
  int64_t t_start_ns = 0, t_end_ns = 0;
  Eigen::Vector3d estimate = Eigen::Vector3d::Zero();  // rad/s, camera frame
};

struct AngularVelocityWindowsEvaluation {
  bool has_groundtruth = false;  // a trajectory was given
  bool has_gyro = false;         // at least two gyro samples were given
  // Per window, in the windows' order: the references, rad/s, camera frame; NaN where there is no
  // such reference or it does not cover the window.
  std::vector<Eigen::Vector3d> groundtruth, gyro;
  AngularVelocityErrors estimate_vs_groundtruth;  // with has_groundtruth
  AngularVelocityErrors estimate_vs_gyro;         // with has_gyro
  AngularVelocityErrors gyro_vs_groundtruth;      // with both
};

// groundtruth: the body's poses (nullptr: none); imu: the gyro's samples in time order (fewer than
// two: none); b2c: how the body frame and clock relate to the camera's.
AngularVelocityWindowsEvaluation evaluate_angular_velocity_windows(const std::vector<AngularVelocityWindow>& windows,
                                                                   const Trajectory* groundtruth,
                                                                   const std::vector<ImuSample>& imu,
                                                                   const BodyToCamera& b2c = {});

// |a - b| in deg/s for two angular velocities in rad/s: one window's error.
double angular_velocity_error_degps(const Eigen::Vector3d& a, const Eigen::Vector3d& b);

}  // namespace evio::evaluation
