#include "evio/simulator/scene.h"

#include <cmath>
#include <cstring>
#include <random>

#include <utility>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

namespace evio::simulator {
namespace {

using calib::CameraIntrinsics;
using calib::DistortionModel;
using calib::PinholeCamera;
using calib::SE3;

PinholeCamera make_camera(int w, int h, double f, bool radtan) {
  CameraIntrinsics in;
  in.width = w;
  in.height = h;
  in.fx = f;
  in.fy = f * 1.01;
  in.cx = (w - 1) / 2.0 + 1.3;
  in.cy = (h - 1) / 2.0 - 0.7;
  if (radtan) {
    in.model = DistortionModel::kRadtan;
    in.distortion = {-0.25, 0.07, 0.0012, -0.0007};
  }
  return PinholeCamera(in);
}

// Pinhole without distortion, principal point at the image centre.
PinholeCamera ideal_camera(int w, int h, double f) {
  CameraIntrinsics in;
  in.width = w;
  in.height = h;
  in.fx = f;
  in.fy = f;
  in.cx = (w - 1) / 2.0;
  in.cy = (h - 1) / 2.0;
  return PinholeCamera(in);
}

cv::Mat random_image(int w, int h, uint64_t seed) {
  std::mt19937_64 rng(seed);
  cv::Mat m(h, w, CV_32F);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) m.at<float>(y, x) = static_cast<float>(0.05 + 0.9 * ((rng() >> 11) * 0x1.0p-53));
  return m;
}

std::shared_ptr<const Texture> constant_texture(float value, int w = 8, int h = 8) {
  return std::make_shared<const Texture>(cv::Mat(h, w, CV_32F, cv::Scalar(value)));
}

// Camera looking along world +x, right = -y, down = -z (level, at the panorama's equator).
Eigen::Matrix3d R_w_c_level() {
  Eigen::Matrix3d R;
  R.col(0) = -Eigen::Vector3d::UnitY();
  R.col(1) = -Eigen::Vector3d::UnitZ();
  R.col(2) = Eigen::Vector3d::UnitX();
  return R;
}

CameraState moving_state(const SE3& T_w_c) {
  CameraState s;
  s.t_ns = 1'000'000'000;
  s.T_w_c = T_w_c;
  s.v_c = Eigen::Vector3d(0.4, -0.25, 0.6);
  s.omega_c = Eigen::Vector3d(0.7, -1.1, 0.5);
  return s;
}

// Pixel of a world point seen by the camera state moved by dt with constant body velocities
// (R(dt) = R Exp(omega dt), p(dt) = p + R v dt, whose derivative at dt = 0 is the model's).
Eigen::Vector2d project_at(const PinholeCamera& cam, const CameraState& s, const Eigen::Vector3d& X_w, double dt,
                           bool at_infinity) {
  const Eigen::Matrix3d R = s.T_w_c.rotation_matrix() * calib::so3_exp(s.omega_c * dt);
  const Eigen::Vector3d p = s.T_w_c.translation + s.T_w_c.rotation_matrix() * s.v_c * dt;
  const Eigen::Vector3d X_c = at_infinity ? Eigen::Vector3d(R.transpose() * X_w) : Eigen::Vector3d(R.transpose() * (X_w - p));
  Eigen::Vector2d px;
  EXPECT_TRUE(cam.project(X_c, &px));
  return px;
}

Eigen::Vector2d numeric_flow(const PinholeCamera& cam, const CameraState& s, const Eigen::Vector3d& X_w,
                             bool at_infinity) {
  const double dt = 1e-4;
  return (project_at(cam, s, X_w, dt, at_infinity) - project_at(cam, s, X_w, -dt, at_infinity)) / (2 * dt);
}

Eigen::Vector2d flow_at(const RenderedView& v, int x, int y) {
  const cv::Vec2f f = v.flow.at<cv::Vec2f>(y, x);
  return Eigen::Vector2d(f[0], f[1]);
}

double image_std(const cv::Mat& m) {
  cv::Scalar mean, stddev;
  cv::meanStdDev(m, mean, stddev);
  return stddev[0];
}

// ---------------------------------------------------------------------------------------------

TEST(PixelRays, BearingsOffsetsAndAngles) {
  const PinholeCamera cam = make_camera(40, 30, 35, true);
  const PixelRays r1(cam, 1);
  const PixelRays r2(cam, 2);
  EXPECT_EQ(r1.centre_sample(), 0);
  EXPECT_EQ(r2.centre_sample(), -1);
  EXPECT_EQ(PixelRays(cam, 3).centre_sample(), 4);
  EXPECT_EQ(r2.samples_per_pixel(), 4);
  EXPECT_NEAR(r2.sub_offset(0).x(), -0.25, 1e-15);
  EXPECT_NEAR(r2.sub_offset(3).y(), 0.25, 1e-15);
  for (int y = 0; y < 30; y += 7) {
    for (int x = 0; x < 40; x += 9) {
      Eigen::Vector3d b;
      ASSERT_TRUE(cam.unproject(Eigen::Vector2d(x, y), &b));
      EXPECT_LT((r1.centre(x, y) - b).norm(), 1e-15);
      EXPECT_LT((r1.sub_ray(x, y, 0) - b).norm(), 1e-15);
      for (int k = 0; k < 4; ++k) {
        Eigen::Vector2d px;
        ASSERT_TRUE(cam.project(r2.sub_ray(x, y, k), &px));
        EXPECT_LT((px - (Eigen::Vector2d(x, y) + r2.sub_offset(k))).norm(), 1e-8);
        EXPECT_NEAR(r2.sub_ray(x, y, k).norm(), 1.0, 1e-12);
      }
      EXPECT_NEAR(r2.sample_angle_rad(x, y), 0.5 * r1.sample_angle_rad(x, y), 1e-12);
    }
  }
  // Ideal pinhole: one pixel at the axis spans 1 / f rad; off-axis the solid angle per px^2 is
  // cos^3(theta) / f^2, so the isotropic angle is cos^1.5(theta) / f.
  const PinholeCamera ideal = ideal_camera(41, 31, 50);
  const PixelRays ri(ideal, 1);
  EXPECT_NEAR(ri.sample_angle_rad(20, 15), 1.0 / 50, 1e-9);
  const double r = std::hypot(20.0, 15.0);
  EXPECT_NEAR(ri.sample_angle_rad(0, 0), std::pow(std::cos(std::atan(r / 50)), 1.5) / 50, 1e-9);
  EXPECT_THROW(PixelRays(cam, 0), std::invalid_argument);
}

TEST(PanoramaScene, PixelSamplesTheTexelOfItsWorldDirection) {
  const int W = 2048, H = 1024;
  const cv::Mat img = random_image(W, H, 11);
  auto tex = std::make_shared<const Texture>(img, TextureWrap::kRepeat, TextureWrap::kClamp);
  const PanoramaScene scene(tex, 1.5);
  const PinholeCamera cam = make_camera(160, 120, 600, true);  // 1.7 mrad pixels < 3 mrad texels: level 0
  const PixelRays rays(cam, 1);
  const int texels[][2] = {{700, 300}, {0, 512}, {2047, 700}, {1024, 100}, {333, 900}};
  const int pixels[][2] = {{50, 70}, {80, 60}, {5, 110}, {150, 3}, {100, 20}};
  for (int c = 0; c < 5; ++c) {
    const int i = texels[c][0], j = texels[c][1];
    const double lon = (i + 0.5) / W * 2 * M_PI - M_PI;
    const double lat = M_PI / 2 - (j + 0.5) / H * M_PI;
    const Eigen::Vector3d d_w(std::cos(lat) * std::cos(lon), std::cos(lat) * std::sin(lon), std::sin(lat));
    const int x = pixels[c][0], y = pixels[c][1];
    const Eigen::Vector3d b = rays.centre(x, y);
    // Any rotation taking b to d_w, with an extra roll about d_w.
    const Eigen::Quaterniond q =
        Eigen::Quaterniond(Eigen::AngleAxisd(0.3 + c, d_w)) * Eigen::Quaterniond::FromTwoVectors(b, d_w);
    CameraState s;
    s.T_w_c = SE3(q, Eigen::Vector3d(1, 2, 3));
    RenderedView v;
    scene.render(s, rays, RenderRequest{}, &v);
    EXPECT_NEAR(v.intensity.at<float>(y, x), 1.5 * img.at<float>(j, i), 2e-3) << "texel " << i << "," << j;
    EXPECT_TRUE(std::isinf(v.depth.at<float>(y, x)));
    EXPECT_EQ(v.label.at<uint16_t>(y, x), 0);
    EXPECT_TRUE(v.flow.empty());
  }
}

TEST(PanoramaScene, ConventionsUpIsRowZeroAndXIsTheMiddleColumn) {
  // Texture: value = column / W on the upper half, 0.05 on the lower half.
  const int W = 512, H = 256;
  cv::Mat img(H, W, CV_32F);
  for (int j = 0; j < H; ++j)
    for (int i = 0; i < W; ++i) img.at<float>(j, i) = j < H / 2 ? (i + 0.5f) / W : 0.05f;
  const PanoramaScene scene(std::make_shared<const Texture>(img));  // clamp/clamp: rebuilt as repeat/clamp
  EXPECT_EQ(scene.texture().wrap_u(), TextureWrap::kRepeat);
  const PinholeCamera cam = ideal_camera(21, 21, 400);
  const PixelRays rays(cam, 1);
  // Looking along +x, tilted up by 20 degrees: longitude 0 is column W/2 in the upper half.
  CameraState s;
  s.T_w_c = SE3(Eigen::Matrix3d(R_w_c_level() * Eigen::AngleAxisd(0.35, Eigen::Vector3d::UnitX()).toRotationMatrix()),
                Eigen::Vector3d::Zero());
  RenderedView v;
  scene.render(s, rays, RenderRequest{}, &v);
  EXPECT_NEAR(v.intensity.at<float>(10, 10), 0.5, 2e-3);
  // Looking along +y (longitude +90 deg): three quarters of the width.
  s.T_w_c = SE3(Eigen::Matrix3d(Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix() *
                                R_w_c_level() * Eigen::AngleAxisd(0.35, Eigen::Vector3d::UnitX()).toRotationMatrix()),
                Eigen::Vector3d::Zero());
  scene.render(s, rays, RenderRequest{}, &v);
  EXPECT_NEAR(v.intensity.at<float>(10, 10), 0.75, 2e-3);
  // Tilted down: lower half.
  s.T_w_c = SE3(Eigen::Matrix3d(R_w_c_level() * Eigen::AngleAxisd(-0.35, Eigen::Vector3d::UnitX()).toRotationMatrix()),
                Eigen::Vector3d::Zero());
  scene.render(s, rays, RenderRequest{}, &v);
  EXPECT_NEAR(v.intensity.at<float>(10, 10), 0.05, 1e-4);
}

// Renders a checkerboard panorama seen with wide pixels (about 5 texels per pixel).
cv::Mat render_checker_panorama(double cell_px, int supersample) {
  ProceduralTextureOptions o;
  o.kind = ProceduralKind::kCheckerboard;
  o.width = 2048;
  o.height = 1024;
  o.cell_px = cell_px;
  o.min_intensity = 0.1;
  o.max_intensity = 0.9;
  const PanoramaScene scene(
      std::make_shared<const Texture>(make_procedural_texture(o, TextureWrap::kRepeat, TextureWrap::kClamp)));
  const PixelRays rays(make_camera(120, 90, 60, false), supersample);
  CameraState s;
  s.T_w_c = SE3(Eigen::Matrix3d(R_w_c_level() * Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitY()).toRotationMatrix()),
                Eigen::Vector3d::Zero());
  RenderedView v;
  scene.render(s, rays, RenderRequest{}, &v);
  return v.intensity.clone();
}

