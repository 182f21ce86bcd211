// Rotational CMax-SLAM back-end: see cmax_slam.h for the model.
#include "evio/backend/cmax_slam.h"

#include <algorithm>
#include <climits>
#include <limits>
#include <memory>
#include <cmath>
#include <stdexcept>

#include <Eigen/Eigenvalues>
#include <ceres/ceres.h>

#include "evio/calib/equirectangular.h"
#include "evio/calib/geometry.h"

namespace evio::backend {

bool CmaxSlamOptions::Validate(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (knot_spacing_ns <= 0) return fail("knot_spacing_ns must be > 0");
  if (window_knots < 2) return fail("window_knots must be >= 2");
  if (step_knots < 1 || step_knots > window_knots) return fail("step_knots must be in [1, window_knots]");
  if (panorama_width < 16 || panorama_height < 8) return fail("the panorama must be at least 16 x 8 px");
  if (!(blur_sigma_px >= 0) || blur_sigma_px > 10) return fail("blur_sigma_px must be in [0, 10]");
  if (!(coarse_blur_sigma_px >= 0) || coarse_blur_sigma_px > 10) return fail("coarse_blur_sigma_px must be in [0, 10]");
  if (max_window_events < 0) return fail("max_window_events must be >= 0");
  if (max_iterations < 1) return fail("max_iterations must be >= 1");
  if (!(map_weight >= 0) || !std::isfinite(map_weight)) return fail("map_weight must be >= 0");
  if (!(box_margin_px >= 0) || !std::isfinite(box_margin_px)) return fail("box_margin_px must be >= 0");
  if (!(prior_weight >= 0) || !std::isfinite(prior_weight)) return fail("prior_weight must be >= 0");
  if (!(rate_prior_weight >= 0) || !std::isfinite(rate_prior_weight)) return fail("rate_prior_weight must be >= 0");
  if (global_iterations < 0) return fail("global_iterations must be >= 0");
  if (!(global_rate_weight >= 0) || !std::isfinite(global_rate_weight)) return fail("global_rate_weight must be >= 0");
  if (global_max_events < 1000) return fail("global_max_events must be >= 1000");
  if (!(min_segment_events >= 0) || !std::isfinite(min_segment_events)) return fail("min_segment_events must be >= 0");
  return true;
}

namespace {

using Mat3 = Eigen::Matrix3d;
using Vec3 = Eigen::Vector3d;

// Normalised Gaussian taps, radius ceil(3 sigma); {1} for sigma 0.
std::vector<double> gaussian_taps(double sigma) {
  if (sigma <= 0) return {1.0};
  const int r = static_cast<int>(std::ceil(3 * sigma));
  std::vector<double> k(2 * r + 1);
  double s = 0;
  for (int i = -r; i <= r; ++i) s += k[i + r] = std::exp(-0.5 * i * i / (sigma * sigma));
  for (double& v : k) v /= s;
  return k;
}

// Separable convolution with zero padding, or circular along x when wrap_x (the full panorama's
// longitude); either way a symmetric operator: it is its own adjoint.
void blur(std::vector<double>* img, int w, int h, const std::vector<double>& k, std::vector<double>* tmp, bool wrap_x = false) {
  const int r = static_cast<int>(k.size()) / 2;
  if (r == 0) return;
  std::vector<double>& a = *img;
  std::vector<double>& b = *tmp;
  b.assign(a.size(), 0.0);
  for (int y = 0; y < h; ++y) {
    const double* row = a.data() + static_cast<size_t>(y) * w;
    double* out = b.data() + static_cast<size_t>(y) * w;
    for (int x = 0; x < w; ++x) {
      double s = 0;
      if (wrap_x && (x < r || x + r >= w)) {
        for (int i = -r; i <= r; ++i) s += k[i + r] * row[((x + i) % w + w) % w];
      } else {
        const int i0 = std::max(-r, -x), i1 = std::min(r, w - 1 - x);
        for (int i = i0; i <= i1; ++i) s += k[i + r] * row[x + i];
      }
      out[x] = s;
    }
  }
  for (int y = 0; y < h; ++y) {
    double* out = a.data() + static_cast<size_t>(y) * w;
    const int i0 = std::max(-r, -y), i1 = std::min(r, h - 1 - y);
    for (int x = 0; x < w; ++x) out[x] = 0;
    for (int i = i0; i <= i1; ++i) {
      const double c = k[i + r];
      const double* row = b.data() + static_cast<size_t>(y + i) * w;
      for (int x = 0; x < w; ++x) out[x] += c * row[x];
    }
  }
}

// A spline segment between consecutive knots R_i, R_{i+1}.
struct Seg {
  Vec3 w;     // Log(R_i^T R_{i+1})
  Mat3 E;     // Exp(w)
  Mat3 Jinv;  // Jr^-1(w)
};
Seg make_seg(const Mat3& Ra, const Mat3& Rb) {
  Seg s;
  s.w = calib::so3_log(Mat3(Ra.transpose() * Rb));
  s.E = calib::so3_exp(s.w);
  s.Jinv = calib::so3_right_jacobian_inv(s.w);
  return s;
}

// The spline's rotation at u in [0, 1] of a time segment whose order control knots start at R0,
// with seg[0 .. order - 2] the segments between them:
//   linear (order 2):  R(u) = R0 Exp(u w0)
//   cubic (order 4), the cumulative uniform B-spline:
//     R(u) = R0 Exp(l1 w0) Exp(l2 w1) Exp(l3 w2),  l1 = (5 + 3u - 3u^2 + u^3) / 6,
//     l2 = (1 + 3u + 3u^2 - 2u^3) / 6,  l3 = u^3 / 6.
// D (optional, order matrices): the right perturbation phi of R(u) per right perturbation delta_c
// of control knot c (dphi = sum_c D[c] ddelta_c), from dw_i = Jr^-1(w_i) (delta_{i+1} - E_i^T delta_i)
// and Exp(l (w + dw)) = Exp(l w) Exp(l Jr(l w) dw):
//   M_j = (A_{j+1} ... A_last)^T l_j Jr(l_j w_{j-1}) Jr^-1(w_{j-1}),  A_j = Exp(l_j w_{j-1}),
//   D[0] = (A_1 ... A_last)^T - M_1 E_0^T,  D[c] = M_c - M_{c+1} E_c^T,  D[last] = M_last.
Mat3 spline_rotation(int order, const Mat3& R0, const Seg* seg, double u, Mat3* D) {
  if (order == 2) {
    const Vec3 uw = u * seg[0].w;
    const Mat3 A = calib::so3_exp(uw);
    if (D) {
      D[1] = u * calib::so3_right_jacobian(uw) * seg[0].Jinv;
      D[0] = A.transpose() - D[1] * seg[0].E.transpose();
    }
    return R0 * A;
  }
  const double u2 = u * u, u3 = u2 * u;
  const double l[3] = {(5 + 3 * u - 3 * u2 + u3) / 6, (1 + 3 * u + 3 * u2 - 2 * u3) / 6, u3 / 6};
  Mat3 A[3];
  for (int j = 0; j < 3; ++j) A[j] = calib::so3_exp(l[j] * seg[j].w);
  if (D) {
    Mat3 Q = Mat3::Identity();  // (A_{j+1} ... A_3)^T
    Mat3 M[3];
    for (int j = 2; j >= 0; --j) {
      M[j] = Q * l[j] * calib::so3_right_jacobian(Vec3(l[j] * seg[j].w)) * seg[j].Jinv;
      Q = Q * A[j].transpose();
    }
    D[0] = Q - M[0] * seg[0].E.transpose();
    D[1] = M[0] - M[1] * seg[1].E.transpose();
    D[2] = M[1] - M[2] * seg[2].E.transpose();
    D[3] = M[2];
  }
  return R0 * A[0] * A[1] * A[2];
}

// The spline's basis weights of a time segment's order control knots at u (they sum to 1): the
// share of an event at u in each knot.
void spline_weights(int order, double u, double* b) {
  if (order == 2) {
    b[0] = 1 - u;
    b[1] = u;
    return;
  }
  const double u2 = u * u, u3 = u2 * u;
  b[0] = (1 - u) * (1 - u) * (1 - u) / 6;
  b[1] = (3 * u3 - 6 * u2 + 4) / 6;
  b[2] = (-3 * u3 + 3 * u2 + 3 * u + 1) / 6;
  b[3] = u3 / 6;
}

// The window's cost -Var(I) over its box as a function of the free knots' right perturbations.
class WindowCost : public ceres::FirstOrderFunction {
 public:
  struct Event {
    int seg;  // the first of its time segment's order control knots (seg .. seg + order - 1)
    double u;  // position in the time segment, [0, 1)
    Vec3 b;   // unit bearing, camera frame
  };
  // Knots [fixed, last] of a spline of the given order (2: linear, 4: cubic): the first n_fixed
  // are fixed, the others free (3 parameters each). Every event's control knots are in [fixed, last].
  WindowCost(const std::vector<Mat3>& knots, int order, int fixed, int last, int n_fixed, std::vector<Event> events,
             const calib::Equirectangular& pano, const std::vector<double>& kernel)
      : knots_(knots), order_(order), fixed_(fixed), last_(last), skip_(n_fixed), ev_(std::move(events)), pano_(pano), kernel_(kernel) {
    for (int j = fixed; j < last; ++j) Ebar_.push_back(knots[j].transpose() * knots[j + 1]);
  }

