// Image reconstruction from events (mapping/reconstruction.h), one core: the complementary filter
// without and with APS frames (BM_ComplementaryFilter/frames:0 and /frames:1), the asynchronous
// Kalman filter, the asynchronous convolution state (async_convolution.h: a Sobel x/y pair, 3x3
// and 5x5, events only: BM_AsyncConvolution/size:3|5) and the event Harris corner path on top of it
// (event_harris.h: gradient state, structure tensor around the event, response and NMS:
// BM_EventHarris), and as a same-process baseline the published complementary-filter equations run
// the straightforward way (per event exp() and double state; per frame a global update with one
// exp() per pixel, as dvs_image_reconstruction's offline loop does, without ROS).
// Input: the real ECD slice (../shared/data/real/ecd_slider_depth_head, or $EVIO_REAL_DATA, 50,000
// events over 0.174 s, 5 APS frames) repeated to 5 M events, copies shifted by 0.176 s, with the
// slice's frames repeated with them (500 frames, decoded once before timing); without the slice a
// synthetic stream (the label says which). Each iteration builds the filter, runs every event and
// frame in time order and reads the image at the end. The "ns/ev" column is nanoseconds per event
// (Google Benchmark prints an inverted rate with an "s" suffix: "4.1s" reads 4.1 ns per event).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <sys/stat.h>
#include <vector>

#include <benchmark/benchmark.h>

#include "bench_reporter.h"
#include "evio/mapping/async_convolution.h"
#include "evio/mapping/event_harris.h"
#include "evio/mapping/reconstruction.h"
#include "evio/sensors/ecd.h"

namespace {

using evio::Event;
using evio::mapping::GreyView;

constexpr size_t kEvents = 5'000'000;
constexpr int64_t kShiftNs = 176'000'000;

struct Input {
  std::vector<Event> events;
  std::vector<int64_t> frame_t;
  std::vector<std::vector<uint8_t>> frames;  // 240 x 180
  std::vector<size_t> frame_at;              // index of the first event after each frame
  std::string label;
  int width = 240, height = 180;
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
    std::vector<std::pair<int64_t, std::vector<uint8_t>>> base_frames;
    if (exists(dir + "/events.txt")) {
      const evio::EventBuffer b = evio::read_ecd_events(dir + "/events.txt");
      base.assign(b.begin(), b.end());
      for (evio::Frame f : evio::read_ecd_image_list(dir + "/images.txt")) {
        if (f.t_ns >= kShiftNs) break;
        evio::load_frame_image(&f);
        std::vector<uint8_t> px;
        for (int y = 0; y < f.image.rows; ++y) px.insert(px.end(), f.image.ptr<uint8_t>(y), f.image.ptr<uint8_t>(y) + f.image.cols);
        base_frames.emplace_back(f.t_ns, std::move(px));
      }
      r.label = "real ECD slider_depth slice";
    } else {
      uint32_t s = 1;
      for (int k = 0; k < 50000; ++k) {
        s = s * 1664525u + 1013904223u;
        base.push_back({3'000 + k * 3'400LL, static_cast<uint16_t>((s >> 8) % 240), static_cast<uint16_t>((s >> 20) % 180),
                        static_cast<int8_t>((s & 1) ? 1 : -1)});
      }
      for (int k = 0; k < 5; ++k) base_frames.emplace_back(k * 38'766'000LL, std::vector<uint8_t>(240 * 180, static_cast<uint8_t>(60 + 30 * k)));
      r.label = "synthetic random stream";
    }
    const size_t reps = (kEvents + base.size() - 1) / base.size();
    r.events.reserve(kEvents);
    for (size_t k = 0; k < reps; ++k) {
      const int64_t shift = static_cast<int64_t>(k) * kShiftNs;
      for (const auto& [t, px] : base_frames) {
        r.frame_t.push_back(t + shift);
        r.frames.push_back(px);
        r.frame_at.push_back(r.events.size());  // the slice's frames precede its events
      }
      for (const Event& e : base) {
        if (r.events.size() == kEvents) break;
        Event f = e;
        f.t_ns += shift;
        r.events.push_back(f);
      }
    }
    // A frame goes before the first event after it.
    for (size_t i = 0; i < r.frame_t.size(); ++i)
      r.frame_at[i] = static_cast<size_t>(std::upper_bound(r.events.begin(), r.events.end(), r.frame_t[i],
                                                           [](int64_t t, const Event& e) { return t < e.t_ns; }) -
                                          r.events.begin());
    r.label += " x" + std::to_string(reps) + " = " + std::to_string(r.events.size()) + " events, " +
               std::to_string(r.frames.size()) + " frames";
    return r;
  }();
  return in;
}

// Runs the input through f: events in batches between frames, frames in order, one image at the end.
template <class F>
void run(F* f, bool frames) {
  const Input& in = input();
  size_t i = 0;
  if (frames) {
    for (size_t k = 0; k < in.frames.size(); ++k) {
      const size_t end = std::min(in.frame_at[k], in.events.size());
      if (end > i) f->process(in.events.data() + i, end - i);
      i = std::max(i, end);
      f->add_frame(in.frame_t[k], GreyView{in.frames[k].data(), in.width, in.height, in.width});
    }
  }
  f->process(in.events.data() + i, in.events.size() - i);
}

