#include "evio/evaluation/rotation_error.h"

#include <cmath>
#include <stdexcept>

namespace evio::evaluation {
namespace {

constexpr double kRadToDeg = 180.0 / M_PI;

double angle_of(const calib::Quat& q) {
  // atan2 form: precise for small angles (acos of the trace loses digits below ~1e-4 deg).
  return 2.0 * std::atan2(q.vec().norm(), std::abs(q.w()));
}

}  // namespace

bool RelativeRotationOptions::Validate(std::string* why) const {
  if (!(interval_s > 0) || !std::isfinite(interval_s)) {
    if (why) *why = "rre interval_s must be finite and > 0";
    return false;
  }
  if (stride < 1) {
    if (why) *why = "rre stride must be >= 1";
    return false;
  }
  return true;
}

RelativeRotationError relative_rotation_error_at(const Trajectory& groundtruth, const Trajectory& estimate,
                                                 const std::vector<int64_t>& start_ns, double interval_s) {
  if (!(interval_s > 0) || !std::isfinite(interval_s)) throw std::invalid_argument("rre interval_s must be finite and > 0");
  RelativeRotationError r;
  r.interval_s = interval_s;
  const int64_t dt = static_cast<int64_t>(std::llround(interval_s * 1e9));
  for (const int64_t t0 : start_ns) {
    const int64_t t1 = t0 + dt;
    const auto g0 = groundtruth.interpolate(t0), g1 = groundtruth.interpolate(t1);
    const auto e0 = estimate.interpolate(t0), e1 = estimate.interpolate(t1);
    if (!g0 || !g1 || !e0 || !e1) continue;
    const calib::Quat q_gt = g0->rotation.conjugate() * g1->rotation;
    const calib::Quat q_est = e0->rotation.conjugate() * e1->rotation;
    r.start_ns.push_back(t0);
    r.errors_deg.push_back(angle_of(q_gt.conjugate() * q_est) * kRadToDeg);
  }
  r.deg = compute_stats(r.errors_deg);
  return r;
}

RelativeRotationError relative_rotation_error(const Trajectory& groundtruth, const Trajectory& estimate,
                                              const RelativeRotationOptions& options) {
  std::string why;
  if (!options.Validate(&why)) throw std::invalid_argument(why);
  std::vector<int64_t> starts;
  for (size_t i = 0; i < estimate.size(); i += options.stride) starts.push_back(estimate[i].t_ns);
  return relative_rotation_error_at(groundtruth, estimate, starts, options.interval_s);
}

GyroIntegrator::GyroIntegrator(int64_t period_ns) : period_ns_(period_ns) {
  if (period_ns_ <= 0) throw std::invalid_argument("GyroIntegrator: period_ns must be > 0");
}

void GyroIntegrator::add(const ImuSample& s) {
  if (have_last_ && s.t_ns <= last_.t_ns) return;
  if (!s.gyro.allFinite()) return;
  if (have_last_) {
    const double dt = 1e-9 * static_cast<double>(s.t_ns - last_.t_ns);
    q_ = (q_ * calib::so3_exp_quat(0.5 * (last_.gyro + s.gyro) * dt)).normalized();
  }
  last_ = s;
  have_last_ = true;
  ++samples_;
  StampedPose p;
  p.t_ns = s.t_ns;
  p.T_w_b = calib::SE3(q_, Eigen::Vector3d::Zero());
  // Keep one pose per period, and always the newest: a pose less than a period after the last
  // kept one is tentative and replaced by the next sample.
  if (tentative_) {
    poses_.back() = p;
  } else {
    poses_.push_back(p);
  }
  tentative_ = poses_.size() > 1 && s.t_ns - kept_t_ns_ < period_ns_;
  if (!tentative_) kept_t_ns_ = s.t_ns;
}

Trajectory GyroIntegrator::trajectory() const { return Trajectory(poses_); }

}  // namespace evio::evaluation
