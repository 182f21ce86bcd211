#include "evio/backend/initialization.h"
#include "evio/backend/option_tables.h"

#include <cmath>
#include <limits>
#include <stdexcept>

#include <Eigen/Geometry>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <unordered_map>

#include "evio/backend/imu_preintegration.h"

namespace evio::backend {

bool StaticInitOptions::Validate(std::string* why) const {
  if (!static_init_table().check(*this, why)) return false;
  if (still_tail_ns > window_ns) {
    if (why) *why = "still_tail_ms must be at most window_ms";
    return false;
  }
  return true;
}

std::optional<VioState> static_initialization(const std::vector<ImuSample>& imu, int64_t t_begin_ns,
                                              const calib::ImuNoise& noise, const StaticInitOptions& o, std::string* why,
                                              InitialSigmas* sigmas) {
  auto fail = [why](const std::string& m) -> std::optional<VioState> {
    if (why) *why = m;
    return std::nullopt;
  };
  std::string v;
  if (!o.Validate(&v)) throw std::invalid_argument("static initialisation options: " + v);
  if (!noise.Validate(&v)) throw std::invalid_argument("static initialisation IMU noise: " + v);
  const int64_t t_end = t_begin_ns + o.window_ns;
  Eigen::Vector3d sg = Eigen::Vector3d::Zero(), sa = Eigen::Vector3d::Zero();
  Eigen::Vector3d sg2 = Eigen::Vector3d::Zero(), sa2 = Eigen::Vector3d::Zero();
  int n = 0;
  int64_t t_last = t_begin_ns, t_first = t_end;
  for (const ImuSample& s : imu) {
    if (s.t_ns < t_begin_ns || s.t_ns > t_end) continue;
    t_first = std::min(t_first, s.t_ns);
    sg += s.gyro;
    sa += s.accel;
    sg2 += s.gyro.cwiseProduct(s.gyro);
    sa2 += s.accel.cwiseProduct(s.accel);
    t_last = s.t_ns;
    ++n;
  }
  if (n < 10) return fail("only " + std::to_string(n) + " IMU samples in the window (need 10)");
  if (static_cast<double>(t_last - t_first) < 0.8 * static_cast<double>(o.window_ns)) {
    return fail("the IMU covers only " + std::to_string(static_cast<double>(t_last - t_first) * 1e-9) + " s of the " +
                std::to_string(static_cast<double>(o.window_ns) * 1e-9) + " s window");
  }
  const Eigen::Vector3d mg = sg / n, ma = sa / n;
  const Eigen::Vector3d std_g = (sg2 / n - mg.cwiseProduct(mg)).cwiseMax(0.0).cwiseSqrt();
  const Eigen::Vector3d std_a = (sa2 / n - ma.cwiseProduct(ma)).cwiseMax(0.0).cwiseSqrt();
  const double rate = noise.update_rate_hz;
  const double gyro_sigma = noise.gyroscope_noise_density * std::sqrt(rate);
  const double accel_sigma = noise.accelerometer_noise_density * std::sqrt(rate);
  if (std_g.maxCoeff() > o.max_gyro_noise_ratio * gyro_sigma) {
    if (!o.allow_rotation) {
      return fail("not still: gyro spread " + std::to_string(std_g.maxCoeff()) + " rad/s exceeds " +
                  std::to_string(o.max_gyro_noise_ratio * gyro_sigma));
    }
    // Rotating in place: the specific force rotated into the body frame at the window's end with
    // the integrated gyro must be constant (-g, no linear acceleration).
    std::vector<const ImuSample*> w;
    for (const ImuSample& m : imu)
      if (m.t_ns >= t_begin_ns && m.t_ns <= t_end) w.push_back(&m);
    std::vector<Eigen::Vector3d> a_end(w.size());
    Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // R_end_k, built backwards from the end
    a_end.back() = w.back()->accel;
    for (size_t k = w.size() - 1; k-- > 0;) {
      const double dt = static_cast<double>(w[k + 1]->t_ns - w[k]->t_ns) * 1e-9;
      R = R * calib::so3_exp(-0.5 * (w[k]->gyro + w[k + 1]->gyro) * dt);  // R_end_k = R_end_k+1 Exp(-w dt)
      a_end[k] = R * w[k]->accel;
    }
    Eigen::Vector3d s1 = Eigen::Vector3d::Zero(), s2 = Eigen::Vector3d::Zero();
    for (const auto& a : a_end) {
      s1 += a;
      s2 += a.cwiseProduct(a);
    }
    const Eigen::Vector3d mean = s1 / static_cast<double>(a_end.size());
    const Eigen::Vector3d spread = (s2 / static_cast<double>(a_end.size()) - mean.cwiseProduct(mean)).cwiseMax(0.0).cwiseSqrt();
    if (spread.maxCoeff() > o.max_accel_noise_ratio * accel_sigma) {
      return fail("not still and not rotating in place: gyro spread " + std::to_string(std_g.maxCoeff()) +
                  " rad/s, gyro-compensated accelerometer spread " + std::to_string(spread.maxCoeff()) + " m/s^2");
    }
    if (std::abs(mean.norm() - o.gravity_mps2) > o.max_gravity_error) {
      return fail("mean specific force " + std::to_string(mean.norm()) + " m/s^2 is not gravity");
    }
    VioState s;
    s.t_ns = w.back()->t_ns;
    s.T_w_b = calib::SE3(Eigen::Quaterniond::FromTwoVectors(mean.normalized(), Eigen::Vector3d::UnitZ()), Eigen::Vector3d::Zero());
    if (sigmas) *sigmas = InitialSigmas{};
    return s;  // gyro bias unknown while rotating: zero
  }
  if (std_a.maxCoeff() > o.max_accel_noise_ratio * accel_sigma) {
    return fail("not still: accelerometer spread " + std::to_string(std_a.maxCoeff()) + " m/s^2 exceeds " +
                std::to_string(o.max_accel_noise_ratio * accel_sigma));
  }
  if (std::abs(ma.norm() - o.gravity_mps2) > o.max_gravity_error) {
    return fail("mean specific force " + std::to_string(ma.norm()) + " m/s^2 is not gravity (" +
                std::to_string(o.gravity_mps2) + ")");
  }
  if (o.still_tail_ns > 0) {
    Eigen::Vector3d tg = Eigen::Vector3d::Zero(), ta = Eigen::Vector3d::Zero();
    int nt = 0;
    for (const ImuSample& m : imu) {
      if (m.t_ns < t_last - o.still_tail_ns || m.t_ns > t_last) continue;
      tg += m.gyro;
      ta += m.accel;
      ++nt;
    }
    if (nt > 0) {
      const double se = 1.0 / std::sqrt(static_cast<double>(nt));
      const double dg = (tg / nt - mg).cwiseAbs().maxCoeff(), da = (ta / nt - ma).cwiseAbs().maxCoeff();
      if (dg > o.max_gyro_noise_ratio * gyro_sigma * se || da > o.max_accel_noise_ratio * accel_sigma * se) {
        return fail("moving at the window's end: the last " + std::to_string(static_cast<double>(o.still_tail_ns) * 1e-9) +
                    " s differ from the window's mean by " + std::to_string(dg) + " rad/s, " + std::to_string(da) + " m/s^2");
      }
    }
  }
  VioState s;
  s.t_ns = t_last;
  // R_w_b maps the measured up direction (specific force at rest = -g) onto world +z; yaw 0.
  s.T_w_b = calib::SE3(Eigen::Quaterniond::FromTwoVectors(ma.normalized(), Eigen::Vector3d::UnitZ()), Eigen::Vector3d::Zero());
  s.bias_gyro = mg;
  if (sigmas) {
    sigmas->bias_gyro_radps = std::max(std_g.maxCoeff(), gyro_sigma) / std::sqrt(static_cast<double>(n));
    sigmas->velocity_mps = o.max_accel_noise_ratio * noise.accelerometer_noise_density *
                           std::sqrt(static_cast<double>(o.window_ns) * 1e-9);
  }
  return s;
}

}  // namespace evio::backend

