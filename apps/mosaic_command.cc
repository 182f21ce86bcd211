#include "mosaic_command.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <yaml-cpp/yaml.h>

#include "dataset_calibration.h"
#include "eval_command.h"
#include "evio/calib/equirectangular.h"
#include "evio/calib/error.h"
#include "evio/calib/geometry.h"
#include "evio/calib/log.h"
#include "evio/frontend/event_filters.h"
#include "evio/sensors/trajectory.h"
#include "json_util.h"
#include "progress.h"

namespace evio::apps {
namespace {
std::string num(double v) { return json_number(v, 9); }
std::string json_string(const std::string& s) { return "\"" + json_escape(s) + "\""; }
}  // namespace
}  // namespace evio::apps
#include "simulate_config.h"
#include "yaml_config.h"

namespace evio::apps {

namespace fs = std::filesystem;
using namespace yaml_config;  // NOLINT

MosaicConfig default_mosaic_config() {
  MosaicConfig c;
  c.display.gamma = 1.0;
  // 100 events per particle update (the library's default is 10): on poster_rotation (1 s, gyro)
  // 0.17 deg RMS at 0.60 M events/s against 0.23 deg at 0.42 M events/s; events only 1.99 vs 2.04 deg.
  c.tracker.batch_size = 100;
  return c;
}

namespace {

std::string config_yaml(const MosaicConfig& c) {
  std::ostringstream y;
  const auto& m = c.mosaic;
  const auto& t = c.tracker;
  y << "mosaic: {width: " << m.width << ", height: " << m.height << ", contrast_threshold: " << num(m.contrast_threshold)
    << ", initial_gradient_std: " << num(m.initial_gradient_std) << ", measurement_std_abs: " << num(m.measurement_std_abs)
    << ", measurement_relative_std: " << num(m.measurement_relative_std) << ", min_tau_ms: " << num(m.min_tau_s * 1e3)
    << ", min_speed_px_s: " << num(m.min_speed_px_s) << ", seen_min_observations: " << m.seen_min_observations
    << ", seen_max_gradient_std: " << num(m.seen_max_gradient_std) << ", max_path_px: " << num(m.max_path_px) << ", reconstruct_ms: " << num(c.reconstruct_period_ns * 1e-6) << "}\n";
  y << "tracker: {particles: " << t.num_particles << ", batch_size: " << t.batch_size << ", event_stride: " << t.event_stride
    << ", max_batch_ms: " << num(t.max_batch_duration_ns * 1e-6)
    << ", motion_model: " << frontend::rotation_motion_model_name(t.motion_model)
    << ", measurement_model: " << frontend::rotation_measurement_model_name(t.measurement_model)
    << ", contrast_threshold: " << num(t.contrast_threshold) << ", linearize_max_spread_rad: " << num(t.linearize_max_spread_rad)
    << ", motion_noise_rad_per_sqrt_s: " << num(t.motion_noise_rad_per_sqrt_s)
    << ", gyro_noise_rad_per_sqrt_s: " << num(t.gyro_noise_rad_per_sqrt_s) << ", likelihood_std: " << num(t.likelihood_std)
    << ", outlier_probability: " << num(t.outlier_probability) << ", resample_ess_fraction: " << num(t.resample_ess_fraction)
    << ", seed: " << t.seed << "}\n";
  y << "bootstrap: {duration_ms: " << num(c.bootstrap_ns * 1e-6) << ", window_ms: " << num(c.bootstrap_window_ns * 1e-6)
    << ", window_events: " << c.bootstrap_window_events
    << ", blur_px: " << num(c.cmax.blur_sigma_px) << ", calibrate_contrast: " << (c.calibrate_contrast ? "true" : "false")
    << ", min_contrast_ratio: " << num(c.min_contrast_ratio) << "}\n";
  y << "output: {trajectory_ms: " << num(c.trajectory_period_ns * 1e-6) << ", snapshot_ms: " << num(c.snapshot_period_ns * 1e-6)
    << ", gamma: " << num(c.display.gamma) << ", low_percentile: " << num(c.display.low_percentile)
    << ", high_percentile: " << num(c.display.high_percentile) << "}\n";
  return y.str();
}

}  // namespace

MosaicConfig load_mosaic_config(const std::string& path, std::string* resolved_yaml) {
  MosaicConfig c = default_mosaic_config();
  const std::string expected = "a mosaic config YAML (see README.md, `evio mosaic`)";
  const YAML::Node root = load_yaml_file(path, expected);
  const Parser parser(path, {});
  if (!root.IsNull()) {
    if (!root.IsMap()) parser.fail(root, "", "is not a map", expected);
    const Section top(&parser, root, "");
    top.allow({"mosaic", "tracker", "bootstrap", "output", "description"});
    if (top.has("mosaic")) {
      const Section s = top.child("mosaic", false, "a map");
      s.allow({"width", "height", "contrast_threshold", "initial_gradient_std", "measurement_std_abs",
               "measurement_relative_std", "min_tau_ms", "min_speed_px_s", "reconstruct_ms", "seen_min_observations",
               "seen_max_gradient_std", "max_path_px"});
      auto& m = c.mosaic;
      m.width = s.integer("width", m.width, 8, 1 << 15);
      m.height = s.integer("height", m.width / 2, 4, 1 << 14);
      m.contrast_threshold = s.number("contrast_threshold", m.contrast_threshold, Range::kPositive, "log units");
      m.initial_gradient_std = s.number("initial_gradient_std", m.initial_gradient_std, Range::kPositive, "log units/px");
      m.measurement_std_abs = s.number("measurement_std_abs", m.measurement_std_abs, Range::kNonNegative, "1/s");
      m.measurement_relative_std = s.number("measurement_relative_std", m.measurement_relative_std, Range::kNonNegative, "");
      m.min_tau_s = s.number("min_tau_ms", m.min_tau_s * 1e3, Range::kPositive, "ms") * 1e-3;
      m.min_speed_px_s = s.number("min_speed_px_s", m.min_speed_px_s, Range::kNonNegative, "px/s");
      c.reconstruct_period_ns = s.time_ns("reconstruct_ms", c.reconstruct_period_ns, Range::kPositive);
      m.seen_min_observations = s.integer("seen_min_observations", m.seen_min_observations, 1, 1000000);
      m.max_path_px = s.number("max_path_px", m.max_path_px, Range::kPositive, "mosaic px");
      m.seen_max_gradient_std = s.number("seen_max_gradient_std", m.seen_max_gradient_std, Range::kNonNegative, "log units/px");
      std::string why;
      if (!m.Validate(&why)) s.fail("invalid mosaic settings: " + why, "consistent settings");
    }
    c.tracker.contrast_threshold = c.mosaic.contrast_threshold;  // unless tracker.contrast_threshold says otherwise
    if (top.has("tracker")) {
      const Section s = top.child("tracker", false, "a map");
      s.allow({"particles", "batch_size", "max_batch_ms", "motion_model", "measurement_model", "contrast_threshold", "event_stride", "linearize_max_spread_rad", "motion_noise_rad_per_sqrt_s",
               "gyro_noise_rad_per_sqrt_s", "likelihood_std", "outlier_probability", "resample_ess_fraction", "seed"});
      auto& t = c.tracker;
      t.num_particles = s.integer("particles", t.num_particles, 1, 1000000);
      t.contrast_threshold = s.number("contrast_threshold", c.mosaic.contrast_threshold, Range::kPositive, "log units");
      t.batch_size = s.integer("batch_size", t.batch_size, 1, 1000000);
      c.event_stride = s.integer("event_stride", c.event_stride, 1, 1000000);
      t.linearize_max_spread_rad = s.number("linearize_max_spread_rad", t.linearize_max_spread_rad, Range::kNonNegative, "rad");
      t.max_batch_duration_ns = s.time_ns("max_batch_ms", t.max_batch_duration_ns, Range::kPositive);
      const std::string mm = s.string("motion_model", frontend::rotation_motion_model_name(t.motion_model),
                                      {"random_walk", "constant_velocity"});
      t.motion_model = mm == "random_walk" ? frontend::RotationMotionModel::kRandomWalk
                                           : frontend::RotationMotionModel::kConstantVelocity;
      const std::string meas = s.string("measurement_model", frontend::rotation_measurement_model_name(t.measurement_model),
                                        {"previous_mean", "relative_motion", "auto"});
      t.measurement_model = meas == "previous_mean"     ? frontend::RotationMeasurementModel::kPreviousMean
                            : meas == "relative_motion" ? frontend::RotationMeasurementModel::kRelativeMotion
                                                        : frontend::RotationMeasurementModel::kAuto;
      t.motion_noise_rad_per_sqrt_s = s.number("motion_noise_rad_per_sqrt_s", t.motion_noise_rad_per_sqrt_s, Range::kPositive, "rad/sqrt(s)");
      t.gyro_noise_rad_per_sqrt_s = s.number("gyro_noise_rad_per_sqrt_s", t.gyro_noise_rad_per_sqrt_s, Range::kPositive, "rad/sqrt(s)");
      t.likelihood_std = s.number("likelihood_std", t.likelihood_std, Range::kPositive, "log units");
      t.outlier_probability = s.number("outlier_probability", t.outlier_probability, Range::kUnit, "");
      t.resample_ess_fraction = s.number("resample_ess_fraction", t.resample_ess_fraction, Range::kUnit, "");
      t.seed = static_cast<uint64_t>(s.integer("seed", static_cast<int>(t.seed), 0, 2147483647));
      std::string why;
      if (!t.Validate(&why)) s.fail("invalid tracker settings: " + why, "consistent settings");
    }
    if (top.has("bootstrap")) {
      const Section s = top.child("bootstrap", false, "a map");
      s.allow({"duration_ms", "window_ms", "window_events", "blur_px", "calibrate_contrast", "min_contrast_ratio"});
      c.calibrate_contrast = s.boolean("calibrate_contrast", c.calibrate_contrast);
      c.min_contrast_ratio = s.number("min_contrast_ratio", c.min_contrast_ratio, Range::kUnit, "");
      c.bootstrap_ns = s.time_ns("duration_ms", c.bootstrap_ns, Range::kNonNegative);
      c.bootstrap_window_ns = s.time_ns("window_ms", c.bootstrap_window_ns, Range::kPositive);
      c.bootstrap_window_events = s.integer("window_events", c.bootstrap_window_events, 1000, 100000000);
      c.cmax.blur_sigma_px = s.number("blur_px", c.cmax.blur_sigma_px, Range::kPositive, "px");
    }
    if (top.has("output")) {
      const Section s = top.child("output", false, "a map");
      s.allow({"trajectory_ms", "snapshot_ms", "gamma", "low_percentile", "high_percentile"});
      c.trajectory_period_ns = s.time_ns("trajectory_ms", c.trajectory_period_ns, Range::kPositive);
      c.snapshot_period_ns = s.time_ns("snapshot_ms", c.snapshot_period_ns, Range::kNonNegative);
      c.display.gamma = s.number("gamma", c.display.gamma, Range::kPositive, "");
      c.display.low_percentile = s.number("low_percentile", c.display.low_percentile, Range::kNonNegative, "%");
      c.display.high_percentile = s.number("high_percentile", c.display.high_percentile, Range::kPositive, "%");
      std::string why;
      if (!c.display.Validate(&why)) s.fail("invalid output settings: " + why, "consistent settings");
    }
  }
  if (resolved_yaml) *resolved_yaml = config_yaml(c);
  return c;
}

namespace {

constexpr int kCalibrationMinUpdates = 5;  // texel updates for a path end to count in the contrast calibration

// The mosaic frame puts the first camera's optical axis on the equator, looking along +x, image
// right = -y, image down = -z (the simulator's rpy [-90, 0, -90] start), away from the poles.
Eigen::Matrix3d initial_camera_rotation() {
  Eigen::Matrix3d R;
  R.col(0) = Eigen::Vector3d(0, -1, 0);
  R.col(1) = Eigen::Vector3d(0, 0, -1);
  R.col(2) = Eigen::Vector3d(1, 0, 0);
  return R;
}

// Log intensity of the last reconstruction for the tracker: NaN where unseen.
void to_map(const mapping::MosaicReconstruction& rec, std::vector<float>* map) {
  const auto& L = rec.log_intensity;
  map->resize(static_cast<size_t>(L.size()));
  for (Eigen::Index j = 0; j < L.rows(); ++j)
    for (Eigen::Index i = 0; i < L.cols(); ++i)
      (*map)[static_cast<size_t>(j * L.cols() + i)] = rec.seen(j, i) ? L(j, i) : std::nanf("");
}

}  // namespace

int run_mosaic(const MosaicArgs& args, std::ostream& out) {
  std::string resolved;
  MosaicConfig cfg = args.config.empty() ? default_mosaic_config() : load_mosaic_config(args.config, &resolved);
  if (args.particles > 0) cfg.tracker.num_particles = args.particles;
  if (args.batch > 0) cfg.tracker.batch_size = args.batch;
  if (args.stride > 0) cfg.event_stride = args.stride;
  cfg.tracker.event_stride = cfg.event_stride > 0 ? cfg.event_stride : (args.use_imu ? 4 : 1);
  if (args.width > 0) {
    cfg.mosaic.width = args.width;
    cfg.mosaic.height = args.width / 2;
  }
  if (args.snapshot_s > 0) cfg.snapshot_period_ns = static_cast<int64_t>(std::llround(args.snapshot_s * 1e9));
  {
    std::string why;
    if (!cfg.mosaic.Validate(&why)) throw InputError(args.config.empty() ? "--width" : args.config, 0, why, "valid mosaic settings");
    if (!cfg.tracker.Validate(&why)) throw InputError(args.config.empty() ? "--particles/--batch" : args.config, 0, why, "valid tracker settings");
  }
  resolved = config_yaml(cfg);

  auto reader = open_dataset(args.dataset, args.dataset_options);
  const DatasetCalibration found = find_dataset_calibration(args.dataset, args.calib, *reader);
  if (!found.camera) throw InputError(args.dataset, 0, "no camera calibration", "--calib FILE (Kalibr camchain YAML or ECD calib.txt)");
  const calib::CameraCalibration cal = *found.camera;
  const int W = cal.camera.width(), H = cal.camera.height();
  std::vector<ImuSample> imu;
  if (args.use_imu) {
    imu = reader->read_imu();
    if (imu.size() < 2) throw InputError(args.dataset, 0, "--use-imu: the dataset has no IMU samples", "a recording with IMU");
  }
  fs::create_directories(args.out);
  {
    std::ofstream f((fs::path(args.out) / "mosaic_config.yaml").string());
    f << resolved;
  }

  const frontend::EventUndistorter undistorter(cal.camera);
  mapping::GradientMosaic mosaic(cfg.mosaic);
  const calib::Equirectangular proj(cfg.mosaic.width, cfg.mosaic.height);
  const Eigen::Quaterniond q_c_b(cal.T_c_b.rotation);
  const int64_t shift = cal.time_shift_ns;  // t_imu = t_cam + shift
  std::vector<float> map;
  std::vector<int64_t> last_t(static_cast<size_t>(W) * H, INT64_MIN);

  // Read every event (the tracker and the mapper run in one pass over them).
  std::vector<Event> events;
  {
    EventBuffer chunk;
    while (reader->read_events(&chunk, size_t{1} << 20) > 0) {
      events.insert(events.end(), chunk.begin(), chunk.end());
      chunk.clear();
    }
  }
  if (events.empty()) throw InputError(args.dataset, 0, "no events", "a recording with events");
  const auto wall0 = std::chrono::steady_clock::now();
  const int64_t t0 = events.front().t_ns, t_last = events.back().t_ns;

  // Gyro in the camera frame on the camera clock (piecewise constant), for the bootstrap and pf.
  size_t next_imu = 0;
  auto gyro_c_at = [&](int64_t t_cam) {
    const int64_t t = t_cam + shift;
    auto it = std::upper_bound(imu.begin(), imu.end(), t, [](int64_t a, const ImuSample& s) { return a < s.t_ns; });
    if (it != imu.begin()) --it;
    return frontend::RotationParticleFilter::camera_rate_from_imu(*it, q_c_b);
  };

  uint64_t mapped = 0;
  // Bootstrap segments (every 8th mapped event) for the tracker's contrast calibration.
  struct Segment {
    Eigen::Vector2d from, to;
    int polarity;
  };
  std::vector<Segment> boot_segments;
  std::vector<Segment>* segments = cfg.calibrate_contrast ? &boot_segments : nullptr;
  // Per sensor pixel: time and mosaic position of its previous event (the mapper's path start).
  std::vector<Eigen::Vector2d> last_uv(static_cast<size_t>(W) * H);
  // The event's direction is R_w_c (b + dt w_c x b): R_w_c at a nearby time, rotated to the
  // event's time to first order (dt |w_c| is a few mrad at most within a particle-filter batch).
  auto map_event = [&](const Event& e, const Eigen::Matrix3d& R_w_c, const Eigen::Vector3d& w_c, double dt) {
    const size_t p = static_cast<size_t>(e.y) * W + e.x;
    if (!undistorter.valid(e.x, e.y)) return;
    const int64_t prev = last_t[p];
    const Eigen::Vector3d b = undistorter.bearing(e.x, e.y).cast<double>();
    const Eigen::Vector2d uv = proj.project(R_w_c * (b + dt * w_c.cross(b)));
    last_t[p] = e.t_ns;
    const Eigen::Vector2d uv_prev = last_uv[p];
    last_uv[p] = uv;
    if (prev == INT64_MIN) return;
    if (mosaic.update_segment(uv_prev, uv, static_cast<double>(e.t_ns - prev) * 1e-9, e.polarity) ==
        mapping::MosaicUpdate::kApplied) {
      ++mapped;
      if (segments && (mapped % 8) == 0) segments->push_back({uv_prev, uv, e.polarity});
    }
  };

  // ---- bootstrap: rotation from the gyro or from contrast-maximisation rates -------------------
  Eigen::Matrix3d R = initial_camera_rotation();
  size_t i = 0;
  const int64_t t_boot = t0 + cfg.bootstrap_ns;
  mapping::RotationalCmaxOptions cmax = cfg.cmax;
  cmax.width = W;
  cmax.height = H;
  cmax.focal_px = std::sqrt(cal.camera.intrinsics().fx * cal.camera.intrinsics().fy);
  Eigen::Vector3d omega_c = Eigen::Vector3d::Zero();
  int cmax_windows = 0;
  Trajectory rotation;
  auto record = [&](int64_t t, const Eigen::Matrix3d& R_w_c) {
    if (!rotation.empty() && t - rotation.t_end_ns() < cfg.trajectory_period_ns) return;
    calib::SE3 T;
    T.rotation = Eigen::Quaterniond(R_w_c * cal.T_c_b.rotation.toRotationMatrix()).normalized();  // R_w_b
    T.translation.setZero();
    rotation.push_back({t, T});
  };
  record(t0, R);
  while (i < events.size() && events[i].t_ns < t_boot) {
    const int64_t tw0 = events[i].t_ns;
    // With the gyro, 1 ms windows: within one the rate at each event's time is held constant.
    int64_t tw1 = std::min(t_boot, tw0 + (args.use_imu ? std::min<int64_t>(cfg.bootstrap_window_ns, 1'000'000)
                                                       : cfg.bootstrap_window_ns));
    size_t j = i;
    const size_t max_events = args.use_imu ? events.size() : static_cast<size_t>(cfg.bootstrap_window_events);
    while (j < events.size() && events[j].t_ns < tw1 && j - i < max_events) ++j;
    if (j < events.size() && events[j].t_ns < tw1) tw1 = events[j].t_ns;  // closed by the event count
    if (!args.use_imu) {
      std::vector<Eigen::Vector3f> b;
      std::vector<int64_t> t;
      for (size_t k = i; k < j; ++k) {
        if (!undistorter.valid(events[k].x, events[k].y)) continue;
        b.push_back(undistorter.bearing(events[k].x, events[k].y));
        t.push_back(events[k].t_ns);
      }
      omega_c = mapping::estimate_angular_velocity(b, t, tw0, omega_c, cmax).omega_c;
      ++cmax_windows;
    }
    for (size_t k = i; k < j; ++k) {
      const Event& e = events[k];
      const Eigen::Vector3d w_c = args.use_imu ? gyro_c_at(e.t_ns) : omega_c;
      const Eigen::Matrix3d R_e = R * calib::so3_exp(w_c * (static_cast<double>(e.t_ns - tw0) * 1e-9));
      map_event(e, R_e, Eigen::Vector3d::Zero(), 0.0);
    }
    // Advance R to the window's end (gyro: integrate the samples inside).
    if (args.use_imu) {
      for (int64_t t = tw0; t < tw1;) {
        const int64_t dt = std::min<int64_t>(1'000'000, tw1 - t);
        R = R * calib::so3_exp(gyro_c_at(t + dt / 2) * (static_cast<double>(dt) * 1e-9));
        t += dt;
      }
    } else {
      R = R * calib::so3_exp(omega_c * (static_cast<double>(tw1 - tw0) * 1e-9));
    }
    record(tw1, R);
    i = j;
  }
  mapping::MosaicReconstruction rec = mosaic.reconstruct(mapping::GradientMosaic::ReconstructMode::kFull);
  to_map(rec, &map);
  segments = nullptr;
  // The tracker's contrast: the mosaic's own log-intensity change along the bootstrap's event
  // paths (poses from the gyro or CMax, not from the tracker). The reconstruction is smoother than
  // the scene, so its change per event is below the sensor's C; tracking with the sensor's C
  // against it makes the tracker over-rotate (previous_mean) until it matches.
  double contrast_used = cfg.tracker.contrast_threshold;
  int64_t contrast_samples = 0;
  if (cfg.calibrate_contrast) {
    const frontend::LogIntensityMapView v0{cfg.mosaic.width, cfg.mosaic.height, map.data()};
    double sum = 0;
    // Only paths between texels with several updates: a young texel's gradient is still shrunk
    // towards the prior's zero, which would bias the calibration low (slow motion, few events).
    auto mature = [&](const Eigen::Vector2d& uv) {
      const int iu = static_cast<int>(std::floor(uv.x())), iv = static_cast<int>(std::floor(uv.y()));
      if (iv < 0 || iv >= cfg.mosaic.height) return false;
      const int w = cfg.mosaic.width;
      return mosaic.observations(((iu % w) + w) % w, iv) >= static_cast<uint32_t>(kCalibrationMinUpdates);
    };
    for (const Segment& sg : boot_segments) {
      if (!mature(sg.from) || !mature(sg.to)) continue;
      const float a = v0.sample(static_cast<float>(sg.to.x()), static_cast<float>(sg.to.y()));
      const float b = v0.sample(static_cast<float>(sg.from.x()), static_cast<float>(sg.from.y()));
      if (std::isnan(a) || std::isnan(b)) continue;
      sum += sg.polarity * static_cast<double>(a - b);
      ++contrast_samples;
    }
    if (contrast_samples >= 1000 && sum > 0) {
      contrast_used = std::clamp(sum / static_cast<double>(contrast_samples),
                                 cfg.min_contrast_ratio * cfg.tracker.contrast_threshold, cfg.tracker.contrast_threshold);
    } else {
      log_warning("evio mosaic: too few bootstrap events (" + std::to_string(contrast_samples) +
               ") to calibrate the tracker's contrast; using tracker.contrast_threshold " + num(contrast_used));
    }
  }
  frontend::RotationParticleFilterOptions tracker_options = cfg.tracker;
  tracker_options.contrast_threshold = contrast_used;
  frontend::RotationParticleFilter pf(undistorter, tracker_options);
  const int64_t t_track0 = i < events.size() ? events[i].t_ns : t_last;
  pf.reset(Eigen::Quaterniond(R), t_track0);
  frontend::LogIntensityMapView view;
  view.width = cfg.mosaic.width;
  view.height = cfg.mosaic.height;
  view.data = map.data();

  // ---- tracking and mapping ----------------------------------------------------------------
  Progress progress("evio mosaic", args.progress, "events");
  int64_t next_rec = t_track0 + cfg.reconstruct_period_ns;
  int64_t next_snap = cfg.snapshot_period_ns > 0 ? t_track0 : INT64_MAX;
  int snapshots = 0, reconstructions = 1;
  if (args.use_imu) {
    while (next_imu < imu.size() && imu[next_imu].t_ns - shift <= t_track0) ++next_imu;
    if (next_imu > 0) --next_imu;
  }
  const size_t batch = static_cast<size_t>(cfg.tracker.batch_size);
  while (i < events.size()) {
    const size_t j = std::min(events.size(), i + batch);
    if (args.use_imu) {
      for (; next_imu < imu.size() && imu[next_imu].t_ns - shift <= events[j - 1].t_ns; ++next_imu)
        pf.add_gyro(imu[next_imu].t_ns - shift, frontend::RotationParticleFilter::camera_rate_from_imu(imu[next_imu], q_c_b));
    }
    pf.update(events.data() + i, j - i, view);
    pf.flush(view);
    const Eigen::Matrix3d R_pf = pf.mean().toRotationMatrix();
    const Eigen::Vector3d w_c = pf.angular_velocity_c();
    const int64_t t_pf = pf.time_ns();
    for (size_t k = i; k < j; ++k) {
      map_event(events[k], R_pf, w_c, static_cast<double>(events[k].t_ns - t_pf) * 1e-9);
    }
    record(t_pf, R_pf);
    const int64_t t_now = events[j - 1].t_ns;
    if (t_now >= next_rec) {
      rec = mosaic.reconstruct(reconstructions % 50 == 0 ? mapping::GradientMosaic::ReconstructMode::kFull : mapping::GradientMosaic::ReconstructMode::kAuto);
      to_map(rec, &map);
      view.data = map.data();
      ++reconstructions;
      next_rec = t_now + cfg.reconstruct_period_ns;
    }
    if (t_now >= next_snap) {
      fs::create_directories(fs::path(args.out) / "snapshots");
      char name[64];
      std::snprintf(name, sizeof(name), "panorama_%06d.png", snapshots++);
      mapping::write_log_image_png8((fs::path(args.out) / "snapshots" / name).string(), rec.log_intensity, &rec.seen, cfg.display);
      next_snap = t_now + cfg.snapshot_period_ns;
    }
    i = j;
    const double seq = static_cast<double>(t_now - t0) * 1e-9;
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
    if ((i / batch) % 4096 == 0)
      progress.update(static_cast<double>(i) / static_cast<double>(events.size()), static_cast<int64_t>(i),
                      "real-time factor " + num(seq > 0 ? wall / seq : 0.0));
  }
  rec = mosaic.reconstruct(mapping::GradientMosaic::ReconstructMode::kFull);
  const double processing_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  const double duration_s = static_cast<double>(t_last - t0) * 1e-9;

  // ---- outputs -------------------------------------------------------------------------------
  write_tum((fs::path(args.out) / "rotation.tum").string(), rotation);
  mapping::write_log_image_png8((fs::path(args.out) / "panorama.png").string(), rec.log_intensity, &rec.seen, cfg.display);
  mapping::write_log_image_tiff((fs::path(args.out) / "panorama_log.tiff").string(), rec.log_intensity, &rec.seen);
  const auto& st = pf.stats();
  int64_t seen = 0;
  for (Eigen::Index k = 0; k < rec.seen.size(); ++k) seen += rec.seen.data()[k] ? 1 : 0;
  {
    std::ofstream f((fs::path(args.out) / "stats.json").string());
    f << "{\n  \"dataset\": " << json_string(args.dataset) << ",\n  \"events\": " << events.size()
      << ",\n  \"processing_time_s\": " << num(processing_s) << ",\n  \"sequence_duration_s\": " << num(duration_s)
      << ",\n  \"real_time_factor\": " << num(duration_s > 0 ? processing_s / duration_s : 0)
      << ",\n  \"events_per_s\": " << num(processing_s > 0 ? events.size() / processing_s : 0)
      << ",\n  \"use_imu\": " << (args.use_imu ? "true" : "false") << ",\n  \"particles\": " << cfg.tracker.num_particles
      << ",\n  \"batch_size\": " << cfg.tracker.batch_size << ",\n  \"event_stride\": " << cfg.tracker.event_stride
      << ",\n  \"measurement_model\": \"" << frontend::rotation_measurement_model_name(cfg.tracker.measurement_model) << "\"" << ",\n  \"mosaic_size\": [" << cfg.mosaic.width << ", "
      << cfg.mosaic.height << "],\n  \"bootstrap\": {\"method\": \"" << (args.use_imu ? "gyro" : "contrast_maximisation")
      << "\", \"duration_s\": " << num((t_track0 - t0) * 1e-9) << ", \"cmax_windows\": " << cmax_windows
      << ", \"tracker_contrast\": " << num(contrast_used) << ", \"contrast_samples\": " << contrast_samples << "}"
      << ",\n  \"tracker\": {\"events_used\": " << st.events_used << ", \"skipped_no_previous\": " << st.skipped_no_previous
      << ", \"skipped_unknown_map\": " << st.skipped_unknown_map << ", \"skipped_stride\": " << st.skipped_stride << ", \"batches\": " << st.batches
      << ", \"resamples\": " << st.resamples << ", \"linearized_batches\": " << st.linearized_batches << ", \"gyro_predictions\": " << st.gyro_predictions << "}"
      << ",\n  \"mapper\": {\"events_mapped\": " << mapped << ", \"reconstructions\": " << reconstructions
      << ", \"seen_pixels\": " << seen << ", \"seen_fraction\": " << num(static_cast<double>(seen) / static_cast<double>(rec.seen.size()))
      << "},\n  \"snapshots\": " << snapshots << "\n}\n";
  }
  out << "events        " << events.size() << " over " << num(duration_s) << " s, bootstrap "
      << (args.use_imu ? "gyro" : "contrast maximisation") << " " << num((t_track0 - t0) * 1e-9) << " s\n";
  out << "speed         " << num(processing_s) << " s processing, real-time factor "
      << num(duration_s > 0 ? processing_s / duration_s : 0) << " (one core), "
      << num(processing_s > 0 ? events.size() / processing_s / 1e6 : 0) << " M events/s\n";
  out << "mosaic        " << cfg.mosaic.width << "x" << cfg.mosaic.height << ", "
      << num(100.0 * static_cast<double>(seen) / static_cast<double>(rec.seen.size())) << "% seen\n";

  if (!args.gt.empty()) {
    const Trajectory gt = load_trajectory(args.gt);
    // Align the initial orientation: A maps the mosaic frame to the ground truth's world.
    std::optional<calib::SE3> g0;
    size_t first = 0;
    for (; first < rotation.size(); ++first)
      if ((g0 = gt.interpolate(rotation[first].t_ns))) break;
    if (!g0) throw InputError(args.gt, 0, "no ground-truth pose within the estimate's time span", "a trajectory overlapping the events");
    const Eigen::Matrix3d A = g0->rotation.toRotationMatrix() * rotation[first].T_w_b.rotation.toRotationMatrix().transpose();
    std::vector<double> err;
    for (size_t k = first; k < rotation.size(); ++k) {
      const auto g = gt.interpolate(rotation[k].t_ns);
      if (!g) continue;
      const Eigen::Matrix3d E = g->rotation.toRotationMatrix().transpose() * A * rotation[k].T_w_b.rotation.toRotationMatrix();
      err.push_back(calib::so3_log(E).norm() * 180.0 / M_PI);
    }
    double s2 = 0, mx = 0;
    for (double e : err) {
      s2 += e * e;
      mx = std::max(mx, e);
    }
    const double rms = err.empty() ? 0 : std::sqrt(s2 / static_cast<double>(err.size()));
    // Mosaic quality against the true panorama of a simulated dataset (scene_resolved.yaml).
    std::string quality_json;
    const fs::path scene = fs::path(args.dataset) / "scene_resolved.yaml";
    if (fs::exists(scene)) {
      const SimulationConfig sc = load_simulation_config(scene.string());
      if (sc.panorama) {
        const Eigen::Matrix3d R_w_m = A;  // mosaic frame -> simulator world
        const calib::Equirectangular tex_proj(sc.panorama->width(), sc.panorama->height());
        mapping::ImageF ref(cfg.mosaic.height, cfg.mosaic.width);
        for (int v = 0; v < cfg.mosaic.height; ++v)
          for (int u = 0; u < cfg.mosaic.width; ++u) {
            const Eigen::Vector2d t = tex_proj.project(R_w_m * proj.pixel_direction(u, v));
            const double footprint = static_cast<double>(sc.panorama->height()) / cfg.mosaic.height;
            ref(v, u) = std::log(std::max(1e-4f, sc.panorama->sample(t.x(), t.y(), footprint)));
          }
        const mapping::ImageQuality q = mapping::compare_images(rec.log_intensity, ref, &rec.seen);
        quality_json = ",\n  \"mosaic_quality\": {\"psnr_db\": " + num(q.psnr_db) + ", \"ssim\": " + num(q.ssim) +
                       ", \"rmse_log\": " + num(q.rmse) + ", \"contrast_gain\": " + num(q.scale) + ", \"pixels\": " + std::to_string(q.pixels) +
                       ", \"fit\": \"affine in log intensity over the seen pixels\"}";
        out << "mosaic vs true panorama: PSNR " << num(q.psnr_db) << " dB, SSIM " << num(q.ssim) << " over "
            << q.pixels << " seen pixels (affine log-intensity fit)\n";
      }
    }
    std::ofstream f((fs::path(args.out) / "eval.json").string());
    f << "{\n  \"groundtruth\": " << json_string(args.gt) << ",\n  \"estimate\": "
      << json_string((fs::path(args.out) / "rotation.tum").string()) << ",\n  \"alignment\": \"initial orientation\""
      << ",\n  \"matched_poses\": " << err.size() << ",\n  \"rot_rms_deg\": " << num(rms) << ",\n  \"rot_max_deg\": " << num(mx)
      << quality_json << "\n}\n";
    out << "evaluation    rotation error rms " << num(rms) << " deg, max " << num(mx) << " deg over " << err.size()
        << " poses (initial orientation aligned)\n";
  }
  out << "wrote " << args.out << "/rotation.tum, panorama.png, panorama_log.tiff, stats.json, mosaic_config.yaml"
      << (args.gt.empty() ? "" : ", eval.json") << "\n";
  return 0;
}

}  // namespace evio::apps
