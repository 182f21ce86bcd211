#include "evio/frontend/sae.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace evio::frontend {

SurfaceOfActiveEvents::SurfaceOfActiveEvents(int width, int height) : width_(width), height_(height) {
  if (width <= 0 || height <= 0 || width > 65536 || height > 65536) {
    throw std::invalid_argument("surface of active events: sensor size " + std::to_string(width) + "x" +
                                std::to_string(height) + " (expected 1..65536 x 1..65536 pixels)");
  }
  times_.assign(2 * plane_size(), kNeverNs);
}

int64_t SurfaceOfActiveEvents::latest(int x, int y) const { return std::max(at(x, y, 1), at(x, y, -1)); }

void SurfaceOfActiveEvents::reset() { std::fill(times_.begin(), times_.end(), kNeverNs); }

cv::Mat SurfaceOfActiveEvents::time_surface(int64_t t_ref_ns, double tau_s, int8_t polarity) const {
  if (!(tau_s > 0) || !std::isfinite(tau_s)) {
    throw std::invalid_argument("time surface: tau " + std::to_string(tau_s) + " s (expected a finite time > 0 s)");
  }
  cv::Mat out(height_, width_, CV_32F);
  const double inv_tau_ns = 1e-9 / tau_s;
  for (int y = 0; y < height_; ++y) {
    float* row = out.ptr<float>(y);
    for (int x = 0; x < width_; ++x) {
      const int64_t t = polarity == 0 ? latest(x, y) : at(x, y, polarity);
      if (t == kNeverNs || t > t_ref_ns) {
        row[x] = 0.f;
        continue;
      }
      // Difference in int64 first: exact for any absolute time.
      row[x] = static_cast<float>(std::exp(-static_cast<double>(t_ref_ns - t) * inv_tau_ns));
    }
  }
  return out;
}

}  // namespace evio::frontend
