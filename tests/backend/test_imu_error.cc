// PoseManifold (Ceres manifold invariants) and ImuError: analytic Jacobians vs ceres::GradientChecker
// at random states, zero residual at the true states from a noise-free IMU, ambient lifting
// (J_ambient * PlusJacobian = J_tangent), and a small Ceres solve that recovers state j.
#include <cmath>
#include <cstdio>
#include <random>
#include <stdexcept>
#include <vector>

#include <gtest/gtest.h>

#include "ceres/ceres.h"
#include "ceres/gradient_checker.h"
#include "ceres/manifold_test_utils.h"
#include "evio/backend/imu_error.h"
#include "evio/backend/imu_preintegration.h"
#include "evio/backend/pose_manifold.h"
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
  return test_scenario::make_trajectory(t_begin_ns, 3.0, false);
}

using Eigen::Matrix3d;
using Eigen::Vector3d;
using Vec7 = Eigen::Matrix<double, 7, 1>;
using Vec9 = Eigen::Matrix<double, 9, 1>;

Vec7 pose_block(const calib::SE3& T) {
  Vec7 x;
  x.head<4>() = T.rotation.coeffs();
  x.tail<3>() = T.translation;
  return x;
}

Vec9 speed_bias_block(const Vector3d& v, const Vector3d& bg, const Vector3d& ba) {
  Vec9 x;
  x << v, bg, ba;
  return x;
}

Vec7 random_pose(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Vec7 x;
  Eigen::Quaterniond q(n(rng), n(rng), n(rng), n(rng));
  q.normalize();
  x.head<4>() = q.coeffs();
  x.tail<3>() = Vector3d(n(rng), n(rng), n(rng));
  return x;
}

TEST(PoseManifold, CeresManifoldInvariantsHold) {
  using namespace ceres;  // the matchers of manifold_test_utils.h
  std::mt19937 rng(7);
  std::normal_distribution<double> n(0.0, 1.0);
  const PoseManifold manifold;
  for (int trial = 0; trial < 20; ++trial) {
    const Vector x = random_pose(rng);
    const Vector y = random_pose(rng);
    Vector delta(6);
    for (int k = 0; k < 6; ++k) delta[k] = n(rng);
    // Keep |dtheta| < pi so Minus(Plus(x, d), x) = d holds (Log returns angles up to 2 pi here).
    if (delta.head<3>().norm() > 3.0) delta.head<3>() *= 3.0 / delta.head<3>().norm();
    const double tolerance = 1e-9;
    EXPECT_THAT_MANIFOLD_INVARIANTS_HOLD(manifold, x, delta, y, tolerance);
  }
}

TEST(PoseManifold, PlusFollowsTheDocumentedConvention) {
  std::mt19937 rng(3);
  const Vec7 x = random_pose(rng);
  Eigen::Matrix<double, 6, 1> d;
  d << 0.1, -0.2, 0.3, 1.0, 2.0, 3.0;
  Vec7 y;
  PoseManifold().Plus(x.data(), d.data(), y.data());
  const Eigen::Quaterniond q(x[3], x[0], x[1], x[2]);
  const Matrix3d expected = q.toRotationMatrix() * calib::so3_exp(d.head<3>());
  EXPECT_LT((Eigen::Quaterniond(y[3], y[0], y[1], y[2]).toRotationMatrix() - expected).cwiseAbs().maxCoeff(), 1e-15);
  EXPECT_LT((y.tail<3>() - x.tail<3>() - d.tail<3>()).norm(), 1e-15);
  // MinusJacobian is the pseudo-inverse of PlusJacobian also for a non-unit quaternion.
  Vec7 x2 = x;
  x2.head<4>() *= 1.7;
  const Eigen::Matrix<double, 6, 6> I = PoseManifold::minus_jacobian(x2.data()) * PoseManifold::plus_jacobian(x2.data());
  EXPECT_LT((I - Eigen::Matrix<double, 6, 6>::Identity()).cwiseAbs().maxCoeff(), 1e-15);
}

