// Corner tracks against simulator ground truth (the checkerboard sequence of
// corner_ground_truth.h): each reported track is assigned to the true corner that most of its
// points lie within 3 px of; reported are the track accuracy (mean pixel error of the smoothed
// track positions against that corner's projection at each point's time), purity (share of
// points nearest to the assigned corner), and mean track length and duration.
#include <cstdio>
#include <map>

#include <gtest/gtest.h>

#include "corner_ground_truth.h"
#include "evio/frontend/corner_tracker.h"
#include "evio/frontend/dart.h"
#include "evio/frontend/efast.h"

namespace evio::frontend {
namespace {
using evio::test::CornerGroundTruthSequence;

struct TrackScore {
  size_t tracks = 0, points = 0, assigned_points = 0, correct_points = 0;
  double mean_error_px = 0, raw_mean_error_px = 0, mean_length = 0, mean_duration_s = 0;
};

TrackScore score_tracks(const CornerGroundTruthSequence& seq, const std::vector<CornerTrack>& tracks) {
  TrackScore s;
  s.tracks = tracks.size();
  double err = 0, raw_err = 0, dur = 0;
  std::vector<Eigen::Vector2d> px;
  std::vector<int> ids;
  for (const CornerTrack& t : tracks) {
    std::map<int, int> votes;
    std::vector<int> nearest(t.points.size(), -1);
    for (size_t i = 0; i < t.points.size(); ++i) {
      seq.true_corners_at(t.points[i].t_ns, 3.0, &px, &ids);
      double best = 3.0;
      for (size_t k = 0; k < px.size(); ++k) {
        const double d = (px[k] - Eigen::Vector2d(t.points[i].x, t.points[i].y)).norm();
        if (d < best) {
          best = d;
          nearest[i] = ids[k];
        }
      }
      if (nearest[i] >= 0) votes[nearest[i]]++;
    }
    s.points += t.points.size();
    s.mean_length += static_cast<double>(t.points.size());
    dur += static_cast<double>(t.t_end_ns() - t.t_begin_ns()) * 1e-9;
    if (votes.empty()) continue;
    int id = -1, most = 0;
    for (const auto& [k, c] : votes) {
      if (c > most) {
        most = c;
        id = k;
      }
    }
    for (size_t i = 0; i < t.points.size(); ++i) {
      Eigen::Vector2d truth;
      if (!seq.project_corner(id, t.points[i].t_ns, &truth)) continue;
      ++s.assigned_points;
      s.correct_points += nearest[i] == id;
      err += (truth - Eigen::Vector2d(t.points[i].x, t.points[i].y)).norm();
      raw_err += (truth - Eigen::Vector2d(t.points[i].raw_x, t.points[i].raw_y)).norm();
    }
  }
  if (s.assigned_points > 0) {
    s.mean_error_px = err / s.assigned_points;
    s.raw_mean_error_px = raw_err / s.assigned_points;
  }
  if (s.tracks > 0) {
    s.mean_length /= s.tracks;
    s.mean_duration_s = dur / s.tracks;
  }
  return s;
}

struct TrackRun {
  TrackScore score;
  CornerTrackerStats stats;
};

TrackRun run_tracker(const CornerGroundTruthSequence& seq, bool dart) {
  EfastDetector det(seq.width(), seq.height());
  CornerTracker tracker(seq.width(), seq.height());
  const DartExtractor extractor{DartOptions{}};
  DartDescriptor d;
  for (const Event& e : seq.events()) {
    if (!det.process(e)) continue;
    const bool has = dart && extractor.compute(det.sae(), e.x, e.y, e.t_ns, e.polarity, &d);
    tracker.add(e, has ? &d : nullptr);
  }
  const std::vector<CornerTrack> tracks = tracker.finish();
  return {score_tracks(seq, tracks), tracker.stats()};
}

TEST(CornerTracksSimulated, AccuracyAndLengthAgainstProjectedCorners) {
  const CornerGroundTruthSequence seq;
  const TrackRun plain = run_tracker(seq, false);
  const TrackRun with_dart = run_tracker(seq, true);
  std::printf("with DART: tracks %zu, purity %.3f, error %.3f px, mean duration %.3f s, %lld descriptor decisions\n",
              with_dart.score.tracks,
              static_cast<double>(with_dart.score.correct_points) / std::max<size_t>(1, with_dart.score.assigned_points),
              with_dart.score.mean_error_px, with_dart.score.mean_duration_s,
              static_cast<long long>(with_dart.stats.descriptor_decisions));
  EXPECT_GT(with_dart.stats.descriptor_decisions, 0);
  EXPECT_GE(static_cast<double>(with_dart.score.correct_points) / with_dart.score.assigned_points,
            static_cast<double>(plain.score.correct_points) / plain.score.assigned_points - 0.01);
  const TrackScore& s = plain.score;
  const CornerTrackerStats& st = plain.stats;
  std::printf("%s\n", seq.describe().c_str());
  std::printf("tracks %zu (of %lld started), points %zu, assigned %zu, purity %.3f\n", s.tracks,
              static_cast<long long>(st.tracks_started), s.points, s.assigned_points,
              static_cast<double>(s.correct_points) / std::max<size_t>(1, s.assigned_points));
  std::printf("track error %.3f px (raw corner events %.3f px), mean length %.1f corner events, mean duration %.3f s\n",
              s.mean_error_px, s.raw_mean_error_px, s.mean_length, s.mean_duration_s);
  // 30 true corners over 1.5 s: tracks exist, last, and stay on their corner.
  EXPECT_GT(s.tracks, 30u);
  EXPECT_GT(static_cast<double>(s.assigned_points), 0.8 * static_cast<double>(s.points));
  EXPECT_GT(static_cast<double>(s.correct_points), 0.9 * static_cast<double>(s.assigned_points));
  EXPECT_LT(s.mean_error_px, 1.5);
  EXPECT_LT(s.mean_error_px, s.raw_mean_error_px);  // smoothing beats the raw corner events
  EXPECT_GT(s.mean_duration_s, 0.05);
}

}  // namespace
}  // namespace evio::frontend
