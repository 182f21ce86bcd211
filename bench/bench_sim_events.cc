// EventGenerator::step cost on a 240x180 sensor (one core): ns per pixel-step for a static scene
// (no events), with realistic sensor noise, and for a translating texture (hand-held-like motion
// and fast motion with many events), plus events/s generated. Renders are precomputed, so only
// event generation is timed. Baseline in the same process: one std::log per pixel (the least a
// per-pixel libm implementation has to do). Prints Google Benchmark's table, then one JSON line
// per result.
//   bench_sim_events [--width W] [--height H] [benchmark flags]
#include <benchmark/benchmark.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "bench_reporter.h"
#include "evio/simulator/events.h"

namespace {

int64_t g_width = 240;
int64_t g_height = 180;
constexpr int64_t kStepNs = 1'000'000;  // 1 kHz rendering
constexpr int kFrames = 100;

// A smooth random texture (sum of random sinusoids and Gaussian blobs) sampled at a subpixel
// shift: linear intensity in [0.05, 1.05].
class Texture {
 public:
  explicit Texture(uint64_t seed, double scale) {
    std::mt19937_64 g(seed);
    auto u = [&](double lo, double hi) { return lo + (hi - lo) * static_cast<double>(g() >> 11) * 0x1.0p-53; };
    for (int k = 0; k < 12; ++k) waves_.push_back({u(-0.3, 0.3) * scale, u(-0.3, 0.3) * scale, u(0, 6.3), u(0.2, 1.0)});
    for (int k = 0; k < 16; ++k) blobs_.push_back({u(0, 240), u(0, 180), u(3, 15) / scale, u(-1.5, 1.5)});
  }
  cv::Mat render(int w, int h, double dx, double dy) const {
    cv::Mat m(h, w, CV_32F);
    for (int y = 0; y < h; ++y) {
      float* row = m.ptr<float>(y);
      for (int x = 0; x < w; ++x) {
        const double px = x + dx, py = y + dy;
        double l = 0;
        for (const auto& wv : waves_) l += wv[3] * std::sin(wv[0] * px + wv[1] * py + wv[2]);
        for (const auto& b : blobs_) {
          const double ex = px - b[0], ey = py - b[1];
          l += b[3] * std::exp(-(ex * ex + ey * ey) / (2 * b[2] * b[2]));
        }
        row[x] = static_cast<float>(0.05 + 1.0 / (1.0 + std::exp(-0.8 * l)));
      }
    }
    return m;
  }

 private:
  std::vector<std::array<double, 4>> waves_, blobs_;
};

// Frames of a texture translating at speed_px_s (ping-pong so the sequence can be replayed).
std::vector<cv::Mat> moving_frames(double speed_px_s, double scale) {
  const Texture tex(3, scale);
  std::vector<cv::Mat> f;
  for (int k = 0; k < kFrames; ++k) {
    const double s = speed_px_s * 1e-9 * static_cast<double>(k * kStepNs);
    f.push_back(tex.render(static_cast<int>(g_width), static_cast<int>(g_height), 0.8 * s, 0.6 * s));
  }
  return f;
}

evio::simulator::EventSimOptions realistic_noise() {
  evio::simulator::EventSimOptions o;
  o.threshold_mismatch_std = 0.03;
  o.refractory_ns = 100'000;
  o.shot_noise_rate_hz = 1.0;
  o.leak_rate_hz = 0.1;
  o.hot_pixel_fraction = 0.001;
  o.hot_pixel_rate_hz = 100;
  o.timestamp_jitter_ns = 1000;
  return o;
}

void run_steps(benchmark::State& state, const std::vector<cv::Mat>& frames, const evio::simulator::EventSimOptions& o) {
  const int w = static_cast<int>(g_width), h = static_cast<int>(g_height);
  evio::simulator::EventGenerator gen(w, h, o);
  const int64_t t_begin = 1'700'000'000'000'000'000LL;  // absolute stamps as in recordings
  gen.reset(frames[0], t_begin);
  std::vector<evio::Event> events;
  events.reserve(1 << 20);
  int64_t t = t_begin, k = 0, n_events = 0;
  const int n = static_cast<int>(frames.size());
  for (auto _ : state) {
    ++k;
    const int64_t phase = k % (2 * n - 2);  // ping-pong through the frames
    const cv::Mat& f = frames[phase < n ? phase : 2 * n - 2 - phase];
    t += kStepNs;
    events.clear();
    gen.step(f, t, &events);
    n_events += static_cast<int64_t>(events.size());
    benchmark::DoNotOptimize(events.data());
  }
  state.SetItemsProcessed(n_events);
  state.counters["pixel_steps"] = benchmark::Counter(static_cast<double>(w) * h, benchmark::Counter::kIsIterationInvariantRate);
  state.counters["events_per_step"] = benchmark::Counter(static_cast<double>(n_events) / static_cast<double>(state.iterations()));
  state.counters["sim_s_per_wall_s"] = benchmark::Counter(kStepNs * 1e-9, benchmark::Counter::kIsIterationInvariantRate);
}

std::vector<cv::Mat> g_static, g_handheld, g_fast;

void static_no_events(benchmark::State& state) { run_steps(state, g_static, evio::simulator::EventSimOptions()); }
void static_noise(benchmark::State& state) { run_steps(state, g_static, realistic_noise()); }
void handheld_motion(benchmark::State& state) { run_steps(state, g_handheld, realistic_noise()); }
void fast_motion_many_events(benchmark::State& state) { run_steps(state, g_fast, realistic_noise()); }

void std_log_baseline(benchmark::State& state) {
  const cv::Mat& f = g_handheld[1];
  const int n = static_cast<int>(g_width * g_height);
  std::vector<double> out(n);
  for (auto _ : state) {
    const float* in = f.ptr<float>();
    for (int i = 0; i < n; ++i) out[i] = std::log(static_cast<double>(in[i]) + 1e-3);
    benchmark::DoNotOptimize(out.data());
  }
  state.SetItemsProcessed(0);
  state.counters["pixel_steps"] = benchmark::Counter(n, benchmark::Counter::kIsIterationInvariantRate);
}

class Reporter : public evio::bench::CollectingReporter {
 public:
  std::map<std::string, std::map<std::string, double>> counters;
  void ReportRuns(const std::vector<Run>& runs) override {
    CollectingReporter::ReportRuns(runs);
    for (const Run& r : runs)
      for (const auto& [k, c] : r.counters) counters[r.run_name.function_name][k] = c.value;
  }
};

}  // namespace

