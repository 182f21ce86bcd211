#include "vio_command.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <ostream>
#include <sstream>

#include <opencv2/core/utility.hpp>
#include <yaml-cpp/yaml.h>

#include "eval_command.h"
#include "evio/backend/motion_model_selection.h"
#include "evio/calib/calibration_io.h"
#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio/evaluation/track_oracle.h"
#include "evio/mapping/landmark_map.h"
#include "evio/sensors/ecd.h"
#include "evio/sensors/time.h"
#include "json_util.h"
#include "dataset_calibration.h"
#include "progress.h"
#include "evio/simulator/scene_config.h"
#include "evio/sensors/yaml_config.h"

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

// YAML names of the pipeline's choices: init.method `groundtruth` is the pipeline's `given`.
const char* init_name(pipeline::VioInitMethod m) {
  return m == pipeline::VioInitMethod::kGiven ? "groundtruth" : pipeline::to_string(m);
}

std::string loss_name(backend::RobustLoss l) {
  return l == backend::RobustLoss::kHuber ? "huber" : l == backend::RobustLoss::kCauchy ? "cauchy" : "none";
}

std::string tracked_landmark_name(backend::TrackedLandmarkMarginalisation m) {
  return m == backend::TrackedLandmarkMarginalisation::kDoubleCount ? "double_count"
         : m == backend::TrackedLandmarkMarginalisation::kRestart   ? "restart"
         : m == backend::TrackedLandmarkMarginalisation::kSplit     ? "split"
                                                                     : "drop";
}

// One feature-tracker section (tracker, aps_tracker) of the resolved config.
std::string tracker_yaml(const char* key, const frontend::FeatureTrackerOptions& tk) {
  std::ostringstream y;
  y << key << ": {grid_cols: " << tk.grid_cols << ", grid_rows: " << tk.grid_rows << ", max_features: " << tk.max_features
    << ", max_per_cell: " << tk.max_per_cell << ", fast_threshold: " << tk.fast_threshold
    << ", min_distance_px: " << tk.min_distance_px << ", klt_window_px: " << tk.klt_window_px
    << ", klt_pyramid_levels: " << tk.klt_pyramid_levels << ", klt_max_iterations: " << tk.klt_max_iterations
    << ", klt_epsilon_px: " << num(tk.klt_epsilon_px) << ", forward_backward_max_px: " << num(tk.forward_backward_max_px)
    << ", template_max_age_frames: " << tk.template_max_age_frames
    << ", template_fallback: " << (tk.template_fallback ? "true" : "false")
    << ", template_max_rotation_deg: " << num(tk.template_max_rotation_deg)
    << ", anchor_frames: " << tk.anchor_frames << ", anchor_ransac_threshold_px: " << num(tk.anchor_ransac_threshold_px)
    << ", ransac: " << frontend::ransac_model_name(tk.ransac)
    << ", ransac_threshold_px: " << num(tk.ransac_threshold_px) << ", min_tracks_before_detection: " << tk.min_tracks_before_detection
    << ", seed: " << tk.seed << "}\n";
  return y.str();
}

