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
#include "evio/calib/equirectangular.h"
#include "evio/calib/error.h"
#include "evio/calib/geometry.h"
#include "evio/calib/log.h"
#include "evio/sensors/time.h"
#include "evio/sensors/trajectory.h"
#include "evio/calib/json.h"
#include "progress.h"

namespace evio::apps {
namespace {
}  // namespace
}  // namespace evio::apps
#include "evio/simulator/scene_config.h"
#include "evio/sensors/config_table.h"
#include "option_tables.h"

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

using C = MosaicConfig;

// The table of `--config` and `--set` (one declaration per key: reading, validation, the resolved
// config); the mosaic, particle filter, contrast maximisation, relocalisation and display options
// come with their own tables (option_tables.h).
const Table<C>& mosaic_config_table() {
  static const Table<C> table = [] {
    auto self = [](C& c) -> C& { return c; };
    Table<C> mosaic("mosaic settings");
    mosaic.include(gradient_mosaic_table(), &C::mosaic)
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
    tracker.include(rotation_particle_filter_table(), &C::tracker, {"event_stride", "min_particles"})
        .integer("event_stride", &C::event_stride, 0, 1000000)
        .integer("min_particles", &C::min_particles, -1, 1000000)
        .note("event_stride", "0: by input, 4 with --use-imu, 1 without")
        .note("min_particles", "-1: by input, 20 with --use-imu, 40 without");
    Table<C> bootstrap("bootstrap settings");
    bootstrap.duration_ms("duration_ms", &C::bootstrap_ns, Range::kNonNegative)
        .duration_ms("window_ms", &C::bootstrap_window_ns, Range::kPositive)
        .integer("window_events", &C::bootstrap_window_events, 1000, 100000000)
        .include(rotational_cmax_table(), &C::cmax, {"width", "height", "focal_px"})  // those: the camera's
        .boolean("calibrate_contrast", &C::calibrate_contrast)
        .number("min_contrast_ratio", &C::min_contrast_ratio, Range::kUnit, "")
        .integer("calibration_sample_stride", &C::calibration_sample_stride, 1, 1000000)
        .integer("calibration_min_texel_updates", &C::calibration_min_texel_updates, 0, 1000000)
        .integer("calibration_min_samples", &C::calibration_min_samples, 1, 100000000)
        .duration_ms("gyro_window_ms", &C::gyro_bootstrap_window_ns, Range::kPositive)
        .duration_ms("gyro_step_ms", &C::gyro_integration_step_ns, Range::kPositive);
    Table<C> failure("failure settings");
    failure.integer("probe_every_batches", [](C& c) -> int& { return c.tracker.probe_every_batches; }, 0, 1000000)
        .number("probe_offset_rad", [](C& c) -> double& { return c.tracker.probe_offset_rad; }, Range::kPositive, "rad")
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
        .include(relocalization_table(), &C::relocalization, {}, "global_");
    Table<C> output("output settings");
    output.duration_ms("trajectory_ms", &C::trajectory_period_ns, Range::kPositive)
        .duration_ms("snapshot_ms", &C::snapshot_period_ns, Range::kNonNegative)
        .include(log_image_display_table(), &C::display);
    Table<C> imu("IMU settings");
    imu.duration_ms("wait_ms", &C::imu_wait_ns, Range::kNonNegative);
    Table<C> top("mosaic pipeline settings");
    top.section("mosaic", mosaic, self)
        .section("tracker", tracker, self)
        .section("bootstrap", bootstrap, self)
        .section("failure", failure, self)
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
                               "a mosaic config YAML (see README.md, `evio mosaic`)");
  if (resolved_yaml) *resolved_yaml = mosaic_config_text(c);
  return c;
}

std::string mosaic_config_text(const MosaicConfig& c) {
  return config_text(mosaic_config_table(), c, kMosaicConfigHeader);
}

