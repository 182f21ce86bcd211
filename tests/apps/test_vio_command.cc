// `evio vio`: config parsing (errors with file:line, round trip of the resolved config), and an
// end-to-end run on a short simulated sequence (poster_6dof, 6 s) with every output checked.
#include "vio_command.h"

#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <random>
#include <regex>
#include <sstream>

#include <gtest/gtest.h>

#include "evio/calib/error.h"
#include "evio/mapping/landmark_map.h"
#include "evio/sensors/ecd.h"
#include "evio/sensors/trajectory.h"
#include "evio_test/real_data.h"
#include "evio_test/temp_dir.h"
#include "evio_test/text_file.h"
#include "simulated_scene.h"
#include "vio_run.h"

namespace evio::apps {
namespace {

std::string read(const std::string& p) { return evio_test::read_text(p); }

double json_value(const std::string& j, const std::string& key) { return evio_test::json_number(j, key); }

// A static camera seeing only shot noise (the extremes suite's noise_only): the static
// initialisation succeeds at the end of the 1 s, and no frame after it has features. The command
// says so in one error and leaves no empty trajectory files (before: exit 1 from the --gt
// evaluation, "trajectory.tum: no poses in the file").
TEST(VioCommand, InitialisedWithoutAnyTrackedFrameIsAClearError) {
  evio_test::TempDir dir;
  VioArgs va;
  va.config = kSimulatorConfig;
  va.dataset = simulate_scene(dir, "static_noise.yaml", 1.0, {"events.shot_noise_rate_hz=5"});
  va.out = dir.file("vio");
  va.gt = va.dataset + "/groundtruth.txt";
  va.progress = false;
  std::ostringstream o;
  try {
    run_vio(va, o);
    ADD_FAILURE() << "no error: " << o.str();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("(static) but no frame after it had features to track"), std::string::npos)
        << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(va.out + "/trajectory.tum"));
  EXPECT_FALSE(std::filesystem::exists(va.out + "/eval.json"));
}

TEST(VioConfig, ErrorsNameFileLineAndKey) {
  evio_test::TempDir dir;
  const auto expect_error = [&](const std::string& yaml, const std::string& what) {
    const std::string p = dir.write("bad.yaml", yaml);
    try {
      load_vio_config(p);
      ADD_FAILURE() << "no error for " << yaml;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
    }
  };
  expect_error("window:\n  size: 1\n", "bad.yaml:2");
  expect_error("window:\n  sise: 10\n", "unknown key 'sise'");
  expect_error("frontend: kalman\n", "frontend");
  expect_error("tracker:\n  ransac: seven_point\n", "tracker.ransac");
  expect_error("frames: {events_per_frame: 100, min_events: 500}\n", "min_events");
  expect_error("init: {method: magic}\n", "init.method");
  expect_error("inputs: video\n", "inputs");
  expect_error("aps: {pixel_sigma: 0}\n", "aps.pixel_sigma");
  expect_error("aps_tracker: {klt_window_px: 4}\n", "klt_window_px");
  expect_error("window: {init_bias_gyro_turn_on_radps: 0}\n", "init_bias_gyro_turn_on_radps");
  expect_error("window: {init_bias_accel_turn_on_mps2: -1}\n", "init_bias_accel_turn_on_mps2");
  expect_error("window: {estimate_time_offset: maybe}\n", "estimate_time_offset");
  expect_error("window: {time_offset_sigma_ms: 0}\n", "time_offset_sigma_ms");
  expect_error("tracker: {seed: -3}\n", "tracker.seed");
  expect_error("frames: {overlap: 0.95}\n", "overlap");
  expect_error("frames: {velocity_at_reference: often}\n", "velocity_at_reference");
  expect_error("frames: {event_lag_px: -0.5}\n", "event_lag_px");
  expect_error("window: {tracked_landmark_marginalisation: keep}\n", "window.tracked_landmark_marginalisation");
  expect_error("window: {function_tolerance: 0}\n", "function_tolerance");
  expect_error("window: {function_tolerance: 1}\n", "function_tolerance");
  expect_error("tracker: {template_fallback: sometimes}\n", "template_fallback");
  expect_error("tracker: {template_max_rotation_deg: -1}\n", "template_max_rotation_deg");
  expect_error("tracker: {anchor_frames: -2}\n", "anchor_frames");
  expect_error("tracker: {anchor_ransac_threshold_px: 0}\n", "anchor_ransac_threshold_px");
  expect_error("window: {rotation_only_min_duration_ms: -5}\n", "rotation_only_min_duration_ms");
}

TEST(VioConfig, ResolvedConfigReadsBackToTheSameValues) {
  evio_test::TempDir dir;
  std::string resolved;
  const VioConfig a = load_vio_config(
      dir.write("c.yaml", "frontend: corners\nwindow: {size: 7, pixel_sigma: 0.8, loss: cauchy, init_bias_gyro_turn_on_radps: 0.0002,\n"
                          "  estimate_time_offset: true, time_offset_sigma_ms: 4, tracked_landmark_marginalisation: restart,\n"
                          "  function_tolerance: 0.0001, rotation_only_min_duration_ms: 120}\nframes: {events_per_frame: 9000, overlap: 0.25, velocity_at_reference: true, event_lag_px: 0.3}\n"
                          "tracker: {ransac: five_point, fast_threshold: 30, template_max_age_frames: 4, template_fallback: false,\n"
                          "  template_max_rotation_deg: 2.5, anchor_frames: 7, anchor_ransac_threshold_px: 1.5}\n"
                          "init: {method: static, window_ms: 1500}\n"
                          "inputs: events+aps\naps_tracker: {fast_threshold: 7}\naps: {pixel_sigma: 0.4, max_gap_ms: 80}\n"),
      &resolved);
  std::string again;
  const VioConfig b = load_vio_config(dir.write("r.yaml", resolved), &again);
  EXPECT_EQ(resolved, again);
  EXPECT_EQ(b.frontend, "corners");
  EXPECT_EQ(b.window.window_size, 7);
  EXPECT_EQ(b.window.loss, backend::RobustLoss::kCauchy);
  EXPECT_DOUBLE_EQ(b.window.pixel_sigma, 0.8);
  EXPECT_EQ(b.frames.events_per_frame, 9000);
  EXPECT_DOUBLE_EQ(b.frames.overlap, 0.25);
  EXPECT_TRUE(b.frame_velocity_at_reference);
  EXPECT_DOUBLE_EQ(b.frames.event_lag_px, 0.3);
  EXPECT_EQ(b.tracker.ransac, frontend::RansacModel::kFivePoint);
  EXPECT_EQ(b.tracker.fast_threshold, 30);
  EXPECT_EQ(b.init, "static");
  EXPECT_EQ(b.init_window_ns, 1'500'000'000);
  EXPECT_EQ(a.window.window_size, b.window.window_size);
  EXPECT_EQ(b.inputs, pipeline::VioInputs::kEventsAndAps);
  EXPECT_EQ(b.aps_tracker.fast_threshold, 7);
  EXPECT_EQ(b.tracker.fast_threshold, 30);
  EXPECT_DOUBLE_EQ(b.aps_pixel_sigma_px, 0.4);
  EXPECT_EQ(b.aps_max_gap_ns, 80'000'000);
  EXPECT_DOUBLE_EQ(b.window.init_bias_gyro_turn_on_radps, 0.0002);
  EXPECT_TRUE(b.window.estimate_time_offset);
  EXPECT_DOUBLE_EQ(b.window.time_offset_sigma_s, 0.004);
  EXPECT_EQ(b.window.tracked_landmark_marginalisation, backend::TrackedLandmarkMarginalisation::kRestart);
  EXPECT_DOUBLE_EQ(b.window.function_tolerance, 1e-4);
  EXPECT_DOUBLE_EQ(b.window.rotation_only_min_duration_s, 0.12);
  EXPECT_EQ(b.tracker.template_max_age_frames, 4);
  EXPECT_FALSE(b.tracker.template_fallback);
  EXPECT_DOUBLE_EQ(b.tracker.template_max_rotation_deg, 2.5);
  EXPECT_EQ(b.tracker.anchor_frames, 7);
  EXPECT_DOUBLE_EQ(b.tracker.anchor_ransac_threshold_px, 1.5);
}

TEST(VioConfig, EveryExampleConfigInDatasetsParses) {
  int n = 0;
  for (const auto& e : std::filesystem::directory_iterator(std::string(EVIO_SOURCE_DIR) + "/datasets/vio")) {
    const std::string name = e.path().filename().string();
    if (e.path().extension() != ".yaml") continue;
    EXPECT_NO_THROW(load_vio_config(e.path().string())) << name;
    ++n;
  }
  EXPECT_GE(n, 3);
}

// --gt-align-first-pose without --gt: rejected before any dataset is read.
TEST(VioCommand, FirstPoseAlignmentNeedsGroundTruth) {
  evio_test::TempDir dir;
  VioArgs va;
  va.dataset = dir.file("missing");
  va.out = dir.file("out");
  va.progress = false;
  va.gt_align_first_pose = true;
  std::ostringstream o;
  try {
    run_vio(va, o);
    ADD_FAILURE() << "no error for --gt-align-first-pose without --gt";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("--gt GT.tum"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("missing"), std::string::npos) << e.what();
  }
}

// A 6 s simulated poster_6dof sequence through `evio vio --gt`.
// --oracle-tracks: rejected before any dataset is read without --gt, or with a scene that is not
// made of planes (no ray caster), naming the scene file.
TEST(VioCommand, OracleTracksNeedGroundTruthAndAPlanesScene) {
  evio_test::TempDir dir;
  VioArgs va;
  va.dataset = dir.file("missing");
  va.out = dir.file("out");
  va.progress = false;
  // Each bad combination is an InputError whose message holds every one of `expected`.
  const auto expect_error = [&](const char* what, std::initializer_list<const char*> expected) {
    std::ostringstream o;
    try {
      run_vio(va, o);
      ADD_FAILURE() << "no error for " << what;
    } catch (const InputError& e) {
      for (const char* x : expected) EXPECT_NE(std::string(e.what()).find(x), std::string::npos) << what << ": " << e.what();
    }
  };
  va.oracle_scene = std::string(EVIO_SOURCE_DIR) + "/datasets/poster_6dof.yaml";
  expect_error("--oracle-tracks without --gt", {"--gt", "poster_6dof.yaml"});
  va.gt = dir.file("gt.tum");
  va.oracle_scene = std::string(EVIO_SOURCE_DIR) + "/datasets/poster_rotation.yaml";
  expect_error("a panorama scene", {"planes scene"});
  va.oracle_scene.clear();
  va.oracle_frame_motion = true;
  expect_error("--oracle-frame-motion without a scene", {"--oracle-tracks"});
  va.oracle_frame_motion = false;
  va.oracle_frame_plane = true;
  expect_error("--oracle-frame-plane without --oracle-frame-motion", {"--oracle-frame-motion"});
  va.oracle_frame_plane = false;
  va.oracle_observations = true;
  expect_error("--oracle-observations without a scene", {"--oracle-tracks"});
  va.oracle_scene = std::string(EVIO_SOURCE_DIR) + "/datasets/poster_6dof.yaml";
  expect_error("--oracle-observations with --oracle-error none", {"--oracle-error real", "poster_6dof.yaml"});
}

TEST(VioCommand, ShortSimulatedSequenceEndToEnd) {
  evio_test::TempDir dir;
  const VioArgs va = vio_on(simulate_scene(dir, "poster_6dof.yaml", 6.0), dir.file("vio"));
  for (const char* f : {"trajectory.tum", "trajectory_causal.tum", "keyframes.txt", "map.ply", "observations.txt", "stats.json",
                        "vio_config.yaml", "eval.json"}) {
    EXPECT_TRUE(std::filesystem::exists(va.out + "/" + f)) << f;
  }
  const std::string stats = read(va.out + "/stats.json");
  EXPECT_GT(json_value(stats, "events"), 1e6);
  EXPECT_GT(json_value(stats, "keyframes"), 20);
  EXPECT_NEAR(json_value(stats, "sequence_duration_s"), 6.0, 0.05);
  EXPECT_GT(json_value(stats, "real_time_factor"), 0.0);
  EXPECT_NE(stats.find("\"motion_model_segments\": [{"), std::string::npos);
  EXPECT_NE(stats.find("\"initialisation\": {\"method\": \"visual-inertial alignment\""), std::string::npos) << stats;
  EXPECT_GT(mapping::read_landmark_map(va.out + "/map.ply").size(), 100u);
  // The trajectory: one pose per event frame after initialisation, finite, in time order.
  std::istringstream tin(read(va.out + "/trajectory.tum"));
  double last_t = -1;
  size_t poses = 0;
  for (std::string l; std::getline(tin, l);) {
    if (l.empty() || l[0] == '#') continue;
    std::istringstream ls(l);
    double v[8];
    for (double& x : v) ASSERT_TRUE(static_cast<bool>(ls >> x)) << l;
    for (double x : v) ASSERT_TRUE(std::isfinite(x)) << l;
    EXPECT_GT(v[0], last_t);
    last_t = v[0];
    ++poses;
  }
  EXPECT_GT(poses, 100u);
  // No jumps: the largest change of the frame-to-frame step (second difference of the positions,
  // rotation invariant) of trajectory.tum against the causal trajectory and the truth.
  auto max_second_difference = [](const std::string& path, const Trajectory* truth) {
    const Trajectory tr = read_tum(path);
    std::vector<Eigen::Vector3d> p;
    for (const StampedPose& s : tr.poses()) {
      if (!truth) {
        p.push_back(s.T_w_b.translation);
      } else if (const auto g = truth->interpolate(s.t_ns)) {
        p.push_back(g->translation);
      }
    }
    double m = 0;
    for (size_t i = 2; i < p.size(); ++i) m = std::max(m, (p[i] - 2 * p[i - 1] + p[i - 2]).norm());
    return m;
  };
  const Trajectory gt = read_tum(va.gt);
  const double jump = max_second_difference(va.out + "/trajectory.tum", nullptr);
  const double jump_causal = max_second_difference(va.out + "/trajectory_causal.tum", nullptr);
  const double jump_true = max_second_difference(va.out + "/trajectory.tum", &gt);
  std::printf("largest second difference of positions: trajectory %.2f mm, causal %.2f mm, truth %.2f mm\n", 1e3 * jump,
              1e3 * jump_causal, 1e3 * jump_true);
  // Measured 9.12 mm, causal 16.38 mm, truth 9.09 mm (chained KLT: 9.07, 14.77): no larger than the true motion explains
  // (with the library's real-sensor bias priors 9.47, 23.60 and 9.09 mm).
  EXPECT_LT(jump, 1.3 * jump_true);
  EXPECT_LT(jump, 0.7 * jump_causal);
  // Accuracy: measured 0.311% on these 6 s with datasets/vio/simulator.yaml (chained KLT 0.356%; 0.394% with the
  // library defaults; KLT windows of 21 px 0.99%; 1.9% before translation compensation was on by
  // default; the 0.3% target of the issue is not met); the bound for a short sequence.
  const std::string ev = read(va.out + "/eval.json");
  const double mpe = json_value(ev, "mean_position_error_percent");
  std::printf("mean position error %.3f%%\n", mpe);
  EXPECT_LT(mpe, 0.41);

  // Error budget: the same front-end tracks replaced by the true projections of their landmarks
  // (--oracle-tracks): what the back-end and the track topology give on their own.
  VioArgs oa = va;
  oa.out = dir.file("oracle");
  oa.oracle_scene = std::string(EVIO_SOURCE_DIR) + "/datasets/poster_6dof.yaml";
  std::ostringstream oo;
  ASSERT_EQ(run_vio(oa, oo), 0) << oo.str();
  const std::string ostats = read(oa.out + "/stats.json");
  ASSERT_NE(ostats.find("\"oracle\": {"), std::string::npos) << ostats;
  EXPECT_GT(json_value(ostats, "replaced"), 1e4);
  const double ompe = json_value(read(oa.out + "/eval.json"), "mean_position_error_percent");
  std::printf("oracle tracks: mean position error %.3f%%\n", ompe);
  EXPECT_LT(ompe, 0.05);  // measured 0.038% (0.069% with the library's real-sensor bias priors)

  // --oracle-error real passes the front-end's own observations through (re-expressed as the true
  // projection plus the error: equal up to rounding): the same estimate.
  VioArgs ra = oa;
  ra.out = dir.file("oracle_real");
  ra.oracle_error = "real";
  ra.oracle_observations = true;
  std::ostringstream ro;
  ASSERT_EQ(run_vio(ra, ro), 0) << ro.str();
  const double rmpe = json_value(read(ra.out + "/eval.json"), "mean_position_error_percent");
  EXPECT_NEAR(rmpe, mpe, 0.002);
  // --oracle-observations: one CSV row per observation the oracle measured (as many as it replaced).
  {
    std::ifstream csv(ra.out + "/oracle_observations.csv");
    std::string header, line;
    ASSERT_TRUE(std::getline(csv, header));
    EXPECT_EQ(header.rfind("t_s,track_id,age,error_x_px,error_y_px,common_x_px,common_y_px,true_x_px,true_y_px,", 0), 0u) << header;
    int64_t rows = 0;
    while (std::getline(csv, line)) ++rows;
    EXPECT_EQ(static_cast<double>(rows), json_value(read(ra.out + "/stats.json"), "replaced"));
  }
  ra.oracle_observations = false;
  // --oracle-frame-motion: the frames' translation compensation from the true velocity and depth.
  ra.out = dir.file("oracle_frame_motion");
  ra.oracle_frame_motion = true;
  ASSERT_EQ(run_vio(ra, ro), 0) << ro.str();
  const double fmpe = json_value(read(ra.out + "/eval.json"), "mean_position_error_percent");
  std::printf("true frame motion: mean position error %.3f%%\n", fmpe);
  EXPECT_GT(std::abs(fmpe - mpe), 0.002);  // the compensation's inputs changed the estimate
  // Measured 0.354% against 0.274% with the estimate's velocity and depth (before keyframe chaining
  // and the two-point RANSAC: 0.243% against 0.311%): on these 6 s the true frame motion is not the
  // term that decides the error.
  EXPECT_LT(fmpe, 0.42);
}

// The poster_6dof motion-capture replay (needs the shared real data): its slow, translating start
// (0.1-0.2 m/s) once made keyframes rotation-only and drifted 90 deg in yaw (52.7% position error
// over 20 s); it must stay 6-DoF throughout.
TEST(VioCommand, MocapReplayKeepsSlowTranslationSixDof) {
  const auto real = evio_test::real_data_dir("trajectories");
  if (!real) GTEST_SKIP() << "real motion-capture trajectory not found";
  evio_test::TempDir dir;
  const VioArgs va = vio_on(simulate_scene(dir, "poster_6dof_mocap.yaml", 12.0, {"trajectory.path=" + *real + "/poster_6dof_mocap.csv"}),
                            dir.file("vio"));
  const std::string ev = read(va.out + "/eval.json");
  const double mpe = json_value(ev, "mean_position_error_percent");
  const double yaw = json_value(ev, "final_yaw_error_deg");
  std::printf("mocap replay 12 s: mean position error %.3f%%, final yaw error %.2f deg\n", mpe, yaw);
  // 6-DoF on every keyframe but at most one (the pixel test alone once chose rotation-only here
  // for seconds and drifted; now one keyframe 0.55 s after the initialisation, 5 keyframes into the
  // window, passes the test, with no effect on the error). Bounds ~1.25x the figures measured before
  // keyframe chaining (seed 1: 0.636% and 0.92 deg; seeds 1-6 0.33-0.64%); now 0.459%, 0.33 deg.
  const std::string stats = read(va.out + "/stats.json");
  EXPECT_LE(json_value(stats, "rotation_only_keyframes"), 1.0) << stats;
  EXPECT_NE(stats.find("\"motion_model_tests\": [\n    {\"t\": "), std::string::npos);
  EXPECT_LT(mpe, 0.80);
  EXPECT_LT(std::abs(yaw), 1.15);
}

// The crosscheck simulator's rot_fast preset (skipped when the simulator is not there): the IMU
// turns in place (up to ~200 deg/s) with the camera 4 cm away on a lever arm, in front of a
// panorama at infinity. The image cannot see the lever arm but the IMU feels its centripetal
// acceleration: with the camera centre as the only candidate centre the IMU vetoed the model on
// almost every keyframe and the position wandered by metres (ATE 2.4 m over 10 s); with the IMU
// origin as a candidate the rotation-only model holds and the position stays put.
TEST(VioCommand, CrosscheckRotationAboutTheImuIsRotationOnly) {
  evio_test::TempDir dir;
  const std::string seq = dir.file("rot_fast");
  const int rc = crosscheck_generate(seq, "rot_fast 1", 5.0);
  if (rc == 77) GTEST_SKIP() << "crosscheck simulator not available: " << read(seq + ".log");
  ASSERT_EQ(rc, 0) << read(seq + ".log");
  const VioArgs va = vio_on(seq, dir.file("vio"), "");
  const std::string stats = read(va.out + "/stats.json");
  const double kf = json_value(stats, "keyframes"), rot = json_value(stats, "rotation_only_keyframes");
  const double ate = json_value(read(va.out + "/eval.json"), "rmse");
  std::printf("crosscheck rot_fast 5 s: %g of %g keyframes rotation-only, ATE %.4f m\n", rot, kf, ate);
  EXPECT_NE(stats.find("\"centre\": \"imu\", \"rotation_only\": true"), std::string::npos);
  EXPECT_GT(rot, 0.45 * kf) << stats;  // measured 28 of 50
  EXPECT_LT(ate, 0.001);  // measured 0.4 mm
}

// boxes_6dof (several boxes, 0.1-0.5 m/s): track losses make keyframes 10 ms apart, over which a
// translation shows no parallax, and at 0.1-0.15 m/s (5.9-6.2 s) the image test chose R even over
// 50 ms. The reference view at least model_selection_min_interval_s back and the IMU veto keep it
// 6-DoF: measured 0 rotation-only keyframes (29 before, 1.96% -> 1.64% over 10 s).
TEST(VioCommand, BoxesSceneNeverRotationOnly) {
  evio_test::TempDir dir;
  const VioArgs va = vio_on(simulate_scene(dir, "boxes_6dof.yaml", 7.0), dir.file("vio"));
  const std::string stats = read(va.out + "/stats.json");
  EXPECT_EQ(json_value(stats, "rotation_only_keyframes"), 0.0);
  EXPECT_EQ(json_value(stats, "rotation_only_share"), 0.0);  // the model block says 6-DoF throughout
  EXPECT_NE(stats.find("\"imu_veto\": true"), std::string::npos) << "the veto never acted";
  EXPECT_NE(stats.find("\"baseline_s\": "), std::string::npos);
}

// Pure rotation (poster_rotation scene, up to ~170 deg/s, 3 s): initialised as rotating in place,
// the rotation-only model chosen for most keyframes and reported in the segments, and the
// orientation tracked (se3 evaluation falls back to the first pose: positions do not move).
TEST(VioCommand, PureRotationChoosesTheRotationOnlyModel) {
  evio_test::TempDir dir;
  const VioArgs va = vio_on(simulate_scene(dir, "poster_rotation.yaml", 3.0), dir.file("vio"));
  const std::string stats = read(va.out + "/stats.json");
  const double kf = json_value(stats, "keyframes"), rot = json_value(stats, "rotation_only_keyframes");
  // Measured 9 of 20 keyframes: tracks kept over the short baselines of event frames live long, so
  // keyframes come every 0.1-0.2 s; rotation-only from 2.25 s (1.2 s after the motion starts, the
  // general model having won by more than the margin over a 0.16 s baseline at 1.69 s) to the end.
  EXPECT_GT(rot, 0.4 * kf) << stats;
  EXPECT_NE(stats.find("\"model\": \"rotation_only\""), std::string::npos);
  // The model block: rotation-only over the end of the run (by time), each segment's keyframes and
  // GRIC margin (general minus rotation-only: positive where rotation-only won), adaptive frames.
  // Measured 0.41 of the time from initialisation (1.01 s) to the end.
  EXPECT_GT(json_value(stats, "rotation_only_share"), 0.35) << stats;
  // Orientation near the gyro's: RRE over 1 s (intervals between the estimate's own poses)
  // measured 0.0278 deg against the gyro's 0.0181 (1.54x).
  const std::string ev = read(va.out + "/eval.json");
  const std::smatch rre = [&ev] {
    std::smatch m;
    std::regex_search(ev, m, std::regex("\"rre\": \\{[^}]*\"deg\": \\{\"rmse\": ([-0-9.eE+]+)[^}]*\\}, \"gyro_count\": [0-9]+, \"gyro_deg\": \\{\"rmse\": ([-0-9.eE+]+)"));
    return m;
  }();
  ASSERT_EQ(rre.size(), 3u) << ev;
  EXPECT_LT(std::stod(rre[1]), 1.75 * std::stod(rre[2])) << ev;
  std::smatch seg;
  ASSERT_TRUE(std::regex_search(stats, seg, std::regex("\"model\": \"rotation_only\", \"t_start_s\": [0-9.]+, \"t_end_s\": "
                                                       "[0-9.]+, \"keyframes\": ([0-9]+), \"gric_margin_mean\": ([-0-9.eE+]+)")));
  EXPECT_GE(std::stoi(seg[1]), 8);  // measured 9
  EXPECT_GT(std::stod(seg[2]), 0.0);
  EXPECT_NE(stats.find("\"adaptive\": true"), std::string::npos);
  EXPECT_NE(stats.find("\"initialisation\": {\"method\": \"static\""), std::string::npos) << stats;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(ev, m, std::regex("\"rot_deg\": \\{\"rmse\": ([-0-9.eE+]+)")));
  std::printf("orientation error rmse %.3f deg\n", std::stod(m[1]));
  EXPECT_LT(std::stod(m[1]), 0.32);  // measured 0.244 deg (bound ~1.3x)
}

// Robustness on one simulated sequence (poster_6dof, 6 s), each case a modified copy:
// no events for 1 s (event-rate drop), a burst of 10x the event rate for 0.3 s of random noise
// events, a 150 ms IMU gap. Every run finishes, covers the sequence with finite poses, and the
// drop is flagged as a tracking-lost segment.
TEST(VioCommand, EventDropBurstAndImuGap) {
  evio_test::TempDir dir;
  const std::string seq = simulate_scene(dir, "poster_6dof.yaml", 6.0);
  const EventBuffer events = read_ecd_events(seq + "/events.txt");
  const std::vector<ImuSample> imu = read_ecd_imu(seq + "/imu.txt");
  const int64_t t0 = events.front().t_ns;
  auto variant = [&](const std::string& name, const std::vector<Event>& ev, const std::vector<ImuSample>& im) {
    const std::string d = dir.file(name);
    std::filesystem::create_directories(d);
    for (const char* f : {"calib.txt", "calib.yaml", "groundtruth.txt"}) {
      std::filesystem::copy_file(seq + "/" + f, d + "/" + f);
    }
    EcdEventWriter w(d + "/events.txt");
    w.write(EventSpan(ev.data(), ev.size()));
    w.close();
    write_ecd_imu(d + "/imu.txt", im);
    return d;
  };
  std::vector<Event> drop, burst;
  std::mt19937 rng(3);
  for (const Event& e : events) {
    if (e.t_ns < t0 + 3'000'000'000 || e.t_ns >= t0 + 4'000'000'000) drop.push_back(e);
  }
  // Burst: 9 random events per real event in [2.0, 2.3) s (10x the rate).
  for (const Event& e : events) {
    burst.push_back(e);
    if (e.t_ns >= t0 + 2'000'000'000 && e.t_ns < t0 + 2'300'000'000) {
      for (int k = 0; k < 9; ++k) {
        burst.push_back({e.t_ns, static_cast<uint16_t>(rng() % 240), static_cast<uint16_t>(rng() % 180), static_cast<int8_t>(rng() % 2 ? 1 : -1)});
      }
    }
  }
  std::vector<ImuSample> gap;
  for (const ImuSample& m : imu) {
    if (m.t_ns < t0 + 2'500'000'000 || m.t_ns > t0 + 2'650'000'000) gap.push_back(m);
  }
  struct Case {
    std::string name;
    std::string dataset;
  };
  for (const Case& c : {Case{"drop", variant("drop", drop, imu)}, Case{"burst", variant("burst", burst, imu)},
                        Case{"imu_gap", variant("imu_gap", std::vector<Event>(events.begin(), events.end()), gap)}}) {
    const VioArgs va = vio_on(c.dataset, c.dataset + "/vio");
    std::istringstream tin(read(va.out + "/trajectory.tum"));
    double first = -1, last = -1;
    for (std::string l; std::getline(tin, l);) {
      if (l.empty() || l[0] == '#') continue;
      std::istringstream ls(l);
      double v[8];
      for (double& x : v) ASSERT_TRUE(static_cast<bool>(ls >> x)) << c.name << ": " << l;
      for (double x : v) ASSERT_TRUE(std::isfinite(x)) << c.name << ": " << l;
      if (first < 0) first = v[0];
      last = v[0];
    }
    const std::string stats = read(va.out + "/stats.json");
    const double mpe = json_value(read(va.out + "/eval.json"), "mean_position_error_percent");
    std::printf("%s: trajectory %.2f..%.2f s, mean position error %.2f%%\n", c.name.c_str(), first, last, mpe);
    EXPECT_LT(first, 2.5) << c.name;
    EXPECT_GT(last, 5.5) << c.name;
    // Measured 0.67% (drop), 0.91% (burst), 0.38% (IMU gap) against 0.31% undisturbed (chained KLT:
    // 0.60%, 0.78%, 0.35% against 0.36%).
    EXPECT_LT(mpe, 1.0) << c.name;
    if (c.name == "drop") {
      EXPECT_NE(stats.find("\"tracking_lost_segments\": [{"), std::string::npos) << stats;
    }
  }
}

}  // namespace
}  // namespace evio::apps
