// Weighted least-squares Poisson reconstruction: the log intensity L whose forward-difference
// gradient best fits a gradient field whose edges carry unequal confidence, for the gradient EKF
// mosaic (gradient_mosaic.h, Kim et al. BMVC 2014) where unseen texels have no gradient
// information and young texels little. Same discretisation as poisson.h (forward differences,
// kNeumann or kPeriodicU boundary). Model:
//   minimise  E(L) = sum over existing edges  wx (L(j,i+1) - L(j,i) - gx(j,i))^2
//                                           + wy (L(j+1,i) - L(j,i) - gy(j,i))^2,
//   normal equations  A L = b,  A = -div(w grad .) (weighted graph Laplacian, symmetric positive
//   semi-definite, null space = constants when the weighted grid is connected), b = -div(w g).
// Solved by preconditioned conjugate gradients (Hestenes-Stiefel; Saad, "Iterative Methods for
// Sparse Linear Systems", alg. 9.1) from a warm start, by default the unweighted spectral solve
// (PoissonSolver::solve) of the same gradients. Every weight is raised to options.weight_floor, so
// the weighted grid is connected and weight-0 regions get the smooth (harmonic) fill of the floor
// term instead of making A singular there. The result has zero mean, like the spectral solve.
#pragma once

#include <string>

#include "evio/mapping/image.h"
#include "evio/mapping/poisson.h"

namespace evio::mapping {

enum class PoissonPreconditioner {
  kNone,    // plain CG
  kJacobi,  // diag(A)^-1
  // The unweighted Laplacian's inverse (PoissonSolver::solve_laplacian; one DCT/DFT solve per
  // iteration): exact for uniform weights. The default: on the mosaics it needs far fewer
  // iterations than the others (docs/design-notes.md, Mosaic).
  kSpectral,
  // S^-1/2 (-lap)^-1 S^-1/2 with S = diag(A) / diag(-lap) (each texel's mean incident edge weight):
  // the spectral inverse rescaled to the local weight level, exact for uniform weights of any value.
  // Slower than kSpectral on the mosaics (the rescaling spreads the spectrum where the weight
  // changes from texel to texel); kept for comparison.
  kScaledSpectral,
};
// "none", "jacobi", "spectral", "scaled_spectral".
const char* poisson_preconditioner_name(PoissonPreconditioner p);

struct WeightedPoissonOptions {
  // Edge weights below this are raised to it, dimensionless (weights are information relative to a
  // fully known gradient, 1). Makes A positive definite on zero-mean images; smaller
  // values let unseen texels pull less on seen ones (on exact gradients the seen error is about
  // 0.45 x the floor) but need more iterations. Default 0.03: over 1e-3..3e-2 the mosaic quality
  // does not change, and the larger floor needs the fewest iterations (docs/results/mosaic.md).
  double weight_floor = 3e-2;
  // Converged when ||b - A L||_2 <= tolerance * ||b||_2, dimensionless.
  double tolerance = 1e-4;
  // At most this many PCG iterations (one A product and one preconditioner application each),
  // count (0 returns the warm start).
  int max_iterations = 200;
  PoissonPreconditioner preconditioner = PoissonPreconditioner::kSpectral;
  bool Validate(std::string* why) const;
};

struct WeightedPoissonStats {
  int iterations = 0;                   // PCG iterations run
  double initial_relative_residual = 0;  // ||b - A L0|| / ||b|| at the warm start (0 when b = 0)
  double relative_residual = 0;          // ||b - A L|| / ||b|| at the end
  bool converged = false;                // relative_residual <= tolerance
};

class WeightedPoissonSolver {
 public:
  // width, height in px (>= 2 each); poisson: boundary (and the spectral solver used for the warm
  // start and the preconditioners). Throws std::invalid_argument when an Options struct does not
  // validate or the size is too small.
  WeightedPoissonSolver(int width, int height, const WeightedPoissonOptions& options = {},
                        const PoissonOptions& poisson = {});

  int width() const { return spectral_.width(); }
  int height() const { return spectral_.height(); }
  const WeightedPoissonOptions& options() const { return options_; }
  const PoissonSolver& spectral() const { return spectral_; }

  // L (H x W, zero mean) minimising E above. gx, gy: gradients on the u and v edges (log units per
  // px, poisson.h's convention; entries on non-existent edges ignored); wx, wy: their weights,
  // dimensionless, finite and >= 0 (1 = full information; raised to options.weight_floor).
  // warm_start (optional, H x W): the starting L; null = the unweighted spectral solve of (gx, gy).
  // L may alias warm_start. Throws std::invalid_argument on size mismatches, a null L, or negative
  // or non-finite weights. Const and thread-safe (own workspace per call).
  WeightedPoissonStats solve(const ImageD& gx, const ImageD& gy, const ImageD& wx, const ImageD& wy, ImageD* L,
                             const ImageD* warm_start = nullptr) const;

 private:
  WeightedPoissonOptions options_;
  PoissonSolver spectral_;
};

}  // namespace evio::mapping
