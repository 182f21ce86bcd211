// Motion-compensated event frames: see event_frame.h.
#include "evio/frontend/event_frame.h"
#include "evio/frontend/option_tables.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "evio/calib/geometry.h"

namespace evio::frontend {
namespace {

// The q-th smallest (0-based) of v[0, m), all positive finite floats, by radix selection on their
// bit patterns (ordered like the values for positive floats): three counting passes over 11, 11
// and 10 bits, each keeping only the bucket that holds rank q. The same value as std::nth_element,
// in linear time. Reorders v.
float select_positive(std::vector<float>* v, size_t m, size_t q) {
  static_assert(sizeof(float) == sizeof(uint32_t), "32-bit floats");
  float* a = v->data();
  constexpr int kShift[3] = {21, 10, 0};
  constexpr uint32_t kMask[3] = {0x7ff, 0x7ff, 0x3ff};
  uint32_t count[2048];
  size_t n = m;
  for (int pass = 0; pass < 3; ++pass) {
    std::fill(count, count + kMask[pass] + 1, 0u);
    for (size_t i = 0; i < n; ++i) {
      uint32_t b;
      std::memcpy(&b, &a[i], sizeof(b));
      ++count[(b >> kShift[pass]) & kMask[pass]];
    }
    uint32_t bucket = 0;
    while (q >= count[bucket]) q -= count[bucket++];
    size_t kept = 0;
    for (size_t i = 0; i < n; ++i) {
      uint32_t b;
      std::memcpy(&b, &a[i], sizeof(b));
      if (((b >> kShift[pass]) & kMask[pass]) == bucket) a[kept++] = a[i];
    }
    n = kept;
  }
  return a[0];  // every value left has the same bits
}

}  // namespace

bool EventFrameOptions::Validate(std::string* why) const {
  if (!event_frame_table().check(*this, why)) return false;
  if (min_window_ns > max_window_ns) return validation_failed(why, "min_window_ms must be <= max_window_ms");
  if (sparse_max_window_ns != 0 && sparse_max_window_ns < max_window_ns)
    return validation_failed(why, "sparse_max_window_ms must be 0 (off) or >= max_window_ms");
  if (min_events > events_per_frame) return validation_failed(why, "min_events must be <= events_per_frame");
  if (use_depth && !motion_compensation) return validation_failed(why, "use_depth needs motion_compensation");
  if (time_surface_tau_fraction > 0.0 && use_polarity)
    return validation_failed(why, "time_surface_tau_fraction > 0 does not go with use_polarity");
  return true;
}

EventFrameBuilder::EventFrameBuilder(const calib::CameraCalibration& camera, const EventFrameOptions& options)
    : o_(options) {
  std::string why;
  if (!o_.Validate(&why)) throw std::invalid_argument("EventFrameOptions: " + why);
  const calib::PinholeCamera& cam = camera.camera;
  const calib::CameraIntrinsics& in = cam.intrinsics();
  std::string cam_why;
  if (!in.Validate(&cam_why)) throw std::invalid_argument("EventFrameBuilder: camera: " + cam_why);
  width_ = in.width;
  height_ = in.height;
  fx_ = static_cast<float>(in.fx);
  fy_ = static_cast<float>(in.fy);
  cx_ = static_cast<float>(in.cx);
  cy_ = static_cast<float>(in.cy);
  const calib::UndistortionLut lut(cam);
  bearings_.resize(static_cast<size_t>(width_) * height_);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (int y = 0; y < height_; ++y)
    for (int x = 0; x < width_; ++x) {
      Eigen::Vector3f b = lut.bearing(x, y);
      // Rays not in front of the camera cannot be drawn in a pinhole image.
      if (!lut.valid(x, y) || !(b.z() > 1e-6f)) b = Eigen::Vector3f(nan, nan, nan);
      bearings_[static_cast<size_t>(y) * width_ + x] = b;
    }
  // Without extrinsics the camera is taken as the body frame (R_c_b = I).
  if (camera.has_T_c_b) R_c_b_ = camera.T_c_b.rotation_matrix();
  time_shift_ns_ = camera.time_shift_ns;
  pending_.reserve(static_cast<size_t>(o_.events_per_frame));
}

Eigen::Matrix3d EventFrameBuilder::K() const {
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
  K(0, 0) = fx_;
  K(1, 1) = fy_;
  K(0, 2) = cx_;
  K(1, 2) = cy_;
  return K;
}

void EventFrameBuilder::add_imu(const ImuSample& s) {
  if (!imu_.empty() && s.t_ns <= imu_.back().t_ns) {
    ++stats_.imu_rejected;
    return;
  }
  imu_.push_back(s);
  // Keep the samples the pending (or next) frame can need: from the last sample at or before its
  // first event (or the last event seen) on.
  if (!pending_.empty()) prune_imu(pending_.front().t_ns + time_shift_ns_);
  else if (have_last_event_) prune_imu(last_event_t_ns_ + time_shift_ns_);
}

void EventFrameBuilder::prune_imu(int64_t t_keep_imu) {
  // Keep one sample at or before t_keep (the bracket), and a margin for extrapolation.
  const int64_t t = t_keep_imu - o_.max_imu_extrapolation_ns;
  while (imu_.size() >= 2 && imu_[1].t_ns <= t) imu_.pop_front();
}

void EventFrameBuilder::set_gyro_bias(const Eigen::Vector3d& b_g) { bias_gyro_ = b_g; }

void EventFrameBuilder::set_motion(const Eigen::Vector3d& v_c, double median_depth_m) {
  if (!(median_depth_m > 0) || !std::isfinite(median_depth_m) || !v_c.allFinite())
    throw std::invalid_argument("EventFrameBuilder::set_motion: need finite v_c and median_depth_m > 0 m");
  v_c_ = v_c;
  depth_m_ = median_depth_m;
  plane_d_ = 0;
}

void EventFrameBuilder::set_motion_plane(const Eigen::Vector3d& v_c, const Eigen::Vector3d& n_c, double d_m) {
  if (!(d_m > 0) || !std::isfinite(d_m) || !v_c.allFinite() || !n_c.allFinite() || std::abs(n_c.norm() - 1) > 1e-6)
    throw std::invalid_argument("EventFrameBuilder::set_motion_plane: need finite v_c, unit n_c and d_m > 0 m");
  v_c_ = v_c;
  plane_n_ = n_c;
  plane_d_ = d_m;
  depth_m_ = d_m;
}

Eigen::Vector3d EventFrameBuilder::gyro_at(int64_t t_imu) const {
  // imu_ is non-empty here (coverage was checked).
  if (t_imu <= imu_.front().t_ns) return imu_.front().gyro - bias_gyro_;
  if (t_imu >= imu_.back().t_ns) return imu_.back().gyro - bias_gyro_;
  const auto it = std::upper_bound(imu_.begin(), imu_.end(), t_imu,
                                   [](int64_t t, const ImuSample& s) { return t < s.t_ns; });
  const ImuSample& b = *it;
  const ImuSample& a = *(it - 1);
  const double s = static_cast<double>(t_imu - a.t_ns) / static_cast<double>(b.t_ns - a.t_ns);
  return a.gyro + s * (b.gyro - a.gyro) - bias_gyro_;
}

bool EventFrameBuilder::compute_knots(int64_t t_begin_cam, int64_t t_end_cam, int64_t t_ref_cam) {
  const int64_t t_lo = std::min(t_begin_cam, t_ref_cam), t_hi = std::max(t_end_cam, t_ref_cam);
  const int64_t a = t_lo + time_shift_ns_, b = t_hi + time_shift_ns_;  // IMU clock
  if (imu_.empty()) return false;
  if (imu_.front().t_ns > a + o_.max_imu_extrapolation_ns) return false;
  if (imu_.back().t_ns < b - o_.max_imu_extrapolation_ns) return false;
  // Gaps: consecutive samples from the last one at or before a to the first one at or after b.
  auto first = std::upper_bound(imu_.begin(), imu_.end(), a, [](int64_t t, const ImuSample& s) { return t < s.t_ns; });
  if (first != imu_.begin()) --first;
  for (auto it = first; it + 1 != imu_.end(); ++it) {
    if ((it + 1)->t_ns - it->t_ns > o_.max_imu_gap_ns) return false;
    if (it->t_ns >= b) break;
  }

  const int64_t h = o_.knot_spacing_ns;
  const int64_t span = t_hi - t_lo;
  const int64_t n_steps = std::max<int64_t>(1, (span + h - 1) / h);
  t_knot0_ = t_lo;
  // Body rotations R_b(t_lo)^T R_b(t_i), integrated with the midpoint rate of each step.
  std::vector<Eigen::Matrix3d> R(static_cast<size_t>(n_steps) + 1);
  R[0].setIdentity();
  const double h_s = static_cast<double>(h) * 1e-9;
  for (int64_t i = 0; i < n_steps; ++i) {
    const Eigen::Vector3d w = gyro_at(a + i * h + h / 2);
    R[i + 1] = R[i] * calib::so3_exp(w * h_s);
  }
  // Rotation at the reference time within its step.
  const int64_t dref = t_ref_cam - t_lo;
  const int64_t iref = std::min<int64_t>(dref / h, n_steps - 1);
  const int64_t rem = dref - iref * h;
  const Eigen::Vector3d w_ref = gyro_at(a + iref * h + h / 2);
  const Eigen::Matrix3d R_ref = R[iref] * calib::so3_exp(w_ref * (static_cast<double>(rem) * 1e-9));
  // Camera-frame knots R_c(ref)_c(t_i) = R_c_b R_b(ref)^T R_b(t_i) R_b_c.
  const Eigen::Matrix3d A = R_c_b_ * R_ref.transpose();
  const Eigen::Matrix3d R_b_c = R_c_b_.transpose();
  knots_.resize(R.size());
  for (size_t i = 0; i < R.size(); ++i) knots_[i] = (A * R[i] * R_b_c).cast<float>();
  return true;
}

EventFrame EventFrameBuilder::build_frame(EventSpan events, int64_t t_ref_ns) {
  EventFrame f;
  f.t_ns = t_ref_ns;
  f.events = events.size();
  if (!events.empty()) {
    f.t_begin_ns = events.front().t_ns;
    f.t_end_ns = events.back().t_ns;
  } else {
    f.t_begin_ns = f.t_end_ns = t_ref_ns;
  }
  cv::Mat acc(height_, width_, CV_32F, cv::Scalar(0));
  bool compensate = false;
  if (o_.motion_compensation && !events.empty()) {
    compensate = compute_knots(f.t_begin_ns, f.t_end_ns, t_ref_ns);
    if (!compensate) ++stats_.frames_uncompensated;
  }
  f.motion_compensated = compensate;
  if (compensate && o_.use_depth && provider_) {
    FrameMotion m;
    if (provider_(t_ref_ns, &m)) {
      if (m.plane_d_m > 0) {
        set_motion_plane(m.v_c, m.plane_n_c, m.plane_d_m);
      } else {
        set_motion(m.v_c, m.depth_m);
      }
    }
  }
  const bool translate = compensate && o_.use_depth && depth_m_ > 0;
  const bool plane = translate && plane_d_ > 0;
  const Eigen::Vector3f v_over_d = (v_c_ / (translate ? (plane ? plane_d_ : depth_m_) : 1.0)).cast<float>();
  const float pnx = static_cast<float>(plane_n_.x()), pny = static_cast<float>(plane_n_.y()), pnz = static_cast<float>(plane_n_.z());
  const int64_t h = o_.knot_spacing_ns;
  const float inv_h = 1.0f / static_cast<float>(h);
  const int64_t last_step = static_cast<int64_t>(knots_.size()) - 2;
  const float w_max = static_cast<float>(width_ - 1), h_max = static_cast<float>(height_ - 1);
  float* a = acc.ptr<float>();
  size_t outside = 0;
  // Knot step of the current event, min(d / h, last_step) for d = t - t_knot0_: advanced as the
  // (time-ordered) events pass the knots, which avoids a 64-bit division per event.
  int64_t i = 0, i_t = 0;  // step, and its start i * h
  const float vx = v_over_d.x(), vy = v_over_d.y(), vz = v_over_d.z();
  // Event lag: the image motion at the reference time, -w x q - (v / Z) + x (v / Z)_z per
  // normalised point q = (x, y, 1), w the camera's angular velocity there.
  const bool lag = compensate && o_.event_lag_px > 0;
  Eigen::Vector3f w_c = Eigen::Vector3f::Zero();
  if (lag) w_c = (R_c_b_ * gyro_at(t_ref_ns + time_shift_ns_)).cast<float>();
  const float lag_px = static_cast<float>(o_.event_lag_px);
  // Time surface: exp((t_e - t_end) / tau), tau a fraction of the span (at least 1 us).
  const bool surface = o_.time_surface_tau_fraction > 0.0;
  const double inv_tau_per_ns = surface ? 1.0 / std::max(1e-6, o_.time_surface_tau_fraction * 1e-9 * static_cast<double>(f.t_end_ns - f.t_begin_ns)) * 1e-9 : 0.0;
  const Event* ev = events.data();
  const size_t n_events = events.size();
  constexpr size_t kAhead = 16;  // events: the bearing table is read at random pixels, fetched ahead
  for (size_t j = 0; j < n_events; ++j) {
    const Event& e = ev[j];
    if (j + kAhead < n_events) {
      const Event& f = ev[j + kAhead];
      __builtin_prefetch(&bearings_[static_cast<size_t>(f.y) * width_ + f.x]);
    }
    const Eigen::Vector3f& b = bearings_[static_cast<size_t>(e.y) * width_ + e.x];
    float px, py, pz;
    if (compensate) {
      const int64_t d = e.t_ns - t_knot0_;
      if (d < i_t) {  // out of order: start over
        i = std::min(d / h, last_step);
        i_t = i * h;
      }
      while (i < last_step && d - i_t >= h) {
        ++i;
        i_t += h;
      }
      const float s = static_cast<float>(d - i_t) * inv_h;
      // p = M0 b + s (M1 b - M0 b), in scalars (Eigen's temporaries went through the stack), summed
      // in Eigen's order, a0 + (a1 + a2), so the frames stay bit-identical.
      const float* M0 = knots_[static_cast<size_t>(i)].data();  // column-major
      const float* M1 = knots_[static_cast<size_t>(i) + 1].data();
      const float bx = b.x(), by = b.y(), bz = b.z();
      const float p0x = M0[0] * bx + (M0[3] * by + M0[6] * bz);
      const float p0y = M0[1] * bx + (M0[4] * by + M0[7] * bz);
      const float p0z = M0[2] * bx + (M0[5] * by + M0[8] * bz);
      const float p1x = M1[0] * bx + (M1[3] * by + M1[6] * bz);
      const float p1y = M1[1] * bx + (M1[4] * by + M1[7] * bz);
      const float p1z = M1[2] * bx + (M1[5] * by + M1[8] * bz);
      px = p0x + s * (p1x - p0x);
      py = p0y + s * (p1y - p0y);
      pz = p0z + s * (p1z - p0z);
      if (translate) {
        // Point at z-depth D along b, moved by the camera displacement: P_ref = (D / b_z) R b +
        // v (t_k - t_ref); scaled by b_z / D (projection is scale-free).
        const float dt_s = static_cast<float>(static_cast<double>(e.t_ns - t_ref_ns) * 1e-9);
        const float k = dt_s * (plane ? pnx * bx + (pny * by + pnz * bz) : bz);
        px += vx * k;
        py += vy * k;
        pz += vz * k;
      }
    } else {
      px = b.x();
      py = b.y();
      pz = b.z();
    }
    if (!(pz > 1e-6f)) {  // also catches NaN bearings
      ++outside;
      continue;
    }
    const float iz = 1.0f / pz;
    float u = fx_ * px * iz + cx_, v = fy_ * py * iz + cy_;
    if (lag) {
      const float x = px * iz, y = py * iz;
      // Rotation: q' = -w x q.
      float mx = -(w_c.y() - w_c.z() * y), my = -(w_c.z() * x - w_c.x()), mz = -(w_c.x() * y - w_c.y() * x);
      if (translate) {  // - v / Z, with 1 / Z = 1 / D or (n . q) / d
        const float inv_z = plane ? pnx * x + (pny * y + pnz) : 1.0f;
        mx -= vx * inv_z;
        my -= vy * inv_z;
        mz -= vz * inv_z;
      }
      const float dx = (mx - x * mz) * fx_, dy = (my - y * mz) * fy_;  // px/s
      const float n2 = dx * dx + dy * dy;
      if (n2 > 1e-12f) {
        const float k = lag_px / std::sqrt(n2);
        u += dx * k;
        v += dy * k;
      }
    }
    if (!(u >= 0.0f && v >= 0.0f && u <= w_max && v <= h_max)) {
      ++outside;
      continue;
    }
    const int x0 = static_cast<int>(u), y0 = static_cast<int>(v);
    const float fu = u - static_cast<float>(x0), fv = v - static_cast<float>(y0);
    const int x1 = std::min(x0 + 1, width_ - 1), y1 = std::min(y0 + 1, height_ - 1);
    float* r0 = a + static_cast<size_t>(y0) * width_;
    float* r1 = a + static_cast<size_t>(y1) * width_;
    if (surface) {
      const float d = std::exp(static_cast<float>(static_cast<double>(e.t_ns - f.t_end_ns) * inv_tau_per_ns));
      r0[x0] = std::max(r0[x0], d * (1.0f - fu) * (1.0f - fv));
      r0[x1] = std::max(r0[x1], d * fu * (1.0f - fv));
      r1[x0] = std::max(r1[x0], d * (1.0f - fu) * fv);
      r1[x1] = std::max(r1[x1], d * fu * fv);
      continue;
    }
    const float wgt = o_.use_polarity ? static_cast<float>(e.polarity) : 1.0f;
    r0[x0] += wgt * (1.0f - fu) * (1.0f - fv);
    r0[x1] += wgt * fu * (1.0f - fv);
    r1[x0] += wgt * (1.0f - fu) * fv;
    r1[x1] += wgt * fu * fv;
  }
  f.events_outside = outside;

  // Normalisation.
  f.image.create(height_, width_, CV_8UC1);
  const size_t n = static_cast<size_t>(width_) * height_;
  uint8_t* img = f.image.ptr<uint8_t>();
  if (o_.normalize) {
    float c = static_cast<float>(o_.clip_count);
    // Non-zero magnitudes, collected without branches, then the exact quantile by nth_element.
    size_t m = 0;
    if (!(o_.clip_count > 0)) {
      scratch_.resize(n);
      for (size_t k = 0; k < n; ++k) {
        scratch_[m] = std::abs(a[k]);
        m += a[k] != 0.0f;
      }
    }
    if (m > 0) {
      const size_t q = static_cast<size_t>(std::floor(o_.clip_percentile * static_cast<double>(m - 1)));
      c = select_positive(&scratch_, m, q);
    }
    if (!(c > 0.0f)) {
      f.image.setTo(o_.use_polarity ? 128 : 0);
    } else if (o_.use_polarity) {
      const float k = 127.5f / c;
      for (size_t i = 0; i < n; ++i)
        img[i] = static_cast<uint8_t>(128.0f + std::clamp(a[i] * k, -127.5f, 127.5f));  // round half up
    } else {
      const float k = 255.0f / c;
      for (size_t i = 0; i < n; ++i) img[i] = static_cast<uint8_t>(std::min(a[i] * k, 255.0f) + 0.5f);  // round
    }
  } else {
    const float off = o_.use_polarity ? 128.0f : 0.0f;
    for (size_t i = 0; i < n; ++i)
      img[i] = static_cast<uint8_t>(std::clamp(a[i] + off, 0.0f, 255.0f) + 0.5f);  // round half up
  }
  if (o_.keep_accumulator) f.accumulator = acc;
  return f;
}

void EventFrameBuilder::emit_pending(std::vector<EventFrame>* out) {
  if (pending_.size() <= fresh_) return;  // nothing new since the last frame
  const size_t added = pending_.size() - fresh_;
  size_t carry = 0;
  if (static_cast<int>(added) < o_.min_events) {
    ++stats_.frames_dropped_sparse;
    stats_.events_dropped_sparse += static_cast<int64_t>(added);
  } else {
    out->push_back(build_frame(EventSpan(pending_.data(), pending_.size()), pending_.back().t_ns));
    ++stats_.frames_emitted;
    last_emitted_end_ns_ = pending_.back().t_ns;
    carry = static_cast<size_t>(o_.overlap * static_cast<double>(pending_.size()));
  }
  // The latest `carry` events start the next frame (carry <= 0.9 of the frame: no overlap of the
  // copied ranges' start).
  std::copy(pending_.end() - static_cast<std::ptrdiff_t>(carry), pending_.end(), pending_.begin());
  pending_.resize(carry);
  fresh_ = carry;
  prune_imu((pending_.empty() ? last_event_t_ns_ : pending_.front().t_ns) + time_shift_ns_);
}

void EventFrameBuilder::add_events(EventSpan events, std::vector<EventFrame>* out) {
  const size_t n = static_cast<size_t>(o_.events_per_frame);
  for (const Event& e : events) {
    if (pending_.size() > fresh_) {
      const int64_t span = e.t_ns - pending_[fresh_].t_ns;
      const bool sparse = static_cast<int>(pending_.size() - fresh_) < o_.min_events;
      const bool starving = sparse_on_ && o_.sparse_max_window_ns > 0 &&
                            (last_emitted_end_ns_ == std::numeric_limits<int64_t>::min() ||
                             e.t_ns - last_emitted_end_ns_ >= o_.sparse_after_ns);
      if (span >= o_.max_window_ns && (!sparse || !starving || span >= o_.sparse_max_window_ns)) {
        emit_pending(out);
      }
    }
    if (fresh_ > 0 && pending_.size() == fresh_ && e.t_ns - pending_.back().t_ns >= o_.max_window_ns) {
      pending_.clear();  // carried events this old describe another scene state: start afresh
      fresh_ = 0;
    }
    if (e.x >= width_ || e.y >= height_) {  // outside the sensor: ignored
      ++stats_.events_outside_sensor;
      continue;
    }
    pending_.push_back(e);
    last_event_t_ns_ = e.t_ns;
    have_last_event_ = true;
    // N events, but not before min_window_ns (high event rates: fewer, fuller frames).
    if (pending_.size() >= n && e.t_ns - pending_.front().t_ns >= o_.min_window_ns) emit_pending(out);
  }
}

void EventFrameBuilder::flush(std::vector<EventFrame>* out) { emit_pending(out); }

}  // namespace evio::frontend
