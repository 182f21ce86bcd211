#include "evio/sensors/event_buffer.h"

#include <random>

#include <gtest/gtest.h>

namespace evio {
namespace {

EventBuffer make_events(int n, int64_t t0, int64_t step, int repeat = 1) {
  EventBuffer b;
  for (int i = 0; i < n; ++i) {
    Event e;
    e.t_ns = t0 + (i / repeat) * step;
    e.x = static_cast<uint16_t>(i % 240);
    e.y = static_cast<uint16_t>(i % 180);
    e.polarity = static_cast<int8_t>(i % 3 == 0 ? 1 : -1);
    b.push_back(e);
  }
  return b;
}

TEST(EventBuffer, SliceIsHalfOpenAndMatchesLinearScan) {
  const EventBuffer b = make_events(1000, 1700000000000000000LL, 1000, 3);  // repeated stamps, large times
  ASSERT_TRUE(b.is_time_sorted());
  std::mt19937 rng(7);
  std::uniform_int_distribution<int64_t> ut(b.front().t_ns - 5000, b.back().t_ns + 5000);
  for (int k = 0; k < 200; ++k) {
    int64_t t0 = ut(rng), t1 = ut(rng);
    if (k % 10 == 0) t0 = b[k].t_ns;  // exactly on a stamp
    const EventSpan s = b.slice(t0, t1);
    size_t expected = 0;
    for (const Event& e : b) expected += (e.t_ns >= t0 && e.t_ns < t1);
    ASSERT_EQ(s.size(), expected) << t0 << " " << t1;
    for (const Event& e : s) {
      ASSERT_GE(e.t_ns, t0);
      ASSERT_LT(e.t_ns, t1);
    }
  }
}

TEST(EventBuffer, EmptyAndDegenerateSlices) {
  const EventBuffer empty;
  EXPECT_TRUE(empty.slice(0, 100).empty());
  EXPECT_TRUE(empty.is_time_sorted());
  const EventBuffer b = make_events(10, 0, 10);
  EXPECT_TRUE(b.slice(50, 50).empty());
  EXPECT_TRUE(b.slice(60, 20).empty());
  EXPECT_EQ(b.slice(INT64_MIN, INT64_MAX).size(), 10u);
  EXPECT_EQ(b.span().subspan(8, 100).size(), 2u);
  EXPECT_TRUE(b.span().subspan(20, 1).empty());
}

TEST(EventBuffer, DetectsUnsortedBuffers) {
  EventBuffer b = make_events(10, 0, 10);
  b.events()[5].t_ns = 1;
  EXPECT_FALSE(b.is_time_sorted());
}

TEST(EventStatistics, CountsAcrossChunks) {
  const EventBuffer b = make_events(999, 1000, 1000);
  EventStatistics whole, chunked;
  whole.add(b.span());
  for (size_t i = 0; i < b.size(); i += 100) chunked.add(b.span().subspan(i, 100));
  EXPECT_EQ(whole.count, 999);
  EXPECT_EQ(whole.on, 333);
  EXPECT_EQ(whole.off, 666);
  EXPECT_EQ(whole.t_first_ns, 1000);
  EXPECT_EQ(whole.t_last_ns, 999000);
  EXPECT_EQ(whole.max_x, 239);
  EXPECT_EQ(whole.max_y, 179);
  EXPECT_NEAR(whole.rate_hz(), 999 / 998e-6, 1e-6);
  EXPECT_EQ(chunked.count, whole.count);
  EXPECT_EQ(chunked.on, whole.on);
  EXPECT_EQ(chunked.t_first_ns, whole.t_first_ns);
  EXPECT_EQ(chunked.t_last_ns, whole.t_last_ns);
  EventStatistics none;
  EXPECT_EQ(none.rate_hz(), 0.0);
  EXPECT_EQ(none.on_fraction(), 0.0);
}

}  // namespace
}  // namespace evio
