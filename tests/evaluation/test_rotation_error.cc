// Known-answer tests of the relative rotation error (RRE) and the gyro integrator.
#include "evio/evaluation/rotation_error.h"

#include <cmath>
#include <stdexcept>

#include <gtest/gtest.h>

namespace ev = evio::evaluation;
using evio::calib::Quat;
using evio::calib::SE3;

namespace {

constexpr int64_t kT0 = 1700000000000000000LL;  // large stamps: 1.7e18 ns

// Constant angular rate w (body frame, rad/s) from identity, 200 Hz for `seconds`.
evio::Trajectory spin(const Eigen::Vector3d& w, double seconds, const Eigen::Vector3d& bias = Eigen::Vector3d::Zero()) {
  std::vector<evio::StampedPose> p;
  const int n = static_cast<int>(seconds * 200);
  for (int k = 0; k <= n; ++k) {
    const double t = 0.005 * k;
    p.push_back({kT0 + 5'000'000LL * k, SE3(evio::calib::so3_exp_quat((w + bias) * t), Eigen::Vector3d(0.1 * t, 0, 0))});
  }
  return evio::Trajectory(p);
}

}  // namespace

TEST(RelativeRotationError, ZeroForTheSameTrajectoryAndTheRateErrorTimesTheInterval) {
  const Eigen::Vector3d w(0.3, -0.2, 1.0);
  const auto gt = spin(w, 5);
  ev::RelativeRotationOptions o;
  const auto same = ev::relative_rotation_error(gt, gt, o);
  // Starts every 5th pose (40 Hz) whose 1 s interval is covered: t in [0, 4] s.
  EXPECT_EQ(same.deg.count, 161u);
  EXPECT_LT(same.deg.max, 1e-9);
  // A rate error of b rad/s about a fixed body axis gives |b| * dt over every interval, whatever
  // the (commuting) motion.
  const Eigen::Vector3d b = 0.002 * w.normalized();
  const auto biased = ev::relative_rotation_error(gt, spin(w, 5, b), o);
  EXPECT_NEAR(biased.deg.rmse, 0.002 * 180 / M_PI, 1e-7);
  o.interval_s = 0.5;
  EXPECT_NEAR(ev::relative_rotation_error(gt, spin(w, 5, b), o).deg.rmse, 0.001 * 180 / M_PI, 1e-7);
  o.interval_s = 0;
  EXPECT_THROW(ev::relative_rotation_error(gt, gt, o), std::invalid_argument);
}

TEST(RelativeRotationError, StartsOutsideEitherTrajectoryAreSkipped) {
  const auto gt = spin(Eigen::Vector3d(0, 0, 1), 2);
  const std::vector<int64_t> starts = {kT0 - 1, kT0, kT0 + 999'999'999, kT0 + 1'000'000'000, kT0 + 1'000'000'001};
  const auto r = ev::relative_rotation_error_at(gt, gt, starts, 1.0);
  // The trajectory spans [kT0, kT0 + 2 s]: starts before it, or ending after it, are skipped.
  ASSERT_EQ(r.start_ns.size(), 3u);
  EXPECT_EQ(r.start_ns.front(), kT0);
  EXPECT_EQ(r.start_ns.back(), kT0 + 1'000'000'000);
}

TEST(GyroIntegrator, IntegratesAConstantRateExactlyAndBiasShowsInTheRre) {
  const Eigen::Vector3d w(0.5, 0.1, -2.0), bias(0.001, -0.002, 0.0005);
  ev::GyroIntegrator gi(5'000'000);
  for (int k = 0; k <= 3000; ++k) {  // 1 kHz, 3 s
    evio::ImuSample s;
    s.t_ns = kT0 + 1'000'000LL * k;
    s.gyro = w + bias;
    gi.add(s);
    if (k == 10) gi.add(s);  // repeated stamps are ignored
  }
  EXPECT_EQ(gi.samples(), 3001u);
  const evio::Trajectory g = gi.trajectory();
  EXPECT_EQ(g.t_end_ns(), kT0 + 3'000'000'000LL);
  EXPECT_LE(g.size(), 602u);  // one pose per 5 ms (plus the newest)
  const Quat expect = evio::calib::so3_exp_quat((w + bias) * 3.0);
  EXPECT_LT(expect.angularDistance(g.poses().back().T_w_b.rotation), 1e-9);
  // Against the true (bias-free) rotation: the RRE over 1 s is |bias| (rad) for a rate about a
  // fixed axis to first order; here w and bias differ in direction, so compare with the exact angle.
  const auto gt = spin(w, 3);
  const auto r = ev::relative_rotation_error(gt, g, ev::RelativeRotationOptions{});
  ASSERT_GT(r.deg.count, 50u);
  const double exact = Quat(evio::calib::so3_exp_quat(w * 1.0)).angularDistance(evio::calib::so3_exp_quat((w + bias) * 1.0));
  EXPECT_NEAR(r.deg.rmse, exact * 180 / M_PI, 1e-6);
}
