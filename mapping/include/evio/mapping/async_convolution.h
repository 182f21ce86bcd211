// Asynchronous spatial convolutions of the complementary filter's state (Scheerlinck, Barnes,
// Mahony, "Asynchronous Spatial Image Convolutions for Event Cameras", RAL 2019): an event of step
// c at pixel p is a "convolved event" c K spread over p's neighbourhood, and each kernel's output
// C = K * L is filtered in continuous time with the complementary filter's own equation
//   dC/dt = K * E(t) - alpha (C - K * L_F)
// solved exactly between events by the complementary filter's time base (scaled_decay.h). Since
// the filter is linear, C(t) equals K convolved with the complementary filter's image L(t) (same
// options) to float precision (tests/mapping/test_async_convolution.cc asserts it).
// PoissonGradientFilter integrates a gradient state (two kernels) with mapping/poisson.h.
//
// Conventions: correlation as OpenCV's filter2D with replicated borders,
//   C(x, y) = sum over i, j in [-r, r] of K(r + j, r + i) L(clamp(x + i), clamp(y + j)),
// K row-major (row = y), size 2r + 1; t int64 ns; polarity +1 / -1. Images H x W (image.h).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "evio/mapping/image.h"
#include "evio/mapping/poisson.h"
#include "evio/mapping/reconstruction.h"
#include "evio/mapping/scaled_decay.h"

namespace evio::mapping {

// A square kernel of odd size, taps row-major (row = y, down; column = x, right).
struct ConvolutionKernel {
  std::string name;          // for logs and configs
  int size = 3;              // px, odd, 1..9
  std::vector<float> taps;   // size * size
  int radius() const { return size / 2; }
  float at(int dx, int dy) const { return taps[static_cast<size_t>(dy + radius()) * size + dx + radius()]; }
  bool Validate(std::string* why) const;
};

// The named kernels, normalised to derivatives per pixel (a ramp of slope 1 per px gives 1; the
// Laplacian gives 2 on x^2), the Gaussian to unit sum:
//   sobel_x3 sobel_y3 sobel_x5 sobel_y5   Sobel d/dx, d/dy (3x3 / 8, 5x5 / 128)
//   laplacian3 laplacian5                 [0 1 0; 1 -4 1; 0 1 0]; 5x5: OpenCV's ksize 5 / 64
//   gaussian3 gaussian5                   sampled Gaussian, sigma = 0.85 / 1.1 px
//   forward_x forward_y                   L(x+1, y) - L(x, y), L(x, y+1) - L(x, y) (3x3 with zeros):
//                                         mapping/poisson.h's gradient, exactly integrable
ConvolutionKernel sobel_kernel(bool d_dx, int size);
ConvolutionKernel laplacian_kernel(int size);
ConvolutionKernel gaussian_kernel(int size, double sigma_px);
ConvolutionKernel forward_difference_kernel(bool d_dx);
// One of the names above; false (and *why) for an unknown name.
bool kernel_from_name(const std::string& name, ConvolutionKernel* k, std::string* why = nullptr);
// A user kernel: size * size taps, row-major. Throws std::invalid_argument when invalid.
ConvolutionKernel user_kernel(const std::string& name, int size, const std::vector<float>& taps);

struct AsyncConvolutionOptions {
  ComplementaryFilterOptions filter;       // cut-off, contrasts, frames, high-pass: as the complementary filter's
  std::vector<ConvolutionKernel> kernels;  // at least one, at most 16
  bool Validate(std::string* why) const;
};

// The convolved complementary (or high-pass) filter: one scaled state plane per kernel, one shared
// clock. An event costs (2r + 1)^2 multiply-adds per kernel, a frame one convolution per kernel.
class AsyncConvolution {
 public:
  // Throws std::invalid_argument for invalid options or a size outside 1..65536.
  AsyncConvolution(int width, int height, int64_t t_start_ns, const AsyncConvolutionOptions& options);

