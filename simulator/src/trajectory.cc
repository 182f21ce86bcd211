// Continuous trajectories for the simulator: closed-form sinusoids and uniform cumulative
// B-splines on SO(3) x R^3 with exact derivatives (Sommer et al., CVPR 2020), random splines from a
// seed and least-squares spline fits to stamped poses.
//
// Spline conventions. Order k (degree k - 1), control points (R_i, p_i), knots t0 + i dt. In
// segment s (t in [t0 + s dt, t0 + (s+1) dt), u = (t - t0)/dt - s in [0, 1)):
//   p(u) = p_s + sum_{j=1}^{k-1} B~_j(u) (p_{s+j} - p_{s+j-1})
//   R(u) = R_s * prod_{j=1}^{k-1} Exp(B~_j(u) d_{s+j-1}),   d_i = Log(R_i^T R_{i+1})
// with the cumulative basis B~_j(u) = sum_{l>=j} B_l(u) (B_l the uniform B-spline basis of order
// k on control point s + l). Body angular velocity and its derivative (per unit u) follow the
// recursion of Sommer et al. (eq. 9-10):
//   w_1 = 0,  w_{j+1} = A_j^T w_j + B~_j' d_j,                                A_j = Exp(B~_j d_j)
//   w'_{j+1} = A_j^T w'_j + B~_j'' d_j + B~_j' (A_j^T w_j) x d_j
// and are divided by dt and dt^2 for rad/s and rad/s^2.
#include "evio/simulator/trajectory.h"
#include "evio/calib/error.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>

#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>

#include "random.h"

