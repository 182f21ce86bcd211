#include "evio/pipeline/vio_pipeline.h"

#include <algorithm>
#include <deque>
#include <functional>
#include <limits>
#include <stdexcept>
#include <utility>

#include "evio/backend/imu_preintegration.h"
#include "evio/backend/trajectory_smoothing.h"
#include "evio/calib/log.h"
#include "evio/sensors/time.h"
#include "vio_pipeline_impl.h"

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
  if (!rotation_tracker_options.Validate(&w)) return fail("rotation_tracker: " + w);
  if (rotation_tracker_start_keyframes < 1 || rotation_tracker_stop_keyframes < 1)
    return fail("rotation_tracker: start_keyframes and stop_keyframes must be >= 1");
  if (rotation_tracker_history_ns < 0) return fail("rotation_tracker: history_ms must be >= 0");
  if (rotation_tracker_hold_ns < 0) return fail("rotation_tracker: hold_ms must be >= 0");
  if (!(rotation_tracker_max_flow_deg_s > 0) || !std::isfinite(rotation_tracker_max_flow_deg_s))
    return fail("rotation_tracker: max_flow_deg_s must be finite and > 0");
  if (rotation_tracker && (!rotation_tracker_options.use_gyro ||
                           (rotation_tracker_options.tracker_method != MosaicTracker::kParticleFilter &&
                            rotation_tracker_options.tracker_method != MosaicTracker::kOdometryParticleFilter)))
    return fail("rotation_tracker: the tracker is the particle filter (pf or odometry+pf) with the gyro");
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

VioPipeline::Impl::Impl(const VioPipelineOptions& o, const calib::CameraCalibration& camera, const calib::ImuNoise& imu_noise)
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

// ---- IMU ------------------------------------------------------------------------------------

