#include "vio_command.h"

#include <malloc.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <fstream>
#include <memory>
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
#include "evio/frontend/option_tables.h"
#include "evio/mapping/option_tables.h"
#include "option_tables.h"
#include "vio_stats.h"

namespace evio::apps {
namespace {
namespace fs = std::filesystem;
using namespace yaml_config;  // NOLINT

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
// config). The library's options structs come with their own tables (evio/frontend/option_tables.h;
// the back-end's in option_tables.h).
const Table<C>& vio_config_table() {
  static const Table<C> table = [] {
    auto self = [](C& c) -> C& { return c; };
    Table<C> filters("filter settings");
    filters.section("refractory", refractory_section<C>(), self)
        .section("background_activity", background_activity_section<C>(), self);

    Table<C> frames("frame settings");
    frames.include(frontend::event_frame_table(), &C::frames).boolean("velocity_at_reference", &C::frame_velocity_at_reference);

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
    corner_tracker.include(frontend::corner_tracker_table(), &C::corner_tracker)
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

    using MO = pipeline::MosaicPipelineOptions;
    Table<MO> rt_tracker("rotation tracker settings");
    rt_tracker.choice("method", &MO::tracker_method,
                      {{"pf", pipeline::MosaicTracker::kParticleFilter}, {"odometry+pf", pipeline::MosaicTracker::kOdometryParticleFilter}})
        .section("particles", frontend::rotation_particle_filter_table(), &MO::tracker)
        .section("mosaic", mapping::gradient_mosaic_table(), &MO::mosaic);
    Table<C> rotation_tracker("rotation tracker settings");
    rotation_tracker.boolean("enabled", &C::rotation_tracker)
        .integer("start_keyframes", &C::rotation_tracker_start_keyframes, 1, 1000000)
        .integer("stop_keyframes", &C::rotation_tracker_stop_keyframes, 1, 1000000)
        .duration_ms("history_ms", &C::rotation_tracker_history_ns, Range::kNonNegative)
        .boolean("from_start", &C::rotation_tracker_from_start)
        .boolean("hold_on_stop", &C::rotation_tracker_hold_on_stop)
        .duration_ms("hold_ms", &C::rotation_tracker_hold_ns, Range::kNonNegative)
        .boolean("held_output", &C::rotation_tracker_held_output)
        .number("max_flow_deg_s", &C::rotation_tracker_max_flow_deg_s, Range::kPositive, "deg/s (speed over the median landmark depth)")
        .include(rt_tracker, &C::rotation_tracker_options)
        .note("enabled", "the mosaic's particle filter with the gyro in rotation-dominant spans; factors: window.tracker_*");

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
        .section("reconstruction_tracker", frontend::feature_tracker_table(), &C::reconstruction_tracker)
        .section("tracker", frontend::feature_tracker_table(), &C::tracker)
        .section("aps_tracker", frontend::feature_tracker_table(), &C::aps_tracker)
        .section("aps", aps, self)
        .section("efast", frontend::efast_table(), &C::efast)
        .section("corner_tracker", corner_tracker, self)
        .section("window", sliding_window_table(), &C::window)
        .section("rotation_tracker", rotation_tracker, self)
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

const char* kVioConfigExpected = "a VIO config YAML (see docs/commands/vio.md)";
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

// The true scene of an oracle run (--oracle-tracks): evio's planar scenes, or a crosscheck room
// (meta.json); empty without --oracle-tracks. Its errors come before a dataset is read.
evaluation::RayCaster open_oracle_scene(const VioArgs& args) {
  if (args.oracle_observations && args.oracle_scene.empty())
    throw InputError(args.dataset, 0, "--oracle-observations needs --oracle-tracks", "--oracle-tracks SCENE --oracle-error real --oracle-observations");
  if (args.oracle_observations && args.oracle_error == "none")
    throw InputError(args.oracle_scene, 0, "--oracle-observations measures the front-end's own error",
                     "--oracle-error real, independent or common_mode");
  if (args.oracle_frame_plane && !args.oracle_frame_motion)
    throw InputError(args.dataset, 0, "--oracle-frame-plane needs --oracle-frame-motion", "--oracle-frame-motion --oracle-frame-plane");
  if (args.oracle_frame_motion && args.oracle_scene.empty())
    throw InputError(args.dataset, 0, "--oracle-frame-motion needs the scene", "--oracle-tracks SCENE.yaml and --gt GT.tum");
  if (args.oracle_scene.empty()) return {};
  if (args.gt.empty()) throw InputError(args.oracle_scene, 0, "--oracle-tracks needs the true trajectory", "--gt GT.tum");
  if (fs::path(args.oracle_scene).extension() == ".json") return evaluation::load_crosscheck_room(args.oracle_scene).caster();
  const simulator::SimulationConfig sc = simulator::load_simulation_config(args.oracle_scene);
  auto planes = std::dynamic_pointer_cast<const simulator::PlanarScene>(sc.scene);
  if (!planes) throw InputError(args.oracle_scene, 0, "--oracle-tracks needs a planes scene (got " + sc.scene_type + ")", "scene: planes");
  return [planes](const Eigen::Vector3d& o, const Eigen::Vector3d& d) { return planes->intersect(o, d); };
}

// The recording with its calibration: --calib, else the dataset folder's calib.yaml (camchain +
// imu0), else the reader's; the IMU noise from the Kalibr file's imu0 when it has one.
struct VioRecording {
  std::unique_ptr<DatasetReader> reader;
  calib::CameraCalibration camera;
  calib::ImuNoise noise;
  std::string noise_source;
};

VioRecording open_recording(const VioArgs& args, const VioConfig& cfg) {
  VioRecording rec;
  rec.reader = open_dataset(args.dataset, args.dataset_options);
  const DatasetCalibration found = find_dataset_calibration(args.dataset, args.calib, *rec.reader);
  rec.noise = cfg.imu_noise;
  rec.noise_source = args.config.empty() ? "defaults" : args.config;
  if (!found.kalibr_yaml.empty()) {
    try {
      rec.noise = calib::load_kalibr_imu(found.kalibr_yaml);
      rec.noise_source = found.kalibr_yaml;
    } catch (const InputError&) {
      // no imu0 section: keep the config's densities
    }
  }
  if (!found.camera) throw InputError(args.dataset, 0, "no camera calibration", "--calib FILE (Kalibr camchain YAML or ECD calib.txt)");
  rec.camera = *found.camera;
  if (!rec.camera.has_T_c_b) log_warning("camera-IMU extrinsics unknown: T_c_b = identity");
  return rec;
}

// The IMU streamed in with the events (read_imu_samples: memory bounded on long recordings):
// holds what was read and not yet given to the pipeline.
class ImuStream {
 public:
  ImuStream(DatasetReader* reader, const std::string& dataset) : reader_(reader) {
    read_chunk();
    if (imu_.size() < 10) throw InputError(dataset, 0, "the dataset has no IMU samples", "a recording with IMU");
  }
  // Every sample up to t_imu_ns into the pipeline (and the gyro integrator).
  void add_until(int64_t t_imu_ns, pipeline::VioPipeline* vio, evaluation::GyroIntegrator* gyro) {
    for (;;) {
      for (; !imu_.empty() && imu_.front().t_ns <= t_imu_ns; imu_.pop_front()) {
        vio->add_imu(imu_.front());
        if (gyro) gyro->add(imu_.front());
      }
      if (!imu_.empty() || done_) break;
      read_chunk();
    }
  }

 private:
  void read_chunk() {
    chunk_.clear();
    if (reader_->read_imu_samples(&chunk_, 4096) == 0) done_ = true;
    imu_.insert(imu_.end(), chunk_.begin(), chunk_.end());
  }
  DatasetReader* reader_;
  std::deque<ImuSample> imu_;
  std::vector<ImuSample> chunk_;
  bool done_ = false;
};

// The diagnostics hooked into the pipeline: init from the ground truth, the track oracle, the
// tracking images. Returns the oracle (null without --oracle-tracks) for its statistics.
std::unique_ptr<evaluation::TrackOracle> attach_diagnostics(const VioArgs& args, const VioConfig& cfg,
                                                            const calib::CameraCalibration& cal,
                                                            const evaluation::RayCaster& oracle_cast, pipeline::VioPipeline* vio) {
  if (cfg.init == pipeline::VioInitMethod::kGiven) {
    if (args.gt.empty()) throw InputError(args.config, 0, "init.method groundtruth needs --gt", "--gt GT.tum, or another init.method");
    vio->set_initial_state_provider([gt = read_trajectory(args.gt)](int64_t t_ns) { return evaluation::groundtruth_state(gt, t_ns); });
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
    oracle = std::make_unique<evaluation::TrackOracle>(read_trajectory(args.gt), cal, oracle_cast, oo);
    vio->set_observation_filter([o = oracle.get()](FeatureObservations* f) { o->apply(f); });
    if (args.oracle_observations) {
      auto csv = std::make_shared<std::ofstream>((fs::path(args.out) / "oracle_observations.csv").string());
      *csv << "t_s,track_id,age,error_x_px,error_y_px,common_x_px,common_y_px,true_x_px,true_y_px,flow_x_px_s,flow_y_px_s,depth_m,"
              "qw_c_w,qx_c_w,qy_c_w,qz_c_w\n";
      oracle->set_observation_sink([csv](const evaluation::OracleObservation& m) {
        char row[400];
        std::snprintf(row, sizeof row, "%s,%lld,%lld,%.4f,%.4f,%.4f,%.4f,%.3f,%.3f,%.2f,%.2f,%.4f,%.9f,%.9f,%.9f,%.9f\n",
                      format_seconds(m.t_ns).c_str(), static_cast<long long>(m.track_id), static_cast<long long>(m.age), m.error_px.x(),
                      m.error_px.y(), m.common_mode_px.x(), m.common_mode_px.y(), m.true_px.x(), m.true_px.y(), m.true_flow_px_s.x(),
                      m.true_flow_px_s.y(), m.depth_m, m.q_c_w.w(), m.q_c_w.x(), m.q_c_w.y(), m.q_c_w.z());
        *csv << row;
      });
    }
    if (args.oracle_frame_motion) {
      vio->set_frame_motion_oracle(
          [gt = read_trajectory(args.gt), T_c_b = cal.T_c_b, plane = args.oracle_frame_plane, cast = oracle_cast](
              const FeatureObservations& f, Eigen::Vector3d* v_c, double* depth_m, Eigen::Vector4d* plane_c) {
            return evaluation::true_frame_motion(gt, T_c_b, cast, f, v_c, depth_m, plane ? plane_c : nullptr);
          });
    }
  }
  if (args.dump_tracking_images > 0) {
    const fs::path dir = fs::path(args.out) / "tracking_images";
    fs::create_directories(dir);
    vio->set_tracking_image_callback([dir, n = args.dump_tracking_images, k = int64_t{0}](int64_t t_ns, const cv::Mat& image) mutable {
      if (k++ % n == 0) write_image((dir / ("frame_" + format_seconds(t_ns) + ".png")).string(), image);
    });
  }
  return oracle;
}

// The files the pipeline streams into: observations.txt, and the output states as soon as they
// are final (memory bounded by the sliding window, not by the recording's length).
struct VioStreamFiles {
  explicit VioStreamFiles(const fs::path& out)
      : observations((out / "observations.txt").string()),
        trajectory((out / "trajectory.tum").string(), false),
        causal((out / "trajectory_causal.tum").string(), false),
        keyframes((out / "keyframes.txt").string(), true) {}

  void attach(pipeline::VioPipeline* vio) {
    observations << "# t[s] track_id bx by bz  (front-end observations: unit bearings in the camera frame, body clock)\n";
    vio->set_observation_callback([this](const FeatureObservations& f) {
      for (const auto& o : f.observations) {
        char line[160];
        std::snprintf(line, sizeof(line), "%s %lld %.7f %.7f %.7f\n", format_seconds(f.t_ns).c_str(),
                      static_cast<long long>(o.track_id), o.bearing_c.x(), o.bearing_c.y(), o.bearing_c.z());
        observations << line;
      }
    });
    vio->set_state_callback([this](pipeline::VioPipeline::StateKind kind, const VioState& s) {
      switch (kind) {
        case pipeline::VioPipeline::StateKind::kTrajectory: trajectory.add(s); break;
        case pipeline::VioPipeline::StateKind::kCausal: causal.add(s); break;
        case pipeline::VioPipeline::StateKind::kKeyframe: keyframes.add(s); break;
      }
    });
  }
  void close() {
    trajectory.close();
    causal.close();
    keyframes.close();
  }

  std::ofstream observations;
  StateFile trajectory, causal, keyframes;
};

// The recording through the pipeline: for APS inputs every IMU sample and every frame first (the
// events+aps merge needs the frame times around each event frame; images decoded one at a time);
// then the events in chunks, the IMU up to 1 s ahead of each (the pipeline keeps only what it
// still needs; the result does not depend on the interleaving). Returns the wall time in s.
double stream_recording(const VioArgs& args, const VioConfig& cfg, VioRecording* rec, ImuStream* imu,
                        pipeline::VioPipeline* vio, evaluation::GyroIntegrator* gyro) {
  if (cfg.inputs != pipeline::VioInputs::kEvents) imu->add_until(std::numeric_limits<int64_t>::max(), vio, gyro);
  const auto wall0 = std::chrono::steady_clock::now();
  if (cfg.inputs != pipeline::VioInputs::kEvents) {
    std::vector<Frame> frames = rec->reader->read_frames();
    if (frames.empty()) {
      throw InputError(args.dataset, 0, std::string("inputs: ") + pipeline::to_string(cfg.inputs) + " needs intensity (APS) frames and the recording has none",
                       "inputs: events, or a recording with frames (ECD images.txt, AEDAT4 frames, ...)");
    }
    for (Frame& f : frames) {
      if (f.image.empty()) load_frame_image(&f);
      vio->add_frame(f);
      f.image.release();
    }
  }
  Progress progress("evio vio", args.progress, "events");
  EventBuffer chunk;
  int64_t events = 0, t_first = 0, t_last = 0;
  while (cfg.inputs != pipeline::VioInputs::kAps) {
    chunk.clear();
    if (rec->reader->read_events(&chunk, size_t{1} << 18) == 0) break;
    const EventSpan span = chunk.span();
    imu->add_until(span.back().t_ns + rec->camera.time_shift_ns + 1'000'000'000, vio, gyro);
    vio->add_events(span);
    if (events == 0) t_first = span.front().t_ns;
    t_last = span.back().t_ns;
    events += static_cast<int64_t>(span.size());
    const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
    const double seq = static_cast<double>(t_last - t_first) * 1e-9;
    progress.update(rec->reader->progress(), events, "real-time factor " + json_number(seq > 0 ? elapsed / seq : 0.0, 10));
  }
  imu->add_until(std::numeric_limits<int64_t>::max(), vio, gyro);
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - wall0).count();
}

// No state came (not initialised, or no frame after the initialisation): no trajectory files, and
// an error that says why.
void check_states(const VioArgs& args, const pipeline::VioResult& r, size_t states) {
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
  if (states == 0) {
    no_state("initialised at " + format_seconds(r.init_t_ns) + " s (" + init_description(r.init_method) +
                 ") but no frame after it had features to track: no state to write",
             "a scene with texture the front-end can track (" + std::to_string(r.stats.frontend_frames) +
                 " front-end frames were made; see frames.* and tracker.* in --print-config)");
  }
}

// Everything but the evaluation: reads, estimates, writes the outputs. Its memory (pipeline, map,
// statistics) is released before the evaluation loads the ground truth, so that a run's peak is the
// larger of the two, not their sum.
int run_vio_estimation(const VioArgs& args, std::ostream& out, evaluation::GyroIntegrator* gyro) {
  // One core: OpenCV's parallel loops (the KLT's per-point loop) run inline instead of handing
  // work to TBB worker threads, whose hand-offs and spinning cost CPU time for no gain here.
  cv::setNumThreads(1);
  const evaluation::RayCaster oracle_cast = open_oracle_scene(args);
  std::string resolved;
  const VioConfig cfg = load_vio_config(args.config, &resolved, args.set);
  VioRecording rec = open_recording(args, cfg);
  ImuStream imu(rec.reader.get(), args.dataset);
  fs::create_directories(args.out);
  {
    std::ofstream f((fs::path(args.out) / "vio_config.yaml").string());
    f << resolved;
  }
  pipeline::VioPipeline vio(cfg, rec.camera, rec.noise);
  const std::unique_ptr<evaluation::TrackOracle> oracle = attach_diagnostics(args, cfg, rec.camera, oracle_cast, &vio);
  VioStreamFiles files(args.out);
  files.attach(&vio);

  VioRunSummary run;
  run.processing_s = stream_recording(args, cfg, &rec, &imu, &vio, gyro);
  const pipeline::VioResult r = vio.finish();
  files.close();
  const pipeline::VioStats& vs = r.stats;
  run.duration_s = static_cast<double>(cfg.inputs == pipeline::VioInputs::kAps ? vs.t_last_aps_ns - vs.t_first_aps_ns
                                                                               : vs.t_last_event_ns - vs.t_first_event_ns) * 1e-9;
  check_states(args, r, files.trajectory.count());
  run.init_method = init_description(r.init_method);
  run.noise_source = rec.noise_source;

  std::vector<mapping::MapPoint> pts;
  for (const auto& [id, p] : r.landmarks) pts.push_back({p, static_cast<float>(id)});
  mapping::write_landmark_map((fs::path(args.out) / "map.ply").string(), pts);
  run.landmarks = pts.size();
  write_vio_stats((fs::path(args.out) / "stats.json").string(), args, cfg, r, run, oracle.get());
  print_vio_summary(out, r, run);
  return 0;
}

}  // namespace

int run_vio(const VioArgs& args, std::ostream& out) {
  if (args.gt_align_first_pose && args.gt.empty())
    throw InputError(args.dataset, 0, "--gt-align-first-pose aligns the evaluation, which needs the ground truth",
                     "--gt GT.tum --gt-align-first-pose");
  // The measured gyro integrated alone (the reference of the evaluation's relative rotation error).
  evaluation::GyroIntegrator gyro;
  const int rc = run_vio_estimation(args, out, args.gt.empty() ? nullptr : &gyro);
  if (rc != 0) return rc;
  malloc_trim(0);  // hand the estimator's freed heap back before the evaluation allocates its own
  if (!args.gt.empty()) {
    EvalArgs ea;
    ea.groundtruth = args.gt;
    ea.estimates = {(fs::path(args.out) / "trajectory.tum").string(), (fs::path(args.out) / "trajectory_causal.tum").string()};
    ea.options.alignment.method = args.gt_align_first_pose ? evaluation::Alignment::kFirstPose : evaluation::Alignment::kSE3;
    ea.options.alignment.first_s = args.gt_align_first_pose ? 0.0 : 5.0;
    if (gyro.samples() >= 2) ea.gyro_orientation = gyro.trajectory();
    const auto results = evaluate_all(ea);
    std::ofstream f((fs::path(args.out) / "eval.json").string());
    f << results_json(ea, results);
    const auto& e = results.front().result;
    char buf[512];
    std::snprintf(buf, sizeof(buf),
                  "evaluation    ATE rmse %.4f m, mean position error %.3f%% of %.2f m, final yaw error %.2f deg, yaw drift "
                  "%.4f deg/m (%s)\n",
                  e.ate.trans_m.rmse, e.mean_position_error_percent, e.groundtruth_length_m, e.final_yaw_error_deg,
                  e.yaw_drift_deg_per_m, args.gt_align_first_pose ? "the first pose aligned" : "SE3 on the first 5 s");
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