TEST(PanoramaScene, MinifiedFineCheckerboardIsFilteredCoarseKeepsContrast) {
  for (int ss : {1, 2}) {
    for (double cell : {1.0, 1.5}) {
      const cv::Mat fine = render_checker_panorama(cell, ss);
      EXPECT_LT(image_std(fine), 0.02) << "fine checkerboard aliases, cell " << cell << " supersample " << ss;
      EXPECT_NEAR(cv::mean(fine)[0], 0.5, 0.02);
    }
    const cv::Mat coarse = render_checker_panorama(128, ss);
    double lo = 0, hi = 0;
    cv::minMaxLoc(coarse, &lo, &hi);
    EXPECT_LT(lo, 0.15);
    EXPECT_GT(hi, 0.85);
    EXPECT_GT(image_std(coarse), 0.3);
  }
}

TEST(PanoramaScene, FlowMatchesNumericDerivativeWithRadtan) {
  const PanoramaScene scene(std::make_shared<const Texture>(random_image(256, 128, 5)));
  const PinholeCamera cam = make_camera(64, 48, 55, true);
  const PixelRays rays(cam, 2);
  const CameraState s = moving_state(SE3(calib::so3_exp(Eigen::Vector3d(0.3, -1.2, 0.4)), Eigen::Vector3d(5, 1, -2)));
  RenderRequest req;
  req.flow = true;
  RenderedView v;
  scene.render(s, rays, req, &v);
  ASSERT_EQ(v.flow.type(), CV_32FC2);
  for (int y = 0; y < 48; y += 5) {
    for (int x = 0; x < 64; x += 7) {
      const Eigen::Vector3d d_w = s.T_w_c.rotation_matrix() * rays.centre(x, y);
      const Eigen::Vector2d expected = numeric_flow(cam, s, d_w, true);
      EXPECT_LT((flow_at(v, x, y) - expected).norm(), 1e-3 * expected.norm() + 1e-3) << x << "," << y;
      EXPECT_LT((static_point_flow(cam, rays.centre(x, y), INFINITY, s) - expected).norm(), 1e-5 * expected.norm());
    }
  }
}

