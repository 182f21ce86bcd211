#include "mosaic_command.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <utility>

#include <yaml-cpp/yaml.h>

#include "dataset_calibration.h"
#include "eval_command.h"
#include "evio/calib/equirectangular.h"
#include "evio/calib/error.h"
#include "evio/calib/geometry.h"
#include "evio/calib/log.h"
#include "evio/sensors/time.h"
#include "evio/sensors/trajectory.h"
#include "json_util.h"
#include "progress.h"

namespace evio::apps {
namespace {
std::string num(double v) { return json_number(v, 9); }
std::string json_string(const std::string& s) { return "\"" + json_escape(s) + "\""; }
}  // namespace
}  // namespace evio::apps
#include "evio/simulator/scene_config.h"
#include "evio/sensors/yaml_config.h"

namespace evio::apps {

namespace fs = std::filesystem;
using namespace yaml_config;  // NOLINT

MosaicConfig default_mosaic_config() {
  MosaicConfig c;
  c.display.gamma = 1.0;
  // Unseen texels transparent in panorama.png and the snapshots (black ones would look like dark texels).
  c.display.transparent_unseen = true;
  // 100 events per particle update (the library's default is 10): on poster_rotation (1 s, gyro)
  // 0.17 deg RMS at 0.60 M events/s against 0.23 deg at 0.42 M events/s; events only 1.99 vs 2.04 deg.
  c.tracker.batch_size = 100;
  // Each particle carries its angular velocity; without the gyro the relative-motion measurement
  // moves the pixel's previous direction back with it (with the gyro the gyro drives, as before).
  // Events only, RMS deg, previous_mean -> particle_velocity: poster slow 30 s 1.42 -> 0.43, medium
  // 10 s 1.11 -> 0.48, boxes 3 s 1.26 -> 0.95 (README, `evio mosaic`).
  c.tracker.motion_model = frontend::RotationMotionModel::kParticleVelocity;
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
    << ", seen_max_gradient_std: " << num(m.seen_max_gradient_std) << ", max_path_px: " << num(m.max_path_px)
    << ", map_viewed_texels: " << (m.map_viewed_texels ? "true" : "false")
    << ", reconstruct_events: " << c.reconstruct_events << ", reconstruct_ms: " << num(c.reconstruct_period_ns * 1e-6)
    << ", reconstruct_latency_events: " << c.reconstruct_latency_events << ", threads: " << c.threads
    << ", footprint_ms: " << num(c.footprint_period_ns * 1e-6)
    << ", full_reconstruct_every: " << c.full_reconstruct_every
    << ", poisson_weighting: " << mapping::poisson_weighting_name(c.output_weighting)
    << ", weight_reference_std: " << num(m.weight_reference_std) << ", viewed_edge_weight: " << num(m.viewed_edge_weight)
    << ", weight_floor: " << num(m.weighted_poisson.weight_floor) << ", pcg_tolerance: " << num(m.weighted_poisson.tolerance)
    << ", pcg_max_iterations: " << m.weighted_poisson.max_iterations
    << ", pcg_preconditioner: " << mapping::poisson_preconditioner_name(m.weighted_poisson.preconditioner) << "}\n";
  // min_particles: as resolved for the run (run_mosaic), else as configured (-1 = by input).
  y << "tracker: {particles: " << t.num_particles
    << ", min_particles: " << (t.min_particles > 0 ? t.min_particles : c.min_particles)
    << ", kld_bin_rad: " << num(t.kld_bin_rad) << ", kld_epsilon: " << num(t.kld_epsilon) << ", kld_z: " << num(t.kld_z)
    << ", batch_size: " << t.batch_size << ", event_stride: " << t.event_stride
    << ", max_batch_ms: " << num(t.max_batch_duration_ns * 1e-6)
    << ", motion_model: " << frontend::rotation_motion_model_name(t.motion_model)
    << ", measurement_model: " << frontend::rotation_measurement_model_name(t.measurement_model)
    << ", contrast_threshold: " << num(t.contrast_threshold) << ", linearize_max_spread_rad: " << num(t.linearize_max_spread_rad)
    << ", motion_noise_rad_per_sqrt_s: " << num(t.motion_noise_rad_per_sqrt_s)
    << ", gyro_noise_rad_per_sqrt_s: " << num(t.gyro_noise_rad_per_sqrt_s)
    << ", velocity_noise_rad_s_per_sqrt_s: " << num(t.velocity_noise_rad_s_per_sqrt_s)
    << ", velocity_rotation_noise_rad_per_sqrt_s: " << num(t.velocity_rotation_noise_rad_per_sqrt_s)
    << ", initial_velocity_spread_rad_s: " << num(t.initial_velocity_spread_rad_s)
    << ", relative_max_interval_ms: " << num(t.relative_max_interval_ns * 1e-6)
    << ", relative_max_path_rad: " << num(t.relative_max_path_rad) << ", likelihood_std: " << num(t.likelihood_std)
    << ", outlier_probability: " << num(t.outlier_probability) << ", resample_ess_fraction: " << num(t.resample_ess_fraction)
    << ", seed: " << t.seed << "}\n";
  y << "bootstrap: {duration_ms: " << num(c.bootstrap_ns * 1e-6) << ", window_ms: " << num(c.bootstrap_window_ns * 1e-6)
    << ", window_events: " << c.bootstrap_window_events
    << ", blur_px: " << num(c.cmax.blur_sigma_px) << ", calibrate_contrast: " << (c.calibrate_contrast ? "true" : "false")
    << ", min_contrast_ratio: " << num(c.min_contrast_ratio) << ", calibration_sample_stride: " << c.calibration_sample_stride
    << ", calibration_min_texel_updates: " << c.calibration_min_texel_updates
    << ", calibration_min_samples: " << c.calibration_min_samples << ", gyro_window_ms: " << num(c.gyro_bootstrap_window_ns * 1e-6)
    << ", gyro_step_ms: " << num(c.gyro_integration_step_ns * 1e-6) << "}\n";
  y << "failure: {probe_every_batches: " << c.tracker.probe_every_batches << ", probe_offset_rad: " << num(c.tracker.probe_offset_rad)
    << ", window_ms: " << num(c.failure_window_ns * 1e-6) << ", min_events: " << c.failure_min_events
    << ", min_rate_ratio: " << num(c.failure_min_rate_ratio) << ", lost_windows: " << c.failure_lost_windows << ", lost_contrast: " << num(c.failure_lost_contrast)
    << ", recovered_contrast: " << num(c.failure_recovered_contrast) << ", freeze_map: " << (c.failure_freeze_map ? "true" : "false")
    << ", relocalize_spread_rad: " << num(c.failure_relocalize_spread_rad)
    << ", rollback: " << (c.failure_rollback ? "true" : "false") << ", checkpoint_ms: " << num(c.failure_checkpoint_period_ns * 1e-6)
    << ", checkpoints: " << c.failure_checkpoints
    << ", global_relocalize: " << (c.failure_global_relocalize ? "true" : "false")
    << ", global_period_ms: " << num(c.failure_global_period_ns * 1e-6) << ", global_min_gain: " << num(c.failure_global_min_gain)
    << ", global_axis_spacing_deg: " << num(c.relocalization.axis_spacing_deg)
    << ", global_roll_step_deg: " << num(c.relocalization.roll_step_deg) << "}\n";
  y << "output: {trajectory_ms: " << num(c.trajectory_period_ns * 1e-6) << ", snapshot_ms: " << num(c.snapshot_period_ns * 1e-6)
    << ", gamma: " << num(c.display.gamma) << ", low_percentile: " << num(c.display.low_percentile)
    << ", high_percentile: " << num(c.display.high_percentile)
    << ", transparent_unseen: " << (c.display.transparent_unseen ? "true" : "false") << "}\n";
  return y.str();
}

// CPU time of the process (all threads), s.
double process_cpu_s() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

// A duration given in milliseconds under `key` (the config's *_ms keys), in ns. (Section::time_ns
// reads seconds: `reconstruct_ms: 20` was 20 s.)
int64_t ms_ns(const Section& s, const std::string& key, int64_t def_ns, Range r) {
  return std::llround(s.number(key, static_cast<double>(def_ns) * 1e-6, r, "ms") * 1e6);
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
    top.allow({"mosaic", "tracker", "bootstrap", "failure", "output", "description"});
    if (top.has("mosaic")) {
      const Section s = top.child("mosaic", false, "a map");
      s.allow({"width", "height", "contrast_threshold", "initial_gradient_std", "measurement_std_abs",
               "measurement_relative_std", "min_tau_ms", "min_speed_px_s", "reconstruct_events", "reconstruct_ms",
               "reconstruct_latency_events", "threads", "footprint_ms", "full_reconstruct_every",
               "seen_min_observations", "seen_max_gradient_std", "max_path_px", "map_viewed_texels", "poisson_weighting", "weight_reference_std", "viewed_edge_weight", "weight_floor",
               "pcg_tolerance", "pcg_max_iterations", "pcg_preconditioner"});
      auto& m = c.mosaic;
      m.width = s.integer("width", m.width, 8, 1 << 15);
      m.height = s.integer("height", m.width / 2, 4, 1 << 14);
      m.contrast_threshold = s.number("contrast_threshold", m.contrast_threshold, Range::kPositive, "log units");
      m.initial_gradient_std = s.number("initial_gradient_std", m.initial_gradient_std, Range::kPositive, "log units/px");
      m.measurement_std_abs = s.number("measurement_std_abs", m.measurement_std_abs, Range::kNonNegative, "1/s");
      m.measurement_relative_std = s.number("measurement_relative_std", m.measurement_relative_std, Range::kNonNegative, "");
      m.min_tau_s = s.number("min_tau_ms", m.min_tau_s * 1e3, Range::kPositive, "ms") * 1e-3;
      m.min_speed_px_s = s.number("min_speed_px_s", m.min_speed_px_s, Range::kNonNegative, "px/s");
      c.reconstruct_events = s.integer("reconstruct_events", static_cast<int>(c.reconstruct_events), 1, 1000000000);
      c.reconstruct_period_ns = ms_ns(s, "reconstruct_ms", c.reconstruct_period_ns, Range::kPositive);
      c.reconstruct_latency_events =
          s.integer("reconstruct_latency_events", static_cast<int>(c.reconstruct_latency_events), 0, 1000000000);
      c.threads = s.integer("threads", c.threads, 1, 2);
      c.footprint_period_ns = ms_ns(s, "footprint_ms", c.footprint_period_ns, Range::kPositive);
      c.full_reconstruct_every = s.integer("full_reconstruct_every", c.full_reconstruct_every, 1, 1000000);
      m.seen_min_observations = s.integer("seen_min_observations", m.seen_min_observations, 1, 1000000);
      m.max_path_px = s.number("max_path_px", m.max_path_px, Range::kPositive, "mosaic px");
      m.map_viewed_texels = s.boolean("map_viewed_texels", m.map_viewed_texels);
      m.seen_max_gradient_std = s.number("seen_max_gradient_std", m.seen_max_gradient_std, Range::kNonNegative, "log units/px");
      const std::string weighting =
          s.string("poisson_weighting", mapping::poisson_weighting_name(c.output_weighting), {"none", "information"});
      c.output_weighting = weighting == "none" ? mapping::PoissonWeighting::kNone : mapping::PoissonWeighting::kInformation;
      m.weight_reference_std = s.number("weight_reference_std", m.weight_reference_std, Range::kPositive, "log units/px");
      m.viewed_edge_weight = s.number("viewed_edge_weight", m.viewed_edge_weight, Range::kUnit, "");
      auto& wp = m.weighted_poisson;
      wp.weight_floor = s.number("weight_floor", wp.weight_floor, Range::kUnit, "");
      wp.tolerance = s.number("pcg_tolerance", wp.tolerance, Range::kUnit, "");
      wp.max_iterations = s.integer("pcg_max_iterations", wp.max_iterations, 0, 1000000);
      const std::string pre = s.string("pcg_preconditioner", mapping::poisson_preconditioner_name(wp.preconditioner),
                                       {"none", "jacobi", "spectral", "scaled_spectral"});
      wp.preconditioner = pre == "none"       ? mapping::PoissonPreconditioner::kNone
                          : pre == "jacobi"   ? mapping::PoissonPreconditioner::kJacobi
                          : pre == "spectral" ? mapping::PoissonPreconditioner::kSpectral
                                              : mapping::PoissonPreconditioner::kScaledSpectral;
      std::string why;
      if (!m.Validate(&why)) s.fail("invalid mosaic settings: " + why, "consistent settings");
    }
    c.tracker.contrast_threshold = c.mosaic.contrast_threshold;  // unless tracker.contrast_threshold says otherwise
    if (top.has("tracker")) {
      const Section s = top.child("tracker", false, "a map");
      s.allow({"particles", "min_particles", "kld_bin_rad", "kld_epsilon", "kld_z", "batch_size", "max_batch_ms", "motion_model", "measurement_model", "contrast_threshold", "event_stride", "linearize_max_spread_rad", "motion_noise_rad_per_sqrt_s",
               "gyro_noise_rad_per_sqrt_s", "likelihood_std", "outlier_probability", "resample_ess_fraction", "seed",
               "velocity_noise_rad_s_per_sqrt_s", "velocity_rotation_noise_rad_per_sqrt_s", "initial_velocity_spread_rad_s", "relative_max_interval_ms",
               "relative_max_path_rad"});
      auto& t = c.tracker;
      t.num_particles = s.integer("particles", t.num_particles, 1, 1000000);
      c.min_particles = s.integer("min_particles", c.min_particles, -1, 1000000);
      t.kld_bin_rad = s.number("kld_bin_rad", t.kld_bin_rad, Range::kPositive, "rad");
      t.kld_epsilon = s.number("kld_epsilon", t.kld_epsilon, Range::kPositive, "");
      t.kld_z = s.number("kld_z", t.kld_z, Range::kPositive, "");
      t.contrast_threshold = s.number("contrast_threshold", c.mosaic.contrast_threshold, Range::kPositive, "log units");
      t.batch_size = s.integer("batch_size", t.batch_size, 1, 1000000);
      c.event_stride = s.integer("event_stride", c.event_stride, 1, 1000000);
      t.linearize_max_spread_rad = s.number("linearize_max_spread_rad", t.linearize_max_spread_rad, Range::kNonNegative, "rad");
      t.max_batch_duration_ns = ms_ns(s, "max_batch_ms", t.max_batch_duration_ns, Range::kPositive);
      const std::string mm = s.string("motion_model", frontend::rotation_motion_model_name(t.motion_model),
                                      {"random_walk", "constant_velocity", "particle_velocity"});
      t.motion_model = mm == "random_walk"         ? frontend::RotationMotionModel::kRandomWalk
                       : mm == "constant_velocity" ? frontend::RotationMotionModel::kConstantVelocity
                                                   : frontend::RotationMotionModel::kParticleVelocity;
      t.velocity_noise_rad_s_per_sqrt_s = s.number("velocity_noise_rad_s_per_sqrt_s", t.velocity_noise_rad_s_per_sqrt_s,
                                                   Range::kPositive, "rad/s/sqrt(s)");
      t.velocity_rotation_noise_rad_per_sqrt_s = s.number("velocity_rotation_noise_rad_per_sqrt_s",
                                                          t.velocity_rotation_noise_rad_per_sqrt_s, Range::kPositive, "rad/sqrt(s)");
      t.initial_velocity_spread_rad_s = s.number("initial_velocity_spread_rad_s", t.initial_velocity_spread_rad_s,
                                                 Range::kNonNegative, "rad/s");
      t.relative_max_interval_ns = ms_ns(s, "relative_max_interval_ms", t.relative_max_interval_ns, Range::kPositive);
      t.relative_max_path_rad = s.number("relative_max_path_rad", t.relative_max_path_rad, Range::kPositive, "rad");
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
      s.allow({"duration_ms", "window_ms", "window_events", "blur_px", "calibrate_contrast", "min_contrast_ratio",
               "calibration_sample_stride", "calibration_min_texel_updates", "calibration_min_samples", "gyro_window_ms",
               "gyro_step_ms"});
      c.calibrate_contrast = s.boolean("calibrate_contrast", c.calibrate_contrast);
      c.min_contrast_ratio = s.number("min_contrast_ratio", c.min_contrast_ratio, Range::kUnit, "");
      c.bootstrap_ns = ms_ns(s, "duration_ms", c.bootstrap_ns, Range::kNonNegative);
      c.bootstrap_window_ns = ms_ns(s, "window_ms", c.bootstrap_window_ns, Range::kPositive);
      c.bootstrap_window_events = s.integer("window_events", c.bootstrap_window_events, 1000, 100000000);
      c.cmax.blur_sigma_px = s.number("blur_px", c.cmax.blur_sigma_px, Range::kPositive, "px");
      c.calibration_sample_stride = s.integer("calibration_sample_stride", c.calibration_sample_stride, 1, 1000000);
      c.calibration_min_texel_updates = s.integer("calibration_min_texel_updates", c.calibration_min_texel_updates, 0, 1000000);
      c.calibration_min_samples = s.integer("calibration_min_samples", c.calibration_min_samples, 1, 100000000);
      c.gyro_bootstrap_window_ns = ms_ns(s, "gyro_window_ms", c.gyro_bootstrap_window_ns, Range::kPositive);
      c.gyro_integration_step_ns = ms_ns(s, "gyro_step_ms", c.gyro_integration_step_ns, Range::kPositive);
    }
    if (top.has("failure")) {
      const Section s = top.child("failure", false, "a map");
      s.allow({"probe_every_batches", "probe_offset_rad", "window_ms", "min_events", "min_rate_ratio", "lost_windows", "lost_contrast", "recovered_contrast",
               "freeze_map", "relocalize_spread_rad", "rollback", "checkpoint_ms", "checkpoints", "global_relocalize", "global_period_ms", "global_min_gain",
               "global_axis_spacing_deg", "global_roll_step_deg"});
      c.failure_min_events = s.integer("min_events", c.failure_min_events, 0, 1000000000);
      c.failure_min_rate_ratio = s.number("min_rate_ratio", c.failure_min_rate_ratio, Range::kNonNegative, "");
      c.failure_lost_windows = s.integer("lost_windows", c.failure_lost_windows, 1, 1000000);
      c.tracker.probe_every_batches = s.integer("probe_every_batches", c.tracker.probe_every_batches, 0, 1000000);
      c.tracker.probe_offset_rad = s.number("probe_offset_rad", c.tracker.probe_offset_rad, Range::kPositive, "rad");
      c.failure_window_ns = ms_ns(s, "window_ms", c.failure_window_ns, Range::kPositive);
      c.failure_lost_contrast = s.number("lost_contrast", c.failure_lost_contrast, Range::kAny, "log-likelihood per event");
      c.failure_recovered_contrast = s.number("recovered_contrast", c.failure_recovered_contrast, Range::kAny, "log-likelihood per event");
      c.failure_freeze_map = s.boolean("freeze_map", c.failure_freeze_map);
      c.failure_relocalize_spread_rad = s.number("relocalize_spread_rad", c.failure_relocalize_spread_rad, Range::kNonNegative, "rad");
      c.failure_rollback = s.boolean("rollback", c.failure_rollback);
      c.failure_checkpoint_period_ns = ms_ns(s, "checkpoint_ms", c.failure_checkpoint_period_ns, Range::kPositive);
      c.failure_checkpoints = s.integer("checkpoints", c.failure_checkpoints, 1, 1000);
      c.failure_global_relocalize = s.boolean("global_relocalize", c.failure_global_relocalize);
      c.failure_global_period_ns = ms_ns(s, "global_period_ms", c.failure_global_period_ns, Range::kPositive);
      c.failure_global_min_gain = s.number("global_min_gain", c.failure_global_min_gain, Range::kPositive, "ratio");
      c.relocalization.axis_spacing_deg = s.number("global_axis_spacing_deg", c.relocalization.axis_spacing_deg, Range::kPositive, "deg");
      c.relocalization.roll_step_deg = s.number("global_roll_step_deg", c.relocalization.roll_step_deg, Range::kPositive, "deg");
      std::string why;
      if (!c.Validate(&why)) s.fail("invalid failure settings: " + why, "consistent settings");
    }
    if (top.has("output")) {
      const Section s = top.child("output", false, "a map");
      s.allow({"trajectory_ms", "snapshot_ms", "gamma", "low_percentile", "high_percentile", "transparent_unseen"});
      c.trajectory_period_ns = ms_ns(s, "trajectory_ms", c.trajectory_period_ns, Range::kPositive);
      c.snapshot_period_ns = ms_ns(s, "snapshot_ms", c.snapshot_period_ns, Range::kNonNegative);
      c.display.gamma = s.number("gamma", c.display.gamma, Range::kPositive, "");
      c.display.low_percentile = s.number("low_percentile", c.display.low_percentile, Range::kNonNegative, "%");
      c.display.high_percentile = s.number("high_percentile", c.display.high_percentile, Range::kPositive, "%");
      c.display.transparent_unseen = s.boolean("transparent_unseen", c.display.transparent_unseen);
      std::string why;
      if (!c.display.Validate(&why)) s.fail("invalid output settings: " + why, "consistent settings");
    }
  }
  if (resolved_yaml) *resolved_yaml = config_yaml(c);
  return c;
}

