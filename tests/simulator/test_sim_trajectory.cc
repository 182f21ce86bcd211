#include "evio/simulator/trajectory.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <random>

#include <gtest/gtest.h>

#include "sim_test_trajectories.h"

#include "evio_test/real_data.h"

namespace evio::simulator {
namespace {

using calib::Quat;
using calib::Vec3;

using test::kLargeT0;
using test::lively_sinusoid;

// Tolerance that scales with the magnitude of the reference.
void expect_vec_near(const Vec3& actual, const Vec3& expected, double rel_tol, const std::string& what) {
  const double tol = rel_tol * std::max(1.0, expected.norm());
  EXPECT_LE((actual - expected).norm(), tol) << what << ": got " << actual.transpose() << ", expected "
                                             << expected.transpose();
}


RandomSplineOptions agile_spline(int order, uint64_t seed, int64_t t0 = 0) {
  RandomSplineOptions o;
  o.t_begin_ns = t0;
  o.duration_s = 10.0;
  o.order = order;
  o.knot_spacing_s = 0.3;
  o.position_m = Vec3(0.5, 0.0, 1.0);
  o.position_std_m = Vec3(0.3, 0.3, 0.2);
  o.rotation_std_rad = 0.5;
  o.seed = seed;
  return o;
}

// Central finite differences of the pose and the analytic velocities, compared with the
// analytic derivatives. h = 50 us: truncation ~ h^2 * third derivative ~ 1e-8, rounding ~ 1e-11.
void check_derivatives(const ContinuousTrajectory& traj, int64_t t, const std::string& label) {
  const int64_t h = 50000;
  const double h_s = 1e-9 * static_cast<double>(h);
  const TrajectoryState c = traj.evaluate(t);
  const TrajectoryState m = traj.evaluate(t - h);
  const TrajectoryState p = traj.evaluate(t + h);
  const Vec3 v_fd = (p.T_w_b.translation - m.T_w_b.translation) / (2 * h_s);
  const Vec3 a_fd = (p.v_w - m.v_w) / (2 * h_s);
  const Vec3 a_fd2 = (p.T_w_b.translation - 2 * c.T_w_b.translation + m.T_w_b.translation) / (h_s * h_s);
  const Vec3 w_fd = calib::so3_log(m.T_w_b.rotation.conjugate() * p.T_w_b.rotation) / (2 * h_s);
  const Vec3 alpha_fd = (p.omega_b - m.omega_b) / (2 * h_s);
  expect_vec_near(c.v_w, v_fd, 1e-6, label + " velocity");
  expect_vec_near(c.a_w, a_fd, 1e-6, label + " acceleration (from velocity)");
  expect_vec_near(c.a_w, a_fd2, 1e-4, label + " acceleration (from position)");
  expect_vec_near(c.omega_b, w_fd, 1e-6, label + " angular velocity");
  expect_vec_near(c.alpha_b, alpha_fd, 1e-6, label + " angular acceleration");
}

TEST(SinusoidTrajectory, DerivativesMatchFiniteDifferences) {
  const SinusoidTrajectory traj(lively_sinusoid(kLargeT0));
  for (int i = 1; i < 40; ++i) {
    const int64_t t = kLargeT0 + i * 249999937LL;
    check_derivatives(traj, t, "sinusoid t=" + std::to_string(i));
  }
  // The motion is really there (a check that is trivially met by zero derivatives would be useless).
  const TrajectoryState s = traj.evaluate(kLargeT0 + 3000000000LL);
  EXPECT_GT(s.omega_b.norm(), 0.1);
  EXPECT_GT(s.alpha_b.norm(), 0.1);
  EXPECT_GT(s.a_w.norm(), 0.1);
}

TEST(SinusoidTrajectory, ClosedFormValues) {
  SinusoidTrajectoryOptions o;
  o.position_m = Vec3(1, 2, 3);
  o.velocity_mps = Vec3(0.5, 0, 0);
  o.amplitude_m = Vec3(0, 2, 0);
  o.frequency_hz = Vec3(0, 0.25, 0);
  o.angle_rate_radps = Vec3(0, 0, 0.1);  // yaw only: omega_b = (0, 0, 0.1)
  const SinusoidTrajectory traj(o);
  const TrajectoryState s = traj.evaluate(1000000000);  // t = 1 s: sin(pi/2) = 1
  EXPECT_NEAR(s.T_w_b.translation.x(), 1.5, 1e-15);
  EXPECT_NEAR(s.T_w_b.translation.y(), 4.0, 1e-15);
  EXPECT_NEAR(s.v_w.y(), 0.0, 1e-15);
  EXPECT_NEAR(s.a_w.y(), -2.0 * std::pow(2 * M_PI * 0.25, 2), 1e-12);
  EXPECT_NEAR((s.omega_b - Vec3(0, 0, 0.1)).norm(), 0.0, 1e-15);
  EXPECT_NEAR(s.T_w_b.rotation.angularDistance(Quat(Eigen::AngleAxisd(0.1, Vec3::UnitZ()))), 0.0, 1e-15);
  EXPECT_EQ(traj.t_end_ns(), 10000000000LL);
  EXPECT_THROW(traj.evaluate(-1), std::out_of_range);
  EXPECT_THROW(traj.evaluate(traj.t_end_ns() + 1), std::out_of_range);
  EXPECT_NO_THROW(traj.evaluate(traj.t_end_ns()));
}

TEST(SinusoidTrajectory, EulerOrderIsZYX) {
  SinusoidTrajectoryOptions o;
  o.angle_rate_radps = Vec3(0.3, -0.2, 0.5);  // (roll, pitch, yaw) per second
  const SinusoidTrajectory traj(o);
  const TrajectoryState s = traj.evaluate(1000000000);
  const Quat expected = Quat(Eigen::AngleAxisd(0.5, Vec3::UnitZ())) * Quat(Eigen::AngleAxisd(-0.2, Vec3::UnitY())) *
                        Quat(Eigen::AngleAxisd(0.3, Vec3::UnitX()));
  EXPECT_LT(s.T_w_b.rotation.angularDistance(expected), 1e-14);
}

TEST(SinusoidTrajectory, RejectsInvalidOptions) {
  SinusoidTrajectoryOptions o;
  std::string why;
  EXPECT_TRUE(o.Validate(&why));
  o.duration_s = 0;
  EXPECT_FALSE(o.Validate(&why));
  EXPECT_THROW(SinusoidTrajectory{o}, std::invalid_argument);
  o.duration_s = 1;
  o.frequency_hz.x() = -1;
  EXPECT_FALSE(o.Validate(&why));
  o.frequency_hz.x() = 1;
  o.q_w_b0.coeffs().setZero();
  EXPECT_FALSE(o.Validate(&why));
}

TEST(SinusoidTrajectory, LargeTimestampsGiveTheShiftedState) {
  const SinusoidTrajectory a(lively_sinusoid(0));
  const SinusoidTrajectory b(lively_sinusoid(kLargeT0));
  for (int64_t dt : std::vector<int64_t>{0LL, 1LL, 123456789LL, 7777777777LL, 10000000000LL}) {
    const TrajectoryState sa = a.evaluate(dt);
    const TrajectoryState sb = b.evaluate(kLargeT0 + dt);
    EXPECT_EQ(sb.t_ns, kLargeT0 + dt);
    EXPECT_EQ(sa.T_w_b.translation, sb.T_w_b.translation);
    EXPECT_EQ(sa.T_w_b.rotation.coeffs(), sb.T_w_b.rotation.coeffs());
    EXPECT_EQ(sa.omega_b, sb.omega_b);
    EXPECT_EQ(sa.a_w, sb.a_w);
  }
}

TEST(SplineTrajectory, ReproducesLinearMotionExactly) {
  // A uniform B-spline of order k reproduces polynomials of degree < k: control points on a line
  // (p_i = i c, R_i = Exp(i phi)) give p(t) = (tau + (k-2)/2) c with tau = (t - t0)/dt, and
  // R(t) = Exp((tau + (k-2)/2) phi) at constant body rate phi / dt.
  const Vec3 c(0.1, -0.2, 0.05);
  const Vec3 phi(0.02, 0.05, -0.03);
  const int64_t t0 = kLargeT0;
  const int64_t dt_ns = 50000000;
  const double dt = 0.05;
  for (int k = 4; k <= 6; ++k) {
    std::vector<Quat> q;
    std::vector<Vec3> p;
    for (int i = 0; i < 12; ++i) {
      p.push_back(i * c);
      q.push_back(calib::so3_exp_quat(i * phi));
    }
    const SplineTrajectory s(k, t0, dt_ns, q, p);
    EXPECT_EQ(s.t_end_ns(), t0 + (12 - k + 1) * dt_ns);
    for (int64_t rel : std::vector<int64_t>{0LL, 1LL, 12345678LL, 50000000LL, 77777777LL, (12 - k + 1) * dt_ns}) {
      const TrajectoryState st = s.evaluate(t0 + rel);
      const double tau = static_cast<double>(rel) / static_cast<double>(dt_ns) + 0.5 * (k - 2);
      expect_vec_near(st.T_w_b.translation, tau * c, 1e-13, "k=" + std::to_string(k) + " position");
      expect_vec_near(st.v_w, c / dt, 1e-12, "velocity");
      expect_vec_near(st.a_w, Vec3::Zero(), 1e-10, "acceleration");
      EXPECT_LT(st.T_w_b.rotation.angularDistance(calib::so3_exp_quat(tau * phi)), 1e-13) << "k=" << k;
      expect_vec_near(st.omega_b, phi / dt, 1e-12, "angular velocity");
      expect_vec_near(st.alpha_b, Vec3::Zero(), 1e-10, "angular acceleration");
    }
  }
}

TEST(SplineTrajectory, DerivativesMatchFiniteDifferences) {
  for (int k = 4; k <= 6; ++k) {
    const SplineTrajectory s = SplineTrajectory::random(agile_spline(k, 7, kLargeT0));
    for (int i = 1; i < 60; ++i) {
      // Times away from knots (the third derivative jumps there for k = 4).
      const int64_t t = kLargeT0 + i * 160000000LL + 13000000LL;
      check_derivatives(s, t, "order " + std::to_string(k) + " sample " + std::to_string(i));
    }
    const TrajectoryState st = s.evaluate(kLargeT0 + 2000000000LL);
    EXPECT_GT(st.omega_b.norm(), 0.2);
    EXPECT_GT(st.a_w.norm(), 0.2);
  }
}

TEST(SplineTrajectory, IdenticalControlPointsAreStatic) {
  const Quat q(Eigen::AngleAxisd(2.0, Vec3(0.3, -1, 0.2).normalized()));
  const Vec3 p(1, 2, 3);
  // Alternate the quaternion sign: the same rotation, so still static.
  std::vector<Quat> qs;
  for (int i = 0; i < 10; ++i) qs.push_back(i % 2 ? Quat(-q.coeffs()) : q);
  const SplineTrajectory s(6, 0, 10000000, qs, std::vector<Vec3>(10, p));
  for (int64_t t = 0; t <= s.t_end_ns(); t += 3333333) {
    const TrajectoryState st = s.evaluate(t);
    EXPECT_LT((st.T_w_b.translation - p).norm(), 1e-14);
    EXPECT_LT(st.T_w_b.rotation.angularDistance(q), 1e-14);
    EXPECT_EQ(st.v_w.norm(), 0.0);
    EXPECT_EQ(st.a_w.norm(), 0.0);
    EXPECT_LT(st.omega_b.norm(), 1e-14);
    EXPECT_LT(st.alpha_b.norm(), 1e-14);
  }
}

TEST(SplineTrajectory, ContinuousAccelerationAcrossKnots) {
  // Cubic (k = 4) is C2: acceleration and angular acceleration are continuous at knots while the
  // jerk jumps. 1 ns either side of a knot the values differ only by (jerk * 1 ns).
  for (int k = 4; k <= 6; ++k) {
    const SplineTrajectory s = SplineTrajectory::random(agile_spline(k, 3, kLargeT0));
    const int64_t dt = s.knot_spacing_ns();
    double max_jump_a = 0, max_jump_alpha = 0, max_jump_v = 0, max_a = 0;
    for (int64_t t = kLargeT0 + dt; t < s.t_end_ns(); t += dt) {
      const TrajectoryState l = s.evaluate(t - 1);
      const TrajectoryState r = s.evaluate(t);
      max_jump_v = std::max(max_jump_v, (l.v_w - r.v_w).norm());
      max_jump_a = std::max(max_jump_a, (l.a_w - r.a_w).norm());
      max_jump_alpha = std::max(max_jump_alpha, (l.alpha_b - r.alpha_b).norm());
      max_a = std::max(max_a, r.a_w.norm());
      EXPECT_LT((l.T_w_b.translation - r.T_w_b.translation).norm(), 1e-8);
      EXPECT_LT(l.T_w_b.rotation.angularDistance(r.T_w_b.rotation), 1e-8);
    }
    EXPECT_GT(max_a, 1.0);  // the spline moves
    EXPECT_LT(max_jump_v, 1e-7) << "order " << k;
    EXPECT_LT(max_jump_a, 1e-6) << "order " << k;
    EXPECT_LT(max_jump_alpha, 1e-6) << "order " << k;
  }
}

TEST(SplineTrajectory, RandomIsDeterministicPerSeed) {
  const SplineTrajectory a = SplineTrajectory::random(agile_spline(6, 42));
  const SplineTrajectory b = SplineTrajectory::random(agile_spline(6, 42));
  const SplineTrajectory c = SplineTrajectory::random(agile_spline(6, 43));
  ASSERT_EQ(a.num_control_points(), b.num_control_points());
  ASSERT_EQ(a.num_control_points(), c.num_control_points());
  // 10 s at 0.3 s knots: ceil(10 / 0.3) = 34 segments, 34 + 5 control points.
  EXPECT_EQ(a.num_control_points(), 39u);
  EXPECT_GE(a.t_end_ns(), 10000000000LL);
  double diff_ab = 0, diff_ac = 0;
  for (size_t i = 0; i < a.num_control_points(); ++i) {
    diff_ab += (a.control_positions()[i] - b.control_positions()[i]).norm() +
               (a.control_rotations()[i].coeffs() - b.control_rotations()[i].coeffs()).norm();
    diff_ac += (a.control_positions()[i] - c.control_positions()[i]).norm();
  }
  EXPECT_EQ(diff_ab, 0.0);
  EXPECT_GT(diff_ac, 1.0);
  // The spread follows the options: sample std of control positions near position_std_m.
  RandomSplineOptions o = agile_spline(4, 5);
  o.duration_s = 300;
  const SplineTrajectory big = SplineTrajectory::random(o);
  Vec3 mean = Vec3::Zero(), sq = Vec3::Zero();
  for (const Vec3& p : big.control_positions()) mean += p;
  mean /= static_cast<double>(big.num_control_points());
  for (const Vec3& p : big.control_positions()) sq += (p - mean).cwiseAbs2();
  const Vec3 std_dev = (sq / static_cast<double>(big.num_control_points() - 1)).cwiseSqrt();
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(std_dev[i] / o.position_std_m[i], 1.0, 0.1);
  EXPECT_LT((mean - o.position_m).norm(), 0.05);
}

TEST(SplineTrajectory, LargeTimestampsGiveTheShiftedState) {
  const SplineTrajectory a = SplineTrajectory::random(agile_spline(5, 9, 0));
  const SplineTrajectory b = SplineTrajectory::random(agile_spline(5, 9, kLargeT0));
  EXPECT_EQ(b.t_end_ns() - b.t_begin_ns(), a.t_end_ns() - a.t_begin_ns());
  for (int64_t dt : std::vector<int64_t>{0LL, 1LL, 299999999LL, 300000000LL, 4444444444LL, a.t_end_ns()}) {
    const TrajectoryState sa = a.evaluate(dt);
    const TrajectoryState sb = b.evaluate(kLargeT0 + dt);
    EXPECT_EQ(sa.T_w_b.translation, sb.T_w_b.translation);
    EXPECT_EQ(sa.T_w_b.rotation.coeffs(), sb.T_w_b.rotation.coeffs());
    EXPECT_EQ(sa.v_w, sb.v_w);
    EXPECT_EQ(sa.omega_b, sb.omega_b);
    EXPECT_EQ(sa.alpha_b, sb.alpha_b);
  }
  // One nanosecond apart at 1.7e18 ns still gives distinct states.
  EXPECT_NE(b.evaluate(kLargeT0 + 5000000000LL).T_w_b.translation,
            b.evaluate(kLargeT0 + 5000000001LL).T_w_b.translation);
}

TEST(SplineTrajectory, RejectsBadInput) {
  std::vector<Quat> q(5, Quat::Identity());
  std::vector<Vec3> p(5, Vec3::Zero());
  EXPECT_THROW(SplineTrajectory(3, 0, 10, q, p), std::invalid_argument);
  EXPECT_THROW(SplineTrajectory(7, 0, 10, q, p), std::invalid_argument);
  EXPECT_THROW(SplineTrajectory(6, 0, 10, q, p), std::invalid_argument);  // 5 < order
  EXPECT_THROW(SplineTrajectory(4, 0, 0, q, p), std::invalid_argument);
  EXPECT_THROW(SplineTrajectory(4, 0, 10, q, std::vector<Vec3>(4, Vec3::Zero())), std::invalid_argument);
  const SplineTrajectory s(4, 100, 10, q, p);
  EXPECT_EQ(s.t_end_ns(), 120);
  EXPECT_THROW(s.evaluate(99), std::out_of_range);
  EXPECT_THROW(s.evaluate(121), std::out_of_range);
  RandomSplineOptions o;
  std::string why;
  EXPECT_TRUE(o.Validate(&why));
  o.order = 7;
  EXPECT_FALSE(o.Validate(&why));
  EXPECT_THROW(SplineTrajectory::random(o), std::invalid_argument);
}

TEST(SampleTrajectory, IncludesBothEnds) {
  SinusoidTrajectoryOptions o = lively_sinusoid(kLargeT0);
  o.duration_s = 1.0;
  const SinusoidTrajectory traj(o);
  const Trajectory t = sample_trajectory(traj, 300000000);  // 0, 0.3, 0.6, 0.9, then the end 1.0
  ASSERT_EQ(t.size(), 5u);
  EXPECT_EQ(t[3].t_ns, kLargeT0 + 900000000);
  EXPECT_EQ(t[4].t_ns, kLargeT0 + 1000000000);
  EXPECT_EQ(t[2].T_w_b.translation, traj.evaluate(kLargeT0 + 600000000).T_w_b.translation);
  EXPECT_EQ(sample_trajectory(traj, 250000000).size(), 5u);  // end hit exactly, not repeated
  EXPECT_THROW(sample_trajectory(traj, 0), std::invalid_argument);
}

TEST(SplineFit, RecoversTheSplineThatMadeTheSamples) {
  // Samples of a spline are fitted exactly by a spline with the same knots (no smoothing).
  for (int k : {4, 6}) {
    RandomSplineOptions o = agile_spline(k, 11, kLargeT0);
    o.duration_s = 4.0;
    o.knot_spacing_s = 0.1;
    o.rotation_std_rad = 0.4;
    const SplineTrajectory truth = SplineTrajectory::random(o);
    const Trajectory samples = sample_trajectory(truth, 5000000);
    SplineFitOptions f;
    f.order = k;
    f.knot_spacing_s = 0.1;
    f.smoothing = 0.0;
    SplineFitReport report;
    const SplineTrajectory fitted = SplineTrajectory::fit(samples, f, &report);
    ASSERT_EQ(fitted.num_control_points(), truth.num_control_points());
    EXPECT_EQ(fitted.t_begin_ns(), truth.t_begin_ns());
    EXPECT_EQ(fitted.t_end_ns(), truth.t_end_ns());
    EXPECT_EQ(report.samples, samples.size());
    EXPECT_EQ(report.control_points, truth.num_control_points());
    EXPECT_LT(report.position_max_m, 1e-9);
    EXPECT_LT(report.rotation_max_deg, 1e-7);
    EXPECT_LE(report.iterations, 10);
    for (size_t i = 0; i < truth.num_control_points(); ++i) {
      EXPECT_LT((fitted.control_positions()[i] - truth.control_positions()[i]).norm(), 1e-6) << i;
      EXPECT_LT(fitted.control_rotations()[i].angularDistance(truth.control_rotations()[i]), 1e-6) << i;
    }
  }
}

// Gaussian draws for the test's sample noise (Box-Muller on mt19937_64).
class Gauss {
 public:
  explicit Gauss(uint64_t seed) : rng_(seed) {}
  double operator()() {
    const double u1 = 1.0 - static_cast<double>(rng_() >> 11) * 0x1.0p-53;
    const double u2 = static_cast<double>(rng_() >> 11) * 0x1.0p-53;
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * M_PI * u2);
  }
  Vec3 vec() {
    const double x = (*this)(), y = (*this)(), z = (*this)();
    return Vec3(x, y, z);
  }