// Reads a feature-tracker section over *t; fails with file:line on invalid settings.
void parse_tracker(const Section& s, frontend::FeatureTrackerOptions* t) {
  s.allow({"grid_cols", "grid_rows", "max_features", "max_per_cell", "fast_threshold", "min_distance_px",
           "klt_window_px", "klt_pyramid_levels", "klt_max_iterations", "klt_epsilon_px", "forward_backward_max_px", "ransac",
           "ransac_threshold_px", "min_tracks_before_detection", "template_max_age_frames", "template_fallback", "template_max_rotation_deg", "anchor_frames",
           "anchor_ransac_threshold_px", "seed"});
  t->grid_cols = s.integer("grid_cols", t->grid_cols, 1, 100);
  t->grid_rows = s.integer("grid_rows", t->grid_rows, 1, 100);
  t->max_features = s.integer("max_features", t->max_features, 1, 100000);
  t->max_per_cell = s.integer("max_per_cell", t->max_per_cell, 1, 100000);
  t->fast_threshold = s.integer("fast_threshold", t->fast_threshold, 1, 255);
  t->min_distance_px = s.integer("min_distance_px", t->min_distance_px, 0, 1000);
  t->klt_window_px = s.integer("klt_window_px", t->klt_window_px, 3, 255);
  t->klt_pyramid_levels = s.integer("klt_pyramid_levels", t->klt_pyramid_levels, 0, 8);
  t->klt_max_iterations = s.integer("klt_max_iterations", t->klt_max_iterations, 1, 1000);
  t->klt_epsilon_px = s.number("klt_epsilon_px", t->klt_epsilon_px, Range::kPositive, "px");
  t->forward_backward_max_px = s.number("forward_backward_max_px", t->forward_backward_max_px, Range::kPositive, "px");
  t->template_max_age_frames = s.integer("template_max_age_frames", t->template_max_age_frames, 1, 100000);
  t->template_fallback = s.boolean("template_fallback", t->template_fallback);
  t->template_max_rotation_deg = s.number("template_max_rotation_deg", t->template_max_rotation_deg, Range::kNonNegative, "deg");
  t->anchor_frames = s.integer("anchor_frames", t->anchor_frames, 0, 100000);
  t->anchor_ransac_threshold_px = s.number("anchor_ransac_threshold_px", t->anchor_ransac_threshold_px, Range::kPositive, "px");
  const std::string r = s.string("ransac", frontend::ransac_model_name(t->ransac), {"two_point", "five_point", "none"});
  t->ransac = r == "two_point" ? frontend::RansacModel::kTwoPoint : r == "five_point" ? frontend::RansacModel::kFivePoint : frontend::RansacModel::kNone;
  t->ransac_threshold_px = s.number("ransac_threshold_px", t->ransac_threshold_px, Range::kPositive, "px");
  t->min_tracks_before_detection = s.integer("min_tracks_before_detection", t->min_tracks_before_detection, 0, 100000);
  t->seed = static_cast<uint64_t>(s.integer("seed", static_cast<int>(t->seed), 0, 1 << 30));
  std::string why;
  if (!t->Validate(&why)) s.fail("invalid tracker settings: " + why, "consistent settings");
}

// The resolved config as YAML (every key, defaults included), readable by load_vio_config.
std::string config_yaml(const VioConfig& c) {
  std::ostringstream y;
  y << "# evio vio configuration (resolved: every key with the value used)\n";
  y << "inputs: " << pipeline::to_string(c.inputs) << "\n";
  y << "frontend: " << pipeline::to_string(c.frontend) << "\n";
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
    << ", velocity_at_reference: " << (c.frame_velocity_at_reference ? "true" : "false")
    << ", event_lag_px: " << num(fr.event_lag_px)
    << ", clip_percentile: " << num(fr.clip_percentile) << ", clip_count: " << num(fr.clip_count)
    << ", overlap: " << num(fr.overlap) << "}\n";
  y << tracker_yaml("tracker", c.tracker);
  y << tracker_yaml("aps_tracker", c.aps_tracker);
  y << "aps: {pixel_sigma: " << num(c.aps_pixel_sigma_px) << ", event_pixel_sigma: " << num(c.aps_event_pixel_sigma_px)
    << ", max_gap_ms: " << num(ns_to_ms(c.aps_max_gap_ns)) << "}\n";
  y << "efast: {filter_sae: " << (c.efast.filter_sae ? "true" : "false")
    << ", filter_window_ms: " << num(ns_to_ms(c.efast.filter_window_ns)) << "}\n";
  const auto& t = c.corner_tracker;
  y << "corner_tracker: {max_distance_px: " << num(t.max_distance_px) << ", max_gap_ms: " << num(ns_to_ms(t.max_gap_ns))
    << ", position_gain: " << num(t.position_gain) << ", velocity_window_ms: " << num(ns_to_ms(t.velocity_window_ns))
    << ", observation_period_ms: " << num(ns_to_ms(c.observation_period_ns))
    << ", min_track_age_ms: " << num(ns_to_ms(c.min_track_age_ns)) << "}\n";
  const auto& w = c.window;
  y << "window:\n  size: " << w.window_size << "\n  max_iterations: " << w.max_iterations
    << "\n  function_tolerance: " << num(w.function_tolerance)
    << "\n  max_solver_time_ms: " << num(w.max_solver_time_s * 1e3) << "\n  loss: " << loss_name(w.loss)
    << "\n  loss_scale: " << num(w.loss_scale) << "\n  pixel_sigma: " << num(w.pixel_sigma)
    << "\n  keyframe_min_parallax_px: " << num(w.keyframe_min_parallax_px)
    << "\n  keyframe_min_tracked_ratio: " << num(w.keyframe_min_tracked_ratio)
    << "\n  keyframe_max_interval_ms: " << num(w.keyframe_max_interval_s * 1e3)
    << "\n  min_triangulation_angle_deg: " << num(w.min_triangulation_angle_deg)
    << "\n  max_reprojection_px: " << num(w.max_reprojection_px)
    << "\n  tracked_landmark_marginalisation: " << tracked_landmark_name(w.tracked_landmark_marginalisation)
    << "\n  rotation_only_parallax_px: " << num(w.rotation_only_parallax_px)
    << "\n  rotation_only_translation_px: " << num(w.rotation_only_translation_px)
    << "\n  rotation_only_min_duration_ms: " << num(w.rotation_only_min_duration_s * 1e3)
    << "\n  init_bias_gyro_turn_on_radps: " << num(w.init_bias_gyro_turn_on_radps)
    << "\n  init_bias_accel_turn_on_mps2: " << num(w.init_bias_accel_turn_on_mps2)
    << "\n  init_bias_horizon_s: " << num(w.init_bias_horizon_s)
    << "\n  estimate_time_offset: " << (w.estimate_time_offset ? "true" : "false")
    << "\n  time_offset_sigma_ms: " << num(w.time_offset_sigma_s * 1e3) << "\n";
  const auto& n = c.imu_noise;
  y << "imu: {accelerometer_noise_density: " << num(n.accelerometer_noise_density)
    << ", accelerometer_random_walk: " << num(n.accelerometer_random_walk)
    << ", gyroscope_noise_density: " << num(n.gyroscope_noise_density)
    << ", gyroscope_random_walk: " << num(n.gyroscope_random_walk) << ", update_rate_hz: " << num(n.update_rate_hz) << "}\n";
  y << "init: {method: " << init_name(c.init) << ", window_ms: " << num(ns_to_ms(c.init_window_ns)) << "}\n";
  return y.str();
}

}  // namespace

