// VioPipeline's rotation tracker (options rotation_tracker): the mosaic's particle filter with the
// gyro (MosaicPipeline), run on the events while the estimator's motion model is rotation-only,
// its orientations against its own panorama given to the estimator as they come.
#include <algorithm>
#include <chrono>
#include <limits>
#include <map>

#include "vio_pipeline_impl.h"

namespace evio::pipeline {

namespace {
// Accumulates the wall time of a scope into *total (s).
struct ScopeTimer {
  explicit ScopeTimer(double* total) : total_(total), t0_(std::chrono::steady_clock::now()) {}
  ~ScopeTimer() { *total_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0_).count(); }
  double* total_;
  std::chrono::steady_clock::time_point t0_;
};
}  // namespace

void VioPipeline::Impl::update_rotation_tracker(int64_t t_kf, bool can_start, bool can_continue) {
  if (rot_lead) {
    // A held tracker (from the recording's start, or stopped): the start rule releases its
    // orientations; the stop rule ends the one from the start before it was released, and
    // rotation_tracker_hold_ns ends either.
    if (rot_hold_start_t < 0) rot_hold_start_t = t_kf;
    rot_lead_start_run = can_start ? rot_lead_start_run + 1 : 0;
    rot_run = can_continue ? 0 : rot_run + 1;
    if ((!rot_fed && rot_run >= opt.rotation_tracker_stop_keyframes) || t_kf - rot_hold_start_t > opt.rotation_tracker_hold_ns) {
      ScopeTimer timer(&result.stats.rotation_tracker_time_s);
      rot_tracker.reset();
      rot_lead = false;
      rot_held.clear();
      rot_held.shrink_to_fit();
      rot_run = 0;
      ++result.stats.rotation_tracker_discarded;
    } else if (rot_lead_start_run >= opt.rotation_tracker_start_keyframes) {
      rot_lead = false;
      rot_run = 0;
      if (!rot_fed) ++result.stats.rotation_tracker_segments;
      rot_fed = true;
      if (opt.rotation_tracker_held_output) correct_held_output();
      for (const auto& r : rot_held) est->add_tracked_rotation(r);
      rot_held.clear();
      rot_held.shrink_to_fit();
    }
    return;
  }
  // rot_run counts the keyframes that disagree with the tracker's state.
  const bool rotation_dominant = rot_tracker ? can_continue : can_start;
  rot_run = rotation_dominant == static_cast<bool>(rot_tracker) ? 0 : rot_run + 1;
  if (rot_run == 1 && !rot_tracker) rot_run_start_t = t_kf;
  if (rot_tracker) {
    if (rot_run >= opt.rotation_tracker_stop_keyframes) {
      rot_run = 0;
      if (opt.rotation_tracker_hold_on_stop) {  // held: its orientations wait for the start rule
        rot_lead = true;
        rot_lead_start_run = 0;
        rot_hold_start_t = -1;
      } else {
        ScopeTimer timer(&result.stats.rotation_tracker_time_s);
        rot_tracker.reset();
      }
    }
    return;
  }
  if (rot_run < opt.rotation_tracker_start_keyframes) return;
  rot_run = 0;
  ScopeTimer timer(&result.stats.rotation_tracker_time_s);
  // The tracker starts at the run's first keyframe: the events kept since (the front-end's frames
  // lag the events read).
  start_rotation_tracker(rot_run_start_t);
  ++result.stats.rotation_tracker_segments;
  rot_fed = true;
  auto first = std::lower_bound(rot_history.begin(), rot_history.end(), rot_run_start_t - shift,
                                [](const Event& e, int64_t t) { return e.t_ns < t; });
  const std::vector<Event> kept(first, rot_history.end());
  rot_history.clear();
  if (!kept.empty()) {
    result.stats.rotation_tracker_events += static_cast<int64_t>(kept.size());
    rot_tracker->add_events(EventSpan(kept.data(), kept.size()));
  }
}

