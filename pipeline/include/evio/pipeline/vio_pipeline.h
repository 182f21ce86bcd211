// The event-based VIO chain as one synchronous library class: raw camera events are checked
// against the undistortion table, filtered (refractory, background activity) and turned into
// feature observations by one of two front-ends (motion-compensated event frames tracked with
// FAST/KLT/RANSAC under the IMU rotation prior, after Rebecq et al., BMVC 2017; or eFAST corner
// events with corner tracks sampled at a fixed period), the state is initialised (static start,
// visual-inertial alignment, or a given state) and estimated by the keyframe sliding window.
// Intensity (APS) frames can replace or join the events (VioInputs): undistorted and tracked with
// their own FeatureTracker, merged with the event tracks at the APS frame times.
// Plain data in (IMU samples, event spans, frames) and out (VioResult); no files, flags or threads.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Core>

#include "evio/backend/initialization.h"
#include "evio/backend/sliding_window_estimator.h"
#include "evio/calib/calibration_io.h"
#include "evio/frontend/corner_tracker.h"
#include "evio/frontend/efast.h"
#include "evio/frontend/event_filters.h"
#include "evio/frontend/event_frame.h"
#include "evio/frontend/feature_tracker.h"
#include "evio/frontend/frame_undistorter.h"
#include "evio/mapping/reconstruction.h"
#include "evio/pipeline/mosaic_pipeline.h"
#include "evio/sensors/event_buffer.h"
#include "evio/sensors/measurements.h"
#include "evio/sensors/vio_types.h"

namespace evio::pipeline {

// Which front-end turns events into feature observations.
enum class VioFrontEnd {
  kFrames,   // motion-compensated event frames + FAST / KLT / RANSAC (frontend::FeatureTracker)
  kCorners,  // eFAST corner events + corner tracks sampled every observation_period_ns
};

// How the first state is found.
enum class VioInitMethod {
  kAuto,       // static start, else visual-inertial alignment
  kStatic,     // static start only (backend::static_initialization)
  kAlignment,  // visual-inertial alignment only (backend::visual_inertial_initialization)
  kGiven,      // the state of VioPipeline::set_initial_state_provider at the first frame
};

// The image the frames front-end tracks features in.
enum class VioTrackingImage {
  kEventFrame,      // motion-compensated event frames (EventFrameBuilder): the events' edges, whose look
                    // changes with the direction of motion
  kReconstruction,  // the log intensity reconstructed from the events alone by the high-pass filter
                    // (mapping::ComplementaryFilter without frames, Scheerlinck et al., ACCV 2018),
                    // undistorted like an APS frame: the scene's texture, whatever the motion
};

// Which measurement streams feed the estimator.
enum class VioInputs {
  kEvents,        // events through the chosen event front-end (VioFrontEnd)
  kAps,           // intensity (APS) frames only: undistorted, FAST/KLT/RANSAC under the IMU rotation prior
  kEventsAndAps,  // both: the estimator gets the APS frames, each with the event tracks interpolated to its
                  // time; event frames alone where no APS frame is near (aps_max_gap_ns)
};

// Names as written in configuration files and reports: "frames", "corners"; "auto", "static",
// "alignment", "given"; "events", "aps", "events+aps". `option == "name"` compares with a name.
const char* to_string(VioFrontEnd f);
const char* to_string(VioInitMethod m);
const char* to_string(VioInputs i);
const char* to_string(VioTrackingImage i);  // "event_frame", "reconstruction"
inline bool operator==(VioFrontEnd f, std::string_view name) { return name == to_string(f); }
inline bool operator==(VioInitMethod m, std::string_view name) { return name == to_string(m); }
inline bool operator==(VioInputs i, std::string_view name) { return name == to_string(i); }
inline bool operator==(VioTrackingImage i, std::string_view name) { return name == to_string(i); }
inline bool operator!=(VioFrontEnd f, std::string_view name) { return !(f == name); }
inline bool operator!=(VioInitMethod m, std::string_view name) { return !(m == name); }
inline bool operator!=(VioInputs i, std::string_view name) { return !(i == name); }

// Track ids of APS-frame tracks are offset by this, so they never meet event-track ids.
constexpr int64_t kApsTrackIdOffset = int64_t{1} << 40;

// The event trackers' template settings (see VioPipelineOptions::tracker): each feature aligned
// against its patch of up to 10 frames ago, not used once turned by more than 4 deg, and the
// previous frame's alignment when the template loses it.
inline frontend::FeatureTrackerOptions template_tracker_options() {
  frontend::FeatureTrackerOptions t;
  t.template_max_age_frames = 10;
  t.template_fallback = true;
  t.template_max_rotation_deg = 4.0;
  return t;
}

struct VioPipelineOptions {
  VioInputs inputs = VioInputs::kEvents;
  VioFrontEnd frontend = VioFrontEnd::kFrames;  // the event front-end (inputs events and events+aps)