  int NumParameters() const override { return 3 * (last_ - fixed_ + 1 - skip_); }

  // The box, in unwrapped panorama pixel coordinates (x = u - 0.5 shifted by multiples of the
  // width to lie nearest bc), from the events at x = 0 (the current knots) grown by margin.
  void set_box(double margin) {
    std::vector<double> zero(NumParameters(), 0.0);
    rotations(zero.data());
    // The window's panorama frame: its x axis through the events' mean direction, its pole along
    // the window's rotation axis (made orthogonal to x), so the sweep runs along the equator where
    // the equirectangular texels are nearly equal in solid angle. Without a rotation (below
    // ~0.5 deg), the pole is the world's z made orthogonal to x.
    Vec3 mean = Vec3::Zero();
    for (const Event& e : ev_) mean += rotation_of(e) * e.b;
    const Vec3 x_axis = mean.norm() > 1e-9 ? Vec3(mean.normalized()) : Vec3::UnitX();
    const Vec3 turn = calib::so3_log(Mat3(Rk_.back() * Rk_.front().transpose()));  // world frame
    Vec3 pole = turn.norm() > 0.01 ? turn.normalized() : Vec3::UnitZ();
    pole -= pole.dot(x_axis) * x_axis;
    if (pole.norm() < 0.1) {  // the axis along the mean direction (a roll): any pole orthogonal to it
      pole = std::abs(x_axis.z()) < 0.9 ? Vec3::UnitZ() : Vec3::UnitY();
      pole -= pole.dot(x_axis) * x_axis;
    }
    pole.normalize();
    R_pw_.row(0) = x_axis.transpose();
    R_pw_.row(1) = pole.cross(x_axis).transpose();
    R_pw_.row(2) = pole.transpose();
    // The box's longitude reference: the first event's.
    bool first = true;
    double x0 = 0, x1 = 0, y0 = 0, y1 = 0;
    for (const Event& e : ev_) {
      const Vec3 d = R_pw_ * (rotation_of(e) * e.b);
      const Eigen::Vector2d uv = pano_.project(d);
      double x = uv.x() - 0.5;
      const double y = uv.y() - 0.5;
      if (first) {
        bc_ = x;
        x0 = x1 = x;
        y0 = y1 = y;
        first = false;
        continue;
      }
      x = unwrap(x);
      x0 = std::min(x0, x);
      x1 = std::max(x1, x);
      y0 = std::min(y0, y);
      y1 = std::max(y1, y);
    }
    const double m = margin + static_cast<double>(kernel_.size() / 2) + 1;
    const int W = pano_.width(), H = pano_.height();
    bu0_ = static_cast<int>(std::floor(x0 - m));
    bw_ = std::min(W, static_cast<int>(std::ceil(x1 + m)) - bu0_ + 1);
    bc_ = bu0_ + 0.5 * bw_;
    bv0_ = std::max(0, static_cast<int>(std::floor(y0 - m)));
    bh_ = std::min(H, static_cast<int>(std::ceil(y1 + m)) + 1) - bv0_;
  }
  // The whole trajectory (the global pass): the full panorama's longitude, wrapping, in a frame
  // whose pole is the trajectory's principal rotation axis (the eigenvector of the sum over the
  // segments of w w^T, w the segment's rotation in the world frame), so the sweep runs along the
  // equator; rows from the events' latitudes grown by margin.
  void set_global(double margin) {
    std::vector<double> zero(NumParameters(), 0.0);
    rotations(zero.data());
    Mat3 S = Mat3::Zero();
    for (int j = 0; j + 1 < static_cast<int>(Rk_.size()); ++j) {
      const Vec3 w = Rk_[j] * seg_[j].w;
      S += w * w.transpose();
    }
    Vec3 pole = Vec3::UnitZ();
    if (S.trace() > 1e-12) {
      Eigen::SelfAdjointEigenSolver<Mat3> es(S);
      pole = es.eigenvectors().col(2).normalized();
    }
    Vec3 x_axis = std::abs(pole.z()) < 0.9 ? Vec3::UnitZ() : Vec3::UnitX();
    x_axis = (x_axis - x_axis.dot(pole) * pole).normalized();
    R_pw_.row(0) = x_axis.transpose();
    R_pw_.row(1) = pole.cross(x_axis).transpose();
    R_pw_.row(2) = pole.transpose();
    wrap_ = true;
    double y0 = 1e300, y1 = -1e300;
    for (const Event& e : ev_) {
      const double y = pano_.project(Vec3(R_pw_ * (rotation_of(e) * e.b))).y() - 0.5;
      y0 = std::min(y0, y);
      y1 = std::max(y1, y);
    }
    const double m = margin + static_cast<double>(kernel_.size() / 2) + 1;
    const int H = pano_.height();
    bu0_ = 0;
    bw_ = pano_.width();
    bc_ = 0.5 * bw_;
    bv0_ = ev_.empty() ? 0 : std::max(0, static_cast<int>(std::floor(y0 - m)));
    bh_ = ev_.empty() ? H : std::max(2, std::min(H, static_cast<int>(std::ceil(y1 + m)) + 1) - bv0_);
  }
  // World frame -> the window's panorama frame (set_box).
  const Mat3& window_frame() const { return R_pw_; }
  int box_u0() const { return bu0_; }
  int box_v0() const { return bv0_; }
  int box_width() const { return bw_; }
  int box_height() const { return bh_; }
  // The constant part of the IWE, alpha G * M inside the box (box_width x box_height).
  void set_base(std::vector<double> base) { base_ = std::move(base); }
  // cost = -scale Var(I) + prior (see prior()).
  void set_scale(double scale, double prior_weight, double rate_prior_weight) {
    scale_ = scale;
    prior_weight_ = prior_weight;
    rate_prior_weight_ = rate_prior_weight;
  }
  // The global pass: the rate prior becomes weight * sum over the segments of the pseudo-Huber
  // norm sqrt(|r|^2 + c^2) - c of their change r (c = kRobustRateRad), which costs a change
  // concentrated in a few segments (a step undone) far less than the same total spread over all
  // (the contrast's own collapse: the panorama swept less, its events denser).
  void set_robust_rate_prior(double weight) { robust_rate_weight_ = weight; }
  // The windows' quadratic rate prior per segment j (between knots fixed + j and fixed + j + 1):
  // its weight times factor[j] (empty: 1 each).
  void set_rate_prior_factors(std::vector<double> factor) { rate_factor_ = std::move(factor); }

