// Panorama mosaicing, mapping half (mapping/poisson.h, mapping/gradient_mosaic.h), one core
// (OpenCV's threads set to 1): full Poisson solve time for 1024x512 and 2048x1024 mosaics with
// both boundary kinds (double and float), the region (incremental) solve of a 128x128 rectangle
// on a 1024x512 mosaic, and the EKF update in ns per event at random positions of a 1024x512
// mosaic with random velocities, and the final reconstruction of a partially seen 1024x512 mosaic
// (GradientMosaic::reconstruct kFull) unweighted and weighted (weighted_poisson.h) with each
// preconditioner. Inputs: fixed-seed random gradient fields; for the reconstruction, an EKF mosaic
// fed with noisy brightness-constancy measurements of a smooth field over a 360 x 300 px patch
// (20 % of the texels, like 3 s of poster_rotation). One JSON line per result at the end
// ("ms_per_solve" or "ns_per_event"; "pcg_iterations" for the weighted solves).
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "bench_reporter.h"
#include <opencv2/core.hpp>

#include "evio/mapping/gradient_mosaic.h"
#include "evio/mapping/poisson.h"
#include "evio/mapping/weighted_poisson.h"

namespace {

using evio::mapping::ImageD;
using evio::mapping::ImageF;
using evio::mapping::PoissonBoundary;

ImageD random_image(int W, int H, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> N(0.0, 0.1);
  ImageD g(H, W);
  for (Eigen::Index k = 0; k < g.size(); ++k) g.data()[k] = N(rng);
  return g;
}

// Args: width, height, boundary (0 Neumann, 1 periodic-u), precision (0 double, 1 float).
void BM_PoissonFull(benchmark::State& state) {
  const int W = static_cast<int>(state.range(0)), H = static_cast<int>(state.range(1));
  evio::mapping::PoissonOptions o;
  o.boundary = state.range(2) ? PoissonBoundary::kPeriodicU : PoissonBoundary::kNeumann;
  const evio::mapping::PoissonSolver solver(W, H, o);
  const ImageD gx = random_image(W, H, 1), gy = random_image(W, H, 2);
  if (state.range(3) == 0) {
    ImageD L;
    for (auto _ : state) {
      solver.solve(gx, gy, &L);
      benchmark::DoNotOptimize(L.data());
    }
  } else {
    const ImageF gxf = gx.cast<float>(), gyf = gy.cast<float>();
    ImageF L;
    for (auto _ : state) {
      solver.solve(gxf, gyf, &L);
      benchmark::DoNotOptimize(L.data());
    }
  }
  state.counters["ms_per_solve"] =
      benchmark::Counter(static_cast<double>(state.iterations()) * 1e-3, benchmark::Counter::kIsRate |
                                                                               benchmark::Counter::kInvert);
}
BENCHMARK(BM_PoissonFull)
    ->ArgNames({"W", "H", "periodic", "float"})
    ->Args({1024, 512, 0, 0})
    ->Args({1024, 512, 1, 0})
    ->Args({1024, 512, 0, 1})
    ->Args({1024, 512, 1, 1})
    ->Args({2048, 1024, 0, 0})
    ->Args({2048, 1024, 1, 0})
    ->Args({2048, 1024, 0, 1})
    ->Args({2048, 1024, 1, 1})
    ->Unit(benchmark::kMillisecond);

// Region solve: side x side rectangle straddling the seam of a 1024x512 periodic mosaic.
void BM_PoissonRegion(benchmark::State& state) {
  const int W = 1024, H = 512, side = static_cast<int>(state.range(0));
  const evio::mapping::PoissonSolver solver(W, H, {});
  const ImageD gx = random_image(W, H, 3), gy = random_image(W, H, 4);
  ImageD L;
  solver.solve(gx, gy, &L);
  const evio::mapping::PixelRect rect{W - side / 2, 200, side, side};
  for (auto _ : state) {
    solver.solve_region(gx, gy, rect, &L);
    benchmark::DoNotOptimize(L.data());
  }
  state.counters["ms_per_solve"] =
      benchmark::Counter(static_cast<double>(state.iterations()) * 1e-3, benchmark::Counter::kIsRate |
                                                                               benchmark::Counter::kInvert);
}
BENCHMARK(BM_PoissonRegion)->ArgName("side")->Arg(64)->Arg(128)->Arg(256)->Unit(benchmark::kMillisecond);

// EKF update at random positions (cache-unfriendly, like events spread over the mosaic).
void BM_EkfUpdate(benchmark::State& state) {
  evio::mapping::GradientMosaicOptions o;  // 1024 x 512
  evio::mapping::GradientMosaic mosaic(o);
  constexpr int kN = 1 << 20;
  std::vector<Eigen::Vector2d> uv(kN), v(kN);
  std::vector<double> tau(kN);
  std::vector<int> pol(kN);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  for (int k = 0; k < kN; ++k) {
    uv[k] = {U(rng) * o.width, U(rng) * o.height};
    const double a = 2 * M_PI * U(rng), s = 50 + 500 * U(rng);
    v[k] = {s * std::cos(a), s * std::sin(a)};
    tau[k] = 1e-4 + 0.05 * U(rng);
    pol[k] = U(rng) < 0.5 ? 1 : -1;
  }
  size_t k = 0, applied = 0;
  for (auto _ : state) {
    applied += mosaic.update(uv[k], v[k], tau[k], pol[k]);
    k = (k + 1) & (kN - 1);
  }
  benchmark::DoNotOptimize(applied);
  state.SetItemsProcessed(static_cast<int64_t>(state.iterations()));
  state.counters["ns_per_event"] = benchmark::Counter(static_cast<double>(state.iterations()) * 1e-9,
                                                      benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
}
BENCHMARK(BM_EkfUpdate);

// A 1024x512 EKF mosaic, 20 % seen: 30 measurements per texel of a 360 x 300 px patch, each the
// exact 1/tau of a smooth field's gradient with 10 % multiplicative noise (random velocities).
evio::mapping::GradientMosaic partially_seen_mosaic(const evio::mapping::GradientMosaicOptions& o) {
  evio::mapping::GradientMosaic m(o);
  std::mt19937 rng(9);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  std::normal_distribution<double> N(0.0, 0.1);
  auto grad = [&](double u, double v) {
    Eigen::Vector2d g = Eigen::Vector2d::Zero();
    const double a[3] = {0.8, 0.4, 0.3}, fu[3] = {3, 11, 29}, fv[3] = {2.3, 7.1, 19.0}, ph[3] = {0.1, 1.3, 2.2};
    for (int k = 0; k < 3; ++k) {
      const double wu = 2 * M_PI * fu[k] / o.width, wv = 2 * M_PI * fv[k] / o.height;
      g += a[k] * std::cos(wu * u + wv * v + ph[k]) * Eigen::Vector2d(wu, wv);
    }
    return g;
  };
  for (int rep = 0; rep < 30; ++rep)
    for (int j = 100; j < 400; ++j)
      for (int i = 300; i < 660; ++i) {
        const Eigen::Vector2d uv(i + U(rng), j + U(rng));
        const double ang = 2 * M_PI * U(rng), speed = 50 + 450 * U(rng);
        const Eigen::Vector2d v(speed * std::cos(ang), speed * std::sin(ang));
        const double gv = grad(uv.x(), uv.y()).dot(v) * (1 + N(rng));
        if (std::abs(gv) < 1e-9) continue;
        m.update(uv, v, o.contrast_threshold / std::abs(gv), gv > 0 ? 1 : -1);
      }
  return m;
}

// Args: weighted (0 = unweighted spectral solve, 1 = weighted), preconditioner (weighted only).
void BM_MosaicFinalReconstruction(benchmark::State& state) {
  evio::mapping::GradientMosaicOptions o;  // 1024 x 512, weighted_poisson defaults
  o.weighted_poisson.preconditioner = static_cast<evio::mapping::PoissonPreconditioner>(state.range(1));
  const evio::mapping::GradientMosaic filled = partially_seen_mosaic(o);
  const auto weighting =
      state.range(0) ? evio::mapping::PoissonWeighting::kInformation : evio::mapping::PoissonWeighting::kNone;
  int iterations = 0;
  for (auto _ : state) {
    state.PauseTiming();
    evio::mapping::GradientMosaic m = filled;  // no solve yet
    state.ResumeTiming();
    const evio::mapping::MosaicReconstruction r = m.reconstruct(evio::mapping::GradientMosaic::ReconstructMode::kFull, weighting);
    iterations = r.weighted_stats.iterations;
    benchmark::DoNotOptimize(r.log_intensity.data());
  }
  state.SetLabel(state.range(0) ? evio::mapping::poisson_preconditioner_name(o.weighted_poisson.preconditioner)
                                 : "unweighted");
  state.counters["pcg_iterations"] = iterations;
  state.counters["ms_per_solve"] =
      benchmark::Counter(static_cast<double>(state.iterations()) * 1e-3, benchmark::Counter::kIsRate |
                                                                               benchmark::Counter::kInvert);
}
BENCHMARK(BM_MosaicFinalReconstruction)
    ->ArgNames({"weighted", "preconditioner"})
    ->Args({0, 0})
    ->Args({1, static_cast<int>(evio::mapping::PoissonPreconditioner::kJacobi)})
    ->Args({1, static_cast<int>(evio::mapping::PoissonPreconditioner::kSpectral)})
    ->Args({1, static_cast<int>(evio::mapping::PoissonPreconditioner::kScaledSpectral)})
    ->Unit(benchmark::kMillisecond)
    ->Iterations(3);

}  // namespace

int main(int argc, char** argv) {
  cv::setNumThreads(1);  // one core, as stated above
  benchmark::Initialize(&argc, argv);
  evio::bench::JsonLinesReporter reporter({{"ms_per_solve", "ms_per_solve"}, {"ns_per_event", "ns_per_event"}, {"pcg_iterations", "pcg_iterations"}});
  benchmark::RunSpecifiedBenchmarks(&reporter);
  benchmark::Shutdown();
  return 0;
}