  // Events in time order (as the complementary filter); outside the sensor: counted and dropped.
  void process(const Event* events, size_t n);
  void process(const std::vector<Event>& events) { process(events.data(), events.size()); }
  // One event; false when it lies outside the sensor.
  bool add_event(const Event& e);
  // An APS frame (as ComplementaryFilter::add_frame): its log intensity convolved with each kernel
  // becomes the reference. Throws std::invalid_argument for a wrong size.
  void add_frame(int64_t t_ns, const GreyView& frame);

  // Kernel k's output C_k at t_ns (>= the last event and frame): H x W.
  void convolved(size_t k, int64_t t_ns, ImageF* out) const;
  ImageF convolved(size_t k, int64_t t_ns) const {
    ImageF out;
    convolved(k, t_ns, &out);
    return out;
  }
  // The mean over the image of the (unconvolved) complementary filter state at t_ns, log units.
  double mean_log_intensity(int64_t t_ns) const;

  // The raw state for detectors built on it (event_harris.h): kernel k's scaled plane S_k (H x W,
  // C_k = S_k inv + R_k gain, clock().readout()); with reference_is_zero() (the high-pass filter
  // without frames) C_k(t) = S_k / w(t) for every pixel.
  const float* scaled_state(size_t k) const { return planes_[k].s.data(); }
  bool reference_is_zero() const;
  const ScaledDecayClock& clock() const { return clock_; }

  size_t num_kernels() const { return planes_.size(); }
  const ConvolutionKernel& kernel(size_t k) const { return o_.kernels[k]; }
  const ReconstructionStats& stats() const { return stats_; }
  int width() const { return width_; }
  int height() const { return height_; }
  const AsyncConvolutionOptions& options() const { return o_; }

 private:
  struct Plane {
    std::vector<float> s;    // scaled state, H x W
    std::vector<float> ref;  // reference K * L_F, H x W
  };
  void rebase(int64_t t_ns);
  void fold_reference(int64_t t_ns);
  void spread(const Event& e, float cw);  // adds cw K to every plane around the event

  int width_, height_;
  AsyncConvolutionOptions o_;
  float c_on_, c_off_;
  std::vector<Plane> planes_;
  double sum_s_ = 0, sum_ref_ = 0;  // the unconvolved state's and reference's sums over the image
  bool frames_seen_ = false;
  std::vector<float> lut_;          // frame value -> log intensity (256)
  ScaledDecayClock clock_;
  ReconstructionStats stats_;
};

// The log-intensity image integrated from a gradient state (Poisson, mapping/poisson.h, Neumann
// borders) plus the complementary filter's mean: with the forward-difference kernels (default) the
// gradient field is exactly integrable and the image is the complementary filter's own; with
// Sobel kernels a smoothed image shifted by half a pixel.
struct PoissonGradientOptions {
  ComplementaryFilterOptions filter;
  bool sobel = false;    // Sobel 3x3 gradients instead of forward differences
  bool Validate(std::string* why) const;
};

class PoissonGradientFilter : public LogIntensityFilter {
 public:
  // Throws std::invalid_argument for invalid options or a size below 2 x 2.
  PoissonGradientFilter(int width, int height, int64_t t_start_ns, const PoissonGradientOptions& options = {});
  void process(const Event* events, size_t n) override { conv_.process(events, n); }
  using LogIntensityFilter::process;
  void add_frame(int64_t t_ns, const GreyView& frame) override { conv_.add_frame(t_ns, frame); }
  // Poisson solve of the gradient state at t_ns, plus the filter's mean.
  void log_intensity(int64_t t_ns, ImageF* out) const override;
  using LogIntensityFilter::log_intensity;
  // The gradient state at t_ns (d/dx, d/dy), log units per px.
  void gradients(int64_t t_ns, ImageF* gx, ImageF* gy) const;
  const ReconstructionStats& stats() const override { return conv_.stats(); }
  int width() const override { return conv_.width(); }
  int height() const override { return conv_.height(); }
  const AsyncConvolution& convolution() const { return conv_; }

 private:
  AsyncConvolution conv_;
  PoissonSolver solver_;
};

}  // namespace evio::mapping
