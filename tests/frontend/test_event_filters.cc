// Refractory and background-activity filters, event undistortion, SAE time surface.
#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "evio/frontend/event_filters.h"
#include "evio/frontend/sae.h"

namespace evio::frontend {
namespace {

TEST(RefractoryFilter, DropsEventsOfAPixelWithinThePeriodOfItsLastPassedEvent) {
  RefractoryFilterOptions o;
  o.period_ns = 1000;
  RefractoryFilter f(10, 10, o);
  EXPECT_TRUE(f.accept({0, 3, 3, 1}));
  EXPECT_FALSE(f.accept({500, 3, 3, -1}));   // any polarity blocks by default
  EXPECT_TRUE(f.accept({500, 4, 3, 1}));     // another pixel
  EXPECT_FALSE(f.accept({999, 3, 3, 1}));
  EXPECT_TRUE(f.accept({1000, 3, 3, 1}));    // exactly one period after the last passed event
  EXPECT_EQ(f.stats().events, 5);
  EXPECT_EQ(f.stats().passed, 3);
  o.per_polarity = true;
  RefractoryFilter g(10, 10, o);
  EXPECT_TRUE(g.accept({0, 3, 3, 1}));
  EXPECT_TRUE(g.accept({10, 3, 3, -1}));
  EXPECT_FALSE(g.accept({20, 3, 3, -1}));
  EXPECT_THROW(RefractoryFilter(10, 10, RefractoryFilterOptions{-1, false}), std::invalid_argument);
}

TEST(RefractoryFilter, HandlesLargeAndNegativeTimestamps) {
  RefractoryFilter f(4, 4);
  EXPECT_TRUE(f.accept({-5'000'000, 0, 0, 1}));
  EXPECT_TRUE(f.accept({1'700'000'000'000'000'000, 0, 0, 1}));
  EXPECT_FALSE(f.accept({1'700'000'000'000'000'001, 0, 0, 1}));
}

TEST(BackgroundActivityFilter, PassesSupportedEventsAndDropsIsolatedNoise) {
  BackgroundActivityFilterOptions o;
  o.window_ns = 1000;
  BackgroundActivityFilter f(20, 20, o);
  EXPECT_FALSE(f.accept({0, 5, 5, 1}));      // nothing around yet
  EXPECT_TRUE(f.accept({100, 6, 6, 1}));     // diagonal neighbour 100 ns earlier
  EXPECT_FALSE(f.accept({200, 8, 6, -1}));   // two pixels away: not a neighbour at radius 1
  EXPECT_FALSE(f.accept({5000, 7, 6, 1}));   // neighbours (6,6), (8,6) are too old
  EXPECT_FALSE(f.accept({5000, 5, 5, 1}));   // its own pixel never counts... neighbours old
  EXPECT_TRUE(f.accept({5500, 6, 5, 1}));    // (5,5) and (7,6) at 5000
  // Border pixels have no out-of-sensor support.
  EXPECT_FALSE(f.accept({6000, 0, 0, 1}));
  EXPECT_TRUE(f.accept({6001, 1, 0, 1}));
  EXPECT_TRUE(f.accept({6002, 19, 19, 1}) == false);
}

TEST(BackgroundActivityFilter, MinSupportAndRadius) {
  BackgroundActivityFilterOptions o;
  o.window_ns = 1000;
  o.radius = 2;
  o.min_support = 2;
  BackgroundActivityFilter f(20, 20, o);
  f.accept({0, 5, 5, 1});
  EXPECT_FALSE(f.accept({1, 7, 7, 1}));  // one supporter at Chebyshev distance 2
  EXPECT_TRUE(f.accept({2, 6, 7, 1}));   // two
  o.min_support = 25;
  EXPECT_THROW(BackgroundActivityFilter(5, 5, o), std::invalid_argument);
  o.min_support = 1;
  o.radius = 0;
  EXPECT_THROW(BackgroundActivityFilter(5, 5, o), std::invalid_argument);
}

TEST(BackgroundActivityFilter, KeepsAMovingEdgeAndRemovesUniformNoise) {
  // A vertical edge sweeping right at 1 px / 200 us over 60x40, plus uniform noise at ~2 kHz.
  std::mt19937_64 rng(11);
  std::vector<std::pair<Event, bool>> ev;  // event, is signal
  for (int col = 0; col < 60; ++col) {
    for (int y = 0; y < 40; ++y) ev.push_back({{col * 200'000 + y * 10, static_cast<uint16_t>(col), static_cast<uint16_t>(y), 1}, true});
  }
  for (int i = 0; i < 24; ++i) {
    ev.push_back({{static_cast<int64_t>(rng() % 12'000'000), static_cast<uint16_t>(rng() % 60), static_cast<uint16_t>(rng() % 40), -1}, false});
  }
  std::stable_sort(ev.begin(), ev.end(), [](const auto& a, const auto& b) { return a.first.t_ns < b.first.t_ns; });
  BackgroundActivityFilterOptions o;
  o.window_ns = 1'000'000;
  BackgroundActivityFilter f(60, 40, o);
  int signal = 0, signal_kept = 0, noise = 0, noise_kept = 0;
  for (const auto& [e, is_signal] : ev) {
    const bool k = f.accept(e);
    (is_signal ? signal : noise)++;
    (is_signal ? signal_kept : noise_kept) += k;
  }
  EXPECT_GT(signal_kept, 0.95 * signal);
  EXPECT_LT(noise_kept, 0.5 * noise);
}

TEST(EventUndistorter, MatchesTheCameraModel) {
  calib::CameraIntrinsics k;
  k.width = 240;
  k.height = 180;
  k.fx = 199.0;
  k.fy = 198.0;
  k.cx = 132.0;
  k.cy = 110.0;
  k.model = calib::DistortionModel::kRadtan;
  k.distortion = {-0.368, 0.150, 0.001, -0.0003};
  const calib::PinholeCamera cam(k);
  const EventUndistorter u(cam);
  ASSERT_EQ(u.width(), 240);
  double worst = 0;
  for (int y = 0; y < 180; y += 7) {
    for (int x = 0; x < 240; x += 5) {
      if (!u.valid(x, y)) continue;
      Eigen::Vector2d n;
      ASSERT_TRUE(cam.undistort(Eigen::Vector2d((x - k.cx) / k.fx, (y - k.cy) / k.fy), &n));
      const Eigen::Vector2d expect(k.fx * n.x() + k.cx, k.fy * n.y() + k.cy);
      worst = std::max(worst, (u.undistorted(x, y).cast<double>() - expect).norm());
    }
  }
  EXPECT_LT(worst, 1e-3);
  // The principal point stays put.
  EXPECT_NEAR(u.undistorted(132, 110).x(), 132.0f, 1e-3);
}

TEST(SurfaceOfActiveEvents, TimeSurfaceDecaysAndIgnoresTheFuture) {
  SurfaceOfActiveEvents s(4, 3);
  s.update({1'000'000'000, 1, 1, 1});
  s.update({1'010'000'000, 2, 1, -1});
  s.update({2'000'000'000, 3, 2, 1});
  const cv::Mat ts = s.time_surface(1'010'000'000, 0.01);
  EXPECT_NEAR(ts.at<float>(1, 1), std::exp(-1.0), 1e-6);
  EXPECT_FLOAT_EQ(ts.at<float>(1, 2), 1.0f);
  EXPECT_FLOAT_EQ(ts.at<float>(2, 3), 0.0f);  // after t_ref
  EXPECT_FLOAT_EQ(ts.at<float>(0, 0), 0.0f);  // never fired
  const cv::Mat on = s.time_surface(1'010'000'000, 0.01, 1);
  EXPECT_FLOAT_EQ(on.at<float>(1, 2), 0.0f);
  EXPECT_EQ(s.latest(2, 1), 1'010'000'000);
  EXPECT_EQ(s.latest(0, 0), kNeverNs);
  EXPECT_THROW(s.time_surface(0, 0.0), std::invalid_argument);
  EXPECT_THROW(SurfaceOfActiveEvents(0, 3), std::invalid_argument);
}

}  // namespace
}  // namespace evio::frontend
