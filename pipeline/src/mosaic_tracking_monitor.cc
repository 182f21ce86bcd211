// MosaicPipeline's tracking monitor: decides from the particle filter's probe contrast (the
// cloud's log-likelihood per event against six rotations off its mean) whether the tracker is lost
// or has recovered, per failure window, and acts while lost: spreads the particles, optionally
// searches the whole mosaic for the view (mapping::RelocalizationMap) and rolls the map back to a
// checkpoint. The thresholds and their meaning are in MosaicPipelineOptions (failure_*).
#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "evio/calib/geometry.h"
#include "evio/calib/log.h"
#include "evio/mapping/contrast_maximization.h"
#include "evio/mapping/rotation_relocalization.h"
#include "mosaic_pipeline_impl.h"

namespace evio::pipeline {

// Collects the tracker's probe contrast; at the end of each failure window decides lost /
// recovered and re-localises while lost.
void MosaicPipeline::Impl::watch_quality(int64_t t_now, size_t batch_events) {
  if (opt.tracker.probe_every_batches <= 0) return;
  window_all_events += static_cast<int64_t>(batch_events);
  if (window_t0 == INT64_MIN) window_t0 = t_now;
  if (pf->last_probe_t_ns() != probe_seen_t && std::isfinite(pf->last_probe_contrast())) {
    probe_seen_t = pf->last_probe_t_ns();
    window_sum += pf->last_probe_contrast();
    window_events += pf->last_batch_loglik_events();
    ++window_n;
  }
  if (t_now - window_t0 < opt.failure_window_ns) return;
  // Event rate against its running mean (exponential, about 20 windows): a near-still moment.
  const double rate = static_cast<double>(window_all_events);
  const bool moving = rate_mean <= 0 || rate >= opt.failure_min_rate_ratio * rate_mean;
  rate_mean = rate_mean <= 0 ? rate : 0.95 * rate_mean + 0.05 * rate;
  window_all_events = 0;
  if (window_n > 0 && window_events >= opt.failure_min_events && moving) {
    const double q = window_sum / static_cast<double>(window_n);
    MosaicStats& st = result.stats;
    st.quality_min = st.quality_windows == 0 ? q : std::min(st.quality_min, q);
    quality_sum += q;
    ++st.quality_windows;
    st.quality_mean = quality_sum / static_cast<double>(st.quality_windows);
    low_windows = q < opt.failure_lost_contrast ? low_windows + 1 : 0;
    if (low_windows == 1) low_since = window_t0;
    if (!lost && low_windows >= opt.failure_lost_windows) {
      lost = true;
      result.tracking_lost.push_back({low_since, t_now, false, 0});
      log_warning("MosaicPipeline: tracking lost at " + std::to_string(1e-9 * static_cast<double>(low_since)) +
                  " s (probe contrast " + std::to_string(q) + " per event)");
      if (opt.failure_rollback) rollback_map(low_since - opt.failure_window_ns, t_now);
    } else if (lost && q >= opt.failure_recovered_contrast) {
      lost = false;
      result.tracking_lost.back().t_end_ns = t_now;
      result.tracking_lost.back().recovered = true;
    }
    if (lost) {
      result.tracking_lost.back().t_end_ns = t_now;
      const bool jumped = !opt.use_gyro && opt.failure_global_relocalize && global_relocalize(t_now);
      if (!jumped && opt.failure_relocalize_spread_rad > 0 && !opt.use_gyro) relocalize();
    }
  } else if (window_n > 0) {
    ++result.stats.quality_windows_undecided;
    if (lost) result.tracking_lost.back().t_end_ns = t_now;
  }
  window_sum = 0;
  window_events = 0;
  window_n = 0;
  window_t0 = t_now;
}

// Spreads the particles around the mean (Gaussian, failure_relocalize_spread_rad per axis),
// equal weights; their velocities stay.
void MosaicPipeline::Impl::relocalize() {
  std::normal_distribution<double> g(0.0, opt.failure_relocalize_spread_rad);
  const Eigen::Quaterniond m = pf->mean();
  std::vector<Eigen::Quaterniond> p(pf->particles().size());
  for (size_t i = 0; i < p.size(); ++i) {
    const Eigen::Vector3d d(g(relocalize_rng), g(relocalize_rng), g(relocalize_rng));
    p[i] = i == 0 ? m : (m * calib::so3_exp_quat(d)).normalized();
  }
  pf->set_particles(p, std::vector<double>(p.size(), 1.0));
  ++result.tracking_lost.back().relocalizations;
}

// Rolls the mosaic back to the newest checkpoint at or before t_bound and gives the tracker a
// full reconstruction of it.
void MosaicPipeline::Impl::rollback_map(int64_t t_bound, int64_t t_now) {
  while (!cp_times.empty() && cp_times.back() > t_bound) cp_times.pop_back();
  if (cp_times.empty()) return;
  result.tracking_lost.back().map_rolled_back_to_ns = cp_times.back();
  block.steps.push_back({MapperBlock::Kind::kRestore, block.events.size(), Eigen::Matrix3d::Identity(),
                         Eigen::Vector3d::Zero(), t_bound, mapping::GradientMosaic::ReconstructMode::kAuto, 0});
  if (recs_in_use < recs_submitted) use_reconstruction();  // one reconstruction in flight at most
  block.steps.push_back({MapperBlock::Kind::kReconstruct, block.events.size(), Eigen::Matrix3d::Identity(),
                         Eigen::Vector3d::Zero(), 0, mapping::GradientMosaic::ReconstructMode::kFull, 1 - front});
  ++result.stats.reconstructions;
  queue.submit(&block);
  ++recs_submitted;
  rec_point = processed;
  rec_t = t_now;
  use_reconstruction();
}

void MosaicPipeline::Impl::remember(const Event* ev, size_t n) {
  const size_t cap = static_cast<size_t>(opt.bootstrap_window_events);
  if (recent.size() < cap) {
    const size_t k = std::min(n, cap - recent.size());
    recent.insert(recent.end(), ev, ev + k);
    ev += k;
    n -= k;
    recent_next = recent.size() % cap;
  }
  for (size_t k = 0; k < n; ++k) {
    recent[recent_next] = ev[k];
    recent_next = (recent_next + 1) % cap;
  }
}

// Searches the whole known mosaic for the view of the most recent events (see
// failure_global_relocalize); true when the particles were moved there.
bool MosaicPipeline::Impl::global_relocalize(int64_t t_now) {
  if (last_global_t != INT64_MIN && t_now - last_global_t < opt.failure_global_period_ns) return false;
  last_global_t = t_now;
  MosaicLostSegment& seg = result.tracking_lost.back();
  ++seg.global_searches;
  // The window: the ring in time order, the events within bootstrap_window_ns of the newest.
  std::vector<Event> win;
  const size_t n = recent.size();
  for (size_t k = 0; k < n; ++k) win.push_back(recent[(recent_next + k) % n]);
  if (win.empty()) return false;
  const int64_t t_ref = win.back().t_ns;
  std::vector<Eigen::Vector3f> b;
  std::vector<int64_t> t;
  for (const Event& e : win) {
    if (t_ref - e.t_ns > opt.bootstrap_window_ns) continue;
    if (e.x >= W || e.y >= H || !undistorter.valid(e.x, e.y)) continue;
    b.push_back(undistorter.bearing(e.x, e.y));
    t.push_back(e.t_ns);
  }
  if (b.size() < 100) return false;
  const Eigen::Vector3d w = mapping::estimate_angular_velocity(b, t, t_ref, pf->angular_velocity_c(), cmax).omega_c;
  for (size_t k = 0; k < b.size(); ++k)
    b[k] = (calib::so3_exp(w * (1e-9 * static_cast<double>(t[k] - t_ref))).cast<float>() * b[k]).eval();
  const mapping::RelocalizationMap rmap(view.data, opt.mosaic.width, opt.mosaic.height, opt.relocalization);
  const mapping::RotationRelocalizationResult r = rmap.search(b);
  if (!r.valid) return false;
  // The estimate at t_ref (the filter is at t_now >= t_ref, within one batch).
  const double current = rmap.score(pf->mean().toRotationMatrix(), b);
  if (!(r.score > opt.failure_global_min_gain * current)) return false;
  pf->reset(Eigen::Quaterniond(r.R_w_c), pf->time_ns());
  pf->set_velocity(w);
  ++seg.global_jumps;
  return true;
}

}  // namespace evio::pipeline
