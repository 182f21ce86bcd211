// pipeline::CornerPipeline: the front-end chain of `evio corners` (validity, filters, eFAST, DART,
// corner tracker) gives the same corner events and tracks as the modules chained by hand, counts
// what it drops, and rejects bad settings.
#include "evio/pipeline/corner_pipeline.h"

#include <random>
#include <stdexcept>
#include <vector>

#include <gtest/gtest.h>

namespace evio::pipeline {
namespace {

// A 12 px bright square moving right at 400 px/s over a 64x48 sensor (its leading edge fires ON
// events, its trailing edge OFF events, one event per edge pixel per column crossed), plus
// uniform noise; in time order. Some noise falls outside the sensor.
std::vector<Event> moving_square_events() {
  std::vector<Event> ev;
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> nx(0, 69), ny(0, 49);
  const int64_t dt_ns = 2'500'000;  // one column per 2.5 ms
  for (int step = 0; step < 40; ++step) {
    const int64_t t = step * dt_ns;
    const int lead = 10 + step, trail = lead - 12;
    for (int y = 18; y < 30; ++y) {
      ev.push_back({t + (y - 18) * 1000, static_cast<uint16_t>(lead), static_cast<uint16_t>(y), 1});
      if (trail >= 0) ev.push_back({t + (y - 18) * 1000 + 500, static_cast<uint16_t>(trail), static_cast<uint16_t>(y), -1});
    }
    for (int k = 0; k < 20; ++k) {
      ev.push_back({t + 20000 + k * 1000, static_cast<uint16_t>(nx(rng)), static_cast<uint16_t>(ny(rng)),
                    static_cast<int8_t>(k % 2 ? 1 : -1)});
    }
  }
  return ev;
}

TEST(CornerPipeline, SameCornersAndTracksAsTheModulesChainedByHand) {
  CornerPipelineOptions o;
  o.refractory_enabled = true;
  o.background_activity_enabled = true;
  o.tracker.min_length = 2;
  const int w = 64, h = 48;
  const std::vector<Event> events = moving_square_events();

  CornerPipeline pipe(o, w, h, std::nullopt);
  std::vector<Event> corners;
  std::vector<frontend::CornerTrack> tracks;
  for (const Event& e : events) {
    if (pipe.process(e)) corners.push_back(e);
  }
  for (auto& t : pipe.take_finished_tracks()) tracks.push_back(std::move(t));
  for (auto& t : pipe.finish()) tracks.push_back(std::move(t));

  frontend::RefractoryFilter refractory(w, h, o.refractory);
  frontend::BackgroundActivityFilter background(w, h, o.background_activity);
  frontend::EfastDetector detector(w, h, o.efast);
  frontend::DartExtractor dart(o.dart);
  frontend::CornerTracker tracker(w, h, o.tracker);
  frontend::DartDescriptor d;
  std::vector<Event> expected;
  int64_t outside = 0, descriptors = 0;
  for (const Event& e : events) {
    if (e.x >= w || e.y >= h) {
      ++outside;
      continue;
    }
    if (!refractory.accept(e) || !background.accept(e) || !detector.process(e)) continue;
    expected.push_back(e);
    const bool has = dart.compute(detector.sae(), e.x, e.y, e.t_ns, e.polarity, &d);
    descriptors += has ? 1 : 0;
    tracker.add(e, has ? &d : nullptr);
  }
  std::vector<frontend::CornerTrack> expected_tracks = tracker.finish();

  ASSERT_GT(expected.size(), 5u);  // the square's corners are found
  ASSERT_EQ(corners.size(), expected.size());
  for (size_t i = 0; i < corners.size(); ++i) {
    EXPECT_EQ(corners[i].t_ns, expected[i].t_ns);
    EXPECT_EQ(corners[i].x, expected[i].x);
    EXPECT_EQ(corners[i].y, expected[i].y);
  }
  ASSERT_EQ(tracks.size(), expected_tracks.size());
  for (size_t i = 0; i < tracks.size(); ++i) EXPECT_EQ(tracks[i].points.size(), expected_tracks[i].points.size());
  EXPECT_EQ(pipe.stats().events, static_cast<int64_t>(events.size()));
  EXPECT_EQ(pipe.stats().outside, outside);
  EXPECT_GT(outside, 0);
  EXPECT_EQ(pipe.stats().corners, static_cast<int64_t>(expected.size()));
  EXPECT_EQ(pipe.stats().descriptors, descriptors);
  EXPECT_EQ(*pipe.refractory_passed(), refractory.stats().passed);
  EXPECT_EQ(*pipe.background_activity_passed(), background.stats().passed);
  EXPECT_EQ(pipe.efast_stats().tested, detector.stats().tested);
}

TEST(CornerPipeline, FiltersAndTracksOffAndBadSettings) {
  CornerPipelineOptions o;
  o.tracks = false;
  CornerPipeline pipe(o, 64, 48, std::nullopt);
  for (const Event& e : moving_square_events()) pipe.process(e);
  EXPECT_EQ(pipe.tracker(), nullptr);
  EXPECT_TRUE(pipe.finish().empty());
  EXPECT_FALSE(pipe.refractory_passed());
  EXPECT_FALSE(pipe.background_activity_passed());
  EXPECT_GT(pipe.stats().corners, 0);
  EXPECT_EQ(pipe.stats().descriptors, 0);

  CornerPipelineOptions bad;
  bad.background_activity.radius = 9;
  EXPECT_THROW(CornerPipeline(bad, 64, 48, std::nullopt), std::invalid_argument);
  EXPECT_THROW(CornerPipeline(CornerPipelineOptions{}, 0, 48, std::nullopt), std::invalid_argument);
}

}  // namespace
}  // namespace evio::pipeline
