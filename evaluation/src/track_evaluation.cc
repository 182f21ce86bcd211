#include "evio/evaluation/track_evaluation.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <sstream>
#include <stdexcept>

#include <Eigen/Dense>

namespace evio::evaluation {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// Quantile q in [0, 1] of v (sorted in place; nearest rank); NaN when empty.
double quantile(std::vector<double>* v, double q) {
  if (v->empty()) return kNaN;
  const size_t k = std::min(v->size() - 1, static_cast<size_t>(q * static_cast<double>(v->size())));
  std::nth_element(v->begin(), v->begin() + static_cast<long>(k), v->end());
  return (*v)[k];
}

double mean(const std::vector<double>& v) {
  if (v.empty()) return kNaN;
  double s = 0;
  for (double x : v) s += x;
  return s / static_cast<double>(v.size());
}

struct Obs {
  size_t frame;  // index into the posed frames
  Eigen::Vector3d bearing_c;
};

// Pixel error (observed - predicted) of an observed bearing against the camera-frame point p_c
// on the ideal pinhole; +inf when either is behind the camera.
Eigen::Vector2d pixel_error(const Eigen::Vector3d& b, const Eigen::Vector3d& p_c, double fx, double fy) {
  if (!(b.z() > 1e-9) || !(p_c.z() > 1e-9)) return Eigen::Vector2d::Constant(std::numeric_limits<double>::infinity());
  return {fx * (b.x() / b.z() - p_c.x() / p_c.z()), fy * (b.y() / b.z() - p_c.y() / p_c.z())};
}

// Least-squares point closest to the rays (origin o_i, unit direction d_i): minimises
// sum |(I - d d^T)(X - o)|^2. nullopt when the rays are too parallel.
std::optional<Eigen::Vector3d> triangulate(const std::vector<Eigen::Vector3d>& o, const std::vector<Eigen::Vector3d>& d,
                                           double min_angle_rad) {
  double max_angle = 0;
  for (size_t i = 0; i < d.size(); ++i)
    for (size_t j = i + 1; j < d.size(); ++j) max_angle = std::max(max_angle, std::acos(std::clamp(d[i].dot(d[j]), -1.0, 1.0)));
  if (max_angle < min_angle_rad) return std::nullopt;
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (size_t i = 0; i < o.size(); ++i) {
    const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - d[i] * d[i].transpose();
    A += P;
    b += P * o[i];
  }
  const Eigen::Vector3d X = A.ldlt().solve(b);
  if (!X.allFinite()) return std::nullopt;
  return X;
}

}  // namespace

