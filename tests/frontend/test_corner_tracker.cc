// Corner tracker on synthetic corner-event streams with known true positions.
#include <cmath>
#include <map>
#include <random>

#include <gtest/gtest.h>

#include "evio/frontend/corner_tracker.h"

namespace evio::frontend {
namespace {

struct Truth {
  Eigen::Vector2d p0, v;  // px, px/s
  Eigen::Vector2d at(int64_t t_ns) const { return p0 + v * (t_ns * 1e-9); }
};

// Corner events of several moving corners: each fires every `period` ns at its true position
// plus uniform jitter of +-jitter px (rounded to pixels, as corner events are).
std::vector<std::pair<Event, int>> corner_stream(const std::vector<Truth>& truths, int64_t duration, int64_t period,
                                                 double jitter, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-jitter, jitter);
  std::vector<std::pair<Event, int>> out;
  for (int64_t t = 0; t < duration; t += period) {
    for (size_t k = 0; k < truths.size(); ++k) {
      const Eigen::Vector2d p = truths[k].at(t + static_cast<int64_t>(k));
      const int x = static_cast<int>(std::lround(p.x() + u(rng))), y = static_cast<int>(std::lround(p.y() + u(rng)));
      if (x < 0 || y < 0 || x >= 240 || y >= 180) continue;
      out.push_back({{t + static_cast<int64_t>(k), static_cast<uint16_t>(x), static_cast<uint16_t>(y), 1}, static_cast<int>(k)});
    }
  }
  return out;
}

TEST(CornerTracker, FollowsMovingCornersWithSubPixelError) {
  const std::vector<Truth> truths = {{{30, 40}, {200, 50}}, {{200, 150}, {-150, -80}}, {{120, 20}, {0, 120}}};
  const auto stream = corner_stream(truths, 500'000'000, 500'000, 1.0, 1);
  CornerTracker tracker(240, 180);
  std::map<int64_t, std::map<int, int>> votes;  // track id -> truth -> count
  for (const auto& [e, k] : stream) votes[tracker.add(e)][k]++;
  const auto tracks = tracker.finish();
  // One track per corner, each collecting only its corner's events.
  ASSERT_EQ(tracks.size(), 3u);
  for (const auto& tr : tracks) {
    ASSERT_EQ(votes[tr.id].size(), 1u) << "track " << tr.id << " mixes corners";
    const Truth& truth = truths[votes[tr.id].begin()->first];
    double err = 0;
    size_t n = 0;
    for (size_t i = 20; i < tr.points.size(); ++i) {  // after the velocity is established
      err += (Eigen::Vector2d(tr.points[i].x, tr.points[i].y) - truth.at(tr.points[i].t_ns)).norm();
      ++n;
    }
    err /= n;
    std::printf("track %lld: %zu points, mean error %.3f px\n", static_cast<long long>(tr.id), tr.points.size(), err);
    EXPECT_LT(err, 0.6);  // raw corner events scatter by +-1 px (mean |error| ~0.8 px)
  }
}

TEST(CornerTracker, GapEndsATrackAndShortTracksAreNotReported) {
  CornerTrackerOptions o;
  o.max_gap_ns = 10'000'000;
  o.min_length = 3;
  CornerTracker t(240, 180, o);
  const int64_t a = t.add({0, 50, 50, 1});
  EXPECT_EQ(t.add({1'000'000, 51, 50, 1}), a);
  EXPECT_EQ(t.add({2'000'000, 51, 51, 1}), a);
  // 20 ms later at the same place: the old track has ended, a new one starts.
  const int64_t b = t.add({22'000'000, 51, 51, 1});
  EXPECT_NE(b, a);
  t.add({23'000'000, 120, 120, 1});  // a one-event track elsewhere
  const auto done = t.finish();
  ASSERT_EQ(done.size(), 1u);  // a (3 events); b and the lone one are below min_length
  EXPECT_EQ(done[0].id, a);
  EXPECT_EQ(t.stats().tracks_started, 3);
  EXPECT_EQ(t.stats().tracks_reported, 1);
}

// Two corners crossing head-on at 400 px/s each, firing every 0.5 ms with +-1 px jitter. Track
// identity through the crossing: the fraction of each track's events that belong to its corner.
// Two distinct DART-shaped descriptors: corner k's pattern fills wedges 6k..6k+3 of every ring.
DartDescriptor pattern(int k) {
  DartDescriptor d;
  d.rings = 7;
  d.wedges = 12;
  for (int r = 0; r < 7; ++r)
    for (int w = 6 * k; w < 6 * k + 4; ++w) d.bins[static_cast<size_t>(r * 12 + w)] = 1.0f;
  return d;
}

double crossing_purity(bool with_descriptors, int64_t* decisions) {
  const std::vector<Truth> truths = {{{40, 80}, {400, 0}}, {{200, 80}, {-400, 0}}};
  const auto stream = corner_stream(truths, 400'000'000, 500'000, 1.0, 5);
  CornerTrackerOptions o;
  o.min_length = 1;
  CornerTracker t(240, 180, o);
  const DartDescriptor looks[2] = {pattern(0), pattern(1)};  // aligned distance: 0 same, sqrt(2) other
  std::map<int64_t, std::map<int, int>> votes;
  for (size_t i = 0; i < stream.size(); ++i) {
    const int k = stream[i].second;
    votes[t.add(stream[i].first, with_descriptors ? &looks[k] : nullptr)][k]++;
  }
  int majority = 0, total = 0;
  for (const auto& [id, v] : votes) {
    int best = 0;
    for (const auto& [k, c] : v) {
      best = std::max(best, c);
      total += c;
    }
    majority += best;
  }
  *decisions = t.stats().descriptor_decisions;
  return static_cast<double>(majority) / total;
}

TEST(CornerTracker, DescriptorsKeepIdentityThroughACrossing) {
  int64_t with_decisions = 0, without_decisions = 0;
  const double with = crossing_purity(true, &with_decisions);
  const double without = crossing_purity(false, &without_decisions);
  std::printf("crossing: purity %.3f with descriptors (%lld decisions), %.3f without\n", with,
              static_cast<long long>(with_decisions), without);
  EXPECT_EQ(with, 1.0);
  EXPECT_GT(with_decisions, 0);
  EXPECT_EQ(without_decisions, 0);
  EXPECT_LE(without, with);
}

TEST(CornerTracker, DescriptorGateStartsATrackForADifferentLookingCorner) {
  CornerTrackerOptions o;
  o.max_distance_px = 4;
  o.min_length = 1;
  o.max_descriptor_distance = 0.5;
  CornerTracker t(240, 180, o);
  const DartDescriptor p0 = pattern(0), p1 = pattern(1);
  EXPECT_NEAR(dart_distance_aligned(p0, p1), std::sqrt(2.0f), 1e-6);
  const int64_t a = t.add({0, 100, 80, 1}, &p0);
  EXPECT_EQ(t.add({100'000, 101, 80, 1}, &p0), a);  // looks the same: joins
  EXPECT_NE(t.add({200'000, 102, 80, 1}, &p1), a);  // looks different, 2 px away: its own track
  EXPECT_EQ(t.stats().tracks_started, 2);
}

TEST(CornerTracker, RejectsBadOptions) {
  CornerTrackerOptions o;
  o.max_distance_px = 0;
  EXPECT_THROW(CornerTracker(10, 10, o), std::invalid_argument);
  o = {};
  o.position_gain = 1.5;
  EXPECT_THROW(CornerTracker(10, 10, o), std::invalid_argument);
  o = {};
  o.min_velocity_span_ns = o.velocity_window_ns + 1;
  EXPECT_THROW(CornerTracker(10, 10, o), std::invalid_argument);
  EXPECT_THROW(CornerTracker(0, 10), std::invalid_argument);
}

}  // namespace
}  // namespace evio::frontend
