#include "evio/simulator/imu.h"

#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>

#include "sim_test_trajectories.h"

namespace evio::simulator {
namespace {

using calib::Quat;
using calib::Vec3;

using test::kLargeT0;
using test::lively_sinusoid;


SinusoidTrajectoryOptions still(int64_t t0, double duration_s) {
  SinusoidTrajectoryOptions o;
  o.t_begin_ns = t0;
  o.duration_s = duration_s;
  o.q_w_b0 = Quat(Eigen::AngleAxisd(0.4, Vec3(1, -1, 0).normalized()));
  return o;
}

calib::ImuNoise test_noise() {
  calib::ImuNoise n;
  n.gyroscope_noise_density = 2e-3;
  n.accelerometer_noise_density = 3e-2;
  n.gyroscope_random_walk = 4e-4;
  n.accelerometer_random_walk = 5e-3;
  n.update_rate_hz = 200;
  return n;
}

// Strapdown integration of IMU samples at 1 kHz with classical RK4 over steps of 2 ms (samples
// i, i+1, i+2 are the step's start, midpoint and end). State: q_w_b, v_w, p_w;
// q' = q (0, omega)/2, v' = R(q) f + g, p' = v.
struct NavState {
  Quat q;
  Vec3 v, p;
};

struct NavDerivative {
  Eigen::Vector4d q;  // (x, y, z, w) coefficients
  Vec3 v, p;
};

NavDerivative nav_derivative(const NavState& s, const ImuSample& m, const Vec3& g) {
  const Quat omega(0.0, m.gyro.x(), m.gyro.y(), m.gyro.z());
  NavDerivative d;
  d.q = 0.5 * (s.q * omega).coeffs();
  d.v = s.q.normalized() * m.accel + g;
  d.p = s.v;
  return d;
}

NavState nav_add(const NavState& s, const NavDerivative& d, double h) {
  NavState r;
  r.q.coeffs() = s.q.coeffs() + h * d.q;
  r.v = s.v + h * d.v;
  r.p = s.p + h * d.p;
  return r;
}

// Integrates from the true state at samples[0] and returns the largest position error (m) and
// rotation error (rad) against the trajectory at every step.
std::pair<double, double> integrate_and_compare(const ContinuousTrajectory& traj, const std::vector<ImuSample>& imu,
                                                const Vec3& g) {
  const TrajectoryState s0 = traj.evaluate(imu.front().t_ns);
  NavState s{s0.T_w_b.rotation, s0.v_w, s0.T_w_b.translation};
  double max_p = 0, max_r = 0;
  for (size_t i = 0; i + 2 < imu.size(); i += 2) {
    const double h = 1e-9 * static_cast<double>(imu[i + 2].t_ns - imu[i].t_ns);
    const NavDerivative k1 = nav_derivative(s, imu[i], g);
    const NavDerivative k2 = nav_derivative(nav_add(s, k1, h / 2), imu[i + 1], g);
    const NavDerivative k3 = nav_derivative(nav_add(s, k2, h / 2), imu[i + 1], g);
    const NavDerivative k4 = nav_derivative(nav_add(s, k3, h), imu[i + 2], g);
    NavDerivative sum;
    sum.q = k1.q + 2 * k2.q + 2 * k3.q + k4.q;
    sum.v = k1.v + 2 * k2.v + 2 * k3.v + k4.v;
    sum.p = k1.p + 2 * k2.p + 2 * k3.p + k4.p;
    s = nav_add(s, sum, h / 6);
    s.q.normalize();
    const TrajectoryState truth = traj.evaluate(imu[i + 2].t_ns);
    max_p = std::max(max_p, (s.p - truth.T_w_b.translation).norm());
    max_r = std::max(max_r, s.q.angularDistance(truth.T_w_b.rotation));
  }
  return {max_p, max_r};
}

TEST(IdealImu, SpecificForceAndRate) {
  TrajectoryState st;
  st.t_ns = 5;
  st.T_w_b = calib::SE3(Quat(Eigen::AngleAxisd(M_PI / 2, Vec3::UnitX())), Vec3(1, 2, 3));
  st.a_w = Vec3(1, 0, 0);
  st.omega_b = Vec3(0.1, 0.2, 0.3);
  const ImuSample m = ideal_imu(st, Vec3(0, 0, -9.81));
  EXPECT_EQ(m.t_ns, 5);
  EXPECT_EQ(m.gyro, st.omega_b);
  // R = Rx(90 deg) maps body y to world z: the upward specific force 9.81 reads on body y;
  // world x acceleration stays on body x.
  EXPECT_LT((m.accel - Vec3(1, 9.81, 0)).norm(), 1e-14);
}

TEST(SimulateImu, IdealSamplesIntegrateBackToTheSinusoid) {
  const SinusoidTrajectory traj(lively_sinusoid(kLargeT0));
  ImuSimOptions o;
  o.enable_noise = false;
  const std::vector<ImuSample> imu = simulate_imu(traj, traj.t_begin_ns(), traj.t_end_ns(), o);
  ASSERT_EQ(imu.size(), 10001u);
  const auto [dp, dr] = integrate_and_compare(traj, imu, o.gravity_w);
  std::printf("sinusoid, 10 s at 1 kHz, RK4: position drift %.3g m, rotation drift %.3g rad\n", dp, dr);
  // Acceptance: under 1 mm over 10 s. Measured 1e-8 m (sinusoid) and 2e-7 m (spline): the tighter bound catches small errors.
  EXPECT_LT(dp, 1e-3);
  EXPECT_LT(dp, 1e-5);
  EXPECT_LT(dr, 1e-7);
}

TEST(SimulateImu, IdealSamplesIntegrateBackToARandomSpline) {
  RandomSplineOptions so;
  so.t_begin_ns = kLargeT0;
  so.duration_s = 10.0;
  so.order = 6;
  so.knot_spacing_s = 0.15;  // agile: peaks of ~10 rad/s and ~40 m/s^2
  so.position_std_m = Vec3(0.3, 0.3, 0.2);
  so.rotation_std_rad = 0.5;
  so.seed = 21;
  const SplineTrajectory traj = SplineTrajectory::random(so);
  ImuSimOptions o;
  o.enable_noise = false;
  const std::vector<ImuSample> imu = simulate_imu(traj, kLargeT0, kLargeT0 + 10000000000LL, o);
  ASSERT_EQ(imu.size(), 10001u);
  double peak_w = 0;
  for (const ImuSample& m : imu) peak_w = std::max(peak_w, m.gyro.norm());
  EXPECT_GT(peak_w, 5.0);  // the motion is agile enough to matter
  const auto [dp, dr] = integrate_and_compare(traj, imu, o.gravity_w);
  std::printf("random spline, 10 s at 1 kHz, RK4: position drift %.3g m, rotation drift %.3g rad (peak |w| %.2f)\n",
              dp, dr, peak_w);
  // Acceptance: under 1 mm over 10 s. Measured 1e-8 m (sinusoid) and 2e-7 m (spline): the tighter bound catches small errors.
  EXPECT_LT(dp, 1e-3);
  EXPECT_LT(dp, 1e-5);
  EXPECT_LT(dr, 1e-7);
}

TEST(SimulateImu, WrongGravityOrBiasIsDetectedByTheIntegration) {
  // The integration check can fail: a 1e-3 m/s^2 accelerometer bias drifts 0.05 m in 10 s.
  const SinusoidTrajectory traj(lively_sinusoid(0));
  ImuSimOptions o;
  o.enable_noise = false;
  o.initial_bias_accel_mps2 = Vec3(1e-3, 0, 0);
  const std::vector<ImuSample> imu = simulate_imu(traj, 0, traj.t_end_ns(), o);
  EXPECT_GT(integrate_and_compare(traj, imu, o.gravity_w).first, 1e-2);
}

TEST(SimulateImu, SampleTimesAndConstantBiasesWithoutNoise) {
  const SinusoidTrajectory traj(lively_sinusoid(kLargeT0));
  ImuSimOptions o;
  o.rate_hz = 300.0;  // period round(1e9 / 300) = 3333333 ns
  o.enable_noise = false;
  o.initial_bias_gyro_radps = Vec3(0.01, -0.02, 0.03);
  o.initial_bias_accel_mps2 = Vec3(-0.1, 0.2, 0.05);
  std::vector<ImuBiasSample> biases;
  const int64_t t1 = kLargeT0 + 1000000000;
  const std::vector<ImuSample> imu = simulate_imu(traj, kLargeT0, t1, o, &biases);
  ASSERT_EQ(imu.size(), 301u);  // 300 * 3333333 = 999999900 <= 1 s
  ASSERT_EQ(biases.size(), imu.size());
  for (size_t i = 0; i < imu.size(); ++i) {
    EXPECT_EQ(imu[i].t_ns, kLargeT0 + static_cast<int64_t>(i) * 3333333);
    EXPECT_EQ(biases[i].t_ns, imu[i].t_ns);
    EXPECT_EQ(biases[i].gyro, o.initial_bias_gyro_radps);
    EXPECT_EQ(biases[i].accel, o.initial_bias_accel_mps2);
    const ImuSample ideal = ideal_imu(traj.evaluate(imu[i].t_ns), o.gravity_w);
    EXPECT_LT((imu[i].gyro - ideal.gyro - o.initial_bias_gyro_radps).norm(), 1e-15);
    EXPECT_LT((imu[i].accel - ideal.accel - o.initial_bias_accel_mps2).norm(), 1e-14);
  }
  EXPECT_THROW(simulate_imu(traj, kLargeT0 - 1, t1, o), std::out_of_range);
  EXPECT_THROW(simulate_imu(traj, kLargeT0, traj.t_end_ns() + 1, o), std::out_of_range);
  o.rate_hz = 0;
  EXPECT_THROW(simulate_imu(traj, kLargeT0, t1, o), std::invalid_argument);
}

TEST(SimulateImu, GapsLeaveSamplesOutAndTheOthersUnchanged) {
  const SinusoidTrajectory traj(lively_sinusoid(kLargeT0));
  ImuSimOptions o;
  o.rate_hz = 1000.0;
  const int64_t t1 = kLargeT0 + 1000000000;
  const std::vector<ImuSample> all = simulate_imu(traj, kLargeT0, t1, o);
  ASSERT_EQ(all.size(), 1001u);
  o.gaps_ns = {{kLargeT0 + 300000000, kLargeT0 + 500000000}, {kLargeT0 + 100000000, kLargeT0 + 100000001}};
  const std::vector<ImuSample> gappy = simulate_imu(traj, kLargeT0, t1, o);
  ASSERT_EQ(gappy.size(), 1001u - 200u - 1u);  // [0.3, 0.5) s: 200 samples; the one at 0.1 s
  size_t j = 0;
  for (const ImuSample& s : all) {
    const int64_t t = s.t_ns - kLargeT0;
    if ((t >= 300000000 && t < 500000000) || t == 100000000) continue;
    ASSERT_LT(j, gappy.size());
    EXPECT_EQ(gappy[j].t_ns, s.t_ns);
    EXPECT_EQ(gappy[j].gyro, s.gyro);  // the noise ran on through the gaps
    EXPECT_EQ(gappy[j].accel, s.accel);
    ++j;
  }
  o.gaps_ns = {{kLargeT0 + 5, kLargeT0 + 5}};
  EXPECT_THROW(simulate_imu(traj, kLargeT0, t1, o), std::invalid_argument);
}

TEST(SimulateImu, WhiteNoiseMatchesTheKalibrDiscreteModel) {
  const SinusoidTrajectory traj(still(0, 50.0));
  ImuSimOptions o;
  o.rate_hz = 200.0;
  o.noise = test_noise();
  o.seed = 5;
  std::vector<ImuBiasSample> biases;
  const std::vector<ImuSample> imu = simulate_imu(traj, 0, traj.t_end_ns(), o, &biases);
  ASSERT_EQ(imu.size(), 10001u);
  const double dt = 0.005;
  // White noise = measurement - ideal - true bias; bias steps = consecutive bias differences.
  double sg = 0, sa = 0, mg = 0, ma = 0, sbg = 0, sba = 0;
  size_t nw = 0, nb = 0;
  for (size_t i = 0; i < imu.size(); ++i) {
    const ImuSample ideal = ideal_imu(traj.evaluate(imu[i].t_ns), o.gravity_w);
    const Vec3 ng = imu[i].gyro - ideal.gyro - biases[i].gyro;
    const Vec3 na = imu[i].accel - ideal.accel - biases[i].accel;
    sg += ng.squaredNorm();
    sa += na.squaredNorm();
    mg += ng.sum();
    ma += na.sum();
    nw += 3;
    if (i > 0) {
      sbg += (biases[i].gyro - biases[i - 1].gyro).squaredNorm();
      sba += (biases[i].accel - biases[i - 1].accel).squaredNorm();
      nb += 3;
    }
  }
  const double nwd = static_cast<double>(nw), nbd = static_cast<double>(nb);
  // 30000 draws: the sample std is within ~0.4% (1 sigma) of the truth; allow 3%.
  EXPECT_NEAR(std::sqrt(sg / nwd) / (o.noise.gyroscope_noise_density / std::sqrt(dt)), 1.0, 0.03);
  EXPECT_NEAR(std::sqrt(sa / nwd) / (o.noise.accelerometer_noise_density / std::sqrt(dt)), 1.0, 0.03);
  EXPECT_NEAR(std::sqrt(sbg / nbd) / (o.noise.gyroscope_random_walk * std::sqrt(dt)), 1.0, 0.03);
  EXPECT_NEAR(std::sqrt(sba / nbd) / (o.noise.accelerometer_random_walk * std::sqrt(dt)), 1.0, 0.03);
  // Zero mean (standard error of the mean ~ sigma / sqrt(30000) = 0.006 sigma).
  EXPECT_LT(std::abs(mg / nwd), 0.03 * o.noise.gyroscope_noise_density / std::sqrt(dt));
  EXPECT_LT(std::abs(ma / nwd), 0.03 * o.noise.accelerometer_noise_density / std::sqrt(dt));
}

TEST(SimulateImu, BiasRandomWalkVarianceGrowsLinearly) {
  // Var(b(t) - b(0)) = sigma_b^2 t, estimated over 400 seeds x 3 axes at t = 0.5 s and 1 s.
  const SinusoidTrajectory traj(still(0, 1.0));
  ImuSimOptions o;
  o.rate_hz = 200.0;
  o.noise = test_noise();
  o.initial_bias_gyro_radps = Vec3(0.1, 0.2, 0.3);
  double vg_half = 0, vg_end = 0, va_end = 0;
  size_t n = 0;
  for (uint64_t seed = 1; seed <= 400; ++seed) {
    o.seed = seed;
    std::vector<ImuBiasSample> b;
    simulate_imu(traj, 0, traj.t_end_ns(), o, &b);
    ASSERT_EQ(b.size(), 201u);
    EXPECT_EQ(b[0].gyro, o.initial_bias_gyro_radps);
    vg_half += (b[100].gyro - b[0].gyro).squaredNorm();
    vg_end += (b[200].gyro - b[0].gyro).squaredNorm();
    va_end += (b[200].accel - b[0].accel).squaredNorm();
    n += 3;
  }
  const double nd = static_cast<double>(n);
  const double sg2 = std::pow(o.noise.gyroscope_random_walk, 2);
  const double sa2 = std::pow(o.noise.accelerometer_random_walk, 2);
  // 1200 samples of a chi-square: relative std of the variance estimate sqrt(2/1200) = 4%; allow 15%.
  EXPECT_NEAR(vg_half / nd / (sg2 * 0.5), 1.0, 0.15);
  EXPECT_NEAR(vg_end / nd / (sg2 * 1.0), 1.0, 0.15);
  EXPECT_NEAR(va_end / nd / (sa2 * 1.0), 1.0, 0.15);
}

TEST(SimulateImu, DeterministicPerSeed) {
  const SinusoidTrajectory traj(lively_sinusoid(0));
  ImuSimOptions o;
  o.noise = test_noise();
  o.seed = 77;
  std::vector<ImuBiasSample> ba, bb;
  const auto a = simulate_imu(traj, 0, 1000000000, o, &ba);
  const auto b = simulate_imu(traj, 0, 1000000000, o, &bb);
  o.seed = 78;
  const auto c = simulate_imu(traj, 0, 1000000000, o);
  ASSERT_EQ(a.size(), b.size());
  ASSERT_EQ(a.size(), c.size());
  double diff_c = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].gyro, b[i].gyro);
    EXPECT_EQ(a[i].accel, b[i].accel);
    EXPECT_EQ(ba[i].accel, bb[i].accel);
    diff_c += (a[i].gyro - c[i].gyro).norm();
  }
  EXPECT_GT(diff_c, 0.1);
}

TEST(SimulateImu, LargeTimestampsGiveTheShiftedSamples) {
  const SinusoidTrajectory a(lively_sinusoid(0));
  const SinusoidTrajectory b(lively_sinusoid(kLargeT0));
  ImuSimOptions o;
  o.noise = test_noise();
  const auto ia = simulate_imu(a, 0, 2000000000, o);
  const auto ib = simulate_imu(b, kLargeT0, kLargeT0 + 2000000000, o);
  ASSERT_EQ(ia.size(), ib.size());
  for (size_t i = 0; i < ia.size(); ++i) {
    EXPECT_EQ(ib[i].t_ns - kLargeT0, ia[i].t_ns);
    EXPECT_EQ(ia[i].gyro, ib[i].gyro);
    EXPECT_EQ(ia[i].accel, ib[i].accel);
  }
}

}  // namespace
}  // namespace evio::simulator
