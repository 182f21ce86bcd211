// Rotational CMax-SLAM back-end: see cmax_slam.h for the model.
#include "evio/backend/cmax_slam.h"

#include <algorithm>
#include <climits>
#include <cmath>
#include <stdexcept>

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

// Separable convolution with zero padding (a symmetric operator: it is its own adjoint).
void blur(std::vector<double>* img, int w, int h, const std::vector<double>& k, std::vector<double>* tmp) {
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
      const int i0 = std::max(-r, -x), i1 = std::min(r, w - 1 - x);
      for (int i = i0; i <= i1; ++i) s += k[i + r] * row[x + i];
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

// The window's cost -Var(I) over its box as a function of the free knots' right perturbations.
class WindowCost : public ceres::FirstOrderFunction {
 public:
  struct Event {
    int seg;  // spline segment (knots seg, seg + 1)
    double u;  // position in the segment, [0, 1)
    Vec3 b;   // unit bearing, camera frame
  };
  // Knots [fixed, last]: the first is fixed unless free_first, the others are free (3 parameters each).
  WindowCost(const std::vector<Mat3>& knots, int fixed, int last, bool free_first, std::vector<Event> events,
             const calib::Equirectangular& pano, const std::vector<double>& kernel)
      : knots_(knots), fixed_(fixed), last_(last), skip_(free_first ? 0 : 1), ev_(std::move(events)), pano_(pano), kernel_(kernel) {
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
    const double wr = rate_prior_weight_ / (nk - 1);
    if (wr > 0) {
      for (int j = 0; j + 1 < nk; ++j) {
        const Mat3& E = Ebar_[j];
        const Vec3 r = delta(j + 1) - E.transpose() * delta(j);
        p += 0.5 * wr * r.squaredNorm();
        if (!gradient) continue;
        Eigen::Map<Vec3>(gradient + 3 * (j + 1 - skip_)) += wr * r;
        if (j >= skip_) Eigen::Map<Vec3>(gradient + 3 * (j - skip_)) -= wr * (E * r);
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
      D0_.resize(ev_.size());
      D1_.resize(ev_.size());
    }
    pos_.resize(ev_.size());
    for (size_t k = 0; k < ev_.size(); ++k) {
      const Event& e = ev_[k];
      const Seg& s = seg_[e.seg - fixed_];
      const Vec3 uw = e.u * s.w;
      const Mat3 A = calib::so3_exp(uw);
      const Mat3 R = Rk_[e.seg - fixed_] * A;
      const Vec3 d = R_pw_ * (R * e.b);
      Eigen::Matrix<double, 2, 3> Jp;
      const Eigen::Vector2d uv = grad ? pano_.project(d, &Jp) : pano_.project(d);
      const double lx = unwrap(uv.x() - 0.5) - bu0_, ly = uv.y() - 0.5 - bv0_;
      pos_[k] = {lx, ly};
      if (grad) {
        Jproj_[k] = Jp * R_pw_ * (-R * calib::hat(e.b));
        const Mat3 D1 = e.u * calib::so3_right_jacobian(uw) * s.Jinv;
        D1_[k] = D1;
        D0_[k] = A.transpose() - D1 * s.E.transpose();
      }
      if (!(lx >= 0 && ly >= 0 && lx < w - 1 && ly < h - 1)) continue;
      const int ix = static_cast<int>(lx), iy = static_cast<int>(ly);
      const double fx = lx - ix, fy = ly - iy;
      double* p = votes_.data() + static_cast<size_t>(iy) * w + ix;
      p[0] += (1 - fx) * (1 - fy);
      p[1] += fx * (1 - fy);
      p[w] += (1 - fx) * fy;
      p[w + 1] += fx * fy;
    }
    img_ = votes_;
    blur(&img_, w, h, kernel_, &tmp_);
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
    blur(&img_, w, h, kernel_, &tmp_);
    for (size_t k = 0; k < ev_.size(); ++k) {
      const double lx = pos_[k].x(), ly = pos_[k].y();
      if (!(lx >= 0 && ly >= 0 && lx < w - 1 && ly < h - 1)) continue;
      const int ix = static_cast<int>(lx), iy = static_cast<int>(ly);
      const double fx = lx - ix, fy = ly - iy;
      const double* g = img_.data() + static_cast<size_t>(iy) * w + ix;
      const double gx = (1 - fy) * (g[1] - g[0]) + fy * (g[w + 1] - g[w]);
      const double gy = (1 - fx) * (g[w] - g[0]) + fx * (g[w + 1] - g[1]);
      const Eigen::RowVector3d gphi = Eigen::RowVector2d(gx, gy) * Jproj_[k];
      const int s = ev_[k].seg;
      if (s - fixed_ >= skip_) {
        Eigen::Map<Eigen::RowVector3d>(gradient + 3 * (s - fixed_ - skip_)) += gphi * D0_[k] * Jr_[s - fixed_];
      }
      Eigen::Map<Eigen::RowVector3d>(gradient + 3 * (s + 1 - fixed_ - skip_)) += gphi * D1_[k] * Jr_[s + 1 - fixed_];
    }
    for (int i = 0; i < NumParameters(); ++i)
      if (!std::isfinite(gradient[i])) return false;
    return true;
  }

 private:
  struct Seg {
    Vec3 w;    // Log(R_i^T R_{i+1})
    Mat3 E;    // Exp(w)
    Mat3 Jinv; // Jr^-1(w)
  };
  double unwrap(double x) const {
    const double W = pano_.width();
    return x + W * std::round((bc_ - x) / W);
  }
  Mat3 rotation_of(const Event& e) const {
    const Seg& s = seg_[e.seg - fixed_];
    return Rk_[e.seg - fixed_] * calib::so3_exp(e.u * s.w);
  }
  // The knots and segments at parameters x.
  void rotations(const double* x) const {
    const int nk = last_ - fixed_ + 1;
    Rk_.resize(nk);
    Jr_.resize(nk);
    seg_.resize(nk - 1);
    Rk_[0] = knots_[fixed_];
    Jr_[0].setIdentity();
    for (int j = skip_; j < nk; ++j) {
      const Vec3 delta(x[3 * (j - skip_)], x[3 * (j - skip_) + 1], x[3 * (j - skip_) + 2]);
      Rk_[j] = knots_[fixed_ + j] * calib::so3_exp(delta);
      Jr_[j] = calib::so3_right_jacobian(delta);
    }
    for (int j = 0; j + 1 < nk; ++j) {
      Seg& s = seg_[j];
      s.w = calib::so3_log(Mat3(Rk_[j].transpose() * Rk_[j + 1]));
      s.E = calib::so3_exp(s.w);
      s.Jinv = calib::so3_right_jacobian_inv(s.w);
    }
  }

  const std::vector<Mat3>& knots_;
  const int fixed_, last_, skip_;
  const std::vector<Event> ev_;
  const calib::Equirectangular& pano_;
  const std::vector<double>& kernel_;
  double bc_ = 0;
  Mat3 R_pw_ = Mat3::Identity();
  int bu0_ = 0, bv0_ = 0, bw_ = 1, bh_ = 1;
  std::vector<double> base_;
  double scale_ = 1, prior_weight_ = 0, rate_prior_weight_ = 0;
  std::vector<Mat3> Ebar_;  // the segments' rotations at x = 0
  mutable std::vector<Mat3> Rk_, Jr_;
  mutable std::vector<Seg> seg_;
  mutable std::vector<double> votes_, img_, tmp_;
  mutable std::vector<Eigen::Vector2d> pos_;
  mutable std::vector<Eigen::Matrix<double, 2, 3>> Jproj_;
  mutable std::vector<Mat3> D0_, D1_;
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
  const double alpha = opt.map_weight * vsum / msum;
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
  std::vector<WindowCost::Event> ev;
  for (size_t k = 0; k < t_ns.size(); ++k) {
    const int64_t s = (t_ns[k] - t0_ns) / dt;
    if (t_ns[k] < t0_ns || s < fixed || s >= last)
      throw std::invalid_argument("cmax_slam_window_cost: an event outside the knots' span");
    ev.push_back({static_cast<int>(s), static_cast<double>(t_ns[k] - t0_ns - s * dt) / static_cast<double>(dt),
                  bearing_c[k].normalized()});
  }
  const calib::Equirectangular pano(options.panorama_width, options.panorama_height);
  const std::vector<double> kernel = gaussian_taps(options.blur_sigma_px);
  WindowCost cost(knots, fixed, last, false, std::move(ev), pano, kernel);
  prepare(&cost, map, options, kernel);
  double f = 0;
  if (gradient) gradient->assign(x.size(), 0.0);
  cost.Evaluate(x.data(), &f, gradient ? gradient->data() : nullptr);
  return f;
}

CmaxSlam::CmaxSlam(const CmaxSlamOptions& options, int64_t t0_ns, const Eigen::Matrix3d& R_w_c0)
    : opt_(options), t0_(t0_ns), dt_(options.knot_spacing_ns), t_a_(t0_ns) {
  std::string why;
  if (!opt_.Validate(&why)) throw std::invalid_argument("CmaxSlamOptions: " + why);
  knots_.push_back(orthonormal(R_w_c0));
  odo_.emplace_back(t0_ns, knots_.front());
  odo_at_last_knot_ = knots_.front();
  map_.assign(static_cast<size_t>(opt_.panorama_width) * opt_.panorama_height, 0.0f);
}

void CmaxSlam::add_event(int64_t t_ns, const Eigen::Vector3f& bearing_c) {
  if (t_ns < t_a_) throw std::invalid_argument("CmaxSlam::add_event: event before the finalised time");
  events_.push_back({t_ns, bearing_c.x(), bearing_c.y(), bearing_c.z()});
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
  if (t_ns <= t0_) return knots_.front();
  const int64_t s = (t_ns - t0_) / dt_;
  if (s + 1 >= static_cast<int64_t>(knots_.size())) return knots_.back();
  const double u = static_cast<double>(t_ns - knot_time(static_cast<size_t>(s))) / static_cast<double>(dt_);
  const Mat3& R0 = knots_[static_cast<size_t>(s)];
  // A final segment's rotation never changes: kept for the next call (finalisation and the
  // caller's mapping ask for every event of a segment in turn).
  if (s != cached_segment_) {
    const Vec3 w = calib::so3_log(Mat3(R0.transpose() * knots_[static_cast<size_t>(s) + 1]));
    if (knot_time(static_cast<size_t>(s) + 1) > t_a_) return R0 * calib::so3_exp(u * w);
    cached_segment_ = s;
    cached_w_ = w;
  }
  return R0 * calib::so3_exp(u * cached_w_);
}

void CmaxSlam::update(int64_t t_complete_ns) {
  const int64_t span = opt_.window_knots * dt_;
  while (t_a_ + span <= t_complete_ns) {
    const int64_t tb = t_a_ + span;
    if (knot_time(knots_.size() - 1) < tb) break;
    optimize_window(t_a_, tb);
    finalize_until(t_a_ + opt_.step_knots * dt_);
  }
}

void CmaxSlam::finish(int64_t t_end_ns) {
  update(t_end_ns);
  // The last window's knots must reach past t_end_ns; beyond the predicted ones the last segment's
  // rotation repeats (constant velocity).
  const Mat3 step = knots_.size() > 1 ? Mat3(knots_[knots_.size() - 2].transpose() * knots_.back()) : Mat3::Identity();
  while (knot_time(knots_.size() - 1) <= t_end_ns) knots_.push_back(knots_.back() * step);
  if (t_end_ns >= t_a_) optimize_window(t_a_, t_end_ns + 1);
  finalize_until(INT64_MAX);
}

void CmaxSlam::optimize_window(int64_t ta, int64_t tb) {
  const int fixed = static_cast<int>((ta - t0_) / dt_);
  const int last = static_cast<int>((tb - t0_ + dt_ - 1) / dt_);
  size_t n = 0;
  while (n < events_.size() && events_[n].t < tb) ++n;
  // The first window keeps the prediction: without a map its cost barely constrains the
  // window's rotation as a whole, nor its first segment, whose errors would offset every later
  // window registered to the map it starts.
  if (n < kMinWindowEvents || last <= fixed || (opt_.keep_first_window && stats_.events_mapped == 0)) {
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
    ev.push_back({static_cast<int>(s), static_cast<double>(e.t - knot_time(static_cast<size_t>(s))) / static_cast<double>(dt_),
                  Vec3(e.bx, e.by, e.bz).normalized()});
  }
  const calib::Equirectangular pano(opt_.panorama_width, opt_.panorama_height);
  const size_t used = ev.size();
  // Coarse to fine: a wider blur first widens the basin, then the fine blur.
  std::vector<double> sigmas;
  if (opt_.coarse_blur_sigma_px > opt_.blur_sigma_px) sigmas.push_back(opt_.coarse_blur_sigma_px);
  sigmas.push_back(opt_.blur_sigma_px);
  // The first window (nothing finalised yet) frees its first knot as well: no earlier event
  // depends on it, and fixing it would let the sparse first segment anchor the whole window.
  const bool free_first = stats_.events_mapped == 0 && fixed == 0;
  const int n_free = last - fixed + (free_first ? 1 : 0);
  std::vector<double> x(static_cast<size_t>(3 * n_free), 0.0);
  double f0 = 0, f1 = 0, prior1 = 0;
  for (size_t level = 0; level < sigmas.size(); ++level) {
    const std::vector<double> kernel = gaussian_taps(sigmas[level]);
    auto* cost = new WindowCost(knots_, fixed, last, free_first, level + 1 < sigmas.size() ? ev : std::move(ev), pano, kernel);
    ceres::GradientProblem problem(cost);  // owns cost
    prepare(cost, map_, opt_, kernel);
    const bool fine = level + 1 == sigmas.size();
    if (fine) {
      std::vector<double> zero(x.size(), 0.0);
      cost->Evaluate(zero.data(), &f0, nullptr);
    }
    ceres::GradientProblemSolver::Options so;
    so.max_num_iterations = opt_.max_iterations;
    so.logging_type = ceres::SILENT;
    so.function_tolerance = 1e-7;
    so.gradient_tolerance = 1e-12;
    so.parameter_tolerance = 1e-9;
    ceres::GradientProblemSolver::Summary sum;
    ceres::Solve(so, problem, x.data(), &sum);
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
    for (int j = free_first ? fixed : fixed + 1; j <= last; ++j) {
      const double* d = x.data() + 3 * (j - fixed - (free_first ? 0 : 1));
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
  t_a_ = std::max(t_a_, std::min(t, knot_time(knots_.size() - 1)));
  while (!events_.empty() && events_.front().t < t) {
    const Ev& e = events_.front();
    vote(&map_, pano, rotation(e.t) * Vec3(e.bx, e.by, e.bz));
    events_.pop_front();
    ++stats_.events_mapped;
  }
}

}  // namespace evio::backend