// ---------------------------------------------------------------------------------------------

TEST(PlanarScene, FrontoParallelPlaneDepthEqualsDistance) {
  const PinholeCamera cam = make_camera(80, 60, 70, true);
  const PixelRays rays(cam, 2);
  const SE3 T_w_c(calib::so3_exp(Eigen::Vector3d(0.4, 0.1, -0.7)), Eigen::Vector3d(-1, 3, 0.5));
  const double d = 2.5;
  TexturedPlane p;
  p.center_w = T_w_c * Eigen::Vector3d(0.6, -0.2, d);
  p.axis_u_w = T_w_c.rotation_matrix() * Eigen::Vector3d::UnitX();
  p.axis_v_w = T_w_c.rotation_matrix() * -Eigen::Vector3d::UnitY();
  p.width_m = 3;
  p.height_m = 2;
  p.texture = std::make_shared<const Texture>(random_image(64, 64, 2));
  const PlanarScene scene({p}, 0.1);
  CameraState s;
  s.T_w_c = T_w_c;
  RenderedView v;
  scene.render(s, rays, RenderRequest{}, &v);
  int hit = 0, miss = 0;
  for (int y = 0; y < 60; ++y) {
    for (int x = 0; x < 80; ++x) {
      const uint16_t label = v.label.at<uint16_t>(y, x);
      const float depth = v.depth.at<float>(y, x);
      // Where the centre ray meets the plane rectangle (in the camera frame): |x - 0.6| <= 1.5, |y + 0.2| <= 1.
      const Eigen::Vector3d b = rays.centre(x, y);
      const Eigen::Vector3d P = b * (d / b.z());
      const bool inside = std::abs(P.x() - 0.6) <= 1.5 && std::abs(P.y() + 0.2) <= 1.0;
      // Skip pixels whose sub-samples (a quarter pixel, ~1 cm away) straddle the border.
      if (std::abs(std::abs(P.x() - 0.6) - 1.5) < 0.03 || std::abs(std::abs(P.y() + 0.2) - 1.0) < 0.03) continue;
      EXPECT_EQ(label, inside ? 1 : 0) << x << "," << y;
      if (inside) {
        ++hit;
        EXPECT_NEAR(depth, d, 1e-5 * d);
      } else {
        ++miss;
        EXPECT_TRUE(std::isinf(depth));
        EXPECT_FLOAT_EQ(v.intensity.at<float>(y, x), 0.1f);
      }
    }
  }
  EXPECT_GT(hit, 1000);
  EXPECT_GT(miss, 200);
}