  // Event filters, applied after the undistortion-validity check, before either front-end.
  bool refractory_enabled = true;                                // drop events within period_ns of the pixel's last
  frontend::RefractoryFilterOptions refractory;                  // period_ns (ns)
  bool background_activity_enabled = true;                       // drop events without recent neighbours
  frontend::BackgroundActivityFilterOptions background_activity; // window_ns (ns), radius (px), min_support (count)

  // Frames front-end. Frames of at least 10 ms (min_window_ns): at high event rates (fast motion)
  // frames hold more events instead of coming faster than the tracker needs (poster_rotation at
  // 3.2 M events/s: real-time factor 1.33 -> 0.91, orientation 1.30 -> 0.87 deg rms).
  // Translation compensated too (use_depth) once initialised: without it a frame shows the
  // translational part of the motion at its events' mean time, not at its stamp, and the tracks
  // share an error that follows the acceleration (poster_6dof: per-frame common-mode track step
  // 0.18 -> 0.13 px, its correlation with the accelerometer R^2 0.41 -> 0.04; mean position error
  // on six simulated scenes 0.78-2.73% against 1.14-3.17% without).
  frontend::EventFrameOptions frames = [] {
    frontend::EventFrameOptions f;
    f.min_window_ns = 10'000'000;
    f.use_depth = true;
    return f;
  }();                                                           // events_per_frame, windows (ns), ...
  // use_depth: the camera velocity of a frame's translation compensation. false (default): the
  // latest state's when the frame before it was tracked (one to two frames old by the time the
  // frame closes); true: the latest state propagated with the IMU to the frame's reference time,
  // as the camera centre's velocity (lever arm of T_c_b included). The propagated velocity
  // removes the event tracks' run-ahead along their motion (poster_6dof, anchored error beyond
  // 40 px of displacement +0.78 -> +0.28 px; drift at age 20 1.45 -> 1.30 px) but the trajectory
  // gets worse: mean position error over six scenes x 3 RANSAC seeds 0.427% -> 0.510%, rotation
  // error up (poster 1.0 -> 3.1 deg). Frames built with the true velocity at the reference time
  // lag the true edges by about 0.6 px along the flow (the events' own lag); modelling it
  // (frames.event_lag_px at each scene's measured lag) gives 0.486%, still worse: off.
  bool frame_velocity_at_reference = false;
  // Event-frame tracks: KLT on a 27 px window (the tracker's own default, 21, stays for APS
  // frames and the reconstruction), each feature aligned against its template (its patch of up to
  // 10 frames ago, not the previous frame's: alignment errors add once per template instead of
  // once per frame); a template turned by more than 4 deg is not used (translation-only KLT
  // against a turned patch is biased), and a track its template loses continues from the previous
  // frame (template_fallback). A tracked point still drifts from its scene point by an error that
  // grows with the track's age (the frames' look changes with the motion). A larger window
  // averages more of a sparse event frame but mixes more structure whose look changes: the
  // crosscheck family's dense photographs track better with 19-21 px, evio's own sparser scenes
  // (and their orientation) with 27 px (docs/results/vio.md, "KLT window").
  // Needs window.rotation_only_min_duration_s (see SlidingWindowOptions).
  frontend::FeatureTrackerOptions tracker = [] {
    frontend::FeatureTrackerOptions t = template_tracker_options();
    t.klt_window_px = 27;
    return t;
  }();                                                           // grid, FAST, KLT (px), RANSAC (px)

