// evaluation::evaluate_angular_velocity_windows: per-window estimates against a constant-rate
// ground truth and a constant gyro with known offsets give known errors; windows a reference does
// not cover are NaN there and left out; no trajectory or fewer than two gyro samples: no reference.
#include "evio/evaluation/angular_velocity_windows.h"

#include <cmath>

#include <gtest/gtest.h>

#include "evio/calib/geometry.h"

namespace evio::evaluation {
namespace {

constexpr int64_t kMs = 1'000'000;
constexpr double kDeg = 180.0 / M_PI;

// Poses every 5 ms over [0, 100 ms] of a body turning at the constant rate w (rad/s).
Trajectory constant_rate(const Eigen::Vector3d& w) {
  std::vector<StampedPose> p;
  for (int64_t t = 0; t <= 100 * kMs; t += 5 * kMs) {
    calib::SE3 T;
    T.rotation = Eigen::Quaterniond(calib::so3_exp(w * (static_cast<double>(t) * 1e-9)));
    p.push_back({t, T});
  }
  return Trajectory(std::move(p));
}

// Gyro samples every 1 ms over [0, 60 ms] reading g.
std::vector<ImuSample> constant_gyro(const Eigen::Vector3d& g) {
  std::vector<ImuSample> imu;
  for (int64_t t = 0; t <= 60 * kMs; t += kMs) {
    ImuSample s;
    s.t_ns = t;
    s.gyro = g;
    imu.push_back(s);
  }
  return imu;
}

TEST(AngularVelocityWindows, KnownOffsetsGiveKnownErrors) {
  const Eigen::Vector3d w(1.0, -2.0, 0.5);
  const Eigen::Vector3d gyro = w + Eigen::Vector3d(0, 0, 0.01);  // 0.573 deg/s off the truth
  const Trajectory gt = constant_rate(w);
  // Estimates 0.02 rad/s off along x, then 0.04 rad/s along y; the third window lies past the
  // gyro's last sample (60 ms), the fourth past the ground truth's central differences (95 ms).
  const std::vector<AngularVelocityWindow> windows = {{10 * kMs, 20 * kMs, w + Eigen::Vector3d(0.02, 0, 0)},
                                                      {20 * kMs, 30 * kMs, w + Eigen::Vector3d(0, 0.04, 0)},
                                                      {70 * kMs, 80 * kMs, w},
                                                      {96 * kMs, 99 * kMs, w}};
  const AngularVelocityWindowsEvaluation e = evaluate_angular_velocity_windows(windows, &gt, constant_gyro(gyro));
  ASSERT_TRUE(e.has_groundtruth);
  ASSERT_TRUE(e.has_gyro);
  ASSERT_EQ(e.groundtruth.size(), 4u);
  ASSERT_EQ(e.gyro.size(), 4u);
  EXPECT_LT((e.groundtruth[0] - w).norm(), 1e-9);
  EXPECT_LT((e.groundtruth[2] - w).norm(), 1e-9);
  EXPECT_FALSE(e.groundtruth[3].allFinite());
  EXPECT_LT((e.gyro[1] - gyro).norm(), 1e-12);
  EXPECT_FALSE(e.gyro[2].allFinite());
  EXPECT_FALSE(e.gyro[3].allFinite());

  // Against the ground truth: windows 0, 1, 2 with errors 0.02, 0.04, 0 rad/s.
  EXPECT_EQ(e.estimate_vs_groundtruth.count, 3u);
  EXPECT_NEAR(e.estimate_vs_groundtruth.rms_degps, std::sqrt((0.02 * 0.02 + 0.04 * 0.04) / 3) * kDeg, 1e-6);
  EXPECT_NEAR(e.estimate_vs_groundtruth.max_degps, 0.04 * kDeg, 1e-6);
  EXPECT_NEAR(e.estimate_vs_groundtruth.median_degps, 0.02 * kDeg, 1e-6);
  EXPECT_NEAR(e.estimate_vs_groundtruth.reference_rms_degps, w.norm() * kDeg, 1e-6);
  // Against the gyro: windows 0 and 1.
  EXPECT_EQ(e.estimate_vs_gyro.count, 2u);
  const double d0 = Eigen::Vector3d(0.02, 0, -0.01).norm(), d1 = Eigen::Vector3d(0, 0.04, -0.01).norm();
  EXPECT_NEAR(e.estimate_vs_gyro.rms_degps, std::sqrt((d0 * d0 + d1 * d1) / 2) * kDeg, 1e-6);
  // The gyro against the ground truth: windows 0 and 1, 0.01 rad/s each.
  EXPECT_EQ(e.gyro_vs_groundtruth.count, 2u);
  EXPECT_NEAR(e.gyro_vs_groundtruth.rms_degps, 0.01 * kDeg, 1e-6);
}

TEST(AngularVelocityWindows, MissingReferencesAreNaNAndNotCounted) {
  const std::vector<AngularVelocityWindow> windows = {{10 * kMs, 20 * kMs, Eigen::Vector3d(1, 0, 0)}};
  // One gyro sample is no gyro; no trajectory is no ground truth.
  const AngularVelocityWindowsEvaluation e =
      evaluate_angular_velocity_windows(windows, nullptr, std::vector<ImuSample>(1));
  EXPECT_FALSE(e.has_groundtruth);
  EXPECT_FALSE(e.has_gyro);
  ASSERT_EQ(e.groundtruth.size(), 1u);
  EXPECT_FALSE(e.groundtruth[0].allFinite());
  EXPECT_FALSE(e.gyro[0].allFinite());
  EXPECT_EQ(e.estimate_vs_groundtruth.count, 0u);
  EXPECT_EQ(e.estimate_vs_gyro.count, 0u);
  EXPECT_EQ(e.gyro_vs_groundtruth.count, 0u);
}

TEST(AngularVelocityWindows, ReferencesAreTurnedIntoTheCameraFrame) {
  const Eigen::Vector3d w(0.0, 0.0, 2.0);
  BodyToCamera b2c;
  b2c.R_c_b = calib::so3_exp(Eigen::Vector3d(M_PI / 2, 0, 0));  // body z -> camera -y
  const AngularVelocityWindowsEvaluation e = evaluate_angular_velocity_windows(
      {{10 * kMs, 20 * kMs, Eigen::Vector3d(0, -2.0, 0)}}, nullptr, constant_gyro(w), b2c);
  ASSERT_TRUE(e.has_gyro);
  EXPECT_LT((e.gyro[0] - Eigen::Vector3d(0, -2.0, 0)).norm(), 1e-12);
  EXPECT_NEAR(e.estimate_vs_gyro.rms_degps, 0.0, 1e-9);
}

TEST(AngularVelocityWindows, ErrorOfOneWindowInDegreesPerSecond) {
  EXPECT_NEAR(angular_velocity_error_degps(Eigen::Vector3d(1, 2, 3), Eigen::Vector3d(1, 2, 3 - M_PI / 180)), 1.0, 1e-12);
  EXPECT_DOUBLE_EQ(angular_velocity_error_degps(Eigen::Vector3d(0.3, 0, 0), Eigen::Vector3d(0, 0.4, 0)), 0.5 * kDeg);
}

}  // namespace
}  // namespace evio::evaluation