TEST(PlanarScene, NearerPlaneOccludesFartherLabelsAndBackground) {
  const PinholeCamera cam = ideal_camera(64, 48, 60);
  const PixelRays rays(cam, 1);
  TexturedPlane far_plane;  // covers the right part of the view only
  far_plane.center_w = Eigen::Vector3d(1.0, 0, 3);
  far_plane.axis_u_w = Eigen::Vector3d::UnitX();
  far_plane.axis_v_w = -Eigen::Vector3d::UnitY();
  far_plane.width_m = 4;
  far_plane.height_m = 6;
  far_plane.texture = constant_texture(0.3f);
  TexturedPlane near_plane = far_plane;
  near_plane.center_w = Eigen::Vector3d(0, 0, 1.5);
  near_plane.width_m = 0.4;
  near_plane.height_m = 0.4;
  near_plane.texture = constant_texture(0.8f);
  near_plane.gain = 2;
  CameraState s;  // identity pose: the camera looks along world +z
  for (bool near_first : {false, true}) {
    const PlanarScene scene(near_first ? std::vector<TexturedPlane>{near_plane, far_plane}
                                       : std::vector<TexturedPlane>{far_plane, near_plane},
                            0.05);
    const uint16_t near_label = near_first ? 1 : 2, far_label = near_first ? 2 : 1;
    RenderedView v;
    scene.render(s, rays, RenderRequest{}, &v);
    // Centre: the near plane (in front of the far one).
    EXPECT_EQ(v.label.at<uint16_t>(24, 32), near_label);
    EXPECT_NEAR(v.depth.at<float>(24, 32), 1.5, 1e-5);
    EXPECT_NEAR(v.intensity.at<float>(24, 32), 1.6, 1e-5);
    // Right edge: the far plane.
    EXPECT_EQ(v.label.at<uint16_t>(24, 60), far_label);
    EXPECT_NEAR(v.depth.at<float>(24, 60), 3.0, 1e-5);
    EXPECT_NEAR(v.intensity.at<float>(24, 60), 0.3, 1e-5);
    // Left edge: x = (0 - 31.5) / 60 * 3 = -1.58 m < -1 m, nothing.
    EXPECT_EQ(v.label.at<uint16_t>(24, 0), 0);
    EXPECT_TRUE(std::isinf(v.depth.at<float>(24, 0)));
    EXPECT_NEAR(v.intensity.at<float>(24, 0), 0.05, 1e-7);
    // intersect agrees with the rendered depth (nearest hit, unit-free direction), misses outside.
    const Eigen::Vector3d o = Eigen::Vector3d::Zero();
    for (const auto& [x, y] : {std::pair<int, int>{32, 24}, {60, 24}, {45, 10}}) {
      const Eigen::Vector3d d = 2.5 * rays.centre(x, y);
      const auto s_hit = scene.intersect(o, d);
      ASSERT_TRUE(s_hit.has_value()) << x << "," << y;
      EXPECT_NEAR((*s_hit * d).z(), v.depth.at<float>(y, x), 1e-5) << x << "," << y;
    }
    EXPECT_FALSE(scene.intersect(o, rays.centre(0, 24)).has_value());
    EXPECT_FALSE(scene.intersect(o, -rays.centre(32, 24)).has_value());  // behind the origin
    EXPECT_FALSE(scene.intersect(o, Eigen::Vector3d::UnitX()).has_value());  // parallel to the planes
  }
}

