// An 8-bit APS frame with its time, for the reconstruction tests, and its GreyView.
#pragma once

#include <cstdint>
#include <vector>

#include "evio/mapping/reconstruction.h"

namespace evio_test {

struct TimedFrame {
  int64_t t_ns;
  std::vector<uint8_t> pixels;  // W x H row-major
};

inline evio::mapping::GreyView view(const TimedFrame& f, int w, int h) {
  return evio::mapping::GreyView{f.pixels.data(), w, h, w};
}

}  // namespace evio_test
