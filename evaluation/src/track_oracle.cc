#include "evio/evaluation/track_oracle.h"

#include <cmath>
#include <stdexcept>
#include <utility>

namespace evio::evaluation {

bool TrackOracleOptions::Validate(std::string* why) const {
  auto fail = [why](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!(white_noise_px >= 0) || !std::isfinite(white_noise_px)) return fail("white_noise_px must be finite and >= 0");
  if (!(drift_px_per_frame >= 0) || !std::isfinite(drift_px_per_frame))
    return fail("drift_px_per_frame must be finite and >= 0");
  return true;
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
    } else if (options_.drift_px_per_frame > 0) {
      it->second.drift_px += Eigen::Vector2d(step(rng_), step(rng_));
    }
    const Landmark& l = it->second;
    const Eigen::Vector3d p_c = T_c_w * l.X_w;
    if (!l.valid || !(p_c.z() > 1e-9)) {
      ++stats_.dropped;
      continue;
    }
    Eigen::Vector2d e = l.drift_px;
    if (options_.white_noise_px > 0) e += Eigen::Vector2d(white(rng_), white(rng_));
    const double x = p_c.x() / p_c.z() + e.x() / K.fx, y = p_c.y() / p_c.z() + e.y() / K.fy;
    o.bearing_c = Eigen::Vector3d(x, y, 1.0).normalized();
    kept.push_back(o);
    ++stats_.replaced;
  }
  frame->observations = std::move(kept);
}

}  // namespace evio::evaluation
