#include "vio_command.h"

#include <malloc.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <fstream>
#include <limits>
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
#include "evio/evaluation/box_room_scene.h"
#include "evio/evaluation/rotation_error.h"
#include "evio/evaluation/track_oracle.h"
#include "evio/mapping/landmark_map.h"
#include "evio/sensors/ecd.h"
#include "evio/sensors/image_io.h"
#include "evio/sensors/time.h"
#include "evio/calib/json.h"
#include "evio/sensors/dataset_calibration.h"
#include "progress.h"
#include "evio/simulator/scene_config.h"
#include "evio/sensors/config_table.h"
#include "option_tables.h"

namespace evio::apps {
namespace {
namespace fs = std::filesystem;
using namespace yaml_config;  // NOLINT

// A JSON list body of spans: {"t_begin": s, "t_end": s, "reason": "..."}, comma-separated.
void write_segments(std::ostream& j, const std::vector<pipeline::VioSegment>& segments) {
  for (size_t i = 0; i < segments.size(); ++i) {
    const pipeline::VioSegment& l = segments[i];
    j << (i ? ", " : "") << "{\"t_begin\": " << format_seconds(l.t_begin_ns) << ", \"t_end\": " << format_seconds(l.t_end_ns)
      << ", \"reason\": \"" << l.what << "\"}";
  }
}

std::string fmt_g(double v) {
  char b[40];
  std::snprintf(b, sizeof(b), "%.4f", v);
  return b;
}

using pipeline::VioFrontEnd;
using pipeline::VioInitMethod;
using pipeline::VioInputs;
using C = VioConfig;

// The table of `--config` and `--set` (one declaration per key: reading, validation, the resolved
// config). The library's options structs come with their own tables (option_tables.h).
const Table<C>& vio_config_table() {
  static const Table<C> table = [] {
    auto self = [](C& c) -> C& { return c; };
    Table<C> filters("filter settings");
    filters.section("refractory", refractory_section<C>(), self)
        .section("background_activity", background_activity_section<C>(), self);

    Table<C> frames("frame settings");
    frames.include(event_frame_table(), &C::frames).boolean("velocity_at_reference", &C::frame_velocity_at_reference);

    Table<C> recon("reconstruction settings");
    using CF = mapping::ComplementaryFilterOptions;
    Table<CF> cf("high-pass filter settings");
    cf.number("cutoff_hz", &CF::cutoff_hz, Range::kNonNegative, "Hz")
        .number("contrast_on", &CF::contrast_on, Range::kPositive, "log intensity")
        .number("contrast_off", &CF::contrast_off, Range::kPositive, "log intensity");
    recon.include(cf, &C::reconstruction).number("grey_per_log", &C::reconstruction_grey_per_log, Range::kPositive, "grey levels per log unit")
        .number("blur_px", &C::reconstruction_blur_px, Range::kNonNegative, "px (Gaussian sigma; 0: none)");

    Table<C> aps("APS settings");
    aps.number("pixel_sigma", &C::aps_pixel_sigma_px, Range::kPositive, "px")
        .number("event_pixel_sigma", &C::aps_event_pixel_sigma_px, Range::kPositive, "px")
        .duration_ms("max_gap_ms", &C::aps_max_gap_ns, Range::kPositive);

    Table<C> corner_tracker("corner tracker settings");
    corner_tracker.include(corner_tracker_table(), &C::corner_tracker)
        .duration_ms("observation_period_ms", &C::observation_period_ns, Range::kPositive)
        .duration_ms("min_track_age_ms", &C::min_track_age_ns, Range::kNonNegative)
        .number("min_bearing_z", &C::corner_min_bearing_z, Range::kUnit, "cos of the angle to the optical axis, < 1");

    Table<C> imu("IMU settings");
    imu.include(imu_noise_table(), &C::imu_noise)
        .duration_ms("lookahead_ms", &C::imu_lookahead_ns, Range::kNonNegative)
        .duration_ms("wait_ms", &C::imu_wait_ns, Range::kNonNegative);

    Table<C> init("initialisation settings");
    init.choice("method", &C::init,
                {{"auto", VioInitMethod::kAuto},
                 {"static", VioInitMethod::kStatic},
                 {"alignment", VioInitMethod::kAlignment},
                 {"groundtruth", VioInitMethod::kGiven}})
        .duration_ms("window_ms", &C::init_window_ns, Range::kPositive)
        .number("retry_slide_fraction", &C::init_retry_slide_fraction, Range::kUnit, "of window_ms, > 0")
        .duration_ms("imu_history_ms", &C::init_imu_history_ns, Range::kNonNegative)
        .section("static", static_init_table(), &C::static_init)
        .section("alignment", visual_inertial_init_table(), &C::vi_init);

    Table<C> reports("report settings");
    reports.integer("tracking_lost_min_tracks", &C::tracking_lost_min_tracks, 0, 100000)
        .duration_ms("tracking_lost_min_duration_ms", &C::tracking_lost_min_duration_ns, Range::kPositive)
        .integer("event_rate_drop_windows", &C::event_rate_drop_windows, 1, 100000)
        .duration_ms("imu_only_min_duration_ms", &C::imu_only_min_duration_ns, Range::kPositive)
        .number("health_visual_chi2_max", &C::health_visual_chi2_max, Range::kPositive, "chi2 per residual dimension")
        .number("health_imu_chi2_max", &C::health_imu_chi2_max, Range::kPositive, "chi2 per residual dimension")
        .integer("health_min_landmarks", &C::health_min_landmarks, 0, 100000)
        .number("health_gyro_bias_sigmas_max", &C::health_gyro_bias_sigmas_max, Range::kPositive, "sigmas of the gyro-bias prior");

    Table<C> top("VIO settings");
    top.choice("inputs", &C::inputs,
               {{"events", VioInputs::kEvents}, {"aps", VioInputs::kAps}, {"events+aps", VioInputs::kEventsAndAps}})
        .choice("frontend", &C::frontend, {{"frames", VioFrontEnd::kFrames}, {"corners", VioFrontEnd::kCorners}})
        .section("filters", filters, self)
        .section("frames", frames, self)
        .choice("tracking_image", &C::tracking_image,
                {{"event_frame", pipeline::VioTrackingImage::kEventFrame},
                 {"reconstruction", pipeline::VioTrackingImage::kReconstruction}})
        .section("reconstruction", recon, self)
        .section("reconstruction_tracker", feature_tracker_table(), &C::reconstruction_tracker)
        .section("tracker", feature_tracker_table(), &C::tracker)
        .section("aps_tracker", feature_tracker_table(), &C::aps_tracker)
        .section("aps", aps, self)
        .section("efast", efast_table(), &C::efast)
        .section("corner_tracker", corner_tracker, self)
        .section("window", sliding_window_table(), &C::window)
        .boolean("keyframe_chaining", &C::keyframe_chaining)
        .section("imu", imu, self)
        .section("init", init, self)
        .section("reports", reports, self)
        .ignored("description")
        .validate();
    return top;
  }();
  return table;
}

const char* kVioConfigExpected = "a VIO config YAML (see README.md, `evio vio`)";
const char* kVioConfigHeader =
    "# evio vio configuration, resolved: every key with the value used (comments: unit and range).\n"
    "# Readable by `evio vio --config`.\n";

}  // namespace

VioConfig default_vio_config() { return VioConfig{}; }

VioConfig load_vio_config(const std::string& path, std::string* resolved_yaml, const std::vector<std::string>& sets) {
  VioConfig c = read_config(vio_config_table(), default_vio_config(), path, sets, kVioConfigExpected);
  if (resolved_yaml) *resolved_yaml = vio_config_text(c);
  return c;
}

std::string vio_config_text(const VioConfig& c) { return config_text(vio_config_table(), c, kVioConfigHeader); }

namespace {

// An output file of states written as the pipeline streams them (trajectory.tum and
// trajectory_causal.tum in TUM form, keyframes.txt with velocity and biases).
class StateFile {
 public:
  StateFile(std::string path, bool full) : path_(std::move(path)), full_(full), f_(path_) {
    if (!f_) throw InputError(path_, 0, "cannot create the file", "a writable output folder");
    f_ << (full_ ? "# t[s] x y z qx qy qz qw vx vy vz bgx bgy bgz bax bay baz  (T_w_b, v_w m/s, biases rad/s and m/s^2)\n"
                 : "# t[s] x y z qx qy qz qw  (body/IMU pose T_w_b, world gravity along -z)\n");
  }
  void add(const VioState& s) {
    char line[512];
    const Eigen::Quaterniond& q = s.T_w_b.rotation;
    const Eigen::Vector3d& p = s.T_w_b.translation;
    if (full_) {
      std::snprintf(line, sizeof(line), "%s %.9f %.9f %.9f %.9f %.9f %.9f %.9f %.6f %.6f %.6f %.7f %.7f %.7f %.6f %.6f %.6f\n",
                    format_seconds(s.t_ns).c_str(), p.x(), p.y(), p.z(), q.x(), q.y(), q.z(), q.w(), s.v_w.x(), s.v_w.y(),
                    s.v_w.z(), s.bias_gyro.x(), s.bias_gyro.y(), s.bias_gyro.z(), s.bias_accel.x(), s.bias_accel.y(),
                    s.bias_accel.z());
    } else {
      std::snprintf(line, sizeof(line), "%s %.9f %.9f %.9f %.9f %.9f %.9f %.9f\n", format_seconds(s.t_ns).c_str(), p.x(),
                    p.y(), p.z(), q.x(), q.y(), q.z(), q.w());
    }
    f_ << line;
    ++count_;
  }
  size_t count() const { return count_; }
  void close() {
    f_.close();
    if (!f_) throw InputError(path_, 0, "write failed (disk full?)", "a writable output folder");
  }
 private:
  std::string path_;
  bool full_;
  std::ofstream f_;
  size_t count_ = 0;
};

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

namespace {

// Everything but the evaluation: reads, estimates, writes the outputs. Its memory (pipeline, map,
// statistics) is released before the evaluation loads the ground truth, so that a run's peak is the
// larger of the two, not their sum (one hour of shapes_6dof: 203 -> see README, "Peak memory").
int run_vio_estimation(const VioArgs& args, std::ostream& out, evaluation::GyroIntegrator* gyro) {
  // One core: OpenCV's parallel loops (the KLT's per-point loop) run inline instead of handing
  // work to TBB worker threads, whose hand-offs and spinning cost CPU time for no gain here.
  cv::setNumThreads(1);
  // The oracle's scene first: its errors come before reading a dataset.
  evaluation::RayCaster oracle_cast;  // the true scene: evio's planar scenes, or a crosscheck room (meta.json)
  if (args.oracle_frame_plane && !args.oracle_frame_motion)
    throw InputError(args.dataset, 0, "--oracle-frame-plane needs --oracle-frame-motion", "--oracle-frame-motion --oracle-frame-plane");
  if (args.oracle_frame_motion && args.oracle_scene.empty())
    throw InputError(args.dataset, 0, "--oracle-frame-motion needs the scene", "--oracle-tracks SCENE.yaml and --gt GT.tum");
  if (!args.oracle_scene.empty()) {
    if (args.gt.empty()) throw InputError(args.oracle_scene, 0, "--oracle-tracks needs the true trajectory", "--gt GT.tum");
    if (fs::path(args.oracle_scene).extension() == ".json") {
      oracle_cast = evaluation::load_crosscheck_room(args.oracle_scene).caster();
    } else {
      const simulator::SimulationConfig sc = simulator::load_simulation_config(args.oracle_scene);
      auto planes = std::dynamic_pointer_cast<const simulator::PlanarScene>(sc.scene);
      if (!planes)
        throw InputError(args.oracle_scene, 0, "--oracle-tracks needs a planes scene (got " + sc.scene_type + ")", "scene: planes");
      oracle_cast = [planes](const Eigen::Vector3d& o, const Eigen::Vector3d& d) { return planes->intersect(o, d); };
    }
  }
  std::string resolved;
  const VioConfig cfg = load_vio_config(args.config, &resolved, args.set);
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
  // The IMU streams in with the events (read_imu_samples: memory bounded on long recordings):
  // `imu` holds what was read and not yet given to the pipeline.
  std::deque<ImuSample> imu;
  bool imu_done = false;
  std::vector<ImuSample> imu_chunk;
  const auto read_imu_chunk = [&] {
    imu_chunk.clear();
    if (reader->read_imu_samples(&imu_chunk, 4096) == 0) imu_done = true;
    imu.insert(imu.end(), imu_chunk.begin(), imu_chunk.end());
  };
  read_imu_chunk();
  if (imu.size() < 10) throw InputError(args.dataset, 0, "the dataset has no IMU samples", "a recording with IMU");
  fs::create_directories(args.out);
  {
    std::ofstream f((fs::path(args.out) / "vio_config.yaml").string());
    f << resolved;
  }

  pipeline::VioPipeline vio(cfg, *cal, noise);
  if (cfg.init == pipeline::VioInitMethod::kGiven) {
    if (args.gt.empty()) throw InputError(args.config, 0, "init.method groundtruth needs --gt", "--gt GT.tum, or another init.method");
    vio.set_initial_state_provider([gt = read_trajectory(args.gt)](int64_t t_ns) { return evaluation::groundtruth_state(gt, t_ns); });
  }
  std::unique_ptr<evaluation::TrackOracle> oracle;
  if (oracle_cast) {
    evaluation::TrackOracleOptions oo;
    oo.white_noise_px = args.oracle_noise_px;
    oo.drift_px_per_frame = args.oracle_drift_px;
    oo.max_error_px = args.oracle_max_error_px;
    oo.keep_error = args.oracle_error == "real"          ? evaluation::OracleError::kReal
                    : args.oracle_error == "independent" ? evaluation::OracleError::kIndependent
                    : args.oracle_error == "common_mode" ? evaluation::OracleError::kCommonMode
                                                         : evaluation::OracleError::kNone;
    const evaluation::RayCaster& cast = oracle_cast;
    oracle = std::make_unique<evaluation::TrackOracle>(read_trajectory(args.gt), *cal, cast, oo);
    vio.set_observation_filter([o = oracle.get()](FeatureObservations* f) { o->apply(f); });
    if (args.oracle_frame_motion) {
      vio.set_frame_motion_oracle(
          [gt = read_trajectory(args.gt), T_c_b = cal->T_c_b, plane = args.oracle_frame_plane, cast](
              const FeatureObservations& f, Eigen::Vector3d* v_c, double* depth_m, Eigen::Vector4d* plane_c) {
            return evaluation::true_frame_motion(gt, T_c_b, cast, f, v_c, depth_m, plane ? plane_c : nullptr);
          });
    }
  }
  if (args.dump_tracking_images > 0) {
    const fs::path dir = fs::path(args.out) / "tracking_images";
    fs::create_directories(dir);
    vio.set_tracking_image_callback([dir, n = args.dump_tracking_images, k = int64_t{0}](int64_t t_ns, const cv::Mat& image) mutable {
      if (k++ % n == 0) write_image((dir / ("frame_" + format_seconds(t_ns) + ".png")).string(), image);
    });
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
  // The output states go to their files as soon as they are final (memory bounded by the sliding
  // window, not by the recording's length).
  StateFile trajectory_file((fs::path(args.out) / "trajectory.tum").string(), false);
  StateFile causal_file((fs::path(args.out) / "trajectory_causal.tum").string(), false);
  StateFile keyframes_file((fs::path(args.out) / "keyframes.txt").string(), true);
  vio.set_state_callback([&](pipeline::VioPipeline::StateKind kind, const VioState& s) {
    switch (kind) {
      case pipeline::VioPipeline::StateKind::kTrajectory: trajectory_file.add(s); break;
      case pipeline::VioPipeline::StateKind::kCausal: causal_file.add(s); break;
      case pipeline::VioPipeline::StateKind::kKeyframe: keyframes_file.add(s); break;
    }
  });
  // The IMU goes in with the events, up to 1 s ahead of each chunk (the pipeline keeps only what
  // it still needs; the result does not depend on the interleaving), all first for APS inputs.
  const auto add_imu_until = [&](int64_t t_imu_ns) {
    for (;;) {
      for (; !imu.empty() && imu.front().t_ns <= t_imu_ns; imu.pop_front()) {
        vio.add_imu(imu.front());
        if (gyro) gyro->add(imu.front());
      }
      if (!imu.empty() || imu_done) break;
      read_imu_chunk();
    }
  };
  if (cfg.inputs != pipeline::VioInputs::kEvents) add_imu_until(std::numeric_limits<int64_t>::max());
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
    add_imu_until(span.back().t_ns + cal->time_shift_ns + 1'000'000'000);
    vio.add_events(span);
    if (events == 0) t_first = span.front().t_ns;
    t_last = span.back().t_ns;
    events += static_cast<int64_t>(span.size());
    const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
    const double seq = static_cast<double>(t_last - t_first) * 1e-9;
    progress.update(reader->progress(), events, "real-time factor " + json_number(seq > 0 ? elapsed / seq : 0.0, 10));
  }
  add_imu_until(std::numeric_limits<int64_t>::max());
  const pipeline::VioResult r = vio.finish();
  trajectory_file.close();
  causal_file.close();
  keyframes_file.close();
  const double processing_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
  const pipeline::VioStats& vs = r.stats;
  const double duration_s =
      static_cast<double>(cfg.inputs == pipeline::VioInputs::kAps ? vs.t_last_aps_ns - vs.t_first_aps_ns
                                                                  : vs.t_last_event_ns - vs.t_first_event_ns) * 1e-9;
  // No state came (not initialised, or no frame after the initialisation): no trajectory files.
  const auto no_state = [&](const std::string& why, const std::string& expected) {
    std::error_code ec;
    for (const char* f : {"trajectory.tum", "trajectory_causal.tum", "keyframes.txt"}) fs::remove(fs::path(args.out) / f, ec);
    throw InputError(args.dataset, 0, why, expected);
  };
  if (!r.initialized) {
    log_debug("vio: " + r.init_failure);
    no_state("could not initialise: " + r.init_failure,
             "a recording that starts still or moves with enough features in the first seconds, with at least "
             "frames.min_events events per frame");
  }
  const std::string init_method = init_description(r.init_method);
  if (trajectory_file.count() == 0) {
    no_state("initialised at " + format_seconds(r.init_t_ns) + " s (" + init_method +
                 ") but no frame after it had features to track: no state to write",
             "a scene with texture the front-end can track (" + std::to_string(vs.frontend_frames) +
                 " front-end frames were made; see frames.* and tracker.* in --print-config)");
  }

  // Outputs.
  std::vector<mapping::MapPoint> pts;
  for (const auto& [id, p] : r.landmarks) pts.push_back({p, static_cast<float>(id)});
  mapping::write_landmark_map((fs::path(args.out) / "map.ply").string(), pts);

  const backend::SlidingWindowStats& st = vs.window;
  std::vector<double> solve = st.solve_time_s;
  std::sort(solve.begin(), solve.end());
  const double med = solve.empty() ? 0 : solve[solve.size() / 2];
  const bool use_frames = cfg.frontend == pipeline::VioFrontEnd::kFrames;
  // The model block: the motion model per segment with the keyframes and GRIC numbers that decided
  // it (margin: GRIC of the general model minus that of rotation-only; > rotation_only_gric_margin
  // for rotation_only_min_keyframes keyframes switches rotation-only on), and the frames' sizes.
  std::ostringstream mj, summary;
  {
    double rot_s = 0, all_s = 0;
    mj << "{\"motion\": {\"selection\": " << (cfg.window.rotation_only_model ? "\"auto\"" : "\"fixed\"")
       << ", \"rule\": \"GRIC per keyframe with hysteresis and the IMU and parallax conditions (backend/sliding_window_estimator.h)\""
       << ", \"gric_margin\": " << json_number(cfg.window.rotation_only_gric_margin, 10) << ", \"min_keyframes\": "
       << cfg.window.rotation_only_min_keyframes << ", \"keyframes\": " << st.keyframes
       << ", \"rotation_only_keyframes\": " << st.rotation_only_keyframes << ", \"segments\": [";
    for (size_t i = 0; i < r.motion_models.size(); ++i) {
      const pipeline::VioSegment& m = r.motion_models[i];
      int keyframes = 0, tested = 0;
      double margin = 0;
      for (const auto& t : st.motion_model_tests) {
        if (t.t_ns < m.t_begin_ns || t.t_ns > m.t_end_ns) continue;
        ++keyframes;
        if (t.best == backend::TwoViewModel::kNone) continue;
        ++tested;
        margin += t.gric_general - t.gric_rotation;
      }
      const double d = static_cast<double>(m.t_end_ns - m.t_begin_ns) * 1e-9;
      all_s += d;
      if (m.what == "rotation_only") rot_s += d;
      mj << (i ? ", " : "") << "{\"model\": \"" << m.what << "\", \"t_start_s\": " << format_seconds(m.t_begin_ns)
         << ", \"t_end_s\": " << format_seconds(m.t_end_ns) << ", \"keyframes\": " << keyframes
         << ", \"gric_margin_mean\": " << json_number(tested ? margin / tested : NAN, 10) << "}";
    }
    const double share = all_s > 0 ? rot_s / all_s : 0.0;
    mj << "], \"rotation_only_s\": " << json_number(rot_s, 10) << ", \"rotation_only_share\": " << json_number(share, 10) << "}";
    summary << "rotation_only " << json_number(100.0 * share, 10) << "% of the time (" << st.rotation_only_keyframes << " of " << st.keyframes
            << " keyframes)";
    if (use_frames) {
      const frontend::EventFrameOptions& fo = cfg.frames;
      const int64_t frames = vs.event_frames.frames_emitted;
      const bool adaptive = fo.min_window_ns > 0;
      mj << ", \"frames\": {\"events_per_frame\": " << fo.events_per_frame << ", \"adaptive\": " << (adaptive ? "true" : "false")
         << ", \"min_window_ms\": " << json_number(fo.min_window_ns * 1e-6, 10) << ", \"max_window_ms\": " << json_number(fo.max_window_ns * 1e-6, 10)
         << ", \"frames\": " << frames << ", \"mean_events_per_frame\": "
         << json_number(frames > 0 ? static_cast<double>(vs.events) / static_cast<double>(frames) : NAN, 10)
         << ", \"mean_frame_interval_ms\": " << json_number(frames > 0 ? 1e3 * duration_s / static_cast<double>(frames) : NAN, 10) << "}";
      summary << "; frames " << (adaptive ? "adaptive" : "fixed") << ", "
              << json_number(frames > 0 ? static_cast<double>(vs.events) / static_cast<double>(frames) : NAN, 10) << " events per frame";
    }
    mj << ", \"summary\": \"" << json_escape(summary.str()) << "\"}";
  }
  // Written as it is formatted: a long run's stats.json (7.5 MB for an hour) is not held in memory twice.
  std::ofstream j((fs::path(args.out) / "stats.json").string());
  j << "{\n  \"dataset\": \"" << json_escape(args.dataset) << "\",\n  \"model\": " << mj.str() << ",\n  \"inputs\": \"" << pipeline::to_string(cfg.inputs)
    << "\",\n  \"frontend\": \"" << pipeline::to_string(cfg.frontend)
    << "\",\n  \"events\": " << vs.events << ",\n  \"corners\": " << vs.corner_events << ",\n  \"frames\": " << st.frames
    << ",\n  \"keyframes\": " << st.keyframes << ",\n  \"landmarks\": " << pts.size()
    << ",\n  \"processing_time_s\": " << json_number(processing_s, 10) << ",\n  \"sequence_duration_s\": " << json_number(duration_s, 10)
    << ",\n  \"real_time_factor\": " << json_number(duration_s > 0 ? processing_s / duration_s : 0.0, 10)
    << ",\n  \"solve_ms_median\": " << json_number(1e3 * med, 10) << ",\n  \"initialisation\": {\"method\": \"" << init_method
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
      << ", \"baseline_s\": " << json_number(m.baseline_s, 10)
      << ", \"gric_static\": " << json_number(m.gric_static, 10) << ", \"gric_rotation\": " << json_number(m.gric_rotation, 10)
      << ", \"gric_general\": " << json_number(m.gric_general, 10) << ", \"imu_chi2\": " << json_number(m.imu_chi2, 10) << ", \"imu_dof\": " << m.imu_dof << ", \"landmarks\": " << m.landmarks << ", \"best\": \""
      << backend::two_view_model_name(m.best) << "\", \"imu_veto\": " << (m.imu_veto ? "true" : "false")
      << ", \"centre\": \"" << (m.centre_imu ? "imu" : "camera") << "\", \"rotation_only\": " << (m.rotation_only ? "true" : "false") << "}";
  }
  j << "],\n  \"tracking_lost_segments\": [";
  write_segments(j, r.tracking_lost);
  j << "],\n  \"health\": {\"keyframes\": [";
  for (size_t i = 0; i < st.health.size(); ++i) {
    const auto& h = st.health[i];
    j << (i ? ",\n    " : "\n    ") << "{\"t\": " << format_seconds(h.t_ns) << ", \"visual_chi2_per_dof\": " << json_number(h.visual_chi2_per_dof, 10)
      << ", \"imu_chi2_per_dof\": " << json_number(h.imu_chi2_per_dof, 10) << ", \"observations\": " << h.observations
      << ", \"landmarks\": " << h.landmarks << ", \"gyro_bias_sigmas\": " << json_number(h.gyro_bias_sigmas, 10) << "}";
  }
  j << "], \"unreliable_segments\": [";
  write_segments(j, r.unreliable);
  j << "]}";
  j << ",\n  \"imu_only_segments\": [";
  write_segments(j, r.imu_only);
  double imu_only_s = 0;
  for (const pipeline::VioSegment& l : r.imu_only) imu_only_s += 1e-9 * static_cast<double>(l.t_end_ns - l.t_begin_ns);
  j << "],\n  \"imu_only_s\": " << json_number(imu_only_s, 10);
  j << ",\n  \"frontend_stats\": {";
  if (use_frames) {
    const auto& ts = vs.tracker;
    const auto& fs_ = vs.event_frames;
    j << "\"event_frames\": " << fs_.frames_emitted << ", \"frames_uncompensated\": " << fs_.frames_uncompensated
      << ", \"frames_dropped_sparse\": " << fs_.frames_dropped_sparse << ", \"tracks_detected\": " << ts.detected
      << ", \"tracked\": " << ts.tracked << ", \"lost_klt\": " << ts.lost_klt << ", \"lost_forward_backward\": " << ts.lost_fb
      << ", \"rejected_ransac\": " << ts.rejected_ransac << ", \"template_fallbacks\": " << ts.template_fallbacks
      << ", \"rejected_anchor\": " << ts.rejected_anchor << ", \"template_rotation_refreshes\": " << ts.template_rotation_refreshes
      << ", \"reacquired\": " << ts.reacquired;
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
    j << ",\n  \"oracle\": {\"scene\": \"" << json_escape(args.oracle_scene) << "\", \"white_noise_px\": " << json_number(args.oracle_noise_px, 10)
      << ", \"drift_px_per_frame\": " << json_number(args.oracle_drift_px, 10) << ", \"replaced\": " << oracle->stats().replaced
      << ", \"dropped\": " << oracle->stats().dropped << ", \"keep_error\": \"" << args.oracle_error
      << "\", \"common_mode_rms_px\": " << json_number(oracle->stats().common_mode_rms_px, 10)
      << ", \"max_error_px\": " << json_number(args.oracle_max_error_px, 10) << ", \"dropped_gross\": " << oracle->stats().dropped_gross << "}";
  }
  j << ",\n  \"outliers_removed\": " << st.outliers_removed << ",\n  \"landmarks_marginalised\": " << st.landmarks_marginalised
    << ",\n  \"observations_dropped\": " << st.observations_dropped
    << ",\n  \"tracked_landmarks_marginalised\": " << st.tracked_landmarks_marginalised << ",\n  \"rotation_only_keyframes\": " << st.rotation_only_keyframes;
  if (cfg.window.estimate_time_offset) j << ",\n  \"time_offset_correction_s\": " << json_number(st.time_offset_s, 10);
  j << "\n}\n";
  j.close();
  if (!j) throw InputError((fs::path(args.out) / "stats.json").string(), 0, "write failed (disk full?)", "a writable output folder");
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
  return 0;
}

}  // namespace

int run_vio(const VioArgs& args, std::ostream& out) {
  // The measured gyro integrated alone (the reference of the evaluation's relative rotation error).
  evaluation::GyroIntegrator gyro;
  const int rc = run_vio_estimation(args, out, args.gt.empty() ? nullptr : &gyro);
  if (rc != 0) return rc;
  malloc_trim(0);  // hand the estimator's freed heap back before the evaluation allocates its own
  if (!args.gt.empty()) {
    EvalArgs ea;
    ea.groundtruth = args.gt;
    ea.estimates = {(fs::path(args.out) / "trajectory.tum").string(), (fs::path(args.out) / "trajectory_causal.tum").string()};
    ea.options.alignment.method = evaluation::Alignment::kSE3;
    ea.options.alignment.first_s = 5.0;
    if (gyro.samples() >= 2) ea.gyro_orientation = gyro.trajectory();
    const auto results = evaluate_all(ea);
    std::ofstream f((fs::path(args.out) / "eval.json").string());
    f << results_json(ea, results);
    const auto& e = results.front().result;
    char buf[512];
    std::snprintf(buf, sizeof(buf),
                  "evaluation    ATE rmse %.4f m, mean position error %.3f%% of %.2f m, final yaw error %.2f deg, yaw drift "
                  "%.4f deg/m (SE3 on the first 5 s)\n",
                  e.ate.trans_m.rmse, e.mean_position_error_percent, e.groundtruth_length_m, e.final_yaw_error_deg,
                  e.yaw_drift_deg_per_m);
    out << buf;
    if (const auto& rre = results.front().rre; rre && rre->deg.count > 0) {
      const auto& g = results.front().rre_gyro;
      std::snprintf(buf, sizeof(buf), "              rotation error over %g s (RRE) %.4f deg rms%s\n", rre->interval_s, rre->deg.rmse,
                    g && g->deg.count > 0 ? (", the gyro alone " + fmt_g(g->deg.rmse) + " deg").c_str() : "");
      out << buf;
    }
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
