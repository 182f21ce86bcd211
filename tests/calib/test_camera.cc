// Tests of the pinhole camera models: unproject/project round trips over whole images (radtan
// with the ECD DAVIS240C calibration, equidistant fisheye), analytic Jacobians against central
// differences, the undistortion lookup table and intrinsics validation.
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "evio/calib/camera.h"

namespace evio::calib {
namespace {

// Short scientific notation for RecordProperty.
std::string sci(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.3g", v);
  return buf;
}

// ECD DAVIS240C calibration (calib.txt of the shapes/dynamic/boxes/poster sequences).
CameraIntrinsics ecd_davis240c() {
  CameraIntrinsics c;
  c.width = 240;
  c.height = 180;
  c.fx = 199.092366542;
  c.fy = 198.82882047;
  c.cx = 132.192071378;
  c.cy = 110.712660011;
  c.model = DistortionModel::kRadtan;
  c.distortion = {-0.368436311798, 0.150947243557, -0.000296130534385, -0.000759431726241, 0.0};
  return c;
}

// DAVIS346-like radtan with a non-zero k3.
CameraIntrinsics davis346_radtan_k3() {
  CameraIntrinsics c;
  c.width = 346;
  c.height = 260;
  c.fx = 320.5;
  c.fy = 319.8;
  c.cx = 170.3;
  c.cy = 128.9;
  c.model = DistortionModel::kRadtan;
  c.distortion = {-0.31, 0.11, 1e-3, -5e-4, -0.02};
  return c;
}

// TUM-VI-like 190 degree fisheye (Kalibr equidistant): the image corners are beyond 90 degrees.
CameraIntrinsics tumvi_fisheye() {
  CameraIntrinsics c;
  c.width = 512;
  c.height = 512;
  c.fx = 190.97847715128717;
  c.fy = 190.9733070521226;
  c.cx = 254.93170605935475;
  c.cy = 256.8974428996504;
  c.model = DistortionModel::kEquidistant;
  c.distortion = {0.0034823894022493434, 0.0007150348452162257, -0.0020532361418706202, 0.00020293673591811182};
  return c;
}

// A narrower equidistant lens whose whole image is in front of the camera.
CameraIntrinsics davis346_equidistant() {
  CameraIntrinsics c;
  c.width = 346;
  c.height = 260;
  c.fx = 250.0;
  c.fy = 249.5;
  c.cx = 172.1;
  c.cy = 131.4;
  c.model = DistortionModel::kEquidistant;
  c.distortion = {-0.012, 0.004, -0.0015, 0.0002};
  return c;
}

struct RoundTripStats {
  double max_error_px = 0.0;
  int points = 0;
  int behind = 0;  // valid bearings with z <= 0 (fisheye beyond 90 degrees)
  int failed = 0;
};

// unproject -> project over a half-pixel grid covering the image including its outer edges.
RoundTripStats round_trip_grid(const PinholeCamera& cam) {
  RoundTripStats s;
  for (double y = -0.5; y <= cam.height() - 0.5; y += 0.5) {
    for (double x = -0.5; x <= cam.width() - 0.5; x += 0.5) {
      const Eigen::Vector2d px(x, y);
      Eigen::Vector3d b;
      if (!cam.unproject(px, &b)) {
        ++s.failed;
        continue;
      }
      EXPECT_NEAR(b.norm(), 1.0, 1e-15);
      Eigen::Vector2d back;
      if (!cam.project(b, &back)) {
        EXPECT_LE(b.z(), 1e-12) << "project refused a point in front at " << x << "," << y;
        ++s.behind;
        continue;
      }
      s.max_error_px = std::max(s.max_error_px, (back - px).norm());
      ++s.points;
    }
  }
  return s;
}

TEST(Camera, RadtanEcdRoundTripFullImage) {
  const PinholeCamera cam(ecd_davis240c());
  const RoundTripStats s = round_trip_grid(cam);
  std::printf("radtan ECD DAVIS240C: %d points, max unproject->project error %.3g px\n", s.points, s.max_error_px);
  RecordProperty("max_error_px", sci(s.max_error_px));
  EXPECT_EQ(s.failed, 0);
  EXPECT_EQ(s.behind, 0);
  EXPECT_EQ(s.points, 481 * 361);
  EXPECT_LT(s.max_error_px, 1e-10);
}

TEST(Camera, RadtanWithK3RoundTripFullImage) {
  const PinholeCamera cam(davis346_radtan_k3());
  const RoundTripStats s = round_trip_grid(cam);
  std::printf("radtan k3 DAVIS346: %d points, max error %.3g px\n", s.points, s.max_error_px);
  EXPECT_EQ(s.failed, 0);
  EXPECT_LT(s.max_error_px, 1e-10);
}

TEST(Camera, EquidistantFisheyeRoundTripFullImage) {
  const PinholeCamera cam(tumvi_fisheye());
  const RoundTripStats s = round_trip_grid(cam);
  std::printf("equidistant TUM-VI fisheye: %d points in front, %d beyond 90 deg, max error %.3g px\n", s.points,
              s.behind, s.max_error_px);
  RecordProperty("max_error_px", sci(s.max_error_px));
  EXPECT_EQ(s.failed, 0);
  EXPECT_GT(s.behind, 0);  // the corners of this lens look backwards
  EXPECT_GT(s.points, 700000);
  EXPECT_LT(s.max_error_px, 1e-10);

  // Rays beyond 90 degrees still satisfy theta_d(theta) = r_d through the angle form.
  const CameraIntrinsics& k = cam.intrinsics();
  double max_angle_residual_px = 0.0;
  for (const Eigen::Vector2d& px : {Eigen::Vector2d(0, 0), Eigen::Vector2d(511, 0), Eigen::Vector2d(0, 511),
                                   Eigen::Vector2d(511, 511)}) {
    Eigen::Vector3d b;
    ASSERT_TRUE(cam.unproject(px, &b));
    EXPECT_LT(b.z(), 0.0);
    const double theta = std::atan2(b.head<2>().norm(), b.z());
    const double t2 = theta * theta;
    const double theta_d =
        theta * (1 + t2 * (k.distortion[0] + t2 * (k.distortion[1] + t2 * (k.distortion[2] + t2 * k.distortion[3]))));
    const Eigen::Vector2d dir = b.head<2>().normalized();
    const Eigen::Vector2d reproj(k.fx * theta_d * dir.x() + k.cx, k.fy * theta_d * dir.y() + k.cy);
    max_angle_residual_px = std::max(max_angle_residual_px, (reproj - px).norm());
    Eigen::Vector2d xn;
    EXPECT_FALSE(cam.undistort(Eigen::Vector2d((px.x() - k.cx) / k.fx, (px.y() - k.cy) / k.fy), &xn));
  }
  EXPECT_LT(max_angle_residual_px, 1e-10);
}

TEST(Camera, EquidistantNarrowRoundTripFullImage) {
  const PinholeCamera cam(davis346_equidistant());
  const RoundTripStats s = round_trip_grid(cam);
  std::printf("equidistant DAVIS346: %d points, max error %.3g px\n", s.points, s.max_error_px);
  EXPECT_EQ(s.failed, 0);
  EXPECT_EQ(s.behind, 0);
  EXPECT_LT(s.max_error_px, 1e-10);
}

TEST(Camera, NoDistortionRoundTrip) {
  CameraIntrinsics c = ecd_davis240c();
  c.model = DistortionModel::kNone;
  c.distortion.clear();
  const PinholeCamera cam(c);
  const RoundTripStats s = round_trip_grid(cam);
  EXPECT_EQ(s.failed, 0);
  EXPECT_LT(s.max_error_px, 1e-12);
}

TEST(Camera, ProjectThenUnprojectRecoversBearing) {
  for (const CameraIntrinsics& c : {ecd_davis240c(), tumvi_fisheye(), davis346_equidistant()}) {
    const PinholeCamera cam(c);
    for (double y = -0.6; y <= 0.6; y += 0.05) {
      for (double x = -0.8; x <= 0.8; x += 0.05) {
        const Eigen::Vector3d p(x * 3.0, y * 3.0, 3.0);
        Eigen::Vector2d px;
        ASSERT_TRUE(cam.project(p, &px));
        Eigen::Vector3d b;
        ASSERT_TRUE(cam.unproject(px, &b)) << distortion_model_name(c.model) << " " << x << "," << y;
        EXPECT_LT((b - p.normalized()).norm(), 1e-12) << distortion_model_name(c.model);
      }
    }
  }
}

TEST(Camera, UnprojectFarOutsideOrInvalidTerminates) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (const CameraIntrinsics& c : {ecd_davis240c(), davis346_radtan_k3(), tumvi_fisheye()}) {
    const PinholeCamera cam(c);
    for (const Eigen::Vector2d& px : {Eigen::Vector2d(-2000, -2000), Eigen::Vector2d(5000, 30),
                                      Eigen::Vector2d(1e9, 1e9), Eigen::Vector2d(-1e12, 3)}) {
      Eigen::Vector3d b;
      if (cam.unproject(px, &b)) {
        EXPECT_NEAR(b.norm(), 1.0, 1e-12);
        Eigen::Vector2d back;
        if (cam.project(b, &back)) {
          EXPECT_LT((back - px).norm(), 1e-10 * std::max(1.0, px.norm()));
        }
      }
    }
    Eigen::Vector3d b;
    EXPECT_FALSE(cam.unproject(Eigen::Vector2d(nan, 10), &b));
    Eigen::Vector2d px;
    EXPECT_FALSE(cam.project(Eigen::Vector3d(nan, 0, 1), &px) && std::isfinite(px.x()));
  }
}

TEST(Camera, ProjectRejectsPointsBehind) {
  const PinholeCamera cam(ecd_davis240c());
  Eigen::Vector2d px;
  EXPECT_FALSE(cam.project(Eigen::Vector3d(0.1, 0.2, 0.0), &px));
  EXPECT_FALSE(cam.project(Eigen::Vector3d(0.1, 0.2, -1.0), &px));
  EXPECT_FALSE(cam.project(Eigen::Vector3d::Zero(), &px));
  Eigen::MatrixXd J;
  EXPECT_FALSE(cam.project_jacobian_intrinsics(Eigen::Vector3d(0, 0, -1), &J));
  EXPECT_TRUE(cam.project(Eigen::Vector3d(0.0, 0.0, 1.0), &px));
  EXPECT_NEAR(px.x(), cam.intrinsics().cx, 1e-12);
  EXPECT_NEAR(px.y(), cam.intrinsics().cy, 1e-12);
}

// Points over the image at depth 2 (m), from a 10 px grid; includes the optical axis.
std::vector<Eigen::Vector3d> test_points(const PinholeCamera& cam) {
  std::vector<Eigen::Vector3d> pts;
  for (int y = 0; y < cam.height(); y += 10) {
    for (int x = 0; x < cam.width(); x += 10) {
      Eigen::Vector3d b;
      if (cam.unproject(Eigen::Vector2d(x, y), &b) && b.z() > 0.2) pts.push_back(2.0 * b / b.z());
    }
  }
  pts.emplace_back(0.0, 0.0, 2.0);
  pts.emplace_back(1e-9, -2e-9, 2.0);
  return pts;
}

std::vector<CameraIntrinsics> all_models() {
  CameraIntrinsics none = ecd_davis240c();
  none.model = DistortionModel::kNone;
  none.distortion.clear();
  CameraIntrinsics radtan4 = ecd_davis240c();
  radtan4.distortion.resize(4);
  return {ecd_davis240c(), radtan4, davis346_radtan_k3(), tumvi_fisheye(), davis346_equidistant(), none};
}

TEST(Camera, PointJacobianMatchesCentralDifferences) {
  double worst = 0.0;
  for (const CameraIntrinsics& c : all_models()) {
    const PinholeCamera cam(c);
    for (const Eigen::Vector3d& p : test_points(cam)) {
      Eigen::Vector2d px;
      Eigen::Matrix<double, 2, 3> J;
      ASSERT_TRUE(cam.project(p, &px, &J));
      const double eps = 1e-6;
      Eigen::Matrix<double, 2, 3> J_num;
      for (int i = 0; i < 3; ++i) {
        Eigen::Vector2d plus, minus;
        ASSERT_TRUE(cam.project(p + eps * Eigen::Vector3d::Unit(i), &plus));
        ASSERT_TRUE(cam.project(p - eps * Eigen::Vector3d::Unit(i), &minus));
        J_num.col(i) = (plus - minus) / (2 * eps);
      }
      const double err = (J - J_num).cwiseAbs().maxCoeff();
      worst = std::max(worst, err);
      EXPECT_LT(err, 1e-6) << distortion_model_name(c.model) << " at " << p.transpose();
    }
  }
  std::printf("point Jacobian: max |analytic - numeric| = %.3g px/m\n", worst);
  RecordProperty("max_point_jacobian_error", sci(worst));
}

TEST(Camera, DistortionJacobianMatchesCentralDifferences) {
  for (const CameraIntrinsics& c : all_models()) {
    const PinholeCamera cam(c);
    for (double y = -0.7; y <= 0.7; y += 0.1) {
      for (double x = -0.9; x <= 0.9; x += 0.1) {
        const Eigen::Vector2d xn(x, y);
        Eigen::Matrix2d J;
        cam.distort(xn, &J);
        Eigen::Matrix2d J_num;
        const double eps = 1e-7;
        for (int i = 0; i < 2; ++i) {
          const Eigen::Vector2d d = eps * Eigen::Vector2d::Unit(i);
          J_num.col(i) = (cam.distort(xn + d) - cam.distort(xn - d)) / (2 * eps);
        }
        EXPECT_LT((J - J_num).cwiseAbs().maxCoeff(), 1e-8) << distortion_model_name(c.model);
      }
    }
    Eigen::Matrix2d J0;
    EXPECT_TRUE(cam.distort(Eigen::Vector2d::Zero(), &J0).isZero(0.0));
    EXPECT_TRUE(J0.isIdentity(1e-15));
  }
}

TEST(Camera, IntrinsicsJacobianMatchesCentralDifferences) {
  double worst = 0.0;
  for (const CameraIntrinsics& c : all_models()) {
    const PinholeCamera cam(c);
    const int n = 4 + static_cast<int>(c.distortion.size());
    for (const Eigen::Vector3d& p : test_points(cam)) {
      Eigen::MatrixXd J;
      ASSERT_TRUE(cam.project_jacobian_intrinsics(p, &J));
      ASSERT_EQ(J.rows(), 2);
      ASSERT_EQ(J.cols(), n);
      for (int i = 0; i < n; ++i) {
        auto perturbed = [&](double delta) {
          CameraIntrinsics k = c;
          double* params[4] = {&k.fx, &k.fy, &k.cx, &k.cy};
          if (i < 4) {
            *params[i] += delta;
          } else {
            k.distortion[i - 4] += delta;
          }
          Eigen::Vector2d px;
          EXPECT_TRUE(PinholeCamera(k).project(p, &px));
          return px;
        };
        const double eps = 1e-6;
        const Eigen::Vector2d col = (perturbed(eps) - perturbed(-eps)) / (2 * eps);
        const double err = (J.col(i) - col).cwiseAbs().maxCoeff();
        worst = std::max(worst, err);
        EXPECT_LT(err, 1e-6) << distortion_model_name(c.model) << " parameter " << i << " at " << p.transpose();
      }
    }
  }
  std::printf("intrinsics Jacobian: max |analytic - numeric| = %.3g px/unit\n", worst);
  RecordProperty("max_intrinsics_jacobian_error", sci(worst));
}

TEST(Camera, UndistortInvertsDistort) {
  for (const CameraIntrinsics& c : all_models()) {
    const PinholeCamera cam(c);
    for (double y = -0.6; y <= 0.6; y += 0.1) {
      for (double x = -0.8; x <= 0.8; x += 0.1) {
        const Eigen::Vector2d xn(x, y);
        Eigen::Vector2d back;
        ASSERT_TRUE(cam.undistort(cam.distort(xn), &back)) << distortion_model_name(c.model);
        EXPECT_LT((back - xn).norm(), 1e-12) << distortion_model_name(c.model);
      }
    }
  }
}

TEST(Camera, LutMatchesUnproject) {
  for (const CameraIntrinsics& c : {ecd_davis240c(), tumvi_fisheye()}) {
    const PinholeCamera cam(c);
    const UndistortionLut lut(cam);
    ASSERT_EQ(lut.width(), cam.width());
    ASSERT_EQ(lut.height(), cam.height());
    double max_err = 0.0;
    double max_norm_err = 0.0;
    for (int y = 0; y < cam.height(); ++y) {
      for (int x = 0; x < cam.width(); ++x) {
        Eigen::Vector3d b;
        const bool ok = cam.unproject(Eigen::Vector2d(x, y), &b);
        ASSERT_EQ(lut.valid(x, y), ok);
        if (!ok) continue;
        max_err = std::max(max_err, (lut.bearing(x, y).cast<double>() - b).norm());
        const Eigen::Vector2f n = lut.normalized(x, y);
        if (b.z() > 0.1) {
          const Eigen::Vector2d n_ref = b.head<2>() / b.z();
          max_norm_err = std::max(max_norm_err, (n.cast<double>() - n_ref).norm() / std::max(1.0, n_ref.norm()));
        } else if (b.z() <= 0.0) {
          EXPECT_TRUE(std::isnan(n.x()) && std::isnan(n.y()));
        }
      }
    }
    EXPECT_LT(max_err, 1e-6) << distortion_model_name(c.model);
    EXPECT_LT(max_norm_err, 1e-6) << distortion_model_name(c.model);
  }
}

TEST(Camera, InImage) {
  const PinholeCamera cam(ecd_davis240c());
  EXPECT_TRUE(cam.in_image(Eigen::Vector2d(0, 0)));
  EXPECT_TRUE(cam.in_image(Eigen::Vector2d(239, 179)));
  EXPECT_FALSE(cam.in_image(Eigen::Vector2d(239.01, 100)));
  EXPECT_FALSE(cam.in_image(Eigen::Vector2d(-0.01, 100)));
  EXPECT_FALSE(cam.in_image(Eigen::Vector2d(5, 5), 6.0));
  EXPECT_TRUE(cam.in_image(Eigen::Vector2d(6, 6), 6.0));
  EXPECT_FALSE(cam.in_image(Eigen::Vector2d(234, 100), 6.0));
}

TEST(Camera, ValidateRejectsBadIntrinsics) {
  std::string why;
  EXPECT_TRUE(ecd_davis240c().Validate(&why)) << why;
  EXPECT_TRUE(tumvi_fisheye().Validate(nullptr));

  const std::vector<std::pair<std::function<void(CameraIntrinsics&)>, std::string>> cases = {
      {[](CameraIntrinsics& c) { c.width = 0; }, "resolution"},
      {[](CameraIntrinsics& c) { c.height = -5; }, "resolution"},
      {[](CameraIntrinsics& c) { c.fx = 0.0; }, "focal"},
      {[](CameraIntrinsics& c) { c.fy = -200.0; }, "focal"},
      {[](CameraIntrinsics& c) { c.fx = std::numeric_limits<double>::quiet_NaN(); }, "focal"},
      {[](CameraIntrinsics& c) { c.cx = std::numeric_limits<double>::infinity(); }, "principal point"},
      {[](CameraIntrinsics& c) { c.distortion[1] = std::numeric_limits<double>::quiet_NaN(); }, "finite"},
      {[](CameraIntrinsics& c) { c.distortion.resize(3); }, "radtan takes 4 or 5"},
      {[](CameraIntrinsics& c) { c.distortion.resize(6); }, "radtan takes 4 or 5"},
      {[](CameraIntrinsics& c) { c.model = DistortionModel::kEquidistant; }, "equidistant takes 4"},
      {[](CameraIntrinsics& c) { c.model = DistortionModel::kNone; }, "none takes no"},
  };
  for (const auto& [mutate, expected] : cases) {
    CameraIntrinsics c = ecd_davis240c();
    mutate(c);
    why.clear();
    EXPECT_FALSE(c.Validate(&why));
    EXPECT_NE(why.find(expected), std::string::npos) << "message: " << why;
    EXPECT_FALSE(c.Validate(nullptr));
    EXPECT_THROW(PinholeCamera{c}, std::invalid_argument);
  }
}

TEST(Camera, DistortionModelNames) {
  for (DistortionModel m : {DistortionModel::kNone, DistortionModel::kRadtan, DistortionModel::kEquidistant}) {
    EXPECT_EQ(distortion_model_from_name(distortion_model_name(m)), m);
  }
  EXPECT_EQ(distortion_model_from_name("plumb_bob"), DistortionModel::kRadtan);
  EXPECT_EQ(distortion_model_from_name("fisheye"), DistortionModel::kEquidistant);
  EXPECT_EQ(distortion_model_from_name("equi"), DistortionModel::kEquidistant);
  EXPECT_FALSE(distortion_model_from_name("fov").has_value());
  EXPECT_FALSE(distortion_model_from_name("").has_value());
}

}  // namespace
}  // namespace evio::calib
