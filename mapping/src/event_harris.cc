#include "evio/mapping/event_harris.h"
#include "evio/calib/error.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace evio::mapping {
namespace {

AsyncConvolutionOptions gradient_state_options(const EventHarrisOptions& o) {
  AsyncConvolutionOptions c;
  c.filter.cutoff_hz = o.cutoff_hz;
  c.filter.contrast_on = o.contrast_on;
  c.filter.contrast_off = o.contrast_off;
  c.filter.high_pass = true;
  c.filter.use_frames = false;
  c.filter.init_from_first_frame = false;
  const int size = o.gradient_size == 5 ? 5 : 3;  // Validate rejects others; keep the kernels constructible
  c.kernels = {sobel_kernel(true, size), sobel_kernel(false, size)};
  return c;
}

}  // namespace

bool EventHarrisOptions::Validate(std::string* why) const {
  if (!(std::isfinite(cutoff_hz) && cutoff_hz >= 0 && cutoff_hz <= 1e6)) return validation_failed(why, "harris cutoff_hz must be in [0, 1e6]");
  if (!(std::isfinite(contrast_on) && contrast_on > 0 && contrast_on <= 10)) return validation_failed(why, "harris contrast_on must be in (0, 10]");
  if (!(std::isfinite(contrast_off) && contrast_off > 0 && contrast_off <= 10))
    return validation_failed(why, "harris contrast_off must be in (0, 10]");
  if (gradient_size != 3 && gradient_size != 5) return validation_failed(why, "harris gradient_size must be 3 or 5");
  if (window_radius < 1 || window_radius > 4) return validation_failed(why, "harris window_radius must be in 1..4");
  if (!(std::isfinite(window_sigma_px) && window_sigma_px > 0 && window_sigma_px <= 100))
    return validation_failed(why, "harris window_sigma_px must be in (0, 100]");
  if (!(harris_k >= 0 && harris_k < 0.25)) return validation_failed(why, "harris k must be in [0, 0.25)");
  if (!(std::isfinite(threshold) && threshold >= 0)) return validation_failed(why, "harris threshold must be finite, >= 0");
  if (nms_radius < 0 || nms_radius > 8) return validation_failed(why, "harris nms_radius must be in 0..8");
  if (border_px < 0) return validation_failed(why, "harris border_px must be >= 0");
  return true;
}

EventHarrisDetector::EventHarrisDetector(int width, int height, int64_t t_start_ns, const EventHarrisOptions& options)
    : o_(options), conv_(width, height, t_start_ns, gradient_state_options(options)), width_(width), height_(height) {
  std::string why;
  if (!o_.Validate(&why)) throw std::invalid_argument("EventHarrisOptions: " + why);
  rg_ = o_.gradient_size / 2;
  rw_ = o_.window_radius;
  window_ = gaussian_kernel(2 * rw_ + 1, o_.window_sigma_px).taps;
  const size_t n = static_cast<size_t>(width) * height;
  for (auto* v : {&pxx_, &pxy_, &pyy_, &mxx_, &mxy_, &myy_}) v->assign(n, 0.0f);
  t_ref_ns_ = conv_.clock().t_ref_ns();
}

void EventHarrisDetector::recompute_all() {
  const float* sx = conv_.scaled_state(0);
  const float* sy = conv_.scaled_state(1);
  for (size_t i = 0; i < pxx_.size(); ++i) {
    pxx_[i] = sx[i] * sx[i];
    pxy_[i] = sx[i] * sy[i];
    pyy_[i] = sy[i] * sy[i];
  }
  const int d = 2 * rw_ + 1;
  for (int y = 0; y < height_; ++y)
    for (int x = 0; x < width_; ++x) {
      double a = 0, b = 0, c = 0;
      for (int j = std::max(-rw_, -y); j <= std::min(rw_, height_ - 1 - y); ++j)
        for (int i = std::max(-rw_, -x); i <= std::min(rw_, width_ - 1 - x); ++i) {
          const size_t q = static_cast<size_t>(y + j) * width_ + x + i;
          const float g = window_[static_cast<size_t>(j + rw_) * d + i + rw_];
          a += g * pxx_[q];
          b += g * pxy_[q];
          c += g * pyy_[q];
        }
      const size_t p = static_cast<size_t>(y) * width_ + x;
      mxx_[p] = static_cast<float>(a);
      mxy_[p] = static_cast<float>(b);
      myy_[p] = static_cast<float>(c);
    }
  ++stats_.recomputes;
}

