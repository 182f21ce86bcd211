// Motion-compensated event frames (frontend/event_frame.h), one core: nanoseconds per event to
// group, warp (gyro rotation, optionally translation with depth) and splat events into 240x180
// frames of 15000 events, including the per-frame normalisation, and frames per second.
// Input: a synthetic 240x180 stream (1 M events at 1 M events/s, pixels and polarities from a
// fixed-seed generator) with a 1 kHz gyro turning at 200 deg/s; DAVIS240C intrinsics with radtan
// distortion. Google Benchmark's "items_per_second" is events/s; the "ns_per_event" and
// "frames_per_s" counters are derived from it. One JSON line per result at the end.
// Uniform random pixels touch about 3/4 of the image per frame, a worst case for the per-frame
// normalisation (exact percentile over the non-zero pixels), which is roughly half of the cost
// without compensation; builder construction and IMU buffering are not timed.
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "bench_reporter.h"

#include "evio/calib/geometry.h"
#include "evio/frontend/event_frame.h"

namespace {

using evio::Event;
using evio::ImuSample;
using evio::frontend::EventFrame;
using evio::frontend::EventFrameBuilder;
using evio::frontend::EventFrameOptions;

constexpr int kEvents = 1'000'000;
constexpr int64_t kEventDtNs = 1'000;  // 1 M events/s

evio::calib::CameraCalibration camera() {
  evio::calib::CameraIntrinsics in;
  in.width = 240;
  in.height = 180;
  in.fx = 199.092366542;
  in.fy = 198.82882047;
  in.cx = 132.192071378;
  in.cy = 110.712660011;
  in.model = evio::calib::DistortionModel::kRadtan;
  in.distortion = {-0.368436311798, 0.150947243557, -0.000296130534385, -0.000759431726241};
  evio::calib::CameraCalibration c;
  c.camera = evio::calib::PinholeCamera(in);
  c.T_c_b = evio::calib::SE3(evio::calib::so3_exp(Eigen::Vector3d(0.1, -1.5, 0.2)), Eigen::Vector3d::Zero());
  c.has_T_c_b = true;
  c.time_shift_ns = 1'000'000;
  return c;
}

const std::vector<Event>& events() {
  static const std::vector<Event> ev = [] {
    std::vector<Event> v(kEvents);
    std::mt19937 rng(42);
    std::uniform_int_distribution<int> ux(0, 239), uy(0, 179), up(0, 1);
    for (int i = 0; i < kEvents; ++i) {
      v[i].t_ns = i * kEventDtNs;
      v[i].x = static_cast<uint16_t>(ux(rng));
      v[i].y = static_cast<uint16_t>(uy(rng));
      v[i].polarity = static_cast<int8_t>(up(rng) ? 1 : -1);
    }
    return v;
  }();
  return ev;
}

std::vector<ImuSample> imu() {
  std::vector<ImuSample> v;
  const double rate = 200.0 * M_PI / 180.0;
  for (int64_t t = -10'000'000; t <= kEvents * kEventDtNs + 20'000'000; t += 1'000'000) {
    ImuSample s;
    s.t_ns = t;
    s.gyro = Eigen::Vector3d(0.3, 0.2, 1.0).normalized() * rate;
    v.push_back(s);
  }
  return v;
}

// mode 0: no compensation, 1: rotation, 2: rotation + translation with depth.
void BM_EventFrames(benchmark::State& state) {
  const int mode = static_cast<int>(state.range(0));
  EventFrameOptions o;
  o.motion_compensation = mode >= 1;
  o.use_depth = mode == 2;
  const auto& ev = events();
  const auto samples = imu();
  const auto cam = camera();
  size_t frames = 0;
  for (auto _ : state) {
    state.PauseTiming();  // construction (undistortion table) and IMU buffering not timed
    EventFrameBuilder b(cam, o);
    if (mode == 2) b.set_motion(Eigen::Vector3d(0.5, 0.1, 0.2), 2.0);
    for (const ImuSample& s : samples) b.add_imu(s);
    state.ResumeTiming();
    std::vector<EventFrame> out;
    for (size_t i = 0; i < ev.size(); i += 5000)
      b.add_events(evio::EventSpan(ev.data(), ev.size()).subspan(i, 5000), &out);
    b.flush(&out);
    frames += out.size();
    benchmark::DoNotOptimize(out.data());
  }
  state.SetItemsProcessed(static_cast<int64_t>(state.iterations()) * kEvents);
  state.counters["ns_per_event"] = benchmark::Counter(static_cast<double>(state.iterations()) * kEvents * 1e-9,
                                                      benchmark::Counter::kIsRate | benchmark::Counter::kInvert);
  state.counters["frames_per_s"] = benchmark::Counter(static_cast<double>(frames), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_EventFrames)->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond)->MinTime(2.0);

// The builder's construction alone (undistortion table of 43,200 bearings), for reference:
// not included above.
void BM_BuilderConstruction(benchmark::State& state) {
  const auto cam = camera();
  EventFrameOptions o;
  for (auto _ : state) {
    EventFrameBuilder b(cam, o);
    benchmark::DoNotOptimize(&b);
  }
}
BENCHMARK(BM_BuilderConstruction)->Unit(benchmark::kMillisecond);

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  evio::bench::JsonLinesReporter reporter({{"ns_per_event", "ns_per_event"}, {"frames_per_s", "frames_per_s"}});
  benchmark::RunSpecifiedBenchmarks(&reporter);
  benchmark::Shutdown();
  return 0;
}
