// Contrast maximisation: warps, IWE, objectives with adjoint gradients, coarse-to-fine BFGS.
#include "evio/mapping/cmax.h"
#include "evio/mapping/option_tables.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <type_traits>

#include <Eigen/Dense>

namespace evio::mapping {
namespace {

constexpr double kMinDepth = 0.2;  // warped d_z below this: the event does not vote

bool finite(double v) { return std::isfinite(v); }

// Warp of event k to dt = dt_k - shift. Writes x', y' and, when Ju/Jv are given, d(x')/dp, d(y')/dp.
template <WarpModel M>
inline bool warp_k(const CmaxEvents& ev, size_t k, const double* p, double shift, double* u, double* v,
                   double* Ju, double* Jv) {
  const double dt_k = static_cast<double>(ev.dt_s[k]);
  const double dt = dt_k - shift;
  const double x = ev.x[k], y = ev.y[k];
  if constexpr (M == WarpModel::kFlow || M == WarpModel::kFlowAccel) {
    *u = x - dt * p[0];
    *v = y - dt * p[1];
    if (Ju) {
      Ju[0] = -dt, Ju[1] = 0;
      Jv[0] = 0, Jv[1] = -dt;
    }
    if constexpr (M == WarpModel::kFlowAccel) {
      // The trajectory x(t) = x0 + v t + a t^2 / 2 taken back from t_k to t_ref + shift.
      const double h = 0.5 * (dt_k * dt_k - shift * shift);
      *u -= h * p[2];
      *v -= h * p[3];
      if (Ju) {
        Ju[2] = -h, Ju[3] = 0;
        Jv[2] = 0, Jv[3] = -h;
      }
    }
    return true;
  } else if constexpr (M == WarpModel::kSimilarity || M == WarpModel::kSimilarityAccel) {
    const WarpGeometry& g = ev.geometry();
    const double rx = x - g.cx, ry = y - g.cy;
    *u = x - dt * (p[0] + p[2] * rx - p[3] * ry);
    *v = y - dt * (p[1] + p[2] * ry + p[3] * rx);
    if (Ju) {
      Ju[0] = -dt, Ju[1] = 0, Ju[2] = -dt * rx, Ju[3] = dt * ry;
      Jv[0] = 0, Jv[1] = -dt, Jv[2] = -dt * ry, Jv[3] = -dt * rx;
    }
    if constexpr (M == WarpModel::kSimilarityAccel) {
      const double h = 0.5 * (dt_k * dt_k - shift * shift);
      *u -= h * p[4];
      *v -= h * p[5];
      if (Ju) {
        Ju[4] = -h, Ju[5] = 0;
        Jv[4] = 0, Jv[5] = -h;
      }
    }
    return true;
  } else {
    const WarpGeometry& g = ev.geometry();
    const double bx = ev.xn[k], by = ev.yn[k];
    const double wx = (M == WarpModel::kRotation) ? p[0] : p[3];
    const double wy = (M == WarpModel::kRotation) ? p[1] : p[4];
    const double wz = (M == WarpModel::kRotation) ? p[2] : p[5];
    // d = b + dt (w x b [+ rho v]), b = (bx, by, 1)
    double dx = bx + dt * (wy - wz * by);
    double dy = by + dt * (wz * bx - wx);
    double dz = 1.0 + dt * (wx * by - wy * bx);
    double rho = 0;
    if constexpr (M == WarpModel::kSixDof) {
      rho = ev.rho[k];
      dx += dt * rho * p[0];
      dy += dt * rho * p[1];
      dz += dt * rho * p[2];
    }
    if (!(dz >= kMinDepth)) return false;
    const double iz = 1.0 / dz;
    const double ex = dx * iz, ey = dy * iz;
    *u = g.cx + g.fx * ex;
    *v = g.cy + g.fy * ey;
    if (Ju) {
      // d(ex)/dq = (d dx/dq - ex d dz/dq) / dz; the same for ey.
      // dd/dw = dt [ (0, 1, -by); (-1, 0, bx); (by, -bx, 0) ] (rows x, y, z), dd/dv = dt rho I.
      const double a = g.fx * iz * dt, b = g.fy * iz * dt;
      const int o = (M == WarpModel::kRotation) ? 0 : 3;
      Ju[o + 0] = a * (0 - ex * by);
      Ju[o + 1] = a * (1 + ex * bx);
      Ju[o + 2] = a * (-by);
      Jv[o + 0] = b * (-1 - ey * by);
      Jv[o + 1] = b * (0 + ey * bx);
      Jv[o + 2] = b * (bx);
      if constexpr (M == WarpModel::kSixDof) {
        Ju[0] = a * rho, Ju[1] = 0, Ju[2] = -a * rho * ex;
        Jv[0] = 0, Jv[1] = b * rho, Jv[2] = -b * rho * ey;
      }
    }
    return true;
  }
}

void gaussian_kernel(double sigma, std::vector<float>* k) {
  k->clear();
  if (sigma <= 0) {
    k->push_back(1.0f);
    return;
  }
  const int r = std::max(1, static_cast<int>(std::ceil(3.0 * sigma)));
  double sum = 0;
  for (int i = -r; i <= r; ++i) sum += std::exp(-0.5 * i * i / (sigma * sigma));
  for (int i = -r; i <= r; ++i) k->push_back(static_cast<float>(std::exp(-0.5 * i * i / (sigma * sigma)) / sum));
}

// Separable convolution with a symmetric kernel and zero padding of the w x h image at `in` (rows
// in_stride floats apart) into `out` (rows out_stride apart; out may be in, with the same stride).
// tmp: scratch of w*h + w + 2r floats. As a linear map it is symmetric, so the same call applies its
// adjoint.
void blur(const float* in, int in_stride, float* out, int out_stride, float* tmp, int w, int h,
          const std::vector<float>& k) {
  const int r = static_cast<int>(k.size()) / 2;
  if (r == 0) {
    for (int j = 0; j < h; ++j)
      std::copy(in + static_cast<size_t>(j) * in_stride, in + static_cast<size_t>(j) * in_stride + w,
                out + static_cast<size_t>(j) * out_stride);
    return;
  }
  using Row = Eigen::Map<Eigen::ArrayXf>;  // Eigen maps: SIMD whatever the compiler's flags
  using ConstRow = Eigen::Map<const Eigen::ArrayXf>;
  const float* kc = k.data() + r;  // kc[-r..r], kc[-d] == kc[d]
  // Rows: each row copied into a zero-padded line, then one fixed-length loop per pair of taps.
  float* line = tmp + static_cast<size_t>(w) * h;  // w + 2r floats after the image scratch
  std::fill(line, line + r, 0.0f);
  std::fill(line + r + w, line + 2 * r + w, 0.0f);
  for (int j = 0; j < h; ++j) {
    const float* row = in + static_cast<size_t>(j) * in_stride;
    std::copy(row, row + w, line + r);
    Row o(tmp + static_cast<size_t>(j) * w, w);
    const float* c = line + r;
    o = kc[0] * ConstRow(c, w);
    for (int d = 1; d <= r; ++d) o += kc[d] * (ConstRow(c - d, w) + ConstRow(c + d, w));
  }
  // Columns: row-vector operations over the rows in reach.
  for (int j = 0; j < h; ++j) {
    Row o(out + static_cast<size_t>(j) * out_stride, w);
    auto at = [&](int jj) { return ConstRow(tmp + static_cast<size_t>(jj) * w, w); };
    o = kc[0] * at(j);
    for (int d = 1; d <= r; ++d) {
      const bool up = j - d >= 0, down = j + d < h;
      if (up && down) o += kc[d] * (at(j - d) + at(j + d));
      else if (up) o += kc[d] * at(j - d);
      else if (down) o += kc[d] * at(j + d);
    }
  }
}

// Objective of the (blurred) image h and, when adj != nullptr, dF/dh into adj.
double image_objective(CmaxObjective o, const float* h, int w, int hh, float* adj) {
  const size_t n = static_cast<size_t>(w) * hh;
  const double inv_n = 1.0 / static_cast<double>(n);
  if (o == CmaxObjective::kVariance || o == CmaxObjective::kMeanSquare) {
    // Double sums in four independent chains (one chain waits on each add's latency).
    double sum[4] = {}, sum2[4] = {};
    size_t i = 0;
    for (; i + 4 <= n; i += 4) {
      for (int l = 0; l < 4; ++l) {
        const double v = h[i + l];
        sum[l] += v;
        sum2[l] += v * v;
      }
    }
    for (; i < n; ++i) {
      sum[0] += h[i];
      sum2[0] += static_cast<double>(h[i]) * h[i];
    }
    const double s1 = (sum[0] + sum[1]) + (sum[2] + sum[3]), s2 = (sum2[0] + sum2[1]) + (sum2[2] + sum2[3]);
    const double mean = (o == CmaxObjective::kVariance) ? s1 * inv_n : 0.0;
    if (adj) {
      const float c = static_cast<float>(2.0 * inv_n), m = static_cast<float>(mean);
      Eigen::Map<Eigen::ArrayXf>(adj, n) = c * (Eigen::Map<const Eigen::ArrayXf>(h, n) - m);
    }
    return s2 * inv_n - mean * mean;
  }
  // Mean squared central-difference gradient over the pixels with both neighbours.
  double f = 0;
  if (adj) std::fill(adj, adj + n, 0.0f);
  for (int j = 0; j < hh; ++j) {
    for (int i = 0; i < w; ++i) {
      const size_t q = static_cast<size_t>(j) * w + i;
      if (i > 0 && i + 1 < w) {
        const double gx = 0.5 * (h[q + 1] - h[q - 1]);
        f += gx * gx;
        if (adj) {
          adj[q + 1] += static_cast<float>(gx * inv_n);
          adj[q - 1] -= static_cast<float>(gx * inv_n);
        }
      }
      if (j > 0 && j + 1 < hh) {
        const double gy = 0.5 * (h[q + w] - h[q - w]);
        f += gy * gy;
        if (adj) {
          adj[q + w] += static_cast<float>(gy * inv_n);
          adj[q - w] -= static_cast<float>(gy * inv_n);
        }
      }
    }
  }
  return f * inv_n;
}

// Bilinear votes of every stride-th event into a (w+2) x (h+2) image with a one-pixel border
// (pixel (i, j) of the IWE is (i+1, j+1) there), so a vote needs no bounds checks; the border is
// dropped afterwards. The m-th event used (k = m stride) leaves its cell (the padded index of its
// top-left pixel, -1 when it does not vote) and its position in the cell (fa, fb) for gather_all.
template <WarpModel M>
void vote_all(const CmaxEvents& ev, const double* p, double shift, double scale, const float* weights, bool polarity,
              int stride, float* pad, int w, int h, int32_t* cell, float* fa, float* fb) {
  const size_t n = ev.size();
  const int pw = w + 2;
  for (size_t k = 0, m = 0; k < n; k += stride, ++m) {
    double u, v;
    cell[m] = -1;
    if (!warp_k<M>(ev, k, p, shift, &u, &v, nullptr, nullptr)) continue;
    const double lu = (u + 0.5) * scale + 0.5, lv = (v + 0.5) * scale + 0.5;  // +1: padded coordinates
    if (!(lu > 0.0 && lv > 0.0 && lu < w + 1 && lv < h + 1)) continue;
    const int i = static_cast<int>(lu), j = static_cast<int>(lv);
    const float a = static_cast<float>(lu - i), b = static_cast<float>(lv - j);
    const int c = j * pw + i;
    cell[m] = c, fa[m] = a, fb[m] = b;
    float wk = weights ? weights[k] : 1.0f;
    if (polarity) wk *= ev.pol[k];
    float* q = pad + c;
    const float wb = wk * b, wb1 = wk - wb;
    q[0] += wb1 - a * wb1;
    q[1] += a * wb1;
    q[pw] += wb - a * wb;
    q[pw + 1] += a * wb;
  }
}

// dF/dp from dF/dIWE (adj, padded like the votes, zero border): the chain rule through each
// event's bilinear vote (its cell and position from vote_all) and its warp Jacobian.
template <WarpModel M, int D>
void gather_all(const CmaxEvents& ev, const double* p, double shift, double scale, const float* weights,
                bool polarity, int stride, const float* pad, int w, const int32_t* cell, const float* fa,
                const float* fb, double* grad) {
  const size_t n = ev.size();
  const int pw = w + 2;
  double g[D] = {};
  for (size_t k = 0, m = 0; k < n; k += stride, ++m) {
    const int c = cell[m];
    if (c < 0) continue;
    const float a = fa[m], b = fb[m];
    const float* q = pad + c;
    // d/da and d/db of the bilinear vote weights (1-a)(1-b), a(1-b), (1-a)b, ab.
    const float du = (1 - b) * (q[1] - q[0]) + b * (q[pw + 1] - q[pw]);
    const float dv = (1 - a) * (q[pw] - q[0]) + a * (q[pw + 1] - q[1]);
    double u, v, Ju[D], Jv[D];
    warp_k<M>(ev, k, p, shift, &u, &v, Ju, Jv);  // votes, so the warp is valid
    double wk = weights ? weights[k] : 1.0;
    if (polarity) wk *= ev.pol[k];
    const double cu = wk * scale * du, cv = wk * scale * dv;
    for (int d = 0; d < D; ++d) g[d] += cu * Ju[d] + cv * Jv[d];
  }
  for (int d = 0; d < D; ++d) grad[d] += g[d];
}

}  // namespace

const std::vector<WarpModel>& warp_models() {
  static const std::vector<WarpModel> all = {WarpModel::kFlow,     WarpModel::kSimilarity, WarpModel::kRotation,
                                             WarpModel::kSixDof,   WarpModel::kFlowAccel,  WarpModel::kSimilarityAccel};
  return all;
}

const char* warp_model_name(WarpModel m) {
  switch (m) {
    case WarpModel::kFlow: return "flow";
    case WarpModel::kSimilarity: return "similarity";
    case WarpModel::kRotation: return "rotation";
    case WarpModel::kSixDof: return "6dof";
    case WarpModel::kFlowAccel: return "flow_accel";
    case WarpModel::kSimilarityAccel: return "similarity_accel";
  }
  return "?";
}

std::optional<WarpModel> warp_model_from_name(const std::string& name) {
  for (WarpModel m : warp_models())
    if (name == warp_model_name(m)) return m;
  return std::nullopt;
}

std::string warp_model_names(const char* sep) {
  std::string out;
  for (WarpModel m : warp_models()) out += (out.empty() ? "" : sep) + std::string(warp_model_name(m));
  return out;
}

int warp_dof(WarpModel m) {
  switch (m) {
    case WarpModel::kFlow: return 2;
    case WarpModel::kSimilarity: return 4;
    case WarpModel::kRotation: return 3;
    case WarpModel::kSixDof: return 6;
    case WarpModel::kFlowAccel: return 4;
    case WarpModel::kSimilarityAccel: return 6;
  }
  return 0;
}

std::vector<std::string> warp_parameter_names(WarpModel m) {
  switch (m) {
    case WarpModel::kFlow: return {"vx_pxps", "vy_pxps"};
    case WarpModel::kSimilarity: return {"vx_pxps", "vy_pxps", "dilation_ps", "rotation_radps"};
    case WarpModel::kRotation: return {"wx_radps", "wy_radps", "wz_radps"};
    case WarpModel::kSixDof: return {"vx_mps", "vy_mps", "vz_mps", "wx_radps", "wy_radps", "wz_radps"};
    case WarpModel::kFlowAccel:
    case WarpModel::kSimilarityAccel: {
      std::vector<std::string> n = warp_parameter_names(warp_velocity_model(m));
      n.insert(n.end(), {"ax_pxps2", "ay_pxps2"});
      return n;
    }
  }
  return {};
}

WarpModel warp_velocity_model(WarpModel m) {
  if (m == WarpModel::kFlowAccel) return WarpModel::kFlow;
  if (m == WarpModel::kSimilarityAccel) return WarpModel::kSimilarity;
  return m;
}

Eigen::VectorXd warp_params_at(WarpModel m, const Eigen::VectorXd& p, double dt_s) {
  Eigen::VectorXd q = p;
  if (warp_velocity_model(m) != m && p.size() == warp_dof(m)) q.head<2>() += dt_s * p.tail<2>();
  return q;
}

CmaxObjective resolve_objective(CmaxObjective o, WarpModel m) {
  if (o != CmaxObjective::kAuto) return o;
  if (warp_velocity_model(m) == WarpModel::kFlow) return CmaxObjective::kVariance;
  if (m == WarpModel::kRotation) return CmaxObjective::kGradientMagnitude;
  return CmaxObjective::kNormalizedGradientMagnitude;
}

const char* cmax_objective_name(CmaxObjective o) {
  switch (o) {
    case CmaxObjective::kAuto: return "auto";
    case CmaxObjective::kVariance: return "variance";
    case CmaxObjective::kMeanSquare: return "mean_square";
    case CmaxObjective::kGradientMagnitude: return "gradient_magnitude";
    case CmaxObjective::kNormalizedGradientMagnitude: return "normalized_gradient_magnitude";
  }
  return "?";
}

std::optional<CmaxObjective> cmax_objective_from_name(const std::string& name) {
  for (CmaxObjective o : {CmaxObjective::kAuto, CmaxObjective::kVariance, CmaxObjective::kMeanSquare, CmaxObjective::kGradientMagnitude,
                          CmaxObjective::kNormalizedGradientMagnitude})
    if (name == cmax_objective_name(o)) return o;
  return std::nullopt;
}

bool WarpGeometry::Validate(std::string* why) const {
  if (!warp_geometry_table().check(*this, why)) return false;
  if (plane_distance_m > 0 && plane_normal_c.norm() < 1e-12) return validation_failed(why, "plane_normal must be non-zero");
  return true;
}

void CmaxEvents::reserve(size_t n) {
  for (auto* v : {&x, &y, &dt_s, &pol, &xn, &yn, &rho}) v->reserve(n);
}

void CmaxEvents::clear() {
  for (auto* v : {&x, &y, &dt_s, &pol, &xn, &yn, &rho}) v->clear();
  dt_min_ = dt_max_ = 0;
}

void pixel_dither(int64_t t_ns, float x, float y, float* ox, float* oy) {
  uint64_t z = static_cast<uint64_t>(t_ns) * 0x9E3779B97F4A7C15ULL ^
               (static_cast<uint64_t>(static_cast<uint32_t>(static_cast<int32_t>(x))) << 32 |
                static_cast<uint32_t>(static_cast<int32_t>(y)));
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  z ^= z >> 31;
  *ox = static_cast<float>(static_cast<double>(z >> 40) * 0x1.0p-24 - 0.5);
  *oy = static_cast<float>(static_cast<double>((z >> 16) & 0xFFFFFF) * 0x1.0p-24 - 0.5);
}

CmaxEvents CmaxEvents::select(const std::vector<uint32_t>& indices) const {
  CmaxEvents out(t_ref_ns_, geometry_);
  out.reserve(indices.size());
  bool first = true;
  for (uint32_t k : indices) {
    out.x.push_back(x[k]);
    out.y.push_back(y[k]);
    out.dt_s.push_back(dt_s[k]);
    out.pol.push_back(pol[k]);
    out.xn.push_back(xn[k]);
    out.yn.push_back(yn[k]);
    out.rho.push_back(rho[k]);
    const double dt = dt_s[k];
    out.dt_min_ = first ? dt : std::min(out.dt_min_, dt);
    out.dt_max_ = first ? dt : std::max(out.dt_max_, dt);
    first = false;
  }
  return out;
}

void CmaxEvents::push_back(float px, float py, int64_t t_ns, int polarity) {
  const double dt = static_cast<double>(t_ns - t_ref_ns_) * 1e-9;
  if (x.empty()) {
    dt_min_ = dt_max_ = dt;
  } else {
    dt_min_ = std::min(dt_min_, dt);
    dt_max_ = std::max(dt_max_, dt);
  }
  x.push_back(px);
  y.push_back(py);
  dt_s.push_back(static_cast<float>(dt));
  pol.push_back(polarity >= 0 ? 1.0f : -1.0f);
  const double bx = (px - geometry_.cx) / geometry_.fx, by = (py - geometry_.cy) / geometry_.fy;
  xn.push_back(static_cast<float>(bx));
  yn.push_back(static_cast<float>(by));
  double r = 1.0 / geometry_.depth_m;
  if (geometry_.plane_distance_m > 0) {
    const Eigen::Vector3d n = geometry_.plane_normal_c.normalized();
    r = std::max(0.0, n.dot(Eigen::Vector3d(bx, by, 1.0)) / geometry_.plane_distance_m);
  }
  rho.push_back(static_cast<float>(r));
}

bool warp_event(WarpModel m, const CmaxEvents& ev, size_t k, const Eigen::VectorXd& p, Eigen::Vector2d* warped,
                Eigen::Matrix<double, 2, Eigen::Dynamic>* J, double dt_shift_s) {
  const int d = warp_dof(m);
  if (p.size() != d) throw std::invalid_argument("warp_event: parameter vector has the wrong size");
  double Ju[6], Jv[6], u = 0, v = 0;
  double* ju = J ? Ju : nullptr;
  double* jv = J ? Jv : nullptr;
  bool ok = false;
  switch (m) {
    case WarpModel::kFlow: ok = warp_k<WarpModel::kFlow>(ev, k, p.data(), dt_shift_s, &u, &v, ju, jv); break;
    case WarpModel::kSimilarity: ok = warp_k<WarpModel::kSimilarity>(ev, k, p.data(), dt_shift_s, &u, &v, ju, jv); break;
    case WarpModel::kRotation: ok = warp_k<WarpModel::kRotation>(ev, k, p.data(), dt_shift_s, &u, &v, ju, jv); break;
    case WarpModel::kSixDof: ok = warp_k<WarpModel::kSixDof>(ev, k, p.data(), dt_shift_s, &u, &v, ju, jv); break;
    case WarpModel::kFlowAccel: ok = warp_k<WarpModel::kFlowAccel>(ev, k, p.data(), dt_shift_s, &u, &v, ju, jv); break;
    case WarpModel::kSimilarityAccel: ok = warp_k<WarpModel::kSimilarityAccel>(ev, k, p.data(), dt_shift_s, &u, &v, ju, jv); break;
  }
  if (!ok) return false;
  *warped = Eigen::Vector2d(u, v);
  if (J) {
    J->resize(2, d);
    for (int i = 0; i < d; ++i) (*J)(0, i) = Ju[i], (*J)(1, i) = Jv[i];
  }
  return true;
}

void sample_at_warped(const ImageF& img, WarpModel m, const CmaxEvents& ev, const Eigen::VectorXd& p,
                      std::vector<float>* out) {
  if (p.size() != warp_dof(m)) throw std::invalid_argument("sample_at_warped: parameter vector has the wrong size");
  out->assign(ev.size(), 0.0f);
  const int w = static_cast<int>(img.cols()), h = static_cast<int>(img.rows());
  auto run = [&](auto tag) {
    constexpr WarpModel M = decltype(tag)::value;
    for (size_t k = 0; k < ev.size(); ++k) {
      double u, v;
      if (!warp_k<M>(ev, k, p.data(), 0.0, &u, &v, nullptr, nullptr)) continue;
      if (!(u > -1.0 && v > -1.0 && u < w && v < h)) continue;
      const int i = static_cast<int>(u + 1.0) - 1, j = static_cast<int>(v + 1.0) - 1;
      const float a = static_cast<float>(u - i), b = static_cast<float>(v - j);
      auto at = [&](int ii, int jj) { return (ii >= 0 && jj >= 0 && ii < w && jj < h) ? img(jj, ii) : 0.0f; };
      (*out)[k] = (1 - a) * (1 - b) * at(i, j) + a * (1 - b) * at(i + 1, j) + (1 - a) * b * at(i, j + 1) + a * b * at(i + 1, j + 1);
    }
  };
  switch (m) {
    case WarpModel::kFlow: run(std::integral_constant<WarpModel, WarpModel::kFlow>()); break;
    case WarpModel::kSimilarity: run(std::integral_constant<WarpModel, WarpModel::kSimilarity>()); break;
    case WarpModel::kRotation: run(std::integral_constant<WarpModel, WarpModel::kRotation>()); break;
    case WarpModel::kSixDof: run(std::integral_constant<WarpModel, WarpModel::kSixDof>()); break;
    case WarpModel::kFlowAccel: run(std::integral_constant<WarpModel, WarpModel::kFlowAccel>()); break;
    case WarpModel::kSimilarityAccel: run(std::integral_constant<WarpModel, WarpModel::kSimilarityAccel>()); break;
  }
}

bool CmaxOptions::Validate(std::string* why) const {
  // The table's check covers the geometry's keys; its Validate adds the conditions between them.
  return cmax_table().check(*this, why) && geometry.Validate(why);
}

ContrastMaximizer::ContrastMaximizer(const CmaxOptions& options) : options_(options) {
  std::string why;
  if (!options_.Validate(&why)) throw std::invalid_argument("contrast maximisation options: " + why);
  gaussian_kernel(options_.blur_sigma_px, &kernel_);
  objective_ = resolve_objective(options_.objective, options_.model);
}

double ContrastMaximizer::plain_objective(const CmaxEvents& ev, const Eigen::VectorXd& p, int level,
                                          const float* weights, int stride, double dt_shift,
                                          Eigen::VectorXd* gradient) {
  const int w = (options_.width + (1 << level) - 1) >> level, h = (options_.height + (1 << level) - 1) >> level;
  const int pw = w + 2;
  const size_t n = static_cast<size_t>(w) * h;
  const size_t np = static_cast<size_t>(pw) * (h + 2);
  const size_t used = (ev.size() + stride - 1) / stride;
  pad_.assign(np, 0.0f);
  img_.resize(n);
  tmp_.resize(n + w + 2 * kernel_.size());
  cell_.resize(used);
  fa_.resize(used);
  fb_.resize(used);
  const double scale = 1.0 / (1 << level);
  const bool pol = options_.use_polarity;
  const double* pp = p.data();
  float* pad = pad_.data();
  int32_t* cell = cell_.data();
  float *fa = fa_.data(), *fb = fb_.data();
  switch (options_.model) {
    case WarpModel::kFlow: vote_all<WarpModel::kFlow>(ev, pp, dt_shift, scale, weights, pol, stride, pad, w, h, cell, fa, fb); break;
    case WarpModel::kSimilarity: vote_all<WarpModel::kSimilarity>(ev, pp, dt_shift, scale, weights, pol, stride, pad, w, h, cell, fa, fb); break;
    case WarpModel::kRotation: vote_all<WarpModel::kRotation>(ev, pp, dt_shift, scale, weights, pol, stride, pad, w, h, cell, fa, fb); break;
    case WarpModel::kSixDof: vote_all<WarpModel::kSixDof>(ev, pp, dt_shift, scale, weights, pol, stride, pad, w, h, cell, fa, fb); break;
    case WarpModel::kFlowAccel: vote_all<WarpModel::kFlowAccel>(ev, pp, dt_shift, scale, weights, pol, stride, pad, w, h, cell, fa, fb); break;
    case WarpModel::kSimilarityAccel: vote_all<WarpModel::kSimilarityAccel>(ev, pp, dt_shift, scale, weights, pol, stride, pad, w, h, cell, fa, fb); break;
  }
  // The IWE is the padded image's interior, blurred.
  blur(pad + pw + 1, pw, img_.data(), w, tmp_.data(), w, h, kernel_);
  const CmaxObjective inner = objective_ == CmaxObjective::kNormalizedGradientMagnitude
                                  ? CmaxObjective::kGradientMagnitude
                                  : objective_;
  if (!gradient) return image_objective(inner, img_.data(), w, h, nullptr);
  adj_.resize(n);
  const double f = image_objective(inner, img_.data(), w, h, adj_.data());
  // dF/dIWE = blur^T dF/dh into the padded image's interior, with a zero border.
  blur(adj_.data(), w, pad + pw + 1, pw, tmp_.data(), w, h, kernel_);
  std::fill(pad, pad + pw, 0.0f);
  std::fill(pad + np - pw, pad + np, 0.0f);
  for (int j = 1; j <= h; ++j) pad[static_cast<size_t>(j) * pw] = pad[static_cast<size_t>(j) * pw + pw - 1] = 0.0f;
  double* g = gradient->data();
  switch (options_.model) {
    case WarpModel::kFlow: gather_all<WarpModel::kFlow, 2>(ev, pp, dt_shift, scale, weights, pol, stride, pad, w, cell, fa, fb, g); break;
    case WarpModel::kSimilarity: gather_all<WarpModel::kSimilarity, 4>(ev, pp, dt_shift, scale, weights, pol, stride, pad, w, cell, fa, fb, g); break;
    case WarpModel::kRotation: gather_all<WarpModel::kRotation, 3>(ev, pp, dt_shift, scale, weights, pol, stride, pad, w, cell, fa, fb, g); break;
    case WarpModel::kSixDof: gather_all<WarpModel::kSixDof, 6>(ev, pp, dt_shift, scale, weights, pol, stride, pad, w, cell, fa, fb, g); break;
    case WarpModel::kFlowAccel: gather_all<WarpModel::kFlowAccel, 4>(ev, pp, dt_shift, scale, weights, pol, stride, pad, w, cell, fa, fb, g); break;
    case WarpModel::kSimilarityAccel: gather_all<WarpModel::kSimilarityAccel, 6>(ev, pp, dt_shift, scale, weights, pol, stride, pad, w, cell, fa, fb, g); break;
  }
  return f;
}

double ContrastMaximizer::evaluate(const CmaxEvents& ev, const Eigen::VectorXd& p, int level, const float* weights,
                                   int stride, Eigen::VectorXd* gradient, double reference_value) {
  if (gradient) gradient->setZero(warp_dof(options_.model));
  if (objective_ != CmaxObjective::kNormalizedGradientMagnitude)
    return plain_objective(ev, p, level, weights, stride, 0.0, gradient);
  // Both ends of the window: the geometric mean of their objectives, normalised by the unwarped
  // IWE's value. A warp that contracts the events towards one end expands them towards the other,
  // and the product of the two ends' sharpness does not reward that.
  Eigen::VectorXd g1;
  if (gradient) g1.setZero(gradient->size());
  const double f0 = plain_objective(ev, p, level, weights, stride, ev.dt_min_s(), gradient);
  const double f1 = plain_objective(ev, p, level, weights, stride, ev.dt_max_s(), gradient ? &g1 : nullptr);
  if (!(f0 > 0 && f1 > 0)) {
    if (gradient) gradient->setZero();
    return 0.0;
  }
  const double F = std::sqrt(f0 * f1) / reference_value;
  if (gradient) *gradient = 0.5 * F * (*gradient / f0 + g1 / f1);
  return F;
}

double ContrastMaximizer::objective(const CmaxEvents& ev, const Eigen::VectorXd& p, int level, const float* weights,
                                    Eigen::VectorXd* gradient) {
  if (p.size() != warp_dof(options_.model)) throw std::invalid_argument("contrast maximisation: parameter vector has the wrong size");
  if (level < 0 || level >= 8) throw std::invalid_argument("contrast maximisation: level must be in [0, 7]");
  double ref = 1.0;
  if (objective_ == CmaxObjective::kNormalizedGradientMagnitude) {
    ref = plain_objective(ev, Eigen::VectorXd::Zero(p.size()), level, weights, 1, 0.0, nullptr);
    if (!(ref > 0)) ref = 1.0;
  }
  return evaluate(ev, p, level, weights, 1, gradient, ref);
}

ImageF ContrastMaximizer::iwe(const CmaxEvents& ev, const Eigen::VectorXd& p, const float* weights, bool blurred,
                              int level, double dt_shift_s) {
  if (p.size() != warp_dof(options_.model)) throw std::invalid_argument("contrast maximisation: parameter vector has the wrong size");
  const int w = (options_.width + (1 << level) - 1) >> level, h = (options_.height + (1 << level) - 1) >> level;
  const std::vector<float> k = kernel_;
  if (!blurred) kernel_.assign(1, 1.0f);
  plain_objective(ev, p, level, weights, 1, dt_shift_s, nullptr);
  kernel_ = k;
  ImageF out(h, w);
  std::copy(img_.begin(), img_.end(), out.data());
  return out;
}

CmaxResult ContrastMaximizer::maximize(const CmaxEvents& ev, const Eigen::VectorXd& init, const float* weights) {
  const int dof = warp_dof(options_.model);
  if (init.size() != 0 && init.size() != dof)
    throw std::invalid_argument("contrast maximisation: initial parameters have the wrong size");
  CmaxResult r;
  r.model = options_.model;
  r.objective_used = objective_;
  r.params = init.size() == dof ? init : Eigen::VectorXd::Zero(dof);
  if (!r.params.allFinite()) throw std::invalid_argument("contrast maximisation: initial parameters are not finite");
  r.events = static_cast<int>(ev.size());
  const Eigen::VectorXd zero = Eigen::VectorXd::Zero(dof);
  if (ev.empty()) {
    r.stop = "no_events";
    return r;
  }

  // Scale each parameter by the RMS displacement (level-0 px) it causes per unit, at the start,
  // so the optimiser works in pixels whatever the units.
  Eigen::VectorXd S = Eigen::VectorXd::Zero(dof);
  {
    const size_t step = std::max<size_t>(1, ev.size() / 4000);
    size_t used = 0;
    Eigen::Matrix<double, 2, Eigen::Dynamic> J;
    Eigen::Vector2d uv;
    for (size_t k = 0; k < ev.size(); k += step) {
      if (!warp_event(options_.model, ev, k, r.params, &uv, &J)) continue;
      S += J.colwise().squaredNorm().transpose();
      ++used;
    }
    if (used > 0) S = (S / static_cast<double>(used)).cwiseSqrt();
    for (int i = 0; i < dof; ++i)
      if (!(S[i] > 1e-12) || !finite(S[i])) S[i] = 1.0;
  }

  auto level_value = [&](const Eigen::VectorXd& p, int level, int stride, double ref) {
    return evaluate(ev, p, level, weights, stride, nullptr, ref);
  };
  auto reference = [&](int level, int stride) {
    if (objective_ != CmaxObjective::kNormalizedGradientMagnitude) return 1.0;
    const double v = plain_objective(ev, zero, level, weights, stride, 0.0, nullptr);
    return v > 0 ? v : 1.0;
  };

  const double ref0 = reference(0, 1);
  r.objective_zero = level_value(zero, 0, 1, ref0);
  r.objective_init = r.params == zero ? r.objective_zero : level_value(r.params, 0, 1, ref0);
  ++r.evaluations;

  Eigen::VectorXd theta = r.params;
  Eigen::MatrixXd H_prev;
  bool have_h = false;
  double f_prev_level = 0, f_level0 = 0;
  for (int level = options_.pyramid_levels - 1; level >= 0; --level) {
    const double lscale = static_cast<double>(1 << level);
    const double tol = level == 0 ? options_.tolerance_px : options_.coarse_tolerance_px;
    const int iterations_before = r.iterations, evaluations_before = r.evaluations;
    int stride = 1;
    if (level > 0 && options_.max_events_coarse > 0 && ev.size() > static_cast<size_t>(options_.max_events_coarse))
      stride = static_cast<int>((ev.size() + options_.max_events_coarse - 1) / options_.max_events_coarse);
    const double ref = level == 0 ? ref0 : reference(level, stride);
    // Minimise f(z) = -F(theta), z = S theta in level-0 px.
    auto eval = [&](const Eigen::VectorXd& z, Eigen::VectorXd* gz) {
      Eigen::VectorXd th = z.cwiseQuotient(S), g(dof);
      const double F = evaluate(ev, th, level, weights, stride, &g, ref);
      ++r.evaluations;
      *gz = -g.cwiseQuotient(S);
      return -F;
    };
    Eigen::VectorXd z = theta.cwiseProduct(S), g(dof);
    double f = eval(z, &g);
    const double step0 = std::max(0.5, options_.blur_sigma_px) * lscale;  // first step, level-0 px
    const double max_step = 4.0 * step0;
    if (!(g.norm() > 0) || !g.allFinite()) {
      r.stop = "zero_gradient";
      r.per_level.push_back({level, stride, 0, r.evaluations - evaluations_before, -f});
      theta = z.cwiseQuotient(S);
      if (level == 0) f_level0 = f;
      continue;
    }
    // Inverse Hessian: the previous level's, rescaled (the objective's curvature in level-0 px
    // goes as its value over the blur width squared, which quadruples per level), else a first
    // step of step0 along the gradient.
    Eigen::MatrixXd H = Eigen::MatrixXd::Identity(dof, dof) * (step0 / g.norm());
    if (have_h && f_prev_level < 0 && f < 0) H = H_prev * (0.25 * f_prev_level / f);
    r.stop = "max_iterations";
    for (int it = 0; it < options_.max_iterations; ++it) {
      ++r.iterations;
      Eigen::VectorXd d = -H * g;
      if (!(g.dot(d) < 0)) {  // not a descent direction: restart from steepest descent
        H = Eigen::MatrixXd::Identity(dof, dof) * (step0 / g.norm());
        d = -H * g;
      }
      if (d.norm() > max_step) d *= max_step / d.norm();
      // Once the curvature is known (it > 0), a quasi-Newton step below the tolerance means the
      // level has converged: evaluating it could move the events by less than the tolerance.
      if (it > 0 && d.norm() / lscale < tol) {
        r.stop = "converged";
        break;
      }
      double t = 1.0, f_new = f;
      Eigen::VectorXd g_new(dof), z_new;
      bool accepted = false;
      const double slope = g.dot(d);
      bool too_short = false;
      for (int ls = 0; ls < 12; ++ls) {
        if (ls > 0 && t * d.norm() / lscale < tol) {  // the same: backtracked below the tolerance
          too_short = true;
          break;
        }
        z_new = z + t * d;
        f_new = eval(z_new, &g_new);
        if (std::isfinite(f_new) && f_new <= f + 1e-4 * t * slope) {
          accepted = true;
          break;
        }
        // Minimum of the quadratic through f, the slope and f_new, kept in [0.1 t, 0.5 t].
        const double curv = f_new - f - slope * t;
        const double t_q = std::isfinite(f_new) && curv > 0 ? -slope * t * t / (2 * curv) : 0.5 * t;
        t = std::clamp(t_q, 0.1 * t, 0.5 * t);
      }
      if (too_short) {
        r.stop = "converged";
        break;
      }
      if (!accepted) {
        r.stop = "line_search";
        break;
      }
      const Eigen::VectorXd s = z_new - z, y = g_new - g;
      z = z_new;
      f = f_new;
      g = g_new;
      const double sy = s.dot(y);
      if (sy > 1e-12 * s.norm() * y.norm()) {
        if (it == 0) H *= sy / y.squaredNorm();
        const double rho = 1.0 / sy;
        const Eigen::MatrixXd I = Eigen::MatrixXd::Identity(dof, dof);
        H = (I - rho * s * y.transpose()) * H * (I - rho * y * s.transpose()) + rho * s * s.transpose();
      }
      if (s.norm() / lscale < tol) {
        r.stop = "converged";
        break;
      }
      if (!(g.norm() > 0)) {
        r.stop = "zero_gradient";
        break;
      }
    }
    H_prev = H;
    have_h = true;
    f_prev_level = f;
    r.per_level.push_back({level, stride, r.iterations - iterations_before, r.evaluations - evaluations_before, -f});
    theta = z.cwiseQuotient(S);
    if (level == 0) f_level0 = f;
  }
  r.params = theta;
  // Level 0 always uses every event, so its last value is the objective at theta.
  r.objective = -f_level0;
  if (!(r.objective >= r.objective_init) || !r.params.allFinite()) {
    r.params = init.size() == dof ? init : zero;
    r.objective = r.objective_init;
    r.stop = "kept_initial";
  }
  return r;
}

CmaxResult maximize_contrast(const CmaxEvents& ev, const CmaxOptions& options, const Eigen::VectorXd& init,
                             const float* weights) {
  ContrastMaximizer m(options);
  return m.maximize(ev, init, weights);
}

}  // namespace evio::mapping