bool TrackEvaluationOptions::Validate(std::string* why) const {
  auto fail = [why](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (max_age_frames < 1) return fail("max_age_frames must be >= 1");
  if (min_observations < 2) return fail("min_observations must be >= 2");
  if (!(min_triangulation_angle_deg >= 0) || !std::isfinite(min_triangulation_angle_deg))
    return fail("min_triangulation_angle_deg must be finite and >= 0");
  if (!(lost_border_px >= 0) || !std::isfinite(lost_border_px)) return fail("lost_border_px must be finite and >= 0");
  if (!(occlusion_tolerance > 0) || !std::isfinite(occlusion_tolerance))
    return fail("occlusion_tolerance must be finite and > 0");
  if (!(gross_error_px > 0)) return fail("gross_error_px must be > 0");
  return true;
}

TrackEvaluation evaluate_tracks(const std::vector<FeatureObservations>& frames, const Trajectory& groundtruth,
                                const calib::CameraCalibration& camera, const RayCaster& cast,
                                const TrackEvaluationOptions& options) {
  std::string why;
  if (!options.Validate(&why)) throw std::invalid_argument("evaluate_tracks: " + why);
  if (options.reference == TrackReference::kAnchored && !cast)
    throw std::invalid_argument("evaluate_tracks: the anchored reference needs a ray caster");
  const auto& K = camera.camera.intrinsics();
  const calib::SE3 T_b_c = camera.T_c_b.inverse();

  // Frames with a true pose, and every track's observations in frame order.
  std::vector<calib::SE3> T_w_c;
  std::vector<int64_t> t_frame;
  std::map<int64_t, std::vector<Obs>> tracks;
  int64_t observed = 0;
  for (const FeatureObservations& f : frames) {
    const auto T_w_b = groundtruth.interpolate(f.t_ns);
    if (!T_w_b) continue;
    const size_t k = T_w_c.size();
    T_w_c.push_back(*T_w_b * T_b_c);
    t_frame.push_back(f.t_ns);
    for (const FeatureObservation& o : f.observations) tracks[o.track_id].push_back({k, o.bearing_c});
    observed += static_cast<int64_t>(f.observations.size());
  }
  TrackEvaluation r;
  r.frames = static_cast<int64_t>(T_w_c.size());
  if (r.frames > 0) r.mean_tracks_per_frame = static_cast<double>(observed) / static_cast<double>(r.frames);

  std::vector<std::vector<double>> by_age(static_cast<size_t>(options.max_age_frames));
  std::vector<double> all, lifetimes, lifetimes_s;
  const double min_angle = options.min_triangulation_angle_deg * M_PI / 180.0;
  for (const auto& [id, obs] : tracks) {
    lifetimes.push_back(static_cast<double>(obs.size()));
    lifetimes_s.push_back(1e-9 * static_cast<double>(t_frame[obs.back().frame] - t_frame[obs.front().frame]));
    if (static_cast<int>(obs.size()) < options.min_observations) continue;
    ++r.tracks;
    std::optional<Eigen::Vector3d> X;
    if (options.reference == TrackReference::kAnchored) {
      const calib::SE3& T = T_w_c[obs.front().frame];
      const Eigen::Vector3d d = T.rotation * obs.front().bearing_c;
      if (const auto s = cast(T.translation, d)) X = T.translation + *s * d;
    } else {
      std::vector<Eigen::Vector3d> o, d;
      for (const Obs& ob : obs) {
        const calib::SE3& T = T_w_c[ob.frame];
        o.push_back(T.translation);
        d.push_back((T.rotation * ob.bearing_c).normalized());
      }
      X = triangulate(o, d, min_angle);
    }
    if (!X) continue;
    ++r.tracks_scored;
    for (size_t i = 1; i < obs.size(); ++i) {
      const calib::SE3 T_c_w = T_w_c[obs[i].frame].inverse();
      const Eigen::Vector2d ev = pixel_error(obs[i].bearing_c, T_c_w * *X, K.fx, K.fy);
      const double e = ev.norm();
      const int age = static_cast<int>(obs[i].frame - obs.front().frame);
      if (options.keep_residuals) r.residuals.push_back({t_frame[obs[i].frame], id, age, ev});
      ++r.observations_scored;
      if (!(e <= options.gross_error_px)) {
        ++r.gross_errors;
        continue;
      }
      by_age[static_cast<size_t>(std::clamp(age, 1, options.max_age_frames) - 1)].push_back(e);
      all.push_back(e);
    }
    // Lost while visible: the landmark in the frame after the track's last observation.
    const size_t next = obs.back().frame + 1;
    if (cast && next < T_w_c.size()) {
      ++r.ended;
      const calib::SE3& T = T_w_c[next];
      const Eigen::Vector3d p_c = T.inverse() * *X;
      Eigen::Vector2d px;
      if (p_c.z() > 1e-6 && camera.camera.project(p_c, &px)) {
        const double b = options.lost_border_px;
        const bool inside = px.x() >= b && px.y() >= b && px.x() <= K.width - 1 - b && px.y() <= K.height - 1 - b;
        const Eigen::Vector3d d = *X - T.translation;
        const auto s = cast(T.translation, d);
        const bool unoccluded = s && std::abs(*s - 1.0) <= options.occlusion_tolerance;
        if (inside && unoccluded) ++r.lost_while_visible;
      }
    }
  }
  r.median_px = quantile(&all, 0.5);
  r.p90_px = quantile(&all, 0.9);
  r.mean_px = mean(all);
  for (int a = 1; a <= options.max_age_frames; ++a) {
    std::vector<double>& v = by_age[static_cast<size_t>(a - 1)];
    TrackAgeBin bin;
    bin.age_frames = a;
    bin.count = static_cast<int64_t>(v.size());
    bin.mean_px = mean(v);
    bin.median_px = quantile(&v, 0.5);
    bin.p90_px = quantile(&v, 0.9);
    r.by_age.push_back(bin);
  }
  r.mean_lifetime_frames = mean(lifetimes);
  r.median_lifetime_frames = quantile(&lifetimes, 0.5);
  r.median_lifetime_s = quantile(&lifetimes_s, 0.5);
  r.lost_fraction = r.ended > 0 ? static_cast<double>(r.lost_while_visible) / static_cast<double>(r.ended) : 0.0;
  return r;
}

std::string track_evaluation_json(const TrackEvaluation& e) {
  std::ostringstream j;
  auto num = [&](double v) {
    if (std::isfinite(v)) {
      j << v;
    } else {
      j << "null";
    }
  };
  j.precision(6);
  j << "{\"frames\": " << e.frames << ", \"tracks\": " << e.tracks << ", \"tracks_scored\": " << e.tracks_scored
    << ", \"observations_scored\": " << e.observations_scored << ", \"gross_errors\": " << e.gross_errors
    << ", \"median_px\": ";
  num(e.median_px);
  j << ", \"mean_px\": ";
  num(e.mean_px);
  j << ", \"p90_px\": ";
  num(e.p90_px);
  j << ", \"median_lifetime_frames\": ";
  num(e.median_lifetime_frames);
  j << ", \"mean_lifetime_frames\": ";
  num(e.mean_lifetime_frames);
  j << ", \"median_lifetime_s\": ";
  num(e.median_lifetime_s);
  j << ", \"lost_while_visible\": " << e.lost_while_visible << ", \"ended\": " << e.ended << ", \"lost_fraction\": ";
  num(e.lost_fraction);
  j << ", \"mean_tracks_per_frame\": ";
  num(e.mean_tracks_per_frame);
  j << ", \"by_age\": [";
  for (size_t i = 0; i < e.by_age.size(); ++i) {
    const TrackAgeBin& b = e.by_age[i];
    j << (i ? ", " : "") << "{\"age\": " << b.age_frames << ", \"count\": " << b.count << ", \"median_px\": ";
    num(b.median_px);
    j << ", \"mean_px\": ";
    num(b.mean_px);
    j << ", \"p90_px\": ";
    num(b.p90_px);
    j << "}";
  }
  j << "]}";
  return j.str();
}

}  // namespace evio::evaluation
