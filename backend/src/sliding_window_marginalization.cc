// SlidingWindowEstimator's marginalisation of the oldest keyframe (see the estimator's header
// comment): the residuals that touch the oldest keyframe's states and the landmarks that leave with
// it (finished tracks, and still-tracked ones by tracked_landmark_marginalisation: drop, double
// count as in VINS-Mono, restart, or split) are collected into one problem and reduced by the Schur
// complement (marginalize in marginalization.h) to a linear prior on the remaining keyframe states.
#include <algorithm>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "evio/backend/marginalization.h"
#include "evio/backend/pose_manifold.h"
#include "sliding_window_internal.h"

namespace evio::backend {

using internal::make_loss;
using internal::problem_options;

void SlidingWindowEstimator::marginalize_oldest() {
  Keyframe& k0 = *window_.front();
  Keyframe& k1 = *window_[1];
  const Keyframe& newest = *window_.back();
  PoseManifold manifold;
  const auto loss = make_loss(options_.loss, options_.loss_scale);
  ceres::Problem problem(problem_options());
  std::vector<ceres::ResidualBlockId> ids;
  std::vector<const double*> removed = {k0.pose.data(), k0.sb.data()};
  auto add_kf_blocks = [&](Keyframe& k) {
    if (!problem.HasParameterBlock(k.pose.data())) problem.AddParameterBlock(k.pose.data(), 7, &manifold);
    if (!problem.HasParameterBlock(k.sb.data())) problem.AddParameterBlock(k.sb.data(), 9);
  };
  add_kf_blocks(k0);
  add_kf_blocks(k1);
  ids.push_back(problem.AddResidualBlock(k1.imu_error.get(), nullptr, {k0.pose.data(), k0.sb.data(), k1.pose.data(), k1.sb.data()}));
  if (prior_) {
    std::vector<double*> blocks;
    for (const PriorBlock& pb : prior_->blocks()) {
      double* p = const_cast<double*>(pb.parameters);
      if (!problem.HasParameterBlock(p)) {
        if (pb.is_pose) {
          problem.AddParameterBlock(p, 7, &manifold);
        } else {
          problem.AddParameterBlock(p, pb.size);
        }
      }
      blocks.push_back(p);
    }
    ids.push_back(problem.AddResidualBlock(prior_.get(), nullptr, blocks));
  }
  for (auto& [track, cost] : k1.rot) {
    const auto lit = landmarks_.find(track);
    if (lit != landmarks_.end() && lit->second.triangulated) continue;
    ids.push_back(problem.AddResidualBlock(cost.get(), loss.get(), k0.pose.data(), k1.pose.data()));
  }
  if (k1.static_centre) ids.push_back(problem.AddResidualBlock(k1.static_centre.get(), nullptr, k0.pose.data(), k1.pose.data()));
  // Landmarks observed in k0 to marginalise with all their window observations: the finished
  // tracks, and by tracked_landmark_marginalisation the still-tracked ones.
  const TrackedLandmarkMarginalisation mode = options_.tracked_landmark_marginalisation;
  std::vector<int64_t> marginalised_tracks, tracked_tracks;
  for (const auto& [track, b] : k0.obs) {
    (void)b;
    auto lit = landmarks_.find(track);
    if (lit == landmarks_.end() || !lit->second.triangulated) continue;
    if (!newest.obs.count(track)) {
      marginalised_tracks.push_back(track);
    } else if (mode != TrackedLandmarkMarginalisation::kDrop) {
      tracked_tracks.push_back(track);
    }
  }
  // Fixed order (k0.obs is a hash map): the prior then does not depend on the hash order.
  std::sort(marginalised_tracks.begin(), marginalised_tracks.end());
  std::sort(tracked_tracks.begin(), tracked_tracks.end());
  // kSplit: how many of a still-tracked landmark's window observations (oldest first) are
  // marginalised: the older half (rounded up), all of them when that would be a single one.
  auto split_count = [&](int64_t track) {
    int m = 0;
    for (auto& k : window_) m += k->obs.count(track) ? 1 : 0;
    const int older = (m + 1) / 2;
    return older < 2 ? m : older;
  };
  // Adds the landmark and its first `count` window observations (oldest first; all by default).
  auto add_landmark = [&](int64_t track, int count = 1 << 30) {
    Landmark& lm = landmarks_.at(track);
    problem.AddParameterBlock(lm.p.data(), 3);
    removed.push_back(lm.p.data());
    for (auto& k : window_) {
      if (!k->obs.count(track)) continue;
      if (count-- <= 0) break;
      if (options_.estimate_time_offset) {
        const auto it = k->reproj_td.find(track);
        if (it == k->reproj_td.end()) continue;
        add_kf_blocks(*k);
        if (!problem.HasParameterBlock(time_offset_.data())) problem.AddParameterBlock(time_offset_.data(), 1);
        ids.push_back(problem.AddResidualBlock(it->second.get(), loss.get(), k->pose.data(), lm.p.data(), time_offset_.data()));
        continue;
      }
      const auto it = k->reproj.find(track);
      if (it == k->reproj.end()) continue;
      add_kf_blocks(*k);
      ids.push_back(problem.AddResidualBlock(it->second.get(), loss.get(), k->pose.data(), lm.p.data()));
    }
  };
  for (int64_t track : marginalised_tracks) add_landmark(track);
  // A still-tracked landmark is eliminated from the marginalisation problem only: the parameter
  // block stays in landmarks_ (its position is where it continues from, kDoubleCount).
  std::unordered_map<int64_t, int> split;  // kSplit: track -> observations marginalised
  for (int64_t track : tracked_tracks) {
    if (mode == TrackedLandmarkMarginalisation::kSplit) split[track] = split_count(track);
    add_landmark(track, mode == TrackedLandmarkMarginalisation::kSplit ? split.at(track) : 1 << 30);
  }
  std::unordered_set<const double*> poses;
  for (auto& k : window_) poses.insert(k->pose.data());
  prior_ = marginalize(&problem, ids, removed, [&poses](const double* p) { return poses.count(p) > 0; });
  // Forget the marginalised landmarks and close their tracks.
  auto forget = [&](int64_t track) {
    for (auto& k : window_) {
      k->obs.erase(track);
      k->reproj.erase(track);
      k->reproj_td.erase(track);
    }
    landmarks_.erase(track);
  };
  for (int64_t track : marginalised_tracks) {
    forget(track);
    closed_tracks_.insert(track);
    ++stats_.landmarks_marginalised;
  }
  for (int64_t track : tracked_tracks) {
    if (mode == TrackedLandmarkMarginalisation::kRestart) {
      forget(track);  // the track stays open: later observations start a new landmark
    } else if (mode == TrackedLandmarkMarginalisation::kSplit) {
      // The landmark continues from its position with its newer observations only.
      int count = split.at(track);
      for (auto& k : window_) {
        if (!k->obs.count(track)) continue;
        if (count-- <= 0) break;
        k->obs.erase(track);
        k->reproj.erase(track);
        k->reproj_td.erase(track);
      }
    } else {
      k0.obs.erase(track);  // kDoubleCount: the landmark continues with its other observations
    }
    ++stats_.tracked_landmarks_marginalised;
  }
  // What remains of k0's observations (open tracks) is dropped; a landmark is forgotten when fewer
  // than two observations remain.
  stats_.observations_dropped += static_cast<int64_t>(k0.obs.size());
  k1.rot.clear();  // they linked k1 to k0, which is gone
  k1.static_centre.reset();
  window_.pop_front();
  for (auto it = landmarks_.begin(); it != landmarks_.end();) {
    int n = 0;
    for (auto& k : window_) n += k->obs.count(it->first) ? 1 : 0;
    if (n == 0) {
      it = landmarks_.erase(it);
    } else {
      if (n < 2) it->second.triangulated = false;
      ++it;
    }
  }
}

}  // namespace evio::backend
