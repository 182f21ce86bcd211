// Rotation particle filter (frontend/rotation_particle_filter.h), one core: time per event and per
// particle of update() (prediction, likelihood, weights, mean, resampling, per-pixel state) on the
// known-map scenario of tests/frontend/panorama_rotation_scenario.h (240x180 pinhole, 1024x512
// map, 150 deg/s peak, 0.2 s, about 0.8 M events/s; the filter starts at the true rotation with
// the per-pixel state empty, so the first event of each pixel is only bookkept).
// Counters: ns_per_event_particle = wall time / (events * N); ns_per_used_event_particle divides
// by the events that weighted the particles instead; rt_factor = filter time / sequence duration
// (below 1: faster than real time for this stream). Google Benchmark's items_per_second is
// events/s. Arguments: particles N x batch size. One JSON line per result at the end.
#include <cstdio>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "bench_reporter.h"

#include "panorama_rotation_scenario.h"

namespace {

using namespace evio::frontend;

const test::PanoramaScenario& scenario() {
  static const test::PanoramaScenario s = [] {
    test::PanoramaScenarioConfig c;
    c.peak_speed_deg_s = 150;
    c.duration_s = 0.2;
    return test::make_panorama_scenario(c);
  }();
  return s;
}

void BM_Update(benchmark::State& state) {
  const test::PanoramaScenario& s = scenario();
  RotationParticleFilterOptions o;
  o.num_particles = static_cast<int>(state.range(0));
  o.batch_size = static_cast<int>(state.range(1));
  RotationParticleFilter pf(s.sensor_width, s.sensor_height, s.bearings, o);
  int64_t used = 0;
  for (auto _ : state) {
    state.PauseTiming();
    pf.reset(s.truth_at(0), 0);
    state.ResumeTiming();
    pf.update(s.events, s.view());
    pf.flush(s.view());
    used += pf.stats().events_used;
    benchmark::DoNotOptimize(pf.mean());
  }
  const double events = static_cast<double>(s.events.size()) * static_cast<double>(state.iterations());
  state.SetItemsProcessed(static_cast<int64_t>(events));
  const double n = static_cast<double>(o.num_particles);
  state.counters["ns_per_event_particle"] =
      benchmark::Counter(events * n * 1e-9, benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
  state.counters["ns_per_used_event_particle"] =
      benchmark::Counter(static_cast<double>(used) * n * 1e-9, benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
  state.counters["rt_factor"] = benchmark::Counter(
      1e-9 * static_cast<double>(s.end_ns()) * static_cast<double>(state.iterations()),
      benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_Update)
    ->ArgsProduct({{100, 300, 1000, 3000}, {1, 10, 100}})
    ->ArgNames({"N", "batch"})
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1);
// The default options (N = 100, batch 10), repeated for a stable events/s.
BENCHMARK(BM_Update)->Args({100, 10})->ArgNames({"N", "batch"})->Unit(benchmark::kMillisecond)->MinTime(2.0);

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  evio::bench::JsonLinesReporter reporter({{"ns_per_event_particle", "ns_per_event_particle"}, {"items_per_second", "events_per_s"}});
  benchmark::RunSpecifiedBenchmarks(&reporter);
  benchmark::Shutdown();
  return 0;
}
