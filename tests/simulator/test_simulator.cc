// Simulator driver: camera kinematics, zero motion, convergence of event counts with the step
// bound, whole-pipeline physics (events integrate the rendered log-intensity change), time shift,
// determinism and APS frames.
#include "evio/simulator/simulator.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <stdexcept>
#include <vector>

#include <gtest/gtest.h>

namespace evio::simulator {
namespace {

calib::PinholeCamera small_camera(int w = 64, int h = 48) {
  calib::CameraIntrinsics in;
  in.width = w;
  in.height = h;
  in.fx = in.fy = 0.8 * w;
  in.cx = (w - 1) / 2.0;
  in.cy = (h - 1) / 2.0;
  in.model = calib::DistortionModel::kRadtan;
  in.distortion = {-0.1, 0.02, 0.0005, -0.0003};
  return calib::PinholeCamera(in);
}

std::shared_ptr<const Scene> boxes_scene() {
  ProceduralTextureOptions t;
  t.kind = ProceduralKind::kShapes;
  t.width = t.height = 256;
  t.seed = 3;
  auto shapes = std::make_shared<Texture>(make_procedural_texture(t));
  t.kind = ProceduralKind::kNoise;
  t.seed = 4;
  auto noise = std::make_shared<Texture>(make_procedural_texture(t));
  std::vector<TexturedPlane> planes(2);
  // Camera looks along +x of the world from the origin (see trajectory below): planes face it.
  planes[0].center_w = {3.0, 0.0, 0.0};
  planes[0].axis_u_w = {0, -1, 0};
  planes[0].axis_v_w = {0, 0, 1};
  planes[0].width_m = planes[0].height_m = 6.0;
  planes[0].texture = noise;
  planes[1].center_w = {1.5, 0.2, 0.1};
  planes[1].axis_u_w = {0, -1, 0};
  planes[1].axis_v_w = {0, 0, 1};
  planes[1].width_m = planes[1].height_m = 0.8;
  planes[1].texture = shapes;
  return std::make_shared<PlanarScene>(planes, 0.1);
}

// Body frame = camera frame rotated so that the camera's z looks along world +x.
calib::SE3 T_c_b_identityish() { return calib::SE3(); }

std::shared_ptr<const ContinuousTrajectory> wobble(double scale, int64_t t0 = 0, double duration = 0.3) {
  SinusoidTrajectoryOptions o;
  o.t_begin_ns = t0;
  o.duration_s = duration;
  // R0 turns the camera (z forward, x right, y down) to look along world +x with z up.
  Eigen::Matrix3d R;
  R << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  o.q_w_b0 = Eigen::Quaterniond(R);
  o.amplitude_m = Eigen::Vector3d(0.02, 0.05, 0.03) * scale;
  o.frequency_hz = {1.3, 2.1, 1.7};
  o.angle_amplitude_rad = Eigen::Vector3d(0.05, 0.08, 0.1) * scale;
  o.angle_frequency_hz = {1.1, 1.9, 2.3};
  o.angle_phase_rad = {0.3, 0.0, 1.0};
  return std::make_shared<SinusoidTrajectory>(o);
}

SimulatorOptions base_options() {
  SimulatorOptions o;
  o.camera = small_camera();
  o.T_c_b = T_c_b_identityish();
  o.events.contrast_threshold_pos = 0.2;
  o.events.contrast_threshold_neg = 0.2;
  o.stepping.max_flow_px = 0.5;
  o.stepping.max_log_change = 0;
  return o;
}

struct Collect : SimulationSink {
  std::vector<Event> events;
  std::vector<uint16_t> labels;
  std::vector<Frame> frames;
  std::vector<RenderedView> views;
  void on_events(const std::vector<Event>& e, const std::vector<uint16_t>* l) override {
    events.insert(events.end(), e.begin(), e.end());
    if (l) labels.insert(labels.end(), l->begin(), l->end());
  }
  void on_frame(const Frame& f) override { frames.push_back(f); }
  void on_ground_truth(const RenderedView& v, const CameraState&) override { views.push_back(v); }
};

TEST(Simulator, CameraVelocityMatchesNumericDerivativeWithExtrinsics) {
  SimulatorOptions o = base_options();
  o.T_c_b = calib::SE3(calib::so3_exp_quat(Eigen::Vector3d(0.1, -0.2, 0.3)), Eigen::Vector3d(0.05, -0.02, 0.03));
  Simulator sim(boxes_scene(), wobble(3.0), o);
  const int64_t t = 100'000'000, h = 10'000;
  const CameraState c = sim.camera_state(t), cp = sim.camera_state(t + h), cm = sim.camera_state(t - h);
  const Eigen::Vector3d v_w_num = (cp.T_w_c.translation - cm.T_w_c.translation) / (2e-9 * h);
  EXPECT_LT((c.T_w_c.rotation * c.v_c - v_w_num).norm(), 1e-6);
  const Eigen::Vector3d omega_num =
      calib::so3_log(cm.T_w_c.rotation.conjugate() * cp.T_w_c.rotation) / (2e-9 * h);
  EXPECT_LT((c.omega_c - omega_num).norm(), 1e-5);
}

TEST(Simulator, ZeroMotionAndNoNoiseGivesNoEvents) {
  SinusoidTrajectoryOptions still;
  still.duration_s = 1.0;
  SimulatorOptions o = base_options();
  Collect sink;
  Simulator sim(boxes_scene(), std::make_shared<SinusoidTrajectory>(still), o);
  const SimulationStats s = sim.run(&sink);
  EXPECT_EQ(s.events, 0u);
  EXPECT_TRUE(sink.events.empty());
  EXPECT_GT(s.steps, 100u);  // still steps (at max_step_ns) through the span
}

TEST(Simulator, IlluminationRampOfAStillSceneGivesItsBurstOfEvents) {
  SinusoidTrajectoryOptions still;
  still.duration_s = 1.0;
  SimulatorOptions o = base_options();
  o.illumination = {{400000000, 1.0}, {450000000, 4.0}};  // x4 over 50 ms, then held
  Simulator sim(boxes_scene(), std::make_shared<SinusoidTrajectory>(still), o);
  EXPECT_EQ(sim.illumination_gain(0), 1.0);
  EXPECT_NEAR(sim.illumination_gain(425000000), 2.0, 1e-12);  // linear in log gain
  EXPECT_EQ(sim.illumination_gain(900000000), 4.0);
  const RenderedView before = sim.render(100000000, false), after = sim.render(900000000, false);
  EXPECT_NEAR(cv::norm(after.intensity, 4.0 * before.intensity, cv::NORM_INF), 0.0, 1e-5);
  Collect sink;
  const SimulationStats s = sim.run(&sink);
  // Every pixel's log intensity rises by ln 4 = 1.386: 6 ON events at C = 0.2 (mismatch 0 here).
  const double pixels = static_cast<double>(o.camera.width()) * o.camera.height();
  EXPECT_GT(static_cast<double>(s.events), 6.0 * pixels * 0.95);
  EXPECT_LT(static_cast<double>(s.events), 7.0 * pixels * 1.05);
  EXPECT_EQ(s.events_off, 0u);
  for (const Event& e : sink.events) {
    EXPECT_GE(e.t_ns, 400000000);
    EXPECT_LE(e.t_ns, 450000000);
  }
  o.illumination = {{0, 1.0}, {0, 2.0}};
  EXPECT_THROW(Simulator(boxes_scene(), std::make_shared<SinusoidTrajectory>(still), o), std::invalid_argument);
}

TEST(Simulator, EventCountsConvergeWhenTheStepBoundIsHalved) {
  std::vector<uint64_t> counts;
  for (double bound : {0.5, 0.25}) {
    SimulatorOptions o = base_options();
    o.stepping.max_flow_px = bound;
    Simulator sim(boxes_scene(), wobble(3.0), o);
    counts.push_back(sim.run(nullptr).events);
  }
  ASSERT_GT(counts[0], 20000u);
  const double change = std::abs(double(counts[0]) - double(counts[1])) / double(counts[1]);
  RecordProperty("relative_change", std::to_string(change));
  std::printf("events at 0.5 px: %llu, at 0.25 px: %llu, change %.4f%%\n", (unsigned long long)counts[0],
              (unsigned long long)counts[1], 100 * change);
  EXPECT_LT(change, 0.01);
}

TEST(Simulator, EventsIntegrateTheRenderedLogIntensityChange) {
  SimulatorOptions o = base_options();
  o.events.threshold_mismatch_std = 0.03;
  o.events.contrast_threshold_neg = 0.25;
  const auto traj = wobble(2.0);
  Simulator sim(boxes_scene(), traj, o);
  Collect sink;
  sim.run(&sink);
  EventGenerator reference(o.camera.width(), o.camera.height(), o.events);  // same seed: same thresholds
  const cv::Mat L0 = reference.to_log(sim.render(sim.t_begin_ns(), false).intensity);
  const cv::Mat L1 = reference.to_log(sim.render(sim.t_end_ns(), false).intensity);
  cv::Mat sum = cv::Mat::zeros(L0.size(), CV_64F);
  for (const Event& e : sink.events)
    sum.at<double>(e.y, e.x) += e.polarity > 0 ? reference.threshold_pos().at<double>(e.y, e.x)
                                               : -reference.threshold_neg().at<double>(e.y, e.x);
  int bad = 0;
  for (int y = 0; y < L0.rows; ++y)
    for (int x = 0; x < L0.cols; ++x) {
      const double change = L1.at<double>(y, x) - L0.at<double>(y, x);
      const double c = std::max(reference.threshold_pos().at<double>(y, x), reference.threshold_neg().at<double>(y, x));
      if (std::abs(sum.at<double>(y, x) - change) > c + 1e-9) ++bad;
    }
  EXPECT_EQ(bad, 0);
  EXPECT_GT(sink.events.size(), 1000u);
}

TEST(Simulator, TimeShiftMovesEventAndFrameStampsOnly) {
  SimulatorOptions o = base_options();
  o.frames.rate_hz = 20;
  o.frames.read_noise_std = 0;
  Collect a, b;
  Simulator(boxes_scene(), wobble(2.0), o).run(&a);
  o.time_shift_ns = 1'234'567;
  Simulator(boxes_scene(), wobble(2.0), o).run(&b);
  ASSERT_EQ(a.events.size(), b.events.size());
  ASSERT_FALSE(a.events.empty());
  for (size_t i = 0; i < a.events.size(); i += 97) {
    EXPECT_EQ(a.events[i].t_ns - 1'234'567, b.events[i].t_ns);
    EXPECT_EQ(a.events[i].x, b.events[i].x);
  }
  ASSERT_EQ(a.frames.size(), b.frames.size());
  ASSERT_FALSE(a.frames.empty());
  EXPECT_EQ(a.frames[0].t_ns - 1'234'567, b.frames[0].t_ns);
  EXPECT_EQ(cv::norm(a.frames[0].image, b.frames[0].image, cv::NORM_INF), 0.0);
}

TEST(Simulator, TrueLogViewIsTheLogOfTheCleanRenderOnTheCameraClock) {
  cv::Mat i(1, 3, CV_32F);
  i.at<float>(0, 0) = 1.0f;
  i.at<float>(0, 1) = 0.0f;
  i.at<float>(0, 2) = -0.5f;  // clamped to 0
  const auto l = log_intensity_view(i, 1e-3);
  EXPECT_FLOAT_EQ(l(0, 0), static_cast<float>(std::log(1.001)));
  EXPECT_FLOAT_EQ(l(0, 1), static_cast<float>(std::log(1e-3)));
  EXPECT_FLOAT_EQ(l(0, 2), static_cast<float>(std::log(1e-3)));
  SimulatorOptions o = base_options();
  o.time_shift_ns = 3'000'000;
  o.events.log_eps = 0.01;
  const Simulator sim(boxes_scene(), wobble(2.0), o);
  const int64_t t_cam = 150'000'000;  // inside the 0.3 s span
  const cv::Mat view = sim.render(t_cam + o.time_shift_ns, false).intensity;
  const auto truth = sim.true_log_view(t_cam);
  ASSERT_EQ(truth.rows(), view.rows);
  ASSERT_EQ(truth.cols(), view.cols);
  for (int y = 0; y < view.rows; y += 17)
    for (int x = 0; x < view.cols; x += 13)
      EXPECT_FLOAT_EQ(truth(y, x), static_cast<float>(std::log(std::max(0.0f, view.at<float>(y, x)) + 0.01)));
  EXPECT_THROW(log_intensity_view(cv::Mat(2, 2, CV_8U), 1e-3), std::invalid_argument);
}

TEST(Simulator, DeterministicForTheSameSeedAndLargeTimestamps) {
  SimulatorOptions o = base_options();
  o.events.shot_noise_rate_hz = 2.0;
  o.events.threshold_mismatch_std = 0.02;
  o.events.timestamp_jitter_ns = 5000;
  Collect a, b, c;
  Simulator(boxes_scene(), wobble(2.0), o).run(&a);
  Simulator(boxes_scene(), wobble(2.0), o).run(&b);
  const int64_t big = 1'700'000'000'000'000'000;
  Simulator(boxes_scene(), wobble(2.0, big), o).run(&c);
  ASSERT_EQ(a.events.size(), b.events.size());
  for (size_t i = 0; i < a.events.size(); ++i) {
    ASSERT_EQ(a.events[i].t_ns, b.events[i].t_ns);
    ASSERT_EQ(a.events[i].x, b.events[i].x);
    ASSERT_EQ(a.events[i].y, b.events[i].y);
    ASSERT_EQ(a.events[i].polarity, b.events[i].polarity);
  }
  // Shifting the whole simulation to 1.7e18 ns changes no relative timestamp.
  ASSERT_EQ(a.events.size(), c.events.size());
  for (size_t i = 0; i < a.events.size(); ++i) ASSERT_EQ(a.events[i].t_ns + big, c.events[i].t_ns);
}

TEST(Simulator, RenderThreadsGiveIdenticalOutput) {
  SimulatorOptions o = base_options();
  o.events.shot_noise_rate_hz = 1.0;
  o.frames.rate_hz = 10;
  o.supersample = 2;
  o.ground_truth_times_ns = {100'000'000};
  // A sprite over the boxes: the sprite pass must honour the row bands too.
  ProceduralTextureOptions t;
  t.kind = ProceduralKind::kShapes;
  t.width = t.height = 128;
  Sprite sprite;
  sprite.texture = std::make_shared<Texture>(make_procedural_texture(t));
  sprite.shape = SpriteShape::kEllipse;
  sprite.width_px = 30;
  sprite.height_px = 20;
  sprite.motion.centre_px = {20, 20};
  sprite.motion.velocity_pxps = {60, 40};
  sprite.motion.angular_rate_radps = 2.0;
  const auto scene = std::make_shared<SpriteScene>(boxes_scene(), std::vector<Sprite>{sprite});
  o.event_labels = true;
  Collect one, three;
  Simulator(scene, wobble(2.0), o).run(&one);
  o.threads = 3;
  Simulator sim3(scene, wobble(2.0), o);
  sim3.run(&three);
  EXPECT_TRUE(one.labels == three.labels);
  ASSERT_GT(one.events.size(), 1000u);
  ASSERT_EQ(one.events.size(), three.events.size());
  for (size_t i = 0; i < one.events.size(); ++i) {
    ASSERT_EQ(one.events[i].t_ns, three.events[i].t_ns);
    ASSERT_EQ(one.events[i].x, three.events[i].x);
    ASSERT_EQ(one.events[i].y, three.events[i].y);
    ASSERT_EQ(one.events[i].polarity, three.events[i].polarity);
  }
  ASSERT_EQ(one.frames.size(), three.frames.size());
  for (size_t i = 0; i < one.frames.size(); ++i)
    EXPECT_EQ(cv::norm(one.frames[i].image, three.frames[i].image, cv::NORM_INF), 0.0);
  ASSERT_EQ(one.views.size(), 1u);
  ASSERT_EQ(three.views.size(), 1u);
  EXPECT_EQ(cv::norm(one.views[0].intensity, three.views[0].intensity, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(one.views[0].flow, three.views[0].flow, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(one.views[0].label, three.views[0].label, cv::NORM_INF), 0.0);
  // A band request into unallocated images is refused, not written out of bounds.
  RenderRequest band;
  band.row_begin = 3;
  band.row_end = 9;
  RenderedView empty;
  EXPECT_THROW(boxes_scene()->render(sim3.camera_state(0), PixelRays(o.camera), band, &empty), std::invalid_argument);
}

TEST(Simulator, FramesBlurWithLongerExposureAndGroundTruthViewsArrive) {
  SimulatorOptions o = base_options();
  o.frames.rate_hz = 10;
  o.frames.read_noise_std = 0;
  o.frames.exposure_s = 0.001;
  o.ground_truth_times_ns = {50'000'000, 150'000'000};
  Collect sharp, blurred;
  Simulator(boxes_scene(), wobble(4.0), o).run(&sharp);
  o.frames.exposure_s = 0.05;
  Simulator(boxes_scene(), wobble(4.0), o).run(&blurred);
  ASSERT_EQ(sharp.frames.size(), 3u);  // 0.3 s at 10 Hz: exposures start at 0, 0.1 and 0.2 s
  ASSERT_EQ(blurred.frames.size(), 3u);
  auto sharpness = [](const cv::Mat& img) {
    double s = 0;
    for (int y = 0; y < img.rows; ++y)
      for (int x = 1; x < img.cols; ++x) s += std::abs(int(img.at<uint8_t>(y, x)) - int(img.at<uint8_t>(y, x - 1)));
    return s;
  };
  EXPECT_LT(sharpness(blurred.frames[1].image), 0.9 * sharpness(sharp.frames[1].image));
  ASSERT_EQ(sharp.views.size(), 2u);
  EXPECT_EQ(sharp.views[0].t_ns, 50'000'000);
  EXPECT_FALSE(sharp.views[0].flow.empty());
  EXPECT_FALSE(sharp.views[0].depth.empty());
}

}  // namespace
}  // namespace evio::simulator
