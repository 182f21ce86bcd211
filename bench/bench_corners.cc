// Event-feature front-end costs per event, one core: undistortion + refractory + background-
// activity filter, SAE update, eFAST (with the share of tested events reaching the outer circle),
// the exhaustive arc scan of the published definition for comparison, and the whole chain.
// Input: the real ECD slice (../shared/data/real/ecd_slider_depth_head, or $EVIO_REAL_DATA)
// repeated to 1 million events with shifted times; without it, a synthetic moving-square stream
// (the label says which). The "ns/ev" column is nanoseconds per event (Google Benchmark prints
// an inverted rate with an "s" suffix: "70.7s" reads 70.7 ns per event).
#include <algorithm>
#include <array>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <sys/stat.h>
#include <vector>

#include <benchmark/benchmark.h>

#include "evio/calib/calibration_io.h"
#include "evio/frontend/corner_tracker.h"
#include "evio/frontend/dart.h"
#include "evio/frontend/efast.h"
#include "evio/frontend/event_filters.h"
#include "evio/sensors/ecd.h"

namespace {

using evio::Event;

struct Input {
  std::vector<Event> events;
  std::string label;
  int width = 240, height = 180;
  evio::calib::CameraIntrinsics intrinsics;
};

bool exists(const std::string& p) {
  struct stat st;
  return stat(p.c_str(), &st) == 0;
}

const Input& input() {
  static const Input in = [] {
    Input r;
    const char* env = std::getenv("EVIO_REAL_DATA");
    const std::string root = env ? env : std::string(EVIO_SOURCE_DIR) + "/../shared/data/real";
    const std::string dir = root + "/ecd_slider_depth_head";
    std::vector<Event> base;
    if (exists(dir + "/events.txt")) {
      const evio::EventBuffer b = evio::read_ecd_events(dir + "/events.txt");
      base.assign(b.begin(), b.end());
      r.intrinsics = evio::calib::load_ecd_calib(dir + "/calib.txt", 240, 180).camera.intrinsics();
      r.label = "real ECD slider_depth slice x";
    } else {
      int64_t t = 0;
      for (int s = 0; s < 2000; ++s) {
        const int x0 = 10 + s % 200, y0 = 10 + (s / 3) % 140;
        for (int k = 0; k < 28; ++k) {
          base.push_back({t, static_cast<uint16_t>(x0 + (k < 14 ? k : 13)), static_cast<uint16_t>(y0 + (k < 14 ? 13 : k - 14)), 1});
          t += 2000;
        }
      }
      r.intrinsics.width = 240;
      r.intrinsics.height = 180;
      r.intrinsics.fx = r.intrinsics.fy = 200;
      r.intrinsics.cx = 120;
      r.intrinsics.cy = 90;
      r.label = "synthetic moving square x";
    }
    const int64_t span = base.back().t_ns - base.front().t_ns + 1000;
    const size_t reps = (1'000'000 + base.size() - 1) / base.size();
    r.events.reserve(1'000'000);
    for (size_t k = 0; k < reps && r.events.size() < 1'000'000; ++k) {
      for (const Event& e : base) {
        if (r.events.size() == 1'000'000) break;
        Event f = e;
        f.t_ns += static_cast<int64_t>(k) * span;
        r.events.push_back(f);
      }
    }
    r.label += std::to_string(reps) + " = " + std::to_string(r.events.size()) + " events";
    return r;
  }();
  return in;
}

void finish(benchmark::State& state, size_t n) {
  state.SetItemsProcessed(static_cast<int64_t>(state.iterations() * n));
  state.counters["ns/ev"] = benchmark::Counter(static_cast<double>(n) * 1e-9,
                                                benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  state.SetLabel(input().label);
}

void BM_UndistortAndFilters(benchmark::State& state) {
  const Input& in = input();
  const evio::frontend::EventUndistorter und{evio::calib::PinholeCamera(in.intrinsics)};
  int64_t passed = 0;
  for (auto _ : state) {
    evio::frontend::RefractoryFilter refr(in.width, in.height);
    evio::frontend::BackgroundActivityFilter ba(in.width, in.height);
    float sx = 0;
    for (const Event& e : in.events) {
      if (!und.valid(e.x, e.y)) continue;
      sx += und.undistorted(e.x, e.y).x();
      if (refr.accept(e) && ba.accept(e)) ++passed;
    }
    benchmark::DoNotOptimize(sx);
  }
  state.counters["passed"] = static_cast<double>(passed) / static_cast<double>(state.iterations()) / in.events.size();
  finish(state, in.events.size());
}

void BM_SaeUpdate(benchmark::State& state) {
  const Input& in = input();
  evio::frontend::SurfaceOfActiveEvents sae(in.width, in.height);
  for (auto _ : state) {
    for (const Event& e : in.events) sae.update(e);
    benchmark::ClobberMemory();
  }
  finish(state, in.events.size());
}

void BM_Efast(benchmark::State& state) {
  const Input& in = input();
  evio::frontend::EfastOptions o;
  o.filter_sae = state.range(0) != 0;
  evio::frontend::EfastStats st;
  for (auto _ : state) {
    evio::frontend::EfastDetector d(in.width, in.height, o);
    int64_t corners = 0;
    for (const Event& e : in.events) corners += d.process(e);
    benchmark::DoNotOptimize(corners);
    st = d.stats();
  }
  state.counters["corners"] = static_cast<double>(st.corners);
  state.counters["reduction"] = static_cast<double>(st.events) / std::max<int64_t>(1, st.corners);
  state.counters["outer_share"] = static_cast<double>(st.inner_passed) / std::max<int64_t>(1, st.tested);
  finish(state, in.events.size());
}

// The published definition scanned exhaustively (every start, every arc length, as the authors'
// FastDetector does), on a double-seconds SAE: the baseline eFAST is compared with.
template <size_t N>
bool exhaustive_arc(const double* t, int lo, int hi) {
  for (size_t i = 0; i < N; ++i) {
    for (int s = lo; s <= hi; ++s) {
      if (t[i] < t[(i + N - 1) % N]) continue;
      if (t[(i + s - 1) % N] < t[(i + s) % N]) continue;
      double m = t[i];
      for (int j = 1; j < s; ++j) m = std::min(m, t[(i + j) % N]);
      bool ok = true;
      for (size_t j = s; j < N && ok; ++j) ok = t[(i + j) % N] < m;
      if (ok) return true;
    }
  }
  return false;
}

void BM_EfastExhaustiveScan(benchmark::State& state) {
  const Input& in = input();
  const int w = in.width, h = in.height;
  int64_t corners = 0;
  for (auto _ : state) {
    std::vector<double> sae[2] = {std::vector<double>(w * h, 0.0), std::vector<double>(w * h, 0.0)};
    corners = 0;
    for (const Event& e : in.events) {
      std::vector<double>& s = sae[e.polarity > 0];
      s[e.y * w + e.x] = e.t_ns * 1e-9;
      if (e.x < 4 || e.y < 4 || e.x >= w - 4 || e.y >= h - 4) continue;
      double c3[16], c4[20];
      for (int i = 0; i < 16; ++i) c3[i] = s[(e.y + evio::frontend::kEfastCircle3[i][1]) * w + e.x + evio::frontend::kEfastCircle3[i][0]];
      if (!exhaustive_arc<16>(c3, 3, 6)) continue;
      for (int i = 0; i < 20; ++i) c4[i] = s[(e.y + evio::frontend::kEfastCircle4[i][1]) * w + e.x + evio::frontend::kEfastCircle4[i][0]];
      corners += exhaustive_arc<20>(c4, 4, 8);
    }
    benchmark::DoNotOptimize(corners);
  }
  state.counters["corners"] = static_cast<double>(corners);
  finish(state, in.events.size());
}

void BM_Chain(benchmark::State& state) {
  const Input& in = input();
  const evio::frontend::EventUndistorter und{evio::calib::PinholeCamera(in.intrinsics)};
  int64_t corners = 0;
  for (auto _ : state) {
    evio::frontend::RefractoryFilter refr(in.width, in.height);
    evio::frontend::BackgroundActivityFilter ba(in.width, in.height);
    evio::frontend::EfastDetector d(in.width, in.height);
    corners = 0;
    float sx = 0;
    for (const Event& e : in.events) {
      if (!und.valid(e.x, e.y) || !refr.accept(e) || !ba.accept(e)) continue;
      if (d.process(e)) {
        ++corners;
        sx += und.undistorted(e.x, e.y).x();
      }
    }
    benchmark::DoNotOptimize(sx);
  }
  state.counters["corners"] = static_cast<double>(corners);
  finish(state, in.events.size());
}

// The chain of `evio corners`: lookup, both filters, eFAST, and per corner event a DART
// descriptor (state.range(0) = 1) and the tracker.
void BM_ChainWithTracks(benchmark::State& state) {
  const Input& in = input();
  const evio::frontend::EventUndistorter und{evio::calib::PinholeCamera(in.intrinsics)};
  const evio::frontend::DartExtractor dart{evio::frontend::DartOptions{}};
  evio::frontend::DartDescriptor d;
  int64_t tracks = 0;
  for (auto _ : state) {
    evio::frontend::RefractoryFilter refr(in.width, in.height);
    evio::frontend::BackgroundActivityFilter ba(in.width, in.height);
    evio::frontend::EfastDetector det(in.width, in.height);
    evio::frontend::CornerTracker tracker(in.width, in.height);
    for (const Event& e : in.events) {
      if (!und.valid(e.x, e.y) || !refr.accept(e) || !ba.accept(e) || !det.process(e)) continue;
      const bool has = state.range(0) != 0 && dart.compute(det.sae(), e.x, e.y, e.t_ns, e.polarity, &d);
      tracker.add(e, has ? &d : nullptr);
    }
    tracks = static_cast<int64_t>(tracker.finish().size());
  }
  state.counters["tracks"] = static_cast<double>(tracks);
  finish(state, in.events.size());
}

BENCHMARK(BM_UndistortAndFilters)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_SaeUpdate)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Efast)->Arg(0)->Arg(1)->ArgName("filter_sae")->Unit(benchmark::kMillisecond);
BENCHMARK(BM_EfastExhaustiveScan)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_Chain)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_ChainWithTracks)->Arg(0)->Arg(1)->ArgName("dart")->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
