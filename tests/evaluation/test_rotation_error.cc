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
  std::vector<int64_t> ends;
  for (int64_t t : starts) ends.push_back(t + 1'000'000'000);
  const auto r = ev::relative_rotation_error_at(gt, gt, starts, ends, 1.0);
  // The trajectory spans [kT0, kT0 + 2 s]: starts before it, or ending after it, are skipped.
  ASSERT_EQ(r.start_ns.size(), 3u);
  EXPECT_EQ(r.start_ns.front(), kT0);
  EXPECT_EQ(r.start_ns.back(), kT0 + 1'000'000'000);
  EXPECT_EQ(r.end_ns.back(), kT0 + 2'000'000'000);
  ends.pop_back();
  EXPECT_THROW(ev::relative_rotation_error_at(gt, gt, starts, ends, 1.0), std::invalid_argument);
}

// An estimate with a gap in its output (no poses for 0.4 s, as over a span without frames) while
// the rate changes: the intervals run between its own poses, so the gap adds nothing (a slerp
// across it would be off by about 1 deg here); an interval whose end falls in the gap further than
// the tolerance from t0 + dt is skipped.
TEST(RelativeRotationError, IntervalsRunBetweenTheEstimatesPosesNotAcrossItsGaps) {
  std::vector<evio::StampedPose> g, e;
  for (int k = 0; k <= 1000; ++k) {  // 200 Hz, 5 s, yaw rate 1.5 sin(3 t) rad/s
    const double t = 0.005 * k;
    const double yaw = 0.5 * (1 - std::cos(3 * t));
    const evio::StampedPose p{kT0 + 5'000'000LL * k, SE3(evio::calib::so3_exp_quat(Eigen::Vector3d(0, 0, yaw)), Eigen::Vector3d::Zero())};
    g.push_back(p);
    if (k % 10 == 0 && !(k > 400 && k < 490)) e.push_back(p);  // 20 Hz with a gap (2.0, 2.45) s
  }
  const evio::Trajectory gt(g), est(e);
  ev::RelativeRotationOptions o;
  o.stride = 1;
  const auto r = ev::relative_rotation_error(gt, est, o);
  EXPECT_LT(r.deg.max, 1e-9);
  ASSERT_EQ(r.start_ns.size(), r.end_ns.size());
  // Starts at t0 = 0, 0.05, ..., 4.0 s (ends up to 5 s) less those whose t0 + 1 s lies in the gap
  // further than 0.1 s from the poses at 2.0 and 2.45 s: t0 = 1.15, 1.2, 1.25 and 1.3 s.
  size_t starts = 0;
  for (const auto& p : e) starts += p.t_ns <= kT0 + 4'000'000'000LL;
  EXPECT_EQ(r.start_ns.size(), starts - 4);
  for (size_t k = 0; k < r.end_ns.size(); ++k) {
    EXPECT_LE(std::llabs(r.end_ns[k] - r.start_ns[k] - 1'000'000'000LL), 100'000'000LL);
  }
  // Interpolating the estimate across the gap instead (as for a dense trajectory) is off by more.
  const auto across = ev::relative_rotation_error_at(gt, est, {kT0 + 1'500'000'000LL}, {kT0 + 2'200'000'000LL}, 0.7);
  ASSERT_EQ(across.deg.count, 1u);
  EXPECT_GT(across.deg.max, 0.5);
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
