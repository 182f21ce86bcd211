// evaluation::CornerEventScorer: precision, chance, event recall and (corner, bin) recall counted by
// hand on a corner moving at a known speed.
#include "evio/evaluation/corner_evaluation.h"

#include <cmath>
#include <stdexcept>

#include <gtest/gtest.h>

namespace evio::evaluation {
namespace {

Event ev(int64_t t_ns, int x, int y) { return Event{t_ns, static_cast<uint16_t>(x), static_cast<uint16_t>(y), 1}; }

// Corner 0 at (20 + 100 t, 30) px (t in s from 0: 100 px/s); corner 1 is never visible (NaN).
void project(int64_t t_ns, std::vector<Eigen::Vector2d>* px) {
  px->assign(2, Eigen::Vector2d::Constant(NAN));
  (*px)[0] = Eigen::Vector2d(20 + 100 * (t_ns * 1e-9), 30);
}

TEST(CornerEvaluation, HandCountedMetrics) {
  // 64 x 48 px, 0.2 s: four 50 ms bins; the corner moves from x 20 to 40, always >= 4 px inside.
  CornerEventScorer s(64, 48, 2, {true, false}, project, 0, 200'000'000);
  // Bin 0 (t 10 ms, corner at x 21): a flagged event 1 px away (TP), an unflagged one 2 px away
  // (near), a flagged one 10 px away (FP), an unflagged far one.
  s.add(ev(10'000'000, 22, 30), true);
  s.add(ev(10'000'000, 21, 32), false);
  s.add(ev(10'000'000, 31, 30), true);
  s.add(ev(10'000'000, 5, 5), false);
  // Bin 2 (t 120 ms, corner at x 32): a flagged event exactly on it (TP).
  s.add(ev(120'000'000, 32, 30), true);
  // Bin 3 (t 160 ms, corner at x 36): a flagged event 3 px away (FP: radius 2 px).
  s.add(ev(160'000'000, 36, 33), true);
  const CornerMetrics m = s.finish();
  EXPECT_EQ(m.events, 6);
  EXPECT_EQ(m.corner_events, 4);
  EXPECT_EQ(m.true_positives, 2);
  EXPECT_DOUBLE_EQ(m.precision(), 0.5);
  EXPECT_EQ(m.near_events, 3);  // the two TPs and the unflagged event 2 px away
  EXPECT_EQ(m.near_events_flagged, 2);
  EXPECT_DOUBLE_EQ(m.chance(), 0.5);
  EXPECT_DOUBLE_EQ(m.event_recall(), 2.0 / 3.0);
  // Four (corner 0, bin) pairs, hits in bins 0 and 2; corner 1 is never visible.
  EXPECT_EQ(m.pairs, 4);
  EXPECT_EQ(m.pairs_hit, 2);
  EXPECT_EQ(m.inner_pairs, 4);
  EXPECT_EQ(m.inner_pairs_hit, 2);
  EXPECT_DOUBLE_EQ(m.pair_recall(), 0.5);
  EXPECT_DOUBLE_EQ(m.f_score(), 0.5);
  EXPECT_DOUBLE_EQ(m.reduction(), 1.5);
}

TEST(CornerEvaluation, SlowAndBorderCornersAreNotPairs) {
  // A still corner (0 px/s < 20 px/s) gives no (corner, bin) pair; nor does one 3 px from the border.
  auto still = [](int64_t, std::vector<Eigen::Vector2d>* px) { px->assign(1, Eigen::Vector2d(30, 30)); };
  CornerEventScorer a(64, 48, 1, {}, still, 0, 100'000'000);
  a.add(ev(1'000'000, 30, 30), true);
  EXPECT_EQ(a.finish().pairs, 0);
  EXPECT_EQ(a.finish().true_positives, 1);
  auto border = [](int64_t t, std::vector<Eigen::Vector2d>* px) { px->assign(1, Eigen::Vector2d(20 + 100 * (t * 1e-9), 3)); };
  CornerEventScorer b(64, 48, 1, {}, border, 0, 100'000'000);
  EXPECT_EQ(b.finish().pairs, 0);
  CornerScoringOptions o;
  o.border_px = 2;
  CornerEventScorer c(64, 48, 1, {}, border, 0, 100'000'000, o);
  EXPECT_EQ(c.finish().pairs, 2);
  EXPECT_EQ(c.finish().inner_pairs, 0);  // no inner flags given
}

TEST(CornerEvaluation, RejectsBadArguments) {
  CornerScoringOptions o;
  o.match_radius_px = 0;
  EXPECT_THROW(CornerEventScorer(64, 48, 2, {}, project, 0, 1, o), std::invalid_argument);
  EXPECT_THROW(CornerEventScorer(64, 48, 2, {true}, project, 0, 1), std::invalid_argument);
  EXPECT_THROW(CornerEventScorer(64, 48, 2, {}, CornerProjector(), 0, 1), std::invalid_argument);
  CornerEventScorer wrong_count(64, 48, 3, {}, project, 0, 1);  // the projector gives 2
  EXPECT_THROW(wrong_count.add(ev(0, 1, 1), false), std::invalid_argument);
}

}  // namespace
}  // namespace evio::evaluation