 private:
  std::mt19937_64 rng_;
};

TEST(SplineFit, AveragesSampleNoiseAndBridgesGaps) {
  // A sinusoid sampled at 200 Hz with motion-capture-like white noise (sigma 0.5 mm and 0.2 deg per
  // axis) and a 50 ms hole, fitted with the default options (quintic, 20 ms knots). Least squares
  // with p parameters on N samples leaves a residual of rms sqrt(1 - p/N) * noise and an error to
  // the truth of rms sqrt(p/N) * noise (noise = 3D rms = sqrt(3) sigma); p/N ~ 1/4 here.
  SinusoidTrajectoryOptions so = lively_sinusoid(kLargeT0);
  so.duration_s = 6.0;
  const SinusoidTrajectory truth(so);
  const double sigma_p = 0.5e-3, sigma_r = 0.2 * M_PI / 180;
  const double noise_p = std::sqrt(3.0) * sigma_p, noise_r = std::sqrt(3.0) * sigma_r;
  const int64_t gap_begin = kLargeT0 + 3000000000LL, gap_end = kLargeT0 + 3050000000LL;
  Gauss gauss(3);
  Trajectory samples;
  for (int64_t t = kLargeT0; t <= truth.t_end_ns(); t += 5000000) {
    if (t > gap_begin && t < gap_end) continue;
    const calib::SE3 T = truth.evaluate(t).T_w_b;
    samples.push_back({t, calib::SE3(T.rotation * calib::so3_exp_quat(sigma_r * gauss.vec()),
                                     T.translation + sigma_p * gauss.vec())});
  }
  SplineFitReport report;
  const SplineTrajectory fitted = SplineTrajectory::fit(samples, SplineFitOptions(), &report);
  const double p_over_n = static_cast<double>(report.control_points) / static_cast<double>(report.samples);
  EXPECT_NEAR(report.position_rms_m / (noise_p * std::sqrt(1 - p_over_n)), 1.0, 0.05);
  EXPECT_NEAR(report.rotation_rms_deg * M_PI / 180 / (noise_r * std::sqrt(1 - p_over_n)), 1.0, 0.05);
  double sum_p = 0, sum_r = 0, max_p = 0, max_r = 0, gap_p = 0, gap_r = 0;
  size_t n = 0;
  for (int64_t t = kLargeT0; t <= truth.t_end_ns(); t += 1000000) {
    const TrajectoryState a = truth.evaluate(t);
    const TrajectoryState b = fitted.evaluate(t);
    const double ep = (a.T_w_b.translation - b.T_w_b.translation).norm();
    const double er = a.T_w_b.rotation.angularDistance(b.T_w_b.rotation);
    sum_p += ep * ep;
    sum_r += er * er;
    const bool near_gap = t > gap_begin - 50000000 && t < gap_end + 50000000;
    (near_gap ? gap_p : max_p) = std::max(near_gap ? gap_p : max_p, ep);
    (near_gap ? gap_r : max_r) = std::max(near_gap ? gap_r : max_r, er);
    ++n;
  }
  const double rms_p = std::sqrt(sum_p / n), rms_r = std::sqrt(sum_r / n);
  std::printf("noisy sinusoid fit: residual rms %.3f mm %.3f deg; error to truth rms %.3f mm %.3f deg, max %.3f mm "
              "%.3f deg (%.3f mm %.3f deg around the gap)\n", 1e3 * report.position_rms_m, report.rotation_rms_deg,
              1e3 * rms_p, rms_r * 180 / M_PI, 1e3 * max_p, max_r * 180 / M_PI, 1e3 * gap_p, gap_r * 180 / M_PI);
  EXPECT_LT(rms_p, 0.6 * noise_p);
  EXPECT_LT(rms_r, 0.6 * noise_r);
  EXPECT_LT(max_p, 1.5 * noise_p);
  EXPECT_LT(max_r, 1.5 * noise_r);
  EXPECT_LT(gap_p, 2.5 * noise_p);
  EXPECT_LT(gap_r, 5.0 * noise_r);
}

TEST(SplineFit, DefaultSmoothingBarelyBiasesExactSamples) {
  // Exact samples of brisk motion (accelerations up to ~10 m/s^2, ~10 rad/s^2) at 200 Hz: the
  // default fit stays within 0.05 mm / 0.005 deg of the truth everywhere, a 50 ms hole included.
  const SinusoidTrajectory truth(lively_sinusoid(0));
  Trajectory samples;
  for (int64_t t = 0; t <= truth.t_end_ns(); t += 5000000)
    if (t <= 3000000000LL || t >= 3050000000LL) samples.push_back({t, truth.evaluate(t).T_w_b});
  const SplineTrajectory fitted = SplineTrajectory::fit(samples, SplineFitOptions());
  double max_p = 0, max_r = 0, max_v = 0, max_w = 0;
  for (int64_t t = 0; t <= truth.t_end_ns(); t += 1000000) {
    const TrajectoryState a = truth.evaluate(t);
    const TrajectoryState b = fitted.evaluate(t);
    max_p = std::max(max_p, (a.T_w_b.translation - b.T_w_b.translation).norm());
    max_r = std::max(max_r, a.T_w_b.rotation.angularDistance(b.T_w_b.rotation));
    max_v = std::max(max_v, (a.v_w - b.v_w).norm());
    max_w = std::max(max_w, (a.omega_b - b.omega_b).norm());
  }
  std::printf("exact sinusoid samples, default fit: max error %.4f mm %.5f deg, %.4f m/s %.4f rad/s\n", 1e3 * max_p,
              max_r * 180 / M_PI, max_v, max_w);
  EXPECT_LT(max_p, 0.05e-3);
  EXPECT_LT(max_r * 180 / M_PI, 0.005);
  EXPECT_LT(max_v, 0.03);  // largest at the ends of the range, where the penalty pulls hardest
  EXPECT_LT(max_w, 0.05);
}

TEST(SplineFit, RejectsTooFewSamples) {
  Trajectory few;
  for (int i = 0; i < 5; ++i) few.push_back({i * 100000000LL, calib::SE3()});
  SplineFitOptions f;
  f.knot_spacing_s = 0.01;
  f.smoothing = 0;  // 41 control points, 5 samples, nothing to bridge with
  EXPECT_THROW(SplineTrajectory::fit(few, f), std::invalid_argument);
  EXPECT_THROW(SplineTrajectory::fit(Trajectory({{0, calib::SE3()}}), SplineFitOptions()), std::invalid_argument);
  f.smoothing = 1e-8;  // the smoothing penalty pins the control points between samples
  EXPECT_NO_THROW(SplineTrajectory::fit(few, f));
  f.order = 3;
  EXPECT_THROW(SplineTrajectory::fit(few, f), std::invalid_argument);
}

struct Peaks {
  double omega = 0, alpha = 0, v = 0, a = 0;
};

Peaks peaks_at_1khz(const ContinuousTrajectory& traj) {
  Peaks p;
  for (int64_t t = traj.t_begin_ns(); t <= traj.t_end_ns(); t += 1000000) {
    const TrajectoryState s = traj.evaluate(t);
    p.omega = std::max(p.omega, s.omega_b.norm());
    p.alpha = std::max(p.alpha, s.alpha_b.norm());
    p.v = std::max(p.v, s.v_w.norm());
    p.a = std::max(p.a, s.a_w.norm());
  }
  return p;
}

// The third difference of samples at a constant period is dominated by white noise (the motion's
// own contribution is jerk * dt^3, ~0.01 mm at 5 ms): E|d3|^2 = 20 * (3D noise variance). Returns the
// 3D rms noise of positions (m) and rotations (rad), from runs of 4 samples 5 +- 0.1 ms apart.
std::pair<double, double> third_difference_noise(const Trajectory& m) {
  double sp = 0, sr = 0;
  size_t n = 0;
  for (size_t i = 0; i + 3 < m.size(); ++i) {
    bool regular = true;
    for (size_t j = i; j < i + 3; ++j) regular = regular && std::abs(m[j + 1].t_ns - m[j].t_ns - 5000000) < 100000;
    if (!regular) continue;
    const Vec3 d3 = m[i + 3].T_w_b.translation - 3 * m[i + 2].T_w_b.translation + 3 * m[i + 1].T_w_b.translation -
                    m[i].T_w_b.translation;
    Vec3 r[3];
    for (size_t j = 0; j < 3; ++j) r[j] = calib::so3_log(m[i + j].T_w_b.rotation.conjugate() * m[i + j + 1].T_w_b.rotation);
    sp += d3.squaredNorm();
    sr += (r[2] - 2 * r[1] + r[0]).squaredNorm();
    ++n;
  }
  return {std::sqrt(sp / n / 20), std::sqrt(sr / n / 20)};
}

TEST(SplineFit, MotionCaptureTrajectory) {
  const auto dir = evio_test::real_data_dir("trajectories");
  if (!dir) GTEST_SKIP() << "real data folder trajectories/ not found";
  const std::string path = *dir + "/poster_6dof_mocap.csv";
  if (!std::ifstream(path)) GTEST_SKIP() << path << " not found";
  const Trajectory mocap = read_euroc_csv(path);
  ASSERT_GT(mocap.size(), 10000u);
  const auto [noise_p, noise_r] = third_difference_noise(mocap);
  std::printf("mocap sample noise (third differences): 3D rms %.3f mm, %.3f deg\n", 1e3 * noise_p,
              noise_r * 180 / M_PI);

  // 1. Default fit (quintic, 20 ms knots): follows the motion; its residual is the capture noise.
  SplineFitReport report;
  const auto start = std::chrono::steady_clock::now();
  const SplineTrajectory fitted = SplineTrajectory::fit(mocap, SplineFitOptions(), &report);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const Peaks pk = peaks_at_1khz(fitted);
  std::printf("default fit: %s; %zu samples, %d iterations, %.2f s\n", fitted.describe().c_str(), report.samples,
              report.iterations, seconds);
  std::printf("  residual: position rms %.4f mm max %.4f mm; rotation rms %.4f deg max %.4f deg\n",
              1e3 * report.position_rms_m, 1e3 * report.position_max_m, report.rotation_rms_deg,
              report.rotation_max_deg);
  std::printf("  peaks (1 kHz): |omega| %.2f rad/s, |alpha| %.0f rad/s^2, |v| %.2f m/s, |a| %.1f m/s^2\n", pk.omega,
              pk.alpha, pk.v, pk.a);
  EXPECT_EQ(report.samples, mocap.size());
  EXPECT_LE(fitted.t_begin_ns(), mocap.t_begin_ns());
  EXPECT_GE(fitted.t_end_ns(), mocap.t_end_ns());
  // The residual matches the noise measured without any fit (within 10%).
  EXPECT_NEAR(report.position_rms_m / noise_p, 1.0, 0.1);
  EXPECT_NEAR(report.rotation_rms_deg * M_PI / 180 / noise_r, 1.0, 0.1);
  // Worst sample: an outlier at 31.095 s (4.9 deg, 9.8 mm off its neighbours).
  EXPECT_LT(report.position_max_m, 12e-3);
  EXPECT_LT(report.rotation_max_deg, 6.0);
  // Hand-held motion: peaks near the raw finite-difference rates (23 rad/s, 3.4 m/s incl. noise).
  EXPECT_GT(pk.omega, 10.0);
  EXPECT_LT(pk.omega, 25.0);
  EXPECT_GT(pk.v, 2.0);
  EXPECT_LT(pk.v, 4.0);

  // 2. Knots at the sample period (5 ms) interpolate: every sample within 1 mm / 0.1 deg, the
  // capture noise turning into motion (angular accelerations of ~1e4 rad/s^2).
  SplineFitOptions interp;
  interp.knot_spacing_s = 0.005;
  interp.smoothing = 1e-12;  // only to bridge the gaps
  SplineFitReport ri;
  const SplineTrajectory dense = SplineTrajectory::fit(mocap, interp, &ri);
  const Peaks pd = peaks_at_1khz(dense);
  std::printf("5 ms knots: %zu control points, %d iterations; residual position rms %.4f max %.4f mm; rotation rms "
              "%.5f max %.5f deg\n", ri.control_points, ri.iterations, 1e3 * ri.position_rms_m,
              1e3 * ri.position_max_m, ri.rotation_rms_deg, ri.rotation_max_deg);
  std::printf("  peaks (1 kHz): |omega| %.2f rad/s, |alpha| %.0f rad/s^2, |v| %.2f m/s, |a| %.1f m/s^2\n", pd.omega,
              pd.alpha, pd.v, pd.a);
  EXPECT_LT(ri.position_max_m, 1e-3);
  EXPECT_LT(ri.rotation_max_deg, 0.1);
}

}  // namespace
}  // namespace evio::simulator