TEST(PlanarScene, TexelOrientationOnThePlane) {
  // Texture u grows along axis_u and v grows against axis_v: a pixel whose ray meets the centre of
  // texel (i, j) shows that texel's value.
  const cv::Mat img = random_image(64, 48, 21);
  const PinholeCamera cam = make_camera(90, 70, 800, true);  // small footprint: level 0
  const PixelRays rays(cam, 1);
  const SE3 T_w_c(calib::so3_exp(Eigen::Vector3d(-0.2, 0.5, 0.3)), Eigen::Vector3d(0.3, -0.4, 1));
  const Eigen::Vector3d u_c = Eigen::Vector3d(1, 0.2, 0.3).normalized();
  const Eigen::Vector3d v_c = u_c.cross(Eigen::Vector3d(0.1, 0.2, 1)).normalized();  // tilted plane
  const int cases[][4] = {{10, 20, 30, 40}, {63, 0, 70, 10}, {0, 47, 5, 60}, {32, 24, 45, 35}};
  for (const auto& c : cases) {
    const int i = c[0], j = c[1], x = c[2], y = c[3];
    const double a = (i + 0.5) / 10.0 - 3.2, bb = 2.4 - (j + 0.5) / 10.0;  // 10 texels per m, 6.4 x 4.8 m
    const Eigen::Vector3d P_c = rays.centre(x, y) * 2.0;
    TexturedPlane p;
    p.center_w = T_w_c * Eigen::Vector3d(P_c - a * u_c - bb * v_c);
    p.axis_u_w = T_w_c.rotation_matrix() * u_c;
    p.axis_v_w = T_w_c.rotation_matrix() * v_c;
    p.width_m = 6.4;
    p.height_m = 4.8;
    p.texture = std::make_shared<const Texture>(img);
    const PlanarScene scene({p});
    CameraState s;
    s.T_w_c = T_w_c;
    RenderedView v;
    scene.render(s, rays, RenderRequest{}, &v);
    EXPECT_NEAR(v.intensity.at<float>(y, x), img.at<float>(j, i), 2e-3) << "texel " << i << "," << j;
    EXPECT_NEAR(v.depth.at<float>(y, x), P_c.z(), 1e-5);
  }
}

