#include "mosaic_outputs.h"

#include <algorithm>
#include <climits>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <optional>
#include <ostream>
#include <string>
#include <utility>
#include <vector>

#include <yaml-cpp/yaml.h>

#include "evio/calib/error.h"
#include "evio/calib/json.h"
#include "evio/evaluation/rotation_error.h"
#include "evio/mapping/mosaic_image.h"
#include "evio/sensors/time.h"
#include "evio/sensors/trajectory.h"
#include "evio/simulator/scene_config.h"
#include "evio/simulator/texture.h"

namespace evio::apps {
namespace {
namespace fs = std::filesystem;

// The model block: the tracker's motion and measurement models as they ran. measurement_model
// auto is relative_motion when the gyro drives the prediction or the particles carry their own
// velocities (particle_velocity without gyro), previous_mean otherwise (rotation_particle_filter.h).
std::string model_json(const MosaicConfig& cfg, const frontend::RotationParticleFilterStats& st) {
  const frontend::RotationParticleFilterOptions& to = cfg.tracker;
  const bool gyro = st.gyro_predictions > 0;
  const bool pv = to.motion_model == frontend::RotationMotionModel::kParticleVelocity && !gyro;
  const frontend::RotationMotionModel motion_used = gyro ? frontend::RotationMotionModel::kRandomWalk : to.motion_model;
  const bool relative = to.measurement_model == frontend::RotationMeasurementModel::kRelativeMotion ||
                        (to.measurement_model == frontend::RotationMeasurementModel::kAuto && (gyro || pv));
  const std::string measurement = relative ? "relative_motion" : "previous_mean";
  // With tracker.method odometry+pf and no gyro, the filter's "gyro" samples are the odometry's rates.
  const bool odometry = cfg.tracker_method != pipeline::MosaicTracker::kParticleFilter && !cfg.use_gyro;
  const std::string driver = odometry ? "contrast-maximisation odometry" : "gyro";
  const std::string why = to.measurement_model != frontend::RotationMeasurementModel::kAuto ? "set in the config"
                          : gyro ? "auto: the " + driver + " drives the prediction"
                          : pv   ? "auto: the particles carry their own velocities (particle_velocity, no gyro)"
                                 : "auto: no gyro and no particle velocities";
  const std::string motion = gyro ? (odometry ? std::string("odometry") : std::string("gyro")) : frontend::rotation_motion_model_name(motion_used);
  const double mean_particles = st.weighted_batches > 0 ? static_cast<double>(st.particle_batches) / static_cast<double>(st.weighted_batches) : 0.0;
  // The tracker as it ran and why (tracker.method auto: chosen by the input).
  const std::string tail = ", \"tracker\": \"" + std::string(pipeline::mosaic_tracker_name(cfg.tracker_method)) +
                           "\", \"tracker_choice\": " + json_string(cfg.tracker_reason) + "}";
  if (cfg.tracker_method == pipeline::MosaicTracker::kCmaxSlam)
    return "{\"summary\": " +
           json_string(std::string("rotation spline refined by the CMax-SLAM back-end (sliding window, panoramic contrast), predicted from the ") +
                       (cfg.use_gyro ? "gyro" : "contrast-maximisation rate of each window")) +
           tail;
  if (cfg.tracker_method == pipeline::MosaicTracker::kOdometry)
    return "{\"summary\": " +
           json_string(std::string("rotation integrated from the ") +
                       (cfg.use_gyro ? "gyro" : "contrast-maximisation rate of each window") + ", no map registration") +
           tail;
  return "{\"summary\": " +
         json_string(std::string(pipeline::mosaic_tracker_name(cfg.tracker_method)) + " tracker: rotation, " + measurement + " measurement (" + why + "), " + motion + " prediction, " + json_number(mean_particles, 9) +
                     " particles on average") +
         ", \"measurement\": {\"option\": \"" + frontend::rotation_measurement_model_name(to.measurement_model) + "\", \"resolved\": \"" +
         measurement + "\", \"reason\": " + json_string(why) + "}, \"motion\": {\"option\": \"" +
         frontend::rotation_motion_model_name(to.motion_model) + "\", \"resolved\": \"" + motion +
         "\", \"gyro_predictions\": " + std::to_string(st.gyro_predictions) + "}, \"particles\": {\"configured\": " +
         std::to_string(to.num_particles) + ", \"mean\": " + json_number(mean_particles, 9) + "}" + tail;
}

void write_stats_json(const MosaicArgs& args, const MosaicConfig& cfg, const MosaicRun& run) {
  const pipeline::MosaicResult& result = run.result;
  const mapping::MosaicReconstruction& rec = result.reconstruction;
  const pipeline::MosaicStats& ms = result.stats;
  const auto& st = ms.tracker;
  const pipeline::MosaicBootstrapStats& bs = ms.bootstrap;
  const double processing_s = run.processing_s, cpu_s = run.cpu_s, duration_s = run.duration_s();
  const int64_t events = run.events;
  std::ofstream f((fs::path(args.out) / "stats.json").string());
  f << "{\n  \"dataset\": " << json_string(args.dataset) << ",\n  \"model\": " << model_json(cfg, st)
    << ",\n  \"events\": " << events
    << ",\n  \"processing_time_s\": " << json_number(processing_s, 9) << ",\n  \"sequence_duration_s\": " << json_number(duration_s, 9)
    << ",\n  \"real_time_factor\": " << json_number(duration_s > 0 ? processing_s / duration_s : 0, 9)
    << ",\n  \"events_per_s\": " << json_number(processing_s > 0 ? events / processing_s : 0, 9)
    << ",\n  \"cpu_time_s\": " << json_number(cpu_s, 9) << ",\n  \"events_per_cpu_s\": " << json_number(cpu_s > 0 ? events / cpu_s : 0, 9)
    << ",\n  \"threads\": " << cfg.threads
    << ",\n  \"use_imu\": " << json_bool(args.use_imu) << ",\n  \"particles\": " << cfg.tracker.num_particles
    << ",\n  \"batch_size\": " << cfg.tracker.batch_size << ",\n  \"event_stride\": " << cfg.tracker.event_stride
    << ",\n  \"measurement_model\": \"" << frontend::rotation_measurement_model_name(cfg.tracker.measurement_model) << "\"" << ",\n  \"mosaic_size\": [" << cfg.mosaic.width << ", "
    << cfg.mosaic.height << "],\n  \"bootstrap\": {\"method\": \"" << (args.use_imu ? "gyro" : "contrast_maximisation")
    << "\", \"duration_s\": " << json_number((bs.t_end_ns - run.t0_ns) * 1e-9, 9) << ", \"cmax_windows\": " << bs.cmax_windows << ", \"short_windows\": " << bs.short_windows << ", \"still_windows\": " << bs.still_windows
    << ", \"tracker_contrast\": " << json_number(bs.tracker_contrast, 9) << ", \"contrast_samples\": " << bs.contrast_samples << "}"
    << ",\n  \"odometry\": {\"windows\": " << ms.odometry.windows << ", \"short_windows\": " << ms.odometry.short_windows << ", \"still_windows\": " << ms.odometry.still_windows << "}"
    << ",\n  \"cmax_slam\": {\"windows\": " << ms.cmax_slam.windows << ", \"skipped_windows\": " << ms.cmax_slam.skipped_windows
    << ", \"iterations\": " << ms.cmax_slam.iterations << ", \"evaluations\": " << ms.cmax_slam.evaluations
    << ", \"events_used\": " << ms.cmax_slam.events_used << ", \"events_mapped\": " << ms.cmax_slam.events_mapped
    << ", \"mean_contrast_gain\": " << json_number(ms.cmax_slam.mean_contrast_gain, 9)
    << ", \"global\": {\"refined\": " << (ms.cmax_slam.global_refined ? "true" : "false") << ", \"iterations\": " << ms.cmax_slam.global_iterations
    << ", \"events\": " << ms.cmax_slam.global_events << ", \"contrast_gain\": " << json_number(ms.cmax_slam.global_contrast_gain, 9) << "}}"
    << ",\n  \"tracker\": {\"events_used\": " << st.events_used << ", \"skipped_no_previous\": " << st.skipped_no_previous
    << ", \"skipped_unknown_map\": " << st.skipped_unknown_map << ", \"skipped_stride\": " << st.skipped_stride << ", \"batches\": " << st.batches
    << ", \"resamples\": " << st.resamples << ", \"linearized_batches\": " << st.linearized_batches << ", \"gyro_predictions\": " << st.gyro_predictions
    << ", \"mean_particles\": " << json_number(st.weighted_batches > 0 ? static_cast<double>(st.particle_batches) / static_cast<double>(st.weighted_batches) : 0.0, 9)
    << ", \"particle_evaluations\": " << st.particle_evaluations << "}"
    << ",\n  \"mapper\": {\"events_mapped\": " << ms.events_mapped << ", \"reconstructions\": " << ms.reconstructions
    << ", \"seen_pixels\": " << ms.seen_pixels << ", \"seen_fraction\": " << json_number(ms.seen_fraction, 9)
    << "},\n  \"poisson\": {\"weighting\": \"" << mapping::poisson_weighting_name(rec.weighting)
    << "\", \"pcg_iterations\": " << rec.weighted_stats.iterations
    << ", \"initial_relative_residual\": " << json_number(rec.weighted_stats.initial_relative_residual, 9)
    << ", \"relative_residual\": " << json_number(rec.weighted_stats.relative_residual, 9)
    << ", \"converged\": " << json_bool(rec.weighted_stats.converged) << "}"
    << ",\n  \"snapshots\": " << run.snapshots << ",\n  \"quality\": {\"windows\": " << ms.quality_windows << ", \"windows_undecided\": " << ms.quality_windows_undecided
    << ", \"probe_contrast_min\": " << json_number(ms.quality_min, 9) << ", \"probe_contrast_mean\": " << json_number(ms.quality_mean, 9)
    << ", \"events_unmapped_lost\": " << ms.events_unmapped_lost << "},\n  \"tracking_lost_segments\": [";
  for (size_t k = 0; k < result.tracking_lost.size(); ++k) {
    const pipeline::MosaicLostSegment& g = result.tracking_lost[k];
    f << (k ? ", " : "") << "{\"t_begin_s\": " << format_seconds(g.t_begin_ns) << ", \"t_end_s\": " << format_seconds(g.t_end_ns)
      << ", \"recovered\": " << json_bool(g.recovered) << ", \"relocalizations\": " << g.relocalizations
      << ", \"global_searches\": " << g.global_searches << ", \"global_jumps\": " << g.global_jumps
      << ", \"map_rolled_back_to_s\": "
      << (g.map_rolled_back_to_ns == INT64_MIN ? std::string("null") : format_seconds(g.map_rolled_back_to_ns)) << "}";
  }
  f << "]\n}\n";
}

// The true panorama's log intensity in the mosaic frame (R_w_m: mosaic -> the simulator's world),
// cfg.mosaic size, for a dataset written from a panorama by `evio simulate` (scene_resolved.yaml)
// or by the crosscheck simulator (meta.json with scene.file, its 16-bit equirectangular texture in
// the same convention, radiance I_min + (I_max - I_min) v / 65535 and log(I + log_eps)).
// std::nullopt for any other dataset.
std::optional<mapping::ImageF> true_panorama_log(const MosaicArgs& args, const MosaicConfig& cfg, const Eigen::Matrix3d& R_w_m) {
  const fs::path scene = fs::path(args.dataset) / "scene_resolved.yaml";
  if (fs::exists(scene)) {
    const simulator::SimulationConfig sc = simulator::load_simulation_config(scene.string());
    if (!sc.panorama) return std::nullopt;
    return simulator::panorama_log_reference(*sc.panorama, R_w_m, cfg.mosaic.width, cfg.mosaic.height);
  }
  const fs::path meta = fs::path(args.dataset) / "meta.json";
  if (!fs::exists(meta)) return std::nullopt;
  const char* expected = "the crosscheck simulator's meta.json (scene.file, config.events.I_min, I_max, log_eps)";
  double i_min = 0, i_max = 0, eps = 0;
  std::string file;
  try {
    const YAML::Node m = YAML::LoadFile(meta.string());  // JSON is YAML
    const YAML::Node scene = m["scene"];
    if (!scene || !scene.IsMap() || !scene["file"]) return std::nullopt;  // not a panorama scene
    const YAML::Node ev = m["config"] ? m["config"]["events"] : YAML::Node();
    if (!ev || !ev["I_min"] || !ev["I_max"] || !ev["log_eps"])
      throw InputError(meta.string(), 0, "a panorama scene without config.events.I_min, I_max and log_eps", expected);
    i_min = ev["I_min"].as<double>();
    i_max = ev["I_max"].as<double>();
    eps = ev["log_eps"].as<double>();
    file = scene["file"].as<std::string>();
  } catch (const YAML::Exception& e) {
    throw InputError(meta.string(), e.mark.line + 1, e.what(), expected);
  }
  if (!(i_min >= 0 && i_max > i_min && eps >= 0 && std::isfinite(i_max) && std::isfinite(eps)))
    throw InputError(meta.string(), 0,
                     "config.events I_min " + std::to_string(i_min) + ", I_max " + std::to_string(i_max) + ", log_eps " +
                         std::to_string(eps),
                     "0 <= I_min < I_max and log_eps >= 0, finite");
  const fs::path png = fs::path(args.dataset) / file;
  // log(I + eps) = log of the texture loaded with both ends shifted by eps.
  const simulator::Texture tex = simulator::Texture::load(png.string(), i_min + eps, i_max + eps,
                                                          simulator::TextureWrap::kRepeat, simulator::TextureWrap::kClamp);
  return simulator::panorama_log_reference(tex, R_w_m, cfg.mosaic.width, cfg.mosaic.height, i_min + eps);
}

// The mosaic against the true panorama (true_panorama_log), as eval.json members (empty when the
// dataset has none).
std::string mosaic_quality_json(const MosaicArgs& args, const MosaicConfig& cfg, const mapping::MosaicReconstruction& rec,
                                const Eigen::Matrix3d& R_w_m, std::ostream& out) {
  const std::optional<mapping::ImageF> truth = true_panorama_log(args, cfg, R_w_m);
  if (!truth) return {};
  const mapping::ImageF& ref = *truth;
  // The truth beside the mosaic, over the seen texels and in the same display mapping.
  mapping::write_log_image_tiff((fs::path(args.out) / "panorama_true_log.tiff").string(), ref, &rec.seen);
  mapping::write_log_image_png8((fs::path(args.out) / "panorama_true.png").string(), ref, &rec.seen, cfg.display);
  const mapping::ImageQuality q = mapping::compare_images(rec.log_intensity, ref, &rec.seen);
  auto quality = [&](const mapping::ImageQuality& x) {
    return "{\"psnr_db\": " + json_number(x.psnr_db, 9) + ", \"ssim\": " + json_number(x.ssim, 9) + ", \"rmse_log\": " + json_number(x.rmse, 9) +
           ", \"contrast_gain\": " + json_number(x.scale, 9) + ", \"pixels\": " + std::to_string(x.pixels) +
           ", \"fit\": \"affine in log intensity over the seen pixels\"}";
  };
  std::string json = ",\n  \"mosaic_quality\": " + quality(q);
  out << "mosaic vs true panorama: PSNR " << json_number(q.psnr_db, 9) << " dB, SSIM " << json_number(q.ssim, 9) << " over "
      << q.pixels << " seen pixels (affine log-intensity fit, " << mapping::poisson_weighting_name(rec.weighting)
      << " Poisson weighting)\n";
  // What a person sees: panorama.png's display values against the truth's linear intensity (as a
  // photograph shows it), affine fit over the seen texels, peak 1.
  mapping::ImageF truth_linear(ref.rows(), ref.cols());
  for (Eigen::Index k = 0; k < ref.size(); ++k) truth_linear.data()[k] = std::exp(ref.data()[k]);
  mapping::ImageQualityOptions display_options;
  display_options.peak = 1.0;
  const float truth_max = truth_linear.maxCoeff();
  if (truth_max > 0) truth_linear /= truth_max;
  const mapping::ImageQuality d =
      mapping::compare_images(mapping::log_image_to_display(rec.log_intensity, &rec.seen, cfg.display), truth_linear, &rec.seen,
                              display_options);
  json += ",\n  \"display_quality\": {\"psnr_db\": " + json_number(d.psnr_db, 9) + ", \"ssim\": " + json_number(d.ssim, 9) +
          ", \"fit\": \"panorama.png's display values against the true linear intensity, affine over the seen pixels\"}";
  out << "  panorama.png vs the true intensity: PSNR " << json_number(d.psnr_db, 9) << " dB, SSIM " << json_number(d.ssim, 9) << "\n";
  if (rec.weighting == mapping::PoissonWeighting::kInformation) {
    // The unweighted solve that seeded the weighted one: before / after on the same mosaic.
    const mapping::ImageQuality u = mapping::compare_images(rec.unweighted_log_intensity, ref, &rec.seen);
    json += ",\n  \"mosaic_quality_unweighted\": " + quality(u);
    out << "  unweighted Poisson: PSNR " << json_number(u.psnr_db, 9) << " dB, SSIM " << json_number(u.ssim, 9) << "\n";
  }
  return json;
}

}  // namespace

void write_mosaic_outputs(const MosaicArgs& args, const MosaicConfig& cfg, const MosaicRun& run, std::ostream& out) {
  const pipeline::MosaicResult& result = run.result;
  const mapping::MosaicReconstruction& rec = result.reconstruction;
  write_tum((fs::path(args.out) / "rotation.tum").string(), result.rotation);
  mapping::write_log_image_png8((fs::path(args.out) / "panorama.png").string(), rec.log_intensity, &rec.seen, cfg.display);
  mapping::write_log_image_tiff((fs::path(args.out) / "panorama_log.tiff").string(), rec.log_intensity, &rec.seen);
  mapping::write_mask_png((fs::path(args.out) / "panorama_seen.png").string(), rec.seen);
  if (!result.event_map.empty()) {
    // The back-end's panoramic event map, log(1 + events per texel), in the panorama's display mapping.
    mapping::ImageF counts(rec.log_intensity.rows(), rec.log_intensity.cols());
    mapping::MaskU8 seen(counts.rows(), counts.cols());
    for (Eigen::Index k = 0; k < counts.size(); ++k) {
      const float c = result.event_map[static_cast<size_t>(k)];
      counts.data()[k] = std::log1p(c);
      seen.data()[k] = c > 0 ? 1 : 0;
    }
    mapping::write_log_image_png8((fs::path(args.out) / "event_map.png").string(), counts, &seen, cfg.display);
  }
  write_stats_json(args, cfg, run);
  for (const pipeline::MosaicLostSegment& g : result.tracking_lost)
    out << "tracking lost " << format_seconds(g.t_begin_ns) << " s to " << format_seconds(g.t_end_ns) << " s ("
        << (g.recovered ? "recovered" : "not recovered") << ", " << g.relocalizations << " local spreads, "
        << g.global_searches << " global searches, " << g.global_jumps << " jumps"
        << (g.map_rolled_back_to_ns == INT64_MIN ? std::string() : ", map rolled back to " + format_seconds(g.map_rolled_back_to_ns) + " s")
        << ")\n";
  const double processing_s = run.processing_s, cpu_s = run.cpu_s, duration_s = run.duration_s();
  const int64_t events = run.events;
  out << "tracker       " << pipeline::mosaic_tracker_name(cfg.tracker_method) << " (" << cfg.tracker_reason << ")\n";
  out << "events        " << events << " over " << json_number(duration_s, 9) << " s, bootstrap "
      << (args.use_imu ? "gyro" : "contrast maximisation") << " " << json_number((result.stats.bootstrap.t_end_ns - run.t0_ns) * 1e-9, 9) << " s\n";
  out << "speed         " << json_number(processing_s, 9) << " s processing, real-time factor "
      << json_number(duration_s > 0 ? processing_s / duration_s : 0, 9) << " (one core), "
      << json_number(processing_s > 0 ? events / processing_s / 1e6 : 0, 9) << " M events/s; CPU time " << json_number(cpu_s, 9) << " s, "
      << json_number(cpu_s > 0 ? events / cpu_s / 1e6 : 0, 9) << " M events per CPU second\n";
  out << "mosaic        " << cfg.mosaic.width << "x" << cfg.mosaic.height << ", "
      << json_number(100.0 * static_cast<double>(result.stats.seen_pixels) / static_cast<double>(rec.seen.size()), 9) << "% seen\n";
}

void evaluate_mosaic(const MosaicArgs& args, const MosaicConfig& cfg, const MosaicRun& run, std::ostream& out) {
  const pipeline::MosaicResult& result = run.result;
  const int64_t boot_end_ns = result.stats.bootstrap.t_end_ns;
  const evaluation::InitialAlignedRotationError e = evaluation::rotation_error_initial_aligned(read_trajectory(args.gt), result.rotation);
  if (e.t_ns.empty()) throw InputError(args.gt, 0, "no ground-truth pose within the estimate's time span", "a trajectory overlapping the events");
  const std::vector<double>& err = e.errors_deg;
  size_t boot_poses = 0;  // the first boot_poses errors are of bootstrap poses (gyro / CMax rates)
  while (boot_poses < e.t_ns.size() && e.t_ns[boot_poses] <= boot_end_ns) ++boot_poses;
  const evaluation::Stats all = evaluation::compute_stats(err);
  // The bootstrap alone: its poses up to the tracking start, and its last one (the rotation the
  // tracker starts from: its error is baked into the bootstrap's part of the mosaic).
  const evaluation::Stats boot = evaluation::compute_stats(std::vector<double>(err.begin(), err.begin() + static_cast<std::ptrdiff_t>(boot_poses)));
  const double rms = all.rmse, mx = all.max, boot_rms = boot.rmse, boot_max = boot.max;
  const double boot_end = boot_poses > 0 ? err[boot_poses - 1] : 0.0;
  const std::string quality_json = mosaic_quality_json(args, cfg, result.reconstruction, e.R_w_m, out);
  const double boot_s = (boot_end_ns - run.t0_ns) * 1e-9;
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
      << json_number(boot_end, 9) << " deg over " << boot_poses << " poses up to " << json_number(boot_s, 9) << " s\n";
}

}  // namespace evio::apps