VioConfig default_vio_config() { return VioConfig{}; }

VioConfig load_vio_config(const std::string& path, std::string* resolved_yaml) {
  VioConfig c = default_vio_config();
  const std::string expected = "a VIO config YAML (see README.md, `evio vio`)";
  const YAML::Node root = load_yaml_file(path, expected);
  const Parser parser(path, {});
  if (!root.IsNull()) {
    if (!root.IsMap()) parser.fail(root, "", "is not a map", expected);
    try {
      const Section top(&parser, root, "");
      top.allow({"inputs", "frontend", "filters", "frames", "tracker", "aps_tracker", "aps", "efast", "corner_tracker", "window",
                 "imu", "init", "description"});
      const std::string in = top.string("inputs", pipeline::to_string(c.inputs), {"events", "aps", "events+aps"});
      c.inputs = in == "aps" ? pipeline::VioInputs::kAps : in == "events+aps" ? pipeline::VioInputs::kEventsAndAps : pipeline::VioInputs::kEvents;
      c.frontend = top.string("frontend", pipeline::to_string(c.frontend), {"frames", "corners"}) == "corners"
                       ? pipeline::VioFrontEnd::kCorners
                       : pipeline::VioFrontEnd::kFrames;
      if (top.has("frames")) {
        const Section s = top.child("frames", false, "a map");
        s.allow({"events_per_frame", "min_window_ms", "max_window_ms", "min_events", "motion_compensation", "use_depth", "clip_percentile",
                 "clip_count", "overlap", "velocity_at_reference", "event_lag_px"});
        auto& f = c.frames;
        f.events_per_frame = s.integer("events_per_frame", f.events_per_frame, 1, 100000000);
        f.max_window_ns = ms_to_ns(s.number("max_window_ms", ns_to_ms(f.max_window_ns), Range::kPositive, "ms"));
        f.min_window_ns = ms_to_ns(s.number("min_window_ms", ns_to_ms(f.min_window_ns), Range::kNonNegative, "ms"));
        f.min_events = s.integer("min_events", f.min_events, 1, 100000000);
        f.motion_compensation = s.boolean("motion_compensation", f.motion_compensation);
        f.use_depth = s.boolean("use_depth", f.use_depth);
        c.frame_velocity_at_reference = s.boolean("velocity_at_reference", c.frame_velocity_at_reference);
        f.clip_percentile = s.number("clip_percentile", f.clip_percentile, Range::kUnit, "");
        f.clip_count = s.number("clip_count", f.clip_count, Range::kNonNegative, "events per pixel");
        f.overlap = s.number("overlap", f.overlap, Range::kNonNegative, "fraction of a frame's events");
        f.event_lag_px = s.number("event_lag_px", f.event_lag_px, Range::kNonNegative, "px");
        std::string why;
        if (!f.Validate(&why)) s.fail("invalid frame settings: " + why, "consistent settings");
      }
      if (top.has("tracker")) parse_tracker(top.child("tracker", false, "a map"), &c.tracker);
      if (top.has("aps_tracker")) parse_tracker(top.child("aps_tracker", false, "a map"), &c.aps_tracker);
      if (top.has("aps")) {
        const Section s = top.child("aps", false, "a map");
        s.allow({"pixel_sigma", "event_pixel_sigma", "max_gap_ms"});
        c.aps_pixel_sigma_px = s.number("pixel_sigma", c.aps_pixel_sigma_px, Range::kPositive, "px");
        c.aps_event_pixel_sigma_px = s.number("event_pixel_sigma", c.aps_event_pixel_sigma_px, Range::kPositive, "px");
        c.aps_max_gap_ns = ms_to_ns(s.number("max_gap_ms", ns_to_ms(c.aps_max_gap_ns), Range::kPositive, "ms"));
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
        s.allow({"size", "max_iterations", "function_tolerance", "max_solver_time_ms", "loss", "loss_scale", "pixel_sigma",
                 "keyframe_min_parallax_px", "keyframe_min_tracked_ratio", "keyframe_max_interval_ms",
                 "min_triangulation_angle_deg", "max_reprojection_px", "rotation_only_parallax_px",
                 "rotation_only_translation_px", "rotation_only_min_duration_ms", "init_bias_gyro_turn_on_radps", "init_bias_accel_turn_on_mps2",
                 "init_bias_horizon_s", "estimate_time_offset", "time_offset_sigma_ms",
                 "tracked_landmark_marginalisation"});
        auto& w = c.window;
        w.window_size = s.integer("size", w.window_size, 2, 200);
        w.max_iterations = s.integer("max_iterations", w.max_iterations, 1, 1000);
        w.function_tolerance = s.number("function_tolerance", w.function_tolerance, Range::kPositive, "relative cost change");
        if (!(w.function_tolerance < 1)) s.fail_at("function_tolerance", "must be < 1", "a relative cost change in (0, 1)");
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
        const std::string tlm = s.string("tracked_landmark_marginalisation", tracked_landmark_name(w.tracked_landmark_marginalisation),
                                         {"drop", "double_count", "restart", "split"});
        w.tracked_landmark_marginalisation = tlm == "double_count" ? backend::TrackedLandmarkMarginalisation::kDoubleCount
                                             : tlm == "restart"    ? backend::TrackedLandmarkMarginalisation::kRestart
                                             : tlm == "split"      ? backend::TrackedLandmarkMarginalisation::kSplit
                                                                   : backend::TrackedLandmarkMarginalisation::kDrop;
        w.rotation_only_parallax_px = s.number("rotation_only_parallax_px", w.rotation_only_parallax_px, Range::kNonNegative, "px");
        w.rotation_only_translation_px = s.number("rotation_only_translation_px", w.rotation_only_translation_px, Range::kPositive, "px");
        w.rotation_only_min_duration_s =
            1e-3 * s.number("rotation_only_min_duration_ms", w.rotation_only_min_duration_s * 1e3, Range::kNonNegative, "ms");
        w.init_bias_gyro_turn_on_radps = s.number("init_bias_gyro_turn_on_radps", w.init_bias_gyro_turn_on_radps, Range::kPositive, "rad/s");
        w.init_bias_accel_turn_on_mps2 = s.number("init_bias_accel_turn_on_mps2", w.init_bias_accel_turn_on_mps2, Range::kPositive, "m/s^2");
        w.init_bias_horizon_s = s.number("init_bias_horizon_s", w.init_bias_horizon_s, Range::kNonNegative, "s");
        w.estimate_time_offset = s.boolean("estimate_time_offset", w.estimate_time_offset);
        w.time_offset_sigma_s = 1e-3 * s.number("time_offset_sigma_ms", w.time_offset_sigma_s * 1e3, Range::kPositive, "ms");
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
        const std::string m = s.string("method", init_name(c.init), {"auto", "static", "alignment", "groundtruth"});
        c.init = m == "static"      ? pipeline::VioInitMethod::kStatic
                 : m == "alignment" ? pipeline::VioInitMethod::kAlignment
                 : m == "groundtruth" ? pipeline::VioInitMethod::kGiven
                                      : pipeline::VioInitMethod::kAuto;
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

std::string init_description(pipeline::VioInitMethod m) {
  switch (m) {
    case pipeline::VioInitMethod::kStatic: return "static";
    case pipeline::VioInitMethod::kAlignment: return "visual-inertial alignment";
    case pipeline::VioInitMethod::kGiven: return "ground truth (diagnostic)";
    case pipeline::VioInitMethod::kAuto: break;
  }
  return "auto";
}

}  // namespace

int run_vio(const VioArgs& args, std::ostream& out) {
  // One core: OpenCV's parallel loops (the KLT's per-point loop) run inline instead of handing
  // work to TBB worker threads, whose hand-offs and spinning cost CPU time for no gain here.
  cv::setNumThreads(1);
  // The oracle's scene first: its errors come before reading a dataset.
  std::shared_ptr<const simulator::PlanarScene> oracle_planes;
  if (args.oracle_frame_plane && !args.oracle_frame_motion)
    throw InputError(args.dataset, 0, "--oracle-frame-plane needs --oracle-frame-motion", "--oracle-frame-motion --oracle-frame-plane");
  if (args.oracle_frame_motion && args.oracle_scene.empty())
    throw InputError(args.dataset, 0, "--oracle-frame-motion needs the scene", "--oracle-tracks SCENE.yaml and --gt GT.tum");
  if (!args.oracle_scene.empty()) {
    if (args.gt.empty()) throw InputError(args.oracle_scene, 0, "--oracle-tracks needs the true trajectory", "--gt GT.tum");
    const simulator::SimulationConfig sc = simulator::load_simulation_config(args.oracle_scene);
    oracle_planes = std::dynamic_pointer_cast<const simulator::PlanarScene>(sc.scene);
    if (!oracle_planes)
      throw InputError(args.oracle_scene, 0, "--oracle-tracks needs a planes scene (got " + sc.scene_type + ")", "scene: planes");
  }
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
  std::vector<ImuSample> imu = reader->read_imu();
  if (imu.size() < 10) throw InputError(args.dataset, 0, "the dataset has no IMU samples", "a recording with IMU");
  fs::create_directories(args.out);
  {
    std::ofstream f((fs::path(args.out) / "vio_config.yaml").string());
    f << resolved;
  }

  pipeline::VioPipeline vio(cfg, *cal, noise);
  if (cfg.init == pipeline::VioInitMethod::kGiven) {
    if (args.gt.empty()) throw InputError(args.config, 0, "init.method groundtruth needs --gt", "--gt GT.tum, or another init.method");
    vio.set_initial_state_provider([gt = load_trajectory(args.gt)](int64_t t_ns) { return evaluation::groundtruth_state(gt, t_ns); });
  }
  std::unique_ptr<evaluation::TrackOracle> oracle;
  if (oracle_planes) {
    evaluation::TrackOracleOptions oo;
    oo.white_noise_px = args.oracle_noise_px;
    oo.drift_px_per_frame = args.oracle_drift_px;
    oo.max_error_px = args.oracle_max_error_px;
    oo.keep_error = args.oracle_error == "real"          ? evaluation::OracleError::kReal
                    : args.oracle_error == "independent" ? evaluation::OracleError::kIndependent
                    : args.oracle_error == "common_mode" ? evaluation::OracleError::kCommonMode
                                                         : evaluation::OracleError::kNone;
    const evaluation::RayCaster cast = [p = oracle_planes](const Eigen::Vector3d& o, const Eigen::Vector3d& d) {
      return p->intersect(o, d);
    };
    oracle = std::make_unique<evaluation::TrackOracle>(load_trajectory(args.gt), *cal, cast, oo);
    vio.set_observation_filter([o = oracle.get()](FeatureObservations* f) { o->apply(f); });
    if (args.oracle_frame_motion) {
      vio.set_frame_motion_oracle(
          [gt = load_trajectory(args.gt), T_c_b = cal->T_c_b, plane = args.oracle_frame_plane, cast](
              const FeatureObservations& f, Eigen::Vector3d* v_c, double* depth_m, Eigen::Vector4d* plane_c) {
            return evaluation::true_frame_motion(gt, T_c_b, cast, f, v_c, depth_m, plane ? plane_c : nullptr);
          });
    }
  }
  std::ofstream obs_file((fs::path(args.out) / "observations.txt").string());
  obs_file << "# t[s] track_id bx by bz  (front-end observations: unit bearings in the camera frame, body clock)\n";
  vio.set_observation_callback([&obs_file](const FeatureObservations& f) {
    for (const auto& o : f.observations) {
      char line[160];
      std::snprintf(line, sizeof(line), "%s %lld %.7f %.7f %.7f\n", format_seconds(f.t_ns).c_str(),
                    static_cast<long long>(o.track_id), o.bearing_c.x(), o.bearing_c.y(), o.bearing_c.z());
      obs_file << line;
    }
  });
  for (const ImuSample& m : imu) vio.add_imu(m);
  imu = {};  // the pipeline keeps what it needs
  const auto wall0 = std::chrono::steady_clock::now();
  if (cfg.inputs != pipeline::VioInputs::kEvents) {
    // Every APS frame before the events (the events+aps merge needs the frame times around each
    // event frame); images are decoded one at a time.
    std::vector<Frame> frames = reader->read_frames();
    if (frames.empty()) {
      throw InputError(args.dataset, 0, std::string("inputs: ") + pipeline::to_string(cfg.inputs) + " needs intensity (APS) frames and the recording has none",
                       "inputs: events, or a recording with frames (ECD images.txt, AEDAT4 frames, ...)");
    }
    for (Frame& f : frames) {
      if (f.image.empty()) load_frame_image(&f);
      vio.add_frame(f);
      f.image.release();
    }
  }

  Progress progress("evio vio", args.progress, "events");
  EventBuffer chunk;
  int64_t events = 0, t_first = 0, t_last = 0;
  while (cfg.inputs != pipeline::VioInputs::kAps) {
    chunk.clear();
    if (reader->read_events(&chunk, size_t{1} << 18) == 0) break;
    const EventSpan span = chunk.span();
    vio.add_events(span);
    if (events == 0) t_first = span.front().t_ns;
    t_last = span.back().t_ns;
    events += static_cast<int64_t>(span.size());
    const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
    const double seq = static_cast<double>(t_last - t_first) * 1e-9;
    progress.update(reader->progress(), events, "real-time factor " + num(seq > 0 ? elapsed / seq : 0.0));
  }
  const pipeline::VioResult r = vio.finish();
  const double processing_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  const pipeline::VioStats& vs = r.stats;
  const double duration_s =
      static_cast<double>(cfg.inputs == pipeline::VioInputs::kAps ? vs.t_last_aps_ns - vs.t_first_aps_ns
                                                                  : vs.t_last_event_ns - vs.t_first_event_ns) * 1e-9;
  if (!r.initialized) {
    log_debug("vio: " + r.init_failure);
    throw InputError(args.dataset, 0, "could not initialise (no still start and the visual-inertial alignment failed)",
                     "a recording that starts still or moves with enough features in the first seconds");
  }
  const std::string init_method = init_description(r.init_method);

  // Outputs.
  write_tum((fs::path(args.out) / "trajectory.tum").string(), r.trajectory);
  write_tum((fs::path(args.out) / "trajectory_causal.tum").string(), r.trajectory_causal);
  {
    std::ofstream f((fs::path(args.out) / "keyframes.txt").string());
    f << "# t[s] x y z qx qy qz qw vx vy vz bgx bgy bgz bax bay baz  (T_w_b, v_w m/s, biases rad/s and m/s^2)\n";
    for (const VioState& s : r.keyframes) {
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
  for (const auto& [id, p] : r.landmarks) pts.push_back({p, static_cast<float>(id)});
  mapping::write_landmark_map((fs::path(args.out) / "map.ply").string(), pts);

  const backend::SlidingWindowStats& st = vs.window;
  std::vector<double> solve = st.solve_time_s;
  std::sort(solve.begin(), solve.end());
  const double med = solve.empty() ? 0 : solve[solve.size() / 2];
  const bool use_frames = cfg.frontend == pipeline::VioFrontEnd::kFrames;
  std::ostringstream j;
  j << "{\n  \"dataset\": \"" << json_escape(args.dataset) << "\",\n  \"inputs\": \"" << pipeline::to_string(cfg.inputs)
    << "\",\n  \"frontend\": \"" << pipeline::to_string(cfg.frontend)
    << "\",\n  \"events\": " << vs.events << ",\n  \"corners\": " << vs.corner_events << ",\n  \"frames\": " << st.frames
    << ",\n  \"keyframes\": " << st.keyframes << ",\n  \"landmarks\": " << pts.size()
    << ",\n  \"processing_time_s\": " << num(processing_s) << ",\n  \"sequence_duration_s\": " << num(duration_s)
    << ",\n  \"real_time_factor\": " << num(duration_s > 0 ? processing_s / duration_s : 0.0)
    << ",\n  \"solve_ms_median\": " << num(1e3 * med) << ",\n  \"initialisation\": {\"method\": \"" << init_method
    << "\", \"t\": " << format_seconds(r.init_t_ns) << "},\n  \"imu_noise_from\": \"" << json_escape(noise_source)
    << "\",\n  \"motion_model_segments\": [";
  for (size_t i = 0; i < r.motion_models.size(); ++i) {
    const pipeline::VioSegment& m = r.motion_models[i];
    j << (i ? ", " : "") << "{\"t_begin\": " << format_seconds(m.t_begin_ns) << ", \"t_end\": " << format_seconds(m.t_end_ns)
      << ", \"model\": \"" << m.what << "\"}";
  }
  // The model-selection test per keyframe (GRIC of the static, rotation and general models; the
  // decision after hysteresis and the pixel conditions).
  j << "],\n  \"motion_model_tests\": [";
  for (size_t i = 0; i < st.motion_model_tests.size(); ++i) {
    const auto& m = st.motion_model_tests[i];
    j << (i ? ",\n    " : "\n    ") << "{\"t\": " << format_seconds(m.t_ns) << ", \"tracks\": " << m.tracks
      << ", \"baseline_s\": " << num(m.baseline_s)
      << ", \"gric_static\": " << num(m.gric_static) << ", \"gric_rotation\": " << num(m.gric_rotation)
      << ", \"gric_general\": " << num(m.gric_general) << ", \"imu_chi2\": " << num(m.imu_chi2) << ", \"best\": \""
      << backend::two_view_model_name(m.best) << "\", \"imu_veto\": " << (m.imu_veto ? "true" : "false")
      << ", \"rotation_only\": " << (m.rotation_only ? "true" : "false") << "}";
  }
  j << "],\n  \"tracking_lost_segments\": [";
  for (size_t i = 0; i < r.tracking_lost.size(); ++i) {
    const pipeline::VioSegment& l = r.tracking_lost[i];
    j << (i ? ", " : "") << "{\"t_begin\": " << format_seconds(l.t_begin_ns) << ", \"t_end\": " << format_seconds(l.t_end_ns)
      << ", \"reason\": \"" << l.what << "\"}";
  }
  j << "],\n  \"frontend_stats\": {";
  if (use_frames) {
    const auto& ts = vs.tracker;
    const auto& fs_ = vs.event_frames;
    j << "\"event_frames\": " << fs_.frames_emitted << ", \"frames_uncompensated\": " << fs_.frames_uncompensated
      << ", \"frames_dropped_sparse\": " << fs_.frames_dropped_sparse << ", \"tracks_detected\": " << ts.detected
      << ", \"tracked\": " << ts.tracked << ", \"lost_klt\": " << ts.lost_klt << ", \"lost_forward_backward\": " << ts.lost_fb
      << ", \"rejected_ransac\": " << ts.rejected_ransac << ", \"template_fallbacks\": " << ts.template_fallbacks
      << ", \"rejected_anchor\": " << ts.rejected_anchor << ", \"template_rotation_refreshes\": " << ts.template_rotation_refreshes;
  } else {
    j << "\"corner_events\": " << vs.corner_events << ", \"corner_tracks_started\": " << vs.corner_tracker.tracks_started;
  }
  if (cfg.inputs != pipeline::VioInputs::kEvents) {
    const auto& as = vs.aps_tracker;
    j << ", \"aps_frames\": " << vs.aps_frames << ", \"aps_frames_dropped\": " << vs.aps_frames_dropped
      << ", \"aps_tracks_detected\": " << as.detected << ", \"aps_tracked\": " << as.tracked << ", \"aps_lost_klt\": " << as.lost_klt
      << ", \"aps_lost_forward_backward\": " << as.lost_fb << ", \"aps_rejected_ransac\": " << as.rejected_ransac;
  }
  j << "}";
  if (oracle) {
    j << ",\n  \"oracle\": {\"scene\": \"" << json_escape(args.oracle_scene) << "\", \"white_noise_px\": " << num(args.oracle_noise_px)
      << ", \"drift_px_per_frame\": " << num(args.oracle_drift_px) << ", \"replaced\": " << oracle->stats().replaced
      << ", \"dropped\": " << oracle->stats().dropped << ", \"keep_error\": \"" << args.oracle_error
      << "\", \"common_mode_rms_px\": " << num(oracle->stats().common_mode_rms_px)
      << ", \"max_error_px\": " << num(args.oracle_max_error_px) << ", \"dropped_gross\": " << oracle->stats().dropped_gross << "}";
  }
  j << ",\n  \"outliers_removed\": " << st.outliers_removed << ",\n  \"landmarks_marginalised\": " << st.landmarks_marginalised
    << ",\n  \"observations_dropped\": " << st.observations_dropped
    << ",\n  \"tracked_landmarks_marginalised\": " << st.tracked_landmarks_marginalised << ",\n  \"rotation_only_keyframes\": " << st.rotation_only_keyframes;
  if (cfg.window.estimate_time_offset) j << ",\n  \"time_offset_correction_s\": " << num(st.time_offset_s);
  j
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
                static_cast<long long>(vs.events), duration_s, static_cast<long long>(vs.corner_events),
                static_cast<long long>(st.frames), static_cast<long long>(st.keyframes), pts.size(),
                format_seconds(r.init_t_ns).c_str(), init_method.c_str(), processing_s,
                duration_s > 0 ? processing_s / duration_s : 0.0, 1e3 * med);
  out << buf;
  out << "motion model  ";
  for (const auto& m : r.motion_models) out << m.what << " " << format_seconds(m.t_begin_ns) << ".." << format_seconds(m.t_end_ns) << "  ";
  out << "\n";
  if (!r.tracking_lost.empty()) out << "tracking lost " << r.tracking_lost.size() << " segment(s), see stats.json\n";
  if (!args.gt.empty()) {
    EvalArgs ea;
    ea.groundtruth = args.gt;
    ea.estimates = {(fs::path(args.out) / "trajectory.tum").string(), (fs::path(args.out) / "trajectory_causal.tum").string()};
    ea.options.alignment.method = evaluation::Alignment::kSE3;
    ea.options.alignment.first_s = 5.0;
    const auto results = evaluate_all(ea);
    std::ofstream f((fs::path(args.out) / "eval.json").string());
    f << results_json(ea, results);
    const auto& e = results.front().result;
    std::snprintf(buf, sizeof(buf),
                  "evaluation    ATE rmse %.4f m, mean position error %.3f%% of %.2f m, final yaw error %.2f deg, yaw drift "
                  "%.4f deg/m (SE3 on the first 5 s)\n",
                  e.ate.trans_m.rmse, e.mean_position_error_percent, e.groundtruth_length_m, e.final_yaw_error_deg,
                  e.yaw_drift_deg_per_m);
    out << buf;
    if (results.size() > 1) {
      const auto& c = results[1].result;
      std::snprintf(buf, sizeof(buf), "              causal (as estimated online): mean position error %.3f%%, final yaw error %.2f deg\n",
                    c.mean_position_error_percent, c.final_yaw_error_deg);
      out << buf;
    }
  }
  out << "wrote " << args.out << "/trajectory.tum, trajectory_causal.tum, keyframes.txt, map.ply, observations.txt, stats.json, vio_config.yaml"
      << (args.gt.empty() ? "" : ", eval.json") << "\n";
  return 0;
}

}  // namespace evio::apps
