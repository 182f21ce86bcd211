// Corner events from a continuous-time Harris response (Scheerlinck, Barnes, Mahony, "Asynchronous
// Spatial Image Convolutions for Event Cameras", RAL 2019, Sec. on Harris): the gradient state
// (Ix, Iy) is the high-pass filter's state convolved with Sobel kernels (async_convolution.h,
// events only); the structure tensor M = G * [Ix^2, Ix Iy; Ix Iy, Iy^2] (G: a Gaussian window) and
// the response R = det M - k (trace M)^2 are updated per event only where the event changed them
// (the gradient kernel's neighbourhood, grown by the window). An event is a corner event when
// R at its pixel exceeds `threshold` and is the largest R within `nms_radius` (local non-maximum
// suppression), and it lies at least `border_px` from the image border.
//
// Implementation: the products and M are kept in the gradient state's scaled units (S = C w(t),
// scaled_decay.h, exact because the high-pass reference is 0), so pixels an event does not touch
// need no update as time passes: R(t) = R_scaled / w(t)^4 for every pixel. At a rebase of the
// state (every 20 / alpha seconds) the products and M are recomputed from the rescaled state,
// which also clears the rounding that incremental updates of M accumulate.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "evio/mapping/async_convolution.h"

namespace evio::mapping {

struct EventHarrisOptions {
  double cutoff_hz = 5.0;       // high-pass cut-off of the gradient state, Hz, in [0, 1e6]
  double contrast_on = 0.1;     // log-intensity step of an ON event, > 0
  double contrast_off = 0.1;    // of an OFF event (subtracted), > 0
  int gradient_size = 3;        // Sobel kernel size: 3 or 5 px
  int window_radius = 2;        // Gaussian window of M: (2 r + 1)^2 px, r in 1..4
  double window_sigma_px = 1.0; // its sigma, px, > 0
  double harris_k = 0.04;       // R = det M - k trace(M)^2, k in [0, 0.25)
  double threshold = 1e-6;      // minimum R of a corner event, (log intensity / px)^4, >= 0; R scales
                                // with contrast^4 and edge strength^4, so the threshold goes with the
                                // contrast and the scene (the default is for contrast 0.1 on real DAVIS
                                // data; the simulated checkerboard's tests, contrast 0.2 and edges of
                                // 1.8 log, use 5e-4; docs/results/corners.md)
  int nms_radius = 3;           // non-maximum suppression radius, px, 0..8 (0: none)
  int border_px = 4;            // events closer to the border are never corners, px, >= 0
  bool Validate(std::string* why) const;
};

struct EventHarrisStats {
  int64_t events = 0;          // events inside the sensor
  int64_t tested = 0;          // of those, inside the border (R and NMS evaluated)
  int64_t above_threshold = 0; // of those, R above the threshold
  int64_t corners = 0;         // corner events
  int64_t recomputes = 0;      // full recomputations of M (one per rebase)
};

class EventHarrisDetector {
 public:
  // Throws std::invalid_argument for invalid options or sizes.
  EventHarrisDetector(int width, int height, int64_t t_start_ns, const EventHarrisOptions& options = {});

  // Updates the state with e (events in time order) and returns true when e is a corner event.
  // Events outside the sensor update nothing and are not corners.
  bool process(const Event& e);

  // The Harris response at t_ns (>= the last event), (log / px)^4: at one pixel, or H x W.
  double response(int x, int y, int64_t t_ns) const;
  void response_image(int64_t t_ns, ImageF* out) const;
  const AsyncConvolution& gradient_state() const { return conv_; }
  const EventHarrisStats& stats() const { return stats_; }
  const EventHarrisOptions& options() const { return o_; }

 private:
  void recompute_all();
  double scaled_response(size_t i) const;

  EventHarrisOptions o_;
  AsyncConvolution conv_;
  int width_, height_, rg_, rw_;
  std::vector<float> window_;                    // (2 rw + 1)^2 Gaussian taps
  std::vector<float> pxx_, pxy_, pyy_;           // gradient products, scaled by w^2
  std::vector<float> mxx_, mxy_, myy_;           // windowed products, scaled by w^2
  int64_t t_ref_ns_;                             // the gradient state's t_ref at the last update
  EventHarrisStats stats_;
};

}  // namespace evio::mapping
