// Poisson reconstruction of a log-intensity image from its gradient field, as in the mapping half
// of Kim et al., "Simultaneous Mosaicing and Tracking with an Event Camera" (BMVC 2014): the mosaic
// EKF estimates per-pixel gradients, and the image is their least-squares integral.
//
// Discretisation (exact, so that a gradient field that is the discrete gradient of some L gives L
// back up to a constant, to round-off). L is H x W, row j (v, down) and column i (u, right).
//   Forward-difference gradient:   gx(j,i) = L(j,i+1) - L(j,i),   gy(j,i) = L(j+1,i) - L(j,i).
//     Boundaries: kNeumann:    gx(j,W-1) = 0 and gy(H-1,i) = 0 (those edges do not exist);
//                 kPeriodicU:  gx(j,W-1) = L(j,0) - L(j,W-1) (u wraps, the equirectangular
//                              mosaic's longitude), gy(H-1,i) = 0 (Neumann at the poles).
//     On input, entries of the gradient on non-existent edges are ignored.
//   Divergence with backward differences (the negative adjoint of the gradient above):
//     div(j,i) = gx(j,i) - gx(j,i-1) + gy(j,i) - gy(j-1,i),  with terms on non-existent edges = 0
//     (kPeriodicU: gx(j,-1) = gx(j,W-1)).
//   Laplacian: lap(L) = div(grad L), the graph Laplacian of the 4-neighbour grid (a cycle along u
//   for kPeriodicU); 1-D eigenvalues -4 sin^2(pi k / (2N)) (Neumann, DCT-II basis) and
//   -4 sin^2(pi k / N) (periodic, DFT basis); 2-D eigenvalue = sum of the two.
// The solve returns the minimiser of sum over existing edges (grad L - g)^2, i.e. lap(L) = div(g),
// with the (0,0) mode (the constant) set to zero: the full solve's result has zero mean.
#pragma once

#include <memory>
#include <string>

#include "evio/mapping/image.h"

namespace evio::mapping {

enum class PoissonBoundary {
  kNeumann,    // Neumann on all four sides (an ordinary image)
  kPeriodicU,  // periodic in u (columns wrap), Neumann in v: the equirectangular mosaic
};

// Pixel rectangle [x, x + width) x [y, y + height). For kPeriodicU, x may be any integer and the
// columns are taken modulo W (a rectangle may straddle the seam); for kNeumann it must lie inside.
struct PixelRect {
  int x = 0;       // px, first column
  int y = 0;       // px, first row
  int width = 0;   // px
  int height = 0;  // px
};

struct PoissonOptions {
  PoissonBoundary boundary = PoissonBoundary::kPeriodicU;  // see the discretisation above
  // Longest rectangle side (px) solved by the region solver's dense separable eigenbasis (cost
  // O(w h (w + h)) plus O(w^3 + h^3) set-up); longer regions fall back to a full solve.
  int max_region_side = 512;
  bool Validate(std::string* why) const;
};

// The discrete gradient of L as defined above (entries on non-existent edges set to 0).
void forward_gradient(const ImageD& L, PoissonBoundary boundary, ImageD* gx, ImageD* gy);
// The backward-difference divergence of (gx, gy) as defined above.
ImageD divergence(const ImageD& gx, const ImageD& gy, PoissonBoundary boundary);
// lap(L) = divergence(forward_gradient(L)).
ImageD laplacian(const ImageD& L, PoissonBoundary boundary);

class PoissonSolver {
 public:
  // width, height in px (>= 2 each; throws std::invalid_argument otherwise or when the options
  // do not validate). Even sizes use OpenCV's DCT/DFT (O(N log N)); an odd width or height falls
  // back to dense separable eigenbases (O(W H (W + H)): fine for small images only).
  PoissonSolver(int width, int height, const PoissonOptions& options = {});

  int width() const { return width_; }
  int height() const { return height_; }
  const PoissonOptions& options() const { return options_; }

  // Full solve: L (zero mean) from gx = dL/du, gy = dL/dv (log units per pixel, forward-difference
  // convention above). weight (optional, H x W, values in [0, 1]) multiplies both gradients of a
  // pixel (its right and down edges) before the divergence: weight 0 = "no gradient information",
  // treated as a zero gradient (not a weighted least-squares fit: the spectral solve needs a
  // constant-coefficient operator). Throws std::invalid_argument on size mismatches.
  // Computed in the precision of the inputs. solve() is const and allocates its own workspace:
  // concurrent calls on one solver are safe.
  void solve(const ImageD& gx, const ImageD& gy, ImageD* L, const ImageD* weight = nullptr) const;
  void solve(const ImageF& gx, const ImageF& gy, ImageF* L, const ImageF* weight = nullptr) const;

  // The inverse Laplacian: L with lap(L) = f - mean(f) and zero mean (f: H x W, any units; the
  // mean of f is removed first, as no L can produce it). Same transforms as solve(); the weighted
  // solver (weighted_poisson.h) uses it as its preconditioner. Double precision only. Throws
  // std::invalid_argument on a size mismatch or null output.
  void solve_laplacian(const ImageD& f, ImageD* L) const;

  // Incremental solve on a region: re-solves the pixels of rect (after clipping its rows to
  // [0, H)) with every pixel outside it held at its current value in *L (Dirichlet data), edges
  // leaving the image keep their Neumann/periodic treatment. The result is the exact minimiser of
  // the same least-squares energy over the rectangle's pixels (a one-shot solve in the separable
  // eigenbasis of the rectangle's Laplacian, no iterations), so when the gradients changed only on
  // edges incident to the rectangle and remain integrable, it equals the full solve up to a
  // constant. The offset is set by the surrounding pixels (no zero-mean re-centring). Falls back to
  // a full solve (zero mean) when the rectangle covers the whole image or a side exceeds
  // options.max_region_side. Throws std::invalid_argument for an empty rectangle, one outside the
  // image (kNeumann), wider than W, or size mismatches. Double precision only.
  // The rectangle is grown to sides that are multiples of 16 px (within the image) so that the
  // eigenbases of its 1-D operators can be cached and reused (thread-safe cache shared by copies
  // of the solver). Returns the rectangle actually re-solved (the grown one, x in [0, W); the whole
  // image after a fallback): every pixel of *L that changed lies in it.
  PixelRect solve_region(const ImageD& gx, const ImageD& gy, const PixelRect& rect, ImageD* L,
                    const ImageD* weight = nullptr) const;

 private:
  struct EigenCache;
  int width_;
  int height_;
  PoissonOptions options_;
  std::shared_ptr<EigenCache> cache_;
};

}  // namespace evio::mapping
