// Pixel-wise gradient EKF mosaic and its Poisson reconstruction. Model in gradient_mosaic.h.
#include "evio/mapping/gradient_mosaic.h"
#include "evio/mapping/option_tables.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <Eigen/Geometry>

namespace evio::mapping {

bool GradientMosaicOptions::Validate(std::string* why) const {
  // The table holds the Poisson solvers' keys too.
  if (!gradient_mosaic_table().check(*this, why)) return false;
  if (measurement_std_abs == 0.0 && measurement_relative_std == 0.0)
    return validation_failed(why, "measurement_std_abs and measurement_relative_std must not both be 0");
  if (min_gradient_std >= initial_gradient_std)
    return validation_failed(why, "min_gradient_std must be < initial_gradient_std");
  if (weight_reference_std < min_gradient_std)
    return validation_failed(why, "weight_reference_std must be >= min_gradient_std");
  return true;
}

const char* poisson_weighting_name(PoissonWeighting w) {
  switch (w) {
    case PoissonWeighting::kNone: return "none";
    case PoissonWeighting::kInformation: return "information";
  }
  return "?";
}

namespace {
const GradientMosaicOptions& validated(const GradientMosaicOptions& o) {
  std::string why;
  if (!o.Validate(&why)) throw std::invalid_argument("GradientMosaicOptions: " + why);
  return o;
}
}  // namespace

GradientMosaic::GradientMosaic(const GradientMosaicOptions& options)
    : options_(validated(options)),
      solver_(options.width, options.height, options.poisson),
      weighted_solver_(options.width, options.height, options.weighted_poisson, options.poisson) {
  const size_t n = static_cast<size_t>(options_.width) * options_.height;
  const double p0 = options_.initial_gradient_std * options_.initial_gradient_std;
  state_.assign(n, PixelState{0.0, 0.0, p0, 0.0, p0, 0, 0});
  edge_gu_ = ImageD::Zero(options_.height, options_.width);
  edge_gv_ = ImageD::Zero(options_.height, options_.width);
  log_intensity_ = ImageD::Zero(options_.height, options_.width);
  dirty_x0_ = dirty_y0_ = 0;
  dirty_x1_ = dirty_y1_ = -1;
}

MosaicUpdate GradientMosaic::update_status(const Eigen::Vector2d& uv, const Eigen::Vector2d& v_px_s, double tau_s,
                                           int polarity) {
  if (!uv.allFinite() || !v_px_s.allFinite() || !std::isfinite(tau_s)) {
    ++stats_.non_finite;
    return MosaicUpdate::kNonFinite;
  }
  if (polarity != 1 && polarity != -1) {
    ++stats_.bad_polarity;
    return MosaicUpdate::kBadPolarity;
  }
  const int W = options_.width, H = options_.height;
  if (uv.y() < 0.0 || uv.y() > H || std::abs(uv.x()) > 1e12) {
    ++stats_.outside;
    return MosaicUpdate::kOutside;
  }
  if (tau_s < options_.min_tau_s) {
    ++stats_.tau_too_small;
    return MosaicUpdate::kTauTooSmall;
  }
  const double speed2 = v_px_s.squaredNorm();
  if (!(speed2 >= options_.min_speed_px_s * options_.min_speed_px_s) || speed2 == 0.0) {
    ++stats_.too_slow;
    return MosaicUpdate::kTooSlow;
  }
  double fu = std::floor(uv.x());
  fu -= W * std::floor(fu / W);
  const int i = std::min(static_cast<int>(fu), W - 1);
  const int j = std::min(static_cast<int>(std::floor(uv.y())), H - 1);
  PixelState& st = state_[index(i, j)];

  // h = H^T = p v / C; z = 1/tau; R = abs^2 + (rel z)^2.
  const double z = 1.0 / tau_s;
  const double s = polarity / options_.contrast_threshold;
  const double hu = s * v_px_s.x(), hv = s * v_px_s.y();
  const double R = options_.measurement_std_abs * options_.measurement_std_abs +
                   (options_.measurement_relative_std * z) * (options_.measurement_relative_std * z);
  const double a = st.puu, b = st.puv, c = st.pvv;
  const double phu = a * hu + b * hv, phv = b * hu + c * hv;  // P h
  const double S = hu * phu + hv * phv + R;
  const double ku = phu / S, kv = phv / S;
  const double y = z - (hu * st.gu + hv * st.gv);
  const double ngu = st.gu + ku * y, ngv = st.gv + kv * y;
  // Joseph form: P' = (I - k h^T) P (I - k h^T)^T + R k k^T.
  Eigen::Matrix2d P;
  P << a, b, b, c;
  Eigen::Matrix2d A = Eigen::Matrix2d::Identity();
  A(0, 0) -= ku * hu;
  A(0, 1) -= ku * hv;
  A(1, 0) -= kv * hu;
  A(1, 1) -= kv * hv;
  const Eigen::Vector2d kvec(ku, kv);
  Eigen::Matrix2d Pn = A * P * A.transpose() + R * kvec * kvec.transpose();
  const double off = 0.5 * (Pn(0, 1) + Pn(1, 0));
  Pn(0, 1) = Pn(1, 0) = off;
  // Eigenvalue floor (closed form for a symmetric 2x2).
  const double floor_var = options_.min_gradient_std * options_.min_gradient_std;
  const double mean = 0.5 * (Pn(0, 0) + Pn(1, 1));
  const double half_diff = 0.5 * (Pn(0, 0) - Pn(1, 1));
  const double rad = std::sqrt(half_diff * half_diff + off * off);
  const double l_min = mean - rad;
  if (!(l_min >= floor_var)) {
    const double l_max = std::max(mean + rad, floor_var);
    // Unit eigenvector of the largest eigenvalue.
    Eigen::Vector2d e_max;
    if (rad > 0.0) {
      e_max = half_diff >= 0.0 ? Eigen::Vector2d(half_diff + rad, off) : Eigen::Vector2d(off, rad - half_diff);
      e_max.normalize();
    } else {
      e_max = Eigen::Vector2d::UnitX();
    }
    Pn = floor_var * Eigen::Matrix2d::Identity() + (l_max - floor_var) * e_max * e_max.transpose();
  }
  if (!Pn.allFinite() || !std::isfinite(ngu) || !std::isfinite(ngv)) {
    ++stats_.non_finite;
    return MosaicUpdate::kNonFinite;
  }
  st.gu = ngu;
  st.gv = ngv;
  st.puu = Pn(0, 0);
  st.puv = Pn(0, 1);
  st.pvv = Pn(1, 1);
  if (st.count < UINT32_MAX) ++st.count;
  ++stats_.applied;
  if (dirty_x1_ < dirty_x0_) {
    dirty_x0_ = dirty_x1_ = i;
    dirty_y0_ = dirty_y1_ = j;
  } else {
    dirty_x0_ = std::min(dirty_x0_, i);
    dirty_x1_ = std::max(dirty_x1_, i);
    dirty_y0_ = std::min(dirty_y0_, j);
    dirty_y1_ = std::max(dirty_y1_, j);
  }
  return MosaicUpdate::kApplied;
}

MosaicUpdate GradientMosaic::update_segment(const Eigen::Vector2d& uv_from, const Eigen::Vector2d& uv_to, double tau_s,
                                            int polarity) {
  if (!uv_from.allFinite() || !uv_to.allFinite() || !std::isfinite(tau_s)) {
    ++stats_.non_finite;
    return MosaicUpdate::kNonFinite;
  }
  Eigen::Vector2d d = uv_to - uv_from;
  const double W = options_.width;
  d.x() -= W * std::round(d.x() / W);
  if (d.squaredNorm() > options_.max_path_px * options_.max_path_px) {
    ++stats_.path_too_long;
    return MosaicUpdate::kPathTooLong;
  }
  if (tau_s < options_.min_tau_s) {  // also keeps d / tau finite
    ++stats_.tau_too_small;
    return MosaicUpdate::kTauTooSmall;
  }
  return update_status(uv_to - 0.5 * d, d / tau_s, tau_s, polarity);
}

ImageF GradientMosaic::gradient_u() const {
  ImageF t(options_.height, options_.width);
  for (size_t k = 0; k < state_.size(); ++k) t.data()[k] = static_cast<float>(state_[k].gu);
  return t;
}
ImageF GradientMosaic::gradient_v() const {
  ImageF t(options_.height, options_.width);
  for (size_t k = 0; k < state_.size(); ++k) t.data()[k] = static_cast<float>(state_[k].gv);
  return t;
}
ImageF GradientMosaic::covariance_trace() const {
  ImageF t(options_.height, options_.width);
  for (size_t k = 0; k < state_.size(); ++k) t.data()[k] = static_cast<float>(state_[k].puu + state_[k].pvv);
  return t;
}
Eigen::Matrix<uint32_t, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> GradientMosaic::observation_count() const {
  Eigen::Matrix<uint32_t, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> c(options_.height, options_.width);
  for (size_t k = 0; k < state_.size(); ++k) c.data()[k] = state_[k].count;
  return c;
}
bool GradientMosaic::is_seen(const PixelState& p) const {
  if (p.count < static_cast<uint32_t>(options_.seen_min_observations)) return false;
  if (options_.seen_max_gradient_std <= 0) return true;
  // Largest eigenvalue of the 2x2 covariance: both gradient components must be known.
  const double mean = 0.5 * (p.puu + p.pvv), half_diff = 0.5 * (p.puu - p.pvv);
  const double l_max = mean + std::sqrt(half_diff * half_diff + p.puv * p.puv);
  return l_max <= options_.seen_max_gradient_std * options_.seen_max_gradient_std;
}

void GradientMosaic::mark_viewed(const Eigen::Vector2d& uv) {
  if (!uv.allFinite()) return;
  const int W = options_.width, H = options_.height;
  const int i0 = static_cast<int>(std::floor(uv.x() - 0.5)) - 1, j0 = static_cast<int>(std::floor(uv.y() - 0.5)) - 1;
  for (int dj = 0; dj < 4; ++dj) {
    const int j = std::min(std::max(j0 + dj, 0), H - 1);
    for (int di = 0; di < 4; ++di) {
      const int i = (((i0 + di) % W) + W) % W;
      state_[index(i, j)].viewed = 1;
    }
  }
}

MaskU8 GradientMosaic::viewed_mask() const {
  MaskU8 m(options_.height, options_.width);
  for (size_t k = 0; k < state_.size(); ++k) m.data()[k] = state_[k].viewed;
  return m;
}

MaskU8 GradientMosaic::seen_mask() const {
  MaskU8 m(options_.height, options_.width);
  for (size_t k = 0; k < state_.size(); ++k) m.data()[k] = is_seen(state_[k]) ? 1 : 0;
  return m;
}

void GradientMosaic::update_edges(int x0, int y0, int w, int h) {
  const int W = options_.width, H = options_.height;
  const bool periodic = options_.poisson.boundary == PoissonBoundary::kPeriodicU;
  auto edge = [](bool s0, double g0, bool s1, double g1) {
    if (s0 && s1) return 0.5 * (g0 + g1);
    if (s0) return g0;
    if (s1) return g1;
    return 0.0;
  };
  for (int j = std::max(y0, 0); j < std::min(y0 + h, H); ++j) {
    for (int t = 0; t < w; ++t) {
      int i = x0 + t;
      i = ((i % W) + W) % W;
      const PixelState& p = state_[index(i, j)];
      const bool s = is_seen(p);
      if (i + 1 < W || periodic) {
        const PixelState& r = state_[index((i + 1) % W, j)];
        edge_gu_(j, i) = edge(s, p.gu, is_seen(r), r.gu);
      } else {
        edge_gu_(j, i) = 0.0;
      }
      if (j + 1 < H) {
        const PixelState& d = state_[index(i, j + 1)];
        edge_gv_(j, i) = edge(s, p.gv, is_seen(d), d.gv);
      } else {
        edge_gv_(j, i) = 0.0;
      }
    }
  }
}

void GradientMosaic::edge_weights(ImageD* wx, ImageD* wy) const {
  const int W = options_.width, H = options_.height;
  const bool periodic = options_.poisson.boundary == PoissonBoundary::kPeriodicU;
  const double ref = options_.weight_reference_std * options_.weight_reference_std;
  const double prior = options_.initial_gradient_std * options_.initial_gradient_std;
  auto weight = [&](bool s0, double p0, bool s1, double p1, bool viewed) {
    if (!s0 && !s1 && viewed) return options_.viewed_edge_weight;
    double var = prior;
    if (s0 && s1) {
      var = 0.25 * (p0 + p1);
    } else if (s0) {
      var = p0;
    } else if (s1) {
      var = p1;
    }
    return std::min(1.0, ref / var);
  };
  wx->setZero(H, W);
  wy->setZero(H, W);
  for (int j = 0; j < H; ++j) {
    for (int i = 0; i < W; ++i) {
      const PixelState& p = state_[index(i, j)];
      const bool s = is_seen(p);
      if (i + 1 < W || periodic) {
        const PixelState& r = state_[index((i + 1) % W, j)];
        (*wx)(j, i) = weight(s, p.puu, is_seen(r), r.puu, p.viewed && r.viewed);
      }
      if (j + 1 < H) {
        const PixelState& d = state_[index(i, j + 1)];
        (*wy)(j, i) = weight(s, p.pvv, is_seen(d), d.pvv, p.viewed && d.viewed);
      }
    }
  }
}

// The solve shared by reconstruct() and reconstruct_map(): updates log_intensity_ and returns the
// re-solved region (empty when nothing changed).
PixelRect GradientMosaic::solve(ReconstructMode mode, PoissonWeighting weighting, MosaicReconstruction* out) {
  const int W = options_.width, H = options_.height;
  const bool periodic = options_.poisson.boundary == PoissonBoundary::kPeriodicU;
  const bool dirty = dirty_x1_ >= dirty_x0_;
  bool full = mode == ReconstructMode::kFull || !solved_once_ || weighting == PoissonWeighting::kInformation;
  PixelRect rect;
  if (!full && dirty) {
    // Changed pixels' edges touch the box grown by one pixel on every side.
    int x0 = dirty_x0_ - 1, x1 = dirty_x1_ + 1;
    if (!periodic) x0 = std::max(x0, 0), x1 = std::min(x1, W - 1);
    rect.x = x0;
    rect.width = std::min(x1 - x0 + 1, W);
    rect.y = std::max(dirty_y0_ - 1, 0);
    rect.height = std::min(dirty_y1_ + 1, H - 1) - rect.y + 1;
    const int side = std::max(rect.width, rect.height);
    if (mode == ReconstructMode::kAuto && side > options_.poisson.max_region_side) full = true;
  }
  PixelRect solved{0, 0, 0, 0};
  if (full) {
    update_edges(0, 0, W, H);
    solver_.solve(edge_gu_, edge_gv_, &log_intensity_);
    if (weighting == PoissonWeighting::kInformation) {
      out->unweighted_log_intensity = log_intensity_.cast<float>();
      ImageD wx, wy;
      edge_weights(&wx, &wy);
      out->weighted_stats = weighted_solver_.solve(edge_gu_, edge_gv_, wx, wy, &log_intensity_, &log_intensity_);
    }
    out->weighting = weighting;
    solved_once_ = true;
    out->full_solve = true;
    out->region = PixelRect{0, 0, W, H};
    solved = out->region;
  } else if (dirty) {
    update_edges(rect.x - 1, rect.y - 1, rect.width + 1, rect.height + 1);
    solved = solver_.solve_region(edge_gu_, edge_gv_, rect, &log_intensity_);
    out->full_solve = solved.width == W && solved.height == H;  // whole image, or the solver fell back
    out->region = rect;
  } else {
    out->full_solve = false;
    out->region = PixelRect{0, 0, 0, 0};
  }
  dirty_x0_ = dirty_y0_ = 0;
  dirty_x1_ = dirty_y1_ = -1;
  return solved;
}

MosaicReconstruction GradientMosaic::reconstruct(ReconstructMode mode, PoissonWeighting weighting) {
  MosaicReconstruction out;
  solve(mode, weighting, &out);
  out.log_intensity = log_intensity_.cast<float>();
  out.seen = seen_mask();
  return out;
}

PixelRect GradientMosaic::reconstruct_map(ReconstructMode mode, std::vector<float>* map) {
  const int W = options_.width, H = options_.height;
  MosaicReconstruction info;
  PixelRect r = solve(mode, PoissonWeighting::kNone, &info);
  const size_t n = static_cast<size_t>(W) * static_cast<size_t>(H);
  if (map->size() != n) {
    map->resize(n);
    r = PixelRect{0, 0, W, H};
  }
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (int j = std::max(r.y, 0); j < std::min(r.y + r.height, H); ++j) {
    float* row = map->data() + static_cast<size_t>(j) * static_cast<size_t>(W);
    for (int t = 0; t < r.width; ++t) {
      const int i = (((r.x + t) % W) + W) % W;
      const PixelState& st = state_[index(i, j)];
      row[i] = is_seen(st) || (options_.map_viewed_texels && st.viewed) ? static_cast<float>(log_intensity_(j, i)) : nan;
    }
  }
  return r;
}

GradientMosaic::Checkpoint GradientMosaic::checkpoint() const {
  Checkpoint c;
  c.state_ = state_;
  return c;
}

void GradientMosaic::restore(const Checkpoint& checkpoint) {
  if (checkpoint.state_.size() != state_.size())
    throw std::invalid_argument("GradientMosaic::restore: a checkpoint of another mosaic size");
  state_ = checkpoint.state_;
  solved_once_ = false;  // the next solve is full
  dirty_x0_ = dirty_y0_ = 0;
  dirty_x1_ = dirty_y1_ = -1;
}

Eigen::Vector2d mosaic_pixel_velocity(const calib::Equirectangular& projection, const Eigen::Matrix3d& R_w_c,
                                      const Eigen::Vector3d& omega_w, const Eigen::Vector3d& bearing_c,
                                      Eigen::Vector2d* uv_out) {
  const Eigen::Vector3d d_w = R_w_c * bearing_c;
  Eigen::Matrix<double, 2, 3> J;
  const Eigen::Vector2d uv = projection.project(d_w, &J);
  if (uv_out) *uv_out = uv;
  return J * omega_w.cross(d_w);
}

}  // namespace evio::mapping
