#include "evio/evaluation/track_oracle.h"

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>
#include <vector>

namespace evio::evaluation {

bool TrackOracleOptions::Validate(std::string* why) const {
  auto fail = [why](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!(white_noise_px >= 0) || !std::isfinite(white_noise_px)) return fail("white_noise_px must be finite and >= 0");
  if (!(max_error_px >= 0) || !std::isfinite(max_error_px)) return fail("max_error_px must be finite and >= 0");
  if (!(drift_px_per_frame >= 0) || !std::isfinite(drift_px_per_frame))
    return fail("drift_px_per_frame must be finite and >= 0");
  return true;
}

double TrackOracleStats::AgeBucket::independent_quantile_px(double q) const {
  if (count == 0) return 0.0;
  const double target = std::clamp(q, 0.0, 1.0) * static_cast<double>(count);
  int64_t below = 0;
  for (int k = 0; k < kBins; ++k) {
    below += independent_hist[static_cast<size_t>(k)];
    if (static_cast<double>(below) >= target) return (k + 1) * kBinPx;
  }
  return kBins * kBinPx;
}

TrackOracle::TrackOracle(const Trajectory& groundtruth, const calib::CameraCalibration& camera, RayCaster cast,
                         const TrackOracleOptions& options)
    : gt_(groundtruth), camera_(camera), cast_(std::move(cast)), options_(options), rng_(options.seed) {
  std::string why;
  if (!options_.Validate(&why)) throw std::invalid_argument("TrackOracle: " + why);
  if (!cast_) throw std::invalid_argument("TrackOracle: needs a ray caster of the true scene");
}

void TrackOracle::apply(FeatureObservations* frame) {
  const auto& K = camera_.camera.intrinsics();
  const auto T_w_b = gt_.interpolate(frame->t_ns);
  if (!T_w_b) {
    stats_.dropped += static_cast<int64_t>(frame->observations.size());
    frame->observations.clear();
    return;
  }
  const calib::SE3 T_w_c = *T_w_b * camera_.T_c_b.inverse();
  const calib::SE3 T_c_w = T_w_c.inverse();
  std::normal_distribution<double> white(0.0, options_.white_noise_px), step(0.0, options_.drift_px_per_frame);
  std::vector<FeatureObservation> kept;
  kept.reserve(frame->observations.size());
  std::vector<Eigen::Vector2d> real_error;  // per kept observation (px), for keep_error
  std::vector<int64_t> age;                 // per kept observation
  std::vector<OracleObservation> measured;  // per kept observation, for the sink
  const auto T_before = gt_.interpolate(frame->t_ns - 2'000'000), T_after = gt_.interpolate(frame->t_ns + 2'000'000);
  for (FeatureObservation o : frame->observations) {
    auto it = landmarks_.find(o.track_id);
    if (it == landmarks_.end()) {
      Landmark l;
      const Eigen::Vector3d d_w = T_w_c.rotation * o.bearing_c.normalized();
      if (const auto s = cast_(T_w_c.translation, d_w)) {
        l.valid = true;
        l.X_w = T_w_c.translation + *s * d_w;
      }
      it = landmarks_.emplace(o.track_id, l).first;
    } else {
      ++it->second.age;
      if (options_.drift_px_per_frame > 0) it->second.drift_px += Eigen::Vector2d(step(rng_), step(rng_));
    }
    const Landmark& l = it->second;
    const Eigen::Vector3d p_c = T_c_w * l.X_w;
    if (!l.valid || !(p_c.z() > 1e-9)) {
      ++stats_.dropped;
      continue;
    }
    Eigen::Vector2d e = l.drift_px;
    if (options_.white_noise_px > 0) e += Eigen::Vector2d(white(rng_), white(rng_));
    if (options_.keep_error != OracleError::kNone) {
      const Eigen::Vector3d b = o.bearing_c;
      real_error.push_back(b.z() > 1e-9 ? Eigen::Vector2d(K.fx * (b.x() / b.z() - p_c.x() / p_c.z()),
                                                          K.fy * (b.y() / b.z() - p_c.y() / p_c.z()))
                                        : Eigen::Vector2d::Zero());
      age.push_back(l.age);
      if (sink_) {
        OracleObservation m;
        m.t_ns = frame->t_ns;
        m.track_id = o.track_id;
        m.age = l.age;
        m.error_px = real_error.back();
        m.true_px = Eigen::Vector2d(K.fx * p_c.x() / p_c.z() + K.cx, K.fy * p_c.y() / p_c.z() + K.cy);
        if (T_before && T_after) {
          const Eigen::Vector3d a = (*T_before * camera_.T_c_b.inverse()).inverse() * l.X_w;
          const Eigen::Vector3d b = (*T_after * camera_.T_c_b.inverse()).inverse() * l.X_w;
          if (a.z() > 1e-9 && b.z() > 1e-9)
            m.true_flow_px_s = Eigen::Vector2d(K.fx * (b.x() / b.z() - a.x() / a.z()), K.fy * (b.y() / b.z() - a.y() / a.z())) / 4e-3;
        }
        m.depth_m = p_c.z();
        m.q_c_w = T_c_w.rotation;
        measured.push_back(m);
      }
    }
    const double x = p_c.x() / p_c.z() + e.x() / K.fx, y = p_c.y() / p_c.z() + e.y() / K.fy;
    o.bearing_c = Eigen::Vector3d(x, y, 1.0).normalized();
    kept.push_back(o);
    ++stats_.replaced;
  }
  if (options_.keep_error != OracleError::kNone && !kept.empty()) {
    // The frame's common mode: per-axis median of the errors within 10 px (gross ones excluded).
    Eigen::Vector2d c = Eigen::Vector2d::Zero();
    for (int axis = 0; axis < 2; ++axis) {
      std::vector<double> v;
      for (const Eigen::Vector2d& e : real_error)
        if (e.norm() < 10.0) v.push_back(e[axis]);
      if (v.empty()) continue;
      std::nth_element(v.begin(), v.begin() + static_cast<long>(v.size() / 2), v.end());
      c[axis] = v[v.size() / 2];
    }
    common_mode_sq_sum_ += c.squaredNorm();
    ++stats_.frames;
    stats_.common_mode_rms_px = std::sqrt(common_mode_sq_sum_ / static_cast<double>(stats_.frames));
    if (sink_)
      for (OracleObservation& m : measured) {
        m.common_mode_px = c;
        sink_(m);
      }
    for (size_t i = 0; i < kept.size(); ++i) {
      if (age[i] < 1) continue;
      int k = TrackOracleStats::kAgeBuckets - 1;
      while (k > 0 && age[i] < TrackOracleStats::kAgeBucketStart[k]) --k;
      TrackOracleStats::AgeBucket& b = stats_.by_age[k];
      ++b.count;
      b.sq_sum += real_error[i].squaredNorm();
      b.independent_sq_sum += (real_error[i] - c).squaredNorm();
      const double bin = (real_error[i] - c).norm() / TrackOracleStats::kBinPx;
      ++b.independent_hist[static_cast<size_t>(std::min(bin, TrackOracleStats::kBins - 1.0))];
      b.error_rms_px = std::sqrt(b.sq_sum / static_cast<double>(b.count));
      b.independent_rms_px = std::sqrt(b.independent_sq_sum / static_cast<double>(b.count));
    }
    std::vector<FeatureObservation> gross_free;
    gross_free.reserve(kept.size());
    for (size_t i = 0; i < kept.size(); ++i) {
      if (options_.max_error_px > 0 && options_.keep_error != OracleError::kCommonMode &&
          real_error[i].norm() > options_.max_error_px) {
        ++stats_.dropped_gross;
        continue;
      }
      const Eigen::Vector2d add = options_.keep_error == OracleError::kReal          ? real_error[i]
                                  : options_.keep_error == OracleError::kIndependent ? Eigen::Vector2d(real_error[i] - c)
                                                                                      : c;
      const Eigen::Vector3d& b = kept[i].bearing_c;  // oracle bearing (z > 0)
      kept[i].bearing_c =
          Eigen::Vector3d(b.x() / b.z() + add.x() / K.fx, b.y() / b.z() + add.y() / K.fy, 1.0).normalized();
      gross_free.push_back(kept[i]);
    }
    kept = std::move(gross_free);
  }
  frame->observations = std::move(kept);
}

std::optional<VioState> groundtruth_state(const Trajectory& groundtruth, int64_t t_ns) {
  constexpr int64_t kHalfStepNs = 5'000'000;
  const auto a = groundtruth.interpolate(t_ns - kHalfStepNs), b = groundtruth.interpolate(t_ns + kHalfStepNs),
             c = groundtruth.interpolate(t_ns);
  if (!a || !b || !c) return std::nullopt;
  VioState s;
  s.t_ns = t_ns;
  s.T_w_b = *c;
  s.v_w = (b->translation - a->translation) / (2e-9 * static_cast<double>(kHalfStepNs));
  return s;
}

bool true_frame_motion(const Trajectory& groundtruth, const calib::SE3& T_c_b, const RayCaster& cast,
                       const FeatureObservations& frame, Eigen::Vector3d* v_c, double* depth_m,
                       Eigen::Vector4d* plane_c) {
  const std::optional<VioState> st = groundtruth_state(groundtruth, frame.t_ns);
  if (!st || !cast) return false;
  const calib::SE3 T_w_c = st->T_w_b * T_c_b.inverse();
  std::vector<double> z;
  std::vector<Eigen::Vector3d> points_c;
  z.reserve(frame.observations.size());
  for (const FeatureObservation& o : frame.observations) {
    const Eigen::Vector3d d = o.bearing_c.normalized();
    if (const auto s = cast(T_w_c.translation, T_w_c.rotation * d)) {
      z.push_back(*s * d.z());
      points_c.push_back(*s * d);
    }
  }
  if (z.empty()) return false;
  if (plane_c) {
    plane_c->setZero();
    if (points_c.size() >= 3) {
      Eigen::Vector3d mean = Eigen::Vector3d::Zero();
      for (const auto& p : points_c) mean += p;
      mean /= static_cast<double>(points_c.size());
      Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
      for (const auto& p : points_c) C += (p - mean) * (p - mean).transpose();
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(C);
      Eigen::Vector3d n = es.eigenvectors().col(0);  // smallest eigenvalue
      if (es.eigenvalues()(1) > 1e-12) {
        double dist = n.dot(mean);
        if (dist < 0) {
          n = -n;
          dist = -dist;
        }
        if (dist > 0) *plane_c << n, dist;
      }
    }
  }
  std::nth_element(z.begin(), z.begin() + static_cast<long>(z.size() / 2), z.end());
  // The camera centre's velocity (central difference over 10 ms, as groundtruth_state), so a
  // camera-IMU lever arm is included.
  constexpr int64_t kHalfStepNs = 5'000'000;
  const auto a = groundtruth.interpolate(frame.t_ns - kHalfStepNs), b = groundtruth.interpolate(frame.t_ns + kHalfStepNs);
  const Eigen::Vector3d p_b_c = T_c_b.inverse().translation;
  const Eigen::Vector3d v_w_c = ((*b * p_b_c) - (*a * p_b_c)) / (2e-9 * static_cast<double>(kHalfStepNs));
  *v_c = T_w_c.rotation.conjugate() * v_w_c;
  *depth_m = z[z.size() / 2];
  return *depth_m > 0 && v_c->allFinite();
}

const char* to_string(OracleError e) {
  switch (e) {
    case OracleError::kReal: return "real";
    case OracleError::kIndependent: return "independent";
    case OracleError::kCommonMode: return "common_mode";
    case OracleError::kNone: break;
  }
  return "none";
}

}  // namespace evio::evaluation