TEST(PlanarScene, FlowMatchesNumericDerivativeWithRadtan) {
  const PinholeCamera cam = make_camera(64, 48, 55, true);
  const SE3 T_w_c(calib::so3_exp(Eigen::Vector3d(0.2, 0.3, -0.1)), Eigen::Vector3d(1, -2, 0.5));
  TexturedPlane p;  // tilted plane covering part of the view
  p.center_w = T_w_c * Eigen::Vector3d(0.5, 0.2, 2.0);
  p.axis_u_w = T_w_c.rotation_matrix() * Eigen::Vector3d(1, 0, 0.5).normalized();
  p.axis_v_w = T_w_c.rotation_matrix() * Eigen::Vector3d(0, -1, 0);
  p.width_m = 2.2;
  p.height_m = 3;
  p.texture = std::make_shared<const Texture>(random_image(32, 32, 4));
  const PlanarScene scene({p});
  const CameraState s = moving_state(T_w_c);
  for (int ss : {1, 2}) {
    const PixelRays rays(cam, ss);
    RenderRequest req;
    req.flow = true;
    RenderedView v;
    scene.render(s, rays, req, &v);
    int hits = 0, misses = 0;
    for (int y = 0; y < 48; y += 3) {
      for (int x = 0; x < 64; x += 3) {
        const Eigen::Vector3d b = rays.centre(x, y);
        const float depth = v.depth.at<float>(y, x);
        const bool at_inf = std::isinf(depth);
        (at_inf ? misses : hits)++;
        EXPECT_EQ(v.label.at<uint16_t>(y, x), at_inf ? 0 : 1);
        const Eigen::Vector3d X_w = at_inf ? Eigen::Vector3d(s.T_w_c.rotation_matrix() * b)
                                           : Eigen::Vector3d(s.T_w_c * Eigen::Vector3d(b * (depth / b.z())));
        const Eigen::Vector2d expected = numeric_flow(cam, s, X_w, at_inf);
        EXPECT_LT((flow_at(v, x, y) - expected).norm(), 1e-3 * expected.norm() + 1e-3) << x << "," << y;
        EXPECT_LT((static_point_flow(cam, b, depth, s) - expected).norm(), 1e-4 * expected.norm() + 1e-4);
      }
    }
    EXPECT_GT(hits, 50);
    EXPECT_GT(misses, 20);
  }
}

TEST(PlanarScene, SupersamplingGivesEdgePixelsIntermediateValues) {
  // Bright plane (1.0) whose left edge is at image column 30.3, dark background (0).
  const PinholeCamera cam = ideal_camera(64, 48, 100);
  const double d = 2, x_edge = (30.3 - 31.5) / 100 * d;
  TexturedPlane p;
  p.center_w = Eigen::Vector3d(x_edge + 5, 0, d);
  p.axis_u_w = Eigen::Vector3d::UnitX();
  p.axis_v_w = -Eigen::Vector3d::UnitY();
  p.width_m = 10;
  p.height_m = 10;
  p.texture = constant_texture(1.0f);
  const PlanarScene scene({p}, 0.0);
  CameraState s;
  RenderedView v1, v4;
  scene.render(s, PixelRays(cam, 1), RenderRequest{}, &v1);
  scene.render(s, PixelRays(cam, 4), RenderRequest{}, &v4);
  for (int y = 0; y < 48; y += 6) {
    for (int x = 0; x < 64; ++x) {
      const float a = v1.intensity.at<float>(y, x);
      EXPECT_TRUE(a == 0.0f || a == 1.0f) << "supersample 1 must be binary, got " << a;
      EXPECT_EQ(a, x >= 31 ? 1.0f : 0.0f);
    }
    // Pixel 30 covers [29.5, 30.5]: 20 % bright; 4x4 samples at 29.625 ... 30.375 see 1 of 4 columns.
    const float edge = v4.intensity.at<float>(y, 30);
    EXPECT_GT(edge, 0.1f);
    EXPECT_LT(edge, 0.4f);
    EXPECT_NEAR(edge, 0.25f, 1e-6);
    EXPECT_EQ(v4.intensity.at<float>(y, 29), 0.0f);
    EXPECT_EQ(v4.intensity.at<float>(y, 31), 1.0f);
    EXPECT_EQ(v4.label.at<uint16_t>(y, 30), 0);  // label from the centre ray
    EXPECT_EQ(v4.label.at<uint16_t>(y, 31), 1);
  }
}

TEST(PlanarScene, MinifiedFineCheckerboardIsFilteredCoarseKeepsContrast) {
  const PinholeCamera cam = ideal_camera(80, 60, 80);
  for (double cell : {1.0, 64.0}) {
    ProceduralTextureOptions o;
    o.kind = ProceduralKind::kCheckerboard;
    o.width = 1024;
    o.height = 1024;
    o.cell_px = cell;
    o.min_intensity = 0.1;
    o.max_intensity = 0.9;
    TexturedPlane p;  // 1024 texels over 4 m at 3 m, tilted 40 degrees: ~10 texels per pixel
    p.center_w = Eigen::Vector3d(0, 0, 3);
    p.axis_u_w = Eigen::Vector3d(std::cos(0.7), 0, std::sin(0.7));
    p.axis_v_w = -Eigen::Vector3d::UnitY();
    p.width_m = 4;
    p.height_m = 4;
    p.texture = std::make_shared<const Texture>(make_procedural_texture(o));
    const PlanarScene scene({p});
    RenderedView v;
    scene.render(CameraState{}, PixelRays(cam, 1), RenderRequest{}, &v);
    const cv::Mat mask = v.label == 1;
    ASSERT_GT(cv::countNonZero(mask), 2000);
    cv::Scalar mean, stddev;
    cv::meanStdDev(v.intensity, mean, stddev, mask);
    if (cell == 1.0) {
      EXPECT_LT(stddev[0], 0.02);
      EXPECT_NEAR(mean[0], 0.5, 0.02);
    } else {
      EXPECT_GT(stddev[0], 0.25);
    }
  }
}

