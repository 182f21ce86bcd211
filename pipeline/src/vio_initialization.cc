// VioPipeline's initialisation: frames are collected until they span init_window_ns (or the IMU
// does while the frames have stalled), then the first state is found by a still window of the IMU
// (backend::static_initialization), by visual-inertial alignment of the frames
// (backend::visual_inertial_initialization) or from the given provider; on failure the window slides
// by init_retry_slide_fraction and it is tried again. The estimator then starts from that state.
#include <algorithm>
#include <string>
#include <vector>

#include "evio/backend/initialization.h"
#include "evio/calib/log.h"
#include "evio/sensors/time.h"
#include "vio_pipeline_impl.h"

namespace evio::pipeline {

// The time (IMU clock) up to which both the events and the IMU have been processed while the
// newest pending frame lags behind them by an event-rate drop; -1 when frames are not stalled.
int64_t VioPipeline::Impl::stalled_frames_until() const {
  if (pending.empty() || imu.empty() || !have_events) return -1;
  const int64_t seen = std::min(imu.back().t_ns - opt.imu_lookahead_ns, result.stats.t_last_event_ns + shift);
  return seen - pending.back().t_ns > opt.event_rate_drop_windows * opt.frames.max_window_ns ? seen : -1;
}

// Not initialised with frames waiting and the frames stalled: the IMU and the events seen may
// complete the initialisation window. Attempted at most once per max_window_ns of data.
void VioPipeline::Impl::try_init_on_stall() {
  if (est || pending.empty()) return;
  const int64_t until = stalled_frames_until();
  if (until < 0 || until - last_stall_init_ns < opt.frames.max_window_ns) return;
  last_stall_init_ns = until;
  try_init(false);
}

void VioPipeline::Impl::try_init(bool final_attempt) {
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

}  // namespace evio::pipeline