  // prior_weight / 2 * mean over the free knots of |delta_j|^2 + rate_prior_weight / 2 * mean
  // over the segments of |delta_{j+1} - E_j^T delta_j|^2, E_j = R_j^T R_{j+1} at x = 0: the
  // second is, to first order, the change of the segment's rotation Log(R_j^T R_{j+1}) from the
  // prediction. Sets the gradient (when given) to the prior's.
  double prior(const double* x, double* gradient) const {
    const int np = NumParameters();
    const int nk = last_ - fixed_ + 1;
    if (gradient) std::fill(gradient, gradient + np, 0.0);
    auto delta = [&](int j) -> Vec3 {  // j: 0 .. nk-1 in the window
      if (j < skip_) return Vec3::Zero();
      return Vec3(x[3 * (j - skip_)], x[3 * (j - skip_) + 1], x[3 * (j - skip_) + 2]);
    };
    double p = 0;
    const double wa = np > 0 ? prior_weight_ / (np / 3) : 0.0;
    for (int j = skip_; j < nk; ++j) {
      const Vec3 d = delta(j);
      p += 0.5 * wa * d.squaredNorm();
      if (gradient) Eigen::Map<Vec3>(gradient + 3 * (j - skip_)) += wa * d;
    }
    if (robust_rate_weight_ > 0) {
      const double c = kRobustRateRad;
      for (int j = 0; j + 1 < nk; ++j) {
        const Mat3& E = Ebar_[j];
        const Vec3 r = delta(j + 1) - E.transpose() * delta(j);
        const double q = std::sqrt(r.squaredNorm() + c * c);
        p += robust_rate_weight_ * (q - c);
        if (!gradient) continue;
        const Vec3 g = robust_rate_weight_ / q * r;
        Eigen::Map<Vec3>(gradient + 3 * (j + 1 - skip_)) += g;
        if (j >= skip_) Eigen::Map<Vec3>(gradient + 3 * (j - skip_)) -= E * g;
      }
      return p;
    }
    const double wr = rate_prior_weight_ / (nk - 1);
    if (wr > 0) {
      for (int j = 0; j + 1 < nk; ++j) {
        const Mat3& E = Ebar_[j];
        const Vec3 r = delta(j + 1) - E.transpose() * delta(j);
        const double w = rate_factor_.empty() ? wr : wr * rate_factor_[static_cast<size_t>(j)];
        p += 0.5 * w * r.squaredNorm();
        if (!gradient) continue;
        Eigen::Map<Vec3>(gradient + 3 * (j + 1 - skip_)) += w * r;
        if (j >= skip_) Eigen::Map<Vec3>(gradient + 3 * (j - skip_)) -= w * (E * r);
      }
    }
    return p;
  }
  // Sum of the votes at the current knots inside the box (x = 0).
  double votes_at_zero() const {
    std::vector<double> zero(NumParameters(), 0.0);
    double f = 0;
    Evaluate(zero.data(), &f, nullptr);
    double s = 0;
    for (double v : votes_) s += v;
    return s;
  }

  bool Evaluate(const double* x, double* cost, double* gradient) const override {
    // A knot moved by more than a radian is outside the model's use (and Exp loses precision).
    for (int i = 0; i < NumParameters(); ++i)
      if (!(std::abs(x[i]) < 1.0)) return false;
    rotations(x);
    const int w = bw_, h = bh_;
    votes_.assign(static_cast<size_t>(w) * h, 0.0);
    const bool grad = gradient != nullptr;
    if (grad) {
      Jproj_.resize(ev_.size());
      D_.resize(ev_.size() * static_cast<size_t>(order_));
    }
    pos_.resize(ev_.size());
    for (size_t k = 0; k < ev_.size(); ++k) {
      const Event& e = ev_[k];
      const int c = e.seg - fixed_;
      const Mat3 R = spline_rotation(order_, Rk_[c], &seg_[c], e.u, grad ? &D_[k * order_] : nullptr);
      const Vec3 d = R_pw_ * (R * e.b);
      Eigen::Matrix<double, 2, 3> Jp;
      const Eigen::Vector2d uv = grad ? pano_.project(d, &Jp) : pano_.project(d);
      double lx = unwrap(uv.x() - 0.5) - bu0_;
      if (wrap_) lx -= w * std::floor(lx / w);
      const double ly = uv.y() - 0.5 - bv0_;
      pos_[k] = {lx, ly};
      if (grad) Jproj_[k] = Jp * R_pw_ * (-R * calib::hat(e.b));
      if (!inside(lx, ly)) continue;
      const int ix = static_cast<int>(lx), iy = static_cast<int>(ly);
      const double fx = lx - ix, fy = ly - iy;
      double* p = votes_.data() + static_cast<size_t>(iy) * w + ix;
      const int dx = right(ix);
      p[0] += (1 - fx) * (1 - fy);
      p[dx] += fx * (1 - fy);
      p[w] += (1 - fx) * fy;
      p[w + dx] += fx * fy;
    }
    img_ = votes_;
    blur(&img_, w, h, kernel_, &tmp_, wrap_);
    const double n = static_cast<double>(img_.size());
    double mean = 0;
    for (size_t i = 0; i < img_.size(); ++i) mean += img_[i] += base_.empty() ? 0.0 : base_[i];
    mean /= n;
    double var = 0;
    for (double v : img_) var += (v - mean) * (v - mean);
    var /= n;
    if (!std::isfinite(var)) return false;
    *cost = -var * scale_ + prior(x, gradient);
    if (!grad) return true;
    // dcost/dI = -2 scale (I - mean) / n; back through the blur (its own adjoint) to the votes.
    for (double& v : img_) v = -2.0 * scale_ * (v - mean) / n;
    blur(&img_, w, h, kernel_, &tmp_, wrap_);
    for (size_t k = 0; k < ev_.size(); ++k) {
      const double lx = pos_[k].x(), ly = pos_[k].y();
      if (!inside(lx, ly)) continue;
      const int ix = static_cast<int>(lx), iy = static_cast<int>(ly);
      const double fx = lx - ix, fy = ly - iy;
      const double* g = img_.data() + static_cast<size_t>(iy) * w + ix;
      const int dx = right(ix);
      const double gx = (1 - fy) * (g[dx] - g[0]) + fy * (g[w + dx] - g[w]);
      const double gy = (1 - fx) * (g[w] - g[0]) + fx * (g[w + dx] - g[dx]);
      const Eigen::RowVector3d gphi = Eigen::RowVector2d(gx, gy) * Jproj_[k];
      const int c0 = ev_[k].seg - fixed_;
      for (int c = std::max(0, skip_ - c0); c < order_; ++c)
        Eigen::Map<Eigen::RowVector3d>(gradient + 3 * (c0 + c - skip_)) += gphi * D_[k * order_ + c] * Jr_[c0 + c];
    }
    for (int i = 0; i < NumParameters(); ++i)
      if (!std::isfinite(gradient[i])) return false;
    return true;
  }

