// eFAST corner events (Mueggler, Bartolozzi, Scaramuzza, "Fast Event-based Corner Detection",
// BMVC 2017). On the SAE of the event's polarity, after updating it with the event, the event is
// a corner when
//   - on the circle of radius 3 (16 pixels) some contiguous arc of 3 to 6 pixels is strictly newer
//     than every other pixel of that circle, and
//   - on the circle of radius 4 (20 pixels) some contiguous arc of 4 to 8 pixels is strictly newer
//     than every other pixel of that circle (tested only when the inner circle passes).
// Events closer than 4 pixels to the border are never corners. These are the decisions of the
// authors' public FastDetector (which updates the SAE with every event), on a correctly sized map.
//
// Optional filtered SAE (Mueggler et al. Sec. 3; formulated as in Alzugaray and Chli, Arc*, 2018):
// an event updates the SAE, and is tested, only when the latest event of its polarity at its
// pixel is older than `filter_window_ns` or the pixel's latest event had the other polarity;
// other events are not corners. The unfiltered latest times are kept for that test.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>

#include "evio/frontend/sae.h"

namespace evio::frontend {

// Circle offsets (dx, dy), in order around the circle (contiguity is what matters).
extern const std::array<std::array<int, 2>, 16> kEfastCircle3;
extern const std::array<std::array<int, 2>, 20> kEfastCircle4;

// Arc tests on the circle's times in circle order. True when some contiguous arc (cyclic) of
// min_arc..max_arc elements has every element strictly greater than every element outside it.
bool efast_arc_test_16(const int64_t t[16]);  // arcs 3..6
bool efast_arc_test_20(const int64_t t[20]);  // arcs 4..8

struct EfastOptions {
  bool filter_sae = false;                 // filtered SAE (see above)
  int64_t filter_window_ns = 50'000'000;   // filter window, ns (paper: 50 ms)
  bool Validate(std::string* why) const;
};

struct EfastStats {
  int64_t events = 0;         // events given to process()
  int64_t tested = 0;         // events that updated the SAE and were inside the border
  int64_t inner_passed = 0;   // events whose inner circle passed (the share reaching the outer circle)
  int64_t corners = 0;        // corner events
};

class EfastDetector {
 public:
  // Sensor size in pixels (from the calibration). Throws std::invalid_argument on bad sizes/options.
  EfastDetector(int width, int height, const EfastOptions& options = {});

  // Updates the SAE with e (per the options) and returns true when e is a corner event.
  // Requires 0 <= e.x < width, 0 <= e.y < height; events must come in non-decreasing time.
  bool process(const Event& e);

  const SurfaceOfActiveEvents& sae() const { return sae_; }
  const EfastStats& stats() const { return stats_; }
  const EfastOptions& options() const { return options_; }
  void reset();

 private:
  EfastOptions options_;
  SurfaceOfActiveEvents sae_;
  SurfaceOfActiveEvents latest_;  // unfiltered latest times (filter_sae only)
  std::array<ptrdiff_t, 16> off3_{};
  std::array<ptrdiff_t, 20> off4_{};
  EfastStats stats_;
};

}  // namespace evio::frontend
