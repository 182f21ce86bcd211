#include "evio/pipeline/vio_pipeline.h"

#include <algorithm>
#include <deque>
#include <limits>
#include <stdexcept>
#include <utility>

#include "evio/backend/imu_preintegration.h"
#include "evio/calib/log.h"
#include "evio/sensors/time.h"

namespace evio::pipeline {

const char* to_string(VioFrontEnd f) { return f == VioFrontEnd::kCorners ? "corners" : "frames"; }

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
        undistorter(camera.camera),
        refractory(width, height, o.refractory),
        background(width, height, o.background_activity) {
    if (use_frames) {
      frame_builder = std::make_unique<frontend::EventFrameBuilder>(cal, opt.frames);
      // The tracker works on the builder's undistorted pinhole images.
      calib::CameraIntrinsics ideal = cal.camera.intrinsics();
      ideal.model = calib::DistortionModel::kNone;
      ideal.distortion.clear();
      frame_tracker = std::make_unique<frontend::FeatureTracker>(ideal, opt.tracker);
    } else {
      detector = std::make_unique<frontend::EfastDetector>(width, height, opt.efast);
      corner_tracker = std::make_unique<frontend::CornerTracker>(width, height, opt.corner_tracker);
    }
  }

  const VioPipelineOptions& opt;
  const calib::CameraCalibration cal;
  const calib::ImuNoise noise;
  const int width, height;
  const int64_t shift;  // t_imu = t_cam + shift
  const bool use_frames;

  InitialStateProvider initial_state;
  ObservationCallback on_observations;
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
  std::unique_ptr<frontend::FeatureTracker> frame_tracker;
  std::unique_ptr<frontend::EfastDetector> detector;
  std::unique_ptr<frontend::CornerTracker> corner_tracker;
  std::vector<Event> filtered;
  std::vector<frontend::EventFrame> built;
  int64_t prev_frame_t = -1;  // camera clock, last event frame
  int64_t next_obs = 0;       // camera clock, next corner observation frame
  bool have_events = false;
  int64_t frame_id = 0;

