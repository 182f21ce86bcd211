// CmaxWindower (event windows for contrast maximisation: counts, durations, caps, stream indices,
// undistortion choice, dither, extremes) and SegmentationPipeline (streamed windows keep their
// labels), in memory.
#include "evio/pipeline/segmentation_pipeline.h"

#include <cmath>
#include <map>
#include <random>

#include <gtest/gtest.h>

#include "evio_test/moving_patches.h"

namespace {

using evio::SubpixelEvent;
using evio::pipeline::CmaxUndistortion;
using evio::pipeline::CmaxWindower;
using evio::pipeline::CmaxWindowOptions;

std::vector<SubpixelEvent> grid_events(int n, int64_t t0, int64_t dt, bool integer) {
  std::vector<SubpixelEvent> v;
  for (int k = 0; k < n; ++k) {
    SubpixelEvent e;
    e.t_ns = t0 + k * dt;
    e.x = static_cast<float>(k % 200) + (integer ? 0.0f : 0.25f);
    e.y = static_cast<float>((k * 7) % 150);
    e.polarity = k % 2 ? 1 : -1;
    v.push_back(e);
  }
  return v;
}

TEST(CmaxWindower, EventWindowsCarryTheirStreamIndices) {
  CmaxWindowOptions o;
  o.window_events = 1000;
  o.max_window_ns = 0;
  CmaxWindower w(o, 240, 180, std::nullopt);
  const auto ev = grid_events(3400, 1'700'000'000'000'000'000LL, 1000, true);
  for (const auto& e : ev) w.process(e);
  w.finish();
  const auto out = w.take();
  // 3 full windows; the 400-event tail is under half a window: skipped.
  ASSERT_EQ(out.size(), 3u);
  EXPECT_EQ(w.stats().windows_skipped, 1);
  for (size_t i = 0; i < out.size(); ++i) {
    EXPECT_EQ(out[i].input_begin, static_cast<int64_t>(i * 1000));
    EXPECT_EQ(out[i].input_end, static_cast<int64_t>((i + 1) * 1000));
    ASSERT_EQ(out[i].input_index.size(), 1000u);
    EXPECT_EQ(out[i].input_index.front(), out[i].input_begin);
    EXPECT_EQ(out[i].t_ref_ns, out[i].t_start_ns + (out[i].t_end_ns - out[i].t_start_ns) / 2);
    // Integer input is dithered within its pixel; times are relative to t_ref (1.7e18 ns stamps).
    const auto& e = out[i].events;
    for (size_t k = 0; k < e.size(); ++k) {
      const SubpixelEvent& s = ev[static_cast<size_t>(out[i].input_index[k])];
      EXPECT_LE(std::abs(e.x[k] - s.x), 0.5f);
      EXPECT_LE(std::abs(e.y[k] - s.y), 0.5f);
    }
    EXPECT_NEAR(e.dt_max_s() - e.dt_min_s(), 999e-6, 1e-9);
  }
  EXPECT_TRUE(w.dithered());
  EXPECT_EQ(w.undistortion(), CmaxUndistortion::kNone);
}

TEST(CmaxWindower, TimeWindowsCapsAndSubpixelInput) {
  CmaxWindowOptions o;
  o.window_ns = 10'000'000;  // 10 ms
  o.min_window_events = 10;
  CmaxWindower w(o, 240, 180, std::nullopt);
  // 100 events in [0, 10) ms, a 35 ms gap, 100 events.
  auto a = grid_events(100, 0, 100'000, false);
  auto b = grid_events(100, 45'000'000, 50'000, false);
  for (const auto& e : a) w.process(e);
  for (const auto& e : b) w.process(e);
  w.finish();
  const auto out = w.take();
  ASSERT_EQ(out.size(), 2u);
  EXPECT_EQ(out[0].t_start_ns, 0);
  EXPECT_EQ(out[0].t_end_ns, 10'000'000);
  EXPECT_EQ(w.stats().windows_skipped, 3);  // the empty 10-20, 20-30, 30-40 ms windows
  EXPECT_FALSE(w.dithered());               // sub-pixel input is used as it is
  EXPECT_FLOAT_EQ(out[0].events.x[0], 0.25f);
  // Event windows capped in time.
  CmaxWindowOptions c;
  c.window_events = 1000;
  c.max_window_ns = 5'000'000;
  CmaxWindower wc(c, 240, 180, std::nullopt);
  for (const auto& e : grid_events(500, 0, 20'000, true)) wc.process(e);  // 10 ms of events
  wc.finish();
  const auto capped = wc.take();
  ASSERT_EQ(capped.size(), 2u);
  EXPECT_LT(capped[0].t_end_ns - capped[0].t_start_ns, 5'000'000);
  // Invalid options.
  CmaxWindowOptions bad;
  bad.dither_px = 9;
  EXPECT_THROW(CmaxWindower(bad, 240, 180, std::nullopt), std::invalid_argument);
  bad = CmaxWindowOptions();
  bad.undistortion = CmaxUndistortion::kLut;
  EXPECT_THROW(CmaxWindower(bad, 240, 180, std::nullopt), std::invalid_argument);
}

TEST(CmaxWindower, DistortedCameraIntegerPixelsGoThroughTheLut) {
  evio::calib::CameraIntrinsics k;
  k.width = 240, k.height = 180, k.fx = k.fy = 200, k.cx = 120, k.cy = 90;
  k.model = evio::calib::DistortionModel::kRadtan;
  k.distortion = {-0.3, 0.1, 0, 0};
  const evio::calib::PinholeCamera cam(k);
  CmaxWindowOptions o;
  o.window_events = 500;
  o.dither_px = 0;
  CmaxWindower w(o, 0, 0, cam);
  for (const auto& e : grid_events(500, 0, 1000, true)) w.process(e);
  const auto out = w.take();
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(w.undistortion(), CmaxUndistortion::kLut);
  EXPECT_NE(w.undistortion_reason().find("radtan"), std::string::npos);
  // Pixel (0, 0) moves outwards when barrel distortion (k1 < 0) is removed.
  ASSERT_EQ(out[0].input_index[0], 0);
  EXPECT_LT(out[0].events.x[0], 0.0f);
  EXPECT_LT(out[0].events.y[0], 0.0f);
  // Sub-pixel input with the same camera: taken as already undistorted.
  CmaxWindower ws(o, 0, 0, cam);
  for (const auto& e : grid_events(500, 0, 1000, false)) ws.process(e);
  ASSERT_EQ(ws.take().size(), 1u);
  EXPECT_EQ(ws.undistortion(), CmaxUndistortion::kNone);
}

// Two patches of short edges moving apart over a still background, streamed: the same label for
// each patch throughout.
TEST(SegmentationPipeline, StreamedWindowsKeepTheirLabels) {
  const double v1[2] = {150, -60}, v2[2] = {-100, -120};
  std::vector<SubpixelEvent> ev;
  std::vector<int> truth;
  for (const evio_test::PatchEvent& p : evio_test::moving_patches(90000, 5, v1, v2, 0, 0.09, true)) {
    SubpixelEvent s;
    s.t_ns = p.t_ns;
    s.x = static_cast<float>(p.x);
    s.y = static_cast<float>(p.y);
    s.polarity = 1;
    ev.push_back(s);
    truth.push_back(p.label);
  }
  evio::pipeline::SegmentationPipelineOptions o;
  o.window.window_events = 30000;
  o.window.max_window_ns = 0;
  evio::pipeline::SegmentationPipeline pipe(o, 240, 180, std::nullopt);
  for (const auto& e : ev) pipe.process(e);
  pipe.finish();
  const auto windows = pipe.take_windows();
  ASSERT_EQ(windows.size(), 3u);
  std::map<int, std::map<int, int>> id_per_object;  // object -> id -> events, over all windows
  int64_t good = 0, total = 0;
  for (const auto& w : windows) {
    // Measured: 4 clusters in the first window (patch 2 split, 0.79 of its events on one label),
    // 3 in the others.
    EXPECT_GE(w.clusters.size(), 3u) << "window " << w.index;
    EXPECT_LE(w.clusters.size(), 4u) << "window " << w.index;
    for (size_t k = 0; k < w.labels.size(); ++k) ++id_per_object[truth[static_cast<size_t>(w.input_index[k])]][w.labels[k]];
  }
  for (const auto& [object, ids] : id_per_object) {
    int best = -2, most = 0, all = 0;
    for (const auto& [id, c] : ids) {
      all += c;
      if (c > most) most = c, best = id;
    }
    good += most, total += all;
    std::printf("object %d: label %d for %.3f of its events over 3 windows\n", object, best, static_cast<double>(most) / all);
  }
  // One label per object over the whole stream (measured 0.95 of all events).
  EXPECT_GE(static_cast<double>(good) / static_cast<double>(total), 0.93);
  EXPECT_LE(pipe.stats().next_id, 4);  // measured 4: the first window's extra cluster
}

}  // namespace
