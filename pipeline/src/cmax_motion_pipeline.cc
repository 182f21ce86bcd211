#include "evio/pipeline/cmax_motion_pipeline.h"

#include <chrono>
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

bool CmaxMotionPipelineOptions::Validate(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  std::string w;
  if (!cmax.Validate(&w)) return fail("cmax: " + w);
  if (window_events <= 0) return fail("window_events must be > 0");
  if (window_ns < 0) return fail("window_ns must be >= 0 (0: windows of window_events events)");
  if (max_window_ns < 0) return fail("max_window_ns must be >= 0 (0: no limit)");
  if (min_window_events < 1) return fail("min_window_events must be >= 1");
  if (warm_pyramid_levels < 0 || warm_pyramid_levels > 8) return fail("warm_pyramid_levels must be in [0, 8] (0: cmax.pyramid_levels)");
  if (!(dither_px >= 0 && dither_px <= 4)) return fail("dither_px must be in [0, 4] px");
  return true;
}

namespace {

const CmaxMotionPipelineOptions& checked(const CmaxMotionPipelineOptions& o, int width, int height,
                                         const std::optional<calib::PinholeCamera>& camera) {
  std::string why;
  if (!o.Validate(&why)) throw std::invalid_argument("CmaxMotionPipeline: " + why);
  if (!camera && (width <= 0 || height <= 0)) throw std::invalid_argument("CmaxMotionPipeline: the sensor size must be positive");
  const bool three_d = o.cmax.model == mapping::WarpModel::kRotation || o.cmax.model == mapping::WarpModel::kSixDof;
  if (three_d && !camera)
    throw std::invalid_argument(std::string("CmaxMotionPipeline: the ") + mapping::warp_model_name(o.cmax.model) +
                                " model needs a camera calibration (its pinhole)");
  if (o.undistortion == CmaxUndistortion::kLut && !camera)
    throw std::invalid_argument("CmaxMotionPipeline: undistortion 'lut' needs a camera calibration");
  return o;
}

// Two numbers uniform in [-0.5, 0.5) from an event's stamp and pixel (splitmix64).
inline void event_hash_offsets(int64_t t_ns, float x, float y, float* ox, float* oy) {
  uint64_t z = static_cast<uint64_t>(t_ns) * 0x9E3779B97F4A7C15ull ^
               (static_cast<uint64_t>(static_cast<uint32_t>(static_cast<int32_t>(x))) << 32 |
                static_cast<uint32_t>(static_cast<int32_t>(y)));
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  z ^= z >> 31;
  *ox = static_cast<float>(static_cast<double>(z >> 40) * 0x1.0p-24 - 0.5);
  *oy = static_cast<float>(static_cast<double>((z >> 16) & 0xFFFFFF) * 0x1.0p-24 - 0.5);
}

bool has_distortion(const calib::PinholeCamera& c) {
  if (c.intrinsics().model == calib::DistortionModel::kNone) return false;
  for (double k : c.intrinsics().distortion)
    if (k != 0.0) return true;
  return false;
}

}  // namespace

CmaxMotionPipeline::CmaxMotionPipeline(const CmaxMotionPipelineOptions& options, int width, int height,
                                       const std::optional<calib::PinholeCamera>& camera)
    : o_(checked(options, width, height, camera)), width_(camera ? camera->width() : width), height_(camera ? camera->height() : height) {
  mapping::CmaxOptions c = o_.cmax;
  c.width = width_;
  c.height = height_;
  if (camera) {
    const calib::CameraIntrinsics& k = camera->intrinsics();
    c.geometry.fx = k.fx;
    c.geometry.fy = k.fy;
    c.geometry.cx = k.cx;
    c.geometry.cy = k.cy;
    distorted_ = has_distortion(*camera);
    distortion_name_ = calib::distortion_model_name(k.model);
    undistorter_ = std::make_unique<frontend::EventUndistorter>(*camera);
  } else {
    c.geometry.cx = 0.5 * (width_ - 1);
    c.geometry.cy = 0.5 * (height_ - 1);
  }
  o_.cmax = c;
  cold_ = std::make_unique<mapping::ContrastMaximizer>(c);
  mapping::CmaxOptions cw = c;
  if (o_.warm_pyramid_levels > 0) cw.pyramid_levels = o_.warm_pyramid_levels;
  warm_ = std::make_unique<mapping::ContrastMaximizer>(cw);
  if (o_.undistortion != CmaxUndistortion::kAuto) {
    undistortion_ = o_.undistortion;
    undistortion_reason_ = "as configured";
  }
  if (o_.window_ns == 0) buf_.reserve(static_cast<size_t>(o_.window_events));
}

