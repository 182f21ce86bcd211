// Weighted least-squares Poisson reconstruction by preconditioned conjugate gradients; model and
// conventions in weighted_poisson.h.
#include "evio/mapping/weighted_poisson.h"
#include "evio/mapping/option_tables.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace evio::mapping {
namespace {

void check_size(const char* what, const ImageD& m, int width, int height) {
  if (m.rows() != height || m.cols() != width)
    throw std::invalid_argument(std::string("weighted Poisson solver: ") + what + " is " + std::to_string(m.rows()) +
                                "x" + std::to_string(m.cols()) + " (rows x cols), expected " + std::to_string(height) +
                                "x" + std::to_string(width));
}

// The weighted grid: effective edge weights (0 on non-existent edges, else max(w, floor)).
struct WeightedGrid {
  int W = 0, H = 0;
  bool periodic = false;
  ImageD ex, ey;  // u edge (j,i)->(j,i+1 mod W), v edge (j,i)->(j+1,i)

  // out = A x = -div(w grad x).
  void apply(const ImageD& x, ImageD* out) const {
    out->resize(H, W);
    for (int j = 0; j < H; ++j) {
      const double* xr = x.data() + static_cast<size_t>(j) * W;
      const double* xd = j + 1 < H ? xr + W : nullptr;
      const double* xu = j > 0 ? xr - W : nullptr;
      const double* wxr = ex.data() + static_cast<size_t>(j) * W;
      const double* wyr = ey.data() + static_cast<size_t>(j) * W;
      const double* wyu = j > 0 ? wyr - W : nullptr;
      double* o = out->data() + static_cast<size_t>(j) * W;
      for (int i = 0; i < W; ++i) {
        const int ir = i + 1 < W ? i + 1 : 0;  // ex is 0 on the last column unless periodic
        const int il = i > 0 ? i - 1 : W - 1;   // ex(j, W-1) is 0 unless periodic
        double s = wxr[i] * (xr[i] - xr[ir]) + wxr[il] * (xr[i] - xr[il]);
        if (xd) s += wyr[i] * (xr[i] - xd[i]);
        if (xu) s += wyu[i] * (xr[i] - xu[i]);
        o[i] = s;
      }
    }
  }
  // diag(A): the sum of a texel's incident edge weights.
  ImageD diagonal() const {
    ImageD d(H, W);
    for (int j = 0; j < H; ++j)
      for (int i = 0; i < W; ++i) {
        const int il = i > 0 ? i - 1 : W - 1;
        double s = ex(j, i) + ex(j, il) + ey(j, i);
        if (j > 0) s += ey(j - 1, i);
        d(j, i) = s;
      }
    return d;
  }
  // diag(-lap): the number of existing incident edges.
  ImageD degree() const {
    ImageD d(H, W);
    for (int j = 0; j < H; ++j)
      for (int i = 0; i < W; ++i) {
        int n = 0;
        if (i + 1 < W || periodic) ++n;
        if (i > 0 || periodic) ++n;
        if (j + 1 < H) ++n;
        if (j > 0) ++n;
        d(j, i) = n;
      }
    return d;
  }
};

double dot(const ImageD& a, const ImageD& b) { return (a.array() * b.array()).sum(); }

}  // namespace

const char* poisson_preconditioner_name(PoissonPreconditioner p) {
  switch (p) {
    case PoissonPreconditioner::kNone: return "none";
    case PoissonPreconditioner::kJacobi: return "jacobi";
    case PoissonPreconditioner::kSpectral: return "spectral";
    case PoissonPreconditioner::kScaledSpectral: return "scaled_spectral";
  }
  return "?";
}

bool WeightedPoissonOptions::Validate(std::string* why) const { return weighted_poisson_table().check(*this, why); }

WeightedPoissonSolver::WeightedPoissonSolver(int width, int height, const WeightedPoissonOptions& options,
                                             const PoissonOptions& poisson)
    : options_(options), spectral_(width, height, poisson) {
  std::string why;
  if (!options_.Validate(&why)) throw std::invalid_argument("WeightedPoissonOptions: " + why);
}