double EventHarrisDetector::scaled_response(size_t i) const {
  const double a = mxx_[i], b = mxy_[i], c = myy_[i];
  const double tr = a + c;
  return a * c - b * b - o_.harris_k * tr * tr;
}

bool EventHarrisDetector::process(const Event& e) {
  if (!conv_.add_event(e)) return false;
  ++stats_.events;
  if (conv_.clock().t_ref_ns() != t_ref_ns_) {  // the gradient state was rescaled
    t_ref_ns_ = conv_.clock().t_ref_ns();
    recompute_all();
  } else {
    // The gradients changed within rg of the event: new products there, their change spread over
    // the window into M.
    const float* sx = conv_.scaled_state(0);
    const float* sy = conv_.scaled_state(1);
    const int d = 2 * rw_ + 1;
    for (int qy = std::max(0, e.y - rg_); qy <= std::min(height_ - 1, e.y + rg_); ++qy)
      for (int qx = std::max(0, e.x - rg_); qx <= std::min(width_ - 1, e.x + rg_); ++qx) {
        const size_t q = static_cast<size_t>(qy) * width_ + qx;
        const float a = sx[q] * sx[q], b = sx[q] * sy[q], c = sy[q] * sy[q];
        const float da = a - pxx_[q], db = b - pxy_[q], dc = c - pyy_[q];
        if (da == 0.0f && db == 0.0f && dc == 0.0f) continue;
        pxx_[q] = a;
        pxy_[q] = b;
        pyy_[q] = c;
        // M(p) gains G(q - p) dP for p = q - (i, j).
        for (int j = std::max(-rw_, qy - (height_ - 1)); j <= std::min(rw_, qy); ++j) {
          const size_t row = static_cast<size_t>(qy - j) * width_;
          const float* g = window_.data() + static_cast<size_t>(j + rw_) * d + rw_;
          for (int i = std::max(-rw_, qx - (width_ - 1)); i <= std::min(rw_, qx); ++i) {
            const size_t p = row + qx - i;
            mxx_[p] += g[i] * da;
            mxy_[p] += g[i] * db;
            myy_[p] += g[i] * dc;
          }
        }
      }
  }
  const int b = o_.border_px;
  if (e.x < b || e.y < b || e.x >= width_ - b || e.y >= height_ - b) return false;
  ++stats_.tested;
  const size_t k = static_cast<size_t>(e.y) * width_ + e.x;
  const double r = scaled_response(k);
  // R = R_scaled / w(t)^4.
  if (!(r > o_.threshold * std::exp(4.0 * conv_.clock().exponent(e.t_ns)))) return false;
  ++stats_.above_threshold;
  const int n = o_.nms_radius;
  for (int y = std::max(0, e.y - n); y <= std::min(height_ - 1, e.y + n); ++y)
    for (int x = std::max(0, e.x - n); x <= std::min(width_ - 1, e.x + n); ++x)
      if (scaled_response(static_cast<size_t>(y) * width_ + x) > r) return false;
  ++stats_.corners;
  return true;
}

double EventHarrisDetector::response(int x, int y, int64_t t_ns) const {
  return scaled_response(static_cast<size_t>(y) * width_ + x) * std::exp(-4.0 * conv_.clock().exponent(t_ns));
}

void EventHarrisDetector::response_image(int64_t t_ns, ImageF* out) const {
  out->resize(height_, width_);
  const double s = std::exp(-4.0 * conv_.clock().exponent(t_ns));
  for (int y = 0; y < height_; ++y)
    for (int x = 0; x < width_; ++x) (*out)(y, x) = static_cast<float>(scaled_response(static_cast<size_t>(y) * width_ + x) * s);
}

}  // namespace evio::mapping
