#include "evio/mapping/async_convolution.h"
#include "evio/calib/error.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace evio::mapping {
namespace {

constexpr double kTwoPi = 6.283185307179586;

// Outer product of a column (y) and a row (x) profile, divided by norm.
ConvolutionKernel separable(const std::string& name, const std::vector<double>& col, const std::vector<double>& row,
                            double norm) {
  ConvolutionKernel k;
  k.name = name;
  k.size = static_cast<int>(row.size());
  for (double cy : col)
    for (double rx : row) k.taps.push_back(static_cast<float>(cy * rx / norm));
  return k;
}

// The range of offsets d in [-r, r] whose replicated-border sample clamp(q + d) lands on the
// event's coordinate e (q: the output pixel), in a line of n pixels: [lo, hi], empty when lo > hi.
inline void clamped_range(int e, int q, int n, int r, int* lo, int* hi) {
  *lo = std::max(-r, e == 0 ? -r : e - q);
  *hi = std::min(r, e == n - 1 ? r : e - q);
}

// Interior event: C(ex - i, ey - j) += cw K(i, j), centre at c; R fixed (unrolled) or -1 (r).
template <int R>
inline void add_interior(float* c, size_t w, const float* tap, float cw, int r) {
  const int rr = R >= 0 ? R : r;
  for (int j = -rr; j <= rr; ++j) {
    float* row = c - static_cast<ptrdiff_t>(j) * static_cast<ptrdiff_t>(w);
    for (int i = -rr; i <= rr; ++i) row[-i] += cw * *tap++;
  }
}

// out = K * in (replicated borders), H x W.
void convolve(const ConvolutionKernel& k, const std::vector<float>& in, int w, int h, std::vector<float>* out) {
  const int r = k.radius();
  out->assign(in.size(), 0.0f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      double acc = 0;
      for (int j = -r; j <= r; ++j) {
        const float* row = in.data() + static_cast<size_t>(std::clamp(y + j, 0, h - 1)) * w;
        for (int i = -r; i <= r; ++i) acc += static_cast<double>(k.at(i, j)) * row[std::clamp(x + i, 0, w - 1)];
      }
      (*out)[static_cast<size_t>(y) * w + x] = static_cast<float>(acc);
    }
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Kernels

bool ConvolutionKernel::Validate(std::string* why) const {
  if (size < 1 || size > 9 || size % 2 == 0) return validation_failed(why, "kernel '" + name + "': size must be odd, 1..9");
  if (taps.size() != static_cast<size_t>(size) * size)
    return validation_failed(why, "kernel '" + name + "': needs size * size = " + std::to_string(size * size) + " taps, has " +
                         std::to_string(taps.size()));
  for (float t : taps)
    if (!std::isfinite(t) || std::fabs(t) > 1e6) return validation_failed(why, "kernel '" + name + "': taps must be finite, |tap| <= 1e6");
  return true;
}

ConvolutionKernel sobel_kernel(bool d_dx, int size) {
  if (size != 3 && size != 5) throw std::invalid_argument("sobel_kernel: size must be 3 or 5");
  const std::vector<double> smooth = size == 3 ? std::vector<double>{1, 2, 1} : std::vector<double>{1, 4, 6, 4, 1};
  const std::vector<double> deriv = size == 3 ? std::vector<double>{-1, 0, 1} : std::vector<double>{-1, -2, 0, 2, 1};
  const double norm = size == 3 ? 8.0 : 128.0;
  const std::string name = std::string(d_dx ? "sobel_x" : "sobel_y") + std::to_string(size);
  return d_dx ? separable(name, smooth, deriv, norm) : separable(name, deriv, smooth, norm);
}

ConvolutionKernel laplacian_kernel(int size) {
  if (size == 3) return user_kernel("laplacian3", 3, {0, 1, 0, 1, -4, 1, 0, 1, 0});
  if (size != 5) throw std::invalid_argument("laplacian_kernel: size must be 3 or 5");
  const std::vector<double> smooth{1, 4, 6, 4, 1}, d2{1, 0, -2, 0, 1};
  ConvolutionKernel a = separable("laplacian5", smooth, d2, 64.0), b = separable("laplacian5", d2, smooth, 64.0);
  for (size_t i = 0; i < a.taps.size(); ++i) a.taps[i] += b.taps[i];
  return a;
}

ConvolutionKernel gaussian_kernel(int size, double sigma_px) {
  if (size < 1 || size > 9 || size % 2 == 0 || !(sigma_px > 0))
    throw std::invalid_argument("gaussian_kernel: size must be odd 1..9, sigma > 0");
  std::vector<double> g;
  double sum = 0;
  for (int i = -size / 2; i <= size / 2; ++i) {
    g.push_back(std::exp(-0.5 * i * i / (sigma_px * sigma_px)));
    sum += g.back();
  }
  return separable("gaussian" + std::to_string(size), g, g, sum * sum);
}

ConvolutionKernel forward_difference_kernel(bool d_dx) {
  return d_dx ? user_kernel("forward_x", 3, {0, 0, 0, 0, -1, 1, 0, 0, 0})
              : user_kernel("forward_y", 3, {0, 0, 0, 0, -1, 0, 0, 1, 0});
}

bool kernel_from_name(const std::string& name, ConvolutionKernel* k, std::string* why) {
  if (name == "sobel_x3" || name == "sobel_x5" || name == "sobel_y3" || name == "sobel_y5") {
    *k = sobel_kernel(name[6] == 'x', name[7] - '0');
  } else if (name == "laplacian3" || name == "laplacian5") {
    *k = laplacian_kernel(name.back() - '0');
  } else if (name == "gaussian3") {
    *k = gaussian_kernel(3, 0.85);
  } else if (name == "gaussian5") {
    *k = gaussian_kernel(5, 1.1);
  } else if (name == "forward_x" || name == "forward_y") {
    *k = forward_difference_kernel(name == "forward_x");
  } else {
    return validation_failed(why, "unknown kernel '" + name +
                         "' (sobel_x3, sobel_y3, sobel_x5, sobel_y5, laplacian3, laplacian5, gaussian3, gaussian5, "
                         "forward_x, forward_y)");
  }
  return true;
}

ConvolutionKernel user_kernel(const std::string& name, int size, const std::vector<float>& taps) {
  ConvolutionKernel k;
  k.name = name;
  k.size = size;
  k.taps = taps;
  std::string why;
  if (!k.Validate(&why)) throw std::invalid_argument(why);
  return k;
}

bool AsyncConvolutionOptions::Validate(std::string* why) const {
  if (kernels.empty() || kernels.size() > 16) return validation_failed(why, "asynchronous convolution: 1 to 16 kernels");
  for (const ConvolutionKernel& k : kernels)
    if (!k.Validate(why)) return false;
  return filter.Validate(why);
}

// ---------------------------------------------------------------------------------------------
// Asynchronous convolution

AsyncConvolution::AsyncConvolution(int width, int height, int64_t t_start_ns, const AsyncConvolutionOptions& options)
    : width_(width), height_(height), o_(options), clock_(kTwoPi * options.filter.cutoff_hz * 1e-9, t_start_ns) {
  if (width < 1 || height < 1 || width > 65536 || height > 65536)
    throw std::invalid_argument("AsyncConvolution: sensor size " + std::to_string(width) + " x " + std::to_string(height) +
                                " outside 1..65536");
  std::string why;
  if (!o_.Validate(&why)) throw std::invalid_argument("AsyncConvolutionOptions: " + why);
  const ComplementaryFilterOptions& f = o_.filter;
  c_on_ = static_cast<float>(f.contrast_on);
  c_off_ = static_cast<float>(-f.contrast_off);
  lut_.resize(256);
  for (int v = 0; v < 256; ++v) lut_[v] = static_cast<float>(f.frame.log_of(v));
  const size_t n = static_cast<size_t>(width) * height;
  // The initial state and the reference are constant images: K * c = c * sum(K) (replicated borders).
  const float reference = f.high_pass ? 0.0f : static_cast<float>(f.frame.log_of(f.frame.initial_grey));
  for (const ConvolutionKernel& k : o_.kernels) {
    double sum = 0;
    for (float t : k.taps) sum += t;
    planes_.push_back(Plane{std::vector<float>(n, static_cast<float>(f.initial_log_intensity * sum)),
                            std::vector<float>(n, static_cast<float>(reference * sum))});
  }
  sum_s_ = f.initial_log_intensity * static_cast<double>(n);
  sum_ref_ = static_cast<double>(reference) * static_cast<double>(n);
}

bool AsyncConvolution::reference_is_zero() const { return sum_ref_ == 0.0 && !frames_seen_; }

void AsyncConvolution::spread(const Event& e, float cw) {
  const int w = width_, h = height_, ex = e.x, ey = e.y;
  for (size_t p = 0; p < planes_.size(); ++p) {
    const ConvolutionKernel& k = o_.kernels[p];
    const int r = k.radius();
    float* s = planes_[p].s.data();
    if (ex >= r && ey >= r && ex + r < w && ey + r < h) {
      float* c = s + static_cast<size_t>(ey) * w + ex;
      switch (r) {
        case 1: add_interior<1>(c, w, k.taps.data(), cw, r); break;
        case 2: add_interior<2>(c, w, k.taps.data(), cw, r); break;
        default: add_interior<-1>(c, w, k.taps.data(), cw, r); break;
      }
      continue;
    }
    // Near the border: every output pixel (x, y) within r sums the taps whose replicated sample is
    // the event's pixel.
    for (int y = std::max(0, ey - r); y <= std::min(h - 1, ey + r); ++y) {
      int jlo, jhi;
      clamped_range(ey, y, h, r, &jlo, &jhi);
      for (int x = std::max(0, ex - r); x <= std::min(w - 1, ex + r); ++x) {
        int ilo, ihi;
        clamped_range(ex, x, w, r, &ilo, &ihi);
        float acc = 0;
        for (int j = jlo; j <= jhi; ++j)
          for (int i = ilo; i <= ihi; ++i) acc += k.at(i, j);
        s[static_cast<size_t>(y) * w + x] += cw * acc;
      }
    }
  }
}

bool AsyncConvolution::add_event(const Event& e) {
  float scale;
  if (!clock_.event_weight(e.t_ns, &scale)) {
    rebase(e.t_ns);
    scale = exp_to_float(clock_.exponent(e.t_ns));  // the event is at or before the new t_ref
  }
  if (e.x >= width_ || e.y >= height_) {
    ++stats_.events_outside;
    return false;
  }
  const float cw = (e.polarity > 0 ? c_on_ : c_off_) * scale;
  spread(e, cw);
  sum_s_ += cw;
  ++stats_.events;
  return true;
}

void AsyncConvolution::process(const Event* events, size_t n) {
  for (size_t i = 0; i < n; ++i) add_event(events[i]);
}

void AsyncConvolution::fold_reference(int64_t t_ns) {
  const double dw = clock_.fold(t_ns);
  if (dw == 0.0) return;
  for (Plane& p : planes_)
    for (size_t i = 0; i < p.s.size(); ++i) p.s[i] += static_cast<float>(p.ref[i] * dw);
  sum_s_ += sum_ref_ * dw;
}

void AsyncConvolution::rebase(int64_t t_ns) {
  const ScaledDecayClock::Rebase r = clock_.rebase(t_ns);
  for (Plane& p : planes_)
    for (size_t i = 0; i < p.s.size(); ++i) {
      const float v = static_cast<float>(p.s[i] * r.scale + p.ref[i] * r.gain);
      p.s[i] = std::fabs(v) < 1e-30f ? 0.0f : v;
    }
  sum_s_ = sum_s_ * r.scale + sum_ref_ * r.gain;
  ++stats_.rebases;
}

void AsyncConvolution::add_frame(int64_t t_ns, const GreyView& frame) {
  if (!o_.filter.use_frames) return;
  if (frame.width != width_ || frame.height != height_ || !frame.data || frame.stride < frame.width)
    throw std::invalid_argument("AsyncConvolution: a frame of " + std::to_string(frame.width) + " x " +
                                std::to_string(frame.height) + " px on a " + std::to_string(width_) + " x " +
                                std::to_string(height_) + " sensor (frames must have the sensor's size)");
  if (clock_.needs_rebase(t_ns)) rebase(t_ns);
  fold_reference(t_ns);  // the previous reference up to t_ns
  std::vector<float> log_frame(static_cast<size_t>(width_) * height_);
  sum_ref_ = 0;
  for (int y = 0; y < height_; ++y)
    for (int x = 0; x < width_; ++x) {
      const float l = lut_[frame.data[y * frame.stride + x]];
      log_frame[static_cast<size_t>(y) * width_ + x] = l;
      sum_ref_ += l;
    }
  for (size_t k = 0; k < planes_.size(); ++k) convolve(o_.kernels[k], log_frame, width_, height_, &planes_[k].ref);
  if (stats_.frames == 0 && o_.filter.init_from_first_frame) {
    const double w = exp_to_float(clock_.exponent(clock_.t_fold_ns()));
    for (Plane& p : planes_)
      for (size_t i = 0; i < p.s.size(); ++i) p.s[i] = static_cast<float>(p.ref[i] * w);
    sum_s_ = sum_ref_ * w;
  }
  frames_seen_ = true;
  ++stats_.frames;
}

void AsyncConvolution::convolved(size_t k, int64_t t_ns, ImageF* out) const {
  out->resize(height_, width_);
  const ScaledDecayClock::Readout r = clock_.readout(t_ns);
  const Plane& p = planes_.at(k);
  float* o = out->data();
  for (size_t i = 0; i < p.s.size(); ++i) o[i] = static_cast<float>(p.s[i] * r.inv + p.ref[i] * r.gain);
}

double AsyncConvolution::mean_log_intensity(int64_t t_ns) const {
  const ScaledDecayClock::Readout r = clock_.readout(t_ns);
  return (sum_s_ * r.inv + sum_ref_ * r.gain) / (static_cast<double>(width_) * height_);
}

// ---------------------------------------------------------------------------------------------
// Poisson image of the gradient state

bool PoissonGradientOptions::Validate(std::string* why) const { return filter.Validate(why); }

namespace {
AsyncConvolutionOptions gradient_options(const PoissonGradientOptions& o) {
  AsyncConvolutionOptions c;
  c.filter = o.filter;
  c.kernels = o.sobel ? std::vector<ConvolutionKernel>{sobel_kernel(true, 3), sobel_kernel(false, 3)}
                      : std::vector<ConvolutionKernel>{forward_difference_kernel(true), forward_difference_kernel(false)};
  return c;
}
PoissonOptions neumann() {
  PoissonOptions p;
  p.boundary = PoissonBoundary::kNeumann;
  return p;
}
}  // namespace

PoissonGradientFilter::PoissonGradientFilter(int width, int height, int64_t t_start_ns, const PoissonGradientOptions& options)
    : conv_(width, height, t_start_ns, gradient_options(options)), solver_(width, height, neumann()) {}

void PoissonGradientFilter::gradients(int64_t t_ns, ImageF* gx, ImageF* gy) const {
  conv_.convolved(0, t_ns, gx);
  conv_.convolved(1, t_ns, gy);
}

void PoissonGradientFilter::log_intensity(int64_t t_ns, ImageF* out) const {
  ImageF gx, gy;
  gradients(t_ns, &gx, &gy);
  solver_.solve(gx, gy, out);
  const float mean = static_cast<float>(conv_.mean_log_intensity(t_ns));
  out->array() += mean - out->mean();
}

}  // namespace evio::mapping