// Preintegration over [0.5 s, 1.3 s] from a noise-free 10 kHz IMU with constant biases.
struct Scenario {
  simulator::SinusoidTrajectory traj = make_trajectory(0);
  Vector3d bg_true = Vector3d(0.01, -0.02, 0.005);
  Vector3d ba_true = Vector3d(0.05, 0.1, -0.08);
  int64_t t_i = 500'000'123, t_j = 1'300'000'456;
  std::vector<ImuSample> samples = ideal_samples(traj, 0, 2'000'000'000, 100'000, bg_true, ba_true);
};

TEST(ImuError, ResidualIsZeroAtTrueStates) {
  const Scenario sc;
  const simulator::TrajectoryState si = sc.traj.evaluate(sc.t_i), sj = sc.traj.evaluate(sc.t_j);
  Vec7 pi = pose_block(si.T_w_b), pj = pose_block(sj.T_w_b);
  Vec9 sbi = speed_bias_block(si.v_w, sc.bg_true, sc.ba_true);
  Vec9 sbj = speed_bias_block(sj.v_w, sc.bg_true, sc.ba_true);
  const double* params[] = {pi.data(), sbi.data(), pj.data(), sbj.data()};

  // Linearised at the true biases: only the discretisation error remains.
  {
    const auto pre = ImuPreintegration::between(sc.samples, sc.t_i, sc.t_j, sc.bg_true, sc.ba_true, test_noise());
    const ImuError err(pre, kGravity);
    const auto r = err.raw_residual(params);
    std::printf("true states, true linearisation biases: |r_R| %.3e rad |r_v| %.3e m/s |r_p| %.3e m\n",
                r.segment<3>(0).norm(), r.segment<3>(3).norm(), r.segment<3>(6).norm());
    EXPECT_LT(r.head<9>().cwiseAbs().maxCoeff(), 1e-6);
    EXPECT_EQ(r.tail<6>().norm(), 0.0);
    Eigen::Matrix<double, 15, 1> whitened;
    ASSERT_TRUE(err.Evaluate(params, whitened.data(), nullptr));
    EXPECT_TRUE(whitened.allFinite());
    EXPECT_LT(whitened.norm(), 1e-2);  // far inside one sigma
  }
  // Linearised at biases off by (2e-3 rad/s, 2e-2 m/s^2): the first-order correction to the true
  // biases brings the residual back near zero.
  {
    const Vector3d off_g(2e-3, -2e-3, 1e-3), off_a(2e-2, 1e-2, -2e-2);
    const auto pre =
        ImuPreintegration::between(sc.samples, sc.t_i, sc.t_j, sc.bg_true + off_g, sc.ba_true + off_a, test_noise());
    const ImuError err(pre, kGravity);
    const auto r = err.raw_residual(params);
    std::printf("true states, linearisation biases off by 2e-3 / 2e-2: |r_R| %.3e |r_v| %.3e |r_p| %.3e\n",
                r.segment<3>(0).norm(), r.segment<3>(3).norm(), r.segment<3>(6).norm());
    EXPECT_LT(r.head<9>().cwiseAbs().maxCoeff(), 5e-5);  // second order in the bias offset
  }
}