void set_counters(benchmark::State& state) {
  const double n = static_cast<double>(input().events.size());
  state.SetItemsProcessed(static_cast<int64_t>(state.iterations() * n));
  state.counters["ns/ev"] = benchmark::Counter(n * 1e-9, benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
  state.SetLabel(input().label);
}

void BM_ComplementaryFilter(benchmark::State& state) {
  const bool frames = state.range(0) != 0;
  evio::mapping::ComplementaryFilterOptions o;  // 0.5 Hz, +-0.1
  o.use_frames = frames;
  o.init_from_first_frame = false;
  evio::mapping::ImageF img;
  for (auto _ : state) {
    evio::mapping::ComplementaryFilter f(input().width, input().height, 0, o);
    run(&f, frames);
    f.log_intensity(input().events.back().t_ns, &img);
    benchmark::DoNotOptimize(img.data());
  }
  set_counters(state);
}

void BM_AsyncKalmanFilter(benchmark::State& state) {
  const bool frames = state.range(0) != 0;
  evio::mapping::AsyncKalmanFilterOptions o;
  o.use_frames = frames;
  evio::mapping::ImageF img;
  for (auto _ : state) {
    evio::mapping::AsyncKalmanFilter f(input().width, input().height, 0, o);
    run(&f, frames);
    f.log_intensity(input().events.back().t_ns, &img);
    benchmark::DoNotOptimize(img.data());
  }
  set_counters(state);
}

void BM_AsyncConvolution(benchmark::State& state) {
  const int size = static_cast<int>(state.range(0));
  evio::mapping::AsyncConvolutionOptions o;  // 0.5 Hz, +-0.1, events only
  o.filter.use_frames = false;
  o.filter.high_pass = true;
  o.kernels = {evio::mapping::sobel_kernel(true, size), evio::mapping::sobel_kernel(false, size)};
  evio::mapping::ImageF img;
  for (auto _ : state) {
    evio::mapping::AsyncConvolution f(input().width, input().height, 0, o);
    run(&f, false);
    f.convolved(0, input().events.back().t_ns, &img);
    benchmark::DoNotOptimize(img.data());
  }
  set_counters(state);
}

void BM_EventHarris(benchmark::State& state) {
  const evio::mapping::EventHarrisOptions o;  // 5 Hz, Sobel 3x3, 5x5 window, NMS radius 3
  int64_t corners = 0;
  for (auto _ : state) {
    evio::mapping::EventHarrisDetector f(input().width, input().height, 0, o);
    for (const Event& e : input().events) corners += f.process(e);
    benchmark::DoNotOptimize(corners);
  }
  set_counters(state);
}

// The published equations, straightforward: double state, per-pixel timestamps, exp() per event;
// per frame the global update (exp() per pixel) and the frame's log.
class PublishedLoop {
 public:
  PublishedLoop(int w, int h) : w_(w), l_(w * h, 0.0), ts_(w * h, 0.0), lf_(w * h, std::log(1.5)) {}
  void process(const Event* ev, size_t n) {
    for (size_t i = 0; i < n; ++i) {
      const Event& e = ev[i];
      const size_t k = static_cast<size_t>(e.y) * w_ + e.x;
      const double t = e.t_ns * 1e-9;
      const double b = std::exp(-alpha_ * (t - ts_[k]));
      l_[k] = b * l_[k] + (1 - b) * lf_[k] + (e.polarity > 0 ? 0.1 : -0.1);
      ts_[k] = t;
    }
  }
  void add_frame(int64_t t_ns, const GreyView& f) {
    global(t_ns * 1e-9);
    for (size_t k = 0; k < lf_.size(); ++k) lf_[k] = std::log(f.data[k] / 255.0 + 1.0);
  }
  void global(double t) {
    for (size_t k = 0; k < l_.size(); ++k) {
      const double b = std::exp(-alpha_ * (t - ts_[k]));
      l_[k] = b * l_[k] + (1 - b) * lf_[k];
      ts_[k] = t;
    }
  }
  const std::vector<double>& state() const { return l_; }

 private:
  int w_;
  double alpha_ = 2 * M_PI * 0.5;
  std::vector<double> l_, ts_, lf_;
};

void BM_PublishedEquationsLoop(benchmark::State& state) {
  const bool frames = state.range(0) != 0;
  for (auto _ : state) {
    PublishedLoop f(input().width, input().height);
    run(&f, frames);
    f.global(input().events.back().t_ns * 1e-9);
    benchmark::DoNotOptimize(f.state().data());
  }
  set_counters(state);
}

BENCHMARK(BM_ComplementaryFilter)->ArgName("frames")->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_AsyncKalmanFilter)->ArgName("frames")->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_AsyncConvolution)->ArgName("size")->Arg(3)->Arg(5)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_EventHarris)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_PublishedEquationsLoop)->ArgName("frames")->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  std::printf("input: %s\n", input().label.c_str());  // read before any timing
  evio::bench::JsonLinesReporter reporter({{"ns/ev", "ns_per_event"}, {"items_per_second", "events_per_s"}});
  benchmark::RunSpecifiedBenchmarks(&reporter);
  benchmark::Shutdown();
  return 0;
}
