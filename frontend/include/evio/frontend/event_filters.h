// Per-event preprocessing: undistortion through the calibration's lookup table, a refractory
// filter and a background-activity (spatio-temporal correlation) noise filter. Each filter keeps
// one int64 time per pixel (sized from the sensor), works event by event, and counts what it did.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "evio/calib/camera.h"
#include "evio/sensors/measurements.h"

namespace evio::frontend {

// Refractory filter: drops an event when the same pixel emitted an event that passed less than
// `period_ns` before it (both polarities, or the same polarity only). Models the pixel's
// refractory period and thins bursts from one pixel.
struct RefractoryFilterOptions {
  int64_t period_ns = 1'000'000;  // refractory period, ns (default 1 ms); 0 passes everything
  bool per_polarity = false;      // true: only an earlier event of the same polarity blocks
  bool Validate(std::string* why) const;
};

// Background-activity filter (Delbruck 2008; the "spatio-temporal correlation" filter of
// v2e/jAER): an event passes when at least `min_support` other pixels within `radius` (Chebyshev
// distance, the event's own pixel excluded) had an event (any polarity) within `window_ns` before
// it. Every event, passed or not, updates its pixel's time. Isolated noise events have no recent
// neighbours; events on moving edges do.
struct BackgroundActivityFilterOptions {
  int64_t window_ns = 10'000'000;  // correlation window, ns (default 10 ms)
  int radius = 1;                  // neighbourhood radius, pixels (1: the 8-neighbourhood)
  int min_support = 1;             // neighbours needed, at most (2r+1)^2-1
  bool Validate(std::string* why) const;
};

struct FilterStats {
  int64_t events = 0;
  int64_t passed = 0;
};

class RefractoryFilter {
 public:
  RefractoryFilter(int width, int height, const RefractoryFilterOptions& options = {});
  // True when e passes. Requires e inside the sensor and non-decreasing times.
  bool accept(const Event& e);
  // A cache hint for an event a few ahead (its pixel's entry is read at random): no effect on results.
  void prefetch(const Event& e) const {
    __builtin_prefetch(last_.data() + static_cast<size_t>(e.y) * width_ + e.x, 1);
  }
  const FilterStats& stats() const { return stats_; }

 private:
  int width_, height_;
  RefractoryFilterOptions options_;
  std::vector<int64_t> last_;  // [plane][y][x], one plane unless per_polarity
  FilterStats stats_;
};

class BackgroundActivityFilter {
 public:
  BackgroundActivityFilter(int width, int height, const BackgroundActivityFilterOptions& options = {});
  // True when e passes. Requires e inside the sensor and non-decreasing times.
  bool accept(const Event& e);
  // A cache hint for an event a few ahead (the rows of its neighbourhood): no effect on results.
  void prefetch(const Event& e) const {
    const int64_t* c = last_.data() + static_cast<size_t>(e.y) * stride_ + e.x;  // top-left of the (2r+1)^2 block
    for (int dy = 0; dy <= 2 * options_.radius; ++dy) __builtin_prefetch(c + static_cast<ptrdiff_t>(dy) * stride_, 1);
  }
  const FilterStats& stats() const { return stats_; }

 private:
  int width_, height_;
  BackgroundActivityFilterOptions options_;
  std::vector<int64_t> last_;  // padded by `radius` on every side so neighbours need no bounds checks
  int stride_;
  FilterStats stats_;
};

// Event undistortion through calib::UndistortionLut: the undistorted pixel position (the ideal
// pinhole of the same fx, fy, cx, cy) and the unit bearing of every sensor pixel, looked up.
class EventUndistorter {
 public:
  explicit EventUndistorter(const calib::PinholeCamera& camera);
  int width() const { return lut_.width(); }
  int height() const { return lut_.height(); }
  // False where the calibration cannot undistort the pixel (outside its valid domain).
  bool valid(int x, int y) const { return lut_.valid(x, y); }
  // Undistorted pixel coordinates of pixel (x, y); NaN where not valid.
  const Eigen::Vector2f& undistorted(int x, int y) const { return undistorted_[index(x, y)]; }
  const Eigen::Vector3f& bearing(int x, int y) const { return lut_.bearing(x, y); }

 private:
  size_t index(int x, int y) const { return static_cast<size_t>(y) * static_cast<size_t>(lut_.width()) + static_cast<size_t>(x); }
  calib::UndistortionLut lut_;
  std::vector<Eigen::Vector2f> undistorted_;
};

}  // namespace evio::frontend