 private:
  // A vote at box position (lx, ly) lands inside (its four texels; x wraps in the global pass).
  bool inside(double lx, double ly) const {
    return ly >= 0 && ly < bh_ - 1 && (wrap_ ? lx >= 0 && lx < bw_ : lx >= 0 && lx < bw_ - 1);
  }
  // The offset from texel column ix to the next (wrapping in the global pass).
  int right(int ix) const { return wrap_ && ix + 1 >= bw_ ? 1 - bw_ : 1; }
  double unwrap(double x) const {
    const double W = pano_.width();
    return x + W * std::round((bc_ - x) / W);
  }
  Mat3 rotation_of(const Event& e) const {
    const int c = e.seg - fixed_;
    return spline_rotation(order_, Rk_[c], &seg_[c], e.u, nullptr);
  }
  // The knots and segments at parameters x.
  void rotations(const double* x) const {
    const int nk = last_ - fixed_ + 1;
    Rk_.resize(nk);
    Jr_.resize(nk);
    seg_.resize(nk - 1);
    for (int j = 0; j < skip_; ++j) {
      Rk_[j] = knots_[fixed_ + j];
      Jr_[j].setIdentity();
    }
    for (int j = skip_; j < nk; ++j) {
      const Vec3 delta(x[3 * (j - skip_)], x[3 * (j - skip_) + 1], x[3 * (j - skip_) + 2]);
      Rk_[j] = knots_[fixed_ + j] * calib::so3_exp(delta);
      Jr_[j] = calib::so3_right_jacobian(delta);
    }
    for (int j = 0; j + 1 < nk; ++j) seg_[j] = make_seg(Rk_[j], Rk_[j + 1]);
  }

  const std::vector<Mat3>& knots_;
  const int order_, fixed_, last_, skip_;
  const std::vector<Event> ev_;
  const calib::Equirectangular& pano_;
  const std::vector<double>& kernel_;
  double bc_ = 0;
  Mat3 R_pw_ = Mat3::Identity();
  int bu0_ = 0, bv0_ = 0, bw_ = 1, bh_ = 1;
  bool wrap_ = false;
  std::vector<double> base_;
  double scale_ = 1, prior_weight_ = 0, rate_prior_weight_ = 0, robust_rate_weight_ = 0;
  std::vector<double> rate_factor_;
  static constexpr double kRobustRateRad = 1e-3;
  std::vector<Mat3> Ebar_;  // the segments' rotations at x = 0
  mutable std::vector<Mat3> Rk_, Jr_;
  mutable std::vector<Seg> seg_;
  mutable std::vector<double> votes_, img_, tmp_;
  mutable std::vector<Eigen::Vector2d> pos_;
  mutable std::vector<Eigen::Matrix<double, 2, 3>> Jproj_;
  mutable std::vector<Mat3> D_;  // order per event: dphi / ddelta of its control knots
};

// The global pass's parameters: the knots' left perturbations as running sums of increments
// less their mean over the events, R_j = Exp(theta_j - theta_mean) R_j0 with
// theta_j = eps_0 + ... + eps_j and theta_mean = sum_j w_j theta_j (w_j: knot j's share of the
// events). One increment turns everything after it, so a step left in the trajectory is one
// parameter, not every later knot's; subtracting the mean holds the panorama as a whole (the
// equirectangular IWE's contrast is not invariant under a rotation of the whole scene, and
// would otherwise turn it), leaving the first knot to fix the world frame afterwards. In the inner
// cost's right perturbations delta_j = R_j0^T (theta_j - theta_mean) (exactly: R Exp(R^T t) =
// Exp(t) R), a linear map; the gradient follows by its transpose.
class IncrementCost : public ceres::FirstOrderFunction {
 public:
  // inner: knots [fixed, last], all free (owned); R0: the knots at x = 0; share: w_j (sum 1).
  IncrementCost(WindowCost* inner, std::vector<Mat3> R0, std::vector<double> share)
      : inner_(inner), R0_(std::move(R0)), w_(std::move(share)) {}
  int NumParameters() const override { return inner_->NumParameters(); }
  bool Evaluate(const double* eps, double* cost, double* gradient) const override {
    const size_t n = R0_.size();
    deltas(eps);
    if (!gradient) return inner_->Evaluate(delta_.data(), cost, nullptr);
    gdelta_.assign(3 * n, 0.0);
    if (!inner_->Evaluate(delta_.data(), cost, gdelta_.data())) return false;
    // h_j = df/dtheta'_j; df/dtheta_j = h_j - w_j sum_i h_i; df/deps_i = sum over j >= i.
    theta_.resize(n);
    Vec3 H = Vec3::Zero(), acc = Vec3::Zero();
    for (size_t j = 0; j < n; ++j) {
      theta_[j] = R0_[j] * Vec3(gdelta_[3 * j], gdelta_[3 * j + 1], gdelta_[3 * j + 2]);
      H += theta_[j];
    }
    for (size_t j = n; j-- > 0;) {
      acc += theta_[j] - w_[j] * H;
      Eigen::Map<Vec3>(gradient + 3 * j) = acc;
    }
    return true;
  }
  // The knots' right perturbations at eps (the linear map above; no cost evaluated).
  const std::vector<double>& deltas(const double* eps) const {
    const size_t n = R0_.size();
    theta_.resize(n);
    Vec3 acc = Vec3::Zero(), mean = Vec3::Zero();
    for (size_t j = 0; j < n; ++j) {
      acc += Vec3(eps[3 * j], eps[3 * j + 1], eps[3 * j + 2]);
      theta_[j] = acc;
      mean += w_[j] * acc;
    }
    delta_.resize(3 * n);
    for (size_t j = 0; j < n; ++j) Eigen::Map<Vec3>(delta_.data() + 3 * j) = R0_[j].transpose() * (theta_[j] - mean);
    return delta_;
  }