  // Frames front-end: what the features are tracked in. With kReconstruction, frames are taken
  // at the event frames' times (events_per_frame, min/max_window_ns of `frames`; also through
  // event-rate drops: the reconstruction keeps the texture it has seen) and the tracker gets the
  // high-pass filter's log intensity, undistorted, as 8-bit grey 128 + reconstruction_grey_per_log * L.
  VioTrackingImage tracking_image = VioTrackingImage::kEventFrame;
  mapping::ComplementaryFilterOptions reconstruction = [] {
    mapping::ComplementaryFilterOptions r;
    r.high_pass = true;
    r.use_frames = false;
    r.cutoff_hz = 0.5;
    r.contrast_on = r.contrast_off = 0.2;
    return r;
  }();                                                           // cutoff_hz (Hz), contrast_on/off (log units)
  double reconstruction_grey_per_log = 64.0;                     // grey levels per log-intensity unit, > 0
  // Gaussian smoothing of the reconstruction before tracking (px, >= 0; 0: none): each pixel's
  // log intensity carries its own contrast-threshold error, a white spatial noise the corner
  // detector would otherwise take for texture.
  double reconstruction_blur_px = 1.0;
  frontend::FeatureTrackerOptions reconstruction_tracker = [] {
    frontend::FeatureTrackerOptions t = template_tracker_options();
    t.fast_threshold = 10;
    return t;
  }();

  // Corners front-end.
  frontend::EfastOptions efast;                                  // filter_sae, filter_window_ns (ns)
  frontend::CornerTrackerOptions corner_tracker;                 // max_distance_px (px), max_gap_ns (ns), ...
  int64_t observation_period_ns = 50'000'000;                    // ns, > 0: one observation frame of the active tracks per period
  int64_t min_track_age_ns = 20'000'000;                         // ns, >= 0: younger tracks are not observed
  double corner_min_bearing_z = 1e-3;                            // unit-bearing z (cos of the angle to the axis), [0, 1): corners at or beyond 90 deg are dropped

  // APS frames (inputs aps and events+aps): undistorted into the ideal pinhole and tracked by their
  // own FeatureTracker. FAST threshold 5 (grey levels): intensity frames have less contrast than
  // normalised event frames (on the simulated poster, threshold 20 found 35 tracks per frame, 10
  // fills the 150; on shapes_6dof 10 found 7 tracks per frame). Mean position error with APS
  // frames on five simulated 10 s scenes: threshold 10 0.79%, 5 0.58%, 3 0.58% (5 keeps a margin
  // over real sensors' noise). Their observations enter the estimator with aps_pixel_sigma_px (px, > 0; KLT
  // on simulated 24 Hz frames with 5 ms exposure: 0.04 px between consecutive frames, 0.12 px
  // against the best-fit landmark, against 0.3-0.45 px for event frames; 0.3 px leaves room for
  // real sensors' blur and noise); event observations take aps_event_pixel_sigma_px.
  // RANSAC two_point_triangulating on APS frames: at 20-25 Hz they have the baseline its test needs,
  // and it drops tracks that drift during a hover, which the epipolar-plane test (right for the
  // 100 Hz event frames) keeps as points that did not move (crosscheck planes_quadrotor, APS only:
  // docs/results/vio.md).
  frontend::FeatureTrackerOptions aps_tracker = [] {
    frontend::FeatureTrackerOptions t;
    t.fast_threshold = 5;
    t.ransac = frontend::RansacModel::kTwoPointTriangulating;
    return t;
  }();
  double aps_pixel_sigma_px = 0.3;
  // inputs events+aps: the noise of the event observations next to the APS ones (px, > 0). Event
  // tracks drift (about 1.2 px after ten frames against their landmark's projection), the APS tracks
  // hardly (0.3 px): weighed at window.pixel_sigma (0.5 px) the event tracks pulled the estimate
  // away from the APS geometry. Mean position error on five simulated 10 s scenes (poster, boxes,
  // room, quadrotor, shapes) by this sigma: 0.5 px 0.77%, 1.0 px 0.45%, 1.5 px 0.36%, 2.0 px
  // 0.38%, 3.0 px 0.38%; APS alone 0.79%.
  double aps_event_pixel_sigma_px = 1.5;
  // inputs events+aps: an event frame with no APS frame within this time of it (either side) goes
  // to the estimator on its own (APS frames missing or sparse), ns, > 0.
  int64_t aps_max_gap_ns = 100'000'000;

