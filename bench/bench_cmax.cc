// Contrast maximisation on the real ECD 10 ms window (../shared/data/real/ecd_dynamic_10ms, or
// $EVIO_REAL_DATA; ~19k sub-pixel undistorted events): ContrastMaximizer::maximize from zero for
// the flow and the rotation model per pyramid-level count (the time `evio flow` spends on the
// window), a warm start one level deep from near the optimum (what a streaming window costs), and
// one objective + gradient evaluation at level 0 (the unit the maximiser's cost is made of).
// maximize from zero also with max_events_coarse (the coarse levels on an even subset of the
// events). Single thread. Counters: ns/ev = wall time per call per event of the window, ns;
// evals and iters = objective evaluations (all levels) and BFGS iterations per call; gain =
// objective at the result / at zero (same gain, same optimum).
// One JSON line per result at the end.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <sys/stat.h>
#include <vector>

#include <benchmark/benchmark.h>

#include "bench_reporter.h"
#include "evio/mapping/cmax.h"
#include "evio/sensors/dataset.h"

namespace {

using evio::mapping::CmaxEvents;
using evio::mapping::CmaxOptions;
using evio::mapping::ContrastMaximizer;
using evio::mapping::WarpModel;

struct Window {
  bool ok = false;
  CmaxEvents events;
  CmaxOptions options;  // the defaults of `evio flow` on the dataset's camera
};

const Window& window() {
  static const Window w = [] {
    Window r;
    const char* env = std::getenv("EVIO_REAL_DATA");
    const std::string root = env ? env : std::string(EVIO_SOURCE_DIR) + "/../shared/data/real";
    const std::string dir = root + "/ecd_dynamic_10ms";
    struct stat st;
    if (stat(dir.c_str(), &st) != 0) return r;
    auto reader = evio::open_dataset(dir);
    std::vector<evio::SubpixelEvent> ev;
    while (reader->read_subpixel_events(&ev, 1 << 16) > 0) {
    }
    const auto cal = reader->read_calibration();
    if (!cal || ev.empty()) return r;
    const auto& k = cal->camera.intrinsics();
    r.options.width = k.width;
    r.options.height = k.height;
    r.options.geometry.fx = k.fx, r.options.geometry.fy = k.fy, r.options.geometry.cx = k.cx, r.options.geometry.cy = k.cy;
    r.events = CmaxEvents(ev.front().t_ns + (ev.back().t_ns - ev.front().t_ns) / 2, r.options.geometry);
    for (const auto& e : ev) r.events.push_back(e.x, e.y, e.t_ns, e.polarity);
    r.ok = true;
    return r;
  }();
  return w;
}

using Clock = std::chrono::steady_clock;

// total_s: wall time summed over the benchmark's iterations.
void set_counters(benchmark::State& state, double total_s, double evals, double iters) {
  const double n = static_cast<double>(window().events.size());
  state.counters["ns/ev"] = 1e9 * total_s / static_cast<double>(state.iterations()) / n;
  state.counters["evals"] = evals;
  state.counters["iters"] = iters;
  state.counters["events"] = n;
  state.SetItemsProcessed(static_cast<int64_t>(state.iterations()) * static_cast<int64_t>(n));
}

void BM_Evaluate(benchmark::State& state) {
  const Window& w = window();
  if (!w.ok) return state.SkipWithError("ecd_dynamic_10ms not found ($EVIO_REAL_DATA or ../shared/data/real)");
  CmaxOptions o = w.options;
  o.model = static_cast<WarpModel>(state.range(0));
  ContrastMaximizer m(o);
  const Eigen::VectorXd p = Eigen::VectorXd::Constant(evio::mapping::warp_dof(o.model), 0.1);
  Eigen::VectorXd g;
  double f = 0, total_s = 0;
  for (auto _ : state) {
    const auto t0 = Clock::now();
    f += m.objective(w.events, p, 0, nullptr, &g);
    benchmark::DoNotOptimize(g.data());
    total_s += std::chrono::duration<double>(Clock::now() - t0).count();
  }
  benchmark::DoNotOptimize(&f);
  set_counters(state, total_s, 1, 0);
  state.SetLabel(evio::mapping::warp_model_name(o.model));
}

void BM_MaximizeFromZero(benchmark::State& state) {
  const Window& w = window();
  if (!w.ok) return state.SkipWithError("ecd_dynamic_10ms not found ($EVIO_REAL_DATA or ../shared/data/real)");
  CmaxOptions o = w.options;
  o.model = static_cast<WarpModel>(state.range(0));
  o.pyramid_levels = static_cast<int>(state.range(1));
  o.max_events_coarse = static_cast<int>(state.range(2));
  ContrastMaximizer m(o);
  evio::mapping::CmaxResult r;
  double total_s = 0;
  for (auto _ : state) {
    const auto t0 = Clock::now();
    r = m.maximize(w.events);
    benchmark::DoNotOptimize(r.params.data());  // (DoNotOptimize on a double corrupts it with this benchmark version)
    total_s += std::chrono::duration<double>(Clock::now() - t0).count();
  }
  set_counters(state, total_s, r.evaluations, r.iterations);
  state.counters["gain"] = r.objective / r.objective_zero;
  state.SetLabel(std::string(evio::mapping::warp_model_name(o.model)) + ", " + std::to_string(o.pyramid_levels) + " levels" +
                 (o.max_events_coarse > 0 ? ", coarse levels " + std::to_string(o.max_events_coarse) + " events" : ""));
}

// From the optimum moved by ~2 px at the window's ends, one level: a streaming window's warm start.
void BM_MaximizeWarm(benchmark::State& state) {
  const Window& w = window();
  if (!w.ok) return state.SkipWithError("ecd_dynamic_10ms not found ($EVIO_REAL_DATA or ../shared/data/real)");
  CmaxOptions o = w.options;
  o.model = static_cast<WarpModel>(state.range(0));
  const Eigen::VectorXd best = ContrastMaximizer(o).maximize(w.events).params;
  o.pyramid_levels = 1;
  ContrastMaximizer m(o);
  const Eigen::VectorXd init = best + Eigen::VectorXd::Constant(best.size(), o.model == WarpModel::kFlow ? 300.0 : 1.5);
  evio::mapping::CmaxResult r;
  double total_s = 0;
  for (auto _ : state) {
    const auto t0 = Clock::now();
    r = m.maximize(w.events, init);
    benchmark::DoNotOptimize(r.params.data());
    total_s += std::chrono::duration<double>(Clock::now() - t0).count();
  }
  set_counters(state, total_s, r.evaluations, r.iterations);
  state.counters["gain"] = r.objective / r.objective_zero;
  state.SetLabel(std::string(evio::mapping::warp_model_name(o.model)) + ", warm, 1 level");
}

BENCHMARK(BM_Evaluate)->Arg(static_cast<int>(WarpModel::kFlow))->Arg(static_cast<int>(WarpModel::kRotation))->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_MaximizeFromZero)
    ->ArgsProduct({{static_cast<int>(WarpModel::kFlow), static_cast<int>(WarpModel::kRotation)}, {1, 2, 3, 4}, {0}})
    ->ArgsProduct({{static_cast<int>(WarpModel::kFlow), static_cast<int>(WarpModel::kRotation)}, {2, 3}, {2000, 5000}})
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_MaximizeWarm)->Arg(static_cast<int>(WarpModel::kFlow))->Arg(static_cast<int>(WarpModel::kRotation))->Unit(benchmark::kMillisecond);

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  evio::bench::JsonLinesReporter reporter({{"ns/ev", "ns_per_event"}, {"evals", "evaluations"}, {"iters", "iterations"}, {"gain", "objective_gain"}});
  benchmark::RunSpecifiedBenchmarks(&reporter);
  benchmark::Shutdown();
  return 0;
}
