// Simulated VIO measurements with ground truth, for back-end tests and benchmarks: a simulator
// scene YAML (datasets/*.yaml) gives the trajectory (e.g. the real poster_6dof motion capture
// spline fit), the camera (intrinsics, T_c_b) and the IMU noise model; landmarks are random points
// on the scene's planes (panorama scenes: on a sphere around the start, far enough that pure
// rotation shows no parallax); every frame observes the landmarks in view, projected through the
// distorted camera with Gaussian pixel noise, a share replaced by outliers, and undistorted back
// to bearings (what a front-end delivers). A landmark that leaves the view and returns gets a new
// track id, as a real tracker would.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "evio/calib/calibration_io.h"
#include "evio/sensors/measurements.h"
#include "evio/simulator/imu.h"
#include "evio/simulator/trajectory.h"
#include "evio/sensors/trajectory.h"
#include "evio/sensors/vio_types.h"

namespace evio::test {

struct VioSimOptions {
  std::string scene_yaml;            // a planes scene (datasets/poster_6dof_mocap.yaml, ...)
  double t_begin_s = 0.0;            // start within the trajectory's span, s
  double duration_s = 10.0;          // s
  double frame_rate_hz = 20.0;       // Hz
  int landmarks = 1500;              // points spread uniformly over the planes
  double pixel_sigma = 0.5;          // px, Gaussian, on the distorted image
  double outlier_fraction = 0.02;    // observations replaced by a uniform random pixel
  double border_px = 4.0;            // observations only this far inside the image
  bool imu_noise = true;             // false: ideal IMU (constant biases)
  Eigen::Vector3d bias_gyro = Eigen::Vector3d(0.002, -0.003, 0.001);   // initial biases, rad/s
  Eigen::Vector3d bias_accel = Eigen::Vector3d(0.02, -0.01, 0.03);     // m/s^2
  uint64_t seed = 7;
  double scene_duration_s = 0;       // > 0: overrides the scene's `duration` (analytic trajectories), s
  std::string trajectory_file;       // non-empty: overrides `trajectory.path` (file trajectories)
  double sphere_radius_m = 20.0;     // panorama scenes: landmarks on a sphere of this radius around the start, m
};

struct VioSimulation {
  calib::CameraCalibration camera;              // intrinsics and T_c_b
  calib::ImuNoise imu_noise;                    // the simulator's densities
  Eigen::Vector3d gravity_w = Eigen::Vector3d(0, 0, -9.81);
  std::shared_ptr<const simulator::ContinuousTrajectory> trajectory;  // ground truth T_w_b(t)
  std::vector<ImuSample> imu;                   // body clock
  std::vector<simulator::ImuBiasSample> biases;       // true biases at every IMU sample
  std::vector<FeatureObservations> frames;      // camera clock (= body clock: no time shift)
  std::vector<Eigen::Vector3d> landmarks_w;
  int64_t outliers = 0;                         // observations replaced by outliers
  int64_t t_begin_ns = 0, t_end_ns = 0;

  // True state at t (body clock) with the true biases.
  VioState true_state(int64_t t_ns) const;
  // Ground truth sampled at the frame times (TUM-like, body poses).
  Trajectory groundtruth_at_frames() const;
};

// Throws std::invalid_argument / evio::InputError when the scene cannot be loaded.
VioSimulation make_vio_simulation(const VioSimOptions& options);

}  // namespace evio::test
