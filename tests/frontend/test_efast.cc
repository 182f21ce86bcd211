// eFAST: arc tests on constructed circles (every arc length at every rotation, ties, gaps),
// detector behaviour at borders, per polarity and on non-240x180 sensors, and event-for-event
// agreement with an exhaustive implementation of the published definition (the authors'
// FastDetector semantics: SAE in seconds initialised to 0, updated with every event) on random
// streams, on a dense synthetic moving-corner stream and on the real ECD slice.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "evio/frontend/efast.h"
#include "evio/sensors/ecd.h"
#include "evio_test/real_data.h"

namespace evio::frontend {
namespace {

// --------------------------------------------------------------- reference (exhaustive scan)
// Written from the definition: for every start i and arc length s, the arc is accepted when its
// oldest time is strictly newer than every other pixel of the circle.
template <size_t N>
bool reference_arc(const std::array<double, N>& t, int min_len, int max_len) {
  for (size_t i = 0; i < N; ++i) {
    for (int s = min_len; s <= max_len; ++s) {
      double arc_min = t[i];
      for (int j = 1; j < s; ++j) arc_min = std::min(arc_min, t[(i + j) % N]);
      bool ok = true;
      for (size_t j = s; j < N && ok; ++j) ok = t[(i + j) % N] < arc_min;
      if (ok) return true;
    }
  }
  return false;
}

class ReferenceFast {
 public:
  ReferenceFast(int w, int h) : w_(w), h_(h), sae_{std::vector<double>(w * h, 0.0), std::vector<double>(w * h, 0.0)} {}
  bool is_feature(const Event& e) {
    auto& s = sae_[e.polarity > 0 ? 1 : 0];
    s[e.y * w_ + e.x] = e.t_ns * 1e-9;
    if (e.x < 4 || e.x >= w_ - 4 || e.y < 4 || e.y >= h_ - 4) return false;
    std::array<double, 16> c3;
    for (int i = 0; i < 16; ++i) c3[i] = s[(e.y + kEfastCircle3[i][1]) * w_ + e.x + kEfastCircle3[i][0]];
    if (!reference_arc(c3, 3, 6)) return false;
    std::array<double, 20> c4;
    for (int i = 0; i < 20; ++i) c4[i] = s[(e.y + kEfastCircle4[i][1]) * w_ + e.x + kEfastCircle4[i][0]];
    return reference_arc(c4, 4, 8);
  }