// Drops the samples no later step can use: everything before the last sample at or before the
// earliest time still needed (that sample stays, as the interpolation bracket).
void VioPipeline::Impl::prune_imu() {
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

void VioPipeline::Impl::output(VioPipeline::StateKind kind, const VioState& s) {
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
void VioPipeline::Impl::release(int64_t t_final) {
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
void VioPipeline::Impl::chain_final(int64_t t_final) {
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
      // A keyframe held by a rotation-tracker factor (or anchoring one) keeps its own orientation: the factor ties it
      // to the segment's anchor, which chaining the relative rotations would undo.
      if (tracker_keyframes.count(it->first)) T.rotation = f.T_w_b.rotation;
      const Eigen::Matrix3d R_corr = T.rotation.toRotationMatrix() * f.T_w_b.rotation.toRotationMatrix().transpose();
      c.T_w_b = T;
      c.v_w = R_corr * f.v_w;
    }
    chained_keyframes[it->first] = c;
    tracker_keyframes.erase(it->first);
  }
}

void VioPipeline::Impl::feed(const FeatureObservations& f) {
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
  if (kf && opt.rotation_tracker && !est->stats().motion_model_tests.empty() &&
      est->stats().motion_model_tests.back().t_ns == f.t_ns) {
    const auto& test = est->stats().motion_model_tests.back();
    // For the start: bearings without G and a known flow below the bound (a tracker started on the
    // rotation-only model before any depth was known tracked worse: docs/design-notes.md). For the stop: G, or a
    // flow at the bound from a window with opt.health_min_landmarks landmarks (the velocity of a
    // window without them has spikes of metres per second while the camera pans in place).
    const double flow = test.translation_flow_deg_s, bound = opt.rotation_tracker_max_flow_deg_s;
    const bool image_rotation = test.image_best != backend::TwoViewModel::kGeneral;
    const bool moving = flow >= bound && test.landmarks >= std::max(1, opt.health_min_landmarks);
    update_rotation_tracker(f.t_ns, image_rotation && flow >= 0 && flow < bound, image_rotation && !moving);
  }
  if (kf) {
    const auto& factors = est->stats().tracker_factors;
    for (; tracker_factors_seen < factors.size(); ++tracker_factors_seen)
      if (opt.keyframe_chaining && !factors[tracker_factors_seen].dropped) {  // for chain_final only
        tracker_keyframes.insert(factors[tracker_factors_seen].t_ns);
        if (!chained_keyframes.count(factors[tracker_factors_seen].anchor_t_ns))  // an anchor already final stays as it is
          tracker_keyframes.insert(factors[tracker_factors_seen].anchor_t_ns);
      }
    for (const auto& [id, p] : est->landmarks()) result.landmarks[id] = p;
    const std::vector<VioState> window = est->keyframe_states();
    for (const VioState& k : window) final_keyframes[k.t_ns] = k;
    for (size_t i = 0; i + 1 < window.size(); ++i)
      relative_to_next[window[i].t_ns] = {window[i + 1].t_ns, window[i].T_w_b.inverse() * window[i + 1].T_w_b};
    // The keyframes before the window's oldest are final (no solve changes them again).
    const auto first_in_window = window.empty() ? final_keyframes.end() : final_keyframes.find(window.front().t_ns);
    if (first_in_window != final_keyframes.begin() && first_in_window != final_keyframes.end()) {
      // While a tracker is held, they wait: its orientations may correct them (rotation_tracker_held_output).
      if (!(rot_lead && opt.rotation_tracker_held_output)) release(std::prev(first_in_window)->first);
    }
  }
}

// The runs of keyframes that failed a health check, per reason, into result.unreliable (time
// order of their starts), with a warning each.
void VioPipeline::Impl::health_segments() {
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
void VioPipeline::Impl::close_imu_only_span(int64_t t) {
  if (last_visual_t < 0 || t - last_visual_t < opt.imu_only_min_duration_ns) return;
  result.imu_only.push_back({last_visual_t, t, gap_since_visual ? "no event frames (event-rate drop)" : lost_reason()});
}

// ---- front-end ------------------------------------------------------------------------------

// Every front-end frame (IMU clock) goes through here.
void VioPipeline::Impl::handle_frame(FeatureObservations f) {
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

// Corners front-end: the active corner tracks sampled at t_cam.
void VioPipeline::Impl::emit_corner_frame(int64_t t_cam) {
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
void VioPipeline::Impl::track_event_frame(const frontend::EventFrame& ef) {
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
bool VioPipeline::Impl::propagated_state(int64_t t, VioState* out) const {
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
std::vector<frontend::TrackPrediction> VioPipeline::Impl::lost_track_predictions(int64_t t) const {
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
void VioPipeline::Impl::emit_gap_frames(int64_t t_cam) {
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
bool VioPipeline::Impl::rotation_prior(int64_t t0_cam, int64_t t1_cam, Eigen::Matrix3d* R_cur_prev) const {
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
void VioPipeline::Impl::emit(FeatureObservations f) {
  if (use_aps && f.t_ns <= last_emitted_t) {
    ++result.stats.aps_frames_dropped;
    return;
  }
  last_emitted_t = f.t_ns;
  f.frame_id = frame_id++;
  handle_frame(std::move(f));
}

// The estimate back to the frame builder after each tracked frame: the gyro bias, and for
// use_depth without frame_velocity_at_reference the latest state's camera velocity and median
// landmark depth for the frames to come (frame_motion_at answers with them).
void VioPipeline::Impl::feed_back_motion(const FeatureObservations& f) {
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
bool VioPipeline::Impl::median_landmark_depth(const VioState& st, double* depth_m) {
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
bool VioPipeline::Impl::frame_motion_at(int64_t t, frontend::FrameMotion* m) {
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
void VioPipeline::Impl::process(EventSpan chunk) {
  VioStats& st = result.stats;
  if (opt.rotation_tracker && opt.rotation_tracker_from_start && !rot_lead_started && !chunk.empty())
    start_rotation_tracker_lead(chunk.front().t_ns + shift);
  if (rot_tracker) {
    rotation_tracker_events(chunk);  // before the frames: its orientations then cover their keyframes
  } else if (opt.rotation_tracker) {
    keep_rotation_tracker_history(chunk);
  }
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
void VioPipeline::Impl::reconstruct_and_track(const std::vector<Event>& ev) {
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

void VioPipeline::Impl::close_recon_frame(int64_t t_cam) {
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
void VioPipeline::Impl::drain(bool all) {
  while (!waiting.empty()) {
    if (!all && !imu_covers(waiting.front().back().t_ns) && !imu_missing()) break;
    const std::vector<Event> chunk = std::move(waiting.front());
    waiting.pop_front();
    process(EventSpan(chunk.data(), chunk.size()));
  }
}

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
  if (p.rot_tracker) p.rotation_tracker_imu();
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
    p.rotation_tracker_spans();
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
