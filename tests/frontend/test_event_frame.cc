// Motion-compensated event frames (event_frame.h): warp geometry against closed forms, sharpness
// and alignment on a simulated fast rotation (panorama, DAVIS240C intrinsics with radtan
// distortion, rotated camera-IMU extrinsics, a camera-IMU time shift, 1 kHz ideal IMU), window
// rules, IMU coverage and large timestamps.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <vector>

#include <gtest/gtest.h>

#include "evio/calib/geometry.h"
#include "evio/frontend/event_frame.h"
#include "evio/simulator/imu.h"
#include "evio/simulator/scene.h"
#include "evio/simulator/texture.h"
#include "evio/simulator/trajectory.h"
#include "evio/simulator/simulator.h"

namespace evio::frontend {
namespace {

using calib::CameraCalibration;

// Body (IMU: x forward, y left, z up) to camera (x right, y down, z forward), plus a small
// misalignment so no axis coincides.
Eigen::Matrix3d camera_from_body_rotation() {
  Eigen::Matrix3d R;
  R << 0, -1, 0,  //
      0, 0, -1,   //
      1, 0, 0;
  return calib::so3_exp(Eigen::Vector3d(0.05, -0.08, 0.1)) * R;
}

CameraCalibration undistorted_camera(int64_t shift_ns, const Eigen::Matrix3d& R_c_b) {
  calib::CameraIntrinsics in;
  in.width = 240;
  in.height = 180;
  in.fx = in.fy = 200.0;
  in.cx = 119.5;
  in.cy = 89.5;
  CameraCalibration c;
  c.camera = calib::PinholeCamera(in);
  c.T_c_b = calib::SE3(R_c_b, Eigen::Vector3d(0.02, -0.01, 0.03));
  c.has_T_c_b = true;
  c.time_shift_ns = shift_ns;
  return c;
}

std::vector<ImuSample> constant_gyro(int64_t t0, int64_t t1, int64_t dt, const Eigen::Vector3d& w_b) {
  std::vector<ImuSample> v;
  for (int64_t t = t0; t <= t1; t += dt) {
    ImuSample s;
    s.t_ns = t;
    s.gyro = w_b;
    v.push_back(s);
  }
  return v;
}

// Weighted centroid of the accumulator, px.
Eigen::Vector2d centroid(const cv::Mat& acc) {
  double sw = 0, sx = 0, sy = 0;
  for (int y = 0; y < acc.rows; ++y)
    for (int x = 0; x < acc.cols; ++x) {
      const double w = acc.at<float>(y, x);
      sw += w;
      sx += w * x;
      sy += w * y;
    }
  return Eigen::Vector2d(sx / sw, sy / sw);
}

Eigen::Vector2d project_k(const CameraCalibration& c, const Eigen::Vector3d& p) {
  const auto& in = c.camera.intrinsics();
  return Eigen::Vector2d(in.fx * p.x() / p.z() + in.cx, in.fy * p.y() / p.z() + in.cy);
}

// Fixed clip: image = round(255 min(a, c) / c) with c = clip_count, whatever else the frame holds
// (the percentile clip would rescale when a bright pixel is added).
TEST(EventFrame, FixedClipCountDoesNotDependOnTheFramesContent) {
  const CameraCalibration cam = undistorted_camera(0, Eigen::Matrix3d::Identity());
  EventFrameOptions o;
  o.motion_compensation = false;
  o.clip_count = 4.0;
  o.min_events = 1;
  EventFrameBuilder b(cam, o);
  auto events_at = [](std::vector<std::pair<int, int>> counts) {  // (pixel x, count) on row 50
    std::vector<Event> ev;
    int64_t t = 1000;
    for (const auto& [x, n] : counts)
      for (int k = 0; k < n; ++k) ev.push_back(Event{t++, static_cast<uint16_t>(x), 50, 1});
    return ev;
  };
  const std::vector<Event> a = events_at({{10, 1}, {20, 2}, {30, 8}});
  const EventFrame f = b.build_frame(EventSpan(a.data(), a.size()), a.back().t_ns);
  EXPECT_NEAR(f.image.at<uint8_t>(50, 10), 64, 1);   // 255 / 4 (bilinear splat: within 1)
  EXPECT_NEAR(f.image.at<uint8_t>(50, 20), 128, 1);  // 255 * 2 / 4
  EXPECT_EQ(f.image.at<uint8_t>(50, 30), 255);       // clipped
  const std::vector<Event> c = events_at({{10, 1}, {20, 2}, {30, 40}});
  const EventFrame g = b.build_frame(EventSpan(c.data(), c.size()), c.back().t_ns);
  EXPECT_EQ(g.image.at<uint8_t>(50, 10), f.image.at<uint8_t>(50, 10));
  EXPECT_EQ(g.image.at<uint8_t>(50, 20), f.image.at<uint8_t>(50, 20));
  o.clip_count = 0.0;  // the percentile clip (here the maximum): pixel 20 scales with the brightest pixel
  o.clip_percentile = 1.0;
  EventFrameBuilder p(cam, o);
  EXPECT_NE(p.build_frame(EventSpan(c.data(), c.size()), c.back().t_ns).image.at<uint8_t>(50, 20),
            p.build_frame(EventSpan(a.data(), a.size()), a.back().t_ns).image.at<uint8_t>(50, 20));
}

// Time surface (time_surface_tau_fraction > 0): each pixel holds the largest exp(-(t_end - t) /
// tau) of its events, tau = fraction x span, so a pixel's value depends on when it last fired, not
// on how often: 1 and 8 events ending together give the same value, where counts differ 8x.
TEST(EventFrame, TimeSurfaceKeepsTheNewestEventNotTheCount) {
  const CameraCalibration cam = undistorted_camera(0, Eigen::Matrix3d::Identity());
  EventFrameOptions o;
  o.motion_compensation = false;
  o.min_events = 1;
  o.clip_percentile = 1.0;
  o.time_surface_tau_fraction = 0.5;
  EventFrameBuilder b(cam, o);
  // Span 0..10 ms (tau 5 ms): pixel 10 fires once at 10 ms, pixel 20 eight times up to 10 ms,
  // pixel 30 once at 0 ms, pixel 40 once at 5 ms.
  std::vector<Event> ev = {{0, 30, 50, 1}};
  for (int k = 0; k < 7; ++k) ev.push_back(Event{1'000'000LL * (k + 1), 20, 50, -1});
  ev.push_back(Event{5'000'000, 40, 50, 1});
  ev.push_back(Event{10'000'000, 20, 50, 1});
  ev.push_back(Event{10'000'000, 10, 50, 1});
  std::stable_sort(ev.begin(), ev.end(), [](const Event& a, const Event& c) { return a.t_ns < c.t_ns; });
  const EventFrame f = b.build_frame(EventSpan(ev.data(), ev.size()), ev.back().t_ns);
  // (within 1e-4: the bilinear weights of a pixel centre through the bearing table)
  EXPECT_NEAR(f.accumulator.at<float>(50, 10), 1.0f, 1e-4);
  EXPECT_NEAR(f.accumulator.at<float>(50, 20), 1.0f, 1e-4);
  EXPECT_NEAR(f.accumulator.at<float>(50, 30), std::exp(-2.0), 1e-4);
  EXPECT_NEAR(f.accumulator.at<float>(50, 40), std::exp(-1.0), 1e-4);
  EXPECT_EQ(f.image.at<uint8_t>(50, 10), 255);
  EXPECT_EQ(f.image.at<uint8_t>(50, 20), 255);
  EXPECT_NEAR(f.image.at<uint8_t>(50, 30), 255 * std::exp(-2.0), 1);
  // Counts: the pixel that fired 8 times is 8x the one that fired once.
  o.time_surface_tau_fraction = 0;
  EventFrameBuilder c(cam, o);
  const EventFrame g = c.build_frame(EventSpan(ev.data(), ev.size()), ev.back().t_ns);
  EXPECT_NEAR(g.accumulator.at<float>(50, 20), 8 * g.accumulator.at<float>(50, 10), 1e-3);
  o.use_polarity = true;
  o.time_surface_tau_fraction = 0.5;
  std::string why;
  EXPECT_FALSE(o.Validate(&why));
}

TEST(EventFrame, RotationWarpMatchesClosedForm) {
  const int64_t shift = 3'000'000;
  const Eigen::Matrix3d R_c_b = camera_from_body_rotation();
  const CameraCalibration cam = undistorted_camera(shift, R_c_b);
  EventFrameOptions o;
  o.min_events = 1;
  EventFrameBuilder b(cam, o);
  const Eigen::Vector3d w_b(0.7, -2.1, 3.3);  // rad/s, |w| = 4 rad/s = 230 deg/s
  for (const ImuSample& s : constant_gyro(0, 200'000'000, 1'000'000, w_b)) b.add_imu(s);
  const Eigen::Vector3d w_c = R_c_b * w_b;
  for (int64_t dt_ns : {1'000'000, 7'300'000, 20'000'000, -5'000'000}) {
    Event e;
    e.t_ns = 50'000'000;
    e.x = 100;
    e.y = 70;
    const int64_t t_ref = e.t_ns + dt_ns;
    const EventFrame f = b.build_frame(EventSpan(&e, 1), t_ref);
    ASSERT_TRUE(f.motion_compensated);
    // R_c(ref)_c(k) = Exp(w_c (t_k - t_ref)) for a constant rate.
    const Eigen::Vector3d bearing((100 - 119.5) / 200.0, (70 - 89.5) / 200.0, 1.0);
    const Eigen::Vector2d expected =
        project_k(cam, calib::so3_exp(w_c * (-static_cast<double>(dt_ns) * 1e-9)) * bearing);
    const Eigen::Vector2d got = centroid(f.accumulator);
    std::printf("dt %.1f ms: expected (%.4f, %.4f), got (%.4f, %.4f), error %.2e px\n", dt_ns * 1e-6, expected.x(),
                expected.y(), got.x(), got.y(), (got - expected).norm());
    EXPECT_LT((got - expected).norm(), 2e-3) << "dt " << dt_ns;
  }
  // A gyro bias equal to the rate removes the motion.
  b.set_gyro_bias(w_b);
  Event e;
  e.t_ns = 50'000'000;
  e.x = 100;
  e.y = 70;
  const Eigen::Vector2d got = centroid(b.build_frame(EventSpan(&e, 1), e.t_ns + 10'000'000).accumulator);
  EXPECT_LT((got - Eigen::Vector2d(100, 70)).norm(), 1e-3);
}

// event_lag_px moves each warped event that far along the image motion at its position at the
// reference time: rotation (the gyro), and translation with use_depth.
TEST(EventFrame, EventLagMovesEventsAlongTheImageMotion) {
  const Eigen::Matrix3d R_c_b = camera_from_body_rotation();
  const CameraCalibration cam = undistorted_camera(0, R_c_b);
  const Eigen::Vector3d w_b(0.7, -2.1, 3.3);
  const Eigen::Vector3d w_c = R_c_b * w_b;
  Event e;
  e.t_ns = 50'000'000;
  e.x = 100;
  e.y = 70;
  const int64_t t_ref = e.t_ns + 10'000'000;
  for (const bool translate : {false, true}) {
    EventFrameOptions o;
    o.min_events = 1;
    o.use_depth = translate;
    EventFrameBuilder plain(cam, o);
    o.event_lag_px = 0.5;
    EventFrameBuilder lagged(cam, o);
    const Eigen::Vector3d v_c(0.4, -0.2, 0.3);
    const double depth = 1.5;
    for (EventFrameBuilder* b : {&plain, &lagged}) {
      for (const ImuSample& s : constant_gyro(0, 200'000'000, 1'000'000, w_b)) b->add_imu(s);
      if (translate) b->set_motion(v_c, depth);
    }
    const Eigen::Vector2d p0 = centroid(plain.build_frame(EventSpan(&e, 1), t_ref).accumulator);
    const Eigen::Vector2d p1 = centroid(lagged.build_frame(EventSpan(&e, 1), t_ref).accumulator);
    // The image motion at p0: the point at depth `depth` on p0's ray, moved for a short time by
    // dP/dt = -w x P - v.
    const Eigen::Vector3d q((p0.x() - 119.5) / 200.0, (p0.y() - 89.5) / 200.0, 1.0);
    const Eigen::Vector3d P = q * depth;
    const Eigen::Vector3d Pdot = -w_c.cross(P) - (translate ? v_c : Eigen::Vector3d::Zero());
    const Eigen::Vector3d P2 = P + 1e-5 * Pdot;
    const Eigen::Vector2d flow(200.0 * (P2.x() / P2.z() - q.x()), 200.0 * (P2.y() / P2.z() - q.y()));
    const Eigen::Vector2d want = p0 + 0.5 * flow.normalized();
    std::printf("translate %d: without lag (%.4f, %.4f), with (%.4f, %.4f), expected (%.4f, %.4f)\n", translate, p0.x(),
                p0.y(), p1.x(), p1.y(), want.x(), want.y());
    EXPECT_LT((p1 - want).norm(), 2e-3);
  }
  EventFrameOptions bad;
  bad.event_lag_px = -0.1;
  std::string why;
  EXPECT_FALSE(bad.Validate(&why));
  EXPECT_NE(why.find("event_lag_px"), std::string::npos);
}

// Translation tests: one event per frame is enough, and the camera does not turn.
EventFrameOptions depth_options() {
  EventFrameOptions o;
  o.min_events = 1;
  o.use_depth = true;
  return o;
}
void add_still_imu(EventFrameBuilder* b) {
  for (const ImuSample& s : constant_gyro(0, 100'000'000, 1'000'000, Eigen::Vector3d::Zero())) b->add_imu(s);
}

TEST(EventFrame, TranslationWithDepth) {
  EventFrameBuilder b(undistorted_camera(0, Eigen::Matrix3d::Identity()), depth_options());
  add_still_imu(&b);
  const double vx = 2.0, depth = 1.5;
  b.set_motion(Eigen::Vector3d(vx, 0, 0), depth);
  Event e;
  e.t_ns = 40'000'000;
  e.x = 119;
  e.y = 89;
  const int64_t dt = 10'000'000;
  const EventFrame f = b.build_frame(EventSpan(&e, 1), e.t_ns + dt);
  // Point at depth D on the pixel's ray, seen from a camera that moved by v dt: x_ref = x - v dt.
  const double X = (119 - 119.5) / 200.0 * depth;
  const double u = 200.0 * (X - vx * dt * 1e-9) / depth + 119.5;
  const Eigen::Vector2d got = centroid(f.accumulator);
  std::printf("translation: expected u %.4f, got (%.4f, %.4f)\n", u, got.x(), got.y());
  EXPECT_NEAR(got.x(), u, 2e-3);
  EXPECT_NEAR(got.y(), 89.0, 2e-3);
  EXPECT_THROW(b.set_motion(Eigen::Vector3d::Zero(), 0.0), std::invalid_argument);
}

// A motion provider is asked once per compensated frame with the frame's reference time, and its
// answer gives the same frame as set_motion with those values; a false answer keeps the motion set
// before.
TEST(EventFrame, MotionProviderAtTheReferenceTime) {
  Event e;
  e.t_ns = 40'000'000;
  e.x = 119;
  e.y = 89;
  const int64_t t_ref = e.t_ns + 10'000'000;
  EventFrameBuilder direct(undistorted_camera(0, Eigen::Matrix3d::Identity()), depth_options());
  add_still_imu(&direct);
  direct.set_motion(Eigen::Vector3d(2.0, 0, 0), 1.5);
  const Eigen::Vector2d want = centroid(direct.build_frame(EventSpan(&e, 1), t_ref).accumulator);

  EventFrameBuilder b(undistorted_camera(0, Eigen::Matrix3d::Identity()), depth_options());
  add_still_imu(&b);
  std::vector<int64_t> asked;
  bool answer = true;
  b.set_motion_provider([&](int64_t t, FrameMotion* m) {
    asked.push_back(t);
    m->v_c = Eigen::Vector3d(2.0, 0, 0);
    m->depth_m = 1.5;
    return answer;
  });
  const Eigen::Vector2d got = centroid(b.build_frame(EventSpan(&e, 1), t_ref).accumulator);
  ASSERT_EQ(asked.size(), 1u);
  EXPECT_EQ(asked[0], t_ref);
  EXPECT_NEAR(got.x(), want.x(), 1e-6);
  EXPECT_NEAR(got.y(), want.y(), 1e-6);
  EXPECT_GT(std::abs(got.x() - 119.0), 0.5);  // the translation moved it
  // false: the previous answer stays in force.
  answer = false;
  b.set_motion(Eigen::Vector3d(-2.0, 0, 0), 1.5);
  const Eigen::Vector2d kept = centroid(b.build_frame(EventSpan(&e, 1), t_ref).accumulator);
  EXPECT_NEAR(kept.x(), 2 * 119.0 - want.x(), 1e-3);  // the opposite velocity: mirrored about the pixel
  EXPECT_GT(kept.x(), 119.0);
  // Not asked without use_depth.
  EventFrameOptions o = depth_options();
  o.use_depth = false;
  EventFrameBuilder off(undistorted_camera(0, Eigen::Matrix3d::Identity()), o);
  add_still_imu(&off);
  asked.clear();
  off.set_motion_provider([&](int64_t t, FrameMotion*) {
    asked.push_back(t);
    return true;
  });
  off.build_frame(EventSpan(&e, 1), t_ref);
  EXPECT_TRUE(asked.empty());
}

// Per-event depth from a plane: a fronto-parallel plane z = D gives the frame of set_motion(v, D)
// bit for bit; a tilted plane puts an off-axis event at the plane's own depth there.
TEST(EventFrame, TranslationWithAScenePlane) {
  EventFrameBuilder b(undistorted_camera(0, Eigen::Matrix3d::Identity()), depth_options());
  add_still_imu(&b);
  const Eigen::Vector3d v(2.0, 0, 0);
  std::vector<Event> ev;
  for (int i = 0; i < 50; ++i) {
    Event e;
    e.t_ns = 30'000'000 + i * 100'000;
    e.x = static_cast<uint16_t>(20 + 4 * i);
    e.y = static_cast<uint16_t>(10 + 3 * i);
    ev.push_back(e);
  }
  const int64_t t_ref = 45'000'000;
  b.set_motion(v, 1.5);
  const cv::Mat a = b.build_frame(EventSpan(ev.data(), ev.size()), t_ref).accumulator.clone();
  b.set_motion_plane(v, Eigen::Vector3d::UnitZ(), 1.5);
  const cv::Mat p = b.build_frame(EventSpan(ev.data(), ev.size()), t_ref).accumulator;
  EXPECT_EQ(cv::norm(a, p, cv::NORM_INF), 0.0);
  // Tilted plane n = (sin 30, 0, cos 30), d = 1.5: on the pixel column u = 179.5 (x = 0.3) the
  // plane is at z = d / (n . (x, 0, 1)); the event moves by v dt / z there.
  const Eigen::Vector3d n(0.5, 0, std::sqrt(0.75));
  b.set_motion_plane(v, n, 1.5);
  Event e;
  e.t_ns = 40'000'000;
  e.x = 179;
  e.y = 89;
  const int64_t dt = 10'000'000;
  const double x = (179 - 119.5) / 200.0, z = 1.5 / n.dot(Eigen::Vector3d(x, 0, 1));
  const double u = 200.0 * (x * z - v.x() * dt * 1e-9) / z + 119.5;
  const Eigen::Vector2d got = centroid(b.build_frame(EventSpan(&e, 1), e.t_ns + dt).accumulator);
  EXPECT_NEAR(got.x(), u, 2e-3);
  EXPECT_NEAR(got.y(), 89.0, 2e-3);
  EXPECT_THROW(b.set_motion_plane(v, Eigen::Vector3d(0, 0, 2), 1.5), std::invalid_argument);
  EXPECT_THROW(b.set_motion_plane(v, Eigen::Vector3d::UnitZ(), 0.0), std::invalid_argument);
}

// Time shift direction: t_imu = t_cam + shift. IMU covers [0, 100 ms] on its clock.
TEST(EventFrame, ImuCoverageAndTimeShift) {
  const CameraCalibration cam = undistorted_camera(50'000'000, Eigen::Matrix3d::Identity());
  EventFrameOptions o;
  o.events_per_frame = 100;
  o.min_events = 10;
  EventFrameBuilder b(cam, o);
  for (const ImuSample& s : constant_gyro(0, 100'000'000, 1'000'000, Eigen::Vector3d(0, 1, 0))) b.add_imu(s);
  std::vector<Event> ev;
  for (int i = 0; i < 400; ++i) {  // camera times 0..79.8 ms -> IMU times 50..129.8 ms
    Event e;
    e.t_ns = i * 200'000;
    e.x = static_cast<uint16_t>(20 + i % 200);
    e.y = static_cast<uint16_t>(30 + i % 100);
    ev.push_back(e);
  }
  std::vector<EventFrame> out;
  b.add_events(EventSpan(ev.data(), ev.size()), &out);
  ASSERT_EQ(out.size(), 4u);
  EXPECT_TRUE(out[0].motion_compensated);  // IMU 50..69.8 ms
  EXPECT_TRUE(out[1].motion_compensated);  // IMU 70..89.8 ms
  EXPECT_FALSE(out[2].motion_compensated);  // IMU 90..109.8 ms: past the last sample
  EXPECT_FALSE(out[3].motion_compensated);
  EXPECT_EQ(b.stats().frames_uncompensated, 2);

  // No IMU at all.
  EventFrameBuilder none(cam, o);
  out.clear();
  none.add_events(EventSpan(ev.data(), ev.size()), &out);
  ASSERT_EQ(out.size(), 4u);
  for (const EventFrame& f : out) EXPECT_FALSE(f.motion_compensated);
  EXPECT_EQ(none.stats().frames_uncompensated, 4);

  // A 30 ms hole in the IMU (max gap 20 ms) makes the frames across it uncompensated.
  EventFrameBuilder gap(undistorted_camera(0, Eigen::Matrix3d::Identity()), o);
  for (const ImuSample& s : constant_gyro(0, 200'000'000, 1'000'000, Eigen::Vector3d(0, 1, 0)))
    if (s.t_ns <= 30'000'000 || s.t_ns >= 60'000'000) gap.add_imu(s);
  out.clear();
  gap.add_events(EventSpan(ev.data(), ev.size()), &out);
  ASSERT_EQ(out.size(), 4u);
  EXPECT_TRUE(out[0].motion_compensated);   // 0..19.8 ms
  EXPECT_FALSE(out[1].motion_compensated);  // 20..39.8 ms spans the hole
  EXPECT_FALSE(out[2].motion_compensated);  // 40..59.8 ms
  EXPECT_TRUE(out[3].motion_compensated);   // 60..79.8 ms
  EXPECT_EQ(gap.stats().frames_uncompensated, 2);
  // Out-of-order IMU samples are rejected and counted.
  ImuSample old;
  old.t_ns = 5;
  gap.add_imu(old);
  EXPECT_EQ(gap.stats().imu_rejected, 1);
}

std::vector<Event> uniform_events(int n, int64_t t0, int64_t dt) {
  std::vector<Event> ev;
  for (int i = 0; i < n; ++i) {
    Event e;
    e.t_ns = t0 + i * dt;
    e.x = static_cast<uint16_t>((i * 37) % 240);
    e.y = static_cast<uint16_t>((i * 11) % 180);
    e.polarity = (i % 3 == 0) ? -1 : 1;
    ev.push_back(e);
  }
  return ev;
}

TEST(EventFrame, WindowRules) {
  const CameraCalibration cam = undistorted_camera(0, Eigen::Matrix3d::Identity());
  EventFrameOptions o;
  o.events_per_frame = 1000;
  o.max_window_ns = 10'000'000;
  o.min_events = 50;
  o.motion_compensation = false;
  // Sparse: 10 k events/s -> 100 events per 10 ms window.
  const std::vector<Event> sparse = uniform_events(1000, 0, 100'000);
  {
    EventFrameBuilder b(cam, o);
    std::vector<EventFrame> out;
    // Fed in uneven chunks: the grouping must not depend on the packet boundaries.
    b.add_events(EventSpan(sparse.data(), 333), &out);
    b.add_events(EventSpan(sparse.data() + 333, sparse.size() - 333), &out);
    EXPECT_EQ(out.size(), 9u);
    b.flush(&out);
    ASSERT_EQ(out.size(), 10u);
    for (size_t i = 0; i < out.size(); ++i) {
      EXPECT_EQ(out[i].events, 100u);
      EXPECT_LT(out[i].t_end_ns - out[i].t_begin_ns, o.max_window_ns);
      EXPECT_EQ(out[i].t_begin_ns, static_cast<int64_t>(i) * 10'000'000);
      EXPECT_EQ(out[i].t_ns, out[i].t_end_ns);
      EXPECT_EQ(out[i].image.type(), CV_8UC1);
      EXPECT_FALSE(out[i].motion_compensated);
    }
    EXPECT_EQ(b.stats().frames_emitted, 10);
    EXPECT_EQ(b.stats().frames_uncompensated, 0);  // compensation off is not a fallback
  }
  {  // min_events above the window's count, sparse windows off: every frame dropped and counted.
    EventFrameOptions o2 = o;
    o2.min_events = 150;
    o2.sparse_max_window_ns = 0;
    EventFrameBuilder b(cam, o2);
    std::vector<EventFrame> out;
    b.add_events(EventSpan(sparse.data(), sparse.size()), &out);
    b.flush(&out);
    EXPECT_TRUE(out.empty());
    EXPECT_EQ(b.stats().frames_dropped_sparse, 10);
    EXPECT_EQ(b.stats().events_dropped_sparse, 1000);
  }
  {  // ... with sparse windows (default 500 ms) and no wait (sparse_after_ns 0): a frame past
     // max_window_ns keeps its events until it has min_events (150 events, 15 ms each); the last
     // 100 are too few at the flush.
    EventFrameOptions o2 = o;
    o2.min_events = 150;
    o2.sparse_after_ns = 0;
    EventFrameBuilder b(cam, o2);
    std::vector<EventFrame> out;
    b.add_events(EventSpan(sparse.data(), sparse.size()), &out);
    b.flush(&out);
    ASSERT_EQ(out.size(), 6u);
    for (const EventFrame& f : out) EXPECT_EQ(f.events, 150u);
    EXPECT_EQ(b.stats().frames_dropped_sparse, 1);
    EXPECT_EQ(b.stats().events_dropped_sparse, 100);
    // ... but no longer than sparse_max_window_ns: 12 ms windows of 120 events are dropped.
    EventFrameOptions o3 = o2;
    o3.sparse_max_window_ns = 12'000'000;
    EventFrameBuilder c(cam, o3);
    out.clear();
    c.add_events(EventSpan(sparse.data(), sparse.size()), &out);
    c.flush(&out);
    EXPECT_TRUE(out.empty());
    EXPECT_EQ(c.stats().events_dropped_sparse, 1000);
    // Default sparse_after_ns (200 ms): before the first frame the sparse window applies; after it,
    // only once 200 ms have passed without a frame, so within the 100 ms of data the 10 ms windows
    // of 100 events that follow the first frame are dropped as before.
    EventFrameOptions o4 = o;
    o4.min_events = 150;
    EventFrameBuilder d(cam, o4);
    out.clear();
    d.add_events(EventSpan(sparse.data(), sparse.size()), &out);
    d.flush(&out);
    ASSERT_EQ(out.size(), 1u);
    EXPECT_EQ(out[0].events, 150u);
    EXPECT_EQ(d.stats().events_dropped_sparse, 850);
  }
  {  // Dense: frames of exactly N events, the remainder on flush.
    const std::vector<Event> dense = uniform_events(2500, 0, 1'000);
    EventFrameBuilder b(cam, o);
    std::vector<EventFrame> out;
    b.add_events(EventSpan(dense.data(), dense.size()), &out);
    ASSERT_EQ(out.size(), 2u);
    EXPECT_EQ(out[0].events, 1000u);
    EXPECT_EQ(out[0].t_begin_ns, 0);
    EXPECT_EQ(out[0].t_ns, 999'000);
    EXPECT_EQ(out[1].t_begin_ns, 1'000'000);
    b.flush(&out);
    ASSERT_EQ(out.size(), 3u);
    EXPECT_EQ(out[2].events, 500u);
    b.flush(&out);  // nothing pending
    EXPECT_EQ(out.size(), 3u);
    // Without normalisation the image holds the rounded counts: the sum of the votes is the
    // number of events drawn.
    EXPECT_NEAR(cv::sum(out[0].accumulator)[0], 1000.0 - out[0].events_outside, 1e-2);
  }
  {  // Events outside the sensor are ignored and counted.
    std::vector<Event> ev = uniform_events(10, 0, 1000);
    ev[3].x = 240;
    EventFrameBuilder b(cam, o);
    std::vector<EventFrame> out;
    b.add_events(EventSpan(ev.data(), ev.size()), &out);
    EXPECT_EQ(b.stats().events_outside_sensor, 1);
  }
}

// min_window_ns: at a high event rate frames hold more than N events and span at least the
// minimum window, so the frame rate is bounded; at a low rate N events still decide.
TEST(EventFrame, MinimumWindowBoundsTheFrameRate) {
  const CameraCalibration cam = undistorted_camera(0, Eigen::Matrix3d::Identity());
  EventFrameOptions o;
  o.events_per_frame = 1000;
  o.min_events = 100;
  o.min_window_ns = 10'000'000;
  o.motion_compensation = false;
  // 1 M events/s: 1000 events take 1 ms, so each frame waits for 10 ms (10,000 events).
  const std::vector<Event> dense = uniform_events(50'000, 0, 1'000);
  EventFrameBuilder b(cam, o);
  std::vector<EventFrame> out;
  b.add_events(EventSpan(dense.data(), dense.size()), &out);
  ASSERT_GE(out.size(), 4u);
  for (const auto& f : out) {
    EXPECT_GE(f.t_end_ns - f.t_begin_ns, o.min_window_ns);
    EXPECT_GE(f.events, 10'000u);
  }
  // 10 k events/s: 1000 events take 100 ms > min window: N events decide.
  const std::vector<Event> sparse = uniform_events(5'000, 0, 100'000);
  o.max_window_ns = 500'000'000;
  EventFrameBuilder b2(cam, o);
  out.clear();
  b2.add_events(EventSpan(sparse.data(), sparse.size()), &out);
  ASSERT_EQ(out.size(), 5u);
  for (const auto& f : out) EXPECT_EQ(f.events, 1000u);
  EventFrameOptions bad;
  bad.min_window_ns = bad.max_window_ns + 1;
  std::string why;
  EXPECT_FALSE(bad.Validate(&why));
  EXPECT_NE(why.find("min_window_ms"), std::string::npos);  // named by its YAML key
}

// overlap: each frame starts with the latest fraction of the previous frame's events, so frames
// come 1 / (1 - overlap) times as often with events_per_frame events each; carried events alone
// never make a frame, and they are discarded after max_window_ns without new events.
TEST(EventFrame, OverlappingWindows) {
  const CameraCalibration cam = undistorted_camera(0, Eigen::Matrix3d::Identity());
  EventFrameOptions o;
  o.events_per_frame = 1000;
  o.min_events = 100;
  o.max_window_ns = 10'000'000;
  o.motion_compensation = false;
  o.overlap = 0.5;
  const std::vector<Event> dense = uniform_events(3000, 0, 1'000);  // 1 M events/s
  EventFrameBuilder b(cam, o);
  std::vector<EventFrame> out;
  b.add_events(EventSpan(dense.data(), 1234), &out);
  b.add_events(EventSpan(dense.data() + 1234, dense.size() - 1234), &out);
  // Frames end at events 999, 1499, 1999, 2499, 2999, each 1000 events.
  ASSERT_EQ(out.size(), 5u);
  for (size_t i = 0; i < out.size(); ++i) {
    EXPECT_EQ(out[i].events, 1000u);
    EXPECT_EQ(out[i].t_begin_ns, static_cast<int64_t>(500 * i) * 1'000);
    EXPECT_EQ(out[i].t_ns, static_cast<int64_t>(999 + 500 * i) * 1'000);
  }
  // The overlapping half is the same events: the second frame's accumulator holds the first's
  // second half plus 500 new events.
  EXPECT_NEAR(cv::sum(out[1].accumulator)[0], 1000.0 - out[1].events_outside, 1e-2);
  b.flush(&out);  // only carried events pending: no frame
  EXPECT_EQ(out.size(), 5u);
  EXPECT_EQ(b.stats().frames_dropped_sparse, 0);
  // After a gap longer than max_window_ns the carried events are stale: the next frame holds only
  // new events.
  std::vector<Event> late = uniform_events(1000, 100'000'000, 1'000);
  b.add_events(EventSpan(late.data(), late.size()), &out);
  ASSERT_EQ(out.size(), 6u);
  EXPECT_EQ(out[5].t_begin_ns, 100'000'000);
  EXPECT_EQ(out[5].events, 1000u);
  // With overlap 0 the frames are disjoint, as before.
  o.overlap = 0.0;
  EventFrameBuilder b0(cam, o);
  out.clear();
  b0.add_events(EventSpan(dense.data(), dense.size()), &out);
  ASSERT_EQ(out.size(), 3u);
  EXPECT_EQ(out[1].t_begin_ns, 1'000'000);
}

TEST(EventFrame, OptionsValidation) {
  EventFrameOptions o;
  std::string why;
  EXPECT_TRUE(o.Validate(&why)) << why;
  auto bad = [](auto mutate) {
    EventFrameOptions x;
    mutate(x);
    std::string w;
    const bool ok = x.Validate(&w);
    EXPECT_FALSE(w.empty());
    return ok;
  };
  EXPECT_FALSE(bad([](EventFrameOptions& x) { x.events_per_frame = 0; }));
  EXPECT_FALSE(bad([](EventFrameOptions& x) { x.max_window_ns = 0; }));
  EXPECT_FALSE(bad([](EventFrameOptions& x) { x.min_events = 0; }));
  EXPECT_FALSE(bad([](EventFrameOptions& x) { x.min_events = x.events_per_frame + 1; }));
  EXPECT_FALSE(bad([](EventFrameOptions& x) {
    x.motion_compensation = false;
    x.use_depth = true;
  }));
  EXPECT_FALSE(bad([](EventFrameOptions& x) { x.clip_percentile = 0.0; }));
  EXPECT_FALSE(bad([](EventFrameOptions& x) { x.clip_percentile = 1.5; }));
  EXPECT_FALSE(bad([](EventFrameOptions& x) { x.clip_percentile = std::nan(""); }));
  EXPECT_FALSE(bad([](EventFrameOptions& x) { x.clip_count = -1.0; }));
  EXPECT_FALSE(bad([](EventFrameOptions& x) { x.overlap = -0.1; }));
  EXPECT_FALSE(bad([](EventFrameOptions& x) { x.overlap = 0.95; }));
  EXPECT_FALSE(bad([](EventFrameOptions& x) { x.overlap = std::nan(""); }));
  EXPECT_FALSE(bad([](EventFrameOptions& x) { x.knot_spacing_ns = 0; }));
  EXPECT_FALSE(bad([](EventFrameOptions& x) { x.max_imu_extrapolation_ns = -1; }));
  EXPECT_FALSE(bad([](EventFrameOptions& x) { x.max_imu_gap_ns = 0; }));
  EventFrameOptions x;
  x.events_per_frame = 0;
  EXPECT_THROW(EventFrameBuilder(undistorted_camera(0, Eigen::Matrix3d::Identity()), x), std::invalid_argument);
}

// ---------------------------------------------------------------------------------------------
// Simulated fast rotation in front of a panorama.

struct Collector final : simulator::SimulationSink {
  std::vector<Event>* out = nullptr;
  void on_events(const std::vector<Event>& events, const std::vector<uint16_t>*) override {
    out->insert(out->end(), events.begin(), events.end());
  }
};

struct RotationSequence {
  CameraCalibration cam;
  std::unique_ptr<simulator::Simulator> sim;
  std::vector<Event> events;
  std::vector<ImuSample> imu;
  double mean_rate_degps = 0;
};

const RotationSequence& rotation_sequence() {
  static const RotationSequence* seq = [] {
    auto* s = new RotationSequence;
    calib::CameraIntrinsics in;  // DAVIS240C of the Event Camera Dataset
    in.width = 240;
    in.height = 180;
    in.fx = 199.092366542;
    in.fy = 198.82882047;
    in.cx = 132.192071378;
    in.cy = 110.712660011;
    in.model = calib::DistortionModel::kRadtan;
    in.distortion = {-0.368436311798, 0.150947243557, -0.000296130534385, -0.000759431726241};
    s->cam.camera = calib::PinholeCamera(in);
    s->cam.T_c_b = calib::SE3(camera_from_body_rotation(), Eigen::Vector3d(0.01, 0.02, -0.005));
    s->cam.has_T_c_b = true;
    s->cam.time_shift_ns = 2'500'000;

    simulator::ProceduralTextureOptions t;
    t.kind = simulator::ProceduralKind::kShapes;
    t.width = 2048;
    t.height = 1024;
    t.num_shapes = 300;
    t.seed = 5;
    auto tex = std::make_shared<simulator::Texture>(
        simulator::make_procedural_texture(t, simulator::TextureWrap::kRepeat, simulator::TextureWrap::kClamp));
    auto scene = std::make_shared<simulator::PanoramaScene>(tex);

    // Pan (yaw about world z) at ~170 deg/s plus tilt and roll oscillations: the rate changes
    // within a frame.
    simulator::SinusoidTrajectoryOptions m;
    m.duration_s = 0.4;
    m.angle_rate_radps = Eigen::Vector3d(0.0, 0.0, 3.0);
    m.angle_amplitude_rad = Eigen::Vector3d(0.08, 0.06, 0.05);
    m.angle_frequency_hz = Eigen::Vector3d(3.0, 4.0, 5.0);
    m.angle_phase_rad = Eigen::Vector3d(0.3, 1.0, 0.0);
    auto traj = std::make_shared<simulator::SinusoidTrajectory>(m);

    simulator::SimulatorOptions so;
    so.camera = s->cam.camera;
    so.T_c_b = s->cam.T_c_b;
    so.time_shift_ns = s->cam.time_shift_ns;
    so.ground_truth_flow = false;
    so.events.seed = 3;
    s->sim = std::make_unique<simulator::Simulator>(scene, traj, so);
    Collector c;
    c.out = &s->events;
    s->sim->run(&c);

    simulator::ImuSimOptions io;
    io.rate_hz = 1000;
    io.enable_noise = false;
    s->imu = simulator::simulate_imu(*traj, traj->t_begin_ns(), traj->t_end_ns(), io);
    double sum = 0;
    for (const ImuSample& x : s->imu) sum += x.gyro.norm();
    s->mean_rate_degps = sum / s->imu.size() * 180.0 / M_PI;
    std::printf("simulated %zu events, %zu IMU samples, mean rate %.0f deg/s\n", s->events.size(), s->imu.size(),
                s->mean_rate_degps);
    return s;
  }();
  return *seq;
}

std::vector<EventFrame> run_builder(const RotationSequence& s, const EventFrameOptions& o,
                                    EventFrameStats* stats = nullptr, int64_t offset_ns = 0) {
  EventFrameBuilder b(s.cam, o);
  // IMU first (it leads the events in a live stream), then events in packets of 1000.
  for (ImuSample x : s.imu) {
    x.t_ns += offset_ns;
    b.add_imu(x);
  }
  std::vector<Event> ev = s.events;
  for (Event& e : ev) e.t_ns += offset_ns;
  std::vector<EventFrame> out;
  for (size_t i = 0; i < ev.size(); i += 1000)
    b.add_events(EventSpan(ev.data(), ev.size()).subspan(i, 1000), &out);
  b.flush(&out);
  if (stats) *stats = b.stats();
  return out;
}

// Contrast of an image (any depth): variance of its values.
double variance(const cv::Mat& img) {
  cv::Scalar mean, std;
  cv::meanStdDev(img, mean, std);
  return std[0] * std[0];
}

// Mean squared central-difference gradient.
double gradient_energy(const cv::Mat& img) {
  cv::Mat f;
  img.convertTo(f, CV_64F);
  double e = 0;
  for (int y = 1; y + 1 < f.rows; ++y)
    for (int x = 1; x + 1 < f.cols; ++x) {
      const double gx = 0.5 * (f.at<double>(y, x + 1) - f.at<double>(y, x - 1));
      const double gy = 0.5 * (f.at<double>(y + 1, x) - f.at<double>(y - 1, x));
      e += gx * gx + gy * gy;
    }
  return e / ((f.rows - 2) * (f.cols - 2));
}

double ncc(const cv::Mat& a, const cv::Mat& b) {
  cv::Mat fa, fb;
  a.convertTo(fa, CV_64F);
  b.convertTo(fb, CV_64F);
  const double ma = cv::mean(fa)[0], mb = cv::mean(fb)[0];
  fa -= ma;
  fb -= mb;
  return fa.dot(fb) / std::sqrt(fa.dot(fa) * fb.dot(fb));
}

TEST(EventFrameSimulated, CompensationSharpens) {
  const RotationSequence& s = rotation_sequence();
  EventFrameOptions on;
  EventFrameOptions off = on;
  off.motion_compensation = false;
  EventFrameStats st;
  const std::vector<EventFrame> a = run_builder(s, on, &st);
  const std::vector<EventFrame> b = run_builder(s, off);
  ASSERT_EQ(a.size(), b.size());
  ASSERT_GE(a.size(), 5u);
  EXPECT_EQ(st.frames_uncompensated, 0);
  // Contrast as in contrast maximisation (Gallego et al., CVPR 2018): the variance of the image of
  // warped events (the accumulator: same events, so the same total), and its gradient energy.
  // The normalised 8-bit images are compared too but not asserted: clipping at the 99th
  // percentile of the non-zero pixels saturates much of a blurred frame, which raises its variance.
  double var_ratio = 0, grad_ratio = 0, min_var_ratio = 1e9, img_var_ratio = 0, img_grad_ratio = 0;
  double window_ms = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_TRUE(a[i].motion_compensated);
    EXPECT_EQ(a[i].t_ns, b[i].t_ns);
    const double r = variance(a[i].accumulator) / variance(b[i].accumulator);
    var_ratio += r;
    // The minimum over full frames (the flushed last one holds a 1 ms remainder).
    if (a[i].events == static_cast<size_t>(on.events_per_frame)) min_var_ratio = std::min(min_var_ratio, r);
    grad_ratio += gradient_energy(a[i].accumulator) / gradient_energy(b[i].accumulator);
    img_var_ratio += variance(a[i].image) / variance(b[i].image);
    img_grad_ratio += gradient_energy(a[i].image) / gradient_energy(b[i].image);
    window_ms += (a[i].t_end_ns - a[i].t_begin_ns) * 1e-6;
  }
  const double nf = static_cast<double>(a.size());
  var_ratio /= nf;
  grad_ratio /= nf;
  img_var_ratio /= nf;
  img_grad_ratio /= nf;
  window_ms /= nf;
  std::printf("%zu frames of %d events (mean window %.1f ms, %.0f deg/s), compensated / uncompensated:\n"
              "  accumulator variance ratio mean %.2f (min over full frames %.2f), gradient-energy ratio %.2f\n"
              "  normalised 8-bit image: variance ratio %.2f, gradient-energy ratio %.2f (not asserted)\n",
              a.size(), on.events_per_frame, window_ms, s.mean_rate_degps, var_ratio, min_var_ratio, grad_ratio,
              img_var_ratio, img_grad_ratio);
  // Measured (seed-fixed simulation): 2.27, min 1.85, 5.74.
  EXPECT_GT(var_ratio, 1.8);
  EXPECT_GT(min_var_ratio, 1.5);
  EXPECT_GT(grad_ratio, 4.0);
}

// The first and the second half of a window, each warped to the window's end, give the same
// picture; without compensation they are displaced by the motion between them.
TEST(EventFrameSimulated, HalvesAlignAtCommonTime) {
  const RotationSequence& s = rotation_sequence();
  EventFrameOptions o;
  EventFrameBuilder on(s.cam, o);
  o.motion_compensation = false;
  EventFrameBuilder off(s.cam, o);
  for (const ImuSample& x : s.imu) on.add_imu(x);
  const size_t n = 15000;
  double ncc_on = 0, ncc_off = 0;
  int windows = 0;
  for (size_t start = 20000; start + 2 * n <= s.events.size(); start += 4 * n, ++windows) {
    const EventSpan all(s.events.data(), s.events.size());
    const EventSpan first = all.subspan(start, n), second = all.subspan(start + n, n);
    const int64_t t_ref = second.back().t_ns;
    const double c_on = ncc(on.build_frame(first, t_ref).accumulator, on.build_frame(second, t_ref).accumulator);
    const double c_off = ncc(off.build_frame(first, t_ref).accumulator, off.build_frame(second, t_ref).accumulator);
    std::printf("window at %.1f ms (%.1f ms long): NCC of the halves compensated %.3f, uncompensated %.3f\n",
                (first.front().t_ns) * 1e-6, (second.back().t_ns - first.front().t_ns) * 1e-6, c_on, c_off);
    ncc_on += c_on;
    ncc_off += c_off;
  }
  ASSERT_GE(windows, 2);
  ncc_on /= windows;
  ncc_off /= windows;
  std::printf("mean NCC: compensated %.3f, uncompensated %.3f\n", ncc_on, ncc_off);
  // Measured: 0.985 and 0.175.
  EXPECT_GT(ncc_on, 0.9);
  EXPECT_GT(ncc_on, ncc_off + 0.5);
}

// The compensated frame lines up with the event density the scene predicts at the reference time,
// |grad(log I) . flow|, rendered by the simulator and resampled into the undistorted pinhole image
// (same fx, fy, cx, cy): checks the output geometry, the reference time and the clock convention.
TEST(EventFrameSimulated, AlignsWithPredictedEdgesInPinholeImage) {
  const RotationSequence& s = rotation_sequence();
  EventFrameOptions on;
  EventFrameOptions off = on;
  off.motion_compensation = false;
  const std::vector<EventFrame> a = run_builder(s, on);
  const std::vector<EventFrame> b = run_builder(s, off);
  const calib::CameraIntrinsics& in = s.cam.camera.intrinsics();
  auto predicted = [&](int64_t t_cam) {
    const simulator::RenderedView v = s.sim->render(t_cam + s.cam.time_shift_ns, true);
    // Density in the distorted image.
    cv::Mat d(v.intensity.size(), CV_32F, cv::Scalar(0));
    for (int y = 1; y + 1 < d.rows; ++y)
      for (int x = 1; x + 1 < d.cols; ++x) {
        auto L = [&](int xx, int yy) { return std::log(v.intensity.at<float>(yy, xx) + 1e-3f); };
        const float gx = 0.5f * (L(x + 1, y) - L(x - 1, y)), gy = 0.5f * (L(x, y + 1) - L(x, y - 1));
        const cv::Vec2f f = v.flow.at<cv::Vec2f>(y, x);
        d.at<float>(y, x) = std::abs(gx * f[0] + gy * f[1]);
      }
    // Resample into the undistorted pinhole image.
    cv::Mat u(d.size(), CV_32F, cv::Scalar(0));
    for (int y = 0; y < u.rows; ++y)
      for (int x = 0; x < u.cols; ++x) {
        Eigen::Vector2d px;
        if (!s.cam.camera.project(Eigen::Vector3d((x - in.cx) / in.fx, (y - in.cy) / in.fy, 1.0), &px)) continue;
        const int x0 = static_cast<int>(std::floor(px.x())), y0 = static_cast<int>(std::floor(px.y()));
        if (x0 < 0 || y0 < 0 || x0 + 1 >= d.cols || y0 + 1 >= d.rows) continue;
        const float fx = static_cast<float>(px.x() - x0), fy = static_cast<float>(px.y() - y0);
        u.at<float>(y, x) = (1 - fx) * (1 - fy) * d.at<float>(y0, x0) + fx * (1 - fy) * d.at<float>(y0, x0 + 1) +
                            (1 - fx) * fy * d.at<float>(y0 + 1, x0) + fx * fy * d.at<float>(y0 + 1, x0 + 1);
      }
    return u;
  };
  double on_sum = 0, off_sum = 0, late_sum = 0;
  int n = 0;
  for (size_t i = 1; i + 1 < a.size(); i += 2, ++n) {
    const cv::Mat p = predicted(a[i].t_ns);
    // The same frame against the prediction at its first event's time (where an uncompensated
    // reference would put it).
    const cv::Mat p_begin = predicted(a[i].t_begin_ns);
    const double c_on = ncc(a[i].accumulator, p), c_off = ncc(b[i].accumulator, p);
    const double c_begin = ncc(a[i].accumulator, p_begin);
    std::printf("frame %zu (%.1f ms window): NCC with predicted edges at t_ref: compensated %.3f, uncompensated %.3f; "
                "compensated vs prediction at t_begin %.3f\n",
                i, (a[i].t_end_ns - a[i].t_begin_ns) * 1e-6, c_on, c_off, c_begin);
    on_sum += c_on;
    off_sum += c_off;
    late_sum += c_begin;
  }
  ASSERT_GE(n, 2);
  std::printf("mean NCC: compensated %.3f, uncompensated %.3f, compensated vs t_begin prediction %.3f\n", on_sum / n,
              off_sum / n, late_sum / n);
  // Measured: 0.929, 0.434 and 0.058.
  EXPECT_GT(on_sum / n, 0.85);
  EXPECT_GT(on_sum / n, off_sum / n + 0.35);
  EXPECT_GT(on_sum / n, late_sum / n + 0.6);
}

TEST(EventFrameSimulated, LargeTimestampsGiveTheSameFrames) {
  const RotationSequence& s = rotation_sequence();
  EventFrameOptions o;
  const int64_t offset = 1'700'000'000'000'000'000LL;
  const std::vector<EventFrame> a = run_builder(s, o);
  const std::vector<EventFrame> b = run_builder(s, o, nullptr, offset);
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].t_ns + offset, b[i].t_ns);
    EXPECT_EQ(a[i].events, b[i].events);
    EXPECT_EQ(a[i].motion_compensated, b[i].motion_compensated);
    EXPECT_EQ(cv::norm(a[i].accumulator, b[i].accumulator, cv::NORM_INF), 0.0) << "frame " << i;
    EXPECT_EQ(cv::norm(a[i].image, b[i].image, cv::NORM_INF), 0.0) << "frame " << i;
  }
}

}  // namespace
}  // namespace evio::frontend