  // Back-end.
  backend::SlidingWindowOptions window;                          // window size, solver, keyframe rules (see its header)
  // Rotation tracker (the mosaic's particle filter with the gyro, MosaicPipeline). A keyframe is
  // rotation-dominant when its bearings do not call for a translation (the model test's image-only
  // GRIC: S or R rather than G; a hand-held pan with a few cm of translation is, although the IMU
  // datum keeps the rotation-only model off) and the translational image motion is small: the
  // body's predicted speed over the median landmark depth below rotation_tracker_max_flow_deg_s
  // (deg/s, > 0; the keyframe-to-keyframe test misses the parallax of a walk through a room, which
  // shows over seconds). The tracker starts after rotation_tracker_start_keyframes consecutive
  // rotation-dominant keyframes (with a depth known: no landmark, no start),
  // against a fresh panorama, and stops after rotation_tracker_stop_keyframes consecutive keyframes
  // whose bearings call for G or whose flow is at or above the bound while the window holds
  // health_min_landmarks landmarks (counts, >= 1; without landmarks the window's velocity has
  // spikes of metres per second during a pan). Its orientations go to the estimator
  // (SlidingWindowEstimator::add_tracked_rotation: relative-rotation factors from each eligible
  // keyframe to the segment's first, window.tracker_* options). A span the tracker reports lost
  // ends its segment; it restarts a new one (a new anchor) once it tracks again.
  bool rotation_tracker = false;
  int rotation_tracker_start_keyframes = 3;
  int rotation_tracker_stop_keyframes = 10;
  double rotation_tracker_max_flow_deg_s = 3.0;
  // While the tracker is off, the raw events of this long are kept (ns, >= 0), so a tracker
  // started after the run's rotation_tracker_start_keyframes keyframes begins at the run's first
  // keyframe: the front-end's frames reach the estimator up to about half a second after their
  // events are read.
  int64_t rotation_tracker_history_ns = 2'000'000'000;
  // The first segment's tracker runs from the recording's first event (true): its orientations are
  // held back until the start rule above opens (a landmark depth is needed for it, seconds into a
  // recording), then given to the estimator, which anchors the segment at the earliest keyframe
  // they cover, marginalised or not (SlidingWindowEstimator::add_tracked_rotation). That keyframe
  // is the trajectory's start, whose orientation the prior fixes, so the gyro's drift until the
  // start rule opens does not stay in the anchor. rotation_tracker_stop_keyframes consecutive
  // keyframes that would stop a running tracker end this one too, its orientations discarded.
  // false: the first segment starts like every later one.
  bool rotation_tracker_from_start = true;
  // A tracker the stop rule stops is held (true): it keeps tracking, its orientations held back,
  // and goes on feeding its segment (the same anchor) once the start rule opens again;
  // rotation_tracker_hold_ns ends it. A window that goes wrong (its velocity, hence the flow,
  // jumps) trips the stop rule while the camera still pans in place; a fresh segment would then be
  // anchored at the wrong estimate, while the held one's anchor pulls it back. false: the stop
  // ends it.
  bool rotation_tracker_hold_on_stop = true;
  // A held tracker (either kind above) is ended once it has been held this long since the first
  // keyframe of its hold (ns, >= 0) without the start rule opening: it bounds the memory and the
  // time a hold costs (the tracker's CPU, and the output waiting below).
  int64_t rotation_tracker_hold_ns = 30'000'000'000;
  // While a tracker is held, the keyframes that become final wait (true) before they and their
  // frames are output. When the start rule releases the tracker's orientations, each waiting
  // keyframe the tracker covers takes the tracker's rotation from the first such keyframe of its
  // segment, whose orientation stays (positions, velocities and biases stay too), and the frames
  // are re-propagated through them. The drift over the held span then leaves the trajectory as
  // the tracker saw it, rather than in the one step the window takes when its keyframes meet the
  // segment's anchor. A tracker ended unreleased leaves them as they were. false: they are output
  // as they become final.
  bool rotation_tracker_held_output = true;
  MosaicPipelineOptions rotation_tracker_options = [] {
    MosaicPipelineOptions m;
    m.tracker_method = MosaicTracker::kParticleFilter;
    m.use_gyro = true;
    m.tracker.event_stride = 4;    // as evio mosaic --use-imu
    m.tracker.min_particles = 20;
    return m;
  }();
  // Output trajectory (trajectory.tum, keyframes.txt): each final keyframe is the previous one
  // composed with their relative pose in the last solve that held both (true), or its own last
  // optimised state (false). The window's solves move its keyframes together by small amounts (the
  // gauge rests on a linearised prior), and a keyframe and its successor leave the window after
  // different solves: without chaining that shift shows as orientation noise between keyframes.
  bool keyframe_chaining = true;

