#include "evio/frontend/event_filters.h"
#include "evio/frontend/option_tables.h"

#include <limits>
#include <stdexcept>

namespace evio::frontend {
namespace {

constexpr int64_t kNever = std::numeric_limits<int64_t>::min();

void check_size(const char* what, int width, int height) {
  if (width <= 0 || height <= 0 || width > 65536 || height > 65536) {
    throw std::invalid_argument(std::string(what) + ": sensor size " + std::to_string(width) + "x" +
                                std::to_string(height) + " (expected 1..65536 x 1..65536 pixels)");
  }
}

// t - last > window without overflow when last is kNever.
inline bool older_than(int64_t t, int64_t last, int64_t window) { return last == kNever || t - last > window; }

}  // namespace

bool RefractoryFilterOptions::Validate(std::string* why) const { return refractory_table().check(*this, why); }

bool BackgroundActivityFilterOptions::Validate(std::string* why) const {
  if (!background_activity_table().check(*this, why)) return false;
  const int n = (2 * radius + 1) * (2 * radius + 1) - 1;
  if (min_support > n) {
    return validation_failed(why, "min_support " + std::to_string(min_support) + " is more than the " +
                                      std::to_string(n) + " neighbours within radius " + std::to_string(radius));
  }
  return true;
}

RefractoryFilter::RefractoryFilter(int width, int height, const RefractoryFilterOptions& options)
    : width_(width), height_(height), options_(options) {
  check_size("refractory filter", width, height);
  std::string why;
  if (!options.Validate(&why)) throw std::invalid_argument("refractory filter options: " + why);
  last_.assign(static_cast<size_t>(width) * height * (options.per_polarity ? 2 : 1), kNever);
}

bool RefractoryFilter::accept(const Event& e) {
  ++stats_.events;
  size_t idx = static_cast<size_t>(e.y) * width_ + e.x;
  if (options_.per_polarity && e.polarity > 0) idx += static_cast<size_t>(width_) * height_;
  int64_t& last = last_[idx];
  // An event exactly `period` after the last passed one passes.
  if (last != kNever && e.t_ns - last < options_.period_ns) return false;
  last = e.t_ns;
  ++stats_.passed;
  return true;
}

BackgroundActivityFilter::BackgroundActivityFilter(int width, int height, const BackgroundActivityFilterOptions& options)
    : width_(width), height_(height), options_(options), stride_(width + 2 * options.radius) {
  check_size("background-activity filter", width, height);
  std::string why;
  if (!options.Validate(&why)) throw std::invalid_argument("background-activity filter options: " + why);
  last_.assign(static_cast<size_t>(stride_) * (height + 2 * options.radius), kNever);
}

bool BackgroundActivityFilter::accept(const Event& e) {
  ++stats_.events;
  const int r = options_.radius;
  int64_t* centre = last_.data() + static_cast<size_t>(e.y + r) * stride_ + (e.x + r);
  int support = 0;
  for (int dy = -r; dy <= r && support < options_.min_support; ++dy) {  // enough support: done
    const int64_t* row = centre + static_cast<ptrdiff_t>(dy) * stride_;
    for (int dx = -r; dx <= r; ++dx) {
      if (dx == 0 && dy == 0) continue;
      support += older_than(e.t_ns, row[dx], options_.window_ns) ? 0 : 1;
    }
  }
  *centre = e.t_ns;
  if (support < options_.min_support) return false;
  ++stats_.passed;
  return true;
}

EventUndistorter::EventUndistorter(const calib::PinholeCamera& camera) : lut_(camera) {
  const calib::CameraIntrinsics& k = camera.intrinsics();
  const float nan = std::numeric_limits<float>::quiet_NaN();
  undistorted_.resize(static_cast<size_t>(lut_.width()) * lut_.height());
  for (int y = 0; y < lut_.height(); ++y) {
    for (int x = 0; x < lut_.width(); ++x) {
      const Eigen::Vector2f n = lut_.normalized(x, y);
      undistorted_[index(x, y)] = lut_.valid(x, y) && n.allFinite()
                                      ? Eigen::Vector2f(static_cast<float>(k.fx * n.x() + k.cx),
                                                        static_cast<float>(k.fy * n.y() + k.cy))
                                      : Eigen::Vector2f(nan, nan);
    }
  }
}

}  // namespace evio::frontend