// ---------------------------------------------------------------------------------------------

struct SpritePose {
  Eigen::Vector2d c;
  double angle, scale;
};

SpritePose pose_at(const SpriteMotion& m, double t) {
  SpritePose p;
  p.c = m.centre_px + m.velocity_pxps * t;
  for (int i = 0; i < 2; ++i) p.c[i] += m.amplitude_px[i] * std::sin(2 * M_PI * m.frequency_hz[i] * t + m.phase_rad[i]);
  p.angle = m.angle_rad + m.angular_rate_radps * t;
  p.scale = m.scale * std::exp(m.scale_rate_per_s * t);
  return p;
}

Eigen::Vector2d sprite_to_image(const SpritePose& p, const Eigen::Vector2d& l) {
  return p.c + p.scale * Eigen::Rotation2Dd(p.angle).toRotationMatrix() * l;
}

TEST(SpriteScene, LabelsIntensityAndFlowMatchTheSpriteMotion) {
  auto background = std::make_shared<const PlanarScene>(std::vector<TexturedPlane>{}, 0.2);
  Sprite a;
  a.texture = constant_texture(0.9f);
  a.width_px = 40;
  a.height_px = 20;
  a.motion.centre_px = Eigen::Vector2d(50, 45);
  a.motion.velocity_pxps = Eigen::Vector2d(30, -10);
  a.motion.amplitude_px = Eigen::Vector2d(5, 3);
  a.motion.frequency_hz = Eigen::Vector2d(2, 1);
  a.motion.phase_rad = Eigen::Vector2d(0.3, 1.0);
  a.motion.angle_rad = 0.4;
  a.motion.angular_rate_radps = 0.8;
  a.motion.scale = 1.2;
  a.motion.scale_rate_per_s = 0.3;
  Sprite b;
  b.texture = constant_texture(0.5f);
  b.shape = SpriteShape::kEllipse;
  b.width_px = 24;
  b.height_px = 16;
  b.gain = 1.5;
  b.motion.centre_px = Eigen::Vector2d(75, 55);
  b.motion.velocity_pxps = Eigen::Vector2d(-20, 5);
  b.motion.angular_rate_radps = -1.5;
  const int64_t t0 = 500'000'000;
  const SpriteScene scene(background, {a, b}, t0);
  EXPECT_FALSE(scene.is_static());
  const PinholeCamera cam = ideal_camera(120, 90, 100);
  const PixelRays rays(cam, 1);
  CameraState s;
  s.t_ns = t0 + 300'000'000;  // t = 0.3 s
  const double t = 0.3;
  RenderRequest req;
  req.flow = true;
  RenderedView v;
  scene.render(s, rays, req, &v);
  const SpritePose pa = pose_at(a.motion, t), pb = pose_at(b.motion, t);
  // Sprite b's centre: on top, label 2, gain applied.
  const int bx = static_cast<int>(std::lround(pb.c.x())), by = static_cast<int>(std::lround(pb.c.y()));
  EXPECT_EQ(v.label.at<uint16_t>(by, bx), 2);
  EXPECT_NEAR(v.intensity.at<float>(by, bx), 0.75, 1e-6);
  // A point in sprite a's left part (away from b): label 1.
  const Eigen::Vector2d pl = sprite_to_image(pa, Eigen::Vector2d(-14, 3));
  const int ax = static_cast<int>(std::lround(pl.x())), ay = static_cast<int>(std::lround(pl.y()));
  EXPECT_EQ(v.label.at<uint16_t>(ay, ax), 1);
  EXPECT_NEAR(v.intensity.at<float>(ay, ax), 0.9, 1e-6);
  // Far away: background.
  EXPECT_EQ(v.label.at<uint16_t>(85, 5), 0);
  EXPECT_NEAR(v.intensity.at<float>(85, 5), 0.2, 1e-6);
  // Flow of every labelled pixel = derivative of the image position of the sprite point there.
  int checked[3] = {0, 0, 0};
  const double dt = 1e-5;
  for (int y = 0; y < 90; ++y) {
    for (int x = 0; x < 120; ++x) {
      const int label = v.label.at<uint16_t>(y, x);
      if (label == 0) continue;
      const SpriteMotion& m = label == 1 ? a.motion : b.motion;
      const SpritePose p = pose_at(m, t);
      const Eigen::Vector2d l =
          Eigen::Rotation2Dd(-p.angle).toRotationMatrix() * (Eigen::Vector2d(x, y) - p.c) / p.scale;
      const Eigen::Vector2d expected =
          (sprite_to_image(pose_at(m, t + dt), l) - sprite_to_image(pose_at(m, t - dt), l)) / (2 * dt);
      EXPECT_LT((flow_at(v, x, y) - expected).norm(), 1e-4 * expected.norm() + 1e-3) << x << "," << y;
      ++checked[label];
    }
  }
  EXPECT_GT(checked[1], 300);
  EXPECT_GT(checked[2], 100);
  // The sprite moves: at another time its pixels are elsewhere.
  CameraState s2 = s;
  s2.t_ns += 200'000'000;
  RenderedView v2;
  scene.render(s2, rays, RenderRequest{}, &v2);
  EXPECT_GT(cv::norm(v.intensity, v2.intensity, cv::NORM_L1), 50.0);
}

