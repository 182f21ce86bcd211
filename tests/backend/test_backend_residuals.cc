// ReprojectionError and LinearPrior: analytic Jacobians vs ceres::GradientChecker (with the
// PoseManifold), known residual values, and marginalisation: on a linear-Gaussian problem the
// prior from the Schur complement reproduces the full problem's solution and covariance of the
// kept variables.
#include <array>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <random>

#include <ceres/ceres.h>
#include <ceres/gradient_checker.h>
#include <gtest/gtest.h>

#include "evio/backend/marginalization.h"
#include "evio/backend/pose_manifold.h"
#include "evio/backend/reprojection_error.h"
#include "evio/calib/geometry.h"

namespace evio::backend {
namespace {

std::array<double, 7> random_pose(std::mt19937& rng, double angle = 1.0) {
  std::normal_distribution<double> n(0.0, 1.0);
  const Eigen::Quaterniond q = calib::so3_exp_quat(Eigen::Vector3d(n(rng), n(rng), n(rng)) * angle);
  return {q.x(), q.y(), q.z(), q.w(), n(rng), n(rng), n(rng)};
}

// Worst |analytic - numeric| relative to max(1, |numeric|) over all tangent Jacobian entries.
double worst_error(const ceres::GradientChecker::ProbeResults& r) {
  double worst = 0;
  for (size_t i = 0; i < r.local_jacobians.size(); ++i) {
    const Eigen::MatrixXd d = r.local_jacobians[i] - r.local_numeric_jacobians[i];
    for (int a = 0; a < d.rows(); ++a)
      for (int b = 0; b < d.cols(); ++b)
        worst = std::max(worst, std::abs(d(a, b)) / std::max(1.0, std::abs(r.local_numeric_jacobians[i](a, b))));
  }
  return worst;
}

// The worst Jacobian error (worst_error) of `cost` at `params`, relative step `step`; infinity
// when the checker could not evaluate it.
double probe_worst(const ceres::CostFunction& cost, const std::vector<const ceres::Manifold*>& manifolds,
                   const double* const* params, double step = 1e-5) {
  ceres::NumericDiffOptions nd;
  const ceres::GradientChecker checker(&cost, &manifolds, nd);
  ceres::GradientChecker::ProbeResults res;
  checker.Probe(params, step, &res);
  return res.return_value ? worst_error(res) : std::numeric_limits<double>::infinity();
}

// A random body pose, a landmark 2-6 m in front of the camera and its bearing with ~2 px noise.
struct RandomObservation {
  std::array<double, 7> pose;
  std::array<double, 3> landmark;
  Eigen::Vector3d bearing;
};
RandomObservation random_observation(std::mt19937& rng, const calib::SE3& T_c_b) {
  std::normal_distribution<double> n(0.0, 1.0);
  RandomObservation o;
  o.pose = random_pose(rng);
  const calib::SE3 T_w_b(Eigen::Quaterniond(o.pose[3], o.pose[0], o.pose[1], o.pose[2]),
                         Eigen::Vector3d(o.pose[4], o.pose[5], o.pose[6]));
  const calib::SE3 T_w_c = T_w_b * T_c_b.inverse();
  const Eigen::Vector3d p_c(0.5 * n(rng), 0.5 * n(rng), 2.0 + 4.0 * std::abs(n(rng)) / 3.0);
  const Eigen::Vector3d p_w = T_w_c.rotation * p_c + T_w_c.translation;
  o.landmark = {p_w.x(), p_w.y(), p_w.z()};
  o.bearing = (p_c + Eigen::Vector3d(0.01 * n(rng), 0.01 * n(rng), 0)).normalized();
  return o;
}

TEST(ReprojectionError, GradientCheckerAtRandomPosesAndPoints) {
  std::mt19937 rng(3);
  std::normal_distribution<double> n(0.0, 1.0);
  const PoseManifold pm;
  const ceres::EuclideanManifold<3> e3;
  const std::vector<const ceres::Manifold*> manifolds = {&pm, &e3};
  const calib::SE3 T_c_b(calib::so3_exp_quat(Eigen::Vector3d(0.1, -0.2, 0.05)), Eigen::Vector3d(0.02, -0.01, 0.03));
  double worst = 0;
  for (int trial = 0; trial < 50; ++trial) {
    const RandomObservation o = random_observation(rng, T_c_b);
    const ReprojectionError err(o.bearing, T_c_b, 200.0, 0.5);
    const double* params[2] = {o.pose.data(), o.landmark.data()};
    worst = std::max(worst, probe_worst(err, manifolds, params));
  }
  std::printf("ReprojectionError: worst Jacobian error %.2e\n", worst);
  EXPECT_LT(worst, 1e-5);
}

TEST(ReprojectionError, ResidualIsThePixelErrorInSigmas) {
  const calib::SE3 T_c_b;  // identity
  std::array<double, 7> pose = {0, 0, 0, 1, 0, 0, 0};
  std::array<double, 3> l = {0.1, -0.2, 2.0};
  // Observed 1 px (f = 200) to the right of the true projection, sigma 0.5 px: r = (2, 0).
  const Eigen::Vector3d b = Eigen::Vector3d(0.05 + 1.0 / 200.0, -0.1, 1.0).normalized();
  const ReprojectionError err(b, T_c_b, 200.0, 0.5);
  double r[2];
  const double* params[2] = {pose.data(), l.data()};
  ASSERT_TRUE(err.Evaluate(params, r, nullptr));
  EXPECT_NEAR(r[0], -2.0, 1e-9);
  EXPECT_NEAR(r[1], 0.0, 1e-9);
  // Behind the camera: the evaluation fails (Ceres shortens the step).
  l = {0, 0, -1};
  EXPECT_FALSE(err.Evaluate(params, r, nullptr));
  EXPECT_THROW(ReprojectionError(Eigen::Vector3d(0, 0, -1), T_c_b, 200, 0.5), std::invalid_argument);
}

// The time-offset form: its Jacobians (pose, landmark and td) against numeric differentiation,
// and at td = 0 the plain reprojection residual; td moves the measurement by -td v.
TEST(TimeOffsetReprojectionError, GradientCheckerAndShiftAlongTheImageVelocity) {
  std::mt19937 rng(4);
  std::normal_distribution<double> n(0.0, 1.0);
  const PoseManifold pm;
  const ceres::EuclideanManifold<3> e3;
  const ceres::EuclideanManifold<1> e1;
  const std::vector<const ceres::Manifold*> manifolds = {&pm, &e3, &e1};
  const calib::SE3 T_c_b(calib::so3_exp_quat(Eigen::Vector3d(0.1, -0.2, 0.05)), Eigen::Vector3d(0.02, -0.01, 0.03));
  double worst = 0;
  for (int trial = 0; trial < 30; ++trial) {
    const RandomObservation o = random_observation(rng, T_c_b);
    const Eigen::Vector3d& bearing = o.bearing;
    std::array<double, 1> td = {0.01 * n(rng)};
    const Eigen::Vector2d v(0.5 * n(rng), 0.5 * n(rng));
    const TimeOffsetReprojectionError err(bearing, v, T_c_b, 200.0, 0.5);
    const double* params[3] = {o.pose.data(), o.landmark.data(), td.data()};
    worst = std::max(worst, probe_worst(err, manifolds, params));
    // td = 0: the plain residual; otherwise it differs by (f / sigma) td v.
    const ReprojectionError plain(bearing, T_c_b, 200.0, 0.5);
    double r_plain[2], r_td[2];
    ASSERT_TRUE(plain.Evaluate(params, r_plain, nullptr));
    ASSERT_TRUE(err.Evaluate(params, r_td, nullptr));
    EXPECT_NEAR(r_td[0] - r_plain[0], 400.0 * td[0] * v.x(), 1e-9);
    EXPECT_NEAR(r_td[1] - r_plain[1], 400.0 * td[0] * v.y(), 1e-9);
  }
  std::printf("TimeOffsetReprojectionError: worst Jacobian error %.2e\n", worst);
  EXPECT_LT(worst, 1e-5);
  EXPECT_THROW(TimeOffsetReprojectionError(Eigen::Vector3d(0, 0, 1), Eigen::Vector2d(NAN, 0), calib::SE3(), 200, 0.5),
               std::invalid_argument);
}

TEST(RotationOnlyError, GradientCheckerAndZeroAtTheTrueRotation) {
  std::mt19937 rng(4);
  std::normal_distribution<double> n(0.0, 1.0);
  const PoseManifold pm;
  const std::vector<const ceres::Manifold*> manifolds = {&pm, &pm};
  const calib::SE3 T_c_b(calib::so3_exp_quat(Eigen::Vector3d(-0.1, 0.2, 0.05)), Eigen::Vector3d(0.02, -0.01, 0.03));
  double worst = 0;
  for (int trial = 0; trial < 50; ++trial) {
    auto pi = random_pose(rng);
    const Eigen::Quaterniond qi(pi[3], pi[0], pi[1], pi[2]);
    const Eigen::Quaterniond qj = qi * calib::so3_exp_quat(Eigen::Vector3d(n(rng), n(rng), n(rng)) * 0.1);
    std::array<double, 7> pj = {qj.x(), qj.y(), qj.z(), qj.w(), n(rng), n(rng), n(rng)};
    // A direction at infinity seen by both cameras.
    const Eigen::Vector3d b_j = Eigen::Vector3d(0.2 * n(rng), 0.2 * n(rng), 1.0).normalized();
    const Eigen::Matrix3d R_c_b = T_c_b.rotation.toRotationMatrix();
    const Eigen::Vector3d b_i = R_c_b * qi.conjugate().toRotationMatrix() * qj.toRotationMatrix() * R_c_b.transpose() * b_j;
    const RotationOnlyError exact(b_i, b_j, T_c_b, 200.0, 0.5);
    double r[2];
    const double* params[2] = {pi.data(), pj.data()};
    ASSERT_TRUE(exact.Evaluate(params, r, nullptr));
    EXPECT_LT(std::hypot(r[0], r[1]), 1e-8);
    const RotationOnlyError err((b_i + Eigen::Vector3d(0.01 * n(rng), 0.01 * n(rng), 0)).normalized(), b_j, T_c_b, 200.0, 0.5);
    worst = std::max(worst, probe_worst(err, manifolds, params));
  }
  std::printf("RotationOnlyError: worst Jacobian error %.2e\n", worst);
  EXPECT_LT(worst, 1e-5);
}

// The camera centre staying put: zero for two poses that turn about the camera centre, the centre's
// displacement over sigma otherwise; Jacobians against numeric differentiation.
TEST(StaticCentreError, GradientCheckerAndZeroForARotationAboutTheCameraCentre) {
  std::mt19937 rng(6);
  std::normal_distribution<double> n(0.0, 1.0);
  const PoseManifold pm;
  const std::vector<const ceres::Manifold*> manifolds = {&pm, &pm};
  const calib::SE3 T_c_b(calib::so3_exp_quat(Eigen::Vector3d(-0.1, 0.2, 0.05)), Eigen::Vector3d(0.02, -0.01, 0.03));
  const Eigen::Vector3d c_b = -(T_c_b.rotation.conjugate() * T_c_b.translation);
  double worst = 0;
  for (int trial = 0; trial < 50; ++trial) {
    auto pi = random_pose(rng);
    const Eigen::Quaterniond qi(pi[3], pi[0], pi[1], pi[2]);
    const Eigen::Quaterniond qj = qi * calib::so3_exp_quat(Eigen::Vector3d(n(rng), n(rng), n(rng)) * 0.3);
    // The body turns about the camera centre: p_j + R_j c = p_i + R_i c.
    const Eigen::Vector3d p_j = Eigen::Vector3d(pi[4], pi[5], pi[6]) + qi * c_b - qj * c_b;
    std::array<double, 7> pj = {qj.x(), qj.y(), qj.z(), qj.w(), p_j.x(), p_j.y(), p_j.z()};
    const StaticCentreError err(T_c_b, 0.004);
    double r[3];
    const double* params[2] = {pi.data(), pj.data()};
    ASSERT_TRUE(err.Evaluate(params, r, nullptr));
    EXPECT_LT(Eigen::Map<Eigen::Vector3d>(r).norm(), 1e-9);
    pj[4] += 0.002;  // 2 mm along x: 0.5 sigma
    ASSERT_TRUE(err.Evaluate(params, r, nullptr));
    EXPECT_NEAR(r[0], 0.5, 1e-9);
    worst = std::max(worst, probe_worst(err, manifolds, params));
  }
  std::printf("StaticCentreError: worst Jacobian error %.2e\n", worst);
  EXPECT_LT(worst, 1e-5);
}

// Any body point as the centre (the IMU origin, c = 0: the position itself stays): zero when the
// body turns in place, the camera-centre version then sees the lever arm move; Jacobians checked.
TEST(StaticCentreError, ABodyPointAsTheCentre) {
  std::mt19937 rng(7);
  std::normal_distribution<double> n(0.0, 1.0);
  const PoseManifold pm;
  const std::vector<const ceres::Manifold*> manifolds = {&pm, &pm};
  const calib::SE3 T_c_b(calib::so3_exp_quat(Eigen::Vector3d(-0.1, 0.2, 0.05)), Eigen::Vector3d(0.02, -0.01, 0.03));
  double worst = 0;
  for (int trial = 0; trial < 20; ++trial) {
    auto pi = random_pose(rng);
    const Eigen::Quaterniond qi(pi[3], pi[0], pi[1], pi[2]);
    const Eigen::Quaterniond qj = qi * calib::so3_exp_quat(Eigen::Vector3d(n(rng), n(rng), n(rng)) * 0.3);
    std::array<double, 7> pj = {qj.x(), qj.y(), qj.z(), qj.w(), pi[4], pi[5], pi[6]};  // turned in place
    const double* params[2] = {pi.data(), pj.data()};
    const StaticCentreError imu(Eigen::Vector3d::Zero(), 0.004), camera(T_c_b, 0.004);
    double r[3];
    ASSERT_TRUE(imu.Evaluate(params, r, nullptr));
    EXPECT_LT(Eigen::Map<Eigen::Vector3d>(r).norm(), 1e-12);
    ASSERT_TRUE(camera.Evaluate(params, r, nullptr));
    const Eigen::Vector3d c_b = -(T_c_b.rotation.conjugate() * T_c_b.translation);
    EXPECT_NEAR(Eigen::Map<Eigen::Vector3d>(r).norm(), (qj * c_b - qi * c_b).norm() / 0.004, 1e-9);
    const StaticCentreError point(Eigen::Vector3d(0.1, -0.2, 0.05), 0.004);
    worst = std::max(worst, probe_worst(point, manifolds, params));
  }
  EXPECT_LT(worst, 1e-5);
}

// The tracker's relative rotation (issue 37): zero at the measured rotation, the whitening by
// the covariance (a turn of one sigma about a camera axis reads 1), Jacobians checked, and a
// covariance that is not positive definite is refused.
TEST(RelativeRotationError, GradientCheckerZeroAtTheMeasurementAndWhitening) {
  std::mt19937 rng(8);
  std::normal_distribution<double> n(0.0, 1.0);
  const PoseManifold pm;
  const calib::SE3 T_c_b(calib::so3_exp_quat(Eigen::Vector3d(-0.1, 0.2, 0.05)), Eigen::Vector3d(0.02, -0.01, 0.03));
  const Eigen::Quaterniond q_c_b = T_c_b.rotation;
  const Eigen::Matrix3d cov = Eigen::Vector3d(1e-4, 4e-4, 9e-4).asDiagonal();  // sigmas 0.01, 0.02, 0.03 rad
  double worst = 0;
  for (int trial = 0; trial < 50; ++trial) {
    auto pi = random_pose(rng);
    const Eigen::Quaterniond qi(pi[3], pi[0], pi[1], pi[2]);
    const Eigen::Quaterniond qj = qi * calib::so3_exp_quat(Eigen::Vector3d(n(rng), n(rng), n(rng)) * 0.5);
    std::array<double, 7> pj = {qj.x(), qj.y(), qj.z(), qj.w(), n(rng), n(rng), n(rng)};
    // The camera's rotation from i to j: R_c_b R_bi_bj R_b_c.
    const Eigen::Quaterniond R_ci_cj = q_c_b * qi.conjugate() * qj * q_c_b.conjugate();
    const RelativeRotationError err(R_ci_cj, cov, T_c_b);
    double r[3];
    const double* params[2] = {pi.data(), pj.data()};
    ASSERT_TRUE(err.Evaluate(params, r, nullptr));
    EXPECT_LT(Eigen::Map<Eigen::Vector3d>(r).norm(), 1e-9);
    // Camera j turned by 0.02 rad (one sigma) about its y axis.
    const Eigen::Quaterniond qj2 = qj * q_c_b.conjugate() * calib::so3_exp_quat(Eigen::Vector3d(0, 0.02, 0)) * q_c_b;
    std::array<double, 7> pj2 = {qj2.x(), qj2.y(), qj2.z(), qj2.w(), pj[4], pj[5], pj[6]};
    const double* params2[2] = {pi.data(), pj2.data()};
    ASSERT_TRUE(err.Evaluate(params2, r, nullptr));
    EXPECT_NEAR(Eigen::Map<Eigen::Vector3d>(r).norm(), 1.0, 1e-6);
    EXPECT_NEAR(err.error(pi.data(), pj2.data()).norm(), 0.02, 1e-9);
    // Tangent-space central differences (h = 1e-6 rad) against the analytic Jacobians, relative to
    // max(1, |entry|): the whitening scales the entries up to 100, beyond what the ambient-space
    // GradientChecker resolves.
    double J[2][21];
    double* jac[2] = {J[0], J[1]};
    ASSERT_TRUE(err.Evaluate(params2, r, jac));
    for (int b = 0; b < 2; ++b) {
      const Eigen::Matrix<double, 3, 6> Jt =
          Eigen::Map<const Eigen::Matrix<double, 3, 7, Eigen::RowMajor>>(J[b]) * PoseManifold::plus_jacobian(params2[b]);
      for (int k = 0; k < 6; ++k) {
        double d[6] = {0, 0, 0, 0, 0, 0}, xp[7], xm[7], rp[3], rm[3];
        d[k] = 1e-6;
        pm.Plus(params2[b], d, xp);
        d[k] = -1e-6;
        pm.Plus(params2[b], d, xm);
        const double* pp[2] = {b ? pi.data() : xp, b ? xp : pj2.data()};
        const double* pn[2] = {b ? pi.data() : xm, b ? xm : pj2.data()};
        ASSERT_TRUE(err.Evaluate(pp, rp, nullptr));
        ASSERT_TRUE(err.Evaluate(pn, rm, nullptr));
        for (int a = 0; a < 3; ++a) {
          const double numeric = (rp[a] - rm[a]) / 2e-6;
          worst = std::max(worst, std::abs(Jt(a, k) - numeric) / std::max(1.0, std::abs(numeric)));
        }
      }
    }
  }
  std::printf("RelativeRotationError: worst Jacobian error %.2e\n", worst);
  EXPECT_LT(worst, 1e-5);
  EXPECT_THROW(RelativeRotationError(Eigen::Quaterniond::Identity(), Eigen::Matrix3d::Zero(), T_c_b), std::invalid_argument);
  EXPECT_THROW(RelativeRotationError(Eigen::Quaterniond::Identity(), -cov, T_c_b), std::invalid_argument);
}

TEST(LinearPrior, GradientCheckerWithPoseAndEuclideanBlocks) {
  std::mt19937 rng(5);
  std::normal_distribution<double> n(0.0, 1.0);
  auto pose = random_pose(rng);
  std::array<double, 9> sb;
  for (double& v : sb) v = n(rng);
  const auto pose0 = random_pose(rng, 0.2);
  PriorBlock a{pose.data(), 7, true, std::vector<double>(pose0.begin(), pose0.end())};
  std::vector<double> sb0(9);
  for (double& v : sb0) v = n(rng);
  PriorBlock b{sb.data(), 9, false, sb0};
  Eigen::MatrixXd J = Eigen::MatrixXd::Random(12, 15);
  Eigen::VectorXd r0 = Eigen::VectorXd::Random(12);
  const LinearPrior prior({a, b}, J, r0);
  const PoseManifold pm;
  const ceres::EuclideanManifold<9> e9;
  const std::vector<const ceres::Manifold*> manifolds = {&pm, &e9};
  const double* params[2] = {pose.data(), sb.data()};
  EXPECT_LT(probe_worst(prior, manifolds, params, 1e-6), 1e-6);
  // At the linearisation point the residual is r0.
  Eigen::VectorXd r(12);
  const double* at0[2] = {pose0.data(), sb0.data()};
  ASSERT_TRUE(prior.Evaluate(at0, r.data(), nullptr));
  EXPECT_LT((r - r0).norm(), 1e-12);
}

// y = A x + noise over three 3-vectors x0, x1, x2 (a chain with an extra link 0-2): solving
// everything, or marginalising x0 and solving x1, x2 with the prior, gives the same x1, x2.
class LinearResidual final : public ceres::CostFunction {
 public:
  LinearResidual(Eigen::MatrixXd A, Eigen::VectorXd y, int blocks) : A_(std::move(A)), y_(std::move(y)) {
    for (int i = 0; i < blocks; ++i) mutable_parameter_block_sizes()->push_back(3);
    set_num_residuals(static_cast<int>(y_.size()));
  }
  bool Evaluate(double const* const* p, double* r, double** J) const override {
    const int nb = static_cast<int>(parameter_block_sizes().size());
    Eigen::VectorXd x(3 * nb);
    for (int i = 0; i < nb; ++i) x.segment<3>(3 * i) = Eigen::Map<const Eigen::Vector3d>(p[i]);
    Eigen::Map<Eigen::VectorXd>(r, y_.size()) = A_ * x - y_;
    if (J) {
      for (int i = 0; i < nb; ++i) {
        if (J[i]) Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>>(J[i], y_.size(), 3) = A_.middleCols(3 * i, 3);
      }
    }
    return true;
  }

