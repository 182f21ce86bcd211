#include "vio_command.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <ostream>
#include <sstream>

#include <yaml-cpp/yaml.h>

#include "eval_command.h"
#include "evio/backend/imu_preintegration.h"
#include "evio/calib/calibration_io.h"
#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio/mapping/landmark_map.h"
#include "evio/sensors/time.h"
#include "json_util.h"
#include "dataset_calibration.h"
#include "progress.h"
#include "yaml_config.h"

namespace evio::apps {
namespace {
namespace fs = std::filesystem;
using namespace yaml_config;  // NOLINT

int64_t ms_to_ns(double ms) { return static_cast<int64_t>(std::llround(ms * 1e6)); }
double ns_to_ms(int64_t ns) { return static_cast<double>(ns) * 1e-6; }

std::string num(double v) {
  char b[40];
  std::snprintf(b, sizeof(b), "%.10g", v);
  return b;
}

std::string loss_name(backend::RobustLoss l) {
  return l == backend::RobustLoss::kHuber ? "huber" : l == backend::RobustLoss::kCauchy ? "cauchy" : "none";
}

// The resolved config as YAML (every key, defaults included), readable by load_vio_config.
std::string config_yaml(const VioConfig& c) {
  std::ostringstream y;
  y << "# evio vio configuration (resolved: every key with the value used)\n";
  y << "frontend: " << c.frontend << "\n";
  y << "filters:\n  refractory: {enabled: " << (c.refractory_enabled ? "true" : "false")
    << ", period_ms: " << num(ns_to_ms(c.refractory.period_ns)) << "}\n";
  y << "  background_activity: {enabled: " << (c.background_activity_enabled ? "true" : "false")
    << ", window_ms: " << num(ns_to_ms(c.background_activity.window_ns)) << ", radius: " << c.background_activity.radius
    << ", min_support: " << c.background_activity.min_support << "}\n";
  const auto& fr = c.frames;
  y << "frames: {events_per_frame: " << fr.events_per_frame << ", min_window_ms: " << num(ns_to_ms(fr.min_window_ns))
    << ", max_window_ms: " << num(ns_to_ms(fr.max_window_ns))
    << ", min_events: " << fr.min_events << ", motion_compensation: " << (fr.motion_compensation ? "true" : "false")
    << ", use_depth: " << (fr.use_depth ? "true" : "false")
    << ", clip_percentile: " << num(fr.clip_percentile) << "}\n";
  const auto& tk = c.tracker;
  y << "tracker: {grid_cols: " << tk.grid_cols << ", grid_rows: " << tk.grid_rows << ", max_features: " << tk.max_features
    << ", max_per_cell: " << tk.max_per_cell << ", fast_threshold: " << tk.fast_threshold
    << ", min_distance_px: " << tk.min_distance_px << ", klt_window_px: " << tk.klt_window_px
    << ", klt_pyramid_levels: " << tk.klt_pyramid_levels << ", forward_backward_max_px: " << num(tk.forward_backward_max_px)
    << ", ransac: " << (tk.ransac == frontend::RansacModel::kTwoPoint ? "two_point" : tk.ransac == frontend::RansacModel::kFivePoint ? "five_point" : "none")
    << ", ransac_threshold_px: " << num(tk.ransac_threshold_px) << ", min_tracks_before_detection: " << tk.min_tracks_before_detection << "}\n";
  y << "efast: {filter_sae: " << (c.efast.filter_sae ? "true" : "false")
    << ", filter_window_ms: " << num(ns_to_ms(c.efast.filter_window_ns)) << "}\n";
  const auto& t = c.corner_tracker;
  y << "corner_tracker: {max_distance_px: " << num(t.max_distance_px) << ", max_gap_ms: " << num(ns_to_ms(t.max_gap_ns))
    << ", position_gain: " << num(t.position_gain) << ", velocity_window_ms: " << num(ns_to_ms(t.velocity_window_ns))
    << ", observation_period_ms: " << num(ns_to_ms(c.observation_period_ns))
    << ", min_track_age_ms: " << num(ns_to_ms(c.min_track_age_ns)) << "}\n";
  const auto& w = c.window;
  y << "window:\n  size: " << w.window_size << "\n  max_iterations: " << w.max_iterations
    << "\n  max_solver_time_ms: " << num(w.max_solver_time_s * 1e3) << "\n  loss: " << loss_name(w.loss)
    << "\n  loss_scale: " << num(w.loss_scale) << "\n  pixel_sigma: " << num(w.pixel_sigma)
    << "\n  keyframe_min_parallax_px: " << num(w.keyframe_min_parallax_px)
    << "\n  keyframe_min_tracked_ratio: " << num(w.keyframe_min_tracked_ratio)
    << "\n  keyframe_max_interval_ms: " << num(w.keyframe_max_interval_s * 1e3)
    << "\n  min_triangulation_angle_deg: " << num(w.min_triangulation_angle_deg)
    << "\n  max_reprojection_px: " << num(w.max_reprojection_px)
    << "\n  rotation_only_parallax_px: " << num(w.rotation_only_parallax_px)
    << "\n  rotation_only_translation_px: " << num(w.rotation_only_translation_px) << "\n";
  const auto& n = c.imu_noise;
  y << "imu: {accelerometer_noise_density: " << num(n.accelerometer_noise_density)
    << ", accelerometer_random_walk: " << num(n.accelerometer_random_walk)
    << ", gyroscope_noise_density: " << num(n.gyroscope_noise_density)
    << ", gyroscope_random_walk: " << num(n.gyroscope_random_walk) << ", update_rate_hz: " << num(n.update_rate_hz) << "}\n";
  y << "init: {method: " << c.init << ", window_ms: " << num(ns_to_ms(c.init_window_ns)) << "}\n";
  return y.str();
}

}  // namespace

VioConfig default_vio_config() {
  VioConfig c;
  // IMU densities of the simulator's default (an MPU-6150-class DAVIS IMU).
  c.imu_noise.accelerometer_noise_density = 0.004;
  c.imu_noise.accelerometer_random_walk = 0.0004;
  c.imu_noise.gyroscope_noise_density = 0.00017;
  c.imu_noise.gyroscope_random_walk = 2e-5;
  c.imu_noise.update_rate_hz = 1000;
  // Frames of at least 10 ms: at high event rates (fast motion) frames hold more events instead of
  // coming faster than the tracker needs (poster_rotation at 3.2 M events/s: real-time factor
  // 1.33 -> 0.91, orientation 1.30 -> 0.87 deg rms).
  c.frames.min_window_ns = 10'000'000;
  return c;
}

VioConfig load_vio_config(const std::string& path, std::string* resolved_yaml) {
  VioConfig c = default_vio_config();
  const std::string expected = "a VIO config YAML (see README.md, `evio vio`)";
  const YAML::Node root = load_yaml_file(path, expected);
  const Parser parser(path, {});
  if (!root.IsNull()) {
    if (!root.IsMap()) parser.fail(root, "", "is not a map", expected);
    try {
      const Section top(&parser, root, "");
      top.allow({"frontend", "filters", "frames", "tracker", "efast", "corner_tracker", "window", "imu", "init", "description"});
      c.frontend = top.string("frontend", c.frontend, {"frames", "corners"});
      if (top.has("frames")) {
        const Section s = top.child("frames", false, "a map");
        s.allow({"events_per_frame", "min_window_ms", "max_window_ms", "min_events", "motion_compensation", "use_depth", "clip_percentile"});
        auto& f = c.frames;
        f.events_per_frame = s.integer("events_per_frame", f.events_per_frame, 1, 100000000);
        f.max_window_ns = ms_to_ns(s.number("max_window_ms", ns_to_ms(f.max_window_ns), Range::kPositive, "ms"));
        f.min_window_ns = ms_to_ns(s.number("min_window_ms", ns_to_ms(f.min_window_ns), Range::kNonNegative, "ms"));
        f.min_events = s.integer("min_events", f.min_events, 1, 100000000);
        f.motion_compensation = s.boolean("motion_compensation", f.motion_compensation);
        f.use_depth = s.boolean("use_depth", f.use_depth);
        f.clip_percentile = s.number("clip_percentile", f.clip_percentile, Range::kUnit, "");
        std::string why;
        if (!f.Validate(&why)) s.fail("invalid frame settings: " + why, "consistent settings");
      }
      if (top.has("tracker")) {
        const Section s = top.child("tracker", false, "a map");
        s.allow({"grid_cols", "grid_rows", "max_features", "max_per_cell", "fast_threshold", "min_distance_px",
                 "klt_window_px", "klt_pyramid_levels", "forward_backward_max_px", "ransac", "ransac_threshold_px",
                 "min_tracks_before_detection"});
        auto& t = c.tracker;
        t.grid_cols = s.integer("grid_cols", t.grid_cols, 1, 100);
        t.grid_rows = s.integer("grid_rows", t.grid_rows, 1, 100);
        t.max_features = s.integer("max_features", t.max_features, 1, 100000);
        t.max_per_cell = s.integer("max_per_cell", t.max_per_cell, 1, 100000);
        t.fast_threshold = s.integer("fast_threshold", t.fast_threshold, 1, 255);
        t.min_distance_px = s.integer("min_distance_px", t.min_distance_px, 0, 1000);
        t.klt_window_px = s.integer("klt_window_px", t.klt_window_px, 3, 255);
        t.klt_pyramid_levels = s.integer("klt_pyramid_levels", t.klt_pyramid_levels, 0, 8);
        t.forward_backward_max_px = s.number("forward_backward_max_px", t.forward_backward_max_px, Range::kPositive, "px");
        const std::string r = s.string("ransac", "two_point", {"two_point", "five_point", "none"});
        t.ransac = r == "two_point" ? frontend::RansacModel::kTwoPoint : r == "five_point" ? frontend::RansacModel::kFivePoint : frontend::RansacModel::kNone;
        t.ransac_threshold_px = s.number("ransac_threshold_px", t.ransac_threshold_px, Range::kPositive, "px");
        t.min_tracks_before_detection = s.integer("min_tracks_before_detection", t.min_tracks_before_detection, 0, 100000);
        std::string why;
        if (!t.Validate(&why)) s.fail("invalid tracker settings: " + why, "consistent settings");
      }
      if (top.has("filters")) {
        const Section f = top.child("filters", false, "a map");
        f.allow({"refractory", "background_activity"});
        if (f.has("refractory")) {
          const Section s = f.child("refractory", false, "a map");
          s.allow({"enabled", "period_ms"});
          c.refractory_enabled = s.boolean("enabled", true);
          c.refractory.period_ns = ms_to_ns(s.number("period_ms", ns_to_ms(c.refractory.period_ns), Range::kNonNegative, "ms"));
        }
        if (f.has("background_activity")) {
          const Section s = f.child("background_activity", false, "a map");
          s.allow({"enabled", "window_ms", "radius", "min_support"});
          auto& b = c.background_activity;
          c.background_activity_enabled = s.boolean("enabled", true);
          b.window_ns = ms_to_ns(s.number("window_ms", ns_to_ms(b.window_ns), Range::kPositive, "ms"));
          b.radius = s.integer("radius", b.radius, 1, 3);
          b.min_support = s.integer("min_support", b.min_support, 1, (2 * b.radius + 1) * (2 * b.radius + 1) - 1);
        }
      }
      if (top.has("efast")) {
        const Section s = top.child("efast", false, "a map");
        s.allow({"filter_sae", "filter_window_ms"});
        c.efast.filter_sae = s.boolean("filter_sae", c.efast.filter_sae);
        c.efast.filter_window_ns = ms_to_ns(s.number("filter_window_ms", ns_to_ms(c.efast.filter_window_ns), Range::kNonNegative, "ms"));
      }
      if (top.has("corner_tracker")) {
        const Section s = top.child("corner_tracker", false, "a map");
        s.allow({"max_distance_px", "max_gap_ms", "position_gain", "velocity_window_ms", "observation_period_ms",
                 "min_track_age_ms"});
        auto& t = c.corner_tracker;
        t.max_distance_px = s.number("max_distance_px", t.max_distance_px, Range::kPositive, "px");
        t.max_gap_ns = ms_to_ns(s.number("max_gap_ms", ns_to_ms(t.max_gap_ns), Range::kPositive, "ms"));
        t.position_gain = s.number("position_gain", t.position_gain, Range::kUnit, "");
        t.velocity_window_ns = ms_to_ns(s.number("velocity_window_ms", ns_to_ms(t.velocity_window_ns), Range::kPositive, "ms"));
        c.observation_period_ns = ms_to_ns(s.number("observation_period_ms", ns_to_ms(c.observation_period_ns), Range::kPositive, "ms"));
        c.min_track_age_ns = ms_to_ns(s.number("min_track_age_ms", ns_to_ms(c.min_track_age_ns), Range::kNonNegative, "ms"));
        std::string why;
        if (!t.Validate(&why)) s.fail("invalid corner tracker settings: " + why, "consistent settings");
      }
      if (top.has("window")) {
        const Section s = top.child("window", false, "a map");
        s.allow({"size", "max_iterations", "max_solver_time_ms", "loss", "loss_scale", "pixel_sigma",
                 "keyframe_min_parallax_px", "keyframe_min_tracked_ratio", "keyframe_max_interval_ms",
                 "min_triangulation_angle_deg", "max_reprojection_px", "rotation_only_parallax_px",
                 "rotation_only_translation_px"});
        auto& w = c.window;
        w.window_size = s.integer("size", w.window_size, 2, 200);
        w.max_iterations = s.integer("max_iterations", w.max_iterations, 1, 1000);
        w.max_solver_time_s = 1e-3 * s.number("max_solver_time_ms", w.max_solver_time_s * 1e3, Range::kNonNegative, "ms");
        const std::string loss = s.string("loss", loss_name(w.loss), {"huber", "cauchy", "none"});
        w.loss = loss == "huber" ? backend::RobustLoss::kHuber : loss == "cauchy" ? backend::RobustLoss::kCauchy : backend::RobustLoss::kNone;
        w.loss_scale = s.number("loss_scale", w.loss_scale, Range::kPositive, "pixel sigmas");
        w.pixel_sigma = s.number("pixel_sigma", w.pixel_sigma, Range::kPositive, "px");
        w.keyframe_min_parallax_px = s.number("keyframe_min_parallax_px", w.keyframe_min_parallax_px, Range::kPositive, "px");
        w.keyframe_min_tracked_ratio = s.number("keyframe_min_tracked_ratio", w.keyframe_min_tracked_ratio, Range::kUnit, "");
        w.keyframe_max_interval_s = 1e-3 * s.number("keyframe_max_interval_ms", w.keyframe_max_interval_s * 1e3, Range::kPositive, "ms");
        w.min_triangulation_angle_deg = s.number("min_triangulation_angle_deg", w.min_triangulation_angle_deg, Range::kNonNegative, "deg");
        w.max_reprojection_px = s.number("max_reprojection_px", w.max_reprojection_px, Range::kPositive, "px");
        w.rotation_only_parallax_px = s.number("rotation_only_parallax_px", w.rotation_only_parallax_px, Range::kNonNegative, "px");
        w.rotation_only_translation_px = s.number("rotation_only_translation_px", w.rotation_only_translation_px, Range::kPositive, "px");
        std::string why;
        if (!w.Validate(&why)) s.fail("invalid window settings: " + why, "consistent settings");
      }
      if (top.has("imu")) {
        const Section s = top.child("imu", false, "a map");
        s.allow({"accelerometer_noise_density", "accelerometer_random_walk", "gyroscope_noise_density",
                 "gyroscope_random_walk", "update_rate_hz"});
        auto& n = c.imu_noise;
        n.accelerometer_noise_density = s.number("accelerometer_noise_density", n.accelerometer_noise_density, Range::kPositive, "m/s^2/sqrt(Hz)");
        n.accelerometer_random_walk = s.number("accelerometer_random_walk", n.accelerometer_random_walk, Range::kPositive, "m/s^3/sqrt(Hz)");
        n.gyroscope_noise_density = s.number("gyroscope_noise_density", n.gyroscope_noise_density, Range::kPositive, "rad/s/sqrt(Hz)");
        n.gyroscope_random_walk = s.number("gyroscope_random_walk", n.gyroscope_random_walk, Range::kPositive, "rad/s^2/sqrt(Hz)");
        n.update_rate_hz = s.number("update_rate_hz", n.update_rate_hz, Range::kPositive, "Hz");
      }
      if (top.has("init")) {
        const Section s = top.child("init", false, "a map");
        s.allow({"method", "window_ms"});
        c.init = s.string("method", c.init, {"auto", "static", "alignment", "groundtruth"});
        c.init_window_ns = ms_to_ns(s.number("window_ms", ns_to_ms(c.init_window_ns), Range::kPositive, "ms"));
      }
    } catch (const YAML::Exception& e) {
      throw InputError(path, static_cast<int64_t>(e.mark.line) + 1, "YAML error: " + e.msg, expected);
    }
  }
  if (resolved_yaml) *resolved_yaml = config_yaml(c);
  return c;
}

namespace {

void write_tum(const std::string& path, const std::vector<VioState>& states) {
  std::ofstream f(path);
  if (!f) throw InputError(path, 0, "cannot create the file", "a writable output folder");
  f << "# t[s] x y z qx qy qz qw  (body/IMU pose T_w_b, world gravity along -z)\n";
  char line[256];
  for (const VioState& s : states) {
    const Eigen::Quaterniond& q = s.T_w_b.rotation;
    const Eigen::Vector3d& p = s.T_w_b.translation;
    std::snprintf(line, sizeof(line), "%s %.9f %.9f %.9f %.9f %.9f %.9f %.9f\n", format_seconds(s.t_ns).c_str(), p.x(),
                  p.y(), p.z(), q.x(), q.y(), q.z(), q.w());
    f << line;
  }
  if (!f) throw InputError(path, 0, "write failed (disk full?)", "a writable output folder");
}

struct Segment {
  int64_t t_begin_ns, t_end_ns;
  std::string what;
};

}  // namespace

int run_vio(const VioArgs& args, std::ostream& out) {
  std::string resolved;
  VioConfig cfg = default_vio_config();
  if (!args.config.empty()) {
    cfg = load_vio_config(args.config, &resolved);
  } else {
    resolved = config_yaml(cfg);
  }
  auto reader = open_dataset(args.dataset, args.dataset_options);
  // Calibration: --calib, else the dataset folder's calib.yaml (camchain + imu0), else the reader's.
  const DatasetCalibration found = find_dataset_calibration(args.dataset, args.calib, *reader);
  std::optional<calib::CameraCalibration> cal = found.camera;
  calib::ImuNoise noise = cfg.imu_noise;
  std::string noise_source = args.config.empty() ? "defaults" : args.config;
  if (!found.kalibr_yaml.empty()) {
    try {
      noise = calib::load_kalibr_imu(found.kalibr_yaml);
      noise_source = found.kalibr_yaml;
    } catch (const InputError&) {
      // no imu0 section: keep the config's densities
    }
  }
  if (!cal) throw InputError(args.dataset, 0, "no camera calibration", "--calib FILE (Kalibr camchain YAML or ECD calib.txt)");
  if (!cal->has_T_c_b) log_warning("camera-IMU extrinsics unknown: T_c_b = identity");
  const int W = cal->camera.width(), H = cal->camera.height();
  std::vector<ImuSample> imu = reader->read_imu();
  if (imu.size() < 10) throw InputError(args.dataset, 0, "the dataset has no IMU samples", "a recording with IMU");
  fs::create_directories(args.out);
  {
    std::ofstream f((fs::path(args.out) / "vio_config.yaml").string());
    f << resolved;
  }

  // Front-end (corners): undistortion validity, filters, eFAST, corner tracker.
  const frontend::EventUndistorter undistorter(cal->camera);
  frontend::RefractoryFilter refractory(W, H, cfg.refractory);
  frontend::BackgroundActivityFilter background(W, H, cfg.background_activity);
  frontend::EfastDetector detector(W, H, cfg.efast);
  frontend::CornerTracker tracker(W, H, cfg.corner_tracker);
  const int64_t shift = cal->time_shift_ns;  // t_imu = t_cam + shift
  const bool use_frames = cfg.frontend == "frames";
  std::unique_ptr<frontend::EventFrameBuilder> frame_builder;
  std::unique_ptr<frontend::FeatureTracker> frame_tracker;
  if (use_frames) {
    frame_builder = std::make_unique<frontend::EventFrameBuilder>(*cal, cfg.frames);
    for (const ImuSample& m : imu) frame_builder->add_imu(m);
    calib::CameraIntrinsics ideal = cal->camera.intrinsics();
    ideal.model = calib::DistortionModel::kNone;
    ideal.distortion.clear();
    frame_tracker = std::make_unique<frontend::FeatureTracker>(ideal, cfg.tracker);
  }
  std::vector<Event> filtered;
  std::vector<frontend::EventFrame> built;
  int64_t prev_frame_t = -1;

  std::optional<Trajectory> gt_traj;
  if (cfg.init == "groundtruth") {
    if (args.gt.empty()) throw InputError(args.config, 0, "init.method groundtruth needs --gt", "--gt GT.tum, or another init.method");
    gt_traj = load_trajectory(args.gt);
  }
  std::unique_ptr<backend::SlidingWindowEstimator> est;
  std::vector<FeatureObservations> pending;  // frames before initialisation
  std::vector<VioState> trajectory;
  std::map<int64_t, Eigen::Vector3d> map_points;
  std::vector<Segment> lost;
  bool in_gap = false;
  std::string init_method;
  int64_t init_t = 0;
  size_t next_imu = 0;
  int64_t frame_id = 0;
  int64_t few_since = -1;

  auto feed = [&](const FeatureObservations& f) {
    while (next_imu < imu.size() && imu[next_imu].t_ns <= f.t_ns + 10'000'000) est->add_imu(imu[next_imu++]);
    const bool kf = est->add_frame(f);
    // One pose per new state time (a frame the estimator skipped adds none).
    const VioState& ls = est->latest_state();
    if (trajectory.empty() || ls.t_ns > trajectory.back().t_ns) trajectory.push_back(ls);
    if (kf) {
      for (const auto& [id, p] : est->landmarks()) map_points[id] = p;
    }
  };
  auto try_init = [&](bool final_attempt) {
    if (pending.empty()) return;
    const int64_t span = pending.back().t_ns - pending.front().t_ns;
    if (span < cfg.init_window_ns && !final_attempt) return;
    std::optional<VioState> s;
    std::string why;
    if (cfg.init == "groundtruth") {
      // Diagnostic: pose and velocity (central difference over 10 ms) from --gt at the first frame.
      const int64_t t0 = pending.front().t_ns;
      const auto a = gt_traj->interpolate(t0 - 5'000'000), b = gt_traj->interpolate(t0 + 5'000'000), c = gt_traj->interpolate(t0);
      if (a && b && c) {
        s = VioState{};
        s->t_ns = t0;
        s->T_w_b = *c;
        s->v_w = (b->translation - a->translation) / 0.01;
        init_method = "ground truth (diagnostic)";
      } else {
        why = "ground truth does not cover " + format_seconds(t0) + " s";
      }
    }
    if (cfg.init == "auto" || cfg.init == "static") {
      s = backend::static_initialization(imu, pending.front().t_ns, noise, cfg.static_init, &why);
      if (s) init_method = "static";
    }
    if (!s && (cfg.init == "auto" || cfg.init == "alignment")) {
      std::vector<FeatureObservations> window;
      for (const auto& f : pending)
        if (f.t_ns - pending.front().t_ns <= cfg.init_window_ns) window.push_back(f);
      s = backend::visual_inertial_initialization(window, imu, *cal, noise, Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(),
                                                  cfg.vi_init, &why);
      if (s) init_method = "visual-inertial alignment";
    }
    if (!s) {
      log_debug("initialisation at " + format_seconds(pending.front().t_ns) + " s failed: " + why);
      // Slide by a quarter of the window and retry with the next frames.
      const int64_t drop_until = pending.front().t_ns + cfg.init_window_ns / 4;
      pending.erase(pending.begin(), std::find_if(pending.begin(), pending.end(), [&](const auto& f) { return f.t_ns > drop_until; }));
      return;
    }
    init_t = s->t_ns;
    log_info("initialised at " + format_seconds(init_t) + " s by " + init_method);
    est = std::make_unique<backend::SlidingWindowEstimator>(cfg.window, *cal, noise);
    est->initialize(*s);
    while (next_imu < imu.size() && imu[next_imu].t_ns < s->t_ns - 50'000'000) ++next_imu;
    for (const auto& f : pending)
      if (f.t_ns >= s->t_ns) feed(f);
    pending.clear();
  };
  std::ofstream obs_file((fs::path(args.out) / "observations.txt").string());
  obs_file << "# t[s] track_id bx by bz  (front-end observations: unit bearings in the camera frame, body clock)\n";
  auto handle_frame = [&](FeatureObservations f) {
    for (const auto& o : f.observations) {
      char line[160];
      std::snprintf(line, sizeof(line), "%s %lld %.7f %.7f %.7f\n", format_seconds(f.t_ns).c_str(),
                    static_cast<long long>(o.track_id), o.bearing_c.x(), o.bearing_c.y(), o.bearing_c.z());
      obs_file << line;
    }
    // Tracking-lost segments: fewer than 5 observed tracks.
    if (in_gap) {
      // counted as the event-rate drop
    } else if (f.observations.size() < 5) {
      if (few_since < 0) few_since = f.t_ns;
    } else if (few_since >= 0) {
      if (f.t_ns - few_since >= 500'000'000) lost.push_back({few_since, f.t_ns, "fewer than 5 tracks"});
      few_since = -1;
    }
    if (est) {
      feed(f);
    } else {
      pending.push_back(std::move(f));
      try_init(false);
    }
  };
  // Corners front-end: the active corner tracks sampled at t_cam.
  auto emit_frame = [&](int64_t t_cam) {
    FeatureObservations f;
    f.t_ns = t_cam + shift;
    f.frame_id = frame_id++;
    tracker.predict_active(t_cam, cfg.observation_period_ns, cfg.min_track_age_ns, [&](int64_t id, const Eigen::Vector2d& px) {
      Eigen::Vector3d b;
      if (px.allFinite() && cal->camera.unproject(px, &b) && b.z() > 1e-3) f.observations.push_back({id, b});
    });
    handle_frame(std::move(f));
  };
  // Frames front-end: one observation frame per event frame, tracked with the IMU rotation prior.
  auto track_event_frame = [&](const frontend::EventFrame& ef) {
    // An event-rate drop: no frames for a while. Empty frames every max_window keep the IMU
    // propagation (and the trajectory) going; the gap is flagged.
    if (prev_frame_t >= 0 && ef.t_ns - prev_frame_t > 2 * cfg.frames.max_window_ns) {
      lost.push_back({prev_frame_t + shift, ef.t_ns + shift, "no event frames (event-rate drop)"});
      in_gap = true;  // these frames are the flagged gap, not a tracking loss
      for (int64_t t = prev_frame_t + cfg.frames.max_window_ns; t < ef.t_ns; t += cfg.frames.max_window_ns) {
        FeatureObservations empty;
        empty.t_ns = t + shift;
        empty.frame_id = frame_id++;
        handle_frame(std::move(empty));
      }
      in_gap = false;
    }
    Eigen::Matrix3d R_cur_prev = Eigen::Matrix3d::Identity();
    bool have_prior = false;
    const Eigen::Vector3d bg = est ? est->latest_state().bias_gyro : Eigen::Vector3d::Zero();
    if (prev_frame_t >= 0) {
      try {
        const auto pre = backend::ImuPreintegration::between(imu, prev_frame_t + shift, ef.t_ns + shift, bg, Eigen::Vector3d::Zero(), noise);
        const Eigen::Matrix3d R_c_b = cal->T_c_b.rotation.toRotationMatrix();
        R_cur_prev = R_c_b * pre.delta_R().transpose() * R_c_b.transpose();
        have_prior = true;
      } catch (const std::invalid_argument&) {
        // no IMU around the frame: track without the rotation prior
      }
    }
    prev_frame_t = ef.t_ns;
    FeatureObservations f = frame_tracker->track(ef.t_ns + shift, ef.image, have_prior ? &R_cur_prev : nullptr);
    f.frame_id = frame_id++;
    if (est) {
      const VioState st = est->latest_state();
      frame_builder->set_gyro_bias(st.bias_gyro);
      if (cfg.frames.use_depth) {
        // Camera velocity and the median landmark depth for translation compensation.
        const calib::SE3 T_c_w = cal->T_c_b * st.T_w_b.inverse();
        std::vector<double> depth;
        for (const auto& [id, p] : est->landmarks()) {
          const double z = (T_c_w.rotation * p + T_c_w.translation).z();
          if (z > 0) depth.push_back(z);
        }
        if (!depth.empty()) {
          std::nth_element(depth.begin(), depth.begin() + static_cast<long>(depth.size() / 2), depth.end());
          const Eigen::Vector3d v_c = cal->T_c_b.rotation * (st.T_w_b.rotation.conjugate() * st.v_w);
          frame_builder->set_motion(v_c, depth[depth.size() / 2]);
        }
      }
    }
    handle_frame(std::move(f));
  };

  Progress progress("evio vio", args.progress, "events");
  EventBuffer chunk;
  int64_t events = 0, corners = 0;
  int64_t t_first = 0, t_last = 0, next_obs = 0;
  bool first = true;
  const auto wall0 = std::chrono::steady_clock::now();
  for (;;) {
    chunk.clear();
    if (reader->read_events(&chunk, size_t{1} << 18) == 0) break;
    filtered.clear();
    for (const Event& e : chunk.span()) {
      if (first) {
        t_first = e.t_ns;
        next_obs = t_first + cfg.observation_period_ns;
        first = false;
      }
      if (!use_frames) {
        while (e.t_ns >= next_obs) {
          emit_frame(next_obs);
          next_obs += cfg.observation_period_ns;
        }
      }
      t_last = e.t_ns;
      ++events;
      if (e.x >= W || e.y >= H || !undistorter.valid(e.x, e.y)) continue;
      if (cfg.refractory_enabled && !refractory.accept(e)) continue;
      if (cfg.background_activity_enabled && !background.accept(e)) continue;
      if (use_frames) {
        filtered.push_back(e);
        continue;
      }
      if (!detector.process(e)) continue;
      ++corners;
      tracker.add(e);
    }
    if (use_frames) {
      built.clear();
      frame_builder->add_events(EventSpan(filtered.data(), filtered.size()), &built);
      for (const auto& ef : built) track_event_frame(ef);
    }
    const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
    const double seq = static_cast<double>(t_last - t_first) * 1e-9;
    progress.update(reader->progress(), events, "real-time factor " + num(seq > 0 ? elapsed / seq : 0.0));
  }
  // Event-rate drops at the end: frames up to the last IMU sample keep the state propagating.
  if (use_frames) {
    built.clear();
    frame_builder->flush(&built);
    for (const auto& ef : built) track_event_frame(ef);
  }
  const int64_t t_end_cam = std::min(imu.back().t_ns - shift, t_last);
  while (!use_frames && !first && next_obs <= t_end_cam) {
    emit_frame(next_obs);
    next_obs += cfg.observation_period_ns;
  }
  if (!est) try_init(true);
  if (few_since >= 0 && t_last + shift - few_since >= 500'000'000) lost.push_back({few_since, t_last + shift, "fewer than 5 tracks"});
  const double processing_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  const double duration_s = static_cast<double>(t_last - t_first) * 1e-9;
  if (!est) {
    throw InputError(args.dataset, 0, "could not initialise (no still start and the visual-inertial alignment failed)",
                     "a recording that starts still or moves with enough features in the first seconds");
  }

  // Outputs.
  write_tum((fs::path(args.out) / "trajectory.tum").string(), trajectory);
  {
    std::ofstream f((fs::path(args.out) / "keyframes.txt").string());
    f << "# t[s] x y z qx qy qz qw vx vy vz bgx bgy bgz bax bay baz  (T_w_b, v_w m/s, biases rad/s and m/s^2)\n";
    for (const VioState& s : est->keyframe_states()) {
      char line[512];
      const Eigen::Quaterniond& q = s.T_w_b.rotation;
      std::snprintf(line, sizeof(line), "%s %.9f %.9f %.9f %.9f %.9f %.9f %.9f %.6f %.6f %.6f %.7f %.7f %.7f %.6f %.6f %.6f\n",
                    format_seconds(s.t_ns).c_str(), s.T_w_b.translation.x(), s.T_w_b.translation.y(), s.T_w_b.translation.z(),
                    q.x(), q.y(), q.z(), q.w(), s.v_w.x(), s.v_w.y(), s.v_w.z(), s.bias_gyro.x(), s.bias_gyro.y(),
                    s.bias_gyro.z(), s.bias_accel.x(), s.bias_accel.y(), s.bias_accel.z());
      f << line;
    }
  }
  std::vector<mapping::MapPoint> pts;
  for (const auto& [id, p] : map_points) pts.push_back({p, static_cast<float>(id)});
  mapping::write_landmark_map((fs::path(args.out) / "map.ply").string(), pts);

  // Motion-model segments from the keyframes' models.
  std::vector<Segment> models;
  for (const auto& [t, rot] : est->stats().motion_model) {
    const std::string m = rot ? "rotation_only" : "6dof";
    if (models.empty() || models.back().what != m) {
      models.push_back({t, t, m});
    } else {
      models.back().t_end_ns = t;
    }
  }
  const auto& st = est->stats();
  std::vector<double> solve = st.solve_time_s;
  std::sort(solve.begin(), solve.end());
  const double med = solve.empty() ? 0 : solve[solve.size() / 2];
  std::ostringstream j;
  j << "{\n  \"dataset\": \"" << json_escape(args.dataset) << "\",\n  \"frontend\": \"" << cfg.frontend << "\",\n  \"events\": " << events
    << ",\n  \"corners\": " << corners << ",\n  \"frames\": " << st.frames << ",\n  \"keyframes\": " << st.keyframes
    << ",\n  \"landmarks\": " << pts.size() << ",\n  \"processing_time_s\": " << num(processing_s)
    << ",\n  \"sequence_duration_s\": " << num(duration_s) << ",\n  \"real_time_factor\": "
    << num(duration_s > 0 ? processing_s / duration_s : 0.0) << ",\n  \"solve_ms_median\": " << num(1e3 * med)
    << ",\n  \"initialisation\": {\"method\": \"" << init_method << "\", \"t\": " << format_seconds(init_t)
    << "},\n  \"imu_noise_from\": \"" << json_escape(noise_source) << "\",\n  \"motion_model_segments\": [";
  for (size_t i = 0; i < models.size(); ++i) {
    j << (i ? ", " : "") << "{\"t_begin\": " << format_seconds(models[i].t_begin_ns) << ", \"t_end\": "
      << format_seconds(models[i].t_end_ns) << ", \"model\": \"" << models[i].what << "\"}";
  }
  j << "],\n  \"tracking_lost_segments\": [";
  for (size_t i = 0; i < lost.size(); ++i) {
    j << (i ? ", " : "") << "{\"t_begin\": " << format_seconds(lost[i].t_begin_ns) << ", \"t_end\": "
      << format_seconds(lost[i].t_end_ns) << ", \"reason\": \"" << lost[i].what << "\"}";
  }
  j << "],\n  \"frontend_stats\": {";
  if (use_frames) {
    const auto& ts = frame_tracker->stats();
    const auto& fs_ = frame_builder->stats();
    j << "\"event_frames\": " << fs_.frames_emitted << ", \"frames_uncompensated\": " << fs_.frames_uncompensated
      << ", \"frames_dropped_sparse\": " << fs_.frames_dropped_sparse << ", \"tracks_detected\": " << ts.detected
      << ", \"tracked\": " << ts.tracked << ", \"lost_klt\": " << ts.lost_klt << ", \"lost_forward_backward\": " << ts.lost_fb
      << ", \"rejected_ransac\": " << ts.rejected_ransac;
  } else {
    j << "\"corner_events\": " << corners << ", \"corner_tracks_started\": " << tracker.stats().tracks_started;
  }
  j << "},\n  \"outliers_removed\": " << st.outliers_removed << ",\n  \"rotation_only_keyframes\": " << st.rotation_only_keyframes
    << "\n}\n";
  {
    std::ofstream f((fs::path(args.out) / "stats.json").string());
    f << j.str();
  }
  char buf[512];
  std::snprintf(buf, sizeof(buf),
                "events        %lld over %.2f s, %lld corner events, %lld frames, %lld keyframes, %zu landmarks\n"
                "initialised   at %s s by %s\n"
                "speed         %.2f s processing, real-time factor %.3f (one core), solve %.1f ms median\n",
                static_cast<long long>(events), duration_s, static_cast<long long>(corners), static_cast<long long>(st.frames),
                static_cast<long long>(st.keyframes), pts.size(), format_seconds(init_t).c_str(), init_method.c_str(),
                processing_s, duration_s > 0 ? processing_s / duration_s : 0.0, 1e3 * med);
  out << buf;
  out << "motion model  ";
  for (const auto& m : models) out << m.what << " " << format_seconds(m.t_begin_ns) << ".." << format_seconds(m.t_end_ns) << "  ";
  out << "\n";
  if (!lost.empty()) out << "tracking lost " << lost.size() << " segment(s), see stats.json\n";
  if (!args.gt.empty()) {
    EvalArgs ea;
    ea.groundtruth = args.gt;
    ea.estimates = {(fs::path(args.out) / "trajectory.tum").string()};
    ea.options.alignment.method = evaluation::Alignment::kSE3;
    ea.options.alignment.first_s = 5.0;
    const auto results = evaluate_all(ea);
    std::ofstream f((fs::path(args.out) / "eval.json").string());
    f << results_json(ea, results);
    const auto& r = results.front().result;
    std::snprintf(buf, sizeof(buf),
                  "evaluation    ATE rmse %.4f m, mean position error %.3f%% of %.2f m, final yaw error %.2f deg, yaw drift "
                  "%.4f deg/m (SE3 on the first 5 s)\n",
                  r.ate.trans_m.rmse, r.mean_position_error_percent, r.groundtruth_length_m, r.final_yaw_error_deg,
                  r.yaw_drift_deg_per_m);
    out << buf;
  }
  out << "wrote " << args.out << "/trajectory.tum, keyframes.txt, map.ply, observations.txt, stats.json, vio_config.yaml"
      << (args.gt.empty() ? "" : ", eval.json") << "\n";
  return 0;
}

}  // namespace evio::apps