TEST(ImuError, AnalyticJacobiansPassGradientChecker) {
  const Scenario sc;
  const auto pre = ImuPreintegration::between(sc.samples, sc.t_i, sc.t_j, sc.bg_true, sc.ba_true, test_noise());
  const ImuError err(pre, kGravity);
  const PoseManifold pose_manifold;
  const ceres::EuclideanManifold<9> euclidean;
  const std::vector<const ceres::Manifold*> manifolds = {&pose_manifold, &euclidean, &pose_manifold, &euclidean};
  ceres::NumericDiffOptions nd;
  // GradientChecker differentiates in the ambient coordinates with Ridders' extrapolation; from the
  // default initial step (1e-2 of each coordinate) it was 2.7e-4 off for one of the 20 states
  // below (central differences along the manifold agreed with the analytic Jacobian to 1e-10).
  nd.ridders_relative_initial_step_size = 1e-4;
  const ceres::GradientChecker checker(&err, &manifolds, nd);

  std::mt19937 rng(42);
  std::normal_distribution<double> n(0.0, 1.0);
  double worst_ceres = 0, worst_floored = 0;
  int floored_entries = 0;
  for (int trial = 0; trial < 20; ++trial) {
    // Random pose i; pose j = pose i moved by the preintegrated rotation and a random rotation of
    // ~0.5 rad (keeps |r_R| well below pi, where Log and central differences lose accuracy), random
    // positions and velocities, biases near the linearisation point (bias correction active).
    Vec7 pi = random_pose(rng);
    Vec7 pj = random_pose(rng);
    const Eigen::Quaterniond qi(pi[3], pi[0], pi[1], pi[2]);
    const Eigen::Quaterniond qj = qi * pre.delta_q() * calib::so3_exp_quat(0.3 * Vector3d(n(rng), n(rng), n(rng)));
    pj.head<4>() = qj.coeffs();
    if (trial % 2 == 1) pi.head<4>() *= 1.3;  // a non-unit quaternion: the residual normalises it
    Vec9 sbi, sbj;
    for (int k = 0; k < 9; ++k) {
      sbi[k] = n(rng);
      sbj[k] = n(rng);
    }
    sbi.segment<3>(3) = sc.bg_true + 0.01 * Vector3d(n(rng), n(rng), n(rng));
    sbi.segment<3>(6) = sc.ba_true + 0.05 * Vector3d(n(rng), n(rng), n(rng));
    const double* params[] = {pi.data(), sbi.data(), pj.data(), sbj.data()};
    ceres::GradientChecker::ProbeResults results;
    checker.Probe(params, 1e-6, &results);
    ASSERT_TRUE(results.return_value);
    worst_ceres = std::max(worst_ceres, results.maximum_relative_error);
    // Ceres' verdict is per entry and purely relative, so entries that are exactly zero in theory
    // (e.g. whitened d r_p / d theta_z through hat()) fail on round-off (1e-14 analytic vs 1e-12
    // numeric against entries of 1e3). Accept |analytic - numeric| <= 1e-6 * max(|a|, |n|) or
    // <= 1e-9 * the largest entry of the whole Jacobian.
    double scale = 0;
    for (const auto& J : results.local_numeric_jacobians) scale = std::max(scale, J.cwiseAbs().maxCoeff());
    for (size_t b = 0; b < results.local_jacobians.size(); ++b) {
      const auto& Ja = results.local_jacobians[b];
      const auto& Jn = results.local_numeric_jacobians[b];
      ASSERT_EQ(Ja.cols(), b % 2 == 0 ? 6 : 9);  // tangent columns for the poses
      for (int r = 0; r < Ja.rows(); ++r)
        for (int c = 0; c < Ja.cols(); ++c) {
          const double a = Ja(r, c), num = Jn(r, c), diff = std::abs(a - num);
          const double mag = std::max(std::abs(a), std::abs(num));
          const bool rel_ok = diff <= 1e-6 * mag;
          if (!rel_ok) ++floored_entries;
          if (mag > 1e-9 * scale) worst_floored = std::max(worst_floored, diff / mag);
          EXPECT_TRUE(rel_ok || diff <= 1e-9 * scale)
              << "trial " << trial << " block " << b << " (" << r << "," << c << "): analytic " << a << " numeric "
              << num << "\n" << results.error_log;
        }
    }
  }
  std::printf("GradientChecker (20 random states): Ceres max relative error %.3e (round-off on zero entries), "
              "max relative error over entries > 1e-9 * max|J|: %.3e, entries accepted by the absolute floor: %d\n",
              worst_ceres, worst_floored, floored_entries);
}

