// Asynchronous convolutions (mapping/async_convolution.h): the convolution-driven state against the
// brute-force reference (the complementary filter's image convolved with the kernel: equal to
// float precision since the filter is linear), for every named kernel and a user kernel, with and
// without frames, on synthetic streams and the real ECD slice; exact decay for dt = 0 and hours;
// 1.7e18 ns stamps; bursts; the Poisson image of the gradient state; the event Harris response
// against a brute-force Harris of the gradient images.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "evio/mapping/async_convolution.h"
#include "evio/mapping/event_harris.h"
#include "evio/sensors/ecd.h"
#include "evio_test/real_data.h"
#include "evio_test/timed_frame.h"

namespace evio::mapping {
namespace {

constexpr double kTwoPi = 6.283185307179586;

using evio_test::TimedFrame;

struct Stream {
  int w = 0, h = 0;
  std::vector<Event> events;
  std::vector<TimedFrame> frames;
};

std::vector<ConvolutionKernel> all_kernels() {
  std::vector<ConvolutionKernel> k;
  for (const char* name : {"sobel_x3", "sobel_y3", "sobel_x5", "sobel_y5", "laplacian3", "laplacian5", "gaussian3",
                           "gaussian5", "forward_x", "forward_y"}) {
    ConvolutionKernel c;
    EXPECT_TRUE(kernel_from_name(name, &c));
    k.push_back(c);
  }
  return k;
}

ConvolutionKernel random_user_kernel(int size, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::vector<float> taps(static_cast<size_t>(size) * size);
  for (float& t : taps) t = u(rng);
  return user_kernel("user" + std::to_string(size), size, taps);
}

// K * L with replicated borders, in double: the reference of the header's convention.
ImageF brute_convolve(const ConvolutionKernel& k, const ImageF& l) {
  const int r = k.radius(), h = static_cast<int>(l.rows()), w = static_cast<int>(l.cols());
  ImageF out(h, w);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      double acc = 0;
      for (int j = -r; j <= r; ++j)
        for (int i = -r; i <= r; ++i) acc += static_cast<double>(k.at(i, j)) * l(std::clamp(y + j, 0, h - 1), std::clamp(x + i, 0, w - 1));
      out(y, x) = static_cast<float>(acc);
    }
  return out;
}

// Feeds a stream to any filter-like object in time order, frames before the first later event,
// calling at(t) at each readout time (after every event at t' < t).
template <class F, class At>
void run_stream(const Stream& s, F* f, bool frames, const std::vector<int64_t>& readouts, At at) {
  size_t i = 0, k = 0;
  auto events_before = [&](int64_t t, bool inclusive) {
    size_t j = i;
    while (j < s.events.size() && (inclusive ? s.events[j].t_ns <= t : s.events[j].t_ns < t)) ++j;
    f->process(s.events.data() + i, j - i);
    i = j;
  };
  for (int64_t t : readouts) {
    while (frames && k < s.frames.size() && s.frames[k].t_ns < t) {
      events_before(s.frames[k].t_ns, true);
      f->add_frame(s.frames[k].t_ns, evio_test::view(s.frames[k], s.w, s.h));
      ++k;
    }
    events_before(t, false);
    at(t);
  }
}

Stream random_stream(int w, int h, int64_t t0, int64_t span_ns, size_t n, int num_frames, uint32_t seed) {
  std::mt19937 rng(seed);
  Stream s;
  s.w = w;
  s.h = h;
  std::uniform_int_distribution<int64_t> T(0, span_ns);
  std::uniform_int_distribution<int> X(0, w - 1), Y(0, h - 1), P(0, 1);
  s.events.resize(n);
  for (Event& e : s.events)
    e = Event{t0 + T(rng), static_cast<uint16_t>(X(rng)), static_cast<uint16_t>(Y(rng)), static_cast<int8_t>(P(rng) ? 1 : -1)};
  // A 10x burst: one pixel (on the border, where the clamped stencil applies) fires 10 times at one time.
  for (int b = 0; b < 10; ++b) s.events.push_back(Event{t0 + span_ns / 2, 0, static_cast<uint16_t>(h / 2), 1});
  std::sort(s.events.begin(), s.events.end(), [](const Event& a, const Event& b) { return a.t_ns < b.t_ns; });
  for (int k = 0; k < num_frames; ++k) {
    TimedFrame f{t0 + span_ns * (k + 1) / (num_frames + 1), std::vector<uint8_t>(static_cast<size_t>(w) * h)};
    for (uint8_t& v : f.pixels) v = static_cast<uint8_t>(rng() % 256);
    s.frames.push_back(std::move(f));
  }
  return s;
}

// Runs the complementary filter and the convolution with the same options over the stream; the
// largest |C_k - K * L| over every kernel, pixel and readout, relative to sum |K| max |L| (the
// float rounding of the convolution itself is ~1e-7 of that; measured at most 1.5e-7).
double max_relative_convolution_error(const Stream& s, const ComplementaryFilterOptions& cf,
                                      const std::vector<ConvolutionKernel>& kernels, const std::vector<int64_t>& readouts,
                                      int64_t t_start) {
  ComplementaryFilter f(s.w, s.h, t_start, cf);
  AsyncConvolutionOptions co;
  co.filter = cf;
  co.kernels = kernels;
  AsyncConvolution conv(s.w, s.h, t_start, co);
  std::vector<ImageF> images;
  run_stream(s, &f, cf.use_frames, readouts, [&](int64_t t) { images.push_back(f.log_intensity(t)); });
  double worst = 0;
  size_t r = 0;
  run_stream(s, &conv, cf.use_frames, readouts, [&](int64_t t) {
    const ImageF& l = images[r++];
    const double lmax = std::max(1e-3, static_cast<double>(l.cwiseAbs().maxCoeff()));
    for (size_t k = 0; k < conv.num_kernels(); ++k) {
      double ksum = 0;
      for (float v : kernels[k].taps) ksum += std::fabs(v);
      const ImageF diff = conv.convolved(k, t) - brute_convolve(kernels[k], l);
      worst = std::max(worst, static_cast<double>(diff.cwiseAbs().maxCoeff()) / (ksum * lmax));
    }
  });
  EXPECT_EQ(conv.stats().events, f.stats().events);
  EXPECT_EQ(conv.stats().rebases, f.stats().rebases);
  return worst;
}

std::vector<int64_t> readout_times(int64_t t0, int64_t span_ns, int n) {
  std::vector<int64_t> r;
  for (int k = 1; k <= n; ++k) r.push_back(t0 + span_ns * k / n + 1);
  return r;
}

// ------------------------------------------------------------------------------------------

// Every named kernel and user kernels of sizes 1, 3, 7, on a small sensor (a third of its events
// within the kernels' reach of the border), with and without frames, high-pass, a cut-off fast
// enough to rebase many times, and starting near 1.7e18 ns.
TEST(AsyncConvolution, EqualsConvolvedComplementaryFilterOnSyntheticStreams) {
  std::vector<ConvolutionKernel> kernels = all_kernels();
  for (int size : {1, 3, 7}) kernels.push_back(random_user_kernel(size, 40 + size));
  for (int64_t t0 : {int64_t{0}, int64_t{1'700'000'000'000'000'000}}) {
    const int64_t span = 20'000'000'000;  // 20 s: rebases at 2 Hz every 1.6 s, at 0.5 Hz every 6.4 s
    const Stream s = random_stream(24, 18, t0, span, 20000, 4, 7);
    for (double cutoff : {0.5, 2.0}) {
      for (int mode = 0; mode < 3; ++mode) {  // 0: cf with frames, 1: cf without, 2: high-pass
        ComplementaryFilterOptions o;
        o.cutoff_hz = cutoff;
        o.contrast_on = 0.12;
        o.contrast_off = 0.09;
        o.use_frames = mode == 0;
        o.high_pass = mode == 2;
        const double err = max_relative_convolution_error(s, o, kernels, readout_times(t0, span, 9), t0);
        std::printf("t0 %lld, cut-off %.1f Hz, mode %d: max |C - K * L| / (sum|K| max|L|) = %.3g\n",
                    static_cast<long long>(t0), cutoff, mode, err);
        EXPECT_LT(err, 5e-7) << "t0 " << t0 << " cutoff " << cutoff << " mode " << mode;
      }
    }
  }
}

// The real ECD slice (50,000 events, 5 APS frames, 240 x 180) with frames, Sobel and Laplacian 5x5.
TEST(AsyncConvolution, EqualsConvolvedComplementaryFilterOnRealSlice) {
  const auto dir = evio_test::real_data_dir("ecd_slider_depth_head");
  if (!dir) GTEST_SKIP() << "real data ecd_slider_depth_head not found (set EVIO_REAL_DATA)";
  Stream s;
  s.w = 240;
  s.h = 180;
  const EventBuffer b = read_ecd_events(*dir + "/events.txt");
  s.events.assign(b.begin(), b.end());
  for (Frame f : read_ecd_image_list(*dir + "/images.txt")) {
    if (f.t_ns > s.events.back().t_ns) break;
    load_frame_image(&f);
    TimedFrame tf{f.t_ns, {}};
    for (int y = 0; y < f.image.rows; ++y) tf.pixels.insert(tf.pixels.end(), f.image.ptr<uint8_t>(y), f.image.ptr<uint8_t>(y) + f.image.cols);
    s.frames.push_back(std::move(tf));
  }
  ASSERT_EQ(s.frames.size(), 5u);
  std::vector<int64_t> readouts;
  for (const TimedFrame& f : s.frames) readouts.push_back(f.t_ns + 1);
  readouts.push_back(s.events.back().t_ns + 1);
  ComplementaryFilterOptions o;
  o.use_frames = true;
  const std::vector<ConvolutionKernel> kernels = {sobel_kernel(true, 5), sobel_kernel(false, 3), laplacian_kernel(5)};
  const double err = max_relative_convolution_error(s, o, kernels, readouts, s.frames.front().t_ns);
  std::printf("real slice with frames: max |C - K * L| / (sum|K| max|L|) = %.3g\n", err);
  EXPECT_LT(err, 5e-7);  // measured 1.7e-7
}

// One event, closed forms: two events at the same time (dt = 0) add exactly; after 3 hours at
// 1e-4 Hz (alpha dt = 6.79) the state is c K exp(-alpha dt); after a day at 0.5 Hz it is 0. Large
// stamps give the same state as the same stream from 0.
TEST(AsyncConvolution, ExactDecayForZeroAndHoursLongGaps) {
  const ConvolutionKernel k = sobel_kernel(true, 3);
  for (int64_t t0 : {int64_t{0}, int64_t{1'700'000'000'000'000'000}}) {
    AsyncConvolutionOptions o;
    o.filter.cutoff_hz = 1e-4;
    o.filter.high_pass = true;
    o.filter.contrast_on = 0.25;
    o.kernels = {k};
    AsyncConvolution conv(9, 9, t0, o);
    conv.process({Event{t0 + 5, 4, 4, 1}, Event{t0 + 5, 4, 4, 1}});
    ImageF c = conv.convolved(0, t0 + 5);
    for (int j = -1; j <= 1; ++j)
      for (int i = -1; i <= 1; ++i) EXPECT_FLOAT_EQ(c(4 - j, 4 - i), 0.5f * k.at(i, j)) << i << " " << j;
    const int64_t hours = int64_t{3} * 3600 * 1'000'000'000;
    const double decay = std::exp(-kTwoPi * 1e-4 * (hours * 1e-9));
    c = conv.convolved(0, t0 + 5 + hours);
    EXPECT_NEAR(c(4, 3), 0.5 * k.at(1, 0) * decay, 2e-7) << "decay " << decay;
    // An event after the gap rebases (the state decayed exactly) and adds on top.
    conv.process({Event{t0 + 5 + hours, 4, 4, 1}});
    c = conv.convolved(0, t0 + 5 + hours);
    EXPECT_NEAR(c(4, 3), 0.25 * k.at(1, 0) * (1 + 2 * decay), 2e-7);
    EXPECT_GE(conv.stats().rebases, 1);
    EXPECT_NEAR(conv.mean_log_intensity(t0 + 5 + hours), 0.25 * (1 + 2 * decay) / 81.0, 1e-9);

    o.filter.cutoff_hz = 0.5;
    AsyncConvolution fast(9, 9, t0, o);
    fast.process({Event{t0 + 5, 4, 4, 1}, Event{t0 + 5 + 24 * 3600 * int64_t{1'000'000'000}, 0, 0, -1}});
    c = fast.convolved(0, t0 + 5 + 24 * 3600 * int64_t{1'000'000'000});
    EXPECT_EQ(c(4, 3), 0.0f);  // a day at 0.5 Hz: decayed to nothing, no NaN or denormal
    EXPECT_TRUE(c.allFinite());
  }
}

// With the forward-difference kernels the gradient state is exactly integrable: its Poisson image
// is the complementary filter's image (the mean comes from the filter's tracked mean).
TEST(PoissonGradientFilter, PoissonImageOfTheGradientStateIsTheComplementaryFilterImage) {
  const int64_t span = 3'000'000'000;
  const Stream s = random_stream(32, 24, 0, span, 8000, 2, 11);
  ComplementaryFilterOptions o;
  o.cutoff_hz = 1.0;
  PoissonGradientOptions po;
  po.filter = o;
  ComplementaryFilter f(s.w, s.h, 0, o);
  PoissonGradientFilter g(s.w, s.h, 0, po);
  std::vector<ImageF> images;
  const std::vector<int64_t> readouts = readout_times(0, span, 4);
  run_stream(s, &f, true, readouts, [&](int64_t t) { images.push_back(f.log_intensity(t)); });
  size_t r = 0;
  double worst = 0;
  run_stream(s, &g, true, readouts, [&](int64_t t) {
    worst = std::max(worst, static_cast<double>((g.log_intensity(t) - images[r++]).cwiseAbs().maxCoeff()));
  });
  std::printf("max |Poisson(gradient state) - cf image| = %.3g\n", worst);
  EXPECT_LT(worst, 5e-6);  // measured 9.4e-7
}

// The per-event Harris state (updated only around each event) equals Harris computed from scratch
// on the gradient images: Sobel of the high-pass image, products, Gaussian window (zero outside
// the image), det - k trace^2; across rebases too.
TEST(EventHarris, IncrementalResponseEqualsBruteForce) {
  EventHarrisOptions o;
  o.cutoff_hz = 3.0;  // rebases every ~1 s
  const int64_t span = 4'000'000'000;
  Stream s = random_stream(30, 20, 0, span, 6000, 0, 5);
  EventHarrisDetector det(s.w, s.h, 0, o);
  ComplementaryFilterOptions hp;
  hp.cutoff_hz = o.cutoff_hz;
  hp.high_pass = true;
  hp.use_frames = false;
  ComplementaryFilter f(s.w, s.h, 0, hp);
  for (const Event& e : s.events) det.process(e);
  f.process(s.events);
  const int64_t t = span + 1;
  const ImageF l = f.log_intensity(t);
  const ImageF gx = brute_convolve(sobel_kernel(true, 3), l), gy = brute_convolve(sobel_kernel(false, 3), l);
  const ConvolutionKernel win = gaussian_kernel(2 * o.window_radius + 1, o.window_sigma_px);
  ImageF ref(s.h, s.w), got;
  for (int y = 0; y < s.h; ++y)
    for (int x = 0; x < s.w; ++x) {
      double a = 0, b = 0, c = 0;
      for (int j = -o.window_radius; j <= o.window_radius; ++j)
        for (int i = -o.window_radius; i <= o.window_radius; ++i) {
          if (y + j < 0 || y + j >= s.h || x + i < 0 || x + i >= s.w) continue;
          const double g = win.at(i, j), u = gx(y + j, x + i), v = gy(y + j, x + i);
          a += g * u * u;
          b += g * u * v;
          c += g * v * v;
        }
      ref(y, x) = static_cast<float>(a * c - b * b - o.harris_k * (a + c) * (a + c));
    }
  det.response_image(t, &got);
  const double scale = ref.cwiseAbs().maxCoeff();
  const double err = (got - ref).cwiseAbs().maxCoeff() / scale;
  std::printf("Harris: %lld recomputes; max |R_event - R_brute| / max |R| = %.3g\n",
              static_cast<long long>(det.stats().recomputes), err);
  EXPECT_GE(det.stats().recomputes, 3);
  EXPECT_LT(err, 2e-6);  // measured 2.6e-7
}

TEST(AsyncConvolution, OptionsValidateAndBadInput) {
  std::string why;
  ConvolutionKernel k;
  EXPECT_FALSE(kernel_from_name("sobel_x7", &k, &why));
  EXPECT_NE(why.find("unknown kernel"), std::string::npos);
  EXPECT_THROW(user_kernel("even", 4, std::vector<float>(16, 1.0f)), std::invalid_argument);
  EXPECT_THROW(user_kernel("short", 3, std::vector<float>(8, 1.0f)), std::invalid_argument);
  AsyncConvolutionOptions o;
  EXPECT_FALSE(o.Validate(&why));  // no kernel
  o.kernels = {laplacian_kernel(3)};
  EXPECT_TRUE(o.Validate(&why)) << why;
  AsyncConvolution conv(8, 6, 0, o);
  std::vector<uint8_t> px(7 * 6, 100);
  EXPECT_THROW(conv.add_frame(1, GreyView{px.data(), 7, 6, 7}), std::invalid_argument);
  EXPECT_FALSE(conv.add_event(Event{2, 8, 0, 1}));
  EXPECT_EQ(conv.stats().events_outside, 1);
  EventHarrisOptions h;
  h.gradient_size = 4;
  EXPECT_FALSE(h.Validate(&why));
  EXPECT_THROW(EventHarrisDetector(10, 10, 0, h), std::invalid_argument);
}

}  // namespace
}  // namespace evio::mapping