CmaxMotionPipeline::~CmaxMotionPipeline() = default;

bool CmaxMotionPipeline::process(const SubpixelEvent& e) {
  ++stats_.events;
  const size_t before = done_.size();
  if (o_.window_ns > 0) {
    if (!started_) {
      started_ = true;
      window_start_ns_ = e.t_ns;
    }
    // Saturating end, so stamps near INT64_MAX cannot overflow.
    const int64_t end = window_start_ns_ > INT64_MAX - o_.window_ns ? INT64_MAX : window_start_ns_ + o_.window_ns;
    if (e.t_ns >= end) {
      close_window(window_start_ns_, end);
      const int64_t k = (e.t_ns - window_start_ns_) / o_.window_ns;  // >= 1 windows later
      stats_.windows_skipped += k - 1;                                  // the empty ones in between
      window_start_ns_ += k * o_.window_ns;
    }
    buf_.push_back(e);
  } else {
    // A window that has spanned max_window_ns closes before this event (its end: its last event).
    if (o_.max_window_ns > 0 && !buf_.empty() && e.t_ns - buf_.front().t_ns >= o_.max_window_ns)
      close_window(buf_.front().t_ns, buf_.back().t_ns);
    buf_.push_back(e);
    if (static_cast<int64_t>(buf_.size()) >= o_.window_events) close_window(buf_.front().t_ns, buf_.back().t_ns);
  }
  return done_.size() > before;
}

void CmaxMotionPipeline::finish() {
  if (buf_.empty()) return;
  // The tail: a window cut short by the end of the stream. Shorter than half a window (in events,
  // or in time against window_ns / max_window_ns) it is dropped once an earlier window was
  // estimated: few events and little motion give a poor estimate (measured on poster_rotation:
  // a 4.5 ms tail of a 60k-event stream, 48 deg/s off, the worst window of 220).
  const int64_t span = buf_.back().t_ns - (o_.window_ns > 0 ? window_start_ns_ : buf_.front().t_ns);
  const bool half_events = o_.window_ns == 0 && static_cast<int64_t>(buf_.size()) * 2 >= o_.window_events;
  const int64_t duration = o_.window_ns > 0 ? o_.window_ns : o_.max_window_ns;
  const bool half_time = duration > 0 && span * 2 >= duration;
  if (stats_.windows > 0 && !half_events && !half_time) {
    ++stats_.windows_skipped;
    buf_.clear();
    return;
  }
  // The partial window spans its events only (a time window's nominal end lies beyond the data).
  close_window(o_.window_ns > 0 ? window_start_ns_ : buf_.front().t_ns, buf_.back().t_ns);
}

std::vector<CmaxMotionWindow> CmaxMotionPipeline::take_windows() {
  std::vector<CmaxMotionWindow> out;
  out.swap(done_);
  return out;
}

bool CmaxMotionPipeline::integer_window() const {
  for (const SubpixelEvent& e : buf_)
    if (e.x != std::floor(e.x) || e.y != std::floor(e.y)) return false;
  return true;
}

void CmaxMotionPipeline::decide_undistortion() {
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
      std::snprintf(buf, sizeof(buf),
                    "sub-pixel input (an event at (%.3f, %.3f) is %s): treated as already undistorted", e.x, e.y,
                    fractional ? "fractional" : "outside the sensor");
      undistortion_ = CmaxUndistortion::kNone;
      undistortion_reason_ = buf;
      return;
    }
  }
  undistortion_ = CmaxUndistortion::kLut;
  undistortion_reason_ = std::string("integer pixels of a distorted camera (") + distortion_name_ +
                         "): undistorted through the lookup table";
}