  // Back-end and results.
  std::unique_ptr<backend::SlidingWindowEstimator> est;
  std::vector<FeatureObservations> pending;  // frames before initialisation
  VioResult result;
  bool in_gap = false;     // emitting the empty frames of an event-rate drop
  int64_t few_since = -1;  // start of the current run of frames with too few tracks (IMU clock)

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
      need = pending.front().t_ns - opt.init_imu_history_ns;  // the initialisation's first frame
    } else if (!use_frames && have_events) {
      need = next_obs + shift - opt.init_imu_history_ns;  // the next corner frame
    } else if (use_frames && prev_frame_t >= 0) {
      need = prev_frame_t + shift - opt.init_imu_history_ns;  // frames after the last one
    } else {
      return;  // no frame yet: the first one may start anywhere
    }
    if (use_frames && prev_frame_t >= 0) need = std::min(need, prev_frame_t + shift);  // rotation prior
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

  void feed(const FeatureObservations& f) {
    while (next_imu < imu.size() && imu[next_imu].t_ns <= f.t_ns + opt.imu_lookahead_ns) est->add_imu(imu[next_imu++]);
    const bool kf = est->add_frame(f);
    // One state per new state time (a frame the estimator skipped adds none).
    const VioState& ls = est->latest_state();
    if (result.trajectory.empty() || ls.t_ns > result.trajectory.back().t_ns) result.trajectory.push_back(ls);
    if (kf) {
      for (const auto& [id, p] : est->landmarks()) result.landmarks[id] = p;
    }
  }

  void try_init(bool final_attempt) {
    if (pending.empty()) return;
    const int64_t t0 = pending.front().t_ns;
    if (pending.back().t_ns - t0 < opt.init_window_ns && !final_attempt) return;
    std::optional<VioState> s;
    std::string why;
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
      s = backend::static_initialization(imu, t0, noise, opt.static_init, &why);
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
    est->initialize(*s);
    while (next_imu < imu.size() && imu[next_imu].t_ns < s->t_ns - opt.init_imu_history_ns) ++next_imu;
    for (const auto& f : pending)
      if (f.t_ns >= s->t_ns) feed(f);
    pending.clear();
  }

  // ---- front-end ------------------------------------------------------------------------------

  // Every front-end frame (IMU clock) goes through here.
  void handle_frame(FeatureObservations f) {
    ++result.stats.frontend_frames;
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
      feed(f);
    } else {
      pending.push_back(std::move(f));
      try_init(false);
    }
  }

  std::string lost_reason() const { return "fewer than " + std::to_string(opt.tracking_lost_min_tracks) + " tracks"; }

  // Corners front-end: the active corner tracks sampled at t_cam.
  void emit_corner_frame(int64_t t_cam) {
    FeatureObservations f;
    f.t_ns = t_cam + shift;
    f.frame_id = frame_id++;
    corner_tracker->predict_active(t_cam, opt.observation_period_ns, opt.min_track_age_ns,
                                   [&](int64_t id, const Eigen::Vector2d& px) {
                                     Eigen::Vector3d b;
                                     if (px.allFinite() && cal.camera.unproject(px, &b) && b.z() > opt.corner_min_bearing_z)
                                       f.observations.push_back({id, b});
                                   });
    handle_frame(std::move(f));
  }

  // Frames front-end: one observation frame per event frame, tracked with the IMU rotation prior.
  void track_event_frame(const frontend::EventFrame& ef) {
    const int64_t max_window = opt.frames.max_window_ns;
    if (prev_frame_t >= 0 && ef.t_ns - prev_frame_t > opt.event_rate_drop_windows * max_window) {
      result.tracking_lost.push_back({prev_frame_t + shift, ef.t_ns + shift, "no event frames (event-rate drop)"});
      in_gap = true;
      for (int64_t t = prev_frame_t + max_window; t < ef.t_ns; t += max_window) {
        FeatureObservations empty;
        empty.t_ns = t + shift;
        empty.frame_id = frame_id++;
        handle_frame(std::move(empty));
      }
      in_gap = false;
    }
    Eigen::Matrix3d R_cur_prev = Eigen::Matrix3d::Identity();
    bool have_prior = false;
    const Eigen::Vector3d bg = est ? est->latest_state().bias_gyro : Eigen::Vector3d::Zero();
    if (prev_frame_t >= 0) {
      try {
        const auto pre = backend::ImuPreintegration::between(imu, prev_frame_t + shift, ef.t_ns + shift, bg,
                                                             Eigen::Vector3d::Zero(), noise);
        const Eigen::Matrix3d R_c_b = cal.T_c_b.rotation.toRotationMatrix();
        R_cur_prev = R_c_b * pre.delta_R().transpose() * R_c_b.transpose();
        have_prior = true;
      } catch (const std::invalid_argument&) {
        // no IMU around the frame: track without the rotation prior
      }
    }
    prev_frame_t = ef.t_ns;
    FeatureObservations f = frame_tracker->track(ef.t_ns + shift, ef.image, have_prior ? &R_cur_prev : nullptr);
    f.frame_id = frame_id++;
    if (est) feed_back_motion();
    handle_frame(std::move(f));
  }

  // The estimate back to the frame builder: gyro bias, and for use_depth the camera velocity and
  // the median landmark depth.
  void feed_back_motion() {
    const VioState st = est->latest_state();
    frame_builder->set_gyro_bias(st.bias_gyro);
    if (!opt.frames.use_depth) return;
    const calib::SE3 T_c_w = cal.T_c_b * st.T_w_b.inverse();
    std::vector<double> depth;
    for (const auto& [id, p] : est->landmarks()) {
      const double z = (T_c_w.rotation * p + T_c_w.translation).z();
      if (z > 0) depth.push_back(z);
    }
    if (depth.empty()) return;
    std::nth_element(depth.begin(), depth.begin() + static_cast<long>(depth.size() / 2), depth.end());
    const Eigen::Vector3d v_c = cal.T_c_b.rotation * (st.T_w_b.rotation.conjugate() * st.v_w);
    frame_builder->set_motion(v_c, depth[depth.size() / 2]);
  }

  // One chunk of raw events through the filters and the front-end.
  void process(EventSpan chunk) {
    VioStats& st = result.stats;
    filtered.clear();
    for (const Event& e : chunk) {
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
    if (use_frames) {
      built.clear();
      frame_builder->add_events(EventSpan(filtered.data(), filtered.size()), &built);
      for (const auto& ef : built) track_event_frame(ef);
    }
    prune_imu();
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

bool VioPipeline::initialized() const { return impl_->est != nullptr; }

void VioPipeline::add_imu(const ImuSample& sample) {
  Impl& p = *impl_;
  p.check_open();
  p.imu.push_back(sample);
  if (p.frame_builder) p.frame_builder->add_imu(sample);
  p.drain(false);
}

void VioPipeline::add_events(EventSpan events) {
  Impl& p = *impl_;
  p.check_open();
  if (events.empty()) return;
  if (p.waiting.empty() && p.imu_covers(events.back().t_ns)) {
    p.process(events);
    return;
  }
  p.waiting.emplace_back(events.begin(), events.end());
  p.drain(false);
}

VioResult VioPipeline::finish() {
  Impl& p = *impl_;
  p.check_open();
  p.finished = true;
  p.drain(true);
  // Event-rate drops at the end: frames up to the last IMU sample keep the state propagating.
  if (p.use_frames) {
    p.built.clear();
    p.frame_builder->flush(&p.built);
    for (const auto& ef : p.built) p.track_event_frame(ef);
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
  if (p.few_since >= 0 && st.t_last_event_ns + p.shift - p.few_since >= options_.tracking_lost_min_duration_ns) {
    p.result.tracking_lost.push_back({p.few_since, st.t_last_event_ns + p.shift, p.lost_reason()});
  }
  if (!p.result.initialized && p.result.init_failure.empty()) {
    p.result.init_failure = p.have_events ? "no frame to initialise from" : "no events";
  }
  if (p.use_frames) {
    st.event_frames = p.frame_builder->stats();
    st.tracker = p.frame_tracker->stats();
  } else {
    st.corner_tracker = p.corner_tracker->stats();
  }
  if (p.est) {
    st.window = p.est->stats();
    p.result.keyframes = p.est->keyframe_states();
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
