// Surface of Active Events (SAE): per pixel and polarity, the time of the latest event (int64 ns).
// The map is sized from the calibration (any sensor size), stored row-major, one plane per
// polarity, so per-event code can read neighbours with precomputed offsets.
#pragma once

#include <cstdint>
#include <limits>
#include <vector>

#include <opencv2/core/mat.hpp>

#include "evio/sensors/measurements.h"

namespace evio::frontend {

// Time of a pixel that has not fired yet: older than any event.
constexpr int64_t kNeverNs = std::numeric_limits<int64_t>::min();

// Plane index of a polarity: 1 for ON (+1), 0 for OFF (-1).
inline int polarity_plane(int8_t polarity) { return polarity > 0 ? 1 : 0; }

class SurfaceOfActiveEvents {
 public:
  // Throws std::invalid_argument unless width, height > 0.
  SurfaceOfActiveEvents(int width, int height);

  int width() const { return width_; }
  int height() const { return height_; }
  bool contains(int x, int y) const { return x >= 0 && y >= 0 && x < width_ && y < height_; }

  // Sets the event's pixel in its polarity plane to e.t_ns (requires contains(e.x, e.y)).
  void update(const Event& e) { plane(e.polarity)[index(e.x, e.y)] = e.t_ns; }
  // Latest time of polarity `polarity` (+1/-1) at (x, y); kNeverNs when it has not fired.
  int64_t at(int x, int y, int8_t polarity) const { return plane(polarity)[index(x, y)]; }
  // Latest time of either polarity.
  int64_t latest(int x, int y) const;

  // Row-major plane of one polarity: element (x, y) at [y * width + x].
  int64_t* plane(int8_t polarity) { return times_.data() + polarity_plane(polarity) * plane_size(); }
  const int64_t* plane(int8_t polarity) const { return times_.data() + polarity_plane(polarity) * plane_size(); }
  size_t index(int x, int y) const { return static_cast<size_t>(y) * static_cast<size_t>(width_) + static_cast<size_t>(x); }

  // Forgets every event.
  void reset();

  // Normalised time surface for display, CV_32F in [0, 1]: exp(-(t_ref - t) / tau) of the latest
  // event (polarity 0: either polarity, +1/-1: that plane), 0 where the pixel never fired or
  // fired after t_ref. tau_s > 0 in seconds.
  cv::Mat time_surface(int64_t t_ref_ns, double tau_s, int8_t polarity = 0) const;

 private:
  size_t plane_size() const { return static_cast<size_t>(width_) * static_cast<size_t>(height_); }

  int width_ = 0;
  int height_ = 0;
  std::vector<int64_t> times_;  // [plane][y][x]
};

}  // namespace evio::frontend