void CmaxMotionPipeline::close_window(int64_t t_start_ns, int64_t t_end_ns) {
  if (static_cast<int64_t>(buf_.size()) < o_.min_window_events) {
    ++stats_.windows_skipped;
    buf_.clear();
    return;
  }
  if (undistortion_ == CmaxUndistortion::kAuto) decide_undistortion();
  if (!input_checked_) {  // integer or sub-pixel input, decided on the first window
    integer_input_ = integer_window();
    input_checked_ = true;
  }
  using clock = std::chrono::steady_clock;
  const auto c0 = clock::now();
  const int64_t t_ref = t_start_ns + (t_end_ns - t_start_ns) / 2;
  const float dither = static_cast<float>(o_.dither_px);
  mapping::CmaxEvents ev(t_ref, cold_->options().geometry);
  ev.reserve(buf_.size());
  if (undistortion_ == CmaxUndistortion::kLut) {
    for (const SubpixelEvent& e : buf_) {
      const float rx = std::round(e.x), ry = std::round(e.y);
      if (!(rx >= 0 && ry >= 0 && rx < static_cast<float>(width_) && ry < static_cast<float>(height_))) {
        ++stats_.events_dropped;
        continue;
      }
      const int xi = static_cast<int>(rx), yi = static_cast<int>(ry);
      if (!undistorter_->valid(xi, yi)) {
        ++stats_.events_dropped;
        continue;
      }
      const Eigen::Vector2f& u = undistorter_->undistorted(xi, yi);
      if (dither > 0) {
        float ox, oy;
        event_hash_offsets(e.t_ns, rx, ry, &ox, &oy);
        ev.push_back(u.x() + dither * ox, u.y() + dither * oy, e.t_ns, e.polarity);
      } else {
        ev.push_back(u.x(), u.y(), e.t_ns, e.polarity);
      }
    }
  } else {
    for (const SubpixelEvent& e : buf_) {
      if (!std::isfinite(e.x) || !std::isfinite(e.y)) {
        ++stats_.events_dropped;
        continue;
      }
      if (integer_input_ && dither > 0) {
        float ox, oy;
        event_hash_offsets(e.t_ns, e.x, e.y, &ox, &oy);
        ev.push_back(e.x + dither * ox, e.y + dither * oy, e.t_ns, e.polarity);
      } else {
        ev.push_back(e.x, e.y, e.t_ns, e.polarity);
      }
    }
  }
  buf_.clear();
  if (static_cast<int64_t>(ev.size()) < o_.min_window_events) {
    ++stats_.windows_skipped;
    return;
  }

  CmaxMotionWindow w;
  const bool warm = o_.warm_start && previous_.has_value();
  mapping::CmaxResult r;
  if (warm) {
    r = warm_->maximize(ev, *previous_);
    if (r.objective_init < r.objective_zero) {  // the previous motion no longer fits: start over from zero
      mapping::CmaxResult c = cold_->maximize(ev);
      c.iterations += r.iterations;
      c.evaluations += r.evaluations;
      r = std::move(c);
      w.reset = true;
    }
  } else {
    r = cold_->maximize(ev);
  }
  w.time_ms = std::chrono::duration<double, std::milli>(clock::now() - c0).count();
  if (r.params.allFinite()) previous_ = r.params;

  w.index = stats_.windows;
  w.t_start_ns = t_start_ns;
  w.t_end_ns = t_end_ns;
  w.t_ref_ns = t_ref;
  w.events = static_cast<int64_t>(ev.size());
  w.model = o_.cmax.model;
  w.params = r.params;
  w.objective_zero = r.objective_zero;
  w.objective = r.objective;
  w.iterations = r.iterations;
  w.evaluations = r.evaluations;
  w.warm_started = warm;
  w.stop = r.stop;
  if (o_.keep_iwe) {
    w.iwe_zero = cold_->iwe(ev, Eigen::VectorXd::Zero(mapping::warp_dof(w.model)), nullptr, false);
    w.iwe = cold_->iwe(ev, w.params, nullptr, false);
  }
  if (o_.keep_events) w.prepared = std::move(ev);
  ++stats_.windows;
  stats_.events_used += w.events;
  stats_.warm_starts += warm ? 1 : 0;
  stats_.resets += w.reset ? 1 : 0;
  stats_.iterations += w.iterations;
  stats_.evaluations += w.evaluations;
  stats_.time_ms += w.time_ms;
  done_.push_back(std::move(w));
}

}  // namespace evio::pipeline