namespace evio::simulator {
namespace {

using calib::Mat3;
using calib::Quat;
using calib::Vec3;

constexpr int kMinOrder = 4;
constexpr int kMaxOrder = 6;
constexpr double kNsPerS = 1e9;

bool finite3(const Eigen::Vector3d& v) { return v.allFinite(); }

bool valid_quaternion(const Eigen::Quaterniond& q) {
  return q.coeffs().allFinite() && q.norm() > 1e-9;
}

// ---------------------------------------------------------------- sinusoids

// angle(t) = rate t + amp sin(2 pi f t + phase) and its first two derivatives.
struct Wave {
  double value, first, second;
};

Wave wave(double rate, double amplitude, double frequency_hz, double phase, double t) {
  const double omega = 2.0 * M_PI * frequency_hz;
  const double arg = omega * t + phase;
  const double s = std::sin(arg);
  const double c = std::cos(arg);
  return {rate * t + amplitude * s, rate + amplitude * omega * c, -amplitude * omega * omega * s};
}

Mat3 rot_x(double a) { return Eigen::AngleAxisd(a, Vec3::UnitX()).toRotationMatrix(); }
Mat3 rot_y(double a) { return Eigen::AngleAxisd(a, Vec3::UnitY()).toRotationMatrix(); }
Mat3 rot_z(double a) { return Eigen::AngleAxisd(a, Vec3::UnitZ()).toRotationMatrix(); }

// ---------------------------------------------------------------- B-spline basis

// Cumulative blending matrix of the uniform B-spline of order k: c[j][n] is the coefficient of
// u^n in B~_j(u). From the (non-cumulative) blending matrix (Qin 2000; Sommer et al. eq. 3)
//   M_{s,n} = C(k-1, n) / (k-1)! * sum_{l=s}^{k-1} (-1)^{l-s} C(k, l-s) (k-1-l)^{k-1-n}.
struct CumulativeBasis {
  int k = 0;
  double c[kMaxOrder][kMaxOrder] = {};
};

double binomial(int n, int r) {
  double v = 1.0;
  for (int i = 1; i <= r; ++i) v = v * (n - r + i) / i;
  return v;
}

double int_pow(double x, int e) {
  double v = 1.0;  // 0^0 = 1, as the formula needs
  for (int i = 0; i < e; ++i) v *= x;
  return v;
}

CumulativeBasis make_basis(int k) {
  double m[kMaxOrder][kMaxOrder] = {};
  double factorial = 1.0;
  for (int i = 2; i <= k - 1; ++i) factorial *= i;
  for (int s = 0; s < k; ++s) {
    for (int n = 0; n < k; ++n) {
      double sum = 0.0;
      for (int l = s; l < k; ++l) {
        const double sign = ((l - s) % 2 == 0) ? 1.0 : -1.0;
        sum += sign * binomial(k, l - s) * int_pow(k - 1 - l, k - 1 - n);
      }
      m[s][n] = binomial(k - 1, n) / factorial * sum;
    }
  }
  CumulativeBasis b;
  b.k = k;
  for (int j = 0; j < k; ++j) {
    for (int n = 0; n < k; ++n) {
      double sum = 0.0;
      for (int s = j; s < k; ++s) sum += m[s][n];
      b.c[j][n] = sum;
    }
  }
  return b;
}

const CumulativeBasis& basis_for_order(int k) {
  static const CumulativeBasis b4 = make_basis(4);
  static const CumulativeBasis b5 = make_basis(5);
  static const CumulativeBasis b6 = make_basis(6);
  if (k == 4) return b4;
  if (k == 5) return b5;
  return b6;
}

// Cumulative basis values and their first two derivatives with respect to u; entries 0..k-1
// (entry 0 is the constant 1) and entry k = 0 so that B_j = B~_j - B~_{j+1} for every j < k.
struct BasisValues {
  double value[kMaxOrder + 1] = {};
  double d1[kMaxOrder + 1] = {};
  double d2[kMaxOrder + 1] = {};
};

BasisValues eval_basis(const CumulativeBasis& b, double u) {
  double p[kMaxOrder];
  p[0] = 1.0;
  for (int n = 1; n < b.k; ++n) p[n] = p[n - 1] * u;
  BasisValues v;
  for (int j = 0; j < b.k; ++j) {
    double value = 0.0, d1 = 0.0, d2 = 0.0;
    for (int n = 0; n < b.k; ++n) {
      value += b.c[j][n] * p[n];
      if (n >= 1) d1 += n * b.c[j][n] * p[n - 1];
      if (n >= 2) d2 += n * (n - 1) * b.c[j][n] * p[n - 2];
    }
    v.value[j] = value;
    v.d1[j] = d1;
    v.d2[j] = d2;
  }
  return v;
}

// Segment index and fraction for t_ns in [t0, t0 + segments * dt]: integer arithmetic for the
// index, so the fraction keeps full double precision however large the absolute timestamps.
struct SplinePosition {
  size_t segment;
  double u;
};

SplinePosition locate(int64_t t_ns, int64_t t0_ns, int64_t dt_ns, size_t segments) {
  const int64_t rel = t_ns - t0_ns;
  int64_t seg = rel / dt_ns;
  int64_t rem = rel - seg * dt_ns;
  if (seg >= static_cast<int64_t>(segments)) {  // t at the very end of the valid range
    seg = static_cast<int64_t>(segments) - 1;
    rem = rel - seg * dt_ns;
  }
  return {static_cast<size_t>(seg), static_cast<double>(rem) / static_cast<double>(dt_ns)};
}

// Quaternions with q_i . q_{i-1} >= 0 and unit norm.
void make_sign_continuous(std::vector<Quat>* q) {
  for (size_t i = 0; i < q->size(); ++i) {
    (*q)[i].normalize();
    if (i > 0 && (*q)[i].coeffs().dot((*q)[i - 1].coeffs()) < 0.0) (*q)[i].coeffs() *= -1.0;
  }
}

std::string format_seconds(int64_t ns) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.6g", static_cast<double>(ns) / kNsPerS);
  return buf;
}

// ---------------------------------------------------------------- fitting

// Symmetric block-banded system of n 3x3 blocks, (i, j) stored for 0 <= j - i < band.
class BlockBandSystem {
 public:
  BlockBandSystem(size_t n, int band)
      : n_(n), band_(band), blocks_(n * static_cast<size_t>(band), Mat3::Zero()),
        rhs_(Eigen::VectorXd::Zero(3 * static_cast<Eigen::Index>(n))) {}

  // Adds b to block (i, j) and b^T to (j, i).
  void add(size_t i, size_t j, const Mat3& b) {
    if (i <= j) {
      block(i, j) += b;
    } else {
      block(j, i) += b.transpose();
    }
  }
  void add_rhs(size_t i, const Vec3& g) { rhs_.segment<3>(3 * static_cast<Eigen::Index>(i)) += g; }