int run_mosaic(const MosaicArgs& args, std::ostream& out) {
  MosaicConfig cfg = load_mosaic_config(args.config, nullptr, args.set);
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
  // The resolved config holds the values used, the stride and particle floor as chosen for this input.
  cfg.event_stride = cfg.tracker.event_stride;
  cfg.min_particles = cfg.tracker.min_particles;
  const std::string resolved = mosaic_config_text(cfg);

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
    diag_gt = read_trajectory(args.gt);
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
    progress.update(reader->progress(), mosaic.events_processed(), "real-time factor " + json_number(seq > 0 ? wall / seq : 0.0, 9));
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
    // The model block: the tracker's motion and measurement models as they ran. measurement_model
    // auto is relative_motion when the gyro drives the prediction or the particles carry their own
    // velocities (particle_velocity without gyro), previous_mean otherwise (rotation_particle_filter.h).
    const frontend::RotationParticleFilterOptions& to = cfg.tracker;
    const bool gyro = st.gyro_predictions > 0;
    const bool pv = to.motion_model == frontend::RotationMotionModel::kParticleVelocity && !gyro;
    const frontend::RotationMotionModel motion_used = gyro ? frontend::RotationMotionModel::kRandomWalk : to.motion_model;
    const bool relative = to.measurement_model == frontend::RotationMeasurementModel::kRelativeMotion ||
                          (to.measurement_model == frontend::RotationMeasurementModel::kAuto && (gyro || pv));
    const std::string measurement = relative ? "relative_motion" : "previous_mean";
    const std::string why = to.measurement_model != frontend::RotationMeasurementModel::kAuto ? "set in the config"
                            : gyro ? "auto: the gyro drives the prediction"
                            : pv   ? "auto: the particles carry their own velocities (particle_velocity, no gyro)"
                                   : "auto: no gyro and no particle velocities";
    const std::string motion = gyro ? std::string("gyro") : frontend::rotation_motion_model_name(motion_used);
    const double mean_particles = st.weighted_batches > 0 ? static_cast<double>(st.particle_batches) / static_cast<double>(st.weighted_batches) : 0.0;
    std::ofstream f((fs::path(args.out) / "stats.json").string());
    f << "{\n  \"dataset\": " << json_string(args.dataset) << ",\n  \"model\": {\"summary\": "
      << json_string("rotation, " + measurement + " measurement (" + why + "), " + motion + " prediction, " + json_number(mean_particles, 9) +
                     " particles on average")
      << ", \"measurement\": {\"option\": \"" << frontend::rotation_measurement_model_name(to.measurement_model)
      << "\", \"resolved\": \"" << measurement << "\", \"reason\": " << json_string(why) << "}, \"motion\": {\"option\": \""
      << frontend::rotation_motion_model_name(to.motion_model) << "\", \"resolved\": \"" << motion
      << "\", \"gyro_predictions\": " << st.gyro_predictions << "}, \"particles\": {\"configured\": " << to.num_particles
      << ", \"mean\": " << json_number(mean_particles, 9) << "}}"
      << ",\n  \"events\": " << events
      << ",\n  \"processing_time_s\": " << json_number(processing_s, 9) << ",\n  \"sequence_duration_s\": " << json_number(duration_s, 9)
      << ",\n  \"real_time_factor\": " << json_number(duration_s > 0 ? processing_s / duration_s : 0, 9)
      << ",\n  \"events_per_s\": " << json_number(processing_s > 0 ? events / processing_s : 0, 9)
      << ",\n  \"cpu_time_s\": " << json_number(cpu_s, 9) << ",\n  \"events_per_cpu_s\": " << json_number(cpu_s > 0 ? events / cpu_s : 0, 9)
      << ",\n  \"threads\": " << cfg.threads
      << ",\n  \"use_imu\": " << (args.use_imu ? "true" : "false") << ",\n  \"particles\": " << cfg.tracker.num_particles
      << ",\n  \"batch_size\": " << cfg.tracker.batch_size << ",\n  \"event_stride\": " << cfg.tracker.event_stride
      << ",\n  \"measurement_model\": \"" << frontend::rotation_measurement_model_name(cfg.tracker.measurement_model) << "\"" << ",\n  \"mosaic_size\": [" << cfg.mosaic.width << ", "
      << cfg.mosaic.height << "],\n  \"bootstrap\": {\"method\": \"" << (args.use_imu ? "gyro" : "contrast_maximisation")
      << "\", \"duration_s\": " << json_number((bs.t_end_ns - t0) * 1e-9, 9) << ", \"cmax_windows\": " << bs.cmax_windows << ", \"short_windows\": " << bs.short_windows
      << ", \"tracker_contrast\": " << json_number(bs.tracker_contrast, 9) << ", \"contrast_samples\": " << bs.contrast_samples << "}"
      << ",\n  \"tracker\": {\"events_used\": " << st.events_used << ", \"skipped_no_previous\": " << st.skipped_no_previous
      << ", \"skipped_unknown_map\": " << st.skipped_unknown_map << ", \"skipped_stride\": " << st.skipped_stride << ", \"batches\": " << st.batches
      << ", \"resamples\": " << st.resamples << ", \"linearized_batches\": " << st.linearized_batches << ", \"gyro_predictions\": " << st.gyro_predictions
      << ", \"mean_particles\": " << json_number(st.weighted_batches > 0 ? static_cast<double>(st.particle_batches) / static_cast<double>(st.weighted_batches) : 0.0, 9)
      << ", \"particle_evaluations\": " << st.particle_evaluations << "}"
      << ",\n  \"mapper\": {\"events_mapped\": " << ms.events_mapped << ", \"reconstructions\": " << ms.reconstructions
      << ", \"seen_pixels\": " << seen << ", \"seen_fraction\": " << json_number(ms.seen_fraction, 9)
      << "},\n  \"poisson\": {\"weighting\": \"" << mapping::poisson_weighting_name(rec.weighting)
      << "\", \"pcg_iterations\": " << rec.weighted_stats.iterations
      << ", \"initial_relative_residual\": " << json_number(rec.weighted_stats.initial_relative_residual, 9)
      << ", \"relative_residual\": " << json_number(rec.weighted_stats.relative_residual, 9)
      << ", \"converged\": " << (rec.weighted_stats.converged ? "true" : "false") << "}"
      << ",\n  \"snapshots\": " << snapshots << ",\n  \"quality\": {\"windows\": " << ms.quality_windows << ", \"windows_undecided\": " << ms.quality_windows_undecided
      << ", \"probe_contrast_min\": " << json_number(ms.quality_min, 9) << ", \"probe_contrast_mean\": " << json_number(ms.quality_mean, 9)
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
  out << "events        " << events << " over " << json_number(duration_s, 9) << " s, bootstrap "
      << (args.use_imu ? "gyro" : "contrast maximisation") << " " << json_number((bs.t_end_ns - t0) * 1e-9, 9) << " s\n";
  out << "speed         " << json_number(processing_s, 9) << " s processing, real-time factor "
      << json_number(duration_s > 0 ? processing_s / duration_s : 0, 9) << " (one core), "
      << json_number(processing_s > 0 ? events / processing_s / 1e6 : 0, 9) << " M events/s; CPU time " << json_number(cpu_s, 9) << " s, "
      << json_number(cpu_s > 0 ? events / cpu_s / 1e6 : 0, 9) << " M events per CPU second\n";
  out << "mosaic        " << cfg.mosaic.width << "x" << cfg.mosaic.height << ", "
      << json_number(100.0 * static_cast<double>(seen) / static_cast<double>(rec.seen.size()), 9) << "% seen\n";

  if (!args.gt.empty()) {
    const Trajectory gt = read_trajectory(args.gt);
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
        const Eigen::Matrix3d& R_w_m = A;  // mosaic frame -> simulator world
        const mapping::ImageF ref = simulator::panorama_log_reference(*sc.panorama, R_w_m, cfg.mosaic.width, cfg.mosaic.height);
        const mapping::ImageQuality q = mapping::compare_images(rec.log_intensity, ref, &rec.seen);
        auto quality = [&](const mapping::ImageQuality& x) {
          return "{\"psnr_db\": " + json_number(x.psnr_db, 9) + ", \"ssim\": " + json_number(x.ssim, 9) + ", \"rmse_log\": " + json_number(x.rmse, 9) +
                 ", \"contrast_gain\": " + json_number(x.scale, 9) + ", \"pixels\": " + std::to_string(x.pixels) +
                 ", \"fit\": \"affine in log intensity over the seen pixels\"}";
        };
        quality_json = ",\n  \"mosaic_quality\": " + quality(q);
        out << "mosaic vs true panorama: PSNR " << json_number(q.psnr_db, 9) << " dB, SSIM " << json_number(q.ssim, 9) << " over "
            << q.pixels << " seen pixels (affine log-intensity fit, " << mapping::poisson_weighting_name(rec.weighting)
            << " Poisson weighting)\n";
        if (rec.weighting == mapping::PoissonWeighting::kInformation) {
          // The unweighted solve that seeded the weighted one: before / after on the same mosaic.
          const mapping::ImageQuality u = mapping::compare_images(rec.unweighted_log_intensity, ref, &rec.seen);
          quality_json += ",\n  \"mosaic_quality_unweighted\": " + quality(u);
          out << "  unweighted Poisson: PSNR " << json_number(u.psnr_db, 9) << " dB, SSIM " << json_number(u.ssim, 9) << "\n";
        }
      }
    }
    std::ofstream f((fs::path(args.out) / "eval.json").string());
    f << "{\n  \"groundtruth\": " << json_string(args.gt) << ",\n  \"estimate\": "
      << json_string((fs::path(args.out) / "rotation.tum").string()) << ",\n  \"alignment\": \"initial orientation\""
      << ",\n  \"matched_poses\": " << err.size() << ",\n  \"rot_rms_deg\": " << json_number(rms, 9) << ",\n  \"rot_max_deg\": " << json_number(mx, 9)
      << ",\n  \"bootstrap\": {\"method\": \"" << (args.use_imu ? "gyro" : "contrast_maximisation") << "\", \"poses\": " << boot_poses
      << ", \"rot_rms_deg\": " << json_number(boot_rms, 9) << ", \"rot_max_deg\": " << json_number(boot_max, 9) << ", \"rot_end_deg\": " << json_number(boot_end, 9) << "}"
      << quality_json << "\n}\n";
    out << "evaluation    rotation error rms " << json_number(rms, 9) << " deg, max " << json_number(mx, 9) << " deg over " << err.size()
        << " poses (initial orientation aligned)\n";
    out << "bootstrap     rotation error rms " << json_number(boot_rms, 9) << " deg, max " << json_number(boot_max, 9) << " deg, at its end "
        << json_number(boot_end, 9) << " deg over " << boot_poses << " poses up to " << json_number((bs.t_end_ns - t0) * 1e-9, 9) << " s\n";
  }
  out << "wrote " << args.out << "/rotation.tum, panorama.png, panorama_seen.png, panorama_log.tiff, stats.json, mosaic_config.yaml"
      << (args.gt.empty() ? "" : ", eval.json") << "\n";
  return 0;
}

}  // namespace evio::apps