 private:
  Eigen::MatrixXd A_;
  Eigen::VectorXd y_;
};

ceres::Solver::Options tight() {
  ceres::Solver::Options so;
  so.max_num_iterations = 50;
  so.function_tolerance = so.gradient_tolerance = so.parameter_tolerance = 1e-16;
  so.linear_solver_type = ceres::DENSE_QR;
  return so;
}

// An r x c matrix of standard normal entries.
Eigen::MatrixXd random_matrix(std::mt19937& rng, int r, int c) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::MatrixXd m(r, c);
  for (int i = 0; i < r; ++i)
    for (int j = 0; j < c; ++j) m(i, j) = n(rng);
  return m;
}

TEST(Marginalization, SchurPriorReproducesTheFullSolutionOfKeptVariables) {
  std::mt19937 rng(9);
  auto rnd = [&](int r, int c) { return random_matrix(rng, r, c); };
  const LinearResidual f0(rnd(4, 3), rnd(4, 1), 1);   // on x0
  const LinearResidual f01(rnd(5, 6), rnd(5, 1), 2);  // x0, x1
  const LinearResidual f02(rnd(4, 6), rnd(4, 1), 2);  // x0, x2
  const LinearResidual f12(rnd(6, 6), rnd(6, 1), 2);  // x1, x2
  ceres::Problem::Options po;
  po.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  // Full solve.
  std::array<double, 3> x0{}, x1{}, x2{};
  {
    ceres::Problem p(po);
    p.AddResidualBlock(const_cast<LinearResidual*>(&f0), nullptr, x0.data());
    p.AddResidualBlock(const_cast<LinearResidual*>(&f01), nullptr, x0.data(), x1.data());
    p.AddResidualBlock(const_cast<LinearResidual*>(&f02), nullptr, x0.data(), x2.data());
    p.AddResidualBlock(const_cast<LinearResidual*>(&f12), nullptr, x1.data(), x2.data());
    ceres::Solver::Options so = tight();
    ceres::Solver::Summary s;
    ceres::Solve(so, &p, &s);
  }
  // Marginalise x0 at an arbitrary linearisation point (exact for a linear problem), then solve.
  std::array<double, 3> y0 = {0.3, -0.2, 0.1}, y1 = {1, 2, 3}, y2 = {-1, 0.5, 0};
  ceres::Problem pm(po);
  std::vector<ceres::ResidualBlockId> ids = {
      pm.AddResidualBlock(const_cast<LinearResidual*>(&f0), nullptr, y0.data()),
      pm.AddResidualBlock(const_cast<LinearResidual*>(&f01), nullptr, y0.data(), y1.data()),
      pm.AddResidualBlock(const_cast<LinearResidual*>(&f02), nullptr, y0.data(), y2.data())};
  MarginalizationStats st;
  auto prior = marginalize(&pm, ids, {y0.data()}, [](const double*) { return false; }, &st);
  ASSERT_TRUE(prior);
  EXPECT_EQ(st.removed_dims, 3);
  EXPECT_EQ(st.kept_dims, 6);
  ceres::Problem p2(po);
  p2.AddResidualBlock(prior.get(), nullptr, y1.data(), y2.data());
  p2.AddResidualBlock(const_cast<LinearResidual*>(&f12), nullptr, y1.data(), y2.data());
  ceres::Solver::Options so = tight();
  ceres::Solver::Summary s;
  ceres::Solve(so, &p2, &s);
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(y1[i], x1[i], 1e-8);
    EXPECT_NEAR(y2[i], x2[i], 1e-8);
  }
}