TEST(ImuError, AmbientJacobianTimesPlusJacobianIsTangentJacobian) {
  // The ambient pose columns times PlusJacobian equal the tangent Jacobian, checked against central
  // differences along the manifold (Plus), independently of ceres::GradientChecker.
  const Scenario sc;
  const auto pre = ImuPreintegration::between(sc.samples, sc.t_i, sc.t_j, sc.bg_true, sc.ba_true, test_noise());
  const ImuError err(pre, kGravity);
  std::mt19937 rng(5);
  Vec7 pi = random_pose(rng), pj = random_pose(rng);
  Vec9 sbi = speed_bias_block(Vector3d(0.3, -0.2, 0.1), sc.bg_true, sc.ba_true);
  Vec9 sbj = speed_bias_block(Vector3d(-0.1, 0.4, 0.2), sc.bg_true, sc.ba_true);
  Eigen::Matrix<double, 15, 7, Eigen::RowMajor> J0, J2;
  Eigen::Matrix<double, 15, 9, Eigen::RowMajor> J1, J3;
  double* jac[] = {J0.data(), J1.data(), J2.data(), J3.data()};
  Eigen::Matrix<double, 15, 1> r;
  const double* params[] = {pi.data(), sbi.data(), pj.data(), sbj.data()};
  ASSERT_TRUE(err.Evaluate(params, r.data(), jac));
  const PoseManifold m;
  for (int block : {0, 2}) {
    Vec7& x = block == 0 ? pi : pj;
    const Eigen::Matrix<double, 15, 6> J_tan =
        (block == 0 ? J0 : J2) * PoseManifold::plus_jacobian(x.data());
    Eigen::Matrix<double, 15, 6> J_num;
    const double h = 1e-6;
    for (int c = 0; c < 6; ++c) {
      Eigen::Matrix<double, 6, 1> d = Eigen::Matrix<double, 6, 1>::Zero();
      d[c] = h;
      const Vec7 x0 = x;
      Vec7 xp, xm;
      m.Plus(x0.data(), d.data(), xp.data());
      d[c] = -h;
      m.Plus(x0.data(), d.data(), xm.data());
      Eigen::Matrix<double, 15, 1> rp, rm;
      x = xp;
      err.Evaluate(params, rp.data(), nullptr);
      x = xm;
      err.Evaluate(params, rm.data(), nullptr);
      x = x0;
      J_num.col(c) = (rp - rm) / (2 * h);
    }
    const double rel = (J_tan - J_num).norm() / J_num.norm();
    std::printf("pose block %d: |J_amb*PlusJ - J_numeric| / |J_numeric| = %.3e\n", block, rel);
    EXPECT_LT(rel, 1e-6);
  }
}