namespace evio::backend {

bool VisualInertialInitOptions::Validate(std::string* why) const {
  if (!visual_inertial_init_table().check(*this, why)) return false;
  if (max_tracks < min_tracks) {
    if (why) *why = "max_tracks must be at least min_tracks";
    return false;
  }
  return true;
}

std::optional<VioState> visual_inertial_initialization(const std::vector<FeatureObservations>& frames,
                                                       const std::vector<ImuSample>& imu,
                                                       const calib::CameraCalibration& camera, const calib::ImuNoise& noise,
                                                       const Eigen::Vector3d& bias_gyro, const Eigen::Vector3d& bias_accel,
                                                       const VisualInertialInitOptions& o, std::string* why) {
  auto fail = [why](const std::string& m) -> std::optional<VioState> {
    if (why) *why = m;
    return std::nullopt;
  };
  std::string v;
  if (!o.Validate(&v)) throw std::invalid_argument("visual-inertial initialisation options: " + v);
  if (static_cast<int>(frames.size()) < o.min_frames) {
    return fail(std::to_string(frames.size()) + " frames (need " + std::to_string(o.min_frames) + ")");
  }
  if (imu.empty() || imu.front().t_ns > frames.front().t_ns || imu.back().t_ns < frames.back().t_ns) {
    return fail("the IMU samples do not cover the frames");
  }
  // IMU: rotation and position deltas of each frame from the first (first body frame).
  const int F = static_cast<int>(frames.size());
  std::vector<Eigen::Matrix3d> R0(F);
  std::vector<Eigen::Vector3d> dp(F);
  std::vector<double> t(F);
  for (int j = 0; j < F; ++j) {
    const ImuPreintegration pre =
        ImuPreintegration::between(imu, frames.front().t_ns, frames[j].t_ns, bias_gyro, bias_accel, noise);
    R0[j] = pre.delta_R();
    dp[j] = pre.delta_p();
    t[j] = pre.dt_s();
  }
  // Excitation: the specific force must vary, else gravity and acceleration cannot be separated.
  {
    Eigen::Vector3d s = Eigen::Vector3d::Zero(), s2 = Eigen::Vector3d::Zero();
    int n = 0;
    for (const ImuSample& m : imu) {
      if (m.t_ns < frames.front().t_ns || m.t_ns > frames.back().t_ns) continue;
      s += m.accel;
      s2 += m.accel.cwiseProduct(m.accel);
      ++n;
    }
    const Eigen::Vector3d mean = s / std::max(1, n);
    const double spread = (s2 / std::max(1, n) - mean.cwiseProduct(mean)).cwiseMax(0.0).cwiseSqrt().norm();
    if (spread < o.min_accel_excitation_mps2) {
      return fail("too little acceleration (specific-force spread " + std::to_string(spread) + " m/s^2)");
    }
  }
  // Tracks seen in enough frames; the most observed first.
  std::unordered_map<int64_t, std::vector<std::pair<int, Eigen::Vector3d>>> tracks;
  for (int j = 0; j < F; ++j)
    for (const FeatureObservation& ob : frames[j].observations) tracks[ob.track_id].push_back({j, ob.bearing_c});
  std::vector<std::pair<int64_t, size_t>> order;
  for (const auto& [id, obs] : tracks)
    if (static_cast<int>(obs.size()) >= o.min_track_frames) order.push_back({id, obs.size()});
  std::sort(order.begin(), order.end(), [](const auto& a, const auto& b) { return a.second != b.second ? a.second > b.second : a.first < b.first; });
  if (static_cast<int>(order.size()) < o.min_tracks) {
    return fail(std::to_string(order.size()) + " tracks seen in " + std::to_string(o.min_track_frames) + "+ frames (need " +
                std::to_string(o.min_tracks) + ")");
  }
  if (static_cast<int>(order.size()) > o.max_tracks) order.resize(static_cast<size_t>(o.max_tracks));
  const int K = static_cast<int>(order.size());
  const Eigen::Matrix3d R_b_c = camera.T_c_b.rotation.toRotationMatrix().transpose();
  const Eigen::Vector3d t_b_c = -(R_b_c * camera.T_c_b.translation);
  // Observations used (outliers are dropped after each solve by their angular error).
  struct Obs {
    int k, j;
    Eigen::Vector3d d;  // world (first body frame) direction
    bool used = true;
  };
  std::vector<Obs> obs;
  for (int k = 0; k < K; ++k)
    for (const auto& [j, bearing] : tracks[order[static_cast<size_t>(k)].first])
      obs.push_back({k, j, (R0[j] * R_b_c * bearing).normalized(), true});
  const double focal = camera.camera.intrinsics().fx;
  // Unknowns: v0 (3), g0 (3), X_k (3 per active track). Each row block is
  //   P (X_k - v0 t_j - g0 t_j^2 / 2) = P (dp_j + R0_j t_b_c),  P = I - d d^T,
  // so the normal equations have a block-diagonal point part: the points are eliminated per track
  // (Schur complement), the 6x6 (3x3 with gravity fixed) system in v0, g0 is solved, and the
  // points follow by back-substitution. Linear in the number of observations.
  std::vector<int> column(static_cast<size_t>(K), -1);
  auto solve = [&](const std::optional<Eigen::Vector3d>& g_fixed, Eigen::VectorXd* x) {
    std::vector<int> count(static_cast<size_t>(K), 0);
    for (const Obs& ob : obs) count[static_cast<size_t>(ob.k)] += ob.used ? 1 : 0;
    int active = 0;
    for (int k = 0; k < K; ++k) column[static_cast<size_t>(k)] = count[static_cast<size_t>(k)] >= 2 ? active++ : -1;
    if (active < o.min_tracks) return false;
    const int m = g_fixed ? 3 : 6;  // state unknowns
    std::vector<Eigen::Matrix3d> Hkk(static_cast<size_t>(active), Eigen::Matrix3d::Zero());
    std::vector<Eigen::Matrix<double, 3, 6>> Hks(static_cast<size_t>(active), Eigen::Matrix<double, 3, 6>::Zero());
    std::vector<Eigen::Vector3d> bk(static_cast<size_t>(active), Eigen::Vector3d::Zero());
    Eigen::Matrix<double, 6, 6> Hss = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> bs = Eigen::Matrix<double, 6, 1>::Zero();
    for (const Obs& ob : obs) {
      const int col = column[static_cast<size_t>(ob.k)];
      if (!ob.used || col < 0) continue;
      const int j = ob.j;
      const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - ob.d * ob.d.transpose();
      // Row block: P X_k + As s = rhs with As = [-P t_j, -P t_j^2/2] ([-P t_j] with gravity fixed).
      Eigen::Matrix<double, 3, 6> As = Eigen::Matrix<double, 3, 6>::Zero();
      As.leftCols<3>() = -P * t[j];
      Eigen::Vector3d rhs = P * (dp[j] + R0[j] * t_b_c);
      if (g_fixed) {
        rhs += P * (0.5 * t[j] * t[j] * *g_fixed);
      } else {
        As.rightCols<3>() = -P * (0.5 * t[j] * t[j]);
      }
      // P is symmetric and idempotent: P^T P = P, P^T As = As, P^T rhs = rhs.
      Hkk[static_cast<size_t>(col)] += P;
      Hks[static_cast<size_t>(col)] += As;
      bk[static_cast<size_t>(col)] += rhs;
      Hss += As.transpose() * As;
      bs += As.transpose() * rhs;
    }
    Eigen::Matrix<double, 6, 6> S = Hss;
    Eigen::Matrix<double, 6, 1> r = bs;
    std::vector<Eigen::Matrix3d> Hinv(static_cast<size_t>(active));
    for (int k = 0; k < active; ++k) {
      const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(Hkk[static_cast<size_t>(k)]);
      if (!(es.eigenvalues().minCoeff() > 1e-9 * std::max(1.0, es.eigenvalues().maxCoeff()))) return false;
      Hinv[static_cast<size_t>(k)] = es.eigenvectors() * es.eigenvalues().cwiseInverse().asDiagonal() * es.eigenvectors().transpose();
      S -= Hks[static_cast<size_t>(k)].transpose() * Hinv[static_cast<size_t>(k)] * Hks[static_cast<size_t>(k)];
      r -= Hks[static_cast<size_t>(k)].transpose() * Hinv[static_cast<size_t>(k)] * bk[static_cast<size_t>(k)];
    }
    const Eigen::MatrixXd Sm = 0.5 * (S.topLeftCorner(m, m) + S.topLeftCorner(m, m).transpose());
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(Sm);
    if (!(es.eigenvalues().minCoeff() > 1e-12 * std::max(1.0, es.eigenvalues().maxCoeff()))) return false;
    const Eigen::VectorXd state =
        es.eigenvectors() * es.eigenvalues().cwiseInverse().asDiagonal() * es.eigenvectors().transpose() * r.head(m);
    x->resize(m + 3 * active);
    x->head(m) = state;
    Eigen::Matrix<double, 6, 1> s6 = Eigen::Matrix<double, 6, 1>::Zero();
    s6.head(m) = state;
    for (int k = 0; k < active; ++k) {
      x->segment<3>(m + 3 * k) = Hinv[static_cast<size_t>(k)] * (bk[static_cast<size_t>(k)] - Hks[static_cast<size_t>(k)] * s6);
    }
    return true;
  };
  // Angular error of each observation for a solution: the ray from the camera centre of frame j
  // to X_k against the observed direction; above 3 px (at the focal length) it is an outlier.
  auto reject = [&](const Eigen::VectorXd& x, const std::optional<Eigen::Vector3d>& g_fixed) {
    const Eigen::Vector3d v0 = x.head<3>();
    const Eigen::Vector3d g = g_fixed ? *g_fixed : Eigen::Vector3d(x.segment<3>(3));
    const int off = g_fixed ? 3 : 6;
    std::vector<double> err(obs.size(), std::numeric_limits<double>::infinity());
    std::vector<double> used_err;
    for (size_t i = 0; i < obs.size(); ++i) {
      const Obs& ob = obs[i];
      const int col = column[static_cast<size_t>(ob.k)];
      if (col < 0) continue;
      const Eigen::Vector3d c = v0 * t[ob.j] + 0.5 * g * t[ob.j] * t[ob.j] + dp[ob.j] + R0[ob.j] * t_b_c;
      const Eigen::Vector3d ray = x.segment<3>(off + 3 * col) - c;
      if (ray.dot(ob.d) <= 0) continue;
      err[i] = std::acos(std::clamp(ray.normalized().dot(ob.d), -1.0, 1.0)) * focal;  // px
      if (ob.used) used_err.push_back(err[i]);
    }
    // Outliers: above 3 px and above 4x the median error (a poorly conditioned first solution
    // has large errors everywhere; those are not outliers).
    std::nth_element(used_err.begin(), used_err.begin() + static_cast<long>(used_err.size() / 2), used_err.end());
    const double thresh = std::max(3.0, used_err.empty() ? 0.0 : 4.0 * used_err[used_err.size() / 2]);
    int dropped = 0;
    for (size_t i = 0; i < obs.size(); ++i) {
      const bool ok = err[i] < thresh;
      if (obs[i].used && !ok) ++dropped;
      obs[i].used = ok;
    }
    return dropped;
  };
  Eigen::VectorXd x;
  for (int it = 0; it < 3; ++it) {
    if (!solve(std::nullopt, &x) || !x.allFinite()) return fail("rank-deficient alignment (degenerate motion or too few tracks)");
    if (reject(x, std::nullopt) == 0) break;
  }
  Eigen::Vector3d g0 = x.segment<3>(3);
  if (std::abs(g0.norm() - o.gravity_mps2) > o.max_gravity_error) {
    return fail("aligned gravity magnitude " + std::to_string(g0.norm()) + " m/s^2 is not " + std::to_string(o.gravity_mps2));
  }
  g0 = g0.normalized() * o.gravity_mps2;
  if (!solve(g0, &x) || !x.allFinite()) return fail("rank-deficient alignment with fixed gravity");
  const Eigen::Vector3d v0 = x.head<3>();
  VioState s;
  s.t_ns = frames.front().t_ns;
  // R_w_b0 g0 = (0, 0, -g): the minimal tilt.
  const Eigen::Quaterniond q = Eigen::Quaterniond::FromTwoVectors(g0.normalized(), -Eigen::Vector3d::UnitZ());
  s.T_w_b = calib::SE3(q, Eigen::Vector3d::Zero());
  s.v_w = q * v0;
  s.bias_gyro = bias_gyro;
  s.bias_accel = bias_accel;
  return s;
}

}  // namespace evio::backend