  // Solves (H + damping I) x = rhs. Returns false when the matrix is not positive definite.
  bool solve(double damping, Eigen::VectorXd* x) const {
    using Sparse = Eigen::SparseMatrix<double>;
    std::vector<Eigen::Triplet<double>> triplets;
    triplets.reserve(n_ * static_cast<size_t>(band_) * 9);
    for (size_t i = 0; i < n_; ++i) {
      for (int o = 0; o < band_ && i + static_cast<size_t>(o) < n_; ++o) {
        const size_t j = i + static_cast<size_t>(o);
        const Mat3& b = blocks_[i * static_cast<size_t>(band_) + static_cast<size_t>(o)];
        for (int r = 0; r < 3; ++r) {
          for (int c = 0; c < 3; ++c) {
            const int row = static_cast<int>(3 * j) + c;  // lower triangle: (j, i) = b^T
            const int col = static_cast<int>(3 * i) + r;
            if (row < col) continue;
            double v = b(r, c);
            if (row == col) v += damping;
            triplets.emplace_back(row, col, v);
          }
        }
      }
    }
    const auto dim = 3 * static_cast<Eigen::Index>(n_);
    Sparse h(dim, dim);
    h.setFromTriplets(triplets.begin(), triplets.end());
    Eigen::SimplicialLDLT<Sparse, Eigen::Lower, Eigen::NaturalOrdering<int>> ldlt(h);
    if (ldlt.info() != Eigen::Success) return false;
    if ((ldlt.vectorD().array() <= 0.0).any()) return false;
    *x = ldlt.solve(rhs_);
    return ldlt.info() == Eigen::Success && x->allFinite();
  }

 private:
  Mat3& block(size_t i, size_t j) { return blocks_[i * static_cast<size_t>(band_) + (j - i)]; }

  size_t n_;
  int band_;
  std::vector<Mat3> blocks_;
  Eigen::VectorXd rhs_;
};

struct FitSample {
  size_t segment;
  BasisValues basis;
  Vec3 p;
  Mat3 R;
};

// Second-difference coefficients on control points j-1, j, j+1.
constexpr double kSecondDifference[3] = {1.0, -2.0, 1.0};

// Rotation fit cost: sum_i |Log(R_meas_i^T R(t_i))|^2 + w sum_j |d_j - d_{j-1}|^2.
double rotation_cost(const std::vector<FitSample>& samples, const std::vector<Quat>& q, int k,
                     double smoothing) {
  const size_t n = q.size();
  std::vector<Vec3> d(n - 1);
  for (size_t i = 0; i + 1 < n; ++i) d[i] = calib::so3_log(q[i].conjugate() * q[i + 1]);
  double cost = 0.0;
  for (const FitSample& s : samples) {
    Mat3 R = q[s.segment].toRotationMatrix();
    for (int j = 1; j < k; ++j) R = R * calib::so3_exp(s.basis.value[j] * d[s.segment + static_cast<size_t>(j) - 1]);
    cost += calib::so3_log(Mat3(s.R.transpose() * R)).squaredNorm();
  }
  for (size_t j = 1; j + 1 < n; ++j) cost += smoothing * (d[j] - d[j - 1]).squaredNorm();
  return cost;
}

}  // namespace

// ---------------------------------------------------------------- SinusoidTrajectory

bool SinusoidTrajectoryOptions::Validate(std::string* why) const {
  if (!std::isfinite(duration_s) || duration_s <= 0.0) return validation_failed(why, "duration_s must be finite and > 0");
  if (duration_s * kNsPerS > 9.0e18 ||
      t_begin_ns > std::numeric_limits<int64_t>::max() - static_cast<int64_t>(std::llround(duration_s * kNsPerS)))
    return validation_failed(why, "t_begin_ns + duration_s overflows int64 nanoseconds");
  if (!finite3(position_m) || !finite3(velocity_mps) || !finite3(amplitude_m) || !finite3(phase_rad))
    return validation_failed(why, "position, velocity, amplitude and phase must be finite");
  if (!valid_quaternion(q_w_b0)) return validation_failed(why, "q_w_b0 must be a finite, non-zero quaternion");
  if (!finite3(frequency_hz) || (frequency_hz.array() < 0.0).any())
    return validation_failed(why, "frequency_hz must be finite and >= 0");
  if (!finite3(angle_rate_radps) || !finite3(angle_amplitude_rad) || !finite3(angle_phase_rad))
    return validation_failed(why, "angle rates, amplitudes and phases must be finite");
  if (!finite3(angle_frequency_hz) || (angle_frequency_hz.array() < 0.0).any())
    return validation_failed(why, "angle_frequency_hz must be finite and >= 0");
  return true;
}

SinusoidTrajectory::SinusoidTrajectory(const SinusoidTrajectoryOptions& options) : o_(options) {
  std::string why;
  if (!o_.Validate(&why)) throw std::invalid_argument("SinusoidTrajectory: " + why);
  o_.q_w_b0.normalize();
}