TEST(ImuError, CeresRecoversStateJ) {
  const Scenario sc;
  const auto pre = ImuPreintegration::between(sc.samples, sc.t_i, sc.t_j, sc.bg_true, sc.ba_true, test_noise());
  const simulator::TrajectoryState si = sc.traj.evaluate(sc.t_i), sj = sc.traj.evaluate(sc.t_j);
  Vec7 pi = pose_block(si.T_w_b);
  Vec9 sbi = speed_bias_block(si.v_w, sc.bg_true, sc.ba_true);
  // State j perturbed: 0.2 rad, 0.5 m, 0.3 m/s, biases off.
  calib::SE3 Tj = sj.T_w_b;
  Tj.rotation = (Tj.rotation * calib::so3_exp_quat(Vector3d(0.1, -0.15, 0.1))).normalized();
  Tj.translation += Vector3d(0.3, -0.4, 0.1);
  Vec7 pj = pose_block(Tj);
  Vec9 sbj = speed_bias_block(sj.v_w + Vector3d(0.2, 0.1, -0.2), sc.bg_true + Vector3d::Constant(0.01),
                              sc.ba_true + Vector3d::Constant(-0.05));
  ceres::Problem problem;
  problem.AddParameterBlock(pi.data(), 7, new PoseManifold);
  problem.AddParameterBlock(pj.data(), 7, new PoseManifold);
  problem.AddParameterBlock(sbi.data(), 9);
  problem.AddParameterBlock(sbj.data(), 9);
  problem.AddResidualBlock(new ImuError(pre, kGravity), nullptr, pi.data(), sbi.data(), pj.data(), sbj.data());
  problem.SetParameterBlockConstant(pi.data());
  problem.SetParameterBlockConstant(sbi.data());
  ceres::Solver::Options options;
  options.max_num_iterations = 50;
  options.function_tolerance = 1e-16;
  options.gradient_tolerance = 1e-16;
  options.parameter_tolerance = 1e-14;
  ceres::Solver::Summary summary;
  ceres::Solve(options, &problem, &summary);
  const Eigen::Quaterniond qj(pj[3], pj[0], pj[1], pj[2]);
  const double rot_err = calib::so3_log(sj.T_w_b.rotation.conjugate() * qj.normalized()).norm();
  const double pos_err = (pj.tail<3>() - sj.T_w_b.translation).norm();
  const double vel_err = (sbj.head<3>() - sj.v_w).norm();
  std::printf("Ceres solve (%d iterations): state j errors rot %.3e rad pos %.3e m vel %.3e m/s\n",
              static_cast<int>(summary.iterations.size()), rot_err, pos_err, vel_err);
  EXPECT_LT(rot_err, 1e-6);
  EXPECT_LT(pos_err, 1e-6);
  EXPECT_LT(vel_err, 1e-6);
  EXPECT_LT((sbj.segment<3>(3) - sc.bg_true).norm(), 1e-9);
  EXPECT_LT((sbj.segment<3>(6) - sc.ba_true).norm(), 1e-9);
}

TEST(ImuError, RejectsEmptyIntervalAndZeroRandomWalk) {
  const Scenario sc;
  const auto empty = ImuPreintegration::between(sc.samples, sc.t_i, sc.t_i, sc.bg_true, sc.ba_true, test_noise());
  EXPECT_THROW(ImuError(empty, kGravity), std::invalid_argument);
  calib::ImuNoise no_walk = test_noise();
  no_walk.gyroscope_random_walk = 0;
  const auto pre = ImuPreintegration::between(sc.samples, sc.t_i, sc.t_j, sc.bg_true, sc.ba_true, no_walk);
  EXPECT_THROW(ImuError(pre, kGravity), std::invalid_argument);
}

TEST(ImuError, LargeTimestampsGiveTheSameResidual) {
  const int64_t big = 1'700'000'000'000'000'000;
  std::vector<Eigen::Matrix<double, 15, 1>> out;
  for (const int64_t t0 : {int64_t{0}, big}) {
    const auto traj = make_trajectory(t0);
    const auto samples = ideal_samples(traj, t0, t0 + 2'000'000'000, 1'000'000, Vector3d::Zero(), Vector3d::Zero());
    const int64_t ti = t0 + 400'000'321, tj = t0 + 900'000'654;
    const auto pre = ImuPreintegration::between(samples, ti, tj, Vector3d::Zero(), Vector3d::Zero(), test_noise());
    const ImuError err(pre, kGravity);
    const simulator::TrajectoryState si = traj.evaluate(ti), sj = traj.evaluate(tj);
    Vec7 pi = pose_block(si.T_w_b), pj = pose_block(sj.T_w_b);
    Vec9 sbi = speed_bias_block(si.v_w + Vector3d(0.01, 0, 0), Vector3d::Zero(), Vector3d::Zero());
    Vec9 sbj = speed_bias_block(sj.v_w, Vector3d::Zero(), Vector3d::Zero());
    const double* params[] = {pi.data(), sbi.data(), pj.data(), sbj.data()};
    Eigen::Matrix<double, 15, 1> r;
    ASSERT_TRUE(err.Evaluate(params, r.data(), nullptr));
    EXPECT_TRUE(r.allFinite());
    out.push_back(r);
  }
  EXPECT_LT((out[0] - out[1]).cwiseAbs().maxCoeff(), 1e-9 * out[0].cwiseAbs().maxCoeff());
}

}  // namespace
}  // namespace evio::backend