 private:
  int w_, h_;
  std::vector<double> sae_[2];
};

// --------------------------------------------------------------- circles
TEST(EfastCircles, AreTheBresenhamCirclesOfRadius3And4InOrder) {
  const auto check = [](const auto& circle, int r) {
    for (size_t i = 0; i < circle.size(); ++i) {
      const auto& a = circle[i];
      const auto& b = circle[(i + 1) % circle.size()];
      // On the circle (max-norm r, or the diagonal pixels of the digital circle) ...
      const double d = std::hypot(a[0], a[1]);
      EXPECT_NEAR(d, r, 0.71) << i;
      // ... and consecutive pixels are 8-neighbours.
      EXPECT_LE(std::max(std::abs(a[0] - b[0]), std::abs(a[1] - b[1])), 1) << i;
      for (size_t j = 0; j < i; ++j) EXPECT_FALSE(circle[j] == a) << "duplicate " << i;
    }
  };
  check(kEfastCircle3, 3);
  check(kEfastCircle4, 4);
}

// Circle of N times: an arc of `len` pixels starting at `start` at time `arc_t`, every other
// pixel at the older `rest_t`. (Varying times inside the arc or the rest would create other
// valid arcs, e.g. the newest 3 of a longer arc; the exhaustive comparison below covers those.)
template <size_t N>
std::array<int64_t, N> circle_with_arc(int start, int len, int64_t arc_t = 1000, int64_t rest_t = 500) {
  std::array<int64_t, N> t;
  t.fill(rest_t);
  for (int j = 0; j < len; ++j) t[(start + j) % N] = arc_t;
  return t;
}

TEST(EfastArcTest, InnerCircleAcceptsArcsOf3To6AtEveryRotation) {
  for (int len = 1; len <= 15; ++len) {
    for (int start = 0; start < 16; ++start) {
      const auto t = circle_with_arc<16>(start, len);
      EXPECT_EQ(efast_arc_test_16(t.data()), len >= 3 && len <= 6) << "len " << len << " start " << start;
    }
  }
}

TEST(EfastArcTest, OuterCircleAcceptsArcsOf4To8AtEveryRotation) {
  for (int len = 1; len <= 19; ++len) {
    for (int start = 0; start < 20; ++start) {
      const auto t = circle_with_arc<20>(start, len);
      EXPECT_EQ(efast_arc_test_20(t.data()), len >= 4 && len <= 8) << "len " << len << " start " << start;
    }
  }
}

TEST(EfastArcTest, OneNewerPixelOutsideTheArcOrATieAcrossItsBoundaryRejects) {
  for (int start = 0; start < 16; ++start) {
    for (int len = 3; len <= 6; ++len) {
      for (int k = 0; k < 16 - len; ++k) {
        const int outside = (start + len + k) % 16;
        auto t = circle_with_arc<16>(start, len);
        // Newer than the arc's oldest pixel: no arc of this set is valid.
        t[outside] = 1000 + 10;
        // Unless the newer pixel is adjacent to the arc and the longer arc is still short enough.
        const bool adjacent = k == 0 || k == 16 - len - 1;
        EXPECT_EQ(efast_arc_test_16(t.data()), adjacent && len + 1 <= 6) << start << " " << len << " " << k;
        // Equal to the arc's oldest pixel (a tie across the boundary): never strictly newer.
        auto u = circle_with_arc<16>(start, len, 1000, 500);
        for (int j = 0; j < len; ++j) u[(start + j) % 16] = 1000;
        u[outside] = 1000;
        EXPECT_EQ(efast_arc_test_16(u.data()), adjacent && len + 1 <= 6) << start << " " << len << " " << k;
      }
    }
  }
}

TEST(EfastArcTest, TiesInsideTheArcAndAllEqualCircles) {
  std::array<int64_t, 16> t;
  t.fill(0);
  EXPECT_FALSE(efast_arc_test_16(t.data()));  // a fresh SAE: nothing is newer than anything
  t.fill(kNeverNs);
  EXPECT_FALSE(efast_arc_test_16(t.data()));
  for (int j = 0; j < 4; ++j) t[(14 + j) % 16] = 42;  // arc wrapping over index 0, all equal
  EXPECT_TRUE(efast_arc_test_16(t.data()));
}

TEST(EfastArcTest, TwoSeparateArcsReject) {
  std::array<int64_t, 16> t;
  t.fill(0);
  t[0] = t[1] = t[2] = 100;
  t[8] = t[9] = t[10] = 100;
  EXPECT_FALSE(efast_arc_test_16(t.data()));
  // But an older second arc leaves the newest one valid on its own.
  t[8] = t[9] = t[10] = 50;
  EXPECT_TRUE(efast_arc_test_16(t.data()));
  // The newest pixels split over two places: no contiguous arc is newer than the rest.
  t.fill(0);
  t[0] = t[1] = t[2] = t[9] = 100;
  EXPECT_FALSE(efast_arc_test_16(t.data()));
}

TEST(EfastArcTest, AgreesWithTheExhaustiveScanOnRandomCircles) {
  std::mt19937_64 rng(7);
  int positives16 = 0, positives20 = 0;
  for (int trial = 0; trial < 200000; ++trial) {
    // Few distinct values make ties frequent; sometimes a planted arc.
    std::uniform_int_distribution<int> v(0, trial % 3 == 0 ? 3 : 30);
    std::array<int64_t, 16> a;
    std::array<double, 16> ad;
    std::array<int64_t, 20> b;
    std::array<double, 20> bd;
    for (int i = 0; i < 16; ++i) ad[i] = static_cast<double>(a[i] = v(rng));
    for (int i = 0; i < 20; ++i) bd[i] = static_cast<double>(b[i] = v(rng));
    if (trial % 2) {
      const int s = static_cast<int>(rng() % 16), l = 2 + static_cast<int>(rng() % 6);
      for (int j = 0; j < l; ++j) ad[(s + j) % 16] = static_cast<double>(a[(s + j) % 16] = 31 + v(rng) % 2);
      const int s4 = static_cast<int>(rng() % 20), l4 = 3 + static_cast<int>(rng() % 7);
      for (int j = 0; j < l4; ++j) bd[(s4 + j) % 20] = static_cast<double>(b[(s4 + j) % 20] = 31 + v(rng) % 2);
    }
    const bool r16 = reference_arc(ad, 3, 6), r20 = reference_arc(bd, 4, 8);
    ASSERT_EQ(efast_arc_test_16(a.data()), r16) << trial;
    ASSERT_EQ(efast_arc_test_20(b.data()), r20) << trial;
    positives16 += r16;
    positives20 += r20;
  }
  EXPECT_GT(positives16, 10000);
  EXPECT_GT(positives20, 10000);
}

// --------------------------------------------------------------- detector
// Writes a corner pattern into the SAE around (x, y) for polarity p: an inner arc of 4 pixels and
// an outer arc of 5 pixels newer than the rest of both circles (which are set, older).
void plant_corner(EfastDetector* d, int x, int y, int8_t p, int64_t t0) {
  for (int i = 0; i < 16; ++i) d->process({t0 + i, static_cast<uint16_t>(x + kEfastCircle3[i][0]), static_cast<uint16_t>(y + kEfastCircle3[i][1]), p});
  for (int i = 0; i < 20; ++i) d->process({t0 + 16 + i, static_cast<uint16_t>(x + kEfastCircle4[i][0]), static_cast<uint16_t>(y + kEfastCircle4[i][1]), p});
  for (int i = 5; i < 9; ++i) d->process({t0 + 100 + i, static_cast<uint16_t>(x + kEfastCircle3[i][0]), static_cast<uint16_t>(y + kEfastCircle3[i][1]), p});
  for (int i = 6; i < 11; ++i) d->process({t0 + 200 + i, static_cast<uint16_t>(x + kEfastCircle4[i][0]), static_cast<uint16_t>(y + kEfastCircle4[i][1]), p});
}

TEST(EfastDetector, PlantedCornerFiresForItsPolarityOnly) {
  for (int8_t p : {int8_t{1}, int8_t{-1}}) {
    EfastDetector d(64, 48);
    plant_corner(&d, 20, 20, p, 1000);
    const int64_t before = d.stats().corners;
    EXPECT_TRUE(d.process({5000, 20, 20, p}));
    EXPECT_FALSE(d.process({5001, 20, 20, static_cast<int8_t>(-p)}));  // other plane is empty
    EXPECT_EQ(d.stats().corners, before + 1);
    EXPECT_EQ(d.sae().at(20, 20, p), 5000);
    EXPECT_EQ(d.sae().at(20, 20, static_cast<int8_t>(-p)), 5001);
  }
}

TEST(EfastDetector, InnerArcAloneIsNotACorner) {
  EfastDetector d(64, 48);
  for (int i = 0; i < 16; ++i) d.process({10 + i, static_cast<uint16_t>(20 + kEfastCircle3[i][0]), static_cast<uint16_t>(20 + kEfastCircle3[i][1]), 1});
  // Outer circle all at one time: no arc is strictly newer than the rest.
  for (int i = 0; i < 20; ++i) d.process({40, static_cast<uint16_t>(20 + kEfastCircle4[i][0]), static_cast<uint16_t>(20 + kEfastCircle4[i][1]), 1});
  for (int i = 5; i < 9; ++i) d.process({100 + i, static_cast<uint16_t>(20 + kEfastCircle3[i][0]), static_cast<uint16_t>(20 + kEfastCircle3[i][1]), 1});
  const int64_t inner_before = d.stats().inner_passed;
  EXPECT_FALSE(d.process({500, 20, 20, 1}));
  EXPECT_EQ(d.stats().inner_passed, inner_before + 1);
}

TEST(EfastDetector, BorderPixelsAreNeverCornersAndTheFirstInsideOneCanBe) {
  const int W = 40, H = 30;
  struct Case {
    int x, y;
    bool inside;
  };
  for (const Case c : {Case{4, 4, true}, Case{W - 5, H - 5, true}, Case{4, H - 5, true}, Case{W - 5, 4, true}}) {
    EfastDetector d(W, H);
    plant_corner(&d, c.x, c.y, 1, 0);
    EXPECT_EQ(d.process({1000, static_cast<uint16_t>(c.x), static_cast<uint16_t>(c.y), 1}), c.inside) << c.x << "," << c.y;
  }
  // Pixels within 4 of the border: the SAE updates, the test is not made.
  EfastDetector d(W, H);
  for (int x = 0; x < W; ++x) {
    for (int y = 0; y < H; ++y) {
      if (x >= 4 && y >= 4 && x < W - 4 && y < H - 4) continue;
      EXPECT_FALSE(d.process({x * 100 + y + 1, static_cast<uint16_t>(x), static_cast<uint16_t>(y), 1}));
      EXPECT_EQ(d.sae().at(x, y, 1), x * 100 + y + 1);
    }
  }
  EXPECT_EQ(d.stats().tested, 0);
}

TEST(EfastDetector, WorksBeyondColumn180OnLargerSensors) {
  // The authors' map is 180 x 240 indexed (x, y): columns >= 180 alias other pixels. Ours is sized
  // from the calibration: a corner at x = 300 on a DAVIS346 fires, and a pattern at another
  // pixel does not leak into it.
  EfastDetector d(346, 260);
  plant_corner(&d, 300, 200, 1, 0);
  EXPECT_TRUE(d.process({1000, 300, 200, 1}));
  EXPECT_FALSE(d.process({1001, 200, 300 - 200, 1}));
}

TEST(EfastDetector, RejectsBadSizesAndOptions) {
  EXPECT_THROW(EfastDetector(0, 10), std::invalid_argument);
  EXPECT_THROW(EfastDetector(10, -1), std::invalid_argument);
  EfastOptions o;
  o.filter_window_ns = -1;
  EXPECT_THROW(EfastDetector(10, 10, o), std::invalid_argument);
}

TEST(EfastDetector, FilteredSaeSkipsRepeatsWithinTheWindow) {
  EfastOptions o;
  o.filter_sae = true;
  o.filter_window_ns = 50'000'000;
  EfastDetector d(64, 48, o);
  d.process({0, 20, 20, 1});
  EXPECT_EQ(d.sae().at(20, 20, 1), 0);
  d.process({10'000'000, 20, 20, 1});  // same polarity 10 ms later: filtered, SAE keeps 0
  EXPECT_EQ(d.sae().at(20, 20, 1), 0);
  d.process({40'000'000, 20, 20, -1});  // other polarity: updates its plane
  EXPECT_EQ(d.sae().at(20, 20, -1), 40'000'000);
  d.process({45'000'000, 20, 20, 1});  // the pixel's latest event was OFF: updates
  EXPECT_EQ(d.sae().at(20, 20, 1), 45'000'000);
  d.process({90'000'000, 20, 20, 1});  // 45 ms after the latest ON: filtered
  EXPECT_EQ(d.sae().at(20, 20, 1), 45'000'000);
  d.process({140'000'001, 20, 20, 1});  // 50 ms + 1 ns after the latest ON (at 90 ms): updates
  EXPECT_EQ(d.sae().at(20, 20, 1), 140'000'001);
  EXPECT_EQ(d.stats().events, 6);
}

// --------------------------------------------------------------- event-for-event agreement
void expect_same_decisions(const std::vector<Event>& events, int w, int h, int64_t* corners_out = nullptr) {
  EfastDetector fast(w, h);
  ReferenceFast ref(w, h);
  int64_t corners = 0;
  for (size_t i = 0; i < events.size(); ++i) {
    const bool a = fast.process(events[i]);
    const bool b = ref.is_feature(events[i]);
    ASSERT_EQ(a, b) << "event " << i << " t " << events[i].t_ns << " (" << events[i].x << "," << events[i].y << ")";
    corners += a;
  }
  if (corners_out) *corners_out = corners;
}

// A bright square moving diagonally over a 64x48 sensor: events on its edges, so corners exist.
std::vector<Event> moving_square_events(int w, int h, int steps) {
  std::vector<Event> ev;
  int64_t t = 1'000'000;
  for (int s = 0; s < steps; ++s) {
    const int x0 = 8 + s % (w - 30), y0 = 6 + (s / 2) % (h - 24);
    for (int y = y0; y < y0 + 14; ++y) {
      for (int x = x0; x < x0 + 14; ++x) {
        const bool leading = x == x0 + 13 || y == y0 + 13;
        const bool trailing = x == x0 || y == y0;
        if (!leading && !trailing) continue;
        ev.push_back({t, static_cast<uint16_t>(x), static_cast<uint16_t>(y), static_cast<int8_t>(leading ? 1 : -1)});
        t += 1000;
      }
    }
  }
  return ev;
}

TEST(EfastAgreement, MovingSquareEventForEvent) {
  int64_t corners = 0;
  expect_same_decisions(moving_square_events(64, 48, 300), 64, 48, &corners);
  EXPECT_GT(corners, 100);
}

TEST(EfastAgreement, RandomStreamsWithEqualTimestampsEventForEvent) {
  std::mt19937_64 rng(3);
  std::vector<Event> ev;
  int64_t t = 0;
  for (int i = 0; i < 300000; ++i) {
    t += static_cast<int64_t>(rng() % 3) * 1000;  // many equal stamps
    ev.push_back({t, static_cast<uint16_t>(rng() % 20), static_cast<uint16_t>(rng() % 16),
                  static_cast<int8_t>(rng() % 2 ? 1 : -1)});
  }
  int64_t corners = 0;
  expect_same_decisions(ev, 20, 16, &corners);
  EXPECT_GT(corners, 0);
}

TEST(EfastAgreement, RealEcdSliceEventForEvent) {
  const auto dir = evio_test::real_data_dir("ecd_slider_depth_head");
  if (!dir) GTEST_SKIP() << "real data not found";
  const EventBuffer buf = read_ecd_events(*dir + "/events.txt");
  std::vector<Event> ev(buf.begin(), buf.end());
  int64_t corners = 0;
  expect_same_decisions(ev, 240, 180, &corners);
  // 10-20x reduction in the paper on whole ECD sequences; this 50k-event slice is its start.
  EXPECT_GT(corners, 100);
  EXPECT_LT(corners, static_cast<int64_t>(ev.size()) / 5);
  std::printf("ecd_slider_depth_head: %zu events, %lld corners, reduction %.1fx\n", ev.size(),
              static_cast<long long>(corners), static_cast<double>(ev.size()) / std::max<int64_t>(1, corners));
}

}  // namespace
}  // namespace evio::frontend
