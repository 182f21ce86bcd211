// VioPipeline's intensity (APS) frames (inputs aps and events+aps): each frame is undistorted into
// the ideal pinhole and tracked by its own FeatureTracker under the gyro's rotation prior; with
// events+aps the estimator gets the APS frames, each with the event tracks seen in the event frames
// on either side interpolated to its time (linear in the normalised image plane), and an event
// frame on its own only where no APS frame is within aps_max_gap_ns.
#include <algorithm>
#include <map>
#include <string>
#include <utility>

#include "evio/calib/log.h"
#include "evio/sensors/time.h"
#include "vio_pipeline_impl.h"

namespace evio::pipeline {

// An event frame's observations (IMU clock). With events+aps the APS frames up to its time go
// first, each with the event tracks seen in both this and the previous event frame interpolated
// to the APS time; the event frame itself only when no APS frame is within aps_max_gap_ns.
void VioPipeline::Impl::emit_event_frame(FeatureObservations e) {
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
void VioPipeline::Impl::append_interpolated(const FeatureObservations& a, const FeatureObservations& b, FeatureObservations* out) {
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
void VioPipeline::Impl::track_aps_frame(const Frame& fr) {
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
void VioPipeline::Impl::drain_frames(bool all) {
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

}  // namespace evio::pipeline