  // Initialisation. Frames are collected until they span init_window_ns, then the method is
  // tried on the first frame (alignment: on the frames within init_window_ns of it); on failure
  // the frames of the first init_retry_slide_fraction * init_window_ns are dropped and it is
  // tried again with the next frame. finish() makes a last attempt with what is left.
  VioInitMethod init = VioInitMethod::kAuto;
  backend::StaticInitOptions static_init;                        // window_ns (ns), stillness ratios, gravity (m/s^2)
  backend::VisualInertialInitOptions vi_init;                    // frames, tracks (counts), gravity (m/s^2)
  int64_t init_window_ns = 2'000'000'000;                        // ns, > 0
  double init_retry_slide_fraction = 0.25;                       // of init_window_ns, (0, 1]
  int64_t init_imu_history_ns = 50'000'000;                      // ns, >= 0: IMU before the initial state given to the estimator

  // IMU.
  int64_t imu_lookahead_ns = 10'000'000;                         // ns, >= 0: the estimator gets the IMU up to a frame's time + this
  // ns, >= 0: events are processed once the IMU reaches their time + imu_lookahead_ns (IMU clock);
  // events further than this ahead of the newest IMU sample are processed without waiting.
  int64_t imu_wait_ns = 1'000'000'000;

  // Reports.
  int tracking_lost_min_tracks = 5;                              // count, >= 0: a frame with fewer observations counts as lost
  int64_t tracking_lost_min_duration_ns = 500'000'000;           // ns, > 0: such frames for this long make a tracking-lost segment
  // Frames front-end: a gap of more than this many frames.max_window_ns between event frames is
  // an event-rate drop (count, >= 1); empty frames every max_window_ns keep the IMU propagation
  // going through it, and it is reported as a segment (not as tracking lost).
  int event_rate_drop_windows = 2;
  // An interval of at least this long without a frame that gave the estimator
  // tracking_lost_min_tracks observations is an IMU-only span (VioResult::imu_only), ns, > 0.
  int64_t imu_only_min_duration_ns = 100'000'000;
  // Health: a keyframe's estimate is reported unreliable (VioResult::unreliable) when, after its
  // solve, the whitened reprojection errors (chi2 per residual dimension; about 1 when the tracks
  // agree with the estimate at their pixel sigma) exceed health_visual_chi2_max, or the IMU errors
  // health_imu_chi2_max (the two disagree); when fewer than health_min_landmarks landmarks are in
  // the solve (the parallax has collapsed: nothing constrains the translation but the IMU); or when
  // the gyro-bias estimate has left its prior by more than health_gyro_bias_sigmas_max sigmas (the
  // tracks pull the orientation away from the gyro).
  double health_visual_chi2_max = 3.0;     // > 0
  double health_imu_chi2_max = 3.0;        // > 0
  int health_min_landmarks = 10;           // count, >= 0 (0: not checked)
  double health_gyro_bias_sigmas_max = 3.0;  // sigmas of the gyro-bias prior, > 0