int64_t SinusoidTrajectory::t_begin_ns() const { return o_.t_begin_ns; }

int64_t SinusoidTrajectory::t_end_ns() const {
  return o_.t_begin_ns + static_cast<int64_t>(std::llround(o_.duration_s * kNsPerS));
}

TrajectoryState SinusoidTrajectory::evaluate(int64_t t_ns) const {
  if (t_ns < t_begin_ns() || t_ns > t_end_ns())
    throw std::out_of_range("SinusoidTrajectory::evaluate: t_ns " + std::to_string(t_ns) + " outside [" +
                            std::to_string(t_begin_ns()) + ", " + std::to_string(t_end_ns()) + "]");
  const double t = static_cast<double>(t_ns - o_.t_begin_ns) / kNsPerS;
  TrajectoryState st;
  st.t_ns = t_ns;

  Vec3 p = o_.position_m + o_.velocity_mps * t;
  Vec3 v = o_.velocity_mps;
  Vec3 a = Vec3::Zero();
  for (int i = 0; i < 3; ++i) {
    const Wave w = wave(0.0, o_.amplitude_m[i], o_.frequency_hz[i], o_.phase_rad[i], t);
    p[i] += w.value;
    v[i] += w.first;
    a[i] += w.second;
  }

  // Angles in order (roll, pitch, yaw); R = R0 Rz(yaw) Ry(pitch) Rx(roll).
  Wave ang[3];
  for (int i = 0; i < 3; ++i)
    ang[i] = wave(o_.angle_rate_radps[i], o_.angle_amplitude_rad[i], o_.angle_frequency_hz[i], o_.angle_phase_rad[i], t);
  const Mat3 Rx = rot_x(ang[0].value);
  const Mat3 Ry = rot_y(ang[1].value);
  const Mat3 Rz = rot_z(ang[2].value);
  const Mat3 R = o_.q_w_b0.toRotationMatrix() * Rz * Ry * Rx;
  // R^T R' = hat(e_x) r' + Rx^T hat(e_y) Rx p' + (Ry Rx)^T hat(e_z) (Ry Rx) y', so
  //   omega_b = r' e_x + p' a + y' b,  a = Rx^T e_y,  b = Rx^T Ry^T e_z.
  // Differentiating with d/dt Rx^T = -r' hat(e_x) Rx^T and d/dt Ry^T = -p' hat(e_y) Ry^T:
  //   alpha_b = r'' e_x + p'' a + y'' b - p' r' e_x x a - y' r' e_x x b - y' p' Rx^T (e_y x Ry^T e_z).
  const Vec3 ex = Vec3::UnitX(), ey = Vec3::UnitY(), ez = Vec3::UnitZ();
  const Vec3 a_vec = Rx.transpose() * ey;
  const Vec3 ry_ez = Ry.transpose() * ez;
  const Vec3 b_vec = Rx.transpose() * ry_ez;
  const double r1 = ang[0].first, p1 = ang[1].first, y1 = ang[2].first;
  const double r2 = ang[0].second, p2 = ang[1].second, y2 = ang[2].second;
  st.omega_b = r1 * ex + p1 * a_vec + y1 * b_vec;
  st.alpha_b = r2 * ex + p2 * a_vec + y2 * b_vec - p1 * r1 * ex.cross(a_vec) - y1 * r1 * ex.cross(b_vec) -
               y1 * p1 * (Rx.transpose() * ey.cross(ry_ez));
  st.T_w_b = calib::SE3(R, p);
  st.v_w = v;
  st.a_w = a;
  return st;
}

std::string SinusoidTrajectory::describe() const {
  return "sinusoid trajectory, " + format_seconds(t_end_ns() - t_begin_ns()) + " s";
}

// ---------------------------------------------------------------- SplineTrajectory

bool RandomSplineOptions::Validate(std::string* why) const {
  if (!std::isfinite(duration_s) || duration_s <= 0.0) return validation_failed(why, "duration_s must be finite and > 0");
  if (order < kMinOrder || order > kMaxOrder) return validation_failed(why, "order must be 4, 5 or 6");
  if (!std::isfinite(knot_spacing_s) || knot_spacing_s < 1e-6)
    return validation_failed(why, "knot_spacing_s must be finite and >= 1e-6");
  if (duration_s / knot_spacing_s > 1e8) return validation_failed(why, "more than 1e8 knots (duration_s / knot_spacing_s)");
  if (duration_s * kNsPerS > 4.0e18 ||
      t_begin_ns > std::numeric_limits<int64_t>::max() / 2 - static_cast<int64_t>(std::llround(duration_s * kNsPerS)))
    return validation_failed(why, "t_begin_ns + duration_s overflows int64 nanoseconds");
  if (!finite3(position_m)) return validation_failed(why, "position_m must be finite");
  if (!valid_quaternion(q_w_b0)) return validation_failed(why, "q_w_b0 must be a finite, non-zero quaternion");
  if (!finite3(position_std_m) || (position_std_m.array() < 0.0).any())
    return validation_failed(why, "position_std_m must be finite and >= 0");
  if (!std::isfinite(rotation_std_rad) || rotation_std_rad < 0.0)
    return validation_failed(why, "rotation_std_rad must be finite and >= 0");
  return true;
}

