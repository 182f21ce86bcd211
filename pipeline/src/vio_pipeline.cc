#include "evio/pipeline/vio_pipeline.h"

#include <algorithm>
#include <deque>
#include <limits>
#include <stdexcept>
#include <utility>

#include "evio/backend/imu_preintegration.h"
#include "evio/backend/trajectory_smoothing.h"
#include "evio/calib/log.h"
#include "evio/sensors/time.h"

#include <opencv2/imgproc.hpp>

namespace evio::pipeline {

const char* to_string(VioFrontEnd f) { return f == VioFrontEnd::kCorners ? "corners" : "frames"; }

const char* to_string(VioInputs i) {
  switch (i) {
    case VioInputs::kAps: return "aps";
    case VioInputs::kEventsAndAps: return "events+aps";
    case VioInputs::kEvents: break;
  }
  return "events";
}

const char* to_string(VioTrackingImage i) { return i == VioTrackingImage::kReconstruction ? "reconstruction" : "event_frame"; }

const char* to_string(VioInitMethod m) {
  switch (m) {
    case VioInitMethod::kStatic: return "static";
    case VioInitMethod::kAlignment: return "alignment";
    case VioInitMethod::kGiven: return "given";
    case VioInitMethod::kAuto: break;
  }
  return "auto";
}

bool VioPipelineOptions::Validate(std::string* why) const {
  auto fail = [why](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  std::string w;
  if (!refractory.Validate(&w)) return fail("refractory: " + w);
  if (!background_activity.Validate(&w)) return fail("background_activity: " + w);
  if (!frames.Validate(&w)) return fail("frames: " + w);
  if (!tracker.Validate(&w)) return fail("tracker: " + w);
  if (!aps_tracker.Validate(&w)) return fail("aps_tracker: " + w);
  if (!reconstruction.Validate(&w)) return fail("reconstruction: " + w);
  if (!reconstruction_tracker.Validate(&w)) return fail("reconstruction_tracker: " + w);
  if (!(reconstruction_grey_per_log > 0) || !std::isfinite(reconstruction_grey_per_log))
    return fail("reconstruction_grey_per_log must be finite and > 0");
  if (!(reconstruction_blur_px >= 0) || !std::isfinite(reconstruction_blur_px)) return fail("reconstruction_blur_px must be finite and >= 0");
  if (inputs != VioInputs::kEvents && inputs != VioInputs::kAps && inputs != VioInputs::kEventsAndAps)
    return fail("inputs must be events, aps or events+aps");
  if (!(aps_pixel_sigma_px > 0) || !std::isfinite(aps_pixel_sigma_px)) return fail("aps_pixel_sigma_px must be finite and > 0");
  if (aps_max_gap_ns <= 0) return fail("aps_max_gap_ns must be > 0");
  if (!(aps_event_pixel_sigma_px > 0) || !std::isfinite(aps_event_pixel_sigma_px))
    return fail("aps_event_pixel_sigma_px must be finite and > 0");
  if (!efast.Validate(&w)) return fail("efast: " + w);
  if (!corner_tracker.Validate(&w)) return fail("corner_tracker: " + w);
  if (!window.Validate(&w)) return fail("window: " + w);
  if (!static_init.Validate(&w)) return fail("static_init: " + w);
  if (!vi_init.Validate(&w)) return fail("vi_init: " + w);
  if (observation_period_ns <= 0) return fail("observation_period_ns must be > 0");
  if (min_track_age_ns < 0) return fail("min_track_age_ns must be >= 0");
  if (!(corner_min_bearing_z >= 0 && corner_min_bearing_z < 1)) return fail("corner_min_bearing_z must be in [0, 1)");
  if (init_window_ns <= 0) return fail("init_window_ns must be > 0");
  if (!(init_retry_slide_fraction > 0 && init_retry_slide_fraction <= 1))
    return fail("init_retry_slide_fraction must be in (0, 1]");
  if (init_imu_history_ns < 0) return fail("init_imu_history_ns must be >= 0");
  if (imu_lookahead_ns < 0) return fail("imu_lookahead_ns must be >= 0");
  if (imu_wait_ns < 0) return fail("imu_wait_ns must be >= 0");
  if (tracking_lost_min_tracks < 0) return fail("tracking_lost_min_tracks must be >= 0");
  if (tracking_lost_min_duration_ns <= 0) return fail("tracking_lost_min_duration_ns must be > 0");
  if (event_rate_drop_windows < 1) return fail("event_rate_drop_windows must be >= 1");
  if (imu_only_min_duration_ns <= 0) return fail("imu_only_min_duration_ns must be > 0");
  if (!(health_visual_chi2_max > 0) || !(health_imu_chi2_max > 0) || !(health_gyro_bias_sigmas_max > 0))
    return fail("health_visual_chi2_max, health_imu_chi2_max and health_gyro_bias_sigmas_max must be > 0");
  if (health_min_landmarks < 0) return fail("health_min_landmarks must be >= 0");
  return true;
}

namespace {

const VioPipelineOptions& checked(const VioPipelineOptions& o, const calib::ImuNoise& noise) {
  std::string why;
  if (!o.Validate(&why)) throw std::invalid_argument("VioPipeline options: " + why);
  if (!noise.Validate(&why)) throw std::invalid_argument("VioPipeline IMU noise: " + why);
  return o;
}

}  // namespace

struct VioPipeline::Impl {
  Impl(const VioPipelineOptions& o, const calib::CameraCalibration& camera, const calib::ImuNoise& imu_noise)
      : opt(o),
        cal(camera),
        noise(imu_noise),
        width(camera.camera.width()),
        height(camera.camera.height()),
        shift(camera.time_shift_ns),
        use_frames(o.frontend == VioFrontEnd::kFrames),
        use_events(o.inputs != VioInputs::kAps),
        use_aps(o.inputs != VioInputs::kEvents),
        undistorter(camera.camera),
        refractory(width, height, o.refractory),
        background(width, height, o.background_activity) {
    if (use_frames && opt.tracking_image == VioTrackingImage::kReconstruction) {
      recon_undistorter = std::make_unique<frontend::FrameUndistorter>(cal.camera);
      frame_tracker = std::make_unique<frontend::FeatureTracker>(ideal_pinhole(), opt.reconstruction_tracker);
      frame_tracker->set_valid_mask(recon_undistorter->mask());
    } else if (use_frames) {
      frame_builder = std::make_unique<frontend::EventFrameBuilder>(cal, opt.frames);
      // Sparse windows only once initialised: before, the frames of a slow start would take the
      // initialisation from a still-window estimate to an alignment over almost no motion.
      frame_builder->set_sparse_windows(false);
      if (opt.frames.use_depth)
        frame_builder->set_motion_provider([this](int64_t t_ref, frontend::FrameMotion* m) { return frame_motion_at(t_ref + shift, m); });
      // The tracker works on the builder's undistorted pinhole images.
      frame_tracker = std::make_unique<frontend::FeatureTracker>(ideal_pinhole(), opt.tracker);
    } else {
      detector = std::make_unique<frontend::EfastDetector>(width, height, opt.efast);
      corner_tracker = std::make_unique<frontend::CornerTracker>(width, height, opt.corner_tracker);
    }
    if (use_aps) {
      aps_undistorter = std::make_unique<frontend::FrameUndistorter>(cal.camera);
      aps_tracker = std::make_unique<frontend::FeatureTracker>(ideal_pinhole(), opt.aps_tracker);
      aps_tracker->set_valid_mask(aps_undistorter->mask());
    }
  }

  // The undistorted pinhole of the event frames and the undistorted APS frames.
  calib::CameraIntrinsics ideal_pinhole() const {
    calib::CameraIntrinsics ideal = cal.camera.intrinsics();
    ideal.model = calib::DistortionModel::kNone;
    ideal.distortion.clear();
    return ideal;
  }

  const VioPipelineOptions& opt;
  const calib::CameraCalibration cal;
  const calib::ImuNoise noise;
  const int width, height;
  const int64_t shift;  // t_imu = t_cam + shift
  const bool use_frames;
  const bool use_events, use_aps;

  InitialStateProvider initial_state;
  ObservationCallback on_observations;
  ObservationFilter observation_filter;
  TrackingImageCallback on_tracking_image;
  FrameMotionOracle frame_motion_oracle;
  // Output states: to on_state, or collected in result. A frame's trajectory state waits in
  // `predictions` until the keyframes around it have left the window (release()); final_keyframes
  // holds the keyframes' last optimised states from the oldest anchor still needed on.
  VioPipeline::StateCallback on_state;
  std::deque<backend::FramePrediction> predictions;  // per causal state not yet released
  std::map<int64_t, VioState> final_keyframes;
  // keyframe_chaining: per keyframe, its pose relative to the next keyframe in the latest solve that
  // held both, T_k^-1 T_k+1 (by k's time), and the output states chained from those relatives.
  std::map<int64_t, std::pair<int64_t, calib::SE3>> relative_to_next;
  std::map<int64_t, VioState> chained_keyframes;
  int64_t last_causal_t = std::numeric_limits<int64_t>::min();
  int64_t last_keyframe_out = std::numeric_limits<int64_t>::min();
  bool finished = false;

  // IMU (IMU clock): every sample still needed by the initialisation, the estimator or the
  // rotation prior; older ones are pruned (prune_imu).
  std::vector<ImuSample> imu;
  size_t next_imu = 0;  // the next sample for the estimator
  // Event chunks waiting for the IMU to cover them (copies of add_events' spans).
  std::deque<std::vector<Event>> waiting;

  // Front-end.
  const frontend::EventUndistorter undistorter;
  frontend::RefractoryFilter refractory;
  frontend::BackgroundActivityFilter background;
  std::unique_ptr<frontend::EventFrameBuilder> frame_builder;
  // tracking_image kReconstruction: the high-pass filter (made at the first event), its frame clock
  // and the undistortion of its images.
  std::unique_ptr<mapping::ComplementaryFilter> recon;
  std::unique_ptr<frontend::FrameUndistorter> recon_undistorter;
  int64_t recon_frame_start = -1;  // camera clock: the current frame's first event (-1: none yet)
  int64_t recon_frame_events = 0;
  mapping::ImageF recon_log;
  cv::Mat recon_grey;
  std::unique_ptr<frontend::FeatureTracker> frame_tracker;
  std::unique_ptr<frontend::EfastDetector> detector;
  std::unique_ptr<frontend::CornerTracker> corner_tracker;
  std::vector<Event> filtered;
  std::vector<frontend::EventFrame> built;
  int64_t prev_frame_t = -1;  // camera clock, last event frame
  std::optional<FeatureObservations> last_tracked;  // the latest event frame's tracks (for the frame-motion oracle)
  std::vector<double> depth_scratch;                // landmark depths (median_landmark_depth)
  std::optional<frontend::FrameMotion> latest_motion;  // use_depth without frame_velocity_at_reference
  int64_t next_obs = 0;       // camera clock, next corner observation frame
  bool have_events = false;
  int64_t last_stall_init_ns = std::numeric_limits<int64_t>::min() / 2;  // IMU clock, try_init_on_stall
  int64_t frame_id = 0;

  // APS frames.
  std::unique_ptr<frontend::FrameUndistorter> aps_undistorter;
  std::unique_ptr<frontend::FeatureTracker> aps_tracker;
  std::deque<Frame> waiting_frames;           // waiting for the IMU to cover them
  int64_t prev_aps_t = -1;                    // camera clock, last tracked APS frame
  std::vector<int64_t> aps_times;             // IMU clock, every APS frame added (events+aps)
  std::deque<FeatureObservations> aps_ready;  // events+aps: tracked, waiting for the event frame after them
  std::optional<FeatureObservations> last_event_obs;  // events+aps: the latest event frame (IMU clock)
  int64_t last_emitted_t = std::numeric_limits<int64_t>::min();  // IMU clock, last frame to the estimator

  // Back-end and results.
  std::unique_ptr<backend::SlidingWindowEstimator> est;
  std::vector<FeatureObservations> pending;  // frames before initialisation
  VioResult result;
  bool in_gap = false;     // emitting the empty frames of an event-rate drop
  int64_t few_since = -1;  // start of the current run of frames with too few tracks (IMU clock)
  // IMU-only spans: the last frame that gave the initialised estimator at least
  // tracking_lost_min_tracks observations (IMU clock; -1: none yet), and whether the frames since
  // were empty gap frames (no events) or frames with too few tracks.
  int64_t last_visual_t = -1;
  bool gap_since_visual = false;

  // ---- IMU ------------------------------------------------------------------------------------

  // True when every IMU sample up to the camera-clock time t_cam + imu_lookahead_ns has come.
  bool imu_covers(int64_t t_cam) const {
    return !imu.empty() && imu.back().t_ns > t_cam + shift + opt.imu_lookahead_ns;
  }
  // True when the newest waiting event is more than imu_wait_ns ahead of the newest IMU sample (of
  // the oldest waiting event without any IMU): the IMU is missing there, do not wait for it.
  bool imu_missing() const {
    const int64_t newest = imu.empty() ? waiting.front().front().t_ns + shift : imu.back().t_ns;
    return waiting.back().back().t_ns + shift - newest > opt.imu_wait_ns;
  }

  // Drops the samples no later step can use: everything before the last sample at or before the
  // earliest time still needed (that sample stays, as the interpolation bracket).
  void prune_imu() {
    constexpr int64_t kNever = std::numeric_limits<int64_t>::max();
    int64_t need = kNever;
    if (est) {
      need = next_imu < imu.size() ? imu[next_imu].t_ns : kNever;  // the estimator's next sample
    } else if (!pending.empty()) {
      // The initialisation's first frame, and the static window that ends there.
      need = pending.front().t_ns - std::max(opt.init_imu_history_ns, 2 * opt.static_init.window_ns);
    } else if (!use_frames && have_events) {
      need = next_obs + shift - opt.init_imu_history_ns;  // the next corner frame
    } else if (use_frames && prev_frame_t >= 0) {
      need = prev_frame_t + shift - opt.init_imu_history_ns;  // frames after the last one
    } else {
      return;  // no frame yet: the first one may start anywhere
    }
    if (use_frames && prev_frame_t >= 0) need = std::min(need, prev_frame_t + shift);  // rotation prior
    if (use_aps && prev_aps_t >= 0) need = std::min(need, prev_aps_t + shift);          // APS rotation prior
    if (!waiting_frames.empty()) need = std::min(need, waiting_frames.front().t_ns + shift);
    const auto after = std::upper_bound(imu.begin(), imu.end(), need, [](int64_t t, const ImuSample& s) { return t < s.t_ns; });
    size_t cut = static_cast<size_t>(after - imu.begin());
    if (cut == 0) return;
    --cut;  // keep the bracket
    if (est) cut = std::min(cut, next_imu);
    constexpr size_t kPruneBatch = size_t{1} << 14;  // amortises the erase
    if (cut < kPruneBatch) return;
    imu.erase(imu.begin(), imu.begin() + static_cast<std::ptrdiff_t>(cut));
    if (est) next_imu -= cut;
  }

  // ---- back-end -------------------------------------------------------------------------------

  void output(VioPipeline::StateKind kind, const VioState& s) {
    if (on_state) {
      on_state(kind, s);
      return;
    }
    switch (kind) {
      case VioPipeline::StateKind::kTrajectory: result.trajectory.push_back(s); break;
      case VioPipeline::StateKind::kCausal: result.trajectory_causal.push_back(s); break;
      case VioPipeline::StateKind::kKeyframe: result.keyframes.push_back(s); break;
    }
  }

  // Outputs the trajectory states of the frames at or before t_final (IMU clock) and the keyframes
  // at or before it: every keyframe there is final, and so is the mismatch each frame's interval
  // spreads (repropagate_trajectory: a frame at or before a final keyframe was predicted from a
  // final keyframe towards a final one). Keeps the keyframes the remaining frames are anchored on.
  void release(int64_t t_final) {
    if (opt.keyframe_chaining) chain_final(t_final);
    const std::map<int64_t, VioState>& finals = opt.keyframe_chaining ? chained_keyframes : final_keyframes;
    size_t n = 0;
    while (n < predictions.size() && predictions[n].state.t_ns <= t_final) ++n;
    if (n > 0) {
      const std::vector<backend::FramePrediction> ready(predictions.begin(), predictions.begin() + static_cast<std::ptrdiff_t>(n));
      for (const VioState& s : backend::repropagate_trajectory(ready, finals, est->options().gravity_w)) {
        output(VioPipeline::StateKind::kTrajectory, s);
      }
      predictions.erase(predictions.begin(), predictions.begin() + static_cast<std::ptrdiff_t>(n));
    }
    int64_t keep = t_final;
    for (const backend::FramePrediction& f : predictions) {
      if (f.predicted) keep = std::min(keep, f.anchor.t_ns);
    }
    if (!chained_keyframes.empty()) keep = std::min(keep, std::prev(chained_keyframes.end())->first);
    for (auto it = final_keyframes.begin(); it != final_keyframes.end() && it->first <= t_final;) {
      if (it->first > last_keyframe_out) {
        output(VioPipeline::StateKind::kKeyframe, finals.at(it->first));
        last_keyframe_out = it->first;
      }
      it = it->first < keep ? final_keyframes.erase(it) : std::next(it);
    }
    // The newest chained keyframe stays (the next one is chained from it), with what it needs.
    if (!chained_keyframes.empty()) {
      const int64_t newest = std::prev(chained_keyframes.end())->first;
      const int64_t cut = std::min(keep, newest);
      chained_keyframes.erase(chained_keyframes.begin(), chained_keyframes.lower_bound(cut));
      relative_to_next.erase(relative_to_next.begin(), relative_to_next.lower_bound(cut));
    }
  }

  // keyframe_chaining: the output state of every final keyframe up to t_final, each one the previous
  // output composed with the relative pose of the two in the last solve that held both. A sliding
  // window's solves shift its keyframes together by small amounts (the gauge is held by a
  // linearised prior); a keyframe leaves the window after one solve and its successor after the
  // next, so their final states differ by that shift as well as by their relative motion. Chaining
  // keeps only the relative motion (velocity rotated along; biases as optimised).
  void chain_final(int64_t t_final) {
    for (auto it = final_keyframes.begin(); it != final_keyframes.end() && it->first <= t_final; ++it) {
      if (chained_keyframes.count(it->first)) continue;
      const VioState& f = it->second;
      VioState c = f;
      const auto prev_c = chained_keyframes.empty() ? chained_keyframes.end() : std::prev(chained_keyframes.end());
      if (prev_c != chained_keyframes.end() && prev_c->first < it->first) {
        const VioState& pf = final_keyframes.at(prev_c->first);
        const auto rel = relative_to_next.find(prev_c->first);
        calib::SE3 T;
        if (rel != relative_to_next.end() && rel->second.first == it->first) {
          T = prev_c->second.T_w_b * rel->second.second;
        } else {
          // No common solve: carry the previous keyframe's correction over.
          T = prev_c->second.T_w_b * pf.T_w_b.inverse() * f.T_w_b;
        }
        const Eigen::Matrix3d R_corr = T.rotation.toRotationMatrix() * f.T_w_b.rotation.toRotationMatrix().transpose();
        c.T_w_b = T;
        c.v_w = R_corr * f.v_w;
      }
      chained_keyframes[it->first] = c;
    }
  }

  void feed(const FeatureObservations& f) {
    while (next_imu < imu.size() && imu[next_imu].t_ns <= f.t_ns + opt.imu_lookahead_ns) est->add_imu(imu[next_imu++]);
    const bool kf = est->add_frame(f);
    // One state per new state time (a frame the estimator skipped adds none).
    const VioState& ls = est->latest_state();
    if (ls.t_ns > last_causal_t) {
      last_causal_t = ls.t_ns;
      output(VioPipeline::StateKind::kCausal, ls);
      backend::FramePrediction fp;
      fp.state = ls;
      const auto& lp = est->last_prediction();
      if (lp && lp->second.t_ns == ls.t_ns) {
        fp.predicted = true;
        fp.anchor = lp->first;
        fp.prediction = lp->second;
      }
      predictions.push_back(std::move(fp));
    }
    if (kf) {
      for (const auto& [id, p] : est->landmarks()) result.landmarks[id] = p;
      const std::vector<VioState> window = est->keyframe_states();
      for (const VioState& k : window) final_keyframes[k.t_ns] = k;
      for (size_t i = 0; i + 1 < window.size(); ++i)
        relative_to_next[window[i].t_ns] = {window[i + 1].t_ns, window[i].T_w_b.inverse() * window[i + 1].T_w_b};
      // The keyframes before the window's oldest are final (no solve changes them again).
      const auto first_in_window = window.empty() ? final_keyframes.end() : final_keyframes.find(window.front().t_ns);
      if (first_in_window != final_keyframes.begin() && first_in_window != final_keyframes.end()) {
        release(std::prev(first_in_window)->first);
      }
    }
  }

  // The time (IMU clock) up to which both the events and the IMU have been processed while the
  // newest pending frame lags behind them by an event-rate drop; -1 when frames are not stalled.
  int64_t stalled_frames_until() const {
    if (pending.empty() || imu.empty() || !have_events) return -1;
    const int64_t seen = std::min(imu.back().t_ns - opt.imu_lookahead_ns, result.stats.t_last_event_ns + shift);
    return seen - pending.back().t_ns > opt.event_rate_drop_windows * opt.frames.max_window_ns ? seen : -1;
  }

  // Not initialised with frames waiting and the frames stalled: the IMU and the events seen may
  // complete the initialisation window. Attempted at most once per max_window_ns of data.
  void try_init_on_stall() {
    if (est || pending.empty()) return;
    const int64_t until = stalled_frames_until();
    if (until < 0 || until - last_stall_init_ns < opt.frames.max_window_ns) return;
    last_stall_init_ns = until;
    try_init(false);
  }

  void try_init(bool final_attempt) {
    if (pending.empty()) return;
    const int64_t t0 = pending.front().t_ns;
    // The window is complete once the frames reach init_window_ns past the first frame, or the IMU
    // does while the frames have stalled (an event-rate drop: a hover from rest gives too few
    // events for frames until the estimate allows sparse ones, and the still start needs the IMU
    // only).
    const int64_t newest = std::max(pending.back().t_ns, stalled_frames_until());
    if (newest - t0 < opt.init_window_ns && !final_attempt) return;
    std::optional<VioState> s;
    std::string why;
    backend::InitialSigmas sigmas;  // from the static initialiser when the body was still
    VioInitMethod method = opt.init;
    if (opt.init == VioInitMethod::kGiven) {
      if (!initial_state) {
        why = "init method 'given' without an initial-state provider";
      } else {
        s = initial_state(t0);
        if (s) {
          s->t_ns = t0;
        } else {
          why = "no initial state given for " + format_seconds(t0) + " s";
        }
      }
    }
    if (opt.init == VioInitMethod::kAuto || opt.init == VioInitMethod::kStatic) {
      // A still body gives no events: the first frame comes once it moves, so the static window
      // that ends at the first frame comes first; then the one that starts there (frames while still).
      // The motion may have begun a little before the first frame: the latest still window
      // ending up to one window before it (in steps of half the still tail); the estimator
      // propagates that state to the first frame with the IMU.
      // A still window first (it measures the gyro bias), then the rotation-in-place case.
      std::string why_before;
      backend::StaticInitOptions still = opt.static_init;
      still.allow_rotation = false;
      const int64_t step = std::max<int64_t>(opt.static_init.still_tail_ns / 2, 10'000'000);
      for (int64_t t_end = t0; !s && t_end >= t0 - opt.static_init.window_ns; t_end -= step) {
        s = backend::static_initialization(imu, t_end - opt.static_init.window_ns, noise, still,
                                           t_end == t0 ? &why_before : nullptr, &sigmas);
      }
      if (!s && opt.static_init.allow_rotation) {
        s = backend::static_initialization(imu, t0 - opt.static_init.window_ns, noise, opt.static_init, &why_before,
                                           &sigmas);
      }
      if (!s) s = backend::static_initialization(imu, t0, noise, opt.static_init, &why, &sigmas);
      if (!s) why = "before the first frame: " + why_before + "; after it: " + why;
      method = VioInitMethod::kStatic;
    }
    if (!s && (opt.init == VioInitMethod::kAuto || opt.init == VioInitMethod::kAlignment)) {
      std::vector<FeatureObservations> window;
      for (const auto& f : pending)
        if (f.t_ns - t0 <= opt.init_window_ns) window.push_back(f);
      s = backend::visual_inertial_initialization(window, imu, cal, noise, Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(),
                                                  opt.vi_init, &why);
      method = VioInitMethod::kAlignment;
    }
    if (!s) {
      result.init_failure = "initialisation at " + format_seconds(t0) + " s failed: " + why;
      log_debug(result.init_failure);
      // Slide and retry with the next frames.
      const int64_t drop_until =
          t0 + static_cast<int64_t>(static_cast<double>(opt.init_window_ns) * opt.init_retry_slide_fraction);
      pending.erase(pending.begin(), std::find_if(pending.begin(), pending.end(), [&](const auto& f) { return f.t_ns > drop_until; }));
      return;
    }
    result.initialized = true;
    result.init_method = method;
    result.init_t_ns = s->t_ns;
    result.init_failure.clear();
    log_info("initialised at " + format_seconds(s->t_ns) + " s by " +
             (method == VioInitMethod::kStatic ? "static" : method == VioInitMethod::kAlignment ? "visual-inertial alignment"
                                                                                               : "the given initial state"));
    est = std::make_unique<backend::SlidingWindowEstimator>(opt.window, cal, noise);
    if (frame_builder) frame_builder->set_sparse_windows(true);
    est->initialize(*s, method == VioInitMethod::kStatic ? sigmas : backend::InitialSigmas{});
    while (next_imu < imu.size() && imu[next_imu].t_ns < s->t_ns - opt.init_imu_history_ns) ++next_imu;
    for (const auto& f : pending)
      if (f.t_ns >= s->t_ns) feed(f);
    pending.clear();
  }

  // ---- front-end ------------------------------------------------------------------------------

  // Every front-end frame (IMU clock) goes through here.
  void handle_frame(FeatureObservations f) {
    ++result.stats.frontend_frames;
    if (observation_filter) observation_filter(&f);
    if (on_observations) on_observations(f);
    if (in_gap) {
      // counted as the event-rate drop
    } else if (f.observations.size() < static_cast<size_t>(opt.tracking_lost_min_tracks)) {
      if (few_since < 0) few_since = f.t_ns;
    } else if (few_since >= 0) {
      if (f.t_ns - few_since >= opt.tracking_lost_min_duration_ns) result.tracking_lost.push_back({few_since, f.t_ns, lost_reason()});
      few_since = -1;
    }
    if (est) {
      const bool visual = f.observations.size() >= static_cast<size_t>(std::max(1, opt.tracking_lost_min_tracks));
      if (visual) {
        close_imu_only_span(f.t_ns);
        last_visual_t = f.t_ns;
        gap_since_visual = false;
      } else if (in_gap) {
        gap_since_visual = true;
      }
      feed(f);
    } else {
      pending.push_back(std::move(f));
      try_init(false);
      if (est) last_visual_t = est->latest_state().t_ns;
    }
  }

  // The runs of keyframes that failed a health check, per reason, into result.unreliable (time
  // order of their starts), with a warning each.
  void health_segments() {
    const auto& hs = est->stats().health;
    const std::vector<std::pair<std::string, std::function<bool(const backend::SlidingWindowStats::Health&)>>> checks = {
        {"visual residuals", [&](const auto& h) { return h.visual_chi2_per_dof > opt.health_visual_chi2_max; }},
        {"inertial residuals", [&](const auto& h) { return h.imu_chi2_per_dof > opt.health_imu_chi2_max; }},
        {"few landmarks", [&](const auto& h) { return h.landmarks < opt.health_min_landmarks; }},
        {"gyro bias off its prior", [&](const auto& h) { return h.gyro_bias_sigmas > opt.health_gyro_bias_sigmas_max; }},
    };
    for (const auto& [what, bad] : checks) {
      int64_t begin = -1, last = -1;
      for (const auto& h : hs) {
        if (bad(h)) {
          if (begin < 0) begin = h.t_ns;
          last = h.t_ns;
        } else if (begin >= 0) {
          result.unreliable.push_back({begin, h.t_ns, what});
          begin = -1;
        }
      }
      if (begin >= 0) result.unreliable.push_back({begin, last, what});
    }
    std::sort(result.unreliable.begin(), result.unreliable.end(),
              [](const VioSegment& a, const VioSegment& b) { return a.t_begin_ns < b.t_begin_ns; });
    for (const VioSegment& u : result.unreliable) {
      log_warning("estimate unreliable (" + u.what + ") from " + format_seconds(u.t_begin_ns) + " to " + format_seconds(u.t_end_ns) + " s");
    }
  }

  // An IMU-only span from the last frame with observations to t (IMU clock), when it lasted at least
  // imu_only_min_duration_ns: the estimate there comes from the IMU alone.
  void close_imu_only_span(int64_t t) {
    if (last_visual_t < 0 || t - last_visual_t < opt.imu_only_min_duration_ns) return;
    result.imu_only.push_back({last_visual_t, t, gap_since_visual ? "no event frames (event-rate drop)" : lost_reason()});
  }

  std::string lost_reason() const { return "fewer than " + std::to_string(opt.tracking_lost_min_tracks) + " tracks"; }

  // Corners front-end: the active corner tracks sampled at t_cam.
  void emit_corner_frame(int64_t t_cam) {
    FeatureObservations f;
    f.t_ns = t_cam + shift;
    corner_tracker->predict_active(t_cam, opt.observation_period_ns, opt.min_track_age_ns,
                                   [&](int64_t id, const Eigen::Vector2d& px) {
                                     Eigen::Vector3d b;
                                     if (px.allFinite() && cal.camera.unproject(px, &b) && b.z() > opt.corner_min_bearing_z)
                                       f.observations.push_back({id, b});
                                   });
    emit_event_frame(std::move(f));
  }

  // Frames front-end: one observation frame per event frame, tracked with the IMU rotation prior.
  void track_event_frame(const frontend::EventFrame& ef) {
    const int64_t max_window = opt.frames.max_window_ns;
    // A frame closes within max_window_ns, or with sparse windows (once initialised) within
    // sparse_max_window_ns: a longer gap has had no events to build a frame from.
    const int64_t longest = est && opt.frames.sparse_max_window_ns > 0 ? std::max(max_window, opt.frames.sparse_max_window_ns) : max_window;
    if (prev_frame_t >= 0 && ef.t_ns - prev_frame_t > std::max<int64_t>(opt.event_rate_drop_windows * max_window, longest + max_window)) {
      emit_gap_frames(ef.t_ns);
    }
    Eigen::Matrix3d R_cur_prev;
    const bool have_prior = prev_frame_t >= 0 && rotation_prior(prev_frame_t, ef.t_ns, &R_cur_prev);
    prev_frame_t = ef.t_ns;
    if (on_tracking_image) on_tracking_image(ef.t_ns + shift, ef.image);
    const std::vector<frontend::TrackPrediction> predictions = lost_track_predictions(ef.t_ns + shift);
    FeatureObservations f =
        frame_tracker->track(ef.t_ns + shift, ef.image, have_prior ? &R_cur_prev : nullptr, predictions.empty() ? nullptr : &predictions);
    if (est) feed_back_motion(f);
    emit_event_frame(std::move(f));
  }

  // The latest state propagated with the IMU to t (IMU clock); false without IMU over the interval.
  bool propagated_state(int64_t t, VioState* out) const {
    if (!est) return false;
    VioState st = est->latest_state();
    if (t > st.t_ns) {
      try {
        const auto pre = backend::ImuPreintegration::between(imu, st.t_ns, t, st.bias_gyro, st.bias_accel, noise);
        const double dt = pre.dt_s();
        const Eigen::Matrix3d R = st.T_w_b.rotation.toRotationMatrix();
        st.T_w_b.translation += st.v_w * dt + 0.5 * opt.window.gravity_w * dt * dt + R * pre.delta_p();
        st.v_w += opt.window.gravity_w * dt + R * pre.delta_v();
        st.T_w_b.rotation = Eigen::Quaterniond(R * pre.delta_R()).normalized();
        st.t_ns = t;
      } catch (const std::invalid_argument&) {
        return false;
      }
    }
    *out = st;
    return true;
  }

  // Where the frame tracker's lost tracks with a landmark in the window should be at t (IMU
  // clock): each landmark projected with the IMU-propagated pose into the ideal pinhole.
  std::vector<frontend::TrackPrediction> lost_track_predictions(int64_t t) const {
    std::vector<frontend::TrackPrediction> out;
    if (!est || !frame_tracker || frame_tracker->options().reacquire_max_age_s <= 0) return out;
    const std::vector<int64_t> lost = frame_tracker->lost_track_ids();
    if (lost.empty()) return out;
    VioState st;
    if (!propagated_state(t, &st)) return out;
    const calib::SE3 T_c_w = cal.T_c_b * st.T_w_b.inverse();
    const calib::CameraIntrinsics K = ideal_pinhole();
    const auto landmarks = est->landmarks();
    for (const int64_t id : lost) {
      const auto it = landmarks.find(id);
      if (it == landmarks.end()) continue;
      const Eigen::Vector3d p = T_c_w.rotation * it->second + T_c_w.translation;
      if (!(p.z() > 1e-3)) continue;
      out.push_back({id, Eigen::Vector2d(K.fx * p.x() / p.z() + K.cx, K.fy * p.y() / p.z() + K.cy)});
    }
    return out;
  }

  // An event-rate drop from the last event frame to t_cam (camera clock): empty frames every
  // max_window_ns keep the IMU propagation going (an IMU-only span), reported as tracking lost.
  void emit_gap_frames(int64_t t_cam) {
    const int64_t max_window = opt.frames.max_window_ns;
    result.tracking_lost.push_back({prev_frame_t + shift, t_cam + shift, "no event frames (event-rate drop)"});
    in_gap = true;
    for (int64_t t = prev_frame_t + max_window; t < t_cam; t += max_window) {
      FeatureObservations empty;
      empty.t_ns = t + shift;
      emit_event_frame(std::move(empty));
    }
    in_gap = false;
  }

  // Camera rotation from camera-clock t0 to t1 from the gyro (estimated bias once initialised):
  // p_cur = R_cur_prev p_prev for points at infinity. False without IMU around the interval.
  bool rotation_prior(int64_t t0_cam, int64_t t1_cam, Eigen::Matrix3d* R_cur_prev) const {
    const Eigen::Vector3d bg = est ? est->latest_state().bias_gyro : Eigen::Vector3d::Zero();
    try {
      const auto pre = backend::ImuPreintegration::between(imu, t0_cam + shift, t1_cam + shift, bg, Eigen::Vector3d::Zero(), noise);
      const Eigen::Matrix3d R_c_b = cal.T_c_b.rotation.toRotationMatrix();
      *R_cur_prev = R_c_b * pre.delta_R().transpose() * R_c_b.transpose();
      return true;
    } catch (const std::invalid_argument&) {
      return false;  // no IMU around the interval: track without the rotation prior
    }
  }

  // A frame to the estimator (through handle_frame) in strict time order; later-arriving older
  // frames are dropped.
  void emit(FeatureObservations f) {
    if (use_aps && f.t_ns <= last_emitted_t) {
      ++result.stats.aps_frames_dropped;
      return;
    }
    last_emitted_t = f.t_ns;
    f.frame_id = frame_id++;
    handle_frame(std::move(f));
  }

  // An event frame's observations (IMU clock). With events+aps the APS frames up to its time go
  // first, each with the event tracks seen in both this and the previous event frame interpolated
  // to the APS time; the event frame itself only when no APS frame is within aps_max_gap_ns.
  void emit_event_frame(FeatureObservations e) {
    if (!use_aps) {
      emit(std::move(e));
      return;
    }
    for (FeatureObservation& o : e.observations) o.sigma_px = opt.aps_event_pixel_sigma_px;
    while (!aps_ready.empty() && aps_ready.front().t_ns <= e.t_ns) {
      FeatureObservations a = std::move(aps_ready.front());
      aps_ready.pop_front();
      if (last_event_obs && last_event_obs->t_ns <= a.t_ns) append_interpolated(*last_event_obs, e, &a);
      emit(std::move(a));
    }
    const auto near = std::lower_bound(aps_times.begin(), aps_times.end(), e.t_ns - opt.aps_max_gap_ns);
    if (near == aps_times.end() || *near > e.t_ns + opt.aps_max_gap_ns) emit(e);
    last_event_obs = std::move(e);
  }

  // Event tracks of a (time t_a) and b (t_b >= t_a) at out->t_ns in [t_a, t_b]: linear in the
  // normalised image plane.
  static void append_interpolated(const FeatureObservations& a, const FeatureObservations& b, FeatureObservations* out) {
    const double span = static_cast<double>(b.t_ns - a.t_ns);
    const double s = span > 0 ? static_cast<double>(out->t_ns - a.t_ns) / span : 1.0;
    std::map<int64_t, const FeatureObservation*> in_a;
    for (const FeatureObservation& o : a.observations) in_a[o.track_id] = &o;
    for (const FeatureObservation& o : b.observations) {
      const auto it = in_a.find(o.track_id);
      if (it == in_a.end()) continue;
      const Eigen::Vector3d& ba = it->second->bearing_c;
      const Eigen::Vector3d& bb = o.bearing_c;
      if (!(ba.z() > 1e-6) || !(bb.z() > 1e-6)) continue;
      const Eigen::Vector2d x = (1 - s) * ba.head<2>() / ba.z() + s * bb.head<2>() / bb.z();
      out->observations.push_back({o.track_id, Eigen::Vector3d(x.x(), x.y(), 1.0).normalized(), o.sigma_px});
    }
  }

  // One APS frame (camera clock) through undistortion and its tracker.
  void track_aps_frame(const Frame& fr) {
    VioStats& st = result.stats;
    cv::Mat img;
    try {
      img = aps_undistorter->undistort(fr.image);
    } catch (const std::invalid_argument& e) {
      ++st.aps_frames_dropped;
      log_warning(std::string("APS frame at ") + format_seconds(fr.t_ns) + " s skipped: " + e.what());
      return;
    }
    Eigen::Matrix3d R_cur_prev;
    const bool have_prior = prev_aps_t >= 0 && rotation_prior(prev_aps_t, fr.t_ns, &R_cur_prev);
    prev_aps_t = fr.t_ns;
    FeatureObservations f = aps_tracker->track(fr.t_ns + shift, img, have_prior ? &R_cur_prev : nullptr);
    for (FeatureObservation& o : f.observations) {
      o.track_id += kApsTrackIdOffset;
      o.sigma_px = opt.aps_pixel_sigma_px;
    }
    if (st.aps_frames == 0) st.t_first_aps_ns = fr.t_ns;
    st.t_last_aps_ns = fr.t_ns;
    ++st.aps_frames;
    if (use_events) {
      aps_ready.push_back(std::move(f));
    } else {
      emit(std::move(f));
    }
  }

  // Tracks the waiting APS frames the IMU covers (all of them with `all`).
  void drain_frames(bool all) {
    while (!waiting_frames.empty()) {
      if (!all && !imu_covers(waiting_frames.front().t_ns)) {
        const int64_t newest = imu.empty() ? waiting_frames.front().t_ns + shift : imu.back().t_ns;
        if (waiting_frames.back().t_ns + shift - newest <= opt.imu_wait_ns) break;
      }
      const Frame fr = std::move(waiting_frames.front());
      waiting_frames.pop_front();
      track_aps_frame(fr);
    }
  }

  // The estimate back to the frame builder after each tracked frame: the gyro bias, and for
  // use_depth without frame_velocity_at_reference the latest state's camera velocity and median
  // landmark depth for the frames to come (frame_motion_at answers with them).
  void feed_back_motion(const FeatureObservations& f) {
    if (!frame_builder) return;
    frame_builder->set_gyro_bias(est->latest_state().bias_gyro);
    if (!opt.frames.use_depth) return;
    if (frame_motion_oracle) last_tracked = f;
    if (opt.frame_velocity_at_reference) return;
    const VioState st = est->latest_state();
    double depth_m = 0;
    if (!median_landmark_depth(st, &depth_m)) return;
    frontend::FrameMotion m;
    m.v_c = cal.T_c_b.rotation * (st.T_w_b.rotation.conjugate() * st.v_w);
    m.depth_m = depth_m;
    latest_motion = m;
  }

  // The median z-depth of the landmarks in front of the camera at state st; false without any.
  bool median_landmark_depth(const VioState& st, double* depth_m) {
    const calib::SE3 T_c_w = cal.T_c_b * st.T_w_b.inverse();
    depth_scratch.clear();
    for (const auto& [id, p] : est->landmarks()) {
      const double z = (T_c_w.rotation * p + T_c_w.translation).z();
      if (z > 0) depth_scratch.push_back(z);
    }
    if (depth_scratch.empty()) return false;
    const auto mid = depth_scratch.begin() + static_cast<long>(depth_scratch.size() / 2);
    std::nth_element(depth_scratch.begin(), mid, depth_scratch.end());
    *depth_m = *mid;
    return true;
  }

  // frames.use_depth: the motion of the frame whose reference time is t (IMU clock): the oracle's
  // answer when one is set; else without frame_velocity_at_reference the one fed back after the
  // last tracked frame; else the latest state propagated to t with the IMU (the camera centre's
  // velocity, lever arm included) and the median landmark depth. False before the
  // initialisation or without landmarks.
  bool frame_motion_at(int64_t t, frontend::FrameMotion* m) {
    if (!est) return false;
    if (frame_motion_oracle && last_tracked) {
      FeatureObservations g = *last_tracked;
      g.t_ns = t;
      Eigen::Vector4d plane = Eigen::Vector4d::Zero();
      if (frame_motion_oracle(g, &m->v_c, &m->depth_m, &plane)) {
        if (plane.w() > 0) {
          m->plane_n_c = plane.head<3>();
          m->plane_d_m = plane.w();
        }
        return true;
      }
    }
    if (!opt.frame_velocity_at_reference) {
      if (!latest_motion) return false;
      *m = *latest_motion;
      return true;
    }
    const VioState st = est->latest_state();
    double depth_m = 0;
    if (!median_landmark_depth(st, &depth_m)) return false;
    Eigen::Matrix3d R_w_b = st.T_w_b.rotation.toRotationMatrix();
    Eigen::Vector3d v_w = st.v_w;
    if (t > st.t_ns) {
      try {
        const auto pre = backend::ImuPreintegration::between(imu, st.t_ns, t, st.bias_gyro, st.bias_accel, noise);
        v_w += opt.window.gravity_w * pre.dt_s() + R_w_b * pre.delta_v();
        R_w_b = R_w_b * pre.delta_R();
      } catch (const std::invalid_argument&) {
        // no IMU over the interval: the latest state's velocity
      }
    }
    Eigen::Vector3d w_b = Eigen::Vector3d::Zero();
    if (!imu.empty() && t >= imu.front().t_ns && t <= imu.back().t_ns)
      w_b = backend::ImuPreintegration::interpolate(imu, t).gyro - st.bias_gyro;
    const Eigen::Vector3d p_b_c = cal.T_c_b.inverse().translation;  // camera centre, body frame
    m->v_c = cal.T_c_b.rotation * (R_w_b.transpose() * v_w + w_b.cross(p_b_c));
    m->depth_m = depth_m;
    return m->v_c.allFinite();
  }

  // One chunk of raw events through the filters and the front-end.
  void process(EventSpan chunk) {
    VioStats& st = result.stats;
    filtered.clear();
    constexpr size_t kAhead = 16;  // events: the filters' per-pixel tables are fetched ahead
    const bool prefetch = use_frames && chunk.size() > kAhead;
    for (size_t j = 0; j < chunk.size(); ++j) {
      const Event& e = chunk[j];
      if (prefetch && j + kAhead < chunk.size()) {
        const Event& f = chunk[j + kAhead];
        if (f.x < width && f.y < height) {
          if (opt.refractory_enabled) refractory.prefetch(f);
          if (opt.background_activity_enabled) background.prefetch(f);
        }
      }
      if (!have_events) {
        st.t_first_event_ns = e.t_ns;
        next_obs = e.t_ns + opt.observation_period_ns;
        have_events = true;
      }
      if (!use_frames) {
        while (e.t_ns >= next_obs) {
          emit_corner_frame(next_obs);
          next_obs += opt.observation_period_ns;
        }
      }
      st.t_last_event_ns = e.t_ns;
      ++st.events;
      if (e.x >= width || e.y >= height || !undistorter.valid(e.x, e.y)) continue;
      if (opt.refractory_enabled && !refractory.accept(e)) continue;
      if (opt.background_activity_enabled && !background.accept(e)) continue;
      if (use_frames) {
        filtered.push_back(e);
        continue;
      }
      if (!detector->process(e)) continue;
      ++st.corner_events;
      corner_tracker->add(e);
    }
    if (use_frames && recon_undistorter) {
      reconstruct_and_track(filtered);
    } else if (use_frames) {
      // In slices of a quarter frame, so each frame is built with the estimate (gyro bias,
      // velocity, depth) fed back after the frame before it, not with the one of the chunk's start.
      const size_t slice = static_cast<size_t>(std::max<int64_t>(256, opt.frames.events_per_frame / 4));
      for (size_t b = 0; b < filtered.size(); b += slice) {
        built.clear();
        frame_builder->add_events(EventSpan(filtered.data() + b, std::min(slice, filtered.size() - b)), &built);
        for (const auto& ef : built) track_event_frame(ef);
      }
    }
    prune_imu();
  }

  // tracking_image kReconstruction: the filtered events into the high-pass filter, in runs that
  // end where a frame closes (the frame clock of `frames`: events_per_frame events and at least
  // min_window_ns, or max_window_ns whatever the count: the reconstruction holds the texture
  // through event-rate drops), and each frame's image to the tracker.
  void reconstruct_and_track(const std::vector<Event>& ev) {
    if (ev.empty()) return;
    if (!recon) recon = std::make_unique<mapping::ComplementaryFilter>(width, height, ev.front().t_ns, opt.reconstruction);
    const frontend::EventFrameOptions& fo = opt.frames;
    size_t begin = 0;
    for (size_t i = 0; i < ev.size(); ++i) {
      const int64_t t = ev[i].t_ns;
      if (recon_frame_start < 0) recon_frame_start = t;
      // Frames that close before this event (max_window_ns passed without enough events).
      while (t - recon_frame_start > fo.max_window_ns) {
        recon->process(ev.data() + begin, i - begin);
        begin = i;
        close_recon_frame(recon_frame_start + fo.max_window_ns);
        recon_frame_start += fo.max_window_ns;
      }
      ++recon_frame_events;
      if (recon_frame_events >= fo.events_per_frame && t - recon_frame_start >= fo.min_window_ns) {
        recon->process(ev.data() + begin, i + 1 - begin);
        begin = i + 1;
        close_recon_frame(t);
        recon_frame_start = -1;
      }
    }
    recon->process(ev.data() + begin, ev.size() - begin);
  }

  void close_recon_frame(int64_t t_cam) {
    recon_frame_events = 0;
    recon->log_intensity(t_cam, &recon_log);
    cv::Mat grey(height, width, CV_8UC1);
    const float k = static_cast<float>(opt.reconstruction_grey_per_log);
    for (int y = 0; y < height; ++y) {
      uint8_t* row = grey.ptr<uint8_t>(y);
      for (int x = 0; x < width; ++x) row[x] = cv::saturate_cast<uint8_t>(128.0f + k * recon_log(y, x));
    }
    if (opt.reconstruction_blur_px > 0) cv::GaussianBlur(grey, grey, cv::Size(0, 0), opt.reconstruction_blur_px);
    recon_grey = recon_undistorter->undistort(grey);
    frontend::EventFrame ef;
    ef.t_ns = ef.t_end_ns = t_cam;
    ef.image = recon_grey;
    ++result.stats.event_frames.frames_emitted;
    track_event_frame(ef);
  }

  // Processes the waiting chunks the IMU covers (all of them with `all`).
  void drain(bool all) {
    while (!waiting.empty()) {
      if (!all && !imu_covers(waiting.front().back().t_ns) && !imu_missing()) break;
      const std::vector<Event> chunk = std::move(waiting.front());
      waiting.pop_front();
      process(EventSpan(chunk.data(), chunk.size()));
    }
  }

  void check_open() const {
    if (finished) throw std::logic_error("VioPipeline: input after finish()");
  }
};

VioPipeline::VioPipeline(const VioPipelineOptions& options, const calib::CameraCalibration& camera,
                         const calib::ImuNoise& noise)
    : options_(checked(options, noise)), impl_(std::make_unique<Impl>(options_, camera, noise)) {}

VioPipeline::~VioPipeline() = default;

void VioPipeline::set_initial_state_provider(InitialStateProvider provider) { impl_->initial_state = std::move(provider); }

void VioPipeline::set_observation_callback(ObservationCallback callback) { impl_->on_observations = std::move(callback); }
void VioPipeline::set_observation_filter(ObservationFilter filter) { impl_->observation_filter = std::move(filter); }
void VioPipeline::set_tracking_image_callback(TrackingImageCallback callback) { impl_->on_tracking_image = std::move(callback); }
void VioPipeline::set_frame_motion_oracle(FrameMotionOracle oracle) { impl_->frame_motion_oracle = std::move(oracle); }
void VioPipeline::set_state_callback(StateCallback callback) { impl_->on_state = std::move(callback); }
size_t VioPipeline::buffered_states() const { return impl_->predictions.size() + impl_->final_keyframes.size(); }

bool VioPipeline::initialized() const { return impl_->est != nullptr; }

void VioPipeline::add_imu(const ImuSample& sample) {
  Impl& p = *impl_;
  p.check_open();
  p.imu.push_back(sample);
  if (p.frame_builder) p.frame_builder->add_imu(sample);
  p.drain_frames(false);
  p.drain(false);
  p.try_init_on_stall();
}

void VioPipeline::add_frame(const Frame& frame) {
  Impl& p = *impl_;
  p.check_open();
  if (!p.use_aps) return;
  const int64_t last = !p.waiting_frames.empty() ? p.waiting_frames.back().t_ns : p.prev_aps_t;
  if (frame.image.empty() || (last >= 0 && frame.t_ns <= last)) {
    ++p.result.stats.aps_frames_dropped;
    return;
  }
  p.aps_times.push_back(frame.t_ns + p.shift);
  p.waiting_frames.push_back(frame);
  p.drain_frames(false);
}

void VioPipeline::add_events(EventSpan events) {
  Impl& p = *impl_;
  p.check_open();
  if (events.empty()) return;
  if (!p.use_events) {
    p.result.stats.events += static_cast<int64_t>(events.size());
    return;
  }
  if (p.waiting.empty() && p.imu_covers(events.back().t_ns)) {
    p.process(events);
  } else {
    p.waiting.emplace_back(events.begin(), events.end());
    p.drain(false);
  }
  p.try_init_on_stall();
}

VioResult VioPipeline::finish() {
  Impl& p = *impl_;
  p.check_open();
  p.finished = true;
  p.drain_frames(true);
  p.drain(true);
  // Event-rate drops at the end: frames up to the last IMU sample keep the state propagating.
  if (p.frame_builder) {
    p.built.clear();
    p.frame_builder->flush(&p.built);
    for (const auto& ef : p.built) p.track_event_frame(ef);
    // No frame since long before the end (too few events): the state propagates with the IMU to the
    // end of the recording, and the span is IMU-only.
    const int64_t t_end_cam = p.imu.empty() ? p.result.stats.t_last_event_ns : p.imu.back().t_ns - p.shift;
    if (p.est && p.prev_frame_t >= 0 && t_end_cam - p.prev_frame_t > 2 * options_.frames.max_window_ns) {
      p.emit_gap_frames(t_end_cam + 1);
      p.prev_frame_t = t_end_cam;
    }
  } else if (p.recon && p.recon_frame_start >= 0 && p.recon_frame_events >= options_.frames.min_events) {
    p.close_recon_frame(p.result.stats.t_last_event_ns);
  }
  // APS frames after the last event frame: without event tracks.
  while (!p.aps_ready.empty()) {
    p.emit(std::move(p.aps_ready.front()));
    p.aps_ready.pop_front();
  }
  VioStats& st = p.result.stats;
  if (!p.use_frames && p.have_events) {
    const int64_t t_end_cam = p.imu.empty() ? st.t_last_event_ns : std::min(p.imu.back().t_ns - p.shift, st.t_last_event_ns);
    while (p.next_obs <= t_end_cam) {
      p.emit_corner_frame(p.next_obs);
      p.next_obs += options_.observation_period_ns;
    }
  }
  if (!p.est) p.try_init(true);
  if (p.est && p.imu.size() > 0) p.close_imu_only_span(std::max(p.last_causal_t, p.last_visual_t));
  for (const VioSegment& s : p.result.imu_only) {
    if (s.t_end_ns - s.t_begin_ns >= options_.tracking_lost_min_duration_ns) {
      log_warning("IMU only (" + s.what + ") from " + format_seconds(s.t_begin_ns) + " to " + format_seconds(s.t_end_ns) +
                  " s: the estimate there drifts with the IMU");
    }
  }
  if (p.few_since >= 0 && st.t_last_event_ns + p.shift - p.few_since >= options_.tracking_lost_min_duration_ns) {
    p.result.tracking_lost.push_back({p.few_since, st.t_last_event_ns + p.shift, p.lost_reason()});
  }
  if (!p.result.initialized && p.result.init_failure.empty()) {
    p.result.init_failure = p.have_events || p.result.stats.aps_frames > 0 ? "no frame to initialise from"
                            : p.use_events                                  ? "no events"
                                                                            : "no APS frames";
  }
  if (p.use_frames) {
    if (p.frame_builder) st.event_frames = p.frame_builder->stats();
    st.tracker = p.frame_tracker->stats();
  } else {
    st.corner_tracker = p.corner_tracker->stats();
  }
  if (p.use_aps) st.aps_tracker = p.aps_tracker->stats();
  if (p.est) {
    st.window = p.est->stats();
    p.health_segments();
    const std::vector<VioState> window = p.est->keyframe_states();
    for (const VioState& k : window) p.final_keyframes[k.t_ns] = k;
    for (size_t i = 0; i + 1 < window.size(); ++i)
      p.relative_to_next[window[i].t_ns] = {window[i + 1].t_ns, window[i].T_w_b.inverse() * window[i + 1].T_w_b};
    p.release(std::numeric_limits<int64_t>::max());
    p.final_keyframes.clear();  // everything is out: nothing more is chained from them
    p.chained_keyframes.clear();
    p.relative_to_next.clear();
    // Motion-model segments from the keyframes' models.
    for (const auto& [t, rotation_only] : st.window.motion_model) {
      const std::string m = rotation_only ? "rotation_only" : "6dof";
      if (p.result.motion_models.empty() || p.result.motion_models.back().what != m) {
        p.result.motion_models.push_back({t, t, m});
      } else {
        p.result.motion_models.back().t_end_ns = t;
      }
    }
  }
  return std::move(p.result);
}

}  // namespace evio::pipeline
