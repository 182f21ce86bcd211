#include "evio/backend/motion_model_selection.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/SVD>

namespace evio::backend {
namespace {

using Eigen::Matrix3d;
using Eigen::Vector2d;
using Eigen::Vector3d;

constexpr double kR = 4.0;         // dimension of a two-view correspondence
constexpr double kLambda3 = 2.0;   // GRIC's outlier cap factor
constexpr double kAicPenaltyPerParameter = 2.0;
constexpr int kMinCorrespondences = 6;

Matrix3d skew(const Vector3d& v) {
  Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

Matrix3d exp_so3(const Vector3d& w) {
  const double a = w.norm();
  if (a < 1e-12) return Matrix3d::Identity() + skew(w);
  return Eigen::AngleAxisd(a, w / a).toRotationMatrix();
}

struct Data {
  const std::vector<Vector3d>& b0;
  const std::vector<Vector3d>& b1;
  double f, inv_s2;
  std::vector<Vector3d> x0, x1;  // b0 / b0.z and b1 / b1.z (normalised image points)
};

// S/R residual: |r|^2 = e^2 (px^2), the 4-D distance to {(x, pi(R x))}.
bool rotation_residual(const Matrix3d& R, const Vector3d& b0, const Vector3d& b1, double f, Vector2d* r,
                       Eigen::Matrix<double, 2, 3>* J) {
  const Vector3d p = R * b0;
  if (p.z() < 1e-9) return false;
  const double s = f / std::sqrt(2.0);
  *r = s * (p.head<2>() / p.z() - b1.head<2>() / b1.z());
  if (J) {
    Eigen::Matrix<double, 2, 3> dpi;
    dpi << 1 / p.z(), 0, -p.x() / (p.z() * p.z()), 0, 1 / p.z(), -p.y() / (p.z() * p.z());
    *J = s * dpi * (-skew(p));  // d/d(delta) of Exp(delta) R b0
  }
  return true;
}

double rotation_cost(const Matrix3d& R, const Data& d, double cap) {
  double c = 0;
  Vector2d r;
  for (size_t i = 0; i < d.b0.size(); ++i) {
    c += rotation_residual(R, d.b0[i], d.b1[i], d.f, &r, nullptr) ? std::min(r.squaredNorm() * d.inv_s2, cap) : cap;
  }
  return c;
}

// Levenberg-Marquardt on the inliers of the capped cost, accepting only steps that lower it.
Matrix3d refine_rotation(Matrix3d R, const Data& d, double cap, double* cost) {
  *cost = rotation_cost(R, d, cap);
  double mu = 1e-3;
  for (int it = 0; it < 15; ++it) {
    Matrix3d H = Matrix3d::Zero();
    Vector3d g = Vector3d::Zero();
    Vector2d r;
    Eigen::Matrix<double, 2, 3> J;
    for (size_t i = 0; i < d.b0.size(); ++i) {
      if (!rotation_residual(R, d.b0[i], d.b1[i], d.f, &r, &J) || r.squaredNorm() * d.inv_s2 >= cap) continue;
      H += J.transpose() * J;
      g += J.transpose() * r;
    }
    const Vector3d delta = -(H + mu * Matrix3d(H.diagonal().asDiagonal()) + 1e-12 * Matrix3d::Identity()).ldlt().solve(g);
    if (!delta.allFinite()) break;
    const Matrix3d Rn = exp_so3(delta) * R;
    const double cn = rotation_cost(Rn, d, cap);
    if (cn < *cost) {
      R = Rn;
      const bool converged = *cost - cn < 1e-9 * std::max(1.0, *cost) || delta.norm() < 1e-12;
      *cost = cn;
      mu = std::max(mu / 10, 1e-9);
      if (converged) break;
    } else {
      mu *= 10;
      if (mu > 1e6) break;
    }
  }
  return R;
}

// Sampson distance (px, signed) of the epipolar constraint x1^T E x0 = 0, E = [t]x R, for the
// normalised image points x0 = b0 / b0.z, x1 = b1 / b1.z.
double sampson(const Matrix3d& E, const Vector3d& x0, const Vector3d& x1, double f) {
  const Vector3d Ex0 = E * x0, Etx1 = E.transpose() * x1;
  const double den = Ex0.head<2>().squaredNorm() + Etx1.head<2>().squaredNorm();
  if (!(den > 1e-24)) return 0.0;
  return f * x1.dot(Ex0) / std::sqrt(den);
}

Matrix3d essential(const Matrix3d& R, const Vector3d& t) { return skew(t) * R; }

double general_cost(const Matrix3d& R, const Vector3d& t, const Data& d, double cap) {
  const Matrix3d E = essential(R, t);
  double c = 0;
  for (size_t i = 0; i < d.x0.size(); ++i) {
    const double e = sampson(E, d.x0[i], d.x1[i], d.f);
    c += std::min(e * e * d.inv_s2, cap);
  }
  return c;
}

// Basis of the tangent plane of the unit sphere at t.
Eigen::Matrix<double, 3, 2> sphere_basis(const Vector3d& t) {
  const Vector3d a = std::abs(t.x()) < 0.9 ? Vector3d::UnitX() : Vector3d::UnitY();
  const Vector3d u = t.cross(a).normalized();
  Eigen::Matrix<double, 3, 2> B;
  B << u, t.cross(u);
  return B;
}

// Translation direction from the linear epipolar constraint (R b0 x b1)^T t = 0 (least squares).
Vector3d linear_translation(const Matrix3d& R, const Data& d) {
  Matrix3d A = Matrix3d::Zero();
  for (size_t i = 0; i < d.b0.size(); ++i) {
    const Vector3d a = (R * d.b0[i].normalized()).cross(d.b1[i].normalized());
    A += a * a.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Matrix3d> es(A);
  return es.eigenvectors().col(0).normalized();
}

// Levenberg-Marquardt on (R, t) over the inliers of the capped Sampson cost, accepting only steps
// that lower it; numeric Jacobian.
void refine_general(Matrix3d* R, Vector3d* t, const Data& d, double cap, double* cost) {
  *cost = general_cost(*R, *t, d, cap);
  double mu = 1e-3;
  const double h = 1e-7;
  auto apply = [](const Matrix3d& R0, const Vector3d& t0, const Eigen::Matrix<double, 5, 1>& x, Matrix3d* Rn, Vector3d* tn) {
    *Rn = exp_so3(x.head<3>()) * R0;
    *tn = (t0 + sphere_basis(t0) * x.tail<2>()).normalized();
  };
  for (int it = 0; it < 15; ++it) {
    Eigen::Matrix<double, 5, 5> H = Eigen::Matrix<double, 5, 5>::Zero();
    Eigen::Matrix<double, 5, 1> g = Eigen::Matrix<double, 5, 1>::Zero();
    // The essential matrices of the central differences, once per iteration.
    Matrix3d Ep[5], Em[5];
    for (int k = 0; k < 5; ++k) {
      Eigen::Matrix<double, 5, 1> x = Eigen::Matrix<double, 5, 1>::Zero();
      x(k) = h;
      Matrix3d Rk;
      Vector3d tk;
      apply(*R, *t, x, &Rk, &tk);
      Ep[k] = essential(Rk, tk);
      apply(*R, *t, -x, &Rk, &tk);
      Em[k] = essential(Rk, tk);
    }
    const Matrix3d E = essential(*R, *t);
    for (size_t i = 0; i < d.x0.size(); ++i) {
      const Vector3d& x0 = d.x0[i];
      const Vector3d& x1 = d.x1[i];
      const double e = sampson(E, x0, x1, d.f);
      if (e * e * d.inv_s2 >= cap) continue;
      Eigen::Matrix<double, 1, 5> J;
      for (int k = 0; k < 5; ++k) {
        J(k) = (sampson(Ep[k], x0, x1, d.f) - sampson(Em[k], x0, x1, d.f)) / (2 * h);
      }
      H += J.transpose() * J;
      g += J.transpose() * e;
    }
    Eigen::Matrix<double, 5, 5> A = H;
    A.diagonal() += mu * H.diagonal() + Eigen::Matrix<double, 5, 1>::Constant(1e-12);
    const Eigen::Matrix<double, 5, 1> x = -A.ldlt().solve(g);
    if (!x.allFinite()) break;
    Matrix3d Rn;
    Vector3d tn;
    apply(*R, *t, x, &Rn, &tn);
    const double cn = general_cost(Rn, tn, d, cap);
    if (cn < *cost) {
      const bool converged = *cost - cn < 1e-9 * std::max(1.0, *cost) || x.norm() < 1e-12;
      *R = Rn;
      *t = tn;
      *cost = cn;
      mu = std::max(mu / 10, 1e-9);
      if (converged) break;
    } else {
      mu *= 10;
      if (mu > 1e6) break;
    }
  }
}

}  // namespace

const char* two_view_model_name(TwoViewModel m) {
  switch (m) {
    case TwoViewModel::kStatic:
      return "static";
    case TwoViewModel::kRotation:
      return "rotation";
    case TwoViewModel::kGeneral:
      return "general";
    default:
      return "none";
  }
}

TwoViewGric two_view_gric(const std::vector<Vector3d>& b0, const std::vector<Vector3d>& b1, const Matrix3d& R_prior,
                          const Vector3d& t_prior, double focal_px, double sigma_px, int imu_dof, double imu_chi2) {
  TwoViewGric out;
  // Only correspondences in front of both cameras.
  std::vector<Vector3d> c0, c1;
  for (size_t i = 0; i < std::min(b0.size(), b1.size()); ++i) {
    if (b0[i].z() > 1e-6 && b1[i].z() > 1e-6 && b0[i].allFinite() && b1[i].allFinite()) {
      c0.push_back(b0[i]);
      c1.push_back(b1[i]);
    }
  }
  out.n = static_cast<int>(c0.size());
  if (out.n < kMinCorrespondences || !(focal_px > 0) || !(sigma_px > 0)) return out;
  Data d{c0, c1, focal_px, 1.0 / (sigma_px * sigma_px), {}, {}};
  d.x0.reserve(c0.size());
  d.x1.reserve(c1.size());
  for (size_t i = 0; i < c0.size(); ++i) {
    d.x0.push_back(c0[i] / c0[i].z());
    d.x1.push_back(c1[i] / c1[i].z());
  }
  const double n = out.n;
  const double lambda1 = std::log(kR), lambda2 = std::log(kR * n);
  const double cap2 = kLambda3 * (kR - 2), cap3 = kLambda3 * (kR - 3);

  // S: identity.
  const double cost_s = rotation_cost(Matrix3d::Identity(), d, cap2);

  // R: Kabsch on the unit bearings and the prior, each refined; the better one.
  Matrix3d M = Matrix3d::Zero();
  for (size_t i = 0; i < c0.size(); ++i) M += c1[i].normalized() * c0[i].normalized().transpose();
  const Eigen::JacobiSVD<Matrix3d> svd(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Matrix3d D = Matrix3d::Identity();
  D(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1 : 1;
  const Matrix3d R_kabsch = svd.matrixU() * D * svd.matrixV().transpose();
  double cost_r = std::numeric_limits<double>::infinity();
  for (const Matrix3d& R0 : {R_kabsch, R_prior}) {
    if (!R0.allFinite()) continue;
    double c = 0;
    const Matrix3d R = refine_rotation(R0, d, cap2, &c);
    if (c < cost_r) {
      cost_r = c;
      out.R_c1_c0 = R;
    }
  }

  // G: from the rotation fit and the prior, translation from the linear constraint, the prior or a
  // camera axis; the lowest refined cost.
  double cost_g = std::numeric_limits<double>::infinity();
  std::vector<std::pair<Matrix3d, Vector3d>> starts;
  for (const Matrix3d& R0 : {out.R_c1_c0, R_prior}) {
    if (!R0.allFinite()) continue;
    starts.emplace_back(R0, linear_translation(R0, d));
    if (t_prior.allFinite() && t_prior.norm() > 1e-9) starts.emplace_back(R0, t_prior.normalized());
    // The camera axes too: a sideways translation is nearly confused with a rotation over a
    // narrow field of view (bas-relief ambiguity), where the linear solution given the rotation
    // fit starts in the wrong basin.
    for (int k = 0; k < 3; ++k) starts.emplace_back(R0, Vector3d::Unit(k));
  }
  for (auto [R, t] : starts) {
    double c = 0;
    refine_general(&R, &t, d, cap3, &c);
    if (c < cost_g) {
      cost_g = c;
      out.t_c1 = t;
    }
  }

  out.gric_static = cost_s + lambda1 * 2 * n;
  out.gric_rotation = cost_r + lambda1 * 2 * n + lambda2 * 3;
  out.gric_general = cost_g + lambda1 * 3 * n + lambda2 * 5;
  out.image_best = out.gric_general < std::min(out.gric_static, out.gric_rotation)
                       ? TwoViewModel::kGeneral
                       : (out.gric_rotation < out.gric_static ? TwoViewModel::kRotation : TwoViewModel::kStatic);
  if (imu_dof > 0) {
    out.imu_dof = imu_dof;
    out.imu_chi2 = std::max(0.0, imu_chi2);
    out.gric_static += out.imu_chi2;
    out.gric_rotation += out.imu_chi2;
    out.gric_general += kAicPenaltyPerParameter * imu_dof;
  }
  out.best = TwoViewModel::kStatic;
  double best = out.gric_static;
  if (out.gric_rotation < best) {
    best = out.gric_rotation;
    out.best = TwoViewModel::kRotation;
  }
  if (out.gric_general < best) out.best = TwoViewModel::kGeneral;
  return out;
}

namespace {

// P(a, x), the regularised lower incomplete gamma function: series for x < a + 1, else the
// continued fraction of Q (Numerical Recipes' gser/gcf forms).
double regularised_gamma_p(double a, double x) {
  if (x <= 0) return 0.0;
  const double log_prefactor = -x + a * std::log(x) - std::lgamma(a);
  if (x < a + 1) {
    double term = 1.0 / a, sum = term;
    for (int n = 1; n < 1000 && std::abs(term) > std::abs(sum) * 1e-15; ++n) {
      term *= x / (a + n);
      sum += term;
    }
    return sum * std::exp(log_prefactor);
  }
  double b = x + 1 - a, c = 1e300, d = 1 / b, h = d;
  for (int i = 1; i < 1000; ++i) {
    const double an = -i * (i - a);
    b += 2;
    d = an * d + b;
    if (std::abs(d) < 1e-300) d = 1e-300;
    c = b + an / c;
    if (std::abs(c) < 1e-300) c = 1e-300;
    d = 1 / d;
    const double del = d * c;
    h *= del;
    if (std::abs(del - 1) < 1e-15) break;
  }
  return 1.0 - std::exp(log_prefactor) * h;
}

}  // namespace

double chi2_upper_quantile(int dof, double p) {
  if (dof < 1 || !(p > 0 && p < 1)) throw std::invalid_argument("chi2_upper_quantile: dof >= 1 and p in (0, 1)");
  double lo = 0, hi = 1;
  while (1.0 - regularised_gamma_p(0.5 * dof, 0.5 * hi) > p) hi *= 2;
  for (int i = 0; i < 200 && hi - lo > 1e-10 * hi; ++i) {
    const double mid = 0.5 * (lo + hi);
    (1.0 - regularised_gamma_p(0.5 * dof, 0.5 * mid) > p ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

}  // namespace evio::backend