int run_mosaic(const MosaicArgs& args, std::ostream& out) {
  std::string resolved;
  MosaicConfig cfg = args.config.empty() ? default_mosaic_config() : load_mosaic_config(args.config, &resolved);
  if (args.particles > 0) cfg.tracker.num_particles = args.particles;
  if (args.batch > 0) cfg.tracker.batch_size = args.batch;
  if (args.stride > 0) cfg.event_stride = args.stride;
  cfg.tracker.event_stride = cfg.event_stride > 0 ? cfg.event_stride : (args.use_imu ? 4 : 1);
  // The adaptive particle count's floor: as configured, else 20 with the gyro and 40 without, never
  // above the particle count (a --particles below it gives a fixed count).
  cfg.tracker.min_particles = std::min(cfg.min_particles >= 0 ? cfg.min_particles : (args.use_imu ? 20 : 40),
                                       cfg.tracker.num_particles);
  cfg.use_gyro = args.use_imu;
  if (args.width > 0) {
    cfg.mosaic.width = args.width;
    cfg.mosaic.height = args.width / 2;
  }
  if (args.threads > 0) cfg.threads = args.threads;
  if (args.snapshot_s > 0) cfg.snapshot_period_ns = static_cast<int64_t>(std::llround(args.snapshot_s * 1e9));
  {
    std::string why;
    if (!cfg.mosaic.Validate(&why)) throw InputError(args.config.empty() ? "--width" : args.config, 0, why, "valid mosaic settings");
    if (!cfg.tracker.Validate(&why)) throw InputError(args.config.empty() ? "--particles/--batch" : args.config, 0, why, "valid tracker settings");
    if (!cfg.Validate(&why)) throw InputError(args.config.empty() ? "the defaults" : args.config, 0, why, "valid mosaic settings");
  }
  resolved = config_yaml(cfg);

  auto reader = open_dataset(args.dataset, args.dataset_options);
  const DatasetCalibration found = find_dataset_calibration(args.dataset, args.calib, *reader);
  if (!found.camera) throw InputError(args.dataset, 0, "no camera calibration", "--calib FILE (Kalibr camchain YAML or ECD calib.txt)");
  const calib::CameraCalibration cal = *found.camera;
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

  pipeline::MosaicPipeline mosaic(cfg, cal);
  // Diagnostics with the ground truth (--gt-bootstrap, --gt-mapping, --oracle-map).
  std::optional<Trajectory> diag_gt;
  if (args.gt_bootstrap || args.gt_mapping || args.oracle_map) {
    if (args.gt.empty())
      throw InputError(args.oracle_map ? "--oracle-map" : args.gt_mapping ? "--gt-mapping" : "--gt-bootstrap", 0,
                       "no ground truth given", "--gt FILE with it");
    diag_gt = load_trajectory(args.gt);
  }
  if (args.gt_bootstrap || args.gt_mapping) {
    mosaic.set_bootstrap_reference([&diag_gt](int64_t t_ns) -> std::optional<Eigen::Quaterniond> {
      const auto T = diag_gt->interpolate(t_ns);
      if (!T) return std::nullopt;
      return T->rotation;
    });
    mosaic.set_reference_for_mapping(args.gt_mapping);
  }
  if (args.oracle_map) {
    const fs::path scene = fs::path(args.dataset) / "scene_resolved.yaml";
    if (!fs::exists(scene))
      throw InputError(scene.string(), 0, "--oracle-map: no scene file", "a dataset written by evio simulate with a panorama scene");
    const simulator::SimulationConfig sc = simulator::load_simulation_config(scene.string());
    if (!sc.panorama) throw InputError(scene.string(), 0, "--oracle-map: the scene is not a panorama", "scene type panorama");
    mosaic.set_tracker_map_reference([&diag_gt, tex = sc.panorama, &cfg, &args](const Eigen::Matrix3d& R_m_b0, int64_t t0) {
      const auto g0 = diag_gt->interpolate(t0);
      if (!g0) throw InputError(args.gt, 0, "--oracle-map: no ground-truth pose at the first event", "a trajectory covering the events");
      const Eigen::Matrix3d R_w_m = g0->rotation.toRotationMatrix() * R_m_b0.transpose();
      const mapping::ImageF ref = simulator::panorama_log_reference(*tex, R_w_m, cfg.mosaic.width, cfg.mosaic.height);
      return std::vector<float>(ref.data(), ref.data() + ref.size());
    });
  }
  int snapshots = 0;
  mosaic.set_snapshot_callback([&](int64_t, const mapping::MosaicReconstruction& rec) {
    fs::create_directories(fs::path(args.out) / "snapshots");
    char name[64];
    std::snprintf(name, sizeof(name), "panorama_%06d.png", snapshots++);
    mapping::write_log_image_png8((fs::path(args.out) / "snapshots" / name).string(), rec.log_intensity, &rec.seen, cfg.display);
  });
  for (const ImuSample& m : imu) mosaic.add_imu(m);
  imu = {};  // the pipeline keeps what it needs

  // Stream the events in chunks: the pipeline keeps only the current bootstrap window or tracker batch.
  Progress progress("evio mosaic", args.progress, "events");
  const auto wall0 = std::chrono::steady_clock::now();
  const double cpu0 = process_cpu_s();
  EventBuffer chunk;
  int64_t events = 0, t0 = 0, t_last = 0;
  for (;;) {
    chunk.clear();
    if (reader->read_events(&chunk, size_t{1} << 18) == 0) break;
    const EventSpan span = chunk.span();
    if (events == 0) t0 = span.front().t_ns;
    t_last = span.back().t_ns;
    events += static_cast<int64_t>(span.size());
    mosaic.add_events(span);
    const double seq = static_cast<double>(t_last - t0) * 1e-9;
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
    progress.update(reader->progress(), mosaic.events_processed(), "real-time factor " + num(seq > 0 ? wall / seq : 0.0));
  }
  if (events == 0) throw InputError(args.dataset, 0, "no events", "a recording with events");
  const pipeline::MosaicResult result = mosaic.finish();
  const Trajectory& rotation = result.rotation;
  const mapping::MosaicReconstruction& rec = result.reconstruction;
  const pipeline::MosaicStats& ms = result.stats;
  const double processing_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  const double cpu_s = process_cpu_s() - cpu0;  // every thread's CPU time over the same span
  const double duration_s = static_cast<double>(t_last - t0) * 1e-9;
  const calib::Equirectangular proj(cfg.mosaic.width, cfg.mosaic.height);

  // ---- outputs -------------------------------------------------------------------------------
  write_tum((fs::path(args.out) / "rotation.tum").string(), rotation);
  mapping::write_log_image_png8((fs::path(args.out) / "panorama.png").string(), rec.log_intensity, &rec.seen, cfg.display);
  mapping::write_log_image_tiff((fs::path(args.out) / "panorama_log.tiff").string(), rec.log_intensity, &rec.seen);
  mapping::write_mask_png((fs::path(args.out) / "panorama_seen.png").string(), rec.seen);
  const auto& st = ms.tracker;
  const pipeline::MosaicBootstrapStats& bs = ms.bootstrap;
  const int64_t seen = ms.seen_pixels;
  {
    std::ofstream f((fs::path(args.out) / "stats.json").string());
    f << "{\n  \"dataset\": " << json_string(args.dataset) << ",\n  \"events\": " << events
      << ",\n  \"processing_time_s\": " << num(processing_s) << ",\n  \"sequence_duration_s\": " << num(duration_s)
      << ",\n  \"real_time_factor\": " << num(duration_s > 0 ? processing_s / duration_s : 0)
      << ",\n  \"events_per_s\": " << num(processing_s > 0 ? events / processing_s : 0)
      << ",\n  \"cpu_time_s\": " << num(cpu_s) << ",\n  \"events_per_cpu_s\": " << num(cpu_s > 0 ? events / cpu_s : 0)
      << ",\n  \"threads\": " << cfg.threads
      << ",\n  \"use_imu\": " << (args.use_imu ? "true" : "false") << ",\n  \"particles\": " << cfg.tracker.num_particles
      << ",\n  \"batch_size\": " << cfg.tracker.batch_size << ",\n  \"event_stride\": " << cfg.tracker.event_stride
      << ",\n  \"measurement_model\": \"" << frontend::rotation_measurement_model_name(cfg.tracker.measurement_model) << "\"" << ",\n  \"mosaic_size\": [" << cfg.mosaic.width << ", "
      << cfg.mosaic.height << "],\n  \"bootstrap\": {\"method\": \"" << (args.use_imu ? "gyro" : "contrast_maximisation")
      << "\", \"duration_s\": " << num((bs.t_end_ns - t0) * 1e-9) << ", \"cmax_windows\": " << bs.cmax_windows << ", \"short_windows\": " << bs.short_windows
      << ", \"tracker_contrast\": " << num(bs.tracker_contrast) << ", \"contrast_samples\": " << bs.contrast_samples << "}"
      << ",\n  \"tracker\": {\"events_used\": " << st.events_used << ", \"skipped_no_previous\": " << st.skipped_no_previous
      << ", \"skipped_unknown_map\": " << st.skipped_unknown_map << ", \"skipped_stride\": " << st.skipped_stride << ", \"batches\": " << st.batches
      << ", \"resamples\": " << st.resamples << ", \"linearized_batches\": " << st.linearized_batches << ", \"gyro_predictions\": " << st.gyro_predictions
      << ", \"mean_particles\": " << num(st.weighted_batches > 0 ? static_cast<double>(st.particle_batches) / static_cast<double>(st.weighted_batches) : 0.0)
      << ", \"particle_evaluations\": " << st.particle_evaluations << "}"
      << ",\n  \"mapper\": {\"events_mapped\": " << ms.events_mapped << ", \"reconstructions\": " << ms.reconstructions
      << ", \"seen_pixels\": " << seen << ", \"seen_fraction\": " << num(ms.seen_fraction)
      << "},\n  \"poisson\": {\"weighting\": \"" << mapping::poisson_weighting_name(rec.weighting)
      << "\", \"pcg_iterations\": " << rec.weighted_stats.iterations
      << ", \"initial_relative_residual\": " << num(rec.weighted_stats.initial_relative_residual)
      << ", \"relative_residual\": " << num(rec.weighted_stats.relative_residual)
      << ", \"converged\": " << (rec.weighted_stats.converged ? "true" : "false") << "}"
      << ",\n  \"snapshots\": " << snapshots << ",\n  \"quality\": {\"windows\": " << ms.quality_windows << ", \"windows_undecided\": " << ms.quality_windows_undecided
      << ", \"probe_contrast_min\": " << num(ms.quality_min) << ", \"probe_contrast_mean\": " << num(ms.quality_mean)
      << ", \"events_unmapped_lost\": " << ms.events_unmapped_lost << "},\n  \"tracking_lost_segments\": [";
    for (size_t k = 0; k < result.tracking_lost.size(); ++k) {
      const pipeline::MosaicLostSegment& g = result.tracking_lost[k];
      f << (k ? ", " : "") << "{\"t_begin_s\": " << format_seconds(g.t_begin_ns) << ", \"t_end_s\": " << format_seconds(g.t_end_ns)
        << ", \"recovered\": " << (g.recovered ? "true" : "false") << ", \"relocalizations\": " << g.relocalizations
        << ", \"global_searches\": " << g.global_searches << ", \"global_jumps\": " << g.global_jumps
        << ", \"map_rolled_back_to_s\": "
        << (g.map_rolled_back_to_ns == INT64_MIN ? std::string("null") : format_seconds(g.map_rolled_back_to_ns)) << "}";
    }
    f << "]\n}\n";
  }
  for (const pipeline::MosaicLostSegment& g : result.tracking_lost)
    out << "tracking lost " << format_seconds(g.t_begin_ns) << " s to " << format_seconds(g.t_end_ns) << " s ("
        << (g.recovered ? "recovered" : "not recovered") << ", " << g.relocalizations << " local spreads, "
        << g.global_searches << " global searches, " << g.global_jumps << " jumps"
        << (g.map_rolled_back_to_ns == INT64_MIN ? std::string() : ", map rolled back to " + format_seconds(g.map_rolled_back_to_ns) + " s")
        << ")\n";
  out << "events        " << events << " over " << num(duration_s) << " s, bootstrap "
      << (args.use_imu ? "gyro" : "contrast maximisation") << " " << num((bs.t_end_ns - t0) * 1e-9) << " s\n";
  out << "speed         " << num(processing_s) << " s processing, real-time factor "
      << num(duration_s > 0 ? processing_s / duration_s : 0) << " (one core), "
      << num(processing_s > 0 ? events / processing_s / 1e6 : 0) << " M events/s; CPU time " << num(cpu_s) << " s, "
      << num(cpu_s > 0 ? events / cpu_s / 1e6 : 0) << " M events per CPU second\n";
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
    size_t boot_poses = 0;  // the first boot_poses errors are of bootstrap poses (gyro / CMax rates)
    for (size_t k = first; k < rotation.size(); ++k) {
      const auto g = gt.interpolate(rotation[k].t_ns);
      if (!g) continue;
      const Eigen::Matrix3d E = g->rotation.toRotationMatrix().transpose() * A * rotation[k].T_w_b.rotation.toRotationMatrix();
      err.push_back(calib::so3_log(E).norm() * 180.0 / M_PI);
      if (rotation[k].t_ns <= bs.t_end_ns) boot_poses = err.size();
    }
    auto rms_max = [](const double* e, size_t n) {
      double s2 = 0, mx = 0;
      for (size_t k = 0; k < n; ++k) {
        s2 += e[k] * e[k];
        mx = std::max(mx, e[k]);
      }
      return std::pair<double, double>(n > 0 ? std::sqrt(s2 / static_cast<double>(n)) : 0.0, mx);
    };
    const auto [rms, mx] = rms_max(err.data(), err.size());
    // The bootstrap alone: its poses up to the tracking start, and its last one (the rotation the
    // tracker starts from: its error is baked into the bootstrap's part of the mosaic).
    const auto [boot_rms, boot_max] = rms_max(err.data(), boot_poses);
    const double boot_end = boot_poses > 0 ? err[boot_poses - 1] : 0.0;
    // Mosaic quality against the true panorama of a simulated dataset (scene_resolved.yaml).
    std::string quality_json;
    const fs::path scene = fs::path(args.dataset) / "scene_resolved.yaml";
    if (fs::exists(scene)) {
      const simulator::SimulationConfig sc = simulator::load_simulation_config(scene.string());
      if (sc.panorama) {
        const Eigen::Matrix3d R_w_m = A;  // mosaic frame -> simulator world
        const mapping::ImageF ref = simulator::panorama_log_reference(*sc.panorama, R_w_m, cfg.mosaic.width, cfg.mosaic.height);
        const mapping::ImageQuality q = mapping::compare_images(rec.log_intensity, ref, &rec.seen);
        auto quality = [&](const mapping::ImageQuality& x) {
          return "{\"psnr_db\": " + num(x.psnr_db) + ", \"ssim\": " + num(x.ssim) + ", \"rmse_log\": " + num(x.rmse) +
                 ", \"contrast_gain\": " + num(x.scale) + ", \"pixels\": " + std::to_string(x.pixels) +
                 ", \"fit\": \"affine in log intensity over the seen pixels\"}";
        };
        quality_json = ",\n  \"mosaic_quality\": " + quality(q);
        out << "mosaic vs true panorama: PSNR " << num(q.psnr_db) << " dB, SSIM " << num(q.ssim) << " over "
            << q.pixels << " seen pixels (affine log-intensity fit, " << mapping::poisson_weighting_name(rec.weighting)
            << " Poisson weighting)\n";
        if (rec.weighting == mapping::PoissonWeighting::kInformation) {
          // The unweighted solve that seeded the weighted one: before / after on the same mosaic.
          const mapping::ImageQuality u = mapping::compare_images(rec.unweighted_log_intensity, ref, &rec.seen);
          quality_json += ",\n  \"mosaic_quality_unweighted\": " + quality(u);
          out << "  unweighted Poisson: PSNR " << num(u.psnr_db) << " dB, SSIM " << num(u.ssim) << "\n";
        }
      }
    }
    std::ofstream f((fs::path(args.out) / "eval.json").string());
    f << "{\n  \"groundtruth\": " << json_string(args.gt) << ",\n  \"estimate\": "
      << json_string((fs::path(args.out) / "rotation.tum").string()) << ",\n  \"alignment\": \"initial orientation\""
      << ",\n  \"matched_poses\": " << err.size() << ",\n  \"rot_rms_deg\": " << num(rms) << ",\n  \"rot_max_deg\": " << num(mx)
      << ",\n  \"bootstrap\": {\"method\": \"" << (args.use_imu ? "gyro" : "contrast_maximisation") << "\", \"poses\": " << boot_poses
      << ", \"rot_rms_deg\": " << num(boot_rms) << ", \"rot_max_deg\": " << num(boot_max) << ", \"rot_end_deg\": " << num(boot_end) << "}"
      << quality_json << "\n}\n";
    out << "evaluation    rotation error rms " << num(rms) << " deg, max " << num(mx) << " deg over " << err.size()
        << " poses (initial orientation aligned)\n";
    out << "bootstrap     rotation error rms " << num(boot_rms) << " deg, max " << num(boot_max) << " deg, at its end "
        << num(boot_end) << " deg over " << boot_poses << " poses up to " << num((bs.t_end_ns - t0) * 1e-9) << " s\n";
  }
  out << "wrote " << args.out << "/rotation.tum, panorama.png, panorama_seen.png, panorama_log.tiff, stats.json, mosaic_config.yaml"
      << (args.gt.empty() ? "" : ", eval.json") << "\n";
  return 0;
}

}  // namespace evio::apps
