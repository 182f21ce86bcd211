// SlidingWindowEstimator's rotation-tracker factors (see the tracker_* options in
// sliding_window_estimator.h): a rotation tracker's orientations against its panorama, attached
// to the rotation-only keyframes they bracket, and one RelativeRotationError per keyframe to its
// segment's anchor keyframe.
#include <algorithm>
#include <cmath>
#include <iterator>
#include <stdexcept>

#include "evio/backend/motion_model_selection.h"
#include "sliding_window_internal.h"

namespace evio::backend {

using internal::quat_of;

namespace {
constexpr double kDeg = 180.0 / M_PI;
}  // namespace

void SlidingWindowEstimator::add_tracked_rotation(const TrackedRotation& r) {
  if (!r.q_m_c.coeffs().allFinite() || !r.cov_c.allFinite() || !(r.q_m_c.norm() > 0))
    throw std::invalid_argument("add_tracked_rotation: the orientation and its covariance must be finite");
  if (!tracked_.empty() && r.t_ns <= tracked_.back().t_ns) return;  // time order: later samples only
  TrackedRotation s = r;
  s.q_m_c.normalize();
  tracked_.push_back(s);
  ++stats_.tracker_samples;
}

void SlidingWindowEstimator::attach_tracked_rotations() {
  if (tracked_.empty()) return;
  const int64_t max_gap = static_cast<int64_t>(options_.tracker_max_gap_s * 1e9);
  const double floor_var = std::pow(options_.tracker_min_sigma_deg / kDeg, 2);
  const Eigen::Matrix3d R_b_c = camera_.T_c_b.rotation.conjugate().toRotationMatrix();
  const double jump_limit = chi2_upper_quantile(3, options_.tracker_reject_p);
  // Segments whose orientations begin before the window: anchored at the earliest marginalised
  // keyframe they cover.
  if (tracked_.front().t_ns < window_.front()->t_ns) {
    const auto first = std::lower_bound(past_keyframes_.begin(), past_keyframes_.end(), tracked_.front().t_ns,
                                        [](const auto& p, int64_t t) { return p.first < t; });
    for (auto it = first; it != past_keyframes_.end(); ++it) {
      TrackedRotation r;
      if (!tracked_rotation_at(tracked_.begin(), tracked_.end(), it->first, max_gap, &r) || tracker_segments_.count(r.segment)) continue;
      const int64_t id = next_tracker_anchor_++;
      tracker_segments_[r.segment] = id;
      TrackerAnchor& anchor = tracker_anchors_[id];
      anchor.t_ns = it->first;
      anchor.q_m_c = r.q_m_c;
      anchor.cov_c = r.cov_c;
      anchor.pose = it->second;
      ++stats_.tracker_anchors;
    }
  }
  for (auto& kp : window_) {
    Keyframe& k = *kp;
    if (!k.tracker_eligible || k.tracked || k.tracker_tried) continue;
    if (tracked_.back().t_ns < k.t_ns) break;  // the tracker has not reached it (nor any later keyframe)
    k.tracker_tried = true;
    TrackedRotation r;
    if (!tracked_rotation_at(tracked_.begin(), tracked_.end(), k.t_ns, max_gap, &r)) continue;
    const int64_t segment = r.segment;
    k.tracker_q_m_c = r.q_m_c;
    k.tracker_cov_c = r.cov_c;
    k.tracked = true;
    // The tracker's segment as the estimator runs it: a registration jump starts a new one.
    auto [seg, fresh_segment] = tracker_segments_.try_emplace(segment, 0);
    if (fresh_segment) seg->second = next_tracker_anchor_++;
    SlidingWindowStats::TrackerFactor f;
    f.t_ns = k.t_ns;
    f.segment = segment;
    TrackerAnchor* anchor = nullptr;
    if (!fresh_segment) {
      anchor = &tracker_anchors_.at(seg->second);
      // Jump test: the tracker's rotation since the segment's previous keyframe against the
      // estimate's (the gyro's, between neighbouring keyframes), under both orientations' spreads,
      // the floor twice and the gyro's noise over the interval.
      if (anchor->last) {
        const Keyframe& j = *anchor->last;
        const Eigen::Matrix3d d_trk = (anchor->last_q.conjugate() * k.tracker_q_m_c).toRotationMatrix();
        const Eigen::Matrix3d d_est = (quat_of(j.pose).toRotationMatrix() * R_b_c).transpose() * quat_of(k.pose).toRotationMatrix() * R_b_c;
        const Eigen::Vector3d e = calib::so3_log(Eigen::Matrix3d(d_trk.transpose() * d_est));
        const double dt = 1e-9 * static_cast<double>(k.t_ns - j.t_ns);
        const Eigen::Matrix3d cov = d_trk.transpose() * anchor->last_cov * d_trk + k.tracker_cov_c +
                                    (2 * floor_var + std::pow(noise_.gyroscope_noise_density, 2) * dt) * Eigen::Matrix3d::Identity();
        if (e.dot(cov.ldlt().solve(e)) > jump_limit) {
          f.dropped = true;
          f.error_deg = e.norm() * kDeg;
          seg->second = next_tracker_anchor_++;
          anchor = nullptr;
        }
      }
    }
    k.tracker_anchor_id = seg->second;
    if (!anchor) {  // k anchors the (new) segment
      TrackerAnchor& fresh = tracker_anchors_[seg->second];
      fresh.t_ns = k.t_ns;
      fresh.q_m_c = k.tracker_q_m_c;
      fresh.cov_c = k.tracker_cov_c;
      fresh.kf = &k;
      fresh.last = &k;
      fresh.last_q = k.tracker_q_m_c;
      fresh.last_cov = k.tracker_cov_c;
      ++stats_.tracker_anchors;
      if (f.dropped) {  // the rejected measurement, reported
        f.anchor_t_ns = k.t_ns;
        stats_.tracker_factors.push_back(f);
      }
      continue;
    }
    anchor->last = &k;
    anchor->last_q = k.tracker_q_m_c;
    anchor->last_cov = k.tracker_cov_c;
    // The camera's rotation from the anchor to k and its covariance (camera k tangent): both
    // orientations' errors, the anchor's carried over by the relative rotation, plus the floor.
    const Eigen::Quaterniond d = anchor->q_m_c.conjugate() * k.tracker_q_m_c;
    const Eigen::Matrix3d D = d.toRotationMatrix();
    Eigen::Matrix3d cov = D.transpose() * anchor->cov_c * D + k.tracker_cov_c;
    cov = 0.5 * (cov + cov.transpose()) + floor_var * Eigen::Matrix3d::Identity();
    k.tracker_factor = std::make_unique<RelativeRotationError>(d, cov, camera_.T_c_b);
    if (!k.rotation_only && !k.static_centre && options_.tracker_centre_px > 0 && last_median_depth_m_ > 0 && &k != window_.front().get()) {
      k.static_centre = std::make_unique<StaticCentreError>(camera_.T_c_b, options_.tracker_centre_px * last_median_depth_m_ / focal_px_);
    }
    f.anchor_t_ns = anchor->t_ns;
    f.measured = d;
    f.sigma_deg = std::sqrt(Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(cov).eigenvalues().maxCoeff()) * kDeg;
    k.tracker_stat = static_cast<int>(stats_.tracker_factors.size());
    stats_.tracker_factors.push_back(f);
  }
  // Samples before the oldest keyframe (one kept for bracketing) serve no keyframe any more.
  const int64_t oldest = window_.front()->t_ns;
  while (tracked_.size() > 1 && tracked_[1].t_ns <= oldest) tracked_.pop_front();
}

void SlidingWindowEstimator::review_tracker_factors() {
  for (auto& kp : window_) {
    Keyframe& k = *kp;
    if (!k.tracker_factor || k.tracker_stat < 0) continue;
    SlidingWindowStats::TrackerFactor& f = stats_.tracker_factors[static_cast<size_t>(k.tracker_stat)];
    const TrackerAnchor& anchor = tracker_anchors_.at(k.tracker_anchor_id);
    const double* pa = anchor.kf ? anchor.kf->pose.data() : anchor.pose.data();
    const double* params[2] = {pa, k.pose.data()};
    Eigen::Vector3d r;
    if (!k.tracker_factor->Evaluate(params, r.data(), nullptr)) continue;
    f.chi2 = r.squaredNorm();
    f.error_deg = k.tracker_factor->error(pa, k.pose.data()).norm() * kDeg;
  }
}

}  // namespace evio::backend