TEST(SpriteScene, SupersampledEdgesAreIntermediate) {
  auto background = std::make_shared<const PlanarScene>(std::vector<TexturedPlane>{}, 0.0);
  Sprite a;
  a.texture = constant_texture(1.0f);
  a.shape = SpriteShape::kEllipse;
  a.width_px = 30.6;
  a.height_px = 20.2;
  a.motion.centre_px = Eigen::Vector2d(32.3, 24.1);
  a.motion.angle_rad = 0.3;
  const SpriteScene scene(background, {a});
  const PinholeCamera cam = ideal_camera(64, 48, 60);
  RenderedView v1, v3;
  scene.render(CameraState{}, PixelRays(cam, 1), RenderRequest{}, &v1);
  scene.render(CameraState{}, PixelRays(cam, 3), RenderRequest{}, &v3);
  int partial1 = 0, partial3 = 0;
  for (int y = 0; y < 48; ++y) {
    for (int x = 0; x < 64; ++x) {
      const float i1 = v1.intensity.at<float>(y, x), i3 = v3.intensity.at<float>(y, x);
      partial1 += (i1 > 0.01f && i1 < 0.99f) ? 1 : 0;
      partial3 += (i3 > 0.01f && i3 < 0.99f) ? 1 : 0;
    }
  }
  EXPECT_EQ(partial1, 0);
  EXPECT_GT(partial3, 40);  // the ellipse outline (~80 px long) is mostly partial
  // The area (sum of coverage) approximates pi a b better with supersampling.
  const double area = M_PI * 15.3 * 10.1;
  EXPECT_NEAR(cv::sum(v3.intensity)[0], area, 0.02 * area);
}

TEST(Scenes, RenderIsDeterministicAndDescribed) {
  ProceduralTextureOptions o;
  o.kind = ProceduralKind::kShapes;
  o.width = 512;
  o.height = 256;
  auto tex = std::make_shared<const Texture>(make_procedural_texture(o, TextureWrap::kRepeat, TextureWrap::kClamp));
  const PanoramaScene pano(tex);
  TexturedPlane p;
  p.center_w = Eigen::Vector3d(0, 0, 3);
  p.texture = tex;
  p.width_m = 4;
  p.height_m = 2;
  const PlanarScene planar({p});
  const PixelRays rays(make_camera(64, 48, 50, true), 2);
  const CameraState s = moving_state(SE3(calib::so3_exp(Eigen::Vector3d(0.1, 0.2, 0.3)), Eigen::Vector3d(0, 0, 0.2)));
  RenderRequest req;
  req.flow = true;
  for (const Scene* scene : {static_cast<const Scene*>(&pano), static_cast<const Scene*>(&planar)}) {
    RenderedView a, b;
    scene->render(s, rays, req, &a);
    scene->render(s, rays, req, &b);
    EXPECT_EQ(a.t_ns, s.t_ns);
    EXPECT_EQ(cv::norm(a.intensity, b.intensity, cv::NORM_INF), 0.0);
    EXPECT_EQ(std::memcmp(a.flow.data, b.flow.data, a.flow.total() * a.flow.elemSize()), 0);
    EXPECT_FALSE(scene->describe().empty());
    EXPECT_TRUE(scene->is_static());
  }
  EXPECT_NE(planar.describe().find("1 textured plane"), std::string::npos);
  TexturedPlane bad = p;
  bad.axis_v_w = Eigen::Vector3d(1, 1, 0).normalized();
  EXPECT_THROW(PlanarScene({bad}), std::invalid_argument);
  bad = p;
  bad.texture.reset();
  EXPECT_THROW(PlanarScene({bad}), std::invalid_argument);
  EXPECT_THROW(PanoramaScene(nullptr), std::invalid_argument);
}

}  // namespace
}  // namespace evio::simulator
