// VioPipeline's rotation tracker (options rotation_tracker): the mosaic's particle filter with the
// gyro (MosaicPipeline), run on the events while the estimator's motion model is rotation-only,
// its orientations against its own panorama given to the estimator as they come.
#include <algorithm>
#include <chrono>
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

void VioPipeline::Impl::update_rotation_tracker(int64_t t_kf, bool rotation_dominant) {
  // rot_run counts the keyframes that disagree with the tracker's state.
  rot_run = rotation_dominant == static_cast<bool>(rot_tracker) ? 0 : rot_run + 1;
  if (rot_run == 1 && !rot_tracker) rot_run_start_t = t_kf;
  if (rot_tracker) {
    if (rot_run >= opt.rotation_tracker_stop_keyframes) {
      ScopeTimer timer(&result.stats.rotation_tracker_time_s);
      rot_tracker.reset();
      rot_run = 0;
    }
    return;
  }
  if (rot_run < opt.rotation_tracker_start_keyframes) return;
  rot_run = 0;
  ScopeTimer timer(&result.stats.rotation_tracker_time_s);
  rot_tracker = std::make_unique<MosaicPipeline>(opt.rotation_tracker_options, cal);
  ++rot_segment;
  ++result.stats.rotation_tracker_segments;
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
    est->add_tracked_rotation(r);
  });
  // The tracker starts at the run's first keyframe: the gyro from a little before it, the events
  // kept since (the front-end's frames lag the events read).
  const int64_t from = rot_run_start_t - 50'000'000;
  rot_imu_fed_t = std::numeric_limits<int64_t>::min();
  for (const ImuSample& s : imu) {
    if (s.t_ns < from) continue;
    rot_tracker->add_imu(s);
    rot_imu_fed_t = s.t_ns;
  }
  auto first = std::lower_bound(rot_history.begin(), rot_history.end(), rot_run_start_t - shift,
                                [](const Event& e, int64_t t) { return e.t_ns < t; });
  const std::vector<Event> kept(first, rot_history.end());
  rot_history.clear();
  if (!kept.empty()) {
    result.stats.rotation_tracker_events += static_cast<int64_t>(kept.size());
    rot_tracker->add_events(EventSpan(kept.data(), kept.size()));
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
