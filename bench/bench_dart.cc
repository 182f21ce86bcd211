// DART costs: compute() on a realistic SAE (a DAVIS240 surface filled by replaying a synthetic
// stream of moving corners and edges plus background noise, descriptors taken at recent corner
// events), dart_distance with the full shift search (12 wedges x (whole + half) x 5 ring shifts),
// and dart_match against 10 and 100 candidates. Default options.
#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include <benchmark/benchmark.h>

#include "evio/frontend/dart.h"

namespace {

using evio::Event;
using namespace evio::frontend;

struct Scene {
  SurfaceOfActiveEvents sae{240, 180};
  std::vector<Event> probes;  // recent events on structure, where descriptors are taken
  int64_t t_end = 0;
};

// 40 L-shaped corners (two 12 px arms at random orientation) drifting at 50..300 px/s for 0.2 s,
// rasterised every 0.5 ms, plus 20k uniformly random noise events.
Scene make_scene() {
  Scene s;
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  struct Corner { double x, y, vx, vy, a, b; };
  std::vector<Corner> cs;
  for (int i = 0; i < 40; ++i) {
    const double sp = 50 + 250 * u(rng), dir = 2 * M_PI * u(rng), a = 2 * M_PI * u(rng);
    cs.push_back({20 + 200 * u(rng), 20 + 140 * u(rng), sp * std::cos(dir), sp * std::sin(dir), a, a + 0.5 * M_PI + u(rng)});
  }
  const int64_t dt = 500'000;
  std::vector<Event> noise;
  for (int i = 0; i < 20000; ++i) {
    Event e;
    e.t_ns = static_cast<int64_t>(u(rng) * 2e8);
    e.x = static_cast<uint16_t>(u(rng) * 240);
    e.y = static_cast<uint16_t>(u(rng) * 180);
    e.polarity = u(rng) < 0.5 ? 1 : -1;
    noise.push_back(e);
  }
  std::sort(noise.begin(), noise.end(), [](const Event& a, const Event& b) { return a.t_ns < b.t_ns; });
  size_t ni = 0;
  for (int64_t t = 0; t <= 200'000'000; t += dt) {
    while (ni < noise.size() && noise[ni].t_ns <= t) s.sae.update(noise[ni++]);
    for (const Corner& c : cs) {
      const double ts = t * 1e-9;
      const double cx = c.x + c.vx * ts, cy = c.y + c.vy * ts;
      for (double arm : {c.a, c.b})
        for (double l = 0; l < 12; l += 0.7) {
          const int x = static_cast<int>(std::lround(cx + l * std::cos(arm)));
          const int y = static_cast<int>(std::lround(cy - l * std::sin(arm)));
          if (!s.sae.contains(x, y)) continue;
          Event e;
          e.t_ns = t;
          e.x = static_cast<uint16_t>(x);
          e.y = static_cast<uint16_t>(y);
          e.polarity = arm == c.a ? 1 : -1;
          s.sae.update(e);
          if (t == 200'000'000 && l == 0) s.probes.push_back(e);
        }
    }
  }
  s.t_end = 200'000'000;
  return s;
}

const Scene& scene() {
  static const Scene s = make_scene();
  return s;
}

std::vector<DartDescriptor> descriptors(size_t n) {
  const Scene& s = scene();
  const DartExtractor ex(DartOptions{});
  std::vector<DartDescriptor> out;
  std::mt19937 rng(7);
  while (out.size() < n) {
    const Event& e = s.probes[out.size() % s.probes.size()];
    DartDescriptor d;
    // Vary the centre a little so the candidates differ.
    const int x = std::clamp<int>(e.x + static_cast<int>(rng() % 7) - 3, 0, 239);
    const int y = std::clamp<int>(e.y + static_cast<int>(rng() % 7) - 3, 0, 179);
    if (ex.compute(s.sae, x, y, s.t_end, e.polarity, &d)) out.push_back(d);
  }
  return out;
}

void BM_DartCompute(benchmark::State& state) {
  const Scene& s = scene();
  DartOptions o;
  o.binning = state.range(0) ? DartBinning::kSoft : DartBinning::kHard;
  const DartExtractor ex(o);
  DartDescriptor d;
  size_t i = 0;
  int64_t counted = 0;
  for (auto _ : state) {
    const Event& e = s.probes[i++ % s.probes.size()];
    benchmark::DoNotOptimize(ex.compute(s.sae, e.x, e.y, s.t_end, e.polarity, &d));
    counted += d.recent_pixels;
  }
  state.SetItemsProcessed(state.iterations());
  state.counters["recent_px_per_desc"] = static_cast<double>(counted) / static_cast<double>(state.iterations());
  state.counters["grid_px"] = static_cast<double>(ex.lookup_table().size());
  state.SetLabel(state.range(0) ? "soft (default)" : "hard");
}
BENCHMARK(BM_DartCompute)->Arg(1)->Arg(0);

void BM_DartDistance(benchmark::State& state) {
  const auto ds = descriptors(64);
  size_t i = 0;
  for (auto _ : state) {
    DartShift sh;
    benchmark::DoNotOptimize(dart_distance(ds[i % 64], ds[(i * 7 + 3) % 64], &sh));
    ++i;
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_DartDistance);

void BM_DartMatch(benchmark::State& state) {
  const size_t n = static_cast<size_t>(state.range(0));
  const auto all = descriptors(n + 32);
  const std::vector<DartDescriptor> cands(all.begin(), all.begin() + static_cast<long>(n));
  size_t i = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(dart_match(all[n + i % 32], cands, 0.8f));
    ++i;
  }
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_DartMatch)->Arg(10)->Arg(100);

}  // namespace

BENCHMARK_MAIN();