int main(int argc, char** argv) {
  evio::bench::take_int_flag(&argc, argv, "--width", &g_width);
  evio::bench::take_int_flag(&argc, argv, "--height", &g_height);
  std::fprintf(stderr, "rendering %d frames of %lldx%lld ...\n", kFrames, static_cast<long long>(g_width),
               static_cast<long long>(g_height));
  g_static.assign(2, Texture(3, 1.0).render(static_cast<int>(g_width), static_cast<int>(g_height), 0, 0));
  g_handheld = moving_frames(200.0, 1.0);  // 0.2 px per 1 ms step
  g_fast = moving_frames(1500.0, 2.5);     // 1.5 px per step over a finer texture
  for (const char* name : {"static_no_events", "static_noise", "handheld_motion", "fast_motion_many_events"}) {
    void (*fn)(benchmark::State&) = std::string(name) == "static_no_events" ? static_no_events
                                    : std::string(name) == "static_noise"   ? static_noise
                                    : std::string(name) == "handheld_motion" ? handheld_motion
                                                                             : fast_motion_many_events;
    benchmark::RegisterBenchmark((std::string("sim_events/") + name).c_str(), fn)
        ->Unit(benchmark::kMicrosecond)->MinTime(1.0)->UseRealTime();
  }
  benchmark::RegisterBenchmark("sim_events/std_log_baseline", std_log_baseline)
      ->Unit(benchmark::kMicrosecond)->MinTime(0.5)->UseRealTime();
  benchmark::Initialize(&argc, argv);
  Reporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  const double base_rate = reporter.counters["sim_events/std_log_baseline"]["pixel_steps"];
  for (const auto& [name, c] : reporter.counters) {
    const double ps = c.count("pixel_steps") ? c.at("pixel_steps") : 0.0;
    const double ns_pp = ps > 0 ? 1e9 / ps : 0.0;
    std::printf("{\"bench\": \"%s\", \"width\": %lld, \"height\": %lld, \"ns_per_pixel_step\": %.4g, "
                "\"us_per_step\": %.4g, \"events_per_step\": %.4g, \"events_per_s\": %.4g, "
                "\"sim_s_per_wall_s\": %.4g, \"speed_vs_std_log_pass\": %.3g}\n",
                name.c_str(), static_cast<long long>(g_width), static_cast<long long>(g_height), ns_pp,
                ns_pp * static_cast<double>(g_width * g_height) * 1e-3,
                c.count("events_per_step") ? c.at("events_per_step") : 0.0, reporter.rate[name],
                c.count("sim_s_per_wall_s") ? c.at("sim_s_per_wall_s") : 0.0,
                base_rate > 0 && ps > 0 ? ps / base_rate : 0.0);
  }
  return 0;
}
