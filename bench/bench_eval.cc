// Trajectory evaluation of a 1-hour, 200 Hz trajectory pair (720,000 poses each): association,
// se3 alignment, ATE and RPE at the default 10..50% lengths. Issue target: under one second.
#include <cmath>
#include <random>

#include <benchmark/benchmark.h>

#include "evio/evaluation/trajectory_evaluation.h"

namespace {

void make_pair(evio::Trajectory* gt, evio::Trajectory* est) {
  const size_t n = 3600 * 200;
  std::vector<evio::StampedPose> g, e;
  g.reserve(n);
  e.reserve(n);
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0.0, 0.01);
  const int64_t t0 = 1700000000000000000LL;
  for (size_t k = 0; k < n; ++k) {
    const double s = static_cast<double>(k) / 200.0;
    const Eigen::Vector3d p(20 * std::cos(0.01 * s), 15 * std::sin(0.013 * s), 2 + std::sin(0.05 * s));
    const auto q = evio::calib::so3_exp_quat(Eigen::Vector3d(0.1 * std::sin(0.2 * s), 0.1 * std::cos(0.3 * s), 0.02 * s));
    g.push_back({t0 + static_cast<int64_t>(k) * 5000000, evio::calib::SE3(q, p)});
    const Eigen::Vector3d dp(noise(rng), noise(rng), noise(rng));
    const auto dq = evio::calib::so3_exp_quat(Eigen::Vector3d(noise(rng), noise(rng), noise(rng)) * 0.1);
    // Estimate stamps 1 ms late (within max_dt), noisy poses.
    e.push_back({t0 + static_cast<int64_t>(k) * 5000000 + 1000000, evio::calib::SE3(q * dq, p + dp)});
  }
  *gt = evio::Trajectory(std::move(g));
  *est = evio::Trajectory(std::move(e));
}

void BM_Evaluate1h200Hz(benchmark::State& state) {
  evio::Trajectory gt, est;
  make_pair(&gt, &est);
  evio::evaluation::EvaluationOptions o;
  o.alignment.method = evio::evaluation::Alignment::kSE3;
  size_t matched = 0;
  for (auto _ : state) {
    const auto r = evio::evaluation::evaluate(gt, est, o);
    matched = r.matched_poses;
    benchmark::DoNotOptimize(r.ate.trans_m.rmse);
  }
  state.counters["poses"] = static_cast<double>(matched);
}
BENCHMARK(BM_Evaluate1h200Hz)->Unit(benchmark::kMillisecond)->Iterations(3);

}  // namespace

BENCHMARK_MAIN();
