// Per-window angular velocities against the ground truth's and the gyro's (angular_velocity_windows.h).
#include "evio/evaluation/angular_velocity_windows.h"

#include <cmath>

namespace evio::evaluation {

AngularVelocityWindowsEvaluation evaluate_angular_velocity_windows(const std::vector<AngularVelocityWindow>& windows,
                                                                   const Trajectory* groundtruth,
                                                                   const std::vector<ImuSample>& imu,
                                                                   const BodyToCamera& b2c) {
  AngularVelocityWindowsEvaluation r;
  r.has_groundtruth = groundtruth != nullptr;
  r.has_gyro = imu.size() >= 2;
  const Eigen::Vector3d none = Eigen::Vector3d::Constant(std::nan(""));
  std::vector<Eigen::Vector3d> estimates;
  for (const AngularVelocityWindow& w : windows) {
    estimates.push_back(w.estimate);
    r.groundtruth.push_back(r.has_groundtruth
                                ? trajectory_angular_velocity(*groundtruth, w.t_start_ns, w.t_end_ns, b2c).value_or(none)
                                : none);
    r.gyro.push_back(r.has_gyro ? mean_gyro(imu, w.t_start_ns, w.t_end_ns, b2c).value_or(none) : none);
  }
  if (r.has_groundtruth) r.estimate_vs_groundtruth = angular_velocity_errors(estimates, r.groundtruth);
  if (r.has_gyro) r.estimate_vs_gyro = angular_velocity_errors(estimates, r.gyro);
  if (r.has_groundtruth && r.has_gyro) r.gyro_vs_groundtruth = angular_velocity_errors(r.gyro, r.groundtruth);
  return r;
}

double angular_velocity_error_degps(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return (a - b).norm() * (180.0 / M_PI);
}

}  // namespace evio::evaluation