bool SplineFitOptions::Validate(std::string* why) const {
  if (order < kMinOrder || order > kMaxOrder) return validation_failed(why, "order must be 4, 5 or 6");
  if (!std::isfinite(knot_spacing_s) || knot_spacing_s < 1e-6)
    return validation_failed(why, "knot_spacing_s must be finite and >= 1e-6");
  if (max_iterations < 0) return validation_failed(why, "max_iterations must be >= 0");
  if (!std::isfinite(smoothing) || smoothing < 0.0) return validation_failed(why, "smoothing must be finite and >= 0");
  return true;
}

SplineTrajectory::SplineTrajectory(int order, int64_t t0_ns, int64_t dt_ns, std::vector<Eigen::Quaterniond> rotations,
                                   std::vector<Eigen::Vector3d> positions)
    : order_(order), t0_ns_(t0_ns), dt_ns_(dt_ns), rotations_(std::move(rotations)), positions_(std::move(positions)) {
  if (order_ < kMinOrder || order_ > kMaxOrder)
    throw std::invalid_argument("SplineTrajectory: order " + std::to_string(order_) + " outside 4..6");
  if (dt_ns_ <= 0) throw std::invalid_argument("SplineTrajectory: knot spacing must be > 0 ns");
  if (rotations_.size() != positions_.size())
    throw std::invalid_argument("SplineTrajectory: " + std::to_string(rotations_.size()) + " rotations but " +
                                std::to_string(positions_.size()) + " positions");
  if (rotations_.size() < static_cast<size_t>(order_))
    throw std::invalid_argument("SplineTrajectory: " + std::to_string(rotations_.size()) +
                                " control points, order " + std::to_string(order_) + " needs at least as many");
  const auto segments = static_cast<int64_t>(rotations_.size()) - order_ + 1;
  if (segments > (std::numeric_limits<int64_t>::max() - std::max<int64_t>(t0_ns_, 0)) / dt_ns_)
    throw std::invalid_argument("SplineTrajectory: end of the valid range overflows int64 nanoseconds");
  for (size_t i = 0; i < rotations_.size(); ++i) {
    if (!valid_quaternion(rotations_[i]) || !positions_[i].allFinite())
      throw std::invalid_argument("SplineTrajectory: control point " + std::to_string(i) + " is not finite");
  }
  make_sign_continuous(&rotations_);
  deltas_.resize(rotations_.size() - 1);
  for (size_t i = 0; i + 1 < rotations_.size(); ++i)
    deltas_[i] = calib::so3_log(rotations_[i].conjugate() * rotations_[i + 1]);
}

int64_t SplineTrajectory::t_begin_ns() const { return t0_ns_; }

int64_t SplineTrajectory::t_end_ns() const {
  return t0_ns_ + (static_cast<int64_t>(positions_.size()) - order_ + 1) * dt_ns_;
}

