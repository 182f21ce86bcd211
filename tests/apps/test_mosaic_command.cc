// `evio mosaic` end to end on a short simulated panorama rotation (poster_rotation, DAVIS240C):
// outputs exist and parse, unseen texels are transparent in panorama.png, the rotation error against ground truth stays bounded with the gyro
// and events only, the mosaic quality is reported; config errors name file, line and key.
#include "mosaic_command.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "evio/calib/error.h"
#include "evio_test/temp_dir.h"
#include "evio_test/text_file.h"
#include "simulate_command.h"
#include "evio/simulator/scene_config.h"
#include "evio/simulator/texture.h"

namespace evio::apps {
namespace {

std::string read(const std::string& p) { return evio_test::read_text(p); }

double json_value(const std::string& j, const std::string& key) { return evio_test::json_number(j, key); }

std::string simulate_rotation(const evio_test::TempDir& dir, double duration_s) {
  SimulateArgs sa;
  sa.scene = std::string(EVIO_SOURCE_DIR) + "/datasets/poster_rotation.yaml";
  sa.out = dir.file("seq");
  sa.overrides.duration_s = duration_s;
  sa.progress = false;
  std::ostringstream so;
  EXPECT_EQ(run_simulate(sa, so), 0);
  return sa.out;
}

TEST(MosaicCommand, ShortRotationWithAndWithoutGyro) {
  evio_test::TempDir dir;
  const std::string seq = simulate_rotation(dir, 1.0);
  for (bool use_imu : {true, false}) {
    MosaicArgs a;
    a.dataset = seq;
    a.out = dir.file(use_imu ? "imu" : "events");
    a.gt = seq + "/groundtruth.txt";
    a.use_imu = use_imu;
    a.progress = false;
    // The particle filter: the default (auto) with the gyro, set events only (auto: cmax_slam).
    if (!use_imu) a.set = {"tracker.method=pf"};
    std::ostringstream o;
    ASSERT_EQ(run_mosaic(a, o), 0);
    std::printf("%s", o.str().c_str());
    EXPECT_NE(o.str().find(use_imu ? "tracker       pf (auto: with the gyro)" : "tracker       pf (set)"), std::string::npos) << o.str();
    for (const char* f : {"rotation.tum", "panorama.png", "panorama_seen.png", "panorama_log.tiff", "stats.json", "eval.json", "mosaic_config.yaml"})
      EXPECT_TRUE(std::filesystem::exists(a.out + "/" + f)) << f;
    const std::string stats = read(a.out + "/stats.json"), ev = read(a.out + "/eval.json");
    // panorama.png: unseen texels (NaN in the TIFF, 0 in the coverage map) transparent, seen ones
    // opaque, and the tone mapping spreads the seen texels over the grey range.
    const cv::Mat png = cv::imread(a.out + "/panorama.png", cv::IMREAD_UNCHANGED);
    const cv::Mat tif = cv::imread(a.out + "/panorama_log.tiff", cv::IMREAD_UNCHANGED);
    const cv::Mat cov = cv::imread(a.out + "/panorama_seen.png", cv::IMREAD_UNCHANGED);
    ASSERT_EQ(png.type(), CV_8UC4);
    ASSERT_EQ(tif.type(), CV_32FC1);
    ASSERT_EQ(cov.type(), CV_8UC1);
    int64_t seen = 0, dark = 0, bright = 0, mismatched = 0;
    for (int j = 0; j < png.rows; ++j)
      for (int i = 0; i < png.cols; ++i) {
        const cv::Vec4b c = png.at<cv::Vec4b>(j, i);
        const bool s = !std::isnan(tif.at<float>(j, i));
        mismatched += (c[3] == (s ? 255 : 0) && cov.at<uint8_t>(j, i) == (s ? 255 : 0)) ? 0 : 1;
        if (!s) continue;
        ++seen;
        dark += c[0] < 64;
        bright += c[0] > 191;
      }
    EXPECT_EQ(mismatched, 0);
    EXPECT_NEAR(static_cast<double>(seen) / (png.rows * png.cols), json_value(stats, "seen_fraction"), 1e-9);
    EXPECT_GT(dark, seen / 20) << "seen " << seen;
    EXPECT_GT(bright, seen / 20) << "seen " << seen;
    EXPECT_GT(json_value(stats, "events"), 1e5);
    EXPECT_GT(json_value(stats, "real_time_factor"), 0);
    const double rms = json_value(ev, "rot_rms_deg"), mx = json_value(ev, "rot_max_deg");
    EXPECT_TRUE(std::isfinite(json_value(ev, "psnr_db"))) << ev;
    // Measured (1 s, up to ~200 deg/s): 0.153 deg RMS with the gyro, 0.505 deg events only
    // (particle velocities); PSNR 27 / 22 dB against the true panorama (bounds ~1.2x).
    EXPECT_LT(rms, use_imu ? 0.19 : 0.55) << ev;
    EXPECT_LE(rms, mx);
    EXPECT_GT(json_value(ev, "psnr_db"), use_imu ? 24.0 : 19.0) << ev;
    // The bootstrap alone (its poses up to the tracking start, 0.3 s): part of the whole run.
    const size_t boot_at = ev.find("\"bootstrap\"");
    ASSERT_NE(boot_at, std::string::npos) << ev;
    const std::string boot = ev.substr(boot_at);
    const double boot_rms = json_value(boot, "rot_rms_deg"), boot_max = json_value(boot, "rot_max_deg");
    const double boot_end = json_value(boot, "rot_end_deg"), boot_poses = json_value(boot, "poses");
    // 0.3 s at one pose per 5 ms at most (1 ms gyro windows), one per CMax window (>= 7 ms here) without.
    EXPECT_GE(boot_poses, use_imu ? 55 : 10) << ev;
    EXPECT_LE(boot_poses, 61) << ev;
    EXPECT_LT(boot_poses, json_value(ev, "matched_poses")) << ev;
    EXPECT_LE(boot_rms, boot_max) << ev;
    EXPECT_LE(boot_end, boot_max) << ev;
    EXPECT_LE(boot_max, mx) << ev;
    // Measured 0.014 deg max (0.009 RMS) with the gyro (the rate linear between samples; 0.154 /
    // 0.091 holding each sample), 0.609 deg max (0.371 RMS) from CMax rates.
    EXPECT_LT(boot_max, use_imu ? 0.018 : 0.73) << ev;
    // The tracker's contrast is calibrated on the bootstrap mosaic: below the sensor's C.
    const double c = json_value(stats, "tracker_contrast");
    EXPECT_GT(c, 0.05) << stats;
    EXPECT_LE(c, 0.2) << stats;
    EXPECT_EQ(json_value(stats, "event_stride"), use_imu ? 4 : 1) << stats;
  }
}

// The default tracker (auto) events only is cmax_slam, and says so: the global pass refines the
// trajectory, and the mosaic is mapped a second time along it (its PSNR against the true panorama).
TEST(MosaicCommand, CmaxSlamGlobalPassRemapsTheMosaic) {
  evio_test::TempDir dir;
  const std::string seq = simulate_rotation(dir, 1.0);
  MosaicArgs a;
  a.dataset = seq;
  a.out = dir.file("slam");
  a.gt = seq + "/groundtruth.txt";
  a.progress = false;
  std::ostringstream o;
  ASSERT_EQ(run_mosaic(a, o), 0);
  std::printf("%s", o.str().c_str());
  const std::string stats = read(a.out + "/stats.json"), ev = read(a.out + "/eval.json");
  EXPECT_NE(stats.find("\"tracker\": \"cmax_slam\", \"tracker_choice\": \"auto: events only\""), std::string::npos) << stats;
  EXPECT_NE(o.str().find("tracker       cmax_slam (auto: events only)"), std::string::npos) << o.str();
  EXPECT_TRUE(std::filesystem::exists(a.out + "/event_map.png"));
  const size_t g = stats.find("\"global\"");
  ASSERT_NE(g, std::string::npos) << stats;
  EXPECT_NE(stats.find("\"refined\": true", g), std::string::npos) << stats;
  EXPECT_GT(json_value(stats.substr(g), "contrast_gain"), 1.0) << stats;
  EXPECT_GT(json_value(stats, "seen_fraction"), 0.05) << stats;
  // Measured: 0.261 deg RMS (0.366 without the global pass), mosaic PSNR 27.1 dB against the
  // true panorama (bounds ~1.2x; 25 dB is 1.6x the squared error).
  EXPECT_LT(json_value(ev, "rot_rms_deg"), 0.32) << ev;
  EXPECT_GT(json_value(ev, "psnr_db"), 25.0) << ev;
}

// The crosscheck simulator's truth (meta.json + a 16-bit equirectangular panorama.png, radiance
// I_min + (I_max - I_min) v / 65535, log(I + log_eps)): the same simulated sequence written in
// that form (evio's panorama texture quantised to 16 bits, scene_resolved.yaml left out) scores
// the same mosaic as evio's own truth, and the truth is written beside it.
TEST(MosaicCommand, CrosscheckPanoramaIsTheSameTruth) {
  evio_test::TempDir dir;
  const std::string seq = simulate_rotation(dir, 0.6);
  const std::string x = dir.file("crosscheck");
  std::filesystem::create_directories(x);
  for (const auto& e : std::filesystem::directory_iterator(seq))
    if (e.is_regular_file() && e.path().filename() != "scene_resolved.yaml")
      std::filesystem::copy_file(e.path(), x + "/" + e.path().filename().string());
  const simulator::SimulationConfig sc = simulator::load_simulation_config(seq + "/scene_resolved.yaml");
  ASSERT_TRUE(sc.panorama);
  const cv::Mat& tex = sc.panorama->level(0);
  double lo = 0, hi = 0;
  cv::minMaxLoc(tex, &lo, &hi);
  cv::Mat v16;
  tex.convertTo(v16, CV_16U, 65535.0 / (hi - lo), -65535.0 * lo / (hi - lo));
  ASSERT_TRUE(cv::imwrite(x + "/panorama.png", v16));
  std::ofstream(x + "/meta.json") << "{\"generator\": \"test\", \"scene\": {\"file\": \"panorama.png\"}, \"config\": {\"events\": "
                                     "{\"I_min\": " << lo << ", \"I_max\": " << hi << ", \"log_eps\": 0.0}}}\n";
  double psnr[2] = {0, 0}, ssim[2] = {0, 0};
  for (int k = 0; k < 2; ++k) {
    MosaicArgs a;
    a.dataset = k == 0 ? seq : x;
    a.out = dir.file(k == 0 ? "own" : "cross");
    a.gt = a.dataset + "/groundtruth.txt";
    a.use_imu = true;
    a.progress = false;
    std::ostringstream o;
    ASSERT_EQ(run_mosaic(a, o), 0);
    const std::string ev = read(a.out + "/eval.json");
    psnr[k] = json_value(ev, "psnr_db");
    ssim[k] = json_value(ev, "ssim");
    EXPECT_TRUE(std::isfinite(json_value(ev.substr(ev.find("display_quality")), "psnr_db"))) << ev;
    EXPECT_TRUE(std::filesystem::exists(a.out + "/panorama_true.png"));
    EXPECT_TRUE(std::filesystem::exists(a.out + "/panorama_true_log.tiff"));
  }
  // A malformed meta.json is an error that names it (the mosaic outputs are written before the evaluation).
  for (const std::string& bad : {std::string("{\"scene\": {\"file\": \"panorama.png\"}}"),
                                 std::string("{\"scene\": {\"file\": \"panorama.png\"}, \"config\": {\"events\": "
                                             "{\"I_min\": \"dark\", \"I_max\": 1, \"log_eps\": 0}}}"),
                                 std::string("{\"scene\": {\"file\": \"panorama.png\"}, \"config\": {\"events\": "
                                             "{\"I_min\": 1, \"I_max\": 0.5, \"log_eps\": 0}}}"),
                                 std::string("{\"scene\": [unclosed")}) {
    std::ofstream(x + "/meta.json") << bad;
    MosaicArgs a;
    a.dataset = x;
    a.out = dir.file("bad");
    a.gt = x + "/groundtruth.txt";
    a.use_imu = true;
    a.progress = false;
    std::ostringstream o;
    try {
      run_mosaic(a, o);
      ADD_FAILURE() << "accepted " << bad;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("meta.json"), std::string::npos) << e.what();
    }
  }
  std::printf("mosaic vs truth: evio's scene %.3f dB / %.4f, crosscheck form %.3f dB / %.4f\n", psnr[0], ssim[0], psnr[1], ssim[1]);
  EXPECT_GT(psnr[0], 20.0);
  EXPECT_NEAR(psnr[1], psnr[0], 0.05);
  EXPECT_NEAR(ssim[1], ssim[0], 0.002);
}

TEST(MosaicConfig, ErrorsNameFileLineAndKey) {
  evio_test::TempDir dir;
  const std::string p = dir.file("bad.yaml");
  std::ofstream(p) << "tracker:\n  particles: -3\n";
  try {
    load_mosaic_config(p);
    FAIL() << "expected an error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("bad.yaml:2"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("particles"), std::string::npos) << e.what();
  }
  std::ofstream(p) << "mosaic:\n  widht: 10\n";
  EXPECT_THROW(load_mosaic_config(p), InputError);
  std::string resolved;
  std::ofstream(p) << "mosaic: {width: 512}\ntracker: {particles: 300, batch_size: 20}\n";
  const MosaicConfig c = load_mosaic_config(p, &resolved);
  EXPECT_EQ(c.mosaic.width, 512);
  EXPECT_EQ(c.mosaic.height, 256);
  EXPECT_EQ(c.tracker.num_particles, 300);
  EXPECT_NE(resolved.find("particles: 300"), std::string::npos) << resolved;
  // The tracker's contrast follows the mosaic's unless given; model names are checked.
  std::ofstream(p) << "mosaic: {contrast_threshold: 0.3, max_path_px: 4, seen_max_gradient_std: 0.1}\n"
                      "tracker: {measurement_model: previous_mean, event_stride: 3}\nbootstrap: {calibrate_contrast: false}\n";
  const MosaicConfig d = load_mosaic_config(p);
  EXPECT_DOUBLE_EQ(d.tracker.contrast_threshold, 0.3);
  EXPECT_DOUBLE_EQ(d.mosaic.max_path_px, 4.0);
  EXPECT_DOUBLE_EQ(d.mosaic.seen_max_gradient_std, 0.1);
  EXPECT_EQ(d.tracker.measurement_model, frontend::RotationMeasurementModel::kPreviousMean);
  EXPECT_EQ(d.event_stride, 3);
  EXPECT_FALSE(d.calibrate_contrast);
  // *_ms keys are milliseconds (they were read as seconds); the resolved config reads back the same.
  std::ofstream(p) << "mosaic: {reconstruct_ms: 20, reconstruct_events: 1000, reconstruct_latency_events: 500, threads: 2}\n"
                      "tracker: {max_batch_ms: 0.5}\nbootstrap: {duration_ms: 250}\noutput: {trajectory_ms: 2}\n";
  std::string resolved_ms;
  const MosaicConfig e = load_mosaic_config(p, &resolved_ms);
  EXPECT_EQ(e.reconstruct_period_ns, 20'000'000);
  EXPECT_EQ(e.reconstruct_events, 1000);
  EXPECT_EQ(e.reconstruct_latency_events, 500);
  EXPECT_EQ(e.threads, 2);
  EXPECT_EQ(e.tracker.max_batch_duration_ns, 500'000);
  EXPECT_EQ(e.bootstrap_ns, 250'000'000);
  EXPECT_EQ(e.trajectory_period_ns, 2'000'000);
  std::ofstream(p) << resolved_ms;
  const MosaicConfig f = load_mosaic_config(p);
  EXPECT_EQ(f.reconstruct_period_ns, e.reconstruct_period_ns);
  EXPECT_EQ(f.bootstrap_ns, e.bootstrap_ns);
  EXPECT_EQ(f.footprint_period_ns, e.footprint_period_ns);
  // Particle-velocity keys: read, written to the resolved config, read back the same; bad values rejected.
  std::ofstream(p) << "tracker: {motion_model: particle_velocity, velocity_noise_rad_s_per_sqrt_s: 3, "
                      "velocity_rotation_noise_rad_per_sqrt_s: 0.05, initial_velocity_spread_rad_s: 0.25, "
                      "relative_max_interval_ms: 40, relative_max_path_rad: 0.2}\n";
  std::string resolved_pv;
  const MosaicConfig g = load_mosaic_config(p, &resolved_pv);
  EXPECT_EQ(g.tracker.motion_model, frontend::RotationMotionModel::kParticleVelocity);
  EXPECT_DOUBLE_EQ(g.tracker.velocity_noise_rad_s_per_sqrt_s, 3.0);
  EXPECT_DOUBLE_EQ(g.tracker.velocity_rotation_noise_rad_per_sqrt_s, 0.05);
  EXPECT_DOUBLE_EQ(g.tracker.initial_velocity_spread_rad_s, 0.25);
  EXPECT_EQ(g.tracker.relative_max_interval_ns, 40'000'000);
  EXPECT_DOUBLE_EQ(g.tracker.relative_max_path_rad, 0.2);
  std::ofstream(p) << resolved_pv;
  const MosaicConfig h = load_mosaic_config(p);
  EXPECT_EQ(h.tracker.motion_model, g.tracker.motion_model);
  EXPECT_DOUBLE_EQ(h.tracker.velocity_noise_rad_s_per_sqrt_s, 3.0);
  EXPECT_EQ(h.tracker.relative_max_interval_ns, 40'000'000);
  EXPECT_DOUBLE_EQ(h.tracker.relative_max_path_rad, 0.2);
  std::ofstream(p) << "tracker: {relative_max_path_rad: 0}\n";
  EXPECT_THROW(load_mosaic_config(p), InputError);
  // Tracking-failure keys: read, resolved, read back; bad values rejected with the key.
  std::ofstream(p) << "failure: {probe_every_batches: 2, probe_offset_rad: 0.015, window_ms: 80, min_events: 500, "
                      "min_rate_ratio: 0.3, lost_windows: 3, lost_contrast: 0.04, recovered_contrast: 0.12, freeze_map: false, "
                      "relocalize_spread_rad: 0}\n";
  std::string resolved_f;
  const MosaicConfig k = load_mosaic_config(p, &resolved_f);
  EXPECT_EQ(k.tracker.probe_every_batches, 2);
  EXPECT_DOUBLE_EQ(k.tracker.probe_offset_rad, 0.015);
  EXPECT_EQ(k.failure_window_ns, 80'000'000);
  EXPECT_DOUBLE_EQ(k.failure_lost_contrast, 0.04);
  EXPECT_DOUBLE_EQ(k.failure_recovered_contrast, 0.12);
  EXPECT_FALSE(k.failure_freeze_map);
  EXPECT_DOUBLE_EQ(k.failure_relocalize_spread_rad, 0.0);
  EXPECT_EQ(k.failure_min_events, 500);
  EXPECT_DOUBLE_EQ(k.failure_min_rate_ratio, 0.3);
  EXPECT_EQ(k.failure_lost_windows, 3);
  std::ofstream(p) << resolved_f;
  const MosaicConfig k2 = load_mosaic_config(p);
  EXPECT_EQ(k2.failure_window_ns, 80'000'000);
  EXPECT_DOUBLE_EQ(k2.failure_recovered_contrast, 0.12);
  EXPECT_EQ(k2.failure_lost_windows, 3);
  for (const char* bad : {"failure: {window_ms: 0}\n", "failure: {lost_contrast: 0.2}\n", "failure: {probe_offset_rad: 0.5}\n",
                          "failure: {freeze_map: often}\n", "failure: {lost_windows: 0}\n"}) {
    std::ofstream(p) << bad;
    EXPECT_THROW(load_mosaic_config(p), InputError) << bad;
  }
  // Recovery keys (this session's) and map_viewed_texels: read, resolved, read back; bad values rejected.
  std::ofstream(p) << "mosaic: {map_viewed_texels: true}\nfailure: {rollback: true, checkpoint_ms: 100, checkpoints: 2, "
                      "global_relocalize: true, global_period_ms: 300, global_min_gain: 1.5, global_axis_spacing_deg: 4, "
                      "global_roll_step_deg: 15}\n";
  std::string resolved_r;
  const MosaicConfig r = load_mosaic_config(p, &resolved_r);
  EXPECT_TRUE(r.mosaic.map_viewed_texels);
  EXPECT_TRUE(r.failure_rollback);
  EXPECT_EQ(r.failure_checkpoint_period_ns, 100'000'000);
  EXPECT_EQ(r.failure_checkpoints, 2);
  EXPECT_TRUE(r.failure_global_relocalize);
  EXPECT_EQ(r.failure_global_period_ns, 300'000'000);
  EXPECT_DOUBLE_EQ(r.failure_global_min_gain, 1.5);
  EXPECT_DOUBLE_EQ(r.relocalization.axis_spacing_deg, 4.0);
  EXPECT_DOUBLE_EQ(r.relocalization.roll_step_deg, 15.0);
  std::ofstream(p) << resolved_r;
  const MosaicConfig r2 = load_mosaic_config(p);
  EXPECT_TRUE(r2.mosaic.map_viewed_texels);
  EXPECT_EQ(r2.failure_checkpoints, 2);
  EXPECT_DOUBLE_EQ(r2.failure_global_min_gain, 1.5);
  EXPECT_DOUBLE_EQ(r2.relocalization.roll_step_deg, 15.0);
  for (const char* bad : {"failure: {checkpoints: 0}\n", "failure: {checkpoint_ms: 0}\n", "failure: {global_min_gain: 0.5}\n",
                          "failure: {global_roll_step_deg: 0}\n", "failure: {rollback: sometimes}\n",
                          "mosaic: {map_viewed_texels: 2}\n"}) {
    std::ofstream(p) << bad;
    EXPECT_THROW(load_mosaic_config(p), InputError) << bad;
  }
  std::ofstream(p) << "tracker: {velocity_noise_rad_s_per_sqrt_s: -1}\n";
  EXPECT_THROW(load_mosaic_config(p), InputError);
  std::ofstream(p) << "mosaic: {threads: 3}\n";
  EXPECT_THROW(load_mosaic_config(p), InputError);
  std::ofstream(p) << "tracker:\n  measurement_model: kim\n";
  try {
    load_mosaic_config(p);
    FAIL() << "expected an error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("bad.yaml:2"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("previous_mean"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace evio::apps
