// ImuPreintegration against the simulator's exact trajectory: deltas vs true relative motion
// (on and off sample times, t0 = 0 and t0 = 1.7e18 ns), bias Jacobians vs numeric re-integration,
// first-order bias correction, covariance vs a Monte Carlo of noisy IMU, edge cases.
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <vector>

#include <Eigen/Eigenvalues>
#include <gtest/gtest.h>

#include "evio/backend/imu_preintegration.h"
#include "evio/calib/geometry.h"
#include "evio/simulator/imu.h"
#include "evio/simulator/trajectory.h"
#include "imu_test_scenario.h"

namespace evio::backend {
namespace {

using test_scenario::ideal_samples;
using test_scenario::kGravity;
using test_scenario::test_noise;
simulator::SinusoidTrajectory make_trajectory(int64_t t_begin_ns) {
  return test_scenario::make_trajectory(t_begin_ns, 4.0, true);
}

using calib::so3_log;
using Eigen::Matrix3d;
using Eigen::Vector3d;

struct DeltaErrors {
  double rot_rad, vel_mps, pos_m;
};

DeltaErrors errors_vs_truth(const ImuPreintegration& pre, const simulator::ContinuousTrajectory& traj) {
  const simulator::TrajectoryState si = traj.evaluate(pre.t_i_ns());
  const simulator::TrajectoryState sj = traj.evaluate(pre.t_j_ns());
  const double dt = static_cast<double>(pre.t_j_ns() - pre.t_i_ns()) * 1e-9;
  const Matrix3d Ri = si.T_w_b.rotation_matrix();
  const Matrix3d dR_true = Ri.transpose() * sj.T_w_b.rotation_matrix();
  const Vector3d dv_true = Ri.transpose() * (sj.v_w - si.v_w - kGravity * dt);
  const Vector3d dp_true =
      Ri.transpose() * (sj.T_w_b.translation - si.T_w_b.translation - si.v_w * dt - 0.5 * kGravity * dt * dt);
  return {so3_log(Matrix3d(dR_true.transpose() * pre.delta_R())).norm(), (pre.delta_v() - dv_true).norm(),
          (pre.delta_p() - dp_true).norm()};
}

TEST(ImuPreintegration, DeltasMatchTrueRelativeMotion) {
  const auto traj = make_trajectory(0);
  const int64_t t_i = 500'000'000, t_j = 1'500'000'000;  // 1 s on sample times
  for (const int64_t rate_hz : {200, 1000, 10000}) {
    const int64_t period = 1'000'000'000 / rate_hz;
    const auto samples = ideal_samples(traj, 0, 2'000'000'000, period);
    const auto pre = ImuPreintegration::between(samples, t_i, t_j, Vector3d::Zero(), Vector3d::Zero(), test_noise());
    EXPECT_NEAR(pre.dt_s(), 1.0, 1e-15);
    const DeltaErrors e = errors_vs_truth(pre, traj);
    std::printf("rate %5lld Hz, 1 s on samples: |dR err| %.3e rad  |dv err| %.3e m/s  |dp err| %.3e m\n",
                static_cast<long long>(rate_hz), e.rot_rad, e.vel_mps, e.pos_m);
    // Trapezoidal/midpoint scheme: error O(h^2). Bounds ~3x the measured errors.
    const double bound = rate_hz == 10000 ? 1e-6 : (rate_hz == 1000 ? 1e-5 : 3e-4);
    EXPECT_LT(e.rot_rad, bound) << rate_hz;
    EXPECT_LT(e.vel_mps, bound) << rate_hz;
    EXPECT_LT(e.pos_m, bound) << rate_hz;
  }
}

TEST(ImuPreintegration, OffSampleEndpointsAndLargeTimestamps) {
  const int64_t period = 100'000;  // 10 kHz
  const int64_t off_i = 500'037'123, off_j = 1'734'567'891;  // not on sample times
  std::vector<ImuPreintegration> results;
  for (const int64_t t0 : {int64_t{0}, int64_t{1'700'000'000'000'000'000}}) {
    const auto traj = make_trajectory(t0);
    const auto samples = ideal_samples(traj, t0, t0 + 2'000'000'000, period);
    const auto pre =
        ImuPreintegration::between(samples, t0 + off_i, t0 + off_j, Vector3d::Zero(), Vector3d::Zero(), test_noise());
    EXPECT_EQ(pre.t_i_ns(), t0 + off_i);
    EXPECT_EQ(pre.t_j_ns(), t0 + off_j);
    EXPECT_DOUBLE_EQ(pre.dt_s(), (off_j - off_i) * 1e-9);
    const DeltaErrors e = errors_vs_truth(pre, traj);
    std::printf("t0 %lld ns, off-sample 10 kHz: |dR err| %.3e rad  |dv err| %.3e m/s  |dp err| %.3e m\n",
                static_cast<long long>(t0), e.rot_rad, e.vel_mps, e.pos_m);
    EXPECT_LT(e.rot_rad, 1e-6);
    EXPECT_LT(e.vel_mps, 1e-6);
    EXPECT_LT(e.pos_m, 1e-6);
    EXPECT_TRUE(pre.covariance().allFinite());
    results.push_back(pre);
  }
  // Same numbers at t0 = 0 and t0 = 1.7e18 ns: only int64 differences enter the arithmetic.
  EXPECT_LT((results[0].delta_R() - results[1].delta_R()).cwiseAbs().maxCoeff(), 1e-14);
  EXPECT_LT((results[0].delta_v() - results[1].delta_v()).cwiseAbs().maxCoeff(), 1e-14);
  EXPECT_LT((results[0].delta_p() - results[1].delta_p()).cwiseAbs().maxCoeff(), 1e-14);
  EXPECT_LT((results[0].covariance() - results[1].covariance()).cwiseAbs().maxCoeff(),
            1e-12 * results[0].covariance().cwiseAbs().maxCoeff());
}

TEST(ImuPreintegration, BiasJacobiansMatchNumericReintegration) {
  const auto traj = make_trajectory(0);
  const auto samples = ideal_samples(traj, 0, 2'000'000'000, 1'000'000);  // 1 kHz
  const Vector3d bg0(0.01, -0.02, 0.015), ba0(0.1, 0.05, -0.2);
  const auto pre = ImuPreintegration::between(samples, 300'000'500, 1'300'250'000, bg0, ba0, test_noise());
  // Central differences of full re-integration, step 1e-6.
  const double eps = 1e-6;
  Eigen::Matrix<double, 9, 6> J_num;
  for (int c = 0; c < 6; ++c) {
    Vector3d dbg = Vector3d::Zero(), dba = Vector3d::Zero();
    (c < 3 ? dbg[c] : dba[c - 3]) = eps;
    ImuPreintegration plus = pre, minus = pre;
    plus.reintegrate(bg0 + dbg, ba0 + dba);
    minus.reintegrate(bg0 - dbg, ba0 - dba);
    J_num.block<3, 1>(0, c) = (so3_log(Matrix3d(pre.delta_R().transpose() * plus.delta_R())) -
                               so3_log(Matrix3d(pre.delta_R().transpose() * minus.delta_R()))) /
                              (2 * eps);
    J_num.block<3, 1>(3, c) = (plus.delta_v() - minus.delta_v()) / (2 * eps);
    J_num.block<3, 1>(6, c) = (plus.delta_p() - minus.delta_p()) / (2 * eps);
  }
  const double err = (J_num - pre.bias_jacobian()).cwiseAbs().maxCoeff();
  const double scale = pre.bias_jacobian().cwiseAbs().maxCoeff();
  std::printf("bias Jacobian: max |analytic - numeric| %.3e (max |J| %.3f)\n", err, scale);
  EXPECT_LT(err, 1e-7 * scale);
  EXPECT_LT((pre.bias_jacobian().block<3, 3>(0, 3).norm()), 1e-15);  // rotation does not depend on b_a
}

TEST(ImuPreintegration, FirstOrderBiasCorrectionMatchesReintegration) {
  const auto traj = make_trajectory(0);
  const auto samples = ideal_samples(traj, 0, 2'000'000'000, 1'000'000);
  const Vector3d bg0(0.01, -0.02, 0.015), ba0(0.1, 0.05, -0.2);
  const auto pre = ImuPreintegration::between(samples, 300'000'000, 1'300'000'000, bg0, ba0, test_noise());
  const Vector3d dbg(1e-3, -1e-3, 1e-3), dba(1e-2, -1e-2, 1e-2);
  ImuPreintegration re = pre;
  re.reintegrate(bg0 + dbg, ba0 + dba);
  const double rot_err = so3_log(pre.corrected_delta_q(bg0 + dbg).conjugate() * re.delta_q()).norm();
  const double vel_err = (pre.corrected_delta_v(bg0 + dbg, ba0 + dba) - re.delta_v()).norm();
  const double pos_err = (pre.corrected_delta_p(bg0 + dbg, ba0 + dba) - re.delta_p()).norm();
  // Size of the change itself (what no correction would leave).
  const double rot_change = so3_log(pre.delta_q().conjugate() * re.delta_q()).norm();
  const double vel_change = (pre.delta_v() - re.delta_v()).norm();
  const double pos_change = (pre.delta_p() - re.delta_p()).norm();
  std::printf("1 s, db_g = 1e-3 rad/s, db_a = 1e-2 m/s^2 per axis: first-order error rot %.3e rad (change %.3e), "
              "vel %.3e m/s (change %.3e), pos %.3e m (change %.3e)\n",
              rot_err, rot_change, vel_err, vel_change, pos_err, pos_change);
  EXPECT_LT(rot_err, 1e-3 * rot_change);
  EXPECT_LT(vel_err, 1e-2 * vel_change);
  EXPECT_LT(pos_err, 1e-2 * pos_change);
  // Re-integration at the original biases restores the original deltas.
  re.reintegrate(bg0, ba0);
  EXPECT_LT((re.delta_R() - pre.delta_R()).cwiseAbs().maxCoeff(), 1e-15);
  EXPECT_LT((re.delta_p() - pre.delta_p()).cwiseAbs().maxCoeff(), 1e-15);
}

TEST(ImuPreintegration, CovarianceSymmetricPositiveDefiniteAndGrowing) {
  const auto traj = make_trajectory(0);
  const auto samples = ideal_samples(traj, 0, 3'000'000'000, 5'000'000);  // 200 Hz
  Eigen::Matrix<double, 9, 9> prev = Eigen::Matrix<double, 9, 9>::Zero();
  for (const int64_t len : {100'000'000, 250'000'000, 500'000'000, 1'000'000'000, 2'000'000'000}) {
    const auto pre = ImuPreintegration::between(samples, 400'000'000, 400'000'000 + len, Vector3d::Zero(),
                                                Vector3d::Zero(), test_noise());
    const auto& P = pre.covariance();
    EXPECT_TRUE(P.allFinite());
    EXPECT_LT((P - P.transpose()).cwiseAbs().maxCoeff(), 1e-15 * P.cwiseAbs().maxCoeff());
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 9, 9>> eig(P);
    EXPECT_GT(eig.eigenvalues().minCoeff(), 0.0) << len;
    for (int k = 0; k < 9; ++k) EXPECT_GT(P(k, k), prev(k, k)) << "entry " << k << " length " << len;
    // Leading order: rotation variance ~ sigma_g^2 dt.
    const double dt = pre.dt_s();
    const double sg = test_noise().gyroscope_noise_density;
    EXPECT_NEAR(P(0, 0) / (sg * sg * dt), 1.0, 1e-6);
    prev = P;
  }
}

TEST(ImuPreintegration, CovarianceMatchesMonteCarlo) {
  const auto traj = make_trajectory(0);
  calib::ImuNoise noise;
  noise.gyroscope_noise_density = 0.01;      // large enough to dominate, small enough to stay linear
  noise.accelerometer_noise_density = 0.05;
  noise.gyroscope_random_walk = 0;            // biases constant: the 9x9 covariance covers white noise only
  noise.accelerometer_random_walk = 0;
  noise.update_rate_hz = 200;
  const int64_t t_i = 500'002'000, t_j = 1'000'001'000;  // ~0.5 s, off the 200 Hz grid
  const Vector3d zero = Vector3d::Zero();
  simulator::ImuSimOptions o;
  o.rate_hz = 200;
  o.noise = noise;
  o.enable_noise = false;
  const auto nominal_samples = simulator::simulate_imu(traj, 0, 1'500'000'000, o);
  const auto nominal = ImuPreintegration::between(nominal_samples, t_i, t_j, zero, zero, noise);
  const Eigen::Matrix<double, 9, 9> P = nominal.covariance();
  const Eigen::Matrix<double, 9, 9> P_inv = P.inverse();

  const int runs = 500;
  Eigen::Matrix<double, 9, 9> C = Eigen::Matrix<double, 9, 9>::Zero();
  double nees = 0;
  o.enable_noise = true;
  for (int r = 0; r < runs; ++r) {
    o.seed = 1000 + r;
    const auto samples = simulator::simulate_imu(traj, 0, 1'500'000'000, o);
    const auto pre = ImuPreintegration::between(samples, t_i, t_j, zero, zero, noise);
    Eigen::Matrix<double, 9, 1> e;
    e << so3_log(nominal.delta_q().conjugate() * pre.delta_q()), pre.delta_v() - nominal.delta_v(),
        pre.delta_p() - nominal.delta_p();
    C += e * e.transpose() / runs;
    nees += e.dot(P_inv * e) / runs;
  }
  double worst = 0;
  for (int k = 0; k < 9; ++k) {
    const double ratio = std::sqrt(C(k, k) / P(k, k));
    worst = std::max(worst, std::abs(ratio - 1.0));
    EXPECT_NEAR(ratio, 1.0, 0.12) << "std ratio, entry " << k;
  }
  std::printf("Monte Carlo (%d runs, 0.5 s at 200 Hz): worst |std_MC / std_pred - 1| = %.3f, mean NEES %.3f (dof 9)\n",
              runs, worst, nees);
  EXPECT_NEAR(nees, 9.0, 1.0);
}

TEST(ImuPreintegration, ZeroLengthIntervalIsIdentity) {
  for (const int64_t t0 : {int64_t{0}, int64_t{1'700'000'000'000'000'000}}) {
    const auto traj = make_trajectory(t0);
    const auto samples = ideal_samples(traj, t0, t0 + 100'000'000, 5'000'000);
    for (const int64_t t : {t0 + 20'000'000, t0 + 22'345'678}) {
      const auto pre = ImuPreintegration::between(samples, t, t, Vector3d(0.1, 0, 0), Vector3d(0, 0.2, 0), test_noise());
      EXPECT_EQ(pre.dt_s(), 0.0);
      EXPECT_EQ(pre.t_i_ns(), t);
      EXPECT_EQ(pre.t_j_ns(), t);
      EXPECT_TRUE(pre.delta_R().isIdentity(0.0));
      EXPECT_TRUE(pre.delta_v().isZero(0.0));
      EXPECT_TRUE(pre.delta_p().isZero(0.0));
      EXPECT_TRUE(pre.covariance().isZero(0.0));
      EXPECT_TRUE(pre.bias_jacobian().isZero(0.0));
      EXPECT_TRUE(pre.corrected_delta_q(Vector3d(0.2, 0, 0)).coeffs().allFinite());
    }
  }
}

TEST(ImuPreintegration, GapIntegratesWithBracketingSamplesAndEndsMustBeBracketed) {
  const auto traj = make_trajectory(0);
  const int64_t period = 100'000;  // 10 kHz, with a hole (100.00, 100.05) ms
  std::vector<ImuSample> samples;
  for (const auto& s : ideal_samples(traj, 0, 200'000'000, period))
    if (s.t_ns <= 100'000'000 || s.t_ns >= 100'050'000) samples.push_back(s);
  const auto pre =
      ImuPreintegration::between(samples, 100'010'000, 100'040'000, Vector3d::Zero(), Vector3d::Zero(), test_noise());
  EXPECT_EQ(pre.knots().size(), 2u);  // the two interpolated end points
  const DeltaErrors e = errors_vs_truth(pre, traj);
  EXPECT_LT(e.rot_rad, 1e-9);
  EXPECT_LT(e.vel_mps, 1e-8);
  EXPECT_LT(e.pos_m, 1e-10);
  // Interval across the hole: still integrated (one long segment in the middle).
  const auto across =
      ImuPreintegration::between(samples, 90'000'000, 110'000'000, Vector3d::Zero(), Vector3d::Zero(), test_noise());
  EXPECT_LT(errors_vs_truth(across, traj).vel_mps, 1e-6);
  // No sample at or before t_i / at or after t_j: clear error, no extrapolation.
  EXPECT_THROW(ImuPreintegration::between(samples, -1, 50'000'000, Vector3d::Zero(), Vector3d::Zero(), test_noise()),
               std::invalid_argument);
  EXPECT_THROW(ImuPreintegration::between(samples, 0, 200'000'001, Vector3d::Zero(), Vector3d::Zero(), test_noise()),
               std::invalid_argument);
  EXPECT_THROW(ImuPreintegration::between(samples, 50, 40, Vector3d::Zero(), Vector3d::Zero(), test_noise()),
               std::invalid_argument);
  EXPECT_THROW(ImuPreintegration::between({}, 0, 0, Vector3d::Zero(), Vector3d::Zero(), test_noise()),
               std::invalid_argument);
  EXPECT_THROW(ImuPreintegration(Vector3d::Zero(), Vector3d::Zero(), calib::ImuNoise{}), std::invalid_argument);
}

TEST(ImuPreintegration, UnsortedSamplesInTheIntervalAreRejected) {
  std::vector<ImuSample> samples;
  for (int k = 0; k <= 100; ++k) {
    ImuSample m;
    m.t_ns = k * 1'000'000;
    m.accel = Vector3d(0, 0, 9.81);
    samples.push_back(m);
  }
  std::swap(samples[50].t_ns, samples[51].t_ns);  // out of order inside [40, 60] ms
  EXPECT_THROW(ImuPreintegration::between(samples, 40'000'000, 60'000'000, Vector3d::Zero(), Vector3d::Zero(), test_noise()),
               std::invalid_argument);
  // An interval that does not use them integrates normally.
  const auto pre = ImuPreintegration::between(samples, 0, 20'000'000, Vector3d::Zero(), Vector3d::Zero(), test_noise());
  EXPECT_NEAR(pre.dt_s(), 0.02, 1e-12);
}

}  // namespace
}  // namespace evio::backend