 private:
  std::unique_ptr<WindowCost> inner_;
  const std::vector<Mat3> R0_;
  const std::vector<double> w_;
  mutable std::vector<Vec3> theta_;
  mutable std::vector<double> delta_, gdelta_;
};

// Bilinear vote of direction d into an equirectangular image (u wraps, v clipped).
void vote(std::vector<float>* img, const calib::Equirectangular& pano, const Vec3& d) {
  const Eigen::Vector2d uv = pano.project(d);
  const int W = pano.width(), H = pano.height();
  const double x = uv.x() - 0.5, y = uv.y() - 0.5;
  const double fxl = std::floor(x), fyl = std::floor(y);
  const int ix = static_cast<int>(fxl), iy = static_cast<int>(fyl);
  const double fx = x - fxl, fy = y - fyl;
  auto add = [&](int cx, int cy, double w) {
    if (cy < 0 || cy >= H) return;
    cx = ((cx % W) + W) % W;
    (*img)[static_cast<size_t>(cy) * W + cx] += static_cast<float>(w);
  };
  add(ix, iy, (1 - fx) * (1 - fy));
  add(ix + 1, iy, fx * (1 - fy));
  add(ix, iy + 1, (1 - fx) * fy);
  add(ix + 1, iy + 1, fx * fy);
}

// The box at the current knots and the map's part of the IWE inside it, alpha G * M.
void prepare_map(WindowCost* cost, const std::vector<float>& map, const CmaxSlamOptions& opt, const std::vector<double>& kernel) {
  if (opt.map_weight <= 0 || map.empty()) return;
  // The map (world panorama) resampled into the window's frame, bilinearly, as events per window texel.
  const int bw = cost->box_width(), bh = cost->box_height(), W = opt.panorama_width, H = opt.panorama_height;
  const calib::Equirectangular pano(W, H);
  const Mat3 R_wp = cost->window_frame().transpose();
  std::vector<double> base(static_cast<size_t>(bw) * bh);
  double msum = 0;
  for (int y = 0; y < bh; ++y)
    for (int x = 0; x < bw; ++x) {
      const Vec3 dp = pano.unproject(cost->box_u0() + x + 0.5, cost->box_v0() + y + 0.5);
      const Vec3 d = R_wp * dp;
      // Counts per texel scale with the texel's solid angle, cos(latitude): per window texel.
      const double area = std::sqrt(std::max(0.0, 1 - dp.z() * dp.z())) / std::max(0.05, std::sqrt(std::max(0.0, 1 - d.z() * d.z())));
      const Eigen::Vector2d uv = pano.project(d);
      const double fx0 = uv.x() - 0.5, fy0 = uv.y() - 0.5;
      const int ix = static_cast<int>(std::floor(fx0)), iy = static_cast<int>(std::floor(fy0));
      const double fx = fx0 - ix, fy = fy0 - iy;
      auto at = [&](int cx, int cy) -> double {
        if (cy < 0 || cy >= H) return 0.0;
        cx = ((cx % W) + W) % W;
        return map[static_cast<size_t>(cy) * W + cx];
      };
      const double v = (1 - fx) * (1 - fy) * at(ix, iy) + fx * (1 - fy) * at(ix + 1, iy) + (1 - fx) * fy * at(ix, iy + 1) +
                       fx * fy * at(ix + 1, iy + 1);
      msum += base[static_cast<size_t>(y) * bw + x] = area * v;
    }
  const double vsum = cost->votes_at_zero();
  if (msum <= 0 || vsum <= 0) return;
  const double alpha = opt.map_weight * std::min(1.0, vsum / msum);
  for (double& v : base) v *= alpha;
  std::vector<double> tmp;
  blur(&base, bw, bh, kernel, &tmp);
  cost->set_base(std::move(base));
}

// The nearest rotation (products of rotations drift off SO(3) in floating point).
Mat3 orthonormal(const Mat3& R) { return Eigen::Quaterniond(R).normalized().toRotationMatrix(); }

// The box, the map's part and the cost's normalisation: the contrast relative to its value at the
// current knots (x = 0), plus the prior.
void prepare(WindowCost* cost, const std::vector<float>& map, const CmaxSlamOptions& opt, const std::vector<double>& kernel) {
  cost->set_box(opt.box_margin_px);
  prepare_map(cost, map, opt, kernel);
  std::vector<double> zero(static_cast<size_t>(cost->NumParameters()), 0.0);
  double f = 0;
  cost->Evaluate(zero.data(), &f, nullptr);
  cost->set_scale(f < 0 ? -1.0 / f : 1.0, opt.prior_weight, opt.rate_prior_weight);
}

// Control knots per time segment.
int spline_order(const CmaxSlamOptions& o) { return o.spline == CmaxSlamSpline::kCubic ? 4 : 2; }

// Coarse to fine: a wider blur first widens the basin, then the fine blur.
std::vector<double> blur_levels(const CmaxSlamOptions& o) {
  std::vector<double> sigmas;
  if (o.coarse_blur_sigma_px > o.blur_sigma_px) sigmas.push_back(o.coarse_blur_sigma_px);
  sigmas.push_back(o.blur_sigma_px);
  return sigmas;
}

// L-BFGS (Ceres' GradientProblemSolver) from x, silently.
ceres::GradientProblemSolver::Summary minimise(const ceres::GradientProblem& problem, double* x, int max_iterations,
                                               double function_tolerance, double parameter_tolerance) {
  ceres::GradientProblemSolver::Options so;
  so.max_num_iterations = max_iterations;
  so.logging_type = ceres::SILENT;
  so.function_tolerance = function_tolerance;
  so.gradient_tolerance = 1e-12;
  so.parameter_tolerance = parameter_tolerance;
  ceres::GradientProblemSolver::Summary sum;
  ceres::Solve(so, problem, x, &sum);
  return sum;
}

// The windows' rate prior per knot segment j of knots [fixed, last] (CmaxSlamOptions::
// min_segment_events): floor / the events of its time segment, at least 1 (empty: floor 0). Knot
// segment j is mostly time segment fixed + j - 1 for the cubic spline (its middle Log), fixed + j
// for the linear one; the cubic's first and last take their neighbour's count.
std::vector<double> rate_prior_factors(const std::vector<int64_t>& t_ns, int64_t t0, int64_t dt, int fixed, int last, int order,
                                       double floor) {
  if (!(floor > 0)) return {};
  const int nseg = last - fixed;
  const int shift = (order - 2) / 2;
  std::vector<double> count(static_cast<size_t>(nseg), 0.0);
  for (int64_t t : t_ns) {
    const int64_t j = (t - t0) / dt - fixed + shift;
    if (j >= 0 && j < nseg) count[static_cast<size_t>(j)] += 1;
  }
  std::vector<double> factor(static_cast<size_t>(nseg));
  for (int j = 0; j < nseg; ++j) {
    const int jj = std::clamp(j, std::min(shift, nseg - 1), std::max(0, nseg - 1 - shift));
    factor[static_cast<size_t>(j)] = std::max(1.0, floor / std::max(1.0, count[static_cast<size_t>(jj)]));
  }
  return factor;
}

// Fewer events than this in a window: no optimisation (the prediction is kept).
constexpr size_t kMinWindowEvents = 50;

}  // namespace

double cmax_slam_window_cost(const std::vector<Eigen::Matrix3d>& knots, int64_t t0_ns, int fixed, int last,
                             const std::vector<int64_t>& t_ns, const std::vector<Eigen::Vector3d>& bearing_c,
                             const std::vector<float>& map, const CmaxSlamOptions& options,
                             const std::vector<double>& x, std::vector<double>* gradient) {
  std::string why;
  if (!options.Validate(&why)) throw std::invalid_argument("CmaxSlamOptions: " + why);
  if (fixed < 0 || last <= fixed || last >= static_cast<int>(knots.size()) || t_ns.size() != bearing_c.size() ||
      x.size() != static_cast<size_t>(3 * (last - fixed)))
    throw std::invalid_argument("cmax_slam_window_cost: inconsistent knots, events or parameters");
  const int64_t dt = options.knot_spacing_ns;
  const int order = spline_order(options);
  std::vector<WindowCost::Event> ev;
  for (size_t k = 0; k < t_ns.size(); ++k) {
    const int64_t s = (t_ns[k] - t0_ns) / dt;
    if (t_ns[k] < t0_ns || s < fixed || s + order - 1 > last)
      throw std::invalid_argument("cmax_slam_window_cost: an event outside the knots' span");
    ev.push_back({static_cast<int>(s), static_cast<double>(t_ns[k] - t0_ns - s * dt) / static_cast<double>(dt),
                  bearing_c[k].normalized()});
  }
  const calib::Equirectangular pano(options.panorama_width, options.panorama_height);
  const std::vector<double> kernel = gaussian_taps(options.blur_sigma_px);
  WindowCost cost(knots, order, fixed, last, 1, std::move(ev), pano, kernel);
  cost.set_rate_prior_factors(rate_prior_factors(t_ns, t0_ns, dt, fixed, last, order, options.min_segment_events));
  prepare(&cost, map, options, kernel);
  double f = 0;
  if (gradient) gradient->assign(x.size(), 0.0);
  cost.Evaluate(x.data(), &f, gradient ? gradient->data() : nullptr);
  return f;
}

namespace {

// The global pass's events: segment and position on the spline of knots from t0_ns.
std::vector<WindowCost::Event> spline_events(size_t knots, int order, int64_t t0_ns, int64_t dt, const std::vector<int64_t>& t_ns,
                                             const std::vector<Eigen::Vector3d>& bearing_c) {
  if (t_ns.size() != bearing_c.size() || knots < static_cast<size_t>(order))
    throw std::invalid_argument("CMax-SLAM global pass: inconsistent knots or events");
  const int64_t smax = static_cast<int64_t>(knots) - order;  // the last time segment
  std::vector<WindowCost::Event> ev;
  ev.reserve(t_ns.size());
  for (size_t k = 0; k < t_ns.size(); ++k) {
    if (t_ns[k] < t0_ns || t_ns[k] > t0_ns + (smax + 1) * dt) throw std::invalid_argument("CMax-SLAM global pass: an event outside the knots' span");
    const int64_t s = std::min<int64_t>((t_ns[k] - t0_ns) / dt, smax);
    ev.push_back({static_cast<int>(s), static_cast<double>(t_ns[k] - t0_ns - s * dt) / static_cast<double>(dt), bearing_c[k].normalized()});
  }
  return ev;
}

// The global pass's cost at one blur (kernel and pano must outlive it): every knot free, as
// running increments less their mean (weights: each knot's share of the events through the
// spline's interpolation), with the robust rate prior; normalised to -1 at eps = 0.
std::unique_ptr<IncrementCost> global_cost(const std::vector<Mat3>& knots, const std::vector<WindowCost::Event>& ev,
                                           const calib::Equirectangular& pano, const std::vector<double>& kernel, const CmaxSlamOptions& o) {
  const int order = spline_order(o);
  std::vector<double> share(knots.size(), 0.0);
  double b[4];
  for (const WindowCost::Event& e : ev) {
    spline_weights(order, e.u, b);
    for (int c = 0; c < order; ++c) share[static_cast<size_t>(e.seg + c)] += b[c] / static_cast<double>(ev.size());
  }
  const int last = static_cast<int>(knots.size()) - 1;
  auto* inner = new WindowCost(knots, order, 0, last, 0, ev, pano, kernel);
  inner->set_global(o.box_margin_px);
  std::vector<double> zero(static_cast<size_t>(inner->NumParameters()), 0.0);
  double fz = 0;
  inner->Evaluate(zero.data(), &fz, nullptr);
  inner->set_scale(fz < 0 ? -1.0 / fz : 1.0, 0.0, 0.0);
  // The prior's weight per rad of change is global_rate_weight over the trajectory's total
  // rotation (rad): shrinking every segment by a fraction a then costs global_rate_weight * a at
  // any length (the contrast it buys also grows with a, not with the length), while undoing a
  // step costs in proportion to the step.
  double turned = 0;
  for (size_t j = 0; j + 1 < knots.size(); ++j) turned += calib::so3_log(Mat3(knots[j].transpose() * knots[j + 1])).norm();
  inner->set_robust_rate_prior(o.global_rate_weight / std::max(turned, 1e-3));
  return std::make_unique<IncrementCost>(inner, knots, std::move(share));
}

}  // namespace

double cmax_slam_global_cost(const std::vector<Eigen::Matrix3d>& knots, int64_t t0_ns, const std::vector<int64_t>& t_ns,
                             const std::vector<Eigen::Vector3d>& bearing_c, const CmaxSlamOptions& options,
                             const std::vector<double>& eps, std::vector<double>* gradient) {
  std::string why;
  if (!options.Validate(&why)) throw std::invalid_argument("CmaxSlamOptions: " + why);
  if (eps.size() != 3 * knots.size()) throw std::invalid_argument("cmax_slam_global_cost: 3 parameters per knot");
  const std::vector<WindowCost::Event> ev = spline_events(knots.size(), spline_order(options), t0_ns, options.knot_spacing_ns, t_ns, bearing_c);
  const calib::Equirectangular pano(options.panorama_width, options.panorama_height);
  const std::vector<double> kernel = gaussian_taps(options.blur_sigma_px);
  const std::unique_ptr<IncrementCost> cost = global_cost(knots, ev, pano, kernel, options);
  double f = 0;
  if (gradient) gradient->assign(eps.size(), 0.0);
  if (!cost->Evaluate(eps.data(), &f, gradient ? gradient->data() : nullptr)) return std::numeric_limits<double>::quiet_NaN();
  return f;
}

CmaxSlamGlobalResult cmax_slam_refine_globally(const std::vector<Eigen::Matrix3d>& knots, int64_t t0_ns, const std::vector<int64_t>& t_ns,
                                               const std::vector<Eigen::Vector3d>& bearing_c, const CmaxSlamOptions& options) {
  std::string why;
  if (!options.Validate(&why)) throw std::invalid_argument("CmaxSlamOptions: " + why);
  CmaxSlamGlobalResult r;
  r.knots = knots;
  const int order = spline_order(options);
  const std::vector<WindowCost::Event> ev = spline_events(knots.size(), order, t0_ns, options.knot_spacing_ns, t_ns, bearing_c);
  if (ev.size() < kMinWindowEvents || knots.size() < static_cast<size_t>(order) + 1 || options.global_iterations < 1) return r;
  const calib::Equirectangular pano(options.panorama_width, options.panorama_height);
  const std::vector<double> sigmas = blur_levels(options);
  std::vector<double> eps(3 * knots.size(), 0.0), delta;
  double f0 = 0, f1 = 0;
  for (size_t level = 0; level < sigmas.size(); ++level) {
    const std::vector<double> kernel = gaussian_taps(sigmas[level]);
    std::unique_ptr<IncrementCost> owned = global_cost(knots, ev, pano, kernel, options);
    IncrementCost* cost = owned.get();
    ceres::GradientProblem problem(owned.release());  // owns the cost
    const bool fine = level + 1 == sigmas.size();
    if (fine) {
      std::vector<double> zero(eps.size(), 0.0);
      cost->Evaluate(zero.data(), &f0, nullptr);
    }
    const ceres::GradientProblemSolver::Summary sum = minimise(problem, eps.data(), options.global_iterations, 1e-8, 1e-10);
    r.iterations += static_cast<int64_t>(sum.iterations.size() > 0 ? sum.iterations.size() - 1 : 0);
    if (fine) {
      cost->Evaluate(eps.data(), &f1, nullptr);
      delta = cost->deltas(eps.data());
    }
  }
  bool finite = std::isfinite(f1);
  for (double v : delta) finite = finite && std::abs(v) < 1.0;
  if (!finite || !(f1 < f0)) return r;
  r.refined = true;
  r.contrast_gain = -f1;  // f0 = -1: the rate prior is zero at eps = 0
  for (size_t j = 0; j < knots.size(); ++j) r.knots[j] = knots[j] * calib::so3_exp(Vec3(delta[3 * j], delta[3 * j + 1], delta[3 * j + 2]));
  // The world frame stays: R(t0) unchanged.
  auto start = [&](const std::vector<Mat3>& k) {
    Seg seg[3];
    for (int j = 0; j + 1 < order; ++j) seg[j] = make_seg(k[static_cast<size_t>(j)], k[static_cast<size_t>(j) + 1]);
    return spline_rotation(order, k.front(), seg, 0.0, nullptr);
  };
  const Mat3 back = start(knots) * start(r.knots).transpose();
  for (Mat3& R : r.knots) R = orthonormal(back * R);
  return r;
}

CmaxSlam::CmaxSlam(const CmaxSlamOptions& options, int64_t t0_ns, const Eigen::Matrix3d& R_w_c0)
    : opt_(options), t0_(t0_ns), dt_(options.knot_spacing_ns), order_(spline_order(options)), offset_(order_ == 4 ? 1 : 0), t_a_(t0_ns) {
  std::string why;
  if (!opt_.Validate(&why)) throw std::invalid_argument("CmaxSlamOptions: " + why);
  // The knots up to t0: a still start (cubic: one more, before t0).
  for (int i = 0; i <= offset_; ++i) knots_.push_back(orthonormal(R_w_c0));
  odo_.emplace_back(t0_ns, knots_.front());
  odo_at_last_knot_ = knots_.front();
  map_.assign(static_cast<size_t>(opt_.panorama_width) * opt_.panorama_height, 0.0f);
}

void CmaxSlam::add_event(int64_t t_ns, const Eigen::Vector3f& bearing_c) {
  if (t_ns < t_a_) throw std::invalid_argument("CmaxSlam::add_event: event before the finalised time");
  events_.push_back({t_ns, bearing_c.x(), bearing_c.y(), bearing_c.z()});
  // The global pass's sample: every kept_stride_-th event; past the cap, every other one is
  // dropped and the stride doubles (an even sample of all events, at most the cap).
  if (opt_.global_iterations > 0 && seen_++ % kept_stride_ == 0) {
    kept_.push_back(events_.back());
    if (kept_.size() > static_cast<size_t>(opt_.global_max_events)) {
      size_t k = 0;
      for (size_t i = 0; i < kept_.size(); i += 2) kept_[k++] = kept_[i];
      kept_.resize(k);
      kept_stride_ *= 2;
      seen_ = 1;  // the next kept event is kept_stride_ after the last one kept
    }
  }
}

void CmaxSlam::predict(int64_t t_ns, const Eigen::Matrix3d& R_odometry) {
  if (t_ns <= odo_.back().first) return;
  odo_.emplace_back(t_ns, orthonormal(R_odometry));
  // New knots follow the odometry's motion since the last knot (linear between its samples).
  while (knot_time(knots_.size()) <= t_ns) {
    const int64_t tk = knot_time(knots_.size());
    while (odo_.size() > 2 && odo_[1].first <= tk) odo_.pop_front();
    const auto& [ta, Ra] = odo_[0];
    const auto& [tb, Rb] = odo_[1];
    const double u = static_cast<double>(tk - ta) / static_cast<double>(tb - ta);
    const Mat3 R_odo = Ra * calib::so3_exp(u * calib::so3_log(Mat3(Ra.transpose() * Rb)));
    knots_.push_back(orthonormal(knots_.back() * odo_at_last_knot_.transpose() * R_odo));
    odo_at_last_knot_ = R_odo;
  }
}

Eigen::Matrix3d CmaxSlam::rotation(int64_t t_ns) const {
  const int64_t smax = static_cast<int64_t>(knots_.size()) - order_;  // the last time segment with its knots
  if (smax < 0) return knots_.back();
  int64_t s = t_ns <= t0_ ? 0 : (t_ns - t0_) / dt_;
  double u = t_ns <= t0_ ? 0.0 : static_cast<double>(t_ns - t0_ - s * dt_) / static_cast<double>(dt_);
  if (s > smax) {  // held at the end
    s = smax;
    u = 1.0;
  }
  const size_t c = static_cast<size_t>(s);
  Seg seg[3];
  // A final segment's rotation never changes: its Logs are kept for the next call (finalisation
  // and the caller's mapping ask for every event of a segment in turn).
  if (s == cached_segment_) {
    for (int j = 0; j + 1 < order_; ++j) seg[j].w = cached_w_[j];
  } else {
    for (int j = 0; j + 1 < order_; ++j) seg[j].w = calib::so3_log(Mat3(knots_[c + j].transpose() * knots_[c + j + 1]));
    if (t0_ + (s + 1) * dt_ <= t_a_) {
      cached_segment_ = s;
      for (int j = 0; j + 1 < order_; ++j) cached_w_[j] = seg[j].w;
    }
  }
  return spline_rotation(order_, knots_[c], seg, u, nullptr);
}

void CmaxSlam::update(int64_t t_complete_ns) {
  const int64_t span = opt_.window_knots * dt_;
  while (t_a_ + span <= t_complete_ns) {
    const int64_t tb = t_a_ + span;
    if (knot_time(knots_.size() - 1) < tb + (order_ - 2 - offset_) * dt_) break;  // the window's last control knot
    optimize_window(t_a_, tb);
    finalize_until(t_a_ + opt_.step_knots * dt_);
  }
}

void CmaxSlam::finish(int64_t t_end_ns) {
  update(t_end_ns);
  // The last window's knots must reach past t_end_ns; beyond the predicted ones the last segment's
  // rotation repeats (constant velocity).
  const Mat3 step = knots_.size() > 1 ? Mat3(knots_[knots_.size() - 2].transpose() * knots_.back()) : Mat3::Identity();
  while (knot_time(knots_.size() - 1) <= t_end_ns + (order_ - 2 - offset_) * dt_) knots_.push_back(knots_.back() * step);
  if (t_end_ns >= t_a_) optimize_window(t_a_, t_end_ns + 1);
  finalize_until(INT64_MAX);
  if (opt_.global_iterations > 0) refine_globally();
}

void CmaxSlam::refine_globally() {
  if (kept_.size() < kMinWindowEvents || knots_.size() < static_cast<size_t>(order_) + 1) return;
  std::vector<int64_t> t;
  std::vector<Eigen::Vector3d> b;
  t.reserve(kept_.size());
  b.reserve(kept_.size());
  for (const Ev& e : kept_) {
    t.push_back(e.t);
    b.emplace_back(e.bx, e.by, e.bz);
  }
  const CmaxSlamGlobalResult r = cmax_slam_refine_globally(knots_, t0_, t, b, opt_);
  stats_.global_iterations = r.iterations;
  stats_.global_events = static_cast<int64_t>(kept_.size());
  if (!r.refined) return;
  stats_.global_contrast_gain = r.contrast_gain;
  stats_.global_refined = true;
  knots_ = r.knots;
  cached_segment_ = -1;
}

void CmaxSlam::optimize_window(int64_t ta, int64_t tb) {
  // The window's time segments [fixed, s_last] have control knots [fixed, s_last + order - 1].
  const int fixed = static_cast<int>((ta - t0_) / dt_);
  const int last = static_cast<int>((tb - t0_ + dt_ - 1) / dt_) - 1 + order_ - 1;
  size_t n = 0;
  while (n < events_.size() && events_[n].t < tb) ++n;
  // The first window keeps the prediction: without a map its cost barely constrains the
  // window's rotation as a whole, nor its first segment, whose errors would offset every later
  // window registered to the map it starts.
  if (n < kMinWindowEvents || last - fixed + 1 <= order_ - 1 || (opt_.keep_first_window && stats_.events_mapped == 0)) {
    ++stats_.skipped_windows;
    return;
  }
  const size_t cap = static_cast<size_t>(opt_.max_window_events);
  const size_t stride = cap > 0 && n > cap ? (n + cap - 1) / cap : 1;
  std::vector<WindowCost::Event> ev;
  ev.reserve(n / stride + 1);
  for (size_t k = 0; k < n; k += stride) {
    const Ev& e = events_[k];
    const int64_t s = (e.t - t0_) / dt_;
    ev.push_back({static_cast<int>(s), static_cast<double>(e.t - t0_ - s * dt_) / static_cast<double>(dt_),
                  Vec3(e.bx, e.by, e.bz).normalized()});
  }
  std::vector<int64_t> times(n);
  for (size_t k = 0; k < n; ++k) times[k] = events_[k].t;
  const std::vector<double> factor = rate_prior_factors(times, t0_, dt_, fixed, last, order_, opt_.min_segment_events);
  const calib::Equirectangular pano(opt_.panorama_width, opt_.panorama_height);
  const size_t used = ev.size();
  const std::vector<double> sigmas = blur_levels(opt_);
  // The first window (nothing finalised yet) frees its first knot as well: no earlier event
  // depends on it, and fixing it would let the sparse first segment anchor the whole window.
  // Otherwise the knots that shape the finalised segments stay: the window's first order - 1.
  const bool free_first = stats_.events_mapped == 0 && fixed == 0;
  const int n_fixed = free_first ? 0 : order_ - 1;
  const int n_free = last - fixed + 1 - n_fixed;
  std::vector<double> x(static_cast<size_t>(3 * n_free), 0.0);
  double f0 = 0, f1 = 0, prior1 = 0;
  for (size_t level = 0; level < sigmas.size(); ++level) {
    const std::vector<double> kernel = gaussian_taps(sigmas[level]);
    auto* cost = new WindowCost(knots_, order_, fixed, last, n_fixed, level + 1 < sigmas.size() ? ev : std::move(ev), pano, kernel);
    ceres::GradientProblem problem(cost);  // owns cost
    cost->set_rate_prior_factors(factor);
    prepare(cost, map_, opt_, kernel);
    const bool fine = level + 1 == sigmas.size();
    if (fine) {
      std::vector<double> zero(x.size(), 0.0);
      cost->Evaluate(zero.data(), &f0, nullptr);
    }
    const ceres::GradientProblemSolver::Summary sum = minimise(problem, x.data(), opt_.max_iterations, 1e-7, 1e-9);
    stats_.iterations += static_cast<int64_t>(sum.iterations.size() > 0 ? sum.iterations.size() - 1 : 0);
    stats_.evaluations += sum.num_cost_evaluations + sum.num_gradient_evaluations;
    if (fine) {
      cost->Evaluate(x.data(), &f1, nullptr);
      prior1 = cost->prior(x.data(), nullptr);
    }
  }
  bool finite = std::isfinite(f1);
  for (double v : x) finite = finite && std::abs(v) < 1.0;
  if (finite && f1 <= f0) {
    const Mat3 last_before = knots_[static_cast<size_t>(last)];
    for (int j = fixed + n_fixed; j <= last; ++j) {
      const double* d = x.data() + 3 * (j - fixed - n_fixed);
      knots_[static_cast<size_t>(j)] = orthonormal(knots_[static_cast<size_t>(j)] * calib::so3_exp(Vec3(d[0], d[1], d[2])));
    }
    // The predicted knots after the window keep their rotations relative to its last knot.
    const Mat3 change = knots_[static_cast<size_t>(last)] * last_before.transpose();
    for (size_t j = static_cast<size_t>(last) + 1; j < knots_.size(); ++j) knots_[j] = orthonormal(change * knots_[j]);
  }
  ++stats_.windows;
  stats_.events_used += static_cast<int64_t>(used);
  // The contrast gain: f = -Var / Var(prediction) + prior, f0 = -1.
  gain_sum_ += finite && f1 <= f0 ? prior1 - f1 : 1.0;
  stats_.mean_contrast_gain = gain_sum_ / static_cast<double>(stats_.windows);
}

void CmaxSlam::finalize_until(int64_t t) {
  const calib::Equirectangular pano(opt_.panorama_width, opt_.panorama_height);
  // The knots before the new t_a_ are final from here on.
  t_a_ = std::max(t_a_, std::min(t, t0_ + (static_cast<int64_t>(knots_.size()) - order_ + 1) * dt_));
  while (!events_.empty() && events_.front().t < t) {
    const Ev& e = events_.front();
    vote(&map_, pano, rotation(e.t) * Vec3(e.bx, e.by, e.bz));
    events_.pop_front();
    ++stats_.events_mapped;
  }
}

}  // namespace evio::backend
