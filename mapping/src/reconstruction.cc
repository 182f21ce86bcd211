#include "evio/mapping/reconstruction.h"
#include "evio/calib/error.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

namespace evio::mapping {
namespace {

constexpr double kTwoPi = 6.283185307179586;
void check_size(int width, int height) {
  if (width < 1 || height < 1 || width > 65536 || height > 65536)
    throw std::invalid_argument("reconstruction: sensor size " + std::to_string(width) + " x " + std::to_string(height) +
                                " outside 1..65536");
}

void check_frame(const GreyView& f, int width, int height) {
  if (f.width != width || f.height != height || !f.data || f.stride < f.width)
    throw std::invalid_argument("reconstruction: a frame of " + std::to_string(f.width) + " x " +
                                std::to_string(f.height) + " px on a " + std::to_string(width) + " x " +
                                std::to_string(height) + " sensor (frames must have the sensor's size)");
}

void copy_frame(const GreyView& f, std::vector<uint8_t>* out) {
  out->resize(static_cast<size_t>(f.width) * f.height);
  for (int y = 0; y < f.height; ++y) std::memcpy(out->data() + static_cast<size_t>(y) * f.width, f.data + y * f.stride, f.width);
}

bool contrasts_valid(double on, double off, std::string* why) {
  if (!(std::isfinite(on) && on > 0 && on <= 10)) return validation_failed(why, "contrast_on must be in (0, 10]");
  if (!(std::isfinite(off) && off > 0 && off <= 10)) return validation_failed(why, "contrast_off must be in (0, 10]");
  return true;
}

}  // namespace

const char* reconstruction_method_name(ReconstructionMethod m) {
  switch (m) {
    case ReconstructionMethod::kHighPass: return "hf";
    case ReconstructionMethod::kComplementary: return "cf";
    case ReconstructionMethod::kKalman: return "akf";
    case ReconstructionMethod::kGradient: return "gradient";
  }
  return "?";
}

bool FrameResponse::Validate(std::string* why) const {
  if (!(std::isfinite(gamma) && gamma > 0 && gamma <= 10)) return validation_failed(why, "frame gamma must be in (0, 10]");
  if (!(std::isfinite(offset) && offset > 0 && offset <= 1e6)) return validation_failed(why, "frame log offset must be in (0, 1e6]");
  if (!(initial_grey >= 0 && initial_grey <= 255)) return validation_failed(why, "initial_grey must be in [0, 255]");
  return true;
}

double FrameResponse::log_of(double v) const { return gamma * std::log(v / 255.0 + offset); }

bool ComplementaryFilterOptions::Validate(std::string* why) const {
  if (!(std::isfinite(cutoff_hz) && cutoff_hz >= 0 && cutoff_hz <= 1e6)) return validation_failed(why, "cutoff_hz must be in [0, 1e6]");
  if (!contrasts_valid(contrast_on, contrast_off, why)) return false;
  if (!std::isfinite(initial_log_intensity) || std::fabs(initial_log_intensity) > 1e6)
    return validation_failed(why, "initial_log_intensity must be finite, |value| <= 1e6");
  return frame.Validate(why);
}

// ---------------------------------------------------------------------------------------------
// Complementary filter

ComplementaryFilter::ComplementaryFilter(int width, int height, int64_t t_start_ns, const ComplementaryFilterOptions& options)
    : width_(width), height_(height), o_(options), clock_(kTwoPi * options.cutoff_hz * 1e-9, t_start_ns) {
  check_size(width, height);
  std::string why;
  if (!o_.Validate(&why)) throw std::invalid_argument("ComplementaryFilterOptions: " + why);
  c_on_ = static_cast<float>(o_.contrast_on);
  c_off_ = static_cast<float>(-o_.contrast_off);
  for (int v = 0; v < 256; ++v) lut_[v] = static_cast<float>(o_.frame.log_of(v));
  reference_ = o_.high_pass ? 0.0f : static_cast<float>(o_.frame.log_of(o_.frame.initial_grey));
  s_.assign(static_cast<size_t>(width) * height, static_cast<float>(o_.initial_log_intensity));
}

void ComplementaryFilter::fold_frame(int64_t t_ns) {
  const double dw = clock_.fold(t_ns);
  if (dw == 0.0) return;
  if (frame_.empty()) {
    if (reference_ == 0.0f) return;
    const float add = static_cast<float>(reference_ * dw);
    for (float& s : s_) s += add;
    return;
  }
  std::array<float, 256> lutw;
  for (int v = 0; v < 256; ++v) lutw[v] = static_cast<float>(lut_[v] * dw);
  const uint8_t* f = frame_.data();
  float* s = s_.data();
  const size_t n = s_.size();
  for (size_t i = 0; i < n; ++i) s[i] += lutw[f[i]];
}

void ComplementaryFilter::rebase(int64_t t_ns) {
  // The state at t_ns in plain log intensity (scaled_decay.h); values below 1e-30 become 0 (no
  // denormals in later sums).
  const ScaledDecayClock::Rebase r = clock_.rebase(t_ns);
  const size_t n = s_.size();
  if (frame_.empty()) {
    const double add = reference_ * r.gain;
    for (size_t i = 0; i < n; ++i) s_[i] = static_cast<float>(s_[i] * r.scale + add);
  } else {
    for (size_t i = 0; i < n; ++i) s_[i] = static_cast<float>(s_[i] * r.scale + lut_[frame_[i]] * r.gain);
  }
  for (float& s : s_)
    if (std::fabs(s) < 1e-30f) s = 0.0f;
  ++stats_.rebases;
}

void ComplementaryFilter::process(const Event* events, size_t n) {
  float* s = s_.data();
  const uint32_t w = static_cast<uint32_t>(width_), h = static_cast<uint32_t>(height_);
  int64_t outside = 0;
  for (size_t i = 0; i < n; ++i) {
    const Event& e = events[i];
    float scale;
    if (!clock_.event_weight(e.t_ns, &scale)) {
      rebase(e.t_ns);
      scale = exp_to_float(clock_.exponent(e.t_ns));  // the event is at or before the new t_ref
    }
    if (e.x >= w || e.y >= h) {
      ++outside;
      continue;
    }
    s[e.y * w + e.x] += (e.polarity > 0 ? c_on_ : c_off_) * scale;
  }
  stats_.events += static_cast<int64_t>(n) - outside;
  stats_.events_outside += outside;
}

void ComplementaryFilter::add_frame(int64_t t_ns, const GreyView& frame) {
  if (!o_.use_frames) return;
  check_frame(frame, width_, height_);
  if (clock_.needs_rebase(t_ns)) rebase(t_ns);
  fold_frame(t_ns);  // the previous L_F up to t_ns (a frame before the last one is fused at its time)
  copy_frame(frame, &frame_);
  if (stats_.frames == 0 && o_.init_from_first_frame) {
    const float w = exp_to_float(clock_.exponent(clock_.t_fold_ns()));
    for (size_t i = 0; i < s_.size(); ++i) s_[i] = lut_[frame_[i]] * w;
  }
  ++stats_.frames;
}

void ComplementaryFilter::log_intensity(int64_t t_ns, ImageF* out) const {
  out->resize(height_, width_);
  // L = S / w(t) + L_F (1 - w(t_fold) / w(t)), in double.
  const ScaledDecayClock::Readout r = clock_.readout(t_ns);
  float* o = out->data();
  const size_t n = s_.size();
  if (frame_.empty()) {
    const double add = reference_ * r.gain;
    for (size_t i = 0; i < n; ++i) o[i] = static_cast<float>(s_[i] * r.inv + add);
  } else {
    for (size_t i = 0; i < n; ++i) o[i] = static_cast<float>(s_[i] * r.inv + lut_[frame_[i]] * r.gain);
  }
}

// ---------------------------------------------------------------------------------------------
// Asynchronous Kalman filter

bool AsyncKalmanFilterOptions::Validate(std::string* why) const {
  if (!contrasts_valid(contrast_on, contrast_off, why)) return false;
  auto nonneg = [](double v) { return std::isfinite(v) && v >= 0 && v <= 1e6; };
  if (!(std::isfinite(initial_variance) && initial_variance > 0 && initial_variance <= 1e6))
    return validation_failed(why, "initial_variance must be in (0, 1e6]");
  if (!nonneg(event_noise)) return validation_failed(why, "event_noise must be in [0, 1e6]");
  if (!nonneg(process_noise)) return validation_failed(why, "process_noise must be in [0, 1e6]");
  if (!nonneg(isolated_noise)) return validation_failed(why, "isolated_noise must be in [0, 1e6]");
  if (!nonneg(refractory_noise)) return validation_failed(why, "refractory_noise must be in [0, 1e6]");
  if (refractory_period_ns < 0) return validation_failed(why, "refractory_period must be >= 0");
  if (!(std::isfinite(frame_noise_std) && frame_noise_std > 0 && frame_noise_std <= 255))
    return validation_failed(why, "frame_noise_std must be in (0, 255]");
  if (!(exposure_low >= 0 && exposure_low <= exposure_high && exposure_high <= 255))
    return validation_failed(why, "need 0 <= exposure_low <= exposure_high <= 255");
  if (!(min_exposure_weight > 0 && min_exposure_weight <= 1)) return validation_failed(why, "min_exposure_weight must be in (0, 1]");
  if (!std::isfinite(initial_log_intensity) || std::fabs(initial_log_intensity) > 1e6)
    return validation_failed(why, "initial_log_intensity must be finite, |value| <= 1e6");
  return frame.Validate(why);
}

AsyncKalmanFilter::AsyncKalmanFilter(int width, int height, int64_t t_start_ns, const AsyncKalmanFilterOptions& options)
    : width_(width), height_(height), o_(options) {
  check_size(width, height);
  std::string why;
  if (!o_.Validate(&why)) throw std::invalid_argument("AsyncKalmanFilterOptions: " + why);
  const size_t n = static_cast<size_t>(width) * height;
  l_.assign(n, static_cast<float>(o_.initial_log_intensity));
  p_.assign(n, static_cast<float>(o_.initial_variance));
  t_update_.assign(n, t_start_ns);
  t_event_.assign(n, t_start_ns);
  const double sv = o_.frame_noise_std / 255.0;
  for (int v = 0; v < 256; ++v) {
    lut_log_[v] = static_cast<float>(o_.frame.log_of(v));
    double w = 1.0;
    if (v < o_.exposure_low) {
      w = o_.min_exposure_weight + (1.0 - o_.min_exposure_weight) * v / o_.exposure_low;
    } else if (v > o_.exposure_high) {
      w = o_.min_exposure_weight + (1.0 - o_.min_exposure_weight) * (255.0 - v) / (255.0 - o_.exposure_high);
    }
    // dL/dv = gamma / (v + 255 offset): the grey-level noise in log units, divided by w
    const double u = v / 255.0 + o_.frame.offset;
    lut_var_[v] = static_cast<float>(sv * sv * o_.frame.gamma * o_.frame.gamma / (u * u * w));
  }
}

void AsyncKalmanFilter::process(const Event* events, size_t n) {
  const uint32_t w = static_cast<uint32_t>(width_), h = static_cast<uint32_t>(height_);
  const float c_on = static_cast<float>(o_.contrast_on), c_off = static_cast<float>(-o_.contrast_off);
  const double proc_per_ns = o_.process_noise * 1e-9, iso_per_ns = o_.isolated_noise * 1e-9;
  int64_t outside = 0;
  for (size_t i = 0; i < n; ++i) {
    const Event& e = events[i];
    if (e.x >= w || e.y >= h) {
      ++outside;
      continue;
    }
    const size_t k = static_cast<size_t>(e.y) * w + e.x;
    const int64_t t = e.t_ns;
    l_[k] += e.polarity > 0 ? c_on : c_off;
    // Event noise: the step's own error, process (time since the pixel's last update), isolated
    // pixel (time since the latest event among the 8 neighbours), refractory (time since the
    // pixel's previous event).
    const int64_t since_own = t - t_event_[k];
    int64_t latest = std::numeric_limits<int64_t>::min();
    const uint32_t ex = e.x, ey = e.y;
    const uint32_t x0 = ex > 0 ? ex - 1 : 0, x1 = ex + 1 < w ? ex + 1 : ex;
    const uint32_t y0 = ey > 0 ? ey - 1 : 0, y1 = ey + 1 < h ? ey + 1 : ey;
    for (uint32_t y = y0; y <= y1; ++y) {
      const int64_t* row = t_event_.data() + static_cast<size_t>(y) * w;
      for (uint32_t x = x0; x <= x1; ++x)
        if ((x != ex || y != ey) && row[x] > latest) latest = row[x];
    }
    double q = o_.event_noise + proc_per_ns * static_cast<double>(std::max<int64_t>(0, t - t_update_[k]));
    if (latest != std::numeric_limits<int64_t>::min()) q += iso_per_ns * static_cast<double>(std::max<int64_t>(0, t - latest));
    if (since_own <= o_.refractory_period_ns) q += o_.refractory_noise;
    p_[k] = static_cast<float>(p_[k] + q);
    t_update_[k] = std::max(t_update_[k], t);
    t_event_[k] = t;
  }
  stats_.events += static_cast<int64_t>(n) - outside;
  stats_.events_outside += outside;
}

void AsyncKalmanFilter::add_frame(int64_t t_ns, const GreyView& frame) {
  if (!o_.use_frames) return;
  check_frame(frame, width_, height_);
  const bool first = stats_.frames == 0;
  const double proc_per_ns = o_.process_noise * 1e-9;
  for (int y = 0; y < height_; ++y) {
    const uint8_t* row = frame.data + y * frame.stride;
    for (int x = 0; x < width_; ++x) {
      const size_t i = static_cast<size_t>(y) * width_ + x;
      const uint8_t v = row[x];
      const float r = lut_var_[v];
      if (first) {
        l_[i] = lut_log_[v];
        p_[i] = r;
      } else {
        // The measurement update: K = P / (P + R), L += K (L_F - L), P = (1 - K) P
        const float p =
            static_cast<float>(p_[i] + proc_per_ns * static_cast<double>(std::max<int64_t>(0, t_ns - t_update_[i])));
        const float k = p / (p + r);
        l_[i] += k * (lut_log_[v] - l_[i]);
        p_[i] = p - k * p;
      }
      t_update_[i] = std::max(t_update_[i], t_ns);
    }
  }
  ++stats_.frames;
}

void AsyncKalmanFilter::log_intensity(int64_t /*t_ns*/, ImageF* out) const {
  out->resize(height_, width_);
  std::copy(l_.begin(), l_.end(), out->data());
}

void AsyncKalmanFilter::variance(int64_t t_ns, ImageF* out) const {
  out->resize(height_, width_);
  float* o = out->data();
  const double proc_per_ns = o_.process_noise * 1e-9;
  for (size_t i = 0; i < p_.size(); ++i)
    o[i] = static_cast<float>(p_[i] + proc_per_ns * static_cast<double>(std::max<int64_t>(0, t_ns - t_update_[i])));
}

}  // namespace evio::mapping