  bool Validate(std::string* why) const;
};

// A span of time with a reason, [t_begin_ns, t_end_ns] on the IMU (body) clock.
struct VioSegment {
  int64_t t_begin_ns = 0;
  int64_t t_end_ns = 0;
  std::string what;  // motion models: "6dof" | "rotation_only"; tracking lost: the reason
};

struct VioStats {
  int64_t events = 0;                 // events given to add_events
  int64_t corner_events = 0;          // corners front-end: eFAST corner events
  int64_t frontend_frames = 0;        // observation frames the front-end produced (incl. empty gap frames)
  int64_t t_first_event_ns = 0;       // camera clock; both 0 without events
  int64_t t_last_event_ns = 0;
  int64_t aps_frames = 0;             // APS frames tracked
  int64_t aps_frames_dropped = 0;     // APS frames out of time order, of another size, or merged too late
  int64_t t_first_aps_ns = 0;         // camera clock; both 0 without APS frames
  int64_t t_last_aps_ns = 0;
  frontend::FeatureTrackerStats aps_tracker;     // inputs aps and events+aps
  frontend::EventFrameStats event_frames;        // frames front-end
  frontend::FeatureTrackerStats tracker;         // frames front-end
  frontend::CornerTrackerStats corner_tracker;   // corners front-end
  backend::SlidingWindowStats window;            // back-end (empty when not initialised)
  // rotation_tracker: segments started, events given to the tracker, and the time its calls took
  // on the caller's thread (s; the mosaic's reconstructions may run on a second thread besides).
  int64_t rotation_tracker_segments = 0;   // segments whose orientations went to the estimator
  int64_t rotation_tracker_discarded = 0;  // held trackers (from the start, or stopped) ended before the start rule opened
  int64_t rotation_tracker_corrected_keyframes = 0;  // waiting keyframes given the held tracker's rotation
  int64_t rotation_tracker_events = 0;
  int64_t rotation_tracker_lost_samples = 0;  // orientations withheld: the tracker counted itself lost
  double rotation_tracker_time_s = 0;
};

struct VioResult {
  bool initialized = false;
  VioInitMethod init_method = VioInitMethod::kAuto;  // kStatic, kAlignment or kGiven when initialised
  int64_t init_t_ns = 0;                             // the initial state's time (IMU clock)
  std::string init_failure;                          // not initialised: the last attempt's reason
  // One state per frame that advanced the estimate, time order: each frame re-propagated with the
  // IMU from the final (last optimised) state of its keyframe, the mismatch at the next keyframe
  // spread over the interval (backend/trajectory_smoothing.h): passes through every keyframe.
  std::vector<VioState> trajectory;
  // The same frames as estimated at the time (causal: what an online user had; jumps at keyframes).
  std::vector<VioState> trajectory_causal;
  std::vector<VioState> keyframes;                   // every keyframe's last optimised state, time order
  // (With VioPipeline::set_state_callback the three lists above stay empty: their states went to
  // the callback.)
  std::map<int64_t, Eigen::Vector3d> landmarks;      // the window's landmarks after every keyframe (world, m), by track id, latest value
  std::vector<VioSegment> motion_models;             // runs of keyframes with the same motion model
  std::vector<VioSegment> tracking_lost;             // event-rate drops and runs with too few tracks
  // Spans (after the initialisation) where the estimate came from the IMU alone: no frame with at
  // least tracking_lost_min_tracks observations for imu_only_min_duration_ns or longer.
  std::vector<VioSegment> imu_only;
  // Runs of keyframes whose estimate failed a health check (options health_*), one reason each:
  // "visual residuals", "inertial residuals", "few landmarks", "gyro bias off its prior".
  std::vector<VioSegment> unreliable;
  // rotation_tracker: the spans where the tracker fed the window (from each segment's anchor
  // keyframe to its last keyframe with a factor kept), what: "segment N".
  std::vector<VioSegment> rotation_tracker;
  VioStats stats;
};

class VioPipeline {
 public:
  using InitialStateProvider = std::function<std::optional<VioState>(int64_t t_ns)>;
  using ObservationCallback = std::function<void(const FeatureObservations&)>;
  using ObservationFilter = std::function<void(FeatureObservations*)>;
  // The image the frames front-end tracks (undistorted CV_8UC1) and its time (IMU clock).
  using TrackingImageCallback = std::function<void(int64_t t_ns, const cv::Mat& image)>;
  // Diagnostic: the camera velocity (camera frame, m/s) at frame.t_ns (IMU clock: an event frame's
  // reference time) and the median z-depth (m) of the tracks of `frame` (the bearings of the latest
  // tracked event frame) for the event frames' translation compensation, in place of the estimate's, and optionally a scene plane (n, d: n . P = d in the camera frame,
  // d > 0; left at d = 0 for none) for per-event depth; false: use the estimate's.
  // Which output list a streamed state belongs to (VioResult::trajectory, trajectory_causal, keyframes).
  enum class StateKind { kTrajectory, kCausal, kKeyframe };
  using StateCallback = std::function<void(StateKind kind, const VioState& state)>;
  using FrameMotionOracle =
      std::function<bool(const FeatureObservations& frame, Eigen::Vector3d* v_c, double* depth_m, Eigen::Vector4d* plane_c)>;

