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

#include "evio/sensors/dataset_calibration.h"
#include "eval_command.h"
#include "evio/backend/option_tables.h"
#include "evio/calib/equirectangular.h"
#include "evio/calib/error.h"
#include "evio/calib/geometry.h"
#include "evio/calib/log.h"
#include "evio/sensors/time.h"
#include "evio/sensors/trajectory.h"
#include "evio/calib/json.h"
#include "progress.h"

#include "evio/simulator/scene_config.h"
#include "evio/sensors/config_table.h"
#include "evio/frontend/option_tables.h"
#include "evio/mapping/option_tables.h"
#include "mosaic_outputs.h"

namespace evio::apps {

namespace fs = std::filesystem;
using namespace yaml_config;  // NOLINT

MosaicConfig default_mosaic_config() {
  MosaicConfig c;
  c.display.gamma = 1.0;
  // Unseen texels transparent in panorama.png and the snapshots (black ones would look like dark texels).
  c.display.transparent_unseen = true;
  // 100 events per particle update (the library's default is 10): prediction, weighting and
  // resampling amortised over more events, as accurate (docs/results/mosaic.md).
  c.tracker.batch_size = 100;
  // Each particle carries its angular velocity; without the gyro the relative-motion measurement
  // moves the pixel's previous direction back with it (with the gyro the gyro drives). Chosen over
  // previous_mean by the events-only errors in docs/results/mosaic.md.
  c.tracker.motion_model = frontend::RotationMotionModel::kParticleVelocity;
  return c;
}

namespace {

using C = MosaicConfig;

// The table of `--config` and `--set` (one declaration per key: reading, validation, the resolved
// config); the mosaic, particle filter, contrast maximisation, relocalisation and display options
// come with their own tables (evio/frontend/option_tables.h, evio/mapping/option_tables.h).
const Table<C>& mosaic_config_table() {
  static const Table<C> table = [] {
    auto self = [](C& c) -> C& { return c; };
    Table<C> mosaic("mosaic settings");
    mosaic.include(mapping::gradient_mosaic_table(), &C::mosaic)
        .integer("reconstruct_events", &C::reconstruct_events, 1, 1000000000)
        .duration_ms("reconstruct_ms", &C::reconstruct_period_ns, Range::kPositive)
        .integer("reconstruct_latency_events", &C::reconstruct_latency_events, 0, 1000000000)
        .integer("threads", &C::threads, 1, 2)
        .duration_ms("footprint_ms", &C::footprint_period_ns, Range::kPositive)
        .integer("full_reconstruct_every", &C::full_reconstruct_every, 1, 1000000)
        .choice("poisson_weighting", &C::output_weighting,
                {{"none", mapping::PoissonWeighting::kNone}, {"information", mapping::PoissonWeighting::kInformation}})
        .finish([](const Section& s, C& c) {
          if (!s.has("height")) c.mosaic.height = c.mosaic.width / 2;  // default: the full sphere
        });
    // event_stride 0 and min_particles -1: chosen by input at run time (mosaic_command.h).
    Table<C> tracker("tracker settings");
    tracker.include(frontend::rotation_particle_filter_table(), &C::tracker,
                    {"event_stride", "min_particles", "probe_every_batches", "probe_offset_rad"})
        .integer("event_stride", &C::event_stride, 0, 1000000)
        .integer("min_particles", &C::min_particles, -1, 1000000)
        .choice("method", &C::tracker_method,
                {{"pf", pipeline::MosaicTracker::kParticleFilter},
                 {"odometry", pipeline::MosaicTracker::kOdometry},
                 {"odometry+pf", pipeline::MosaicTracker::kOdometryParticleFilter},
                 {"cmax_slam", pipeline::MosaicTracker::kCmaxSlam},
                 {"auto", pipeline::MosaicTracker::kAuto}})
        .number("odometry_noise_rad_per_sqrt_s", &C::odometry_noise_rad_per_sqrt_s, Range::kPositive, "rad/sqrt(s)")
        .note("event_stride", "0: by input, 4 with --use-imu, 1 without")
        .note("min_particles", "-1: by input, 20 with --use-imu, 40 without")
        .note("method", "auto: cmax_slam events only, pf with --use-imu");
    Table<C> bootstrap("bootstrap settings");
    bootstrap.duration_ms("duration_ms", &C::bootstrap_ns, Range::kNonNegative)
        .duration_ms("window_ms", &C::bootstrap_window_ns, Range::kPositive)
        .integer("window_events", &C::bootstrap_window_events, 1000, 100000000)
        .integer("min_window_events", &C::bootstrap_min_window_events, 0, 100000000)
        .duration_ms("max_window_ms", &C::bootstrap_max_window_ns, Range::kPositive)
        .note("min_window_events", "0: no floor; a window with fewer events by window_ms stays open up to max_window_ms")
        .number("min_contrast_gain", &C::bootstrap_min_contrast_gain, Interval::at_least(1), "ratio")
        .integer("rate_max_events", &C::bootstrap_rate_max_events, 0, 100000000)
        .note("rate_max_events", "0: all of the window's events")
        .include(mapping::rotational_cmax_table(), &C::cmax, {"width", "height", "focal_px"})  // those: the camera's
        .boolean("calibrate_contrast", &C::calibrate_contrast)
        .number("min_contrast_ratio", &C::min_contrast_ratio, Range::kUnit, "")
        .integer("calibration_sample_stride", &C::calibration_sample_stride, 1, 1000000)
        .integer("calibration_min_texel_updates", &C::calibration_min_texel_updates, 0, 1000000)
        .integer("calibration_min_samples", &C::calibration_min_samples, 1, 100000000)
        .duration_ms("gyro_window_ms", &C::gyro_bootstrap_window_ns, Range::kPositive)
        .duration_ms("gyro_step_ms", &C::gyro_integration_step_ns, Range::kPositive);
    Table<C> failure("failure settings");
    failure.include(frontend::rotation_probe_table(), &C::tracker)
        .duration_ms("window_ms", &C::failure_window_ns, Range::kPositive)
        .integer("min_events", &C::failure_min_events, 0, 1000000000)
        .number("min_rate_ratio", &C::failure_min_rate_ratio, Range::kNonNegative, "")
        .integer("lost_windows", &C::failure_lost_windows, 1, 1000000)
        .number("lost_contrast", &C::failure_lost_contrast, Range::kAny, "log-likelihood per event")
        .number("recovered_contrast", &C::failure_recovered_contrast, Range::kAny, "log-likelihood per event")
        .boolean("freeze_map", &C::failure_freeze_map)
        .number("relocalize_spread_rad", &C::failure_relocalize_spread_rad, Range::kNonNegative, "rad")
        .boolean("rollback", &C::failure_rollback)
        .duration_ms("checkpoint_ms", &C::failure_checkpoint_period_ns, Range::kPositive)
        .integer("checkpoints", &C::failure_checkpoints, 1, 1000)
        .boolean("global_relocalize", &C::failure_global_relocalize)
        .duration_ms("global_period_ms", &C::failure_global_period_ns, Range::kPositive)
        .number("global_min_gain", &C::failure_global_min_gain, Range::kPositive, "ratio")
        .include(mapping::relocalization_table(), &C::relocalization, {}, "global_");
    Table<C> slam("CMax-SLAM back-end settings (tracker.method cmax_slam)");
    slam.include(backend::cmax_slam_table(), &C::cmax_slam, {"panorama_width", "panorama_height"})  // those: the mosaic's
        .note("knot_spacing_ms", "the rotation spline's knot spacing");
    Table<C> output("output settings");
    output.duration_ms("trajectory_ms", &C::trajectory_period_ns, Range::kPositive)
        .duration_ms("snapshot_ms", &C::snapshot_period_ns, Range::kNonNegative)
        .include(mapping::log_image_display_table(), &C::display);
    Table<C> imu("IMU settings");
    imu.duration_ms("wait_ms", &C::imu_wait_ns, Range::kNonNegative);
    Table<C> top("mosaic pipeline settings");
    top.section("mosaic", mosaic, self)
        .section("tracker", tracker, self)
        .section("bootstrap", bootstrap, self)
        .section("failure", failure, self)
        .section("cmax_slam", slam, self)
        .section("output", output, self)
        .section("imu", imu, self)
        .ignored("description")
        .finish([](const Section& s, C& c) {
          // The tracker's C is the mosaic's unless tracker.contrast_threshold says otherwise.
          if (!has_path(s, "tracker.contrast_threshold")) c.tracker.contrast_threshold = c.mosaic.contrast_threshold;
        })
        .validate();
    return top;
  }();
  return table;
}

const char* kMosaicConfigHeader =
    "# evio mosaic configuration, resolved: every key with the value used (comments: unit and range).\n"
    "# Readable by `evio mosaic --config`.\n";

// CPU time of the process (all threads), s.
double process_cpu_s() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

}  // namespace

MosaicConfig load_mosaic_config(const std::string& path, std::string* resolved_yaml,
                                const std::vector<std::string>& sets) {
  MosaicConfig c = read_config(mosaic_config_table(), default_mosaic_config(), path, sets,
                               "a mosaic config YAML (see docs/commands/mosaic.md)");
  if (resolved_yaml) *resolved_yaml = mosaic_config_text(c);
  return c;
}

std::string mosaic_config_text(const MosaicConfig& c) {
  return config_text(mosaic_config_table(), c, kMosaicConfigHeader);
}

namespace {

// The config as it runs: --config and --set, the command-line overrides, the tracker's settings
// that depend on the input (frontend::resolve_input_defaults), validated. The resolved config
// holds the values used.
MosaicConfig resolve_mosaic_config(const MosaicArgs& args) {
  MosaicConfig cfg = load_mosaic_config(args.config, nullptr, args.set);
  if (args.particles > 0) cfg.tracker.num_particles = args.particles;
  if (args.batch > 0) cfg.tracker.batch_size = args.batch;
  if (args.stride > 0) cfg.event_stride = args.stride;
  frontend::resolve_input_defaults(&cfg.tracker, args.use_imu, cfg.event_stride, cfg.min_particles);
  cfg.use_gyro = args.use_imu;
  cfg.tracker_reason = pipeline::mosaic_tracker_reason(cfg.tracker_method, cfg.use_gyro);
  cfg.tracker_method = pipeline::resolve_mosaic_tracker(cfg.tracker_method, cfg.use_gyro);
  if (args.width > 0) {
    cfg.mosaic.width = args.width;
    cfg.mosaic.height = args.width / 2;
  }
  if (args.threads > 0) cfg.threads = args.threads;
  if (args.snapshot_s > 0) cfg.snapshot_period_ns = static_cast<int64_t>(std::llround(args.snapshot_s * 1e9));
  std::string why;
  if (!cfg.mosaic.Validate(&why)) throw InputError(args.config.empty() ? "--width" : args.config, 0, why, "valid mosaic settings");
  if (!cfg.tracker.Validate(&why)) throw InputError(args.config.empty() ? "--particles/--batch" : args.config, 0, why, "valid tracker settings");
  if (!cfg.Validate(&why)) throw InputError(args.config.empty() ? "the defaults" : args.config, 0, why, "valid mosaic settings");
  cfg.event_stride = cfg.tracker.event_stride;
  cfg.min_particles = cfg.tracker.min_particles;
  return cfg;
}

// Diagnostics with the ground truth (--gt-bootstrap, --gt-mapping, --oracle-map). *gt holds the
// ground truth for the pipeline's callbacks: it must outlive the pipeline's run.
void attach_mosaic_diagnostics(const MosaicArgs& args, const MosaicConfig& cfg, std::optional<Trajectory>* gt,
                               pipeline::MosaicPipeline* mosaic) {
  if (!args.gt_bootstrap && !args.gt_mapping && !args.oracle_map) return;
  if (args.gt.empty())
    throw InputError(args.oracle_map ? "--oracle-map" : args.gt_mapping ? "--gt-mapping" : "--gt-bootstrap", 0,
                     "no ground truth given", "--gt FILE with it");
  *gt = read_trajectory(args.gt);
  if (args.gt_bootstrap || args.gt_mapping) {
    mosaic->set_bootstrap_reference([gt](int64_t t_ns) -> std::optional<Eigen::Quaterniond> {
      const auto T = (*gt)->interpolate(t_ns);
      if (!T) return std::nullopt;
      return T->rotation;
    });
    mosaic->set_reference_for_mapping(args.gt_mapping);
  }
  if (!args.oracle_map) return;
  const fs::path scene = fs::path(args.dataset) / "scene_resolved.yaml";
  if (!fs::exists(scene))
    throw InputError(scene.string(), 0, "--oracle-map: no scene file", "a dataset written by evio simulate with a panorama scene");
  const simulator::SimulationConfig sc = simulator::load_simulation_config(scene.string());
  if (!sc.panorama) throw InputError(scene.string(), 0, "--oracle-map: the scene is not a panorama", "scene type panorama");
  mosaic->set_tracker_map_reference([gt, tex = sc.panorama, width = cfg.mosaic.width, height = cfg.mosaic.height,
                                     gt_path = args.gt](const Eigen::Matrix3d& R_m_b0, int64_t t0) {
    const auto g0 = (*gt)->interpolate(t0);
    if (!g0) throw InputError(gt_path, 0, "--oracle-map: no ground-truth pose at the first event", "a trajectory covering the events");
    const Eigen::Matrix3d R_w_m = g0->rotation.toRotationMatrix() * R_m_b0.transpose();
    const mapping::ImageF ref = simulator::panorama_log_reference(*tex, R_w_m, width, height);
    return std::vector<float>(ref.data(), ref.data() + ref.size());
  });
}

// The events in chunks (the pipeline keeps only the current bootstrap window or tracker batch).
MosaicRun stream_events(const MosaicArgs& args, DatasetReader* reader, pipeline::MosaicPipeline* mosaic) {
  Progress progress("evio mosaic", args.progress, "events");
  const auto wall0 = std::chrono::steady_clock::now();
  const double cpu0 = process_cpu_s();
  MosaicRun run;
  EventBuffer chunk;
  for (;;) {
    chunk.clear();
    if (reader->read_events(&chunk, size_t{1} << 18) == 0) break;
    const EventSpan span = chunk.span();
    if (run.events == 0) run.t0_ns = span.front().t_ns;
    run.t_last_ns = span.back().t_ns;
    run.events += static_cast<int64_t>(span.size());
    mosaic->add_events(span);
    const double seq = static_cast<double>(run.t_last_ns - run.t0_ns) * 1e-9;
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
    progress.update(reader->progress(), mosaic->events_processed(), "real-time factor " + json_number(seq > 0 ? wall / seq : 0.0, 9));
  }
  if (run.events == 0) throw InputError(args.dataset, 0, "no events", "a recording with events");
  run.result = mosaic->finish();
  run.processing_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  run.cpu_s = process_cpu_s() - cpu0;  // every thread's CPU time over the same span
  return run;
}

// The CMax-SLAM back-end's global pass moved the trajectory after the events were mapped: a
// second pass over the recording maps them again along the refined trajectory (the gradient
// mosaic and its reconstruction; the trajectory, the event map and the statistics stay the first
// pass's). Its time counts in the run's.
void remap_along_trajectory(const MosaicArgs& args, const MosaicConfig& cfg, const calib::CameraCalibration& camera, MosaicRun* run) {
  pipeline::MosaicPipelineOptions o = cfg;
  o.tracker_method = pipeline::MosaicTracker::kOdometry;
  o.use_gyro = false;
  pipeline::MosaicPipeline mosaic(o, camera);
  const Trajectory& rotation = run->result.rotation;
  mosaic.set_bootstrap_reference([&rotation](int64_t t_ns) -> std::optional<Eigen::Quaterniond> {
    const auto T = rotation.interpolate(t_ns);
    if (!T) return std::nullopt;
    return T->rotation;
  });
  auto reader = open_dataset(args.dataset, args.dataset_options);
  MosaicRun second = stream_events(args, reader.get(), &mosaic);
  pipeline::MosaicResult& r = run->result;
  r.reconstruction = std::move(second.result.reconstruction);
  r.stats.events_mapped = second.result.stats.events_mapped;
  r.stats.seen_pixels = second.result.stats.seen_pixels;
  r.stats.seen_fraction = second.result.stats.seen_fraction;
  run->processing_s += second.processing_s;
  run->cpu_s += second.cpu_s;
}

}  // namespace

int run_mosaic(const MosaicArgs& args, std::ostream& out) {
  const MosaicConfig cfg = resolve_mosaic_config(args);
  auto reader = open_dataset(args.dataset, args.dataset_options);
  const DatasetCalibration found = find_dataset_calibration(args.dataset, args.calib, *reader);
  if (!found.camera) throw InputError(args.dataset, 0, "no camera calibration", "--calib FILE (Kalibr camchain YAML or ECD calib.txt)");
  std::vector<ImuSample> imu;
  if (args.use_imu) {
    imu = reader->read_imu();
    if (imu.size() < 2) throw InputError(args.dataset, 0, "--use-imu: the dataset has no IMU samples", "a recording with IMU");
  }
  fs::create_directories(args.out);
  {
    std::ofstream f((fs::path(args.out) / "mosaic_config.yaml").string());
    f << mosaic_config_text(cfg);
  }

  pipeline::MosaicPipeline mosaic(cfg, *found.camera);
  std::optional<Trajectory> diag_gt;
  attach_mosaic_diagnostics(args, cfg, &diag_gt, &mosaic);
  int snapshots = 0;
  mosaic.set_snapshot_callback([&](int64_t, const mapping::MosaicReconstruction& rec) {
    fs::create_directories(fs::path(args.out) / "snapshots");
    char name[64];
    std::snprintf(name, sizeof(name), "panorama_%06d.png", snapshots++);
    mapping::write_log_image_png8((fs::path(args.out) / "snapshots" / name).string(), rec.log_intensity, &rec.seen, cfg.display);
  });
  for (const ImuSample& m : imu) mosaic.add_imu(m);
  imu = {};  // the pipeline keeps what it needs

  MosaicRun run = stream_events(args, reader.get(), &mosaic);
  run.snapshots = snapshots;
  if (run.result.stats.cmax_slam.global_refined) remap_along_trajectory(args, cfg, *found.camera, &run);
  write_mosaic_outputs(args, cfg, run, out);
  if (!args.gt.empty()) evaluate_mosaic(args, cfg, run, out);
  out << "wrote " << args.out << "/rotation.tum, panorama.png, panorama_seen.png, panorama_log.tiff, stats.json, mosaic_config.yaml"
      << (args.gt.empty() ? "" : ", eval.json") << "\n";
  return 0;
}

}  // namespace evio::apps
