// Tests of the SO(3)/SE(3) helpers: exp/log round trips from the identity to angle pi, Jacobians
// against central differences, interpolation and SE(3) algebra against 4x4 matrices.
#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <unsupported/Eigen/MatrixFunctions>

#include "evio/calib/geometry.h"

namespace evio::calib {
namespace {

// Short scientific notation for RecordProperty.
std::string sci(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.3g", v);
  return buf;
}

Vec3 random_unit(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  return Vec3(n(rng), n(rng), n(rng)).normalized();
}

Quat random_quat(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  return Quat(n(rng), n(rng), n(rng), n(rng)).normalized();
}

// Angle of R0^T R1 (rad): a metric independent of the log under test.
double rotation_distance(const Mat3& R0, const Mat3& R1) {
  return Eigen::AngleAxisd(R0.transpose() * R1).angle();
}

// d(f)/d(d) at d = 0 by central differences, f: R^3 -> R^3.
template <typename F>
Mat3 numeric_jacobian(F f, double eps = 1e-6) {
  Mat3 J;
  for (int i = 0; i < 3; ++i) {
    const Vec3 d = eps * Vec3::Unit(i);
    J.col(i) = (f(d) - f(-d)) / (2.0 * eps);
  }
  return J;
}

const std::vector<double> kAngles = {0.0, 1e-12, 1e-9, 1e-6, 1e-4, 1e-3, 1e-2, 0.1, 1.0, 2.0, 3.0,
                                     M_PI - 1e-6, M_PI - 1e-9};

TEST(Geometry, HatVee) {
  std::mt19937 rng(1);
  std::normal_distribution<double> n(0.0, 1.0);
  for (int i = 0; i < 20; ++i) {
    const Vec3 w(n(rng), n(rng), n(rng));
    const Vec3 v(n(rng), n(rng), n(rng));
    EXPECT_LT((hat(w) * v - w.cross(v)).norm(), 1e-14);
    EXPECT_EQ((hat(w) + hat(w).transpose()).norm(), 0.0);
    EXPECT_LT((vee(hat(w)) - w).norm(), 1e-15);
  }
  // vee averages an asymmetric perturbation: the symmetric part is ignored.
  Mat3 W = hat(Vec3(1, 2, 3));
  W(0, 1) += 0.2;
  W(1, 0) += 0.2;
  EXPECT_LT((vee(W) - Vec3(1, 2, 3)).norm(), 1e-15);
}

TEST(Geometry, ExpMatchesAngleAxisAndQuaternion) {
  std::mt19937 rng(2);
  for (double angle : kAngles) {
    for (int i = 0; i < 10; ++i) {
      const Vec3 axis = random_unit(rng);
      const Vec3 phi = angle * axis;
      const Mat3 R = so3_exp(phi);
      const Mat3 R_ref = Eigen::AngleAxisd(angle, axis).toRotationMatrix();
      EXPECT_LT((R - R_ref).cwiseAbs().maxCoeff(), 1e-15) << "angle " << angle;
      EXPECT_LT((R.transpose() * R - Mat3::Identity()).cwiseAbs().maxCoeff(), 4e-15);
      const Quat q = so3_exp_quat(phi);
      EXPECT_NEAR(q.norm(), 1.0, 1e-15);
      EXPECT_LT((q.toRotationMatrix() - R).cwiseAbs().maxCoeff(), 1e-15) << "angle " << angle;
    }
  }
}

TEST(Geometry, LogExpRoundTripAllAngles) {
  std::mt19937 rng(3);
  double worst_abs = 0.0;
  for (double angle : kAngles) {
    for (int i = 0; i < 50; ++i) {
      const Vec3 phi = angle * random_unit(rng);
      const Vec3 from_matrix = so3_log(so3_exp(phi));
      const Vec3 from_quat = so3_log(so3_exp_quat(phi));
      const double err_m = (from_matrix - phi).norm();
      const double err_q = (from_quat - phi).norm();
      worst_abs = std::max({worst_abs, err_m, err_q});
      // Relative accuracy at small angles, absolute near pi where R itself carries 1e-16 rounding.
      const double tol = std::max(1e-15, 1e-13 * angle);
      EXPECT_LE(err_m, tol) << "matrix log, angle " << angle;
      EXPECT_LE(err_q, tol) << "quaternion log, angle " << angle;
    }
  }
  std::printf("so3 log(exp(phi)): max |error| = %.3g rad\n", worst_abs);
  RecordProperty("worst_log_exp_error", sci(worst_abs));
}

TEST(Geometry, LogAtExactlyPi) {
  std::mt19937 rng(4);
  // Exact half-turn matrices 2 a a^T - I, including the coordinate axes.
  std::vector<Vec3> axes = {Vec3::UnitX(), Vec3::UnitY(), Vec3::UnitZ(), Vec3(1, 1, 0).normalized(),
                            Vec3(1, -1, 1).normalized()};
  for (int i = 0; i < 50; ++i) axes.push_back(random_unit(rng));
  for (const Vec3& a : axes) {
    const Mat3 R = 2.0 * a * a.transpose() - Mat3::Identity();
    const Vec3 phi = so3_log(R);
    EXPECT_NEAR(phi.norm(), M_PI, 1e-14);
    // The axis of a half turn is defined up to sign.
    EXPECT_NEAR(std::abs(phi.normalized().dot(a)), 1.0, 1e-14);
    EXPECT_LT((so3_exp(phi) - R).cwiseAbs().maxCoeff(), 1e-14);
    // Through so3_exp at exactly pi too.
    const Vec3 phi2 = so3_log(so3_exp(M_PI * a));
    EXPECT_NEAR(phi2.norm(), M_PI, 1e-14);
    EXPECT_NEAR(std::abs(phi2.normalized().dot(a)), 1.0, 1e-14);
    EXPECT_NEAR(so3_log(Quat(0.0, a.x(), a.y(), a.z())).norm(), M_PI, 1e-15);
  }
}

TEST(Geometry, LogNearPiIsAccurate) {
  std::mt19937 rng(5);
  for (double eps : {1e-3, 1e-6, 1e-9, 1e-12}) {
    for (int i = 0; i < 50; ++i) {
      const Vec3 a = random_unit(rng);
      const double angle = M_PI - eps;
      const Mat3 R = Eigen::AngleAxisd(angle, a).toRotationMatrix();
      const Vec3 phi = so3_log(R);
      EXPECT_NEAR(phi.norm(), angle, 1e-14) << "eps " << eps;
      EXPECT_GT(phi.normalized().dot(a), 1.0 - 1e-14) << "eps " << eps;
      EXPECT_LT(rotation_distance(so3_exp(phi), R), 1e-14);
    }
  }
}

TEST(Geometry, LogOfRandomRotations) {
  std::mt19937 rng(6);
  for (int i = 0; i < 500; ++i) {
    const Quat q = random_quat(rng);
    const Vec3 phi = so3_log(q);
    EXPECT_LE(phi.norm(), M_PI + 1e-15);
    EXPECT_LT(rotation_distance(so3_exp(phi), q.toRotationMatrix()), 1e-14);
    EXPECT_LT((so3_log(q.toRotationMatrix()) - phi).norm(), 1e-13);
    // -q is the same rotation.
    EXPECT_LT((so3_log(Quat(-q.coeffs())) - phi).norm(), 1e-15);
  }
}

TEST(Geometry, RightAndLeftJacobiansMatchNumeric) {
  std::mt19937 rng(7);
  double worst = 0.0;
  for (double angle : {0.0, 1e-12, 1e-6, 1e-3, 1e-2, 0.5, 1.0, 2.0, 2.5, 3.0}) {
    for (int i = 0; i < 10; ++i) {
      const Vec3 phi = angle * random_unit(rng);
      const Mat3 R = so3_exp(phi);
      // Exp(phi + d) = Exp(phi) Exp(Jr d):  Jr = d Log(Exp(phi)^T Exp(phi + d)) / dd.
      const Mat3 Jr_num =
          numeric_jacobian([&](const Vec3& d) { return so3_log(Mat3(R.transpose() * so3_exp(phi + d))); });
      // Exp(phi + d) = Exp(Jl d) Exp(phi).
      const Mat3 Jl_num =
          numeric_jacobian([&](const Vec3& d) { return so3_log(Mat3(so3_exp(phi + d) * R.transpose())); });
      const double er = (so3_right_jacobian(phi) - Jr_num).cwiseAbs().maxCoeff();
      const double el = (so3_left_jacobian(phi) - Jl_num).cwiseAbs().maxCoeff();
      worst = std::max({worst, er, el});
      EXPECT_LT(er, 1e-8) << "angle " << angle;
      EXPECT_LT(el, 1e-8) << "angle " << angle;
      EXPECT_LT((so3_left_jacobian(phi) - R * so3_right_jacobian(phi)).cwiseAbs().maxCoeff(), 1e-15);
    }
  }
  std::printf("so3 Jr/Jl: max |analytic - numeric| = %.3g\n", worst);
  RecordProperty("worst_jacobian_error", sci(worst));
}

TEST(Geometry, JacobianInversesIncludingNearZeroAndPi) {
  std::mt19937 rng(8);
  for (double angle : {0.0, 1e-12, 1e-8, 1e-4, 1e-3 * (1 - 1e-9), 1e-3 * (1 + 1e-9), 1e-2 * (1 - 1e-9),
                       1e-2 * (1 + 1e-9), 0.3, 1.0, 2.0, 3.0, M_PI - 1e-9, M_PI}) {
    for (int i = 0; i < 10; ++i) {
      const Vec3 phi = angle * random_unit(rng);
      EXPECT_LT((so3_right_jacobian(phi) * so3_right_jacobian_inv(phi) - Mat3::Identity()).cwiseAbs().maxCoeff(),
                1e-14)
          << "angle " << angle;
      EXPECT_LT((so3_left_jacobian(phi) * so3_left_jacobian_inv(phi) - Mat3::Identity()).cwiseAbs().maxCoeff(),
                1e-14)
          << "angle " << angle;
      EXPECT_LT((so3_right_jacobian_inv(phi) - so3_right_jacobian(phi).inverse()).cwiseAbs().maxCoeff(), 1e-13);
    }
  }
  EXPECT_TRUE(so3_right_jacobian(Vec3::Zero()).isIdentity(0.0));
  EXPECT_TRUE(so3_right_jacobian_inv(Vec3::Zero()).isIdentity(0.0));
}

TEST(Geometry, JacobiansAreContinuousAcrossSeriesThresholds) {
  const Vec3 axis = Vec3(0.3, -0.5, 0.8).normalized();
  // One ulp either side of each branch switch: a mismatch between the series and the closed form
  // would show as a jump; the true change over two ulps is ~1e-18.
  for (double t : {1e-4, 1e-3, 1e-2}) {
    const Vec3 a = std::nextafter(t, 0.0) * axis;
    const Vec3 b = std::nextafter(t, 1.0) * axis;
    EXPECT_LT((so3_right_jacobian(a) - so3_right_jacobian(b)).cwiseAbs().maxCoeff(), 1e-15);
    EXPECT_LT((so3_right_jacobian_inv(a) - so3_right_jacobian_inv(b)).cwiseAbs().maxCoeff(), 1e-15);
    EXPECT_LT((so3_exp(a) - so3_exp(b)).cwiseAbs().maxCoeff(), 1e-15);
  }
}

TEST(Geometry, So3Interpolation) {
  std::mt19937 rng(9);
  for (int i = 0; i < 100; ++i) {
    const Quat q0 = random_quat(rng);
    const Quat q1 = random_quat(rng);
    EXPECT_LT(q0.angularDistance(so3_interpolate(q0, q1, 0.0)), 1e-14);
    EXPECT_LT(q1.angularDistance(so3_interpolate(q0, q1, 1.0)), 1e-7);  // acos-based metric
    EXPECT_LT((so3_interpolate(q0, q1, 1.0).toRotationMatrix() - q1.toRotationMatrix()).cwiseAbs().maxCoeff(),
              1e-14);
    const Quat mid = so3_interpolate(q0, q1, 0.5);
    const Vec3 full = so3_log(q0.conjugate() * q1);
    const Vec3 half = so3_log(q0.conjugate() * mid);
    EXPECT_LT((2.0 * half - full).norm(), 1e-13);
    // Same as Eigen's shortest-path slerp, and independent of the sign of q1.
    EXPECT_LT((mid.toRotationMatrix() - q0.slerp(0.5, q1).toRotationMatrix()).cwiseAbs().maxCoeff(), 1e-13);
    const Quat mid_neg = so3_interpolate(q0, Quat(-q1.coeffs()), 0.5);
    EXPECT_LT((mid_neg.toRotationMatrix() - mid.toRotationMatrix()).cwiseAbs().maxCoeff(), 1e-14);
  }
}

SE3 random_se3(std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  return SE3(random_quat(rng), Vec3(n(rng), n(rng), n(rng)));
}

bool se3_near(const SE3& a, const SE3& b, double tol) {
  return (a.matrix() - b.matrix()).cwiseAbs().maxCoeff() <= tol;
}

TEST(Geometry, Se3ExpLogRoundTripAndMatrixExponential) {
  std::mt19937 rng(10);
  std::normal_distribution<double> n(0.0, 1.0);
  for (double angle : {0.0, 1e-12, 1e-6, 0.5, 2.0, 3.0, M_PI - 1e-6}) {
    for (int i = 0; i < 20; ++i) {
      Vec6 xi;
      xi.head<3>() = Vec3(n(rng), n(rng), n(rng));
      xi.tail<3>() = angle * random_unit(rng);
      const SE3 T = se3_exp(xi);
      // Reference: exponential of the 4x4 twist matrix.
      Eigen::Matrix4d X = Eigen::Matrix4d::Zero();
      X.topLeftCorner<3, 3>() = hat(xi.tail<3>());
      X.topRightCorner<3, 1>() = xi.head<3>();
      const Eigen::Matrix4d T_ref = X.exp();
      EXPECT_LT((T.matrix() - T_ref).cwiseAbs().maxCoeff(), 1e-12) << "angle " << angle;
      const double tol = angle > 3.0 ? 1e-8 : 1e-12;  // Jl^-1 grows as 1/(pi - angle)
      EXPECT_LT((se3_log(T) - xi).norm(), tol) << "angle " << angle;
    }
  }
  Vec6 pure_translation;
  pure_translation << 1.0, -2.0, 3.0, 0.0, 0.0, 0.0;
  EXPECT_TRUE(se3_exp(pure_translation).translation.isApprox(Vec3(1, -2, 3), 0.0));
}

TEST(Geometry, Se3InverseCompositionAndMatrix) {
  std::mt19937 rng(11);
  std::normal_distribution<double> n(0.0, 1.0);
  for (int i = 0; i < 100; ++i) {
    const SE3 a = random_se3(rng);
    const SE3 b = random_se3(rng);
    const Vec3 p(n(rng), n(rng), n(rng));
    EXPECT_TRUE(se3_near(a * a.inverse(), SE3::identity(), 1e-14));
    EXPECT_TRUE(se3_near(a.inverse() * a, SE3::identity(), 1e-14));
    EXPECT_LT(((a * b).matrix() - a.matrix() * b.matrix()).cwiseAbs().maxCoeff(), 1e-14);
    EXPECT_LT(((a * b) * p - a * (b * p)).norm(), 1e-14);
    const Eigen::Vector4d ph = a.matrix() * p.homogeneous();
    EXPECT_LT((a * p - ph.head<3>()).norm(), 1e-14);
    EXPECT_TRUE(se3_near(SE3::from_matrix(a.matrix()), a, 1e-15));
    EXPECT_LT((a.inverse().matrix() - a.matrix().inverse()).cwiseAbs().maxCoeff(), 1e-14);
  }
  // from_matrix re-orthonormalises a slightly perturbed rotation block.
  Eigen::Matrix4d M = random_se3(rng).matrix();
  M(0, 1) += 1e-9;
  const SE3 T = SE3::from_matrix(M);
  EXPECT_NEAR(T.rotation.norm(), 1.0, 1e-15);
  EXPECT_LT((T.rotation_matrix().transpose() * T.rotation_matrix() - Mat3::Identity()).cwiseAbs().maxCoeff(),
            1e-15);
  EXPECT_LT((T.matrix() - M).cwiseAbs().maxCoeff(), 1e-9);
}

TEST(Geometry, Se3Interpolation) {
  std::mt19937 rng(12);
  for (int i = 0; i < 50; ++i) {
    const SE3 a = random_se3(rng);
    const SE3 b = random_se3(rng);
    EXPECT_TRUE(se3_near(se3_interpolate(a, b, 0.0), a, 1e-14));
    EXPECT_TRUE(se3_near(se3_interpolate(a, b, 1.0), b, 1e-14));
    const SE3 m = se3_interpolate(a, b, 0.5);
    EXPECT_LT((m.translation - 0.5 * (a.translation + b.translation)).norm(), 1e-15);
    EXPECT_LT((m.rotation_matrix() - so3_interpolate(a.rotation, b.rotation, 0.5).toRotationMatrix())
                  .cwiseAbs()
                  .maxCoeff(),
              1e-15);
  }
}

}  // namespace
}  // namespace evio::calib