  // Throws std::invalid_argument when the options or the IMU noise are invalid.
  VioPipeline(const VioPipelineOptions& options, const calib::CameraCalibration& camera, const calib::ImuNoise& noise);
  ~VioPipeline();
  VioPipeline(const VioPipeline&) = delete;
  VioPipeline& operator=(const VioPipeline&) = delete;

  // For VioInitMethod::kGiven: the state at an IMU-clock time (pose, velocity; biases as given),
  // or nullopt when it has none (initialisation then retries with later frames).
  void set_initial_state_provider(InitialStateProvider provider);
  // Called with every front-end frame (IMU clock), before the estimator sees it.
  void set_observation_callback(ObservationCallback callback);
  // Called with every tracking image of the frames front-end before it is tracked (diagnostics).
  void set_tracking_image_callback(TrackingImageCallback callback);
  // Called with every front-end frame before the callback and the estimator, and may change it
  // (e.g. evaluation::TrackOracle replaces the bearings by true projections for an error budget).
  // The front-end keeps tracking its own observations.
  void set_observation_filter(ObservationFilter filter);
  // Frames front-end with frames.use_depth, once initialised: each frame's translation
  // compensation takes its velocity and depth from `oracle` (e.g. the ground truth) when it
  // answers; an error budget of the compensation's inputs.
  void set_frame_motion_oracle(FrameMotionOracle oracle);
  // Streams the output states instead of collecting them in VioResult (bounded memory on long
  // recordings): each kind in time order, every state once, as soon as it is final. Causal states
  // come with their frame; trajectory states and keyframes once the keyframes around them have
  // left the sliding window (their last optimised values); the rest from finish(). The states are
  // the ones VioResult would hold. Set before the first input.
  void set_state_callback(StateCallback callback);
  // States held for the trajectory until their keyframes are final (bounded by the window's span,
  // not the recording's length; for tests).
  size_t buffered_states() const;

  // IMU samples in time order (IMU clock; t_imu = t_cam + camera.time_shift_ns). They may all come
  // first or be interleaved with add_events: events wait until the IMU covers them (imu_wait_ns).
  void add_imu(const ImuSample& sample);
  // An intensity (APS) frame (camera clock, 8-bit grey or BGR of the camera's size, distorted as
  // recorded), for inputs aps and events+aps (ignored otherwise). Frames must come in time order;
  // with events+aps add each frame before the events of its time (a merge needs the APS times
  // around an event frame when that frame is built; adding every frame first is simplest).
  void add_frame(const Frame& frame);
  // Raw events in time order (camera clock), e.g. chunks as read (ignored with inputs aps). Event frames completed within one
  // call are built before the estimate of the first of them feeds back (gyro bias, velocity and
  // depth), so the results depend on the chunking (as for any streaming reader).
  void add_events(EventSpan events);
  // Processes everything buffered, makes a last initialisation attempt and returns the results.
  // No input is accepted afterwards (std::logic_error).
  VioResult finish();

  bool initialized() const;
  const VioPipelineOptions& options() const { return options_; }

 private:
  struct Impl;
  VioPipelineOptions options_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace evio::pipeline