TrajectoryState SplineTrajectory::evaluate(int64_t t_ns) const {
  if (t_ns < t_begin_ns() || t_ns > t_end_ns())
    throw std::out_of_range("SplineTrajectory::evaluate: t_ns " + std::to_string(t_ns) + " outside [" +
                            std::to_string(t_begin_ns()) + ", " + std::to_string(t_end_ns()) + "]");
  const size_t segments = positions_.size() - static_cast<size_t>(order_) + 1;
  const SplinePosition sp = locate(t_ns, t0_ns_, dt_ns_, segments);
  const BasisValues b = eval_basis(basis_for_order(order_), sp.u);
  const double dt = static_cast<double>(dt_ns_) / kNsPerS;
  const size_t s = sp.segment;

  Vec3 p = positions_[s];
  Vec3 v = Vec3::Zero();
  Vec3 a = Vec3::Zero();
  Quat q = rotations_[s];
  Vec3 w = Vec3::Zero();
  Vec3 w_dot = Vec3::Zero();
  for (int j = 1; j < order_; ++j) {
    const size_t i = s + static_cast<size_t>(j);
    const Vec3 dp = positions_[i] - positions_[i - 1];
    p += b.value[j] * dp;
    v += b.d1[j] * dp;
    a += b.d2[j] * dp;

    const Vec3& d = deltas_[i - 1];
    const Quat qa = calib::so3_exp_quat(b.value[j] * d);
    q = q * qa;
    const Mat3 At = qa.toRotationMatrix().transpose();
    const Vec3 w_rot = At * w;
    w_dot = At * w_dot + b.d2[j] * d + b.d1[j] * w_rot.cross(d);
    w = w_rot + b.d1[j] * d;
  }
  TrajectoryState st;
  st.t_ns = t_ns;
  st.T_w_b = calib::SE3(q, p);
  st.v_w = v / dt;
  st.a_w = a / (dt * dt);
  st.omega_b = w / dt;
  st.alpha_b = w_dot / (dt * dt);
  return st;
}

std::string SplineTrajectory::describe() const {
  static const char* const kNames[] = {"", "", "", "", "cubic", "quartic", "quintic"};
  return std::string(kNames[order_]) + " B-spline (order " + std::to_string(order_) + "), " +
         std::to_string(positions_.size()) + " control points at " + format_seconds(dt_ns_ * 1000) + " ms, " +
         format_seconds(t_end_ns() - t_begin_ns()) + " s";
}

SplineTrajectory SplineTrajectory::random(const RandomSplineOptions& options) {
  std::string why;
  if (!options.Validate(&why)) throw std::invalid_argument("SplineTrajectory::random: " + why);
  const int64_t dt_ns = std::max<int64_t>(1, std::llround(options.knot_spacing_s * kNsPerS));
  const int64_t duration_ns = std::llround(options.duration_s * kNsPerS);
  const int64_t segments = std::max<int64_t>(1, (duration_ns + dt_ns - 1) / dt_ns);
  const size_t n = static_cast<size_t>(segments) + static_cast<size_t>(options.order) - 1;
  const Quat q0 = options.q_w_b0.normalized();
  internal::NormalSampler rng(options.seed);
  std::vector<Quat> rotations(n);
  std::vector<Vec3> positions(n);
  for (size_t i = 0; i < n; ++i) {
    positions[i] = options.position_m + options.position_std_m.cwiseProduct(rng.next3());
    rotations[i] = q0 * calib::so3_exp_quat(options.rotation_std_rad * rng.next3());
  }
  return SplineTrajectory(options.order, options.t_begin_ns, dt_ns, std::move(rotations), std::move(positions));
}