void VioPipeline::Impl::correct_held_output() {
  if (rot_held.empty() || !est) return;
  const std::vector<VioState> window = est->keyframe_states();
  const int64_t t_window = window.empty() ? std::numeric_limits<int64_t>::max() : window.front().t_ns;
  const auto max_gap = static_cast<int64_t>(est->options().tracker_max_gap_s * 1e9);
  const Eigen::Quaterniond q_b_c = cal.T_c_b.rotation.conjugate();
  // Per segment: the body orientation and the tracker's at its first waiting keyframe.
  std::map<int64_t, std::pair<Eigen::Quaterniond, Eigen::Quaterniond>> reference;
  for (auto it = final_keyframes.upper_bound(last_keyframe_out); it != final_keyframes.end() && it->first < t_window; ++it) {
    backend::SlidingWindowEstimator::TrackedRotation r;
    if (!backend::tracked_rotation_at(rot_held.begin(), rot_held.end(), it->first, max_gap, &r)) continue;
    calib::SE3& T = it->second.T_w_b;
    const auto [ref, first] = reference.try_emplace(r.segment, T.rotation, r.q_m_c);
    if (!first) {
      // R_w_b = R_w_b(ref) R_b_c R_cref_c R_c_b, with R_cref_c the tracker's camera rotation since the reference.
      T.rotation = (ref->second.first * q_b_c * (ref->second.second.conjugate() * r.q_m_c) * q_b_c.conjugate()).normalized();
      ++result.stats.rotation_tracker_corrected_keyframes;
    }
    if (opt.keyframe_chaining) tracker_keyframes.insert(it->first);  // chain_final keeps its orientation
  }
}

void VioPipeline::Impl::start_rotation_tracker_lead(int64_t t_first_event) {
  rot_lead_started = true;
  rot_lead = true;
  rot_lead_start_run = 0;
  rot_hold_start_t = -1;
  rot_run = 0;
  ScopeTimer timer(&result.stats.rotation_tracker_time_s);
  start_rotation_tracker(t_first_event);
}

void VioPipeline::Impl::start_rotation_tracker(int64_t from_t) {
  rot_tracker = std::make_unique<MosaicPipeline>(opt.rotation_tracker_options, cal);
  ++rot_segment;
  rot_fed = false;
  rot_lost = false;
  rot_tracker->set_track_callback([this](int64_t t_cam, const Eigen::Quaterniond& q_m_c, const Eigen::Matrix3d& cov_c, bool lost) {
    if (lost) {
      ++result.stats.rotation_tracker_lost_samples;
      rot_lost = true;
      return;
    }
    if (rot_lost) {  // tracking again after a loss: a new anchor
      ++rot_segment;
      rot_lost = false;
    }
    backend::SlidingWindowEstimator::TrackedRotation r;
    r.t_ns = t_cam + shift;
    r.q_m_c = q_m_c;
    r.cov_c = cov_c;
    r.segment = rot_segment;
    if (rot_lead) {  // held back: one orientation per millisecond is plenty for keyframes
      if (rot_held.empty() || r.segment != rot_held.back().segment || r.t_ns - rot_held.back().t_ns >= 1'000'000)
        rot_held.push_back(r);
    } else {
      est->add_tracked_rotation(r);
    }
  });
  // The gyro from a little before the first event.
  const int64_t from = from_t - 50'000'000;
  rot_imu_fed_t = std::numeric_limits<int64_t>::min();
  for (const ImuSample& s : imu) {
    if (s.t_ns < from) continue;
    rot_tracker->add_imu(s);
    rot_imu_fed_t = s.t_ns;
  }
}

void VioPipeline::Impl::keep_rotation_tracker_history(EventSpan chunk) {
  if (chunk.empty()) return;
  rot_history.insert(rot_history.end(), chunk.begin(), chunk.end());
  const int64_t keep_from = chunk.back().t_ns - opt.rotation_tracker_history_ns;
  auto first = std::lower_bound(rot_history.begin(), rot_history.end(), keep_from,
                                [](const Event& e, int64_t t) { return e.t_ns < t; });
  rot_history.erase(rot_history.begin(), first);
}

void VioPipeline::Impl::rotation_tracker_events(EventSpan chunk) {
  ScopeTimer timer(&result.stats.rotation_tracker_time_s);
  result.stats.rotation_tracker_events += static_cast<int64_t>(chunk.size());
  rot_tracker->add_events(chunk);
}

void VioPipeline::Impl::rotation_tracker_imu() {
  ScopeTimer timer(&result.stats.rotation_tracker_time_s);
  if (imu.back().t_ns <= rot_imu_fed_t) return;
  rot_tracker->add_imu(imu.back());
  rot_imu_fed_t = imu.back().t_ns;
}

void VioPipeline::Impl::rotation_tracker_spans() {
  if (!est) return;
  std::map<int64_t, VioSegment> spans;  // by segment
  for (const auto& f : est->stats().tracker_factors) {
    if (f.dropped) continue;
    auto [it, fresh] = spans.try_emplace(f.segment);
    if (fresh) {
      it->second.t_begin_ns = f.anchor_t_ns;
      it->second.what = "segment " + std::to_string(f.segment);
    }
    it->second.t_end_ns = f.t_ns;
  }
  for (auto& [segment, span] : spans) result.rotation_tracker.push_back(span);
}

}  // namespace evio::pipeline
