// Plain data passed between the VIO front-end and back-end (ARCHITECTURE.md: frontend and backend
// meet only through these types): the feature observations of one frame and the estimated state.
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "evio/calib/geometry.h"

namespace evio {

// One feature seen in a frame: its track (stable id across frames while the front-end tracks it)
// and its undistorted unit bearing in the camera frame.
struct FeatureObservation {
  int64_t track_id = 0;
  Eigen::Vector3d bearing_c = Eigen::Vector3d::UnitZ();
  // Observation noise on the undistorted image (px, 1 sigma); 0: the estimator's default.
  double sigma_px = 0.0;
};

// The observations of one frame. t_ns is on the body (IMU) clock, ns: the front-ends stamp their
// camera-clock frames with t_cam + camera.time_shift_ns (t_imu = t_cam + shift) before the
// estimator sees them.
struct FeatureObservations {
  int64_t t_ns = 0;
  int64_t frame_id = 0;
  std::vector<FeatureObservation> observations;
};

// Estimated body (IMU) state: pose in the world (gravity along -z), velocity, IMU biases.
struct VioState {
  int64_t t_ns = 0;
  calib::SE3 T_w_b;
  Eigen::Vector3d v_w = Eigen::Vector3d::Zero();         // m/s
  Eigen::Vector3d bias_gyro = Eigen::Vector3d::Zero();   // rad/s
  Eigen::Vector3d bias_accel = Eigen::Vector3d::Zero();  // m/s^2
};

}  // namespace evio
