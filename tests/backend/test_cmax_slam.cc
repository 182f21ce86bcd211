// Rotational CMax-SLAM back-end: the analytic gradients (window and global pass, linear and cubic
// spline) against central differences, the sliding window's rotations on a synthetic point scene
// against the truth when the front-end's rates are biased, and the global pass undoing a step.
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "evio/backend/cmax_slam.h"
#include "evio/calib/equirectangular.h"
#include "evio/calib/geometry.h"

namespace evio::backend {
namespace {

using Mat3 = Eigen::Matrix3d;
using Vec3 = Eigen::Vector3d;

constexpr double kPi = 3.14159265358979323846;

// Camera looking along the world's +x, image right = -y, image down = -z.
Mat3 base_rotation() {
  Mat3 R;
  R.col(0) = Vec3(0, -1, 0);
  R.col(1) = Vec3(0, 0, -1);
  R.col(2) = Vec3(1, 0, 0);
  return R;
}

// Camera-frame rate of the synthetic motion at t (s): a pan about the camera's y with tilt and roll.
Vec3 true_rate(double t) {
  return Vec3(0.6 * std::sin(2 * kPi * 0.7 * t), 2.0 + 1.2 * std::sin(2 * kPi * 0.5 * t), 0.4 * std::cos(2 * kPi * 0.9 * t));
}

struct Scene {
  std::vector<Vec3> landmarks;   // unit directions, world
  std::vector<int64_t> t;        // events
  std::vector<Vec3> b;           // their bearings, camera
  std::vector<Mat3> R_truth;     // R_w_c every 0.1 ms from t = 0
  Mat3 truth(int64_t t_ns) const { return R_truth[static_cast<size_t>(t_ns / 100'000)]; }
};

// Point landmarks near the horizon; events at 100 k/s, each at a random visible landmark with
// 0.3 px noise, through a 240 x 180 pinhole of focal 200 px.
Scene make_scene(double duration_s, uint64_t seed) {
  Scene s;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(-1, 1);
  std::normal_distribution<double> N(0, 1);
  for (int i = 0; i < 3000; ++i) {
    const double lon = kPi * U(rng), lat = 0.6 * U(rng);
    s.landmarks.push_back(Vec3(std::cos(lat) * std::cos(lon), std::cos(lat) * std::sin(lon), std::sin(lat)));
  }
  const int steps = static_cast<int>(duration_s / 1e-4) + 2;
  Mat3 R = base_rotation();
  for (int i = 0; i < steps; ++i) {
    s.R_truth.push_back(R);
    R = R * calib::so3_exp(true_rate((i + 0.5) * 1e-4) * 1e-4);
  }
  const double f = 200, cx = 120, cy = 90;
  const int64_t n_events = static_cast<int64_t>(duration_s * 100'000);
  std::uniform_int_distribution<size_t> pick(0, s.landmarks.size() - 1);
  for (int64_t k = 0; k < n_events; ++k) {
    const int64_t t = k * 10'000 + 1;
    const Mat3& Rt = s.truth(t);
    for (;;) {
      const Vec3 c = Rt.transpose() * s.landmarks[pick(rng)];
      if (c.z() < 0.3) continue;
      const double x = cx + f * c.x() / c.z() + 0.3 * N(rng), y = cy + f * c.y() / c.z() + 0.3 * N(rng);
      if (x < 0 || x >= 240 || y < 0 || y >= 180) continue;
      s.t.push_back(t);
      s.b.push_back(Vec3((x - cx) / f, (y - cy) / f, 1).normalized());
      break;
    }
  }
  return s;
}

double angle_deg(const Mat3& a, const Mat3& b) { return calib::so3_log(Mat3(a.transpose() * b)).norm() * 180 / kPi; }

// |g - central differences of f at x| / |central differences| (step 1e-7: small enough that the
// bilinear votes' kinks are rarely crossed), and the latter's norm in *norm.
template <class F>
double relative_gradient_error(const F& f, const std::vector<double>& x, const std::vector<double>& g, double* norm) {
  double gnorm = 0, err = 0;
  for (size_t i = 0; i < x.size(); ++i) {
    const double h = 1e-7;
    std::vector<double> xp = x, xm = x;
    xp[i] += h;
    xm[i] -= h;
    const double num = (f(xp) - f(xm)) / (2 * h);
    gnorm += num * num;
    err += (num - g[i]) * (num - g[i]);
  }
  *norm = std::sqrt(gnorm);
  return std::sqrt(err / gnorm);
}

TEST(CmaxSlam, WindowGradientMatchesCentralDifferences) {
  const Scene s = make_scene(0.2, 3);
  for (CmaxSlamSpline spline : {CmaxSlamSpline::kLinear, CmaxSlamSpline::kCubic}) {
    const bool cubic = spline == CmaxSlamSpline::kCubic;
    CmaxSlamOptions o;
    o.spline = spline;
    o.knot_spacing_ns = 20'000'000;
    o.panorama_width = 512;
    o.panorama_height = 256;
    // Knots 0 .. last from the truth, perturbed; the window [1, last] holds the events of time
    // segments [1, 5) (cubic: their control knots reach 3 past the segment).
    const int last = cubic ? 7 : 5;
    std::vector<Mat3> knots;
    std::mt19937_64 rng(9);
    std::normal_distribution<double> N(0, 0.01);
    for (int i = 0; i <= last; ++i) knots.push_back(s.truth(std::max(0, i - (cubic ? 1 : 0)) * o.knot_spacing_ns) * calib::so3_exp(Vec3(N(rng), N(rng), N(rng))));
    std::vector<int64_t> t;
    std::vector<Vec3> b;
    std::vector<float> map(static_cast<size_t>(o.panorama_width) * o.panorama_height, 0.0f);
    const calib::Equirectangular pano(o.panorama_width, o.panorama_height);
    for (size_t k = 0; k < s.t.size(); k += 4) {
      if (s.t[k] >= o.knot_spacing_ns && s.t[k] < 5 * o.knot_spacing_ns) {
        t.push_back(s.t[k]);
        b.push_back(s.b[k]);
      } else {  // the other events make the map
        const Eigen::Vector2d uv = pano.project(s.truth(s.t[k]) * s.b[k]);
        map[static_cast<size_t>(uv.y()) * o.panorama_width + static_cast<size_t>(uv.x())] += 1.0f;
      }
    }
    ASSERT_GT(t.size(), 1000u);
    for (double weight : {0.0, 1.0}) {
      o.map_weight = weight;
      o.rate_prior_weight = 50 * weight;  // the priors' gradients too
      std::vector<double> x(3 * (last - 1));
      for (double& v : x) v = 0.3 * N(rng);
      std::vector<double> g;
      const double f = cmax_slam_window_cost(knots, 0, 1, last, t, b, map, o, x, &g);
      EXPECT_LT(f, 0);
      double norm = 0;
      const double err = relative_gradient_error(
          [&](const std::vector<double>& y) { return cmax_slam_window_cost(knots, 0, 1, last, t, b, map, o, y, nullptr); }, x, g, &norm);
      EXPECT_GT(norm, 0);
      std::printf("%s map_weight %.0f: relative gradient error %.2e\n", cubic ? "cubic" : "linear", weight, err);
      // Measured 0.8-1.6e-8.
      EXPECT_LT(err, 5e-8) << "map_weight " << weight << (cubic ? ", cubic" : ", linear");
    }
  }
}

// Runs the back-end on a scene with the front-end's rates scaled by 1.15 and biased, and returns
// the RMS rotation error (deg) of the back-end's and of the prediction's rotations every 5 ms.
struct SlamRun {
  double slam_rms = 0, predicted_rms = 0;
  CmaxSlamStats stats;
};
SlamRun run(const Scene& s, const CmaxSlamOptions& o, double duration_s) {
  CmaxSlam slam(o, 0, s.truth(0));
  const Vec3 bias(0.08, -0.1, 0.05);
  const int64_t chunk = 10'000'000;
  Mat3 predicted = s.truth(0);
  std::vector<Mat3> pred_at;  // every chunk
  pred_at.push_back(predicted);
  size_t k = 0;
  for (int64_t t1 = chunk; t1 <= static_cast<int64_t>(duration_s * 1e9); t1 += chunk) {
    const Vec3 w = 1.15 * true_rate(1e-9 * static_cast<double>(t1 - chunk / 2)) + bias;
    for (; k < s.t.size() && s.t[k] < t1; ++k) slam.add_event(s.t[k], s.b[k].cast<float>());
    predicted = predicted * calib::so3_exp(w * 1e-9 * static_cast<double>(chunk));
    pred_at.push_back(predicted);
    slam.predict(t1, predicted);
    slam.update(t1);
  }
  slam.finish(s.t.back());
  SlamRun r;
  int n = 0;
  for (int64_t t = 0; t + chunk < static_cast<int64_t>(duration_s * 1e9); t += chunk, ++n) {
    r.slam_rms += std::pow(angle_deg(slam.rotation(t), s.truth(t)), 2);
    r.predicted_rms += std::pow(angle_deg(pred_at[static_cast<size_t>(t / chunk)], s.truth(t)), 2);
  }
  r.slam_rms = std::sqrt(r.slam_rms / n);
  r.predicted_rms = std::sqrt(r.predicted_rms / n);
  r.stats = slam.stats();
  return r;
}

TEST(CmaxSlam, SlidingWindowCorrectsBiasedFrontEndRates) {
  const double duration = 1.0;
  const Scene s = make_scene(duration, 5);
  CmaxSlamOptions o;
  o.panorama_width = 1024;
  o.panorama_height = 512;
  // The rates are 15% off from the start: the first window is optimised too (by default it keeps
  // the prediction, right for a front-end that starts accurate).
  o.keep_first_window = false;
  o.global_iterations = 0;  // the sliding window alone (GlobalPassUndoesAStep tests the global pass)
  const SlamRun with_map = run(s, o, duration);
  o.map_weight = 0;
  const SlamRun window_only = run(s, o, duration);
  o.map_weight = 1;
  o.spline = CmaxSlamSpline::kCubic;
  const SlamRun cubic = run(s, o, duration);
  std::printf("predicted %.3f deg, window only %.3f deg, with the map %.3f deg, cubic spline %.3f deg; %lld windows, %lld evaluations, gain %.3f\n",
              with_map.predicted_rms, window_only.slam_rms, with_map.slam_rms, cubic.slam_rms,
              static_cast<long long>(with_map.stats.windows), static_cast<long long>(with_map.stats.evaluations), with_map.stats.mean_contrast_gain);
  // Measured: predicted 11.180 deg, the back-end 1.602 deg with the map and 1.643 deg without,
  // 1.589 deg with the cubic spline and the map.
  EXPECT_GT(with_map.predicted_rms, 10.0);
  EXPECT_LT(with_map.slam_rms, 2.0);
  EXPECT_LT(window_only.slam_rms, 2.0);
  EXPECT_LT(cubic.slam_rms, 1.9);
  EXPECT_EQ(cubic.stats.events_mapped, static_cast<int64_t>(s.t.size()));
  EXPECT_EQ(with_map.stats.events_mapped, static_cast<int64_t>(s.t.size()));
  EXPECT_GT(with_map.stats.mean_contrast_gain, 1.0);
}

// The global pass's cost (full wrapping panorama, running increments, gauge, robust rate prior)
// against central differences.
TEST(CmaxSlam, GlobalGradientMatchesCentralDifferences) {
  const Scene s = make_scene(0.2, 4);
  for (CmaxSlamSpline spline : {CmaxSlamSpline::kLinear, CmaxSlamSpline::kCubic}) {
    CmaxSlamOptions o;
    o.spline = spline;
    o.panorama_width = 512;
    o.panorama_height = 256;
    o.global_rate_weight = 0.5;
    std::vector<Mat3> knots;
    std::mt19937_64 rng(11);
    std::normal_distribution<double> N(0, 0.01);
    for (int i = 0; i <= 11; ++i) knots.push_back(s.truth(std::min(i, 10) * o.knot_spacing_ns) * calib::so3_exp(Vec3(N(rng), N(rng), N(rng))));
    std::vector<int64_t> t;
    std::vector<Vec3> b;
    for (size_t k = 0; k < s.t.size() && s.t[k] < 180'000'000; k += 4) {
      t.push_back(s.t[k]);
      b.push_back(s.b[k]);
  }
  // The panorama's seam: turn the world so that the events cross longitude 180 deg.
  const Mat3 turn = calib::so3_exp(Vec3(0, 0, kPi - 0.3));
  for (Mat3& R : knots) R = turn * R;
  std::vector<double> eps(3 * knots.size());
  for (double& v : eps) v = 0.003 * N(rng) / 0.01;
  std::vector<double> g;
  const double f = cmax_slam_global_cost(knots, 0, t, b, o, eps, &g);
  EXPECT_TRUE(std::isfinite(f));
  double norm = 0;
  const double err = relative_gradient_error(
      [&](const std::vector<double>& y) { return cmax_slam_global_cost(knots, 0, t, b, o, y, nullptr); }, eps, g, &norm);
  EXPECT_GT(norm, 0);
  std::printf("global %s: relative gradient error %.2e\n", spline == CmaxSlamSpline::kCubic ? "cubic" : "linear", err);
  // Measured 2.3e-8 (linear) and 1.7e-5 (cubic: a vote crossing a texel edge inside the step).
  EXPECT_LT(err, 5e-5) << (spline == CmaxSlamSpline::kCubic ? "cubic" : "linear");
  }
}

// A trajectory that is right but for a step at 0.2 s (every later knot turned by 2 deg, as the
// sliding window leaves one it cannot see): the global pass, on a scene seen again after a full
// turn, undoes it.
TEST(CmaxSlam, GlobalPassUndoesAStep) {
  const double duration = 3.6;  // about 400 deg of pan
  const Scene s = make_scene(duration, 6);
  CmaxSlamOptions o;
  o.global_iterations = 100;
  std::vector<Mat3> knots;
  const Mat3 step = calib::so3_exp(Vec3(0.02, -0.025, 0.015));
  const int n = static_cast<int>(duration * 1e9 / static_cast<double>(o.knot_spacing_ns));
  for (int i = 0; i <= n; ++i) knots.push_back(i >= 10 ? Mat3(step * s.truth(i * o.knot_spacing_ns)) : s.truth(i * o.knot_spacing_ns));
  std::vector<int64_t> t;
  std::vector<Vec3> b;
  for (size_t k = 0; k < s.t.size(); k += 4) {
    if (s.t[k] > n * o.knot_spacing_ns) break;
    t.push_back(s.t[k]);
    b.push_back(s.b[k]);
  }
  const CmaxSlamGlobalResult r = cmax_slam_refine_globally(knots, 0, t, b, o);
  double before = 0, after = 0;
  for (int i = 0; i <= n; ++i) {
    before += std::pow(angle_deg(knots[static_cast<size_t>(i)], s.truth(i * o.knot_spacing_ns)), 2);
    after += std::pow(angle_deg(r.knots[static_cast<size_t>(i)], s.truth(i * o.knot_spacing_ns)), 2);
  }
  before = std::sqrt(before / (n + 1));
  after = std::sqrt(after / (n + 1));
  std::printf("step: RMS %.3f deg before, %.3f deg after the global pass (%lld iterations, gain %.4f)\n", before, after,
              static_cast<long long>(r.iterations), r.contrast_gain);
  // Measured: 1.969 deg before, 0.143 after.
  EXPECT_TRUE(r.refined);
  EXPECT_GT(before, 1.9);
  EXPECT_LT(after, 0.18);
  EXPECT_NEAR(angle_deg(r.knots.front(), knots.front()), 0, 1e-9);
}

// min_segment_events: each knot segment's rate prior weighs min_segment_events / its time
// segment's events (at least 1). Moving one knot changes the two segments beside it by the same
// amount, so the cost with the floor exceeds the cost without it by exactly the extra prior.
TEST(CmaxSlam, SparseSegmentsWeighTheirRatePriorByTheFloor) {
  const Scene s = make_scene(0.1, 5);
  CmaxSlamOptions o;
  o.panorama_width = 512;
  o.panorama_height = 256;
  o.prior_weight = 0;
  const int64_t dt = o.knot_spacing_ns;
  std::vector<Mat3> knots;
  for (int i = 0; i <= 3; ++i) knots.push_back(s.truth(i * dt));
  // Segment 0: every 40th event; segment 1: none; segment 2: all.
  std::vector<int64_t> t;
  std::vector<Vec3> b;
  size_t n0 = 0;
  for (size_t k = 0; k < s.t.size() && s.t[k] < 3 * dt; ++k) {
    const int64_t seg = s.t[k] / dt;
    if (seg == 1 || (seg == 0 && k % 40 != 0)) continue;
    n0 += seg == 0;
    t.push_back(s.t[k]);
    b.push_back(s.b[k]);
  }
  ASSERT_GT(n0, 10u);
  ASSERT_LT(n0, 500u);
  std::vector<double> x(9, 0.0);
  x[0] = 0.004, x[1] = -0.003, x[2] = 0.002;  // knot 1 turned
  const double d2 = x[0] * x[0] + x[1] * x[1] + x[2] * x[2];
  o.min_segment_events = 0;
  const double without = cmax_slam_window_cost(knots, 0, 0, 3, t, b, {}, o, x, nullptr);
  o.min_segment_events = 1000;
  const double with = cmax_slam_window_cost(knots, 0, 0, 3, t, b, {}, o, x, nullptr);
  const double wr = o.rate_prior_weight / 3;  // per segment: the mean over the window's three
  const double extra = 0.5 * wr * d2 * ((1000.0 / static_cast<double>(n0) - 1) + (1000.0 - 1));
  EXPECT_NEAR(with - without, extra, 1e-9 * extra);
}

TEST(CmaxSlam, RejectsInvalidOptionsAndLateEvents) {
  CmaxSlamOptions o;
  o.step_knots = 11;
  EXPECT_THROW(CmaxSlam(o, 0, Mat3::Identity()), std::invalid_argument);
  o = CmaxSlamOptions();
  o.global_iterations = -1;
  EXPECT_THROW(CmaxSlam(o, 0, Mat3::Identity()), std::invalid_argument);
  o = CmaxSlamOptions();
  o.global_max_events = 999;
  EXPECT_THROW(CmaxSlam(o, 0, Mat3::Identity()), std::invalid_argument);
  o = CmaxSlamOptions();
  o.global_rate_weight = -0.1;
  EXPECT_THROW(CmaxSlam(o, 0, Mat3::Identity()), std::invalid_argument);
  o = CmaxSlamOptions();
  o.min_segment_events = -1;
  EXPECT_THROW(CmaxSlam(o, 0, Mat3::Identity()), std::invalid_argument);
  // The global pass on its own: events outside the knots' span are refused.
  o = CmaxSlamOptions();
  const std::vector<Mat3> three(3, Mat3::Identity());
  EXPECT_THROW(cmax_slam_refine_globally(three, 0, {100'000'000}, {Vec3(0, 0, 1)}, o), std::invalid_argument);
  o = CmaxSlamOptions();
  CmaxSlam slam(o, 1000, Mat3::Identity());
  EXPECT_THROW(slam.add_event(999, Eigen::Vector3f(0, 0, 1)), std::invalid_argument);
  // No events at all: finishing keeps the prediction.
  slam.predict(100'000'000, calib::so3_exp(Vec3(0, 0.1, 0)));
  slam.finish(90'000'000);
  EXPECT_NEAR(angle_deg(slam.rotation(50'001'000), calib::so3_exp(Vec3(0, 0.05, 0))), 0, 1e-4);
  EXPECT_EQ(slam.stats().windows, 0);
}

}  // namespace
}  // namespace evio::backend
