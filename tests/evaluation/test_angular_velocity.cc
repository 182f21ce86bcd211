// Reference angular velocities (evaluation/angular_velocity.h): exact on a constant-rate trajectory,
// close to the analytic window mean on a sinusoidal one sampled at 200 Hz (where the rate between
// interpolated poses is not), R_c_b and the time shift applied, the gyro's window mean, and the
// error statistics.
#include "evio/evaluation/angular_velocity.h"

#include <cmath>
#include <cstdio>

#include <gtest/gtest.h>

#include "evio/calib/geometry.h"

namespace evio::evaluation {
namespace {

constexpr int64_t kMs = 1'000'000;

// Poses every `period_ns` over [0, 1 s] with R_w_b(t) = R0 Exp(phi(t)) for phi(t) = a sin(2 pi f t).
Trajectory sinusoid(int64_t period_ns, const Eigen::Vector3d& a, double f) {
  std::vector<StampedPose> p;
  const Eigen::Matrix3d R0 = calib::so3_exp(Eigen::Vector3d(0.3, -0.2, 0.1));
  for (int64_t t = 0; t <= 1000 * kMs; t += period_ns) {
    const double s = static_cast<double>(t) * 1e-9;
    calib::SE3 T;
    T.rotation = Eigen::Quaterniond(R0 * calib::so3_exp(a * std::sin(2 * M_PI * f * s)));
    p.push_back({t, T});
  }
  return Trajectory(std::move(p));
}

// The exact mean body rate of that trajectory over [t0, t1], by fine numerical differentiation.
Eigen::Vector3d exact_mean(const Eigen::Vector3d& a, double f, double t0, double t1) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  const int n = 2000;
  const double h = 1e-7;
  for (int i = 0; i < n; ++i) {
    const double t = t0 + (t1 - t0) * (i + 0.5) / n;
    const Eigen::Matrix3d R1 = calib::so3_exp(a * std::sin(2 * M_PI * f * t));
    const Eigen::Matrix3d R2 = calib::so3_exp(a * std::sin(2 * M_PI * f * (t + h)));
    sum += calib::so3_log(Eigen::Matrix3d(R1.transpose() * R2)) / h;
  }
  return sum / n;
}

TEST(AngularVelocity, ConstantRateIsExactAndTurnedIntoTheCameraFrame) {
  const Eigen::Vector3d w(0.5, -1.2, 2.0);
  std::vector<StampedPose> p;
  for (int64_t t = 0; t <= 100 * kMs; t += 5 * kMs) {
    calib::SE3 T;
    T.rotation = Eigen::Quaterniond(calib::so3_exp(w * (static_cast<double>(t) * 1e-9)));
    p.push_back({t, T});
  }
  const Trajectory traj(std::move(p));
  const auto r = trajectory_angular_velocity(traj, 20 * kMs, 23 * kMs);
  ASSERT_TRUE(r);
  EXPECT_LT((*r - w).norm(), 1e-9);
  // Camera frame: w_c = R_c_b w_b; the time shift moves the window on the body clock.
  BodyToCamera b2c;
  b2c.R_c_b = calib::so3_exp(Eigen::Vector3d(0, 0, M_PI / 2));
  b2c.time_shift_ns = 3 * kMs;
  const auto rc = trajectory_angular_velocity(traj, 20 * kMs, 23 * kMs, b2c);
  ASSERT_TRUE(rc);
  EXPECT_LT((*rc - b2c.R_c_b * w).norm(), 1e-9);
  // A zero-length window: the rate at that time.
  const auto r0 = trajectory_angular_velocity(traj, 42 * kMs, 42 * kMs);
  ASSERT_TRUE(r0);
  EXPECT_LT((*r0 - w).norm(), 1e-9);
  // Outside the central differences' span (before the second pose, after the second-to-last).
  EXPECT_FALSE(trajectory_angular_velocity(traj, 2 * kMs, 10 * kMs));
  EXPECT_FALSE(trajectory_angular_velocity(traj, 90 * kMs, 99 * kMs));
  EXPECT_FALSE(trajectory_angular_velocity(traj, 30 * kMs, 20 * kMs));
  EXPECT_FALSE(trajectory_angular_velocity(Trajectory(), 0, 1));
}

TEST(AngularVelocity, ShortWindowsOnA200HzTrajectoryMatchTheAnalyticMean) {
  // Rates up to ~4 rad/s, angular accelerations up to ~25 rad/s^2, poses every 5 ms, windows of
  // 3 ms at odd offsets. The rate between slerped poses errs by up to alpha times half a pose
  // period (measured: 1.46 deg/s at worst); the central differences by 0.08 deg/s at worst.
  const Eigen::Vector3d a(0.35, 0.6, 0.45);
  const double f = 1.0;
  const Trajectory traj = sinusoid(5 * kMs, a, f);
  double worst = 0, worst_slerp = 0;
  for (int64_t t0 = 20 * kMs + 700'000; t0 < 900 * kMs; t0 += 37 * kMs) {
    const int64_t t1 = t0 + 3 * kMs;
    const auto r = trajectory_angular_velocity(traj, t0, t1);
    ASSERT_TRUE(r);
    const Eigen::Vector3d ref = exact_mean(a, f, static_cast<double>(t0) * 1e-9, static_cast<double>(t1) * 1e-9);
    worst = std::max(worst, (*r - ref).norm() * 180 / M_PI);
    const Eigen::Quaterniond q = traj.interpolate(t0)->rotation.conjugate() * traj.interpolate(t1)->rotation;
    worst_slerp = std::max(worst_slerp, (calib::so3_log(q) / 3e-3 - ref).norm() * 180 / M_PI);
  }
  std::printf("worst window error: central differences %.3f deg/s, rate between slerped poses %.3f deg/s\n", worst,
              worst_slerp);
  EXPECT_LT(worst, 0.2);
  EXPECT_GT(worst_slerp, 1.0);  // what the naive reference would have cost
}

TEST(AngularVelocity, GyroMeanOverTheWindowOrInterpolated) {
  std::vector<ImuSample> imu;
  for (int k = 0; k <= 100; ++k) {
    ImuSample s;
    s.t_ns = k * kMs;
    s.gyro = Eigen::Vector3d(k, 2 * k, -k) * 0.01;
    imu.push_back(s);
  }
  const auto m = mean_gyro(imu, 10 * kMs, 20 * kMs);  // samples 10 .. 20, mean at 15
  ASSERT_TRUE(m);
  EXPECT_LT((*m - Eigen::Vector3d(0.15, 0.30, -0.15)).norm(), 1e-12);
  const auto i = mean_gyro(imu, 10 * kMs + 200'000, 10 * kMs + 400'000);  // no sample inside
  ASSERT_TRUE(i);
  EXPECT_LT((*i - Eigen::Vector3d(0.1030, 0.2060, -0.1030)).norm(), 1e-9);
  BodyToCamera b2c;
  b2c.R_c_b = -Eigen::Matrix3d::Identity();
  b2c.R_c_b(2, 2) = 1;  // a rotation by pi about z
  b2c.time_shift_ns = 5 * kMs;
  const auto c = mean_gyro(imu, 5 * kMs, 15 * kMs, b2c);
  ASSERT_TRUE(c);
  EXPECT_LT((*c - Eigen::Vector3d(-0.15, -0.30, -0.15)).norm(), 1e-12);
  EXPECT_FALSE(mean_gyro(imu, 95 * kMs, 120 * kMs));
  EXPECT_FALSE(mean_gyro({}, 0, 1));
}

TEST(AngularVelocity, ErrorStatisticsSkipNonFinitePairs) {
  const double d = M_PI / 180;
  const std::vector<Eigen::Vector3d> est = {{3 * d, 0, 0}, {0, 4 * d, 0}, {1, 1, 1}};
  const std::vector<Eigen::Vector3d> ref = {{0, 0, 0}, {0, 0, 0}, Eigen::Vector3d::Constant(std::nan(""))};
  const AngularVelocityErrors e = angular_velocity_errors(est, ref);
  EXPECT_EQ(e.count, 2u);
  EXPECT_NEAR(e.rms_degps, std::sqrt(12.5), 1e-9);
  EXPECT_NEAR(e.rms_axis_degps.x(), std::sqrt(4.5), 1e-9);
  EXPECT_NEAR(e.max_degps, 4, 1e-9);
  EXPECT_NEAR(e.median_degps, 3.5, 1e-9);
  EXPECT_EQ(e.relative_rms, 0.0);  // zero reference rate
  EXPECT_EQ(angular_velocity_errors({}, {}).count, 0u);
}

}  // namespace
}  // namespace evio::evaluation
