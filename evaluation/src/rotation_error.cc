#include "evio/evaluation/rotation_error.h"

#include "evio/calib/geometry.h"

#include <cmath>
#include <optional>
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
  if (!(end_tolerance >= 0 && end_tolerance < 1)) {
    if (why) *why = "rre end_tolerance must be in [0, 1)";
    return false;
  }
  return true;
}

namespace {

// Appends the interval [t0, t1] with the estimate's rotations q0, q1 there (skipped when the
// ground truth does not cover it).
void add_interval(const Trajectory& groundtruth, int64_t t0, int64_t t1, const calib::Quat& q0, const calib::Quat& q1,
                  RelativeRotationError* r) {
  const auto g0 = groundtruth.interpolate(t0), g1 = groundtruth.interpolate(t1);
  if (!g0 || !g1) return;
  const calib::Quat q_gt = g0->rotation.conjugate() * g1->rotation;
  const calib::Quat q_est = q0.conjugate() * q1;
  r->start_ns.push_back(t0);
  r->end_ns.push_back(t1);
  r->errors_deg.push_back(angle_of(q_gt.conjugate() * q_est) * kRadToDeg);
}

}  // namespace

RelativeRotationError relative_rotation_error_at(const Trajectory& groundtruth, const Trajectory& estimate,
                                                 const std::vector<int64_t>& start_ns, const std::vector<int64_t>& end_ns,
                                                 double interval_s) {
  if (!(interval_s > 0) || !std::isfinite(interval_s)) throw std::invalid_argument("rre interval_s must be finite and > 0");
  if (start_ns.size() != end_ns.size()) throw std::invalid_argument("rre: as many interval ends as starts are needed");
  RelativeRotationError r;
  r.interval_s = interval_s;
  for (size_t k = 0; k < start_ns.size(); ++k) {
    const auto e0 = estimate.interpolate(start_ns[k]), e1 = estimate.interpolate(end_ns[k]);
    if (!e0 || !e1) continue;
    add_interval(groundtruth, start_ns[k], end_ns[k], e0->rotation, e1->rotation, &r);
  }
  r.deg = compute_stats(r.errors_deg);
  return r;
}

RelativeRotationError relative_rotation_error(const Trajectory& groundtruth, const Trajectory& estimate,
                                              const RelativeRotationOptions& options) {
  std::string why;
  if (!options.Validate(&why)) throw std::invalid_argument(why);
  RelativeRotationError r;
  r.interval_s = options.interval_s;
  const int64_t dt = static_cast<int64_t>(std::llround(options.interval_s * 1e9));
  const int64_t tol = static_cast<int64_t>(std::llround(options.end_tolerance * options.interval_s * 1e9));
  const auto& p = estimate.poses();
  size_t j = 0;  // the first pose at or after t0 + dt (advances with t0)
  for (size_t i = 0; i < p.size(); i += options.stride) {
    const int64_t want = p[i].t_ns + dt;
    while (j < p.size() && p[j].t_ns < want) ++j;
    if (j == p.size()) break;  // the estimate ends before t0 + dt
    // The nearer of the poses either side of t0 + dt.
    size_t best = j;
    if (j > i + 1 && want - p[j - 1].t_ns < p[j].t_ns - want) best = j - 1;
    const int64_t off = p[best].t_ns > want ? p[best].t_ns - want : want - p[best].t_ns;
    if (off > tol) continue;
    add_interval(groundtruth, p[i].t_ns, p[best].t_ns, p[i].T_w_b.rotation, p[best].T_w_b.rotation, &r);
  }
  r.deg = compute_stats(r.errors_deg);
  return r;
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

InitialAlignedRotationError rotation_error_initial_aligned(const Trajectory& groundtruth, const Trajectory& estimate) {
  InitialAlignedRotationError r;
  std::optional<calib::SE3> g0;
  size_t first = 0;
  for (; first < estimate.size(); ++first)
    if ((g0 = groundtruth.interpolate(estimate[first].t_ns))) break;
  if (!g0) return r;
  r.R_w_m = g0->rotation.toRotationMatrix() * estimate[first].T_w_b.rotation.toRotationMatrix().transpose();
  for (size_t k = first; k < estimate.size(); ++k) {
    const auto g = groundtruth.interpolate(estimate[k].t_ns);
    if (!g) continue;
    const Eigen::Matrix3d E = g->rotation.toRotationMatrix().transpose() * r.R_w_m * estimate[k].T_w_b.rotation.toRotationMatrix();
    r.t_ns.push_back(estimate[k].t_ns);
    r.errors_deg.push_back(calib::so3_log(E).norm() * 180.0 / M_PI);
  }
  return r;
}

}  // namespace evio::evaluation