SplineTrajectory SplineTrajectory::fit(const Trajectory& samples, const SplineFitOptions& options,
                                       SplineFitReport* report) {
  std::string why;
  if (!options.Validate(&why)) throw std::invalid_argument("SplineTrajectory::fit: " + why);
  if (samples.size() < 2) throw std::invalid_argument("SplineTrajectory::fit: needs at least 2 samples");
  const int k = options.order;
  const int64_t dt_ns = std::max<int64_t>(1, std::llround(options.knot_spacing_s * kNsPerS));
  const int64_t t0 = samples.t_begin_ns();
  const int64_t span = samples.t_end_ns() - t0;
  const int64_t segments64 = std::max<int64_t>(1, (span + dt_ns - 1) / dt_ns);
  const auto segments = static_cast<size_t>(segments64);
  const size_t n = segments + static_cast<size_t>(k) - 1;
  // lambda * integral |c''|^2 dt over the spline ~= lambda / dt^3 * sum_j |c_{j-1} - 2 c_j + c_{j+1}|^2.
  const double dt_s = static_cast<double>(dt_ns) / kNsPerS;
  const double w = options.smoothing / (dt_s * dt_s * dt_s);
  // Without smoothing every control point must be pinned by samples; with it, the second-difference
  // penalty bridges control points that no sample reaches (gaps, knots finer than the samples).
  if (w == 0.0 && samples.size() < n)
    throw std::invalid_argument("SplineTrajectory::fit: " + std::to_string(samples.size()) + " samples cannot constrain " +
                                std::to_string(n) + " control points (order " + std::to_string(k) +
                                ", knot spacing " + format_seconds(dt_ns) + " s); use a larger knot spacing");
  const CumulativeBasis& basis = basis_for_order(k);

  std::vector<FitSample> data;
  data.reserve(samples.size());
  for (const StampedPose& pose : samples) {
    const SplinePosition sp = locate(pose.t_ns, t0, dt_ns, segments);
    data.push_back({sp.segment, eval_basis(basis, sp.u), pose.T_w_b.translation, pose.T_w_b.rotation_matrix()});
  }

  // Positions: linear least squares sum_i |sum_m B_m(u_i) c_{s_i+m} - p_i|^2 + w |second differences|^2.
  std::vector<Vec3> positions(n);
  {
    BlockBandSystem sys(n, k);
    for (const FitSample& s : data) {
      for (int a = 0; a < k; ++a) {
        const double ba = s.basis.value[a] - s.basis.value[a + 1];
        sys.add_rhs(s.segment + static_cast<size_t>(a), ba * s.p);
        for (int c = a; c < k; ++c) {
          const double bc = s.basis.value[c] - s.basis.value[c + 1];
          sys.add(s.segment + static_cast<size_t>(a), s.segment + static_cast<size_t>(c), ba * bc * Mat3::Identity());
        }
      }
    }
    for (size_t j = 1; j + 1 < n; ++j)
      for (int a = 0; a < 3; ++a)
        for (int c = a; c < 3; ++c)
          sys.add(j - 1 + static_cast<size_t>(a), j - 1 + static_cast<size_t>(c),
                  w * kSecondDifference[a] * kSecondDifference[c] * Mat3::Identity());
    Eigen::VectorXd x;
    if (!sys.solve(0.0, &x))
      throw std::invalid_argument("SplineTrajectory::fit: control points not constrained by the samples (gaps longer "
                                  "than the spline support); raise smoothing or the knot spacing");
    for (size_t i = 0; i < n; ++i) positions[i] = x.segment<3>(3 * static_cast<Eigen::Index>(i));
  }

  // Rotations: start from the samples interpolated (slerp) at the centre of each control point's
  // support, t0 + (i - (k-2)/2) dt, then Gauss-Newton (Levenberg-Marquardt damped) on right
  // perturbations R_i <- R_i Exp(delta_i).
  std::vector<Quat> q(n);
  for (size_t i = 0; i < n; ++i) {
    const int64_t tc2 = 2 * t0 + (2 * static_cast<int64_t>(i) - (k - 2)) * dt_ns;  // twice the centre time
    const int64_t tc = std::clamp<int64_t>(tc2 / 2, samples.t_begin_ns(), samples.t_end_ns());
    q[i] = samples.interpolate(tc)->rotation;
  }
  make_sign_continuous(&q);

  double cost = rotation_cost(data, q, k, w);
  double damping = 1e-9;
  int iterations = 0;
  std::vector<Vec3> d(n - 1);
  std::vector<Mat3> jr_inv(n - 1), jl_inv(n - 1);
  for (int it = 0; it < options.max_iterations; ++it) {
    ++iterations;
    for (size_t i = 0; i + 1 < n; ++i) {
      d[i] = calib::so3_log(q[i].conjugate() * q[i + 1]);
      jr_inv[i] = calib::so3_right_jacobian_inv(d[i]);
      jl_inv[i] = calib::so3_left_jacobian_inv(d[i]);
    }
    BlockBandSystem sys(n, k);
    Mat3 A[kMaxOrder], P[kMaxOrder], Jlam[kMaxOrder], J[kMaxOrder];
    for (const FitSample& s : data) {
      // R = R_s A_1 ... A_{k-1}; P_j = A_{j+1} ... A_{k-1}.
      for (int j = 1; j < k; ++j) {
        const Vec3 phi = s.basis.value[j] * d[s.segment + static_cast<size_t>(j) - 1];
        A[j] = calib::so3_exp(phi);
        Jlam[j] = s.basis.value[j] * calib::so3_right_jacobian(phi);
      }
      P[k - 1].setIdentity();
      for (int j = k - 1; j >= 1; --j) P[j - 1] = A[j] * P[j];
      const Mat3 R = q[s.segment].toRotationMatrix() * P[0];
      const Vec3 r = calib::so3_log(Mat3(s.R.transpose() * R));
      const Mat3 jres = calib::so3_right_jacobian_inv(r);
      // Perturbing d_j by e moves R to R Exp(P_j^T lambda_j Jr(lambda_j d_j) e); d_j = Log(R_{j-1}^T R_j)
      // moves by Jr^-1(d_j) delta_j - Jl^-1(d_j) delta_{j-1}; R_s Exp(delta_0) moves R by P_0^T delta_0.
      for (int m = 0; m < k; ++m) {
        Mat3 jm = Mat3::Zero();
        if (m == 0) jm += P[0].transpose();
        if (m >= 1) jm += P[m].transpose() * Jlam[m] * jr_inv[s.segment + static_cast<size_t>(m) - 1];
        if (m <= k - 2) jm -= P[m + 1].transpose() * Jlam[m + 1] * jl_inv[s.segment + static_cast<size_t>(m)];
        J[m] = jres * jm;
      }
      for (int a = 0; a < k; ++a) {
        sys.add_rhs(s.segment + static_cast<size_t>(a), -J[a].transpose() * r);
        for (int c = a; c < k; ++c)
          sys.add(s.segment + static_cast<size_t>(a), s.segment + static_cast<size_t>(c), J[a].transpose() * J[c]);
      }
    }
    // Smoothing residual e_j = d_j - d_{j-1} on control points j-1, j, j+1.
    for (size_t j = 1; j + 1 < n; ++j) {
      const Vec3 e = d[j] - d[j - 1];
      const Mat3 Js[3] = {jl_inv[j - 1], -jr_inv[j - 1] - jl_inv[j], jr_inv[j]};
      for (int a = 0; a < 3; ++a) {
        sys.add_rhs(j - 1 + static_cast<size_t>(a), -w * Js[a].transpose() * e);
        for (int c = a; c < 3; ++c)
          sys.add(j - 1 + static_cast<size_t>(a), j - 1 + static_cast<size_t>(c), w * Js[a].transpose() * Js[c]);
      }
    }
    bool accepted = false;
    double step_max = 0.0;
    for (int attempt = 0; attempt < 10 && !accepted; ++attempt) {
      Eigen::VectorXd delta;
      if (!sys.solve(damping, &delta)) {
        damping = std::max(damping * 100.0, 1e-6);
        continue;
      }
      std::vector<Quat> candidate(q);
      step_max = 0.0;
      for (size_t i = 0; i < n; ++i) {
        const Vec3 di = delta.segment<3>(3 * static_cast<Eigen::Index>(i));
        step_max = std::max(step_max, di.norm());
        candidate[i] = (q[i] * calib::so3_exp_quat(di)).normalized();
      }
      const double new_cost = rotation_cost(data, candidate, k, w);
      if (new_cost <= cost) {
        q.swap(candidate);
        cost = new_cost;
        damping = std::max(damping * 0.1, 1e-12);
        accepted = true;
      } else {
        damping *= 100.0;
      }
    }
    if (!accepted || step_max < 1e-10) break;
  }

  SplineTrajectory spline(k, t0, dt_ns, std::move(q), std::move(positions));
  if (report) {
    *report = SplineFitReport();
    report->samples = samples.size();
    report->control_points = n;
    report->iterations = iterations;
    double sum_p = 0.0, sum_r = 0.0;
    for (const StampedPose& pose : samples) {
      const TrajectoryState st = spline.evaluate(pose.t_ns);
      const double ep = (st.T_w_b.translation - pose.T_w_b.translation).norm();
      const double er = calib::so3_log(pose.T_w_b.rotation.conjugate() * st.T_w_b.rotation).norm() * 180.0 / M_PI;
      sum_p += ep * ep;
      sum_r += er * er;
      report->position_max_m = std::max(report->position_max_m, ep);
      report->rotation_max_deg = std::max(report->rotation_max_deg, er);
    }
    report->position_rms_m = std::sqrt(sum_p / static_cast<double>(samples.size()));
    report->rotation_rms_deg = std::sqrt(sum_r / static_cast<double>(samples.size()));
  }
  return spline;
}

Trajectory sample_trajectory(const ContinuousTrajectory& trajectory, int64_t period_ns) {
  if (period_ns <= 0) throw std::invalid_argument("sample_trajectory: period_ns must be > 0");
  const int64_t t_begin = trajectory.t_begin_ns();
  const int64_t t_end = trajectory.t_end_ns();
  std::vector<StampedPose> poses;
  poses.reserve(static_cast<size_t>((t_end - t_begin) / period_ns) + 2);
  int64_t t = t_begin;
  for (;;) {
    poses.push_back({t, trajectory.evaluate(t).T_w_b});
    if (t_end - t < period_ns) break;
    t += period_ns;
  }
  if (poses.back().t_ns != t_end) poses.push_back({t_end, trajectory.evaluate(t_end).T_w_b});
  return Trajectory(std::move(poses));
}

}  // namespace evio::simulator
