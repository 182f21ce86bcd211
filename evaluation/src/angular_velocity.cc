#include "evio/evaluation/angular_velocity.h"

#include <algorithm>
#include <cmath>

#include "evio/calib/geometry.h"

namespace evio::evaluation {
namespace {

constexpr double kRadToDeg = 180.0 / M_PI;

// Central-difference rate of pose k (1 <= k <= n-2), body frame, rad/s, at time *tau_ns.
Eigen::Vector3d central_rate(const std::vector<StampedPose>& p, size_t k, int64_t* tau_ns) {
  const StampedPose& a = p[k - 1];
  const StampedPose& b = p[k + 1];
  *tau_ns = a.t_ns + (b.t_ns - a.t_ns) / 2;
  const Eigen::Quaterniond q = a.T_w_b.rotation.conjugate() * b.T_w_b.rotation;
  return calib::so3_log(q) / (static_cast<double>(b.t_ns - a.t_ns) * 1e-9);
}

}  // namespace

std::optional<Eigen::Vector3d> trajectory_angular_velocity(const Trajectory& T_w_b, int64_t t0_ns, int64_t t1_ns,
                                                            const BodyToCamera& b2c) {
  const std::vector<StampedPose>& p = T_w_b.poses();
  if (p.size() < 3 || t1_ns < t0_ns) return std::nullopt;
  const int64_t a = t0_ns + b2c.time_shift_ns, b = t1_ns + b2c.time_shift_ns;
  // Rates at the central-difference times tau_k, k = 1 .. n-2; the first k whose tau_k >= a.
  auto tau_of = [&](size_t k) { return p[k - 1].t_ns + (p[k + 1].t_ns - p[k - 1].t_ns) / 2; };
  if (a < tau_of(1) || b > tau_of(p.size() - 2)) return std::nullopt;
  // Binary search over k in [1, n-2] for the segment [tau_k, tau_{k+1}] holding a.
  size_t lo = 1, hi = p.size() - 2;
  while (hi - lo > 1) {
    const size_t mid = (lo + hi) / 2;
    (tau_of(mid) <= a ? lo : hi) = mid;
  }
  int64_t t_k = 0, t_k1 = 0;
  Eigen::Vector3d w_k = central_rate(p, lo, &t_k);
  // Integrate the piecewise-linear rate over [a, b] (times in s relative to a).
  auto at = [](int64_t t, int64_t t_left, const Eigen::Vector3d& w_left, int64_t t_right, const Eigen::Vector3d& w_right) {
    if (t_right == t_left) return w_left;
    const double s = static_cast<double>(t - t_left) / static_cast<double>(t_right - t_left);
    return Eigen::Vector3d(w_left + s * (w_right - w_left));
  };
  Eigen::Vector3d integral = Eigen::Vector3d::Zero();
  size_t k = lo;
  for (;;) {
    const bool last = k + 1 > p.size() - 2;
    const Eigen::Vector3d w_k1 = last ? w_k : central_rate(p, k + 1, &t_k1);
    if (last) t_k1 = t_k;
    const int64_t s0 = std::max(a, t_k), s1 = std::min(b, t_k1);
    if (b == a) {
      integral = at(a, t_k, w_k, t_k1, w_k1);
      break;
    }
    if (s1 > s0) {
      const Eigen::Vector3d w0 = at(s0, t_k, w_k, t_k1, w_k1), w1 = at(s1, t_k, w_k, t_k1, w_k1);
      integral += 0.5 * (w0 + w1) * (static_cast<double>(s1 - s0) * 1e-9);
    }
    if (last || t_k1 >= b) break;
    ++k;
    t_k = t_k1;
    w_k = w_k1;
  }
  const Eigen::Vector3d w_b = b == a ? integral : Eigen::Vector3d(integral / (static_cast<double>(b - a) * 1e-9));
  return Eigen::Vector3d(b2c.R_c_b * w_b);
}

std::optional<Eigen::Vector3d> mean_gyro(const std::vector<ImuSample>& imu, int64_t t0_ns, int64_t t1_ns,
                                         const BodyToCamera& b2c) {
  if (imu.size() < 2 || t1_ns < t0_ns) return std::nullopt;
  const int64_t a = t0_ns + b2c.time_shift_ns, b = t1_ns + b2c.time_shift_ns;
  if (a < imu.front().t_ns || b > imu.back().t_ns) return std::nullopt;
  auto first = std::lower_bound(imu.begin(), imu.end(), a, [](const ImuSample& s, int64_t t) { return s.t_ns < t; });
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  size_t n = 0;
  for (auto it = first; it != imu.end() && it->t_ns <= b; ++it, ++n) sum += it->gyro;
  if (n == 0) {  // no sample inside: interpolate at the middle
    const int64_t m = a + (b - a) / 2;
    auto r = std::lower_bound(imu.begin(), imu.end(), m, [](const ImuSample& s, int64_t t) { return s.t_ns < t; });
    if (r == imu.begin()) r = imu.begin() + 1;
    const ImuSample& s0 = *(r - 1);
    const ImuSample& s1 = *r;
    const double f = s1.t_ns == s0.t_ns ? 0.0 : static_cast<double>(m - s0.t_ns) / static_cast<double>(s1.t_ns - s0.t_ns);
    return Eigen::Vector3d(b2c.R_c_b * (s0.gyro + f * (s1.gyro - s0.gyro)));
  }
  return Eigen::Vector3d(b2c.R_c_b * (sum / static_cast<double>(n)));
}

AngularVelocityErrors angular_velocity_errors(const std::vector<Eigen::Vector3d>& estimate,
                                              const std::vector<Eigen::Vector3d>& reference) {
  AngularVelocityErrors r;
  std::vector<double> norms;
  double s2 = 0, ref2 = 0;
  Eigen::Vector3d axis2 = Eigen::Vector3d::Zero();
  const size_t n = std::min(estimate.size(), reference.size());
  for (size_t i = 0; i < n; ++i) {
    if (!estimate[i].allFinite() || !reference[i].allFinite()) continue;
    const Eigen::Vector3d e = (estimate[i] - reference[i]) * kRadToDeg;
    norms.push_back(e.norm());
    s2 += e.squaredNorm();
    axis2 += e.cwiseAbs2();
    ref2 += (reference[i] * kRadToDeg).squaredNorm();
  }
  r.count = norms.size();
  if (r.count == 0) return r;
  const double c = static_cast<double>(r.count);
  r.rms_degps = std::sqrt(s2 / c);
  r.rms_axis_degps = (axis2 / c).cwiseSqrt();
  r.reference_rms_degps = std::sqrt(ref2 / c);
  r.relative_rms = r.reference_rms_degps > 0 ? r.rms_degps / r.reference_rms_degps : 0.0;
  r.max_degps = *std::max_element(norms.begin(), norms.end());
  std::sort(norms.begin(), norms.end());
  const size_t m = norms.size();
  r.median_degps = m % 2 ? norms[m / 2] : 0.5 * (norms[m / 2 - 1] + norms[m / 2]);
  return r;
}

}  // namespace evio::evaluation