WeightedPoissonStats WeightedPoissonSolver::solve(const ImageD& gx, const ImageD& gy, const ImageD& wx,
                                                  const ImageD& wy, ImageD* L, const ImageD* warm_start) const {
  const int W = width(), H = height();
  if (L == nullptr) throw std::invalid_argument("weighted Poisson solver: null output");
  check_size("gx", gx, W, H);
  check_size("gy", gy, W, H);
  check_size("wx", wx, W, H);
  check_size("wy", wy, W, H);
  if (warm_start) check_size("warm_start", *warm_start, W, H);
  for (const ImageD* w : {&wx, &wy})
    for (Eigen::Index k = 0; k < w->size(); ++k)
      if (!(std::isfinite(w->data()[k]) && w->data()[k] >= 0.0))
        throw std::invalid_argument("weighted Poisson solver: weights must be finite and >= 0, found " +
                                    std::to_string(w->data()[k]));

  WeightedGrid grid;
  grid.W = W;
  grid.H = H;
  grid.periodic = spectral_.options().boundary == PoissonBoundary::kPeriodicU;
  grid.ex.setZero(H, W);
  grid.ey.setZero(H, W);
  const double floor = options_.weight_floor;
  for (int j = 0; j < H; ++j)
    for (int i = 0; i < W; ++i) {
      if (i + 1 < W || grid.periodic) grid.ex(j, i) = std::max(wx(j, i), floor);
      if (j + 1 < H) grid.ey(j, i) = std::max(wy(j, i), floor);
    }
  // b = -div(w g) (edges that do not exist have weight 0).
  ImageD b(H, W);
  for (int j = 0; j < H; ++j)
    for (int i = 0; i < W; ++i) {
      const int il = i > 0 ? i - 1 : W - 1;
      double s = grid.ex(j, i) * gx(j, i) - grid.ex(j, il) * gx(j, il) + grid.ey(j, i) * gy(j, i);
      if (j > 0) s -= grid.ey(j - 1, i) * gy(j - 1, i);
      b(j, i) = -s;
    }

  ImageD x;
  if (warm_start) {
    x = *warm_start;
  } else {
    spectral_.solve(gx, gy, &x);
  }

  // Preconditioner z = M r.
  ImageD inv_diag, inv_sqrt_scale;
  if (options_.preconditioner == PoissonPreconditioner::kJacobi) {
    inv_diag = grid.diagonal().cwiseInverse();
  } else if (options_.preconditioner == PoissonPreconditioner::kScaledSpectral) {
    inv_sqrt_scale = (grid.degree().array() / grid.diagonal().array()).sqrt().matrix();
  }
  ImageD tmp;
  auto precondition = [&](const ImageD& r, ImageD* z) {
    switch (options_.preconditioner) {
      case PoissonPreconditioner::kNone:
        *z = r;
        return;
      case PoissonPreconditioner::kJacobi:
        *z = (r.array() * inv_diag.array()).matrix();
        return;
      case PoissonPreconditioner::kSpectral:
        spectral_.solve_laplacian(r, z);  // lap z = r - mean(r): z = (-lap)^-1 applied to -r
        *z = -*z;
        return;
      case PoissonPreconditioner::kScaledSpectral:
        tmp = (r.array() * inv_sqrt_scale.array()).matrix();
        spectral_.solve_laplacian(tmp, z);
        *z = (-z->array() * inv_sqrt_scale.array()).matrix();
        return;
    }
  };

  WeightedPoissonStats st;
  const double b_norm = b.norm();
  ImageD Ax;
  grid.apply(x, &Ax);
  ImageD r = b - Ax;
  if (b_norm == 0.0) {
    // Zero data: the minimiser is the constant (zero-mean: 0) whatever the start.
    L->setZero(H, W);
    st.converged = true;
    return st;
  }
  st.initial_relative_residual = st.relative_residual = r.norm() / b_norm;
  const double target = options_.tolerance * b_norm;
  if (r.norm() > target && options_.max_iterations > 0) {
    ImageD z, p, Ap;
    precondition(r, &z);
    p = z;
    double rz = dot(r, z);
    for (int k = 0; k < options_.max_iterations; ++k) {
      grid.apply(p, &Ap);
      const double pAp = dot(p, Ap);
      if (!(pAp > 0.0)) break;  // p in the null space (constants) or round-off: nothing left to gain
      const double alpha = rz / pAp;
      x += alpha * p;
      r -= alpha * Ap;
      ++st.iterations;
      const double rn = r.norm();
      st.relative_residual = rn / b_norm;
      if (rn <= target) break;
      precondition(r, &z);
      const double rz_new = dot(r, z);
      p = z + (rz_new / rz) * p;
      rz = rz_new;
    }
  }
  st.converged = st.relative_residual <= options_.tolerance;
  *L = (x.array() - x.mean()).matrix();
  return st;
}

}  // namespace evio::mapping
