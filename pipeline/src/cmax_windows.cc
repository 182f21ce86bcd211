#include "evio/pipeline/cmax_windows.h"

#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "evio/frontend/event_filters.h"

namespace evio::pipeline {

const char* cmax_undistortion_name(CmaxUndistortion u) {
  switch (u) {
    case CmaxUndistortion::kAuto: return "auto";
    case CmaxUndistortion::kNone: return "none";
    case CmaxUndistortion::kLut: return "lut";
  }
  return "?";
}

std::optional<CmaxUndistortion> cmax_undistortion_from_name(const std::string& name) {
  for (CmaxUndistortion u : {CmaxUndistortion::kAuto, CmaxUndistortion::kNone, CmaxUndistortion::kLut})
    if (name == cmax_undistortion_name(u)) return u;
  return std::nullopt;
}

bool CmaxWindowOptions::Validate(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (window_events <= 0) return fail("window_events must be > 0");
  if (window_ns < 0) return fail("window_ns must be >= 0 (0: windows of window_events events)");
  if (max_window_ns < 0) return fail("max_window_ns must be >= 0 (0: no limit)");
  if (min_window_events < 1) return fail("min_window_events must be >= 1");
  if (!(dither_px >= 0 && dither_px <= 4)) return fail("dither_px must be in [0, 4] px");
  return true;
}

namespace {

bool has_distortion(const calib::PinholeCamera& c) {
  if (c.intrinsics().model == calib::DistortionModel::kNone) return false;
  for (double k : c.intrinsics().distortion)
    if (k != 0.0) return true;
  return false;
}

}  // namespace

CmaxWindower::CmaxWindower(const CmaxWindowOptions& options, int width, int height,
                           const std::optional<calib::PinholeCamera>& camera, const mapping::WarpGeometry& base)
    : options_(options), geometry_(base) {
  std::string why;
  if (!options_.Validate(&why)) throw std::invalid_argument("CMax windows: " + why);
  if (!camera && (width <= 0 || height <= 0)) throw std::invalid_argument("CMax windows: the sensor size must be positive");
  if (options_.undistortion == CmaxUndistortion::kLut && !camera)
    throw std::invalid_argument("CMax windows: undistortion 'lut' needs a camera calibration");
  width_ = camera ? camera->width() : width;
  height_ = camera ? camera->height() : height;
  if (camera) {
    const calib::CameraIntrinsics& k = camera->intrinsics();
    geometry_.fx = k.fx, geometry_.fy = k.fy, geometry_.cx = k.cx, geometry_.cy = k.cy;
    distorted_ = has_distortion(*camera);
    distortion_name_ = calib::distortion_model_name(k.model);
    undistorter_ = std::make_unique<frontend::EventUndistorter>(*camera);
  } else {
    geometry_.cx = 0.5 * (width_ - 1);
    geometry_.cy = 0.5 * (height_ - 1);
  }
  if (options_.undistortion != CmaxUndistortion::kAuto) {
    undistortion_ = options_.undistortion;
    undistortion_reason_ = "as configured";
  }
  if (options_.window_ns == 0) buf_.reserve(static_cast<size_t>(std::min<int64_t>(options_.window_events, 1 << 24)));
}

CmaxWindower::~CmaxWindower() = default;

bool CmaxWindower::process(const SubpixelEvent& e) {
  ++stats_.events;
  const size_t before = done_.size();
  if (options_.window_ns > 0) {
    if (!started_) {
      started_ = true;
      window_start_ns_ = e.t_ns;
    }
    // Saturating end, so stamps near INT64_MAX cannot overflow.
    const int64_t end =
        window_start_ns_ > INT64_MAX - options_.window_ns ? INT64_MAX : window_start_ns_ + options_.window_ns;
    if (e.t_ns >= end) {
      close_window(window_start_ns_, end);
      const int64_t k = (e.t_ns - window_start_ns_) / options_.window_ns;  // >= 1 windows later
      stats_.windows_skipped += k - 1;                                     // the empty ones in between
      window_start_ns_ += k * options_.window_ns;
    }
    buf_.push_back(e);
  } else {
    if (options_.max_window_ns > 0 && !buf_.empty() && e.t_ns - buf_.front().t_ns >= options_.max_window_ns)
      close_window(buf_.front().t_ns, buf_.back().t_ns);
    buf_.push_back(e);
    if (static_cast<int64_t>(buf_.size()) >= options_.window_events) close_window(buf_.front().t_ns, buf_.back().t_ns);
  }
  return done_.size() > before;
}

void CmaxWindower::finish() {
  if (buf_.empty()) return;
  const int64_t span = buf_.back().t_ns - (options_.window_ns > 0 ? window_start_ns_ : buf_.front().t_ns);
  const bool half_events = options_.window_ns == 0 && static_cast<int64_t>(buf_.size()) * 2 >= options_.window_events;
  const int64_t duration = options_.window_ns > 0 ? options_.window_ns : options_.max_window_ns;
  const bool half_time = duration > 0 && span * 2 >= duration;
  if (stats_.windows > 0 && !half_events && !half_time) {
    ++stats_.windows_skipped;
    buf_first_index_ += static_cast<int64_t>(buf_.size());
    buf_.clear();
    return;
  }
  // The partial window spans its events only (a time window's nominal end lies beyond the data).
  close_window(options_.window_ns > 0 ? window_start_ns_ : buf_.front().t_ns, buf_.back().t_ns);
}

std::vector<CmaxWindow> CmaxWindower::take() {
  std::vector<CmaxWindow> out;
  out.swap(done_);
  return out;
}

void CmaxWindower::decide_undistortion() {
  if (!undistorter_) {
    undistortion_ = CmaxUndistortion::kNone;
    undistortion_reason_ = "no camera calibration: coordinates used as they are";
    return;
  }
  if (!distorted_) {
    undistortion_ = CmaxUndistortion::kNone;
    undistortion_reason_ = "the camera has no lens distortion: coordinates used as they are";
    return;
  }
  for (const SubpixelEvent& e : buf_) {
    const bool fractional = e.x != std::floor(e.x) || e.y != std::floor(e.y);
    const bool outside = !(e.x >= 0 && e.y >= 0 && e.x < width_ && e.y < height_);
    if (fractional || outside) {
      char buf[200];
      std::snprintf(buf, sizeof(buf), "sub-pixel input (an event at (%.3f, %.3f) is %s): treated as already undistorted",
                    e.x, e.y, fractional ? "fractional" : "outside the sensor");
      undistortion_ = CmaxUndistortion::kNone;
      undistortion_reason_ = buf;
      return;
    }
  }
  undistortion_ = CmaxUndistortion::kLut;
  undistortion_reason_ =
      std::string("integer pixels of a distorted camera (") + distortion_name_ + "): undistorted through the lookup table";
}

void CmaxWindower::close_window(int64_t t_start_ns, int64_t t_end_ns) {
  const int64_t first = buf_first_index_;
  buf_first_index_ += static_cast<int64_t>(buf_.size());
  if (static_cast<int64_t>(buf_.size()) < options_.min_window_events) {
    ++stats_.windows_skipped;
    buf_.clear();
    return;
  }
  if (undistortion_ == CmaxUndistortion::kAuto) decide_undistortion();
  if (!input_checked_) {  // integer or sub-pixel input, decided on the first window
    integer_input_ = true;
    for (const SubpixelEvent& e : buf_)
      if (e.x != std::floor(e.x) || e.y != std::floor(e.y)) integer_input_ = false;
    input_checked_ = true;
  }
  CmaxWindow w;
  w.t_start_ns = t_start_ns;
  w.t_end_ns = t_end_ns;
  w.t_ref_ns = t_start_ns + (t_end_ns - t_start_ns) / 2;
  w.input_begin = first;
  w.input_end = buf_first_index_;
  w.events = mapping::CmaxEvents(w.t_ref_ns, geometry_);
  w.events.reserve(buf_.size());
  w.input_index.reserve(buf_.size());
  const float dither = static_cast<float>(options_.dither_px);
  for (size_t i = 0; i < buf_.size(); ++i) {
    const SubpixelEvent& e = buf_[i];
    float x = e.x, y = e.y;
    if (!std::isfinite(x) || !std::isfinite(y)) {
      ++stats_.events_dropped;
      continue;
    }
    if (undistortion_ == CmaxUndistortion::kLut) {
      const float rx = std::round(x), ry = std::round(y);
      if (!(rx >= 0 && ry >= 0 && rx < static_cast<float>(width_) && ry < static_cast<float>(height_)) ||
          !undistorter_->valid(static_cast<int>(rx), static_cast<int>(ry))) {
        ++stats_.events_dropped;
        continue;
      }
      const Eigen::Vector2f& u = undistorter_->undistorted(static_cast<int>(rx), static_cast<int>(ry));
      x = u.x(), y = u.y();
      if (dither > 0) {
        float ox, oy;
        mapping::pixel_dither(e.t_ns, rx, ry, &ox, &oy);
        x += dither * ox, y += dither * oy;
      }
    } else if (integer_input_ && dither > 0) {
      float ox, oy;
      mapping::pixel_dither(e.t_ns, x, y, &ox, &oy);
      x += dither * ox, y += dither * oy;
    }
    w.events.push_back(x, y, e.t_ns, e.polarity);
    w.input_index.push_back(first + static_cast<int64_t>(i));
  }
  buf_.clear();
  if (static_cast<int64_t>(w.events.size()) < options_.min_window_events) {
    ++stats_.windows_skipped;
    return;
  }
  w.index = stats_.windows++;
  stats_.events_used += static_cast<int64_t>(w.events.size());
  done_.push_back(std::move(w));
}

}  // namespace evio::pipeline