// The two-stage elimination (landmark-like blocks, which share no residual, first; then the rest of
// the removed blocks) gives the Schur complement of one dense elimination of all removed blocks.
TEST(Marginalization, TwoStageEliminationEqualsTheDenseSchurComplement) {
  std::mt19937 rng(17);
  auto rnd = [&](int r, int c) { return random_matrix(rng, r, c); };
  // Removed: a "pose" p and landmarks l1, l2 (each seen from p and a kept pose); kept: k1, k2.
  std::array<double, 3> p{0.1, 0.2, 0.3}, l1{1, 2, 3}, l2{-1, 0, 2}, k1{0.5, 0.5, 0.5}, k2{0, -1, 1};
  std::vector<std::unique_ptr<LinearResidual>> costs;
  ceres::Problem::Options po;
  po.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem pm(po);
  std::vector<ceres::ResidualBlockId> ids;
  std::vector<std::vector<double*>> params = {{p.data()}, {p.data(), l1.data()}, {k1.data(), l1.data()},
                                              {p.data(), l2.data()}, {k2.data(), l2.data()}, {p.data(), k1.data()},
                                              {k1.data(), k2.data()}};
  for (const auto& ps : params) {
    const int nb = static_cast<int>(ps.size());
    costs.push_back(std::make_unique<LinearResidual>(rnd(2 + 2 * nb, 3 * nb), rnd(2 + 2 * nb, 1), nb));
    ids.push_back(pm.AddResidualBlock(costs.back().get(), nullptr, ps));
  }
  MarginalizationStats st;
  auto prior = marginalize(&pm, ids, {p.data(), l1.data(), l2.data()}, [](const double*) { return false; }, &st);
  ASSERT_TRUE(prior);
  EXPECT_EQ(st.removed_dims, 9);
  EXPECT_EQ(st.kept_dims, 6);
  // Dense reference over [p l1 l2 | k1 k2].
  std::map<const double*, int> col = {{p.data(), 0}, {l1.data(), 3}, {l2.data(), 6}, {k1.data(), 9}, {k2.data(), 12}};
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(15, 15);
  Eigen::VectorXd g = Eigen::VectorXd::Zero(15);
  for (size_t i = 0; i < params.size(); ++i) {
    const int nr = costs[i]->num_residuals();
    Eigen::MatrixXd J = Eigen::MatrixXd::Zero(nr, 15);
    Eigen::VectorXd r(nr);
    std::vector<Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>> jac(params[i].size());
    std::vector<double*> jp;
    for (auto& j : jac) {
      j.resize(nr, 3);
      jp.push_back(j.data());
    }
    ASSERT_TRUE(costs[i]->Evaluate(params[i].data(), r.data(), jp.data()));
    for (size_t b = 0; b < params[i].size(); ++b) J.middleCols(col[params[i][b]], 3) = jac[b];
    H += J.transpose() * J;
    g += J.transpose() * r;
  }
  const Eigen::MatrixXd Hmm_inv = H.topLeftCorner(9, 9).inverse();
  const Eigen::MatrixXd Hs = H.bottomRightCorner(6, 6) - H.bottomLeftCorner(6, 9) * Hmm_inv * H.topRightCorner(9, 6);
  const Eigen::VectorXd gs = g.tail(6) - H.bottomLeftCorner(6, 9) * Hmm_inv * g.head(9);
  // The prior's blocks are in first-seen order (k1, k2).
  ASSERT_EQ(prior->blocks().size(), 2u);
  EXPECT_EQ(prior->blocks()[0].parameters, k1.data());
  const Eigen::MatrixXd& Js = prior->jacobian();
  EXPECT_LT((Js.transpose() * Js - Hs).norm(), 1e-8 * Hs.norm());
  EXPECT_LT((Js.transpose() * prior->residual0() - gs).norm(), 1e-8 * std::max(1.0, gs.norm()));
}

}  // namespace
}  // namespace evio::backend
