// Pixel-wise EKF on the log-intensity gradient of an equirectangular mosaic, the mapping half of
// Kim et al., "Simultaneous Mosaicing and Tracking with an Event Camera" (BMVC 2014), with Poisson
// reconstruction of the log intensity (poisson.h).
//
// Model. State per mosaic pixel: g = (dL/du, dL/dv), L = log intensity, in log units per mosaic
// pixel, with 2x2 covariance P; prior g = 0, P = initial_gradient_std^2 I; static scene (no
// process noise; the covariance floor below plays that role). An event of polarity p (+1/-1) at a
// sensor pixel whose view moves over the mosaic with velocity v (mosaic px/s), whose previous
// event at the same sensor pixel was tau seconds earlier, obeys brightness constancy
//   (g . v) tau = p C     (C = contrast threshold, log units),
// used as the scalar measurement z = 1/tau (1/s) with
//   h(g) = p (g . v) / C,   H = p v^T / C,
//   R = measurement_std_abs^2 + (measurement_relative_std * z)^2   (1/s^2).
// R grows with z because the dominant error is relative: the threshold C varies from pixel to
// pixel and event to event (~10-20 %), which scales 1/tau; the absolute term covers timestamp
// jitter and long-tau events. The update is the Joseph form, then symmetrised, then each
// eigenvalue of P is floored at min_gradient_std^2 (keeps P symmetric positive definite through
// 1e6 updates and lets the filter follow slow changes).
// Association: the event updates the nearest mosaic pixel, (floor(u) mod W, floor(v) clamped to
// [0, H-1]); no bilinear splitting (the four pixels' updates would be correlated).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "evio/calib/equirectangular.h"
#include "evio/mapping/image.h"
#include "evio/mapping/poisson.h"
#include "evio/mapping/weighted_poisson.h"

namespace evio::mapping {

// One pixel's state of GradientMosaic in one 48-byte record: an update touches one cache line.
struct GradientMosaicPixelState {
  double gu, gv;         // gradient, log units / px
  double puu, puv, pvv;  // covariance, (log units / px)^2
  uint32_t count;        // accepted updates
  uint8_t viewed;        // mark_viewed (fits in the record's padding)
};

struct GradientMosaicOptions {
  int width = 1024;                   // px, mosaic columns (u, longitude; wraps)
  int height = 512;                   // px, mosaic rows (v, latitude; row 0 = up)
  double contrast_threshold = 0.2;    // C, log-intensity units per event
  double initial_gradient_std = 1.0;  // sigma0 of each gradient component, log units / mosaic px
  double measurement_std_abs = 10.0;  // absolute std of z = 1/tau, 1/s
  double measurement_relative_std = 0.2;  // std of z relative to z, dimensionless (not both 0)
  // Events with tau below this are skipped (bursts, refractory artefacts; their z = 1/tau would
  // claim |g . v| > C / min_tau_s, i.e. > 2e4 log units/s at the defaults), s.
  double min_tau_s = 1e-5;
  // Events whose mosaic velocity is slower than this carry no gradient information: skipped,
  // mosaic px/s.
  double min_speed_px_s = 1.0;
  // Floor on the std of P along any direction, log units / mosaic px (< initial_gradient_std).
  double min_gradient_std = 1e-3;
  // A pixel counts as "seen" (reconstructed, used by the tracker; unseen pixels' gradients are 0 in
  // the Poisson solve) once it has this many accepted updates and, when
  // seen_max_gradient_std > 0, the std of its gradient along every direction (sqrt of P's largest
  // eigenvalue) is at most seen_max_gradient_std, log units / mosaic px (0 = no such test).
  // The covariance test leaves out pixels observed along one direction only.
  int seen_min_observations = 1;
  double seen_max_gradient_std = 0.0;
  // update_segment: longest path between a pixel's two events that is still used, mosaic px.
  double max_path_px = 8.0;
  // Poisson solver for reconstruct(): kPeriodicU is the equirectangular mosaic's boundary;
  // poisson.max_region_side bounds the incremental solve.
  PoissonOptions poisson;
  // Weighted solve of reconstruct(..., PoissonWeighting::kInformation): weight floor, PCG
  // tolerance, iteration cap, preconditioner (weighted_poisson.h).
  WeightedPoissonOptions weighted_poisson;
  // Edge weight of the weighted solve: (weight_reference_std / std of the edge gradient)^2 capped
  // at 1 (edge_weights()), log units / mosaic px (>= min_gradient_std). min_gradient_std = pure
  // information weighting (weights grow with the number of updates up to the covariance floor);
  // larger values give full weight to every edge known at least this well. Default 0.03: the
  // error left after tracking does not shrink with a texel's update count, so weighting beyond
  // that level does not help (docs/design-notes.md, Mosaic).
  double weight_reference_std = 3e-2;
  // Weight of an edge between two texels that are not seen but were in the camera's view
  // (mark_viewed): no events there is evidence of a small gradient, which the EKF (updated by
  // events only) does not record; the edge's gradient is 0, dimensionless. Never-viewed
  // edges keep the prior's weight (raised to weighted_poisson.weight_floor).
  double viewed_edge_weight = 1.0;
  // reconstruct_map (the tracker's map): texels that were in the camera's view (mark_viewed) but
  // are not seen are known too, with the solve's value (flat where no events came), instead of
  // NaN. An unknown texel says nothing about a particle, so on a sparse scene (flat shapes with
  // edges) a particle that slides off the thin band of seen edge texels is not penalised. Default
  // false: it helps sparse scenes and hurts densely textured ones, where texels entering the view
  // count as known before their events are mapped (docs/design-notes.md, Mosaic).
  bool map_viewed_texels = false;
  bool Validate(std::string* why) const;
};

// How a full Poisson solve of the mosaic weighs its edge gradients.
enum class PoissonWeighting {
  kNone,  // unweighted spectral solve (poisson.h): an edge between unseen texels is a zero gradient at full weight
  // Weighted least squares (weighted_poisson.h) with each edge's weight the EKF information of its
  // gradient relative to weight_reference_std (GradientMosaic::edge_weights), seeded by the kNone solve.
  kInformation,
};
// "none", "information".
const char* poisson_weighting_name(PoissonWeighting w);

// Why update() skipped an event (counted in GradientMosaic::Stats).
enum class MosaicUpdate { kApplied, kNonFinite, kBadPolarity, kOutside, kTauTooSmall, kTooSlow, kPathTooLong };

struct MosaicReconstruction {
  ImageF log_intensity;  // H x W, log units up to a global offset (zero mean after a full solve)
  MaskU8 seen;           // H x W, 1 where the pixel is seen (GradientMosaicOptions::seen_*)
  bool full_solve = true;    // false: region (incremental) solve on `region`
  PixelRect region;          // the re-solved rectangle (whole image after a full solve)
  PoissonWeighting weighting = PoissonWeighting::kNone;  // of this solve
  // kInformation only: the unweighted spectral solve that seeded the PCG (H x W, zero mean; the
  // "before" of the weighted solve) and the PCG's statistics. Empty / default otherwise.
  ImageF unweighted_log_intensity;
  WeightedPoissonStats weighted_stats;
};

class GradientMosaic {
 public:
  enum class ReconstructMode {
    kAuto,         // full solve the first time or when the changed region is large, else region solve
    kFull,         // always a full (global least-squares) solve
    kIncremental,  // region solve on the changed rectangle whenever possible
  };
  struct Stats {
    uint64_t applied = 0;
    uint64_t non_finite = 0;    // non-finite input, or an update that would give non-finite state
    uint64_t bad_polarity = 0;  // polarity not +1 / -1
    uint64_t outside = 0;       // v outside [0, H]
    uint64_t tau_too_small = 0;
    uint64_t too_slow = 0;
    uint64_t path_too_long = 0;  // update_segment: the path was longer than max_path_px
  };

  // Throws std::invalid_argument when the options do not validate.
  explicit GradientMosaic(const GradientMosaicOptions& options);

  const GradientMosaicOptions& options() const { return options_; }
  int width() const { return options_.width; }
  int height() const { return options_.height; }

  // One event at continuous mosaic position uv (px; u wraps, v in [0, H]), its mosaic velocity
  // v_px_s (px/s), the time since the previous event at the same sensor pixel tau_s (s) and its
  // polarity (+1/-1). Returns false when a guard skipped it (state untouched).
  bool update(const Eigen::Vector2d& uv, const Eigen::Vector2d& v_px_s, double tau_s, int polarity) {
    return update_status(uv, v_px_s, tau_s, polarity) == MosaicUpdate::kApplied;
  }
  MosaicUpdate update_status(const Eigen::Vector2d& uv, const Eigen::Vector2d& v_px_s, double tau_s, int polarity);

  // One event given the mosaic positions of its sensor pixel at the previous event (uv_from) and
  // at this one (uv_to), tau_s apart. The contrast C was crossed along that path, so 1/tau measures
  // the gradient averaged over it: the update uses the mean velocity (uv_to - uv_from) / tau and
  // sits at the path's midpoint. Attaching it to uv_to instead (update() with the instantaneous
  // velocity) shifts every gradient by half a path along the motion: at 150 deg/s and a 12 ms
  // pixel period that is 2.5 px of a 1024-px mosaic, which the tracker then follows. u differences
  // wrap (the shorter way round). Paths longer than max_path_px are skipped (kPathTooLong): the
  // gradient along them is not close to constant.
  MosaicUpdate update_segment(const Eigen::Vector2d& uv_from, const Eigen::Vector2d& uv_to, double tau_s, int polarity);

  // Per-pixel state at column i, row j (unchecked indices).
  Eigen::Vector2d gradient(int i, int j) const {
    const PixelState& s = state_[index(i, j)];
    return {s.gu, s.gv};
  }
  Eigen::Matrix2d covariance(int i, int j) const {
    const PixelState& s = state_[index(i, j)];
    Eigen::Matrix2d P;
    P << s.puu, s.puv, s.puv, s.pvv;
    return P;
  }
  uint32_t observations(int i, int j) const { return state_[index(i, j)].count; }

  // Marks the texels around continuous mosaic position uv (px; u wraps, v clamped) as viewed: the
  // 4 x 4 texels whose centres are nearest to it, so that positions up to 4 texels apart leave no gaps.
  // Used by the weighted solve (viewed_edge_weight); the caller marks the camera's footprint.
  void mark_viewed(const Eigen::Vector2d& uv);
  MaskU8 viewed_mask() const;  // H x W, 1 where marked
  // Whole planes (H x W): gradient components, trace of P, accepted updates, seen mask.
  ImageF gradient_u() const;
  ImageF gradient_v() const;
  ImageF covariance_trace() const;
  Eigen::Matrix<uint32_t, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> observation_count() const;
  MaskU8 seen_mask() const;
  const Stats& stats() const { return stats_; }

  // Edge weights for the weighted solve (H x W each, dimensionless in [0, 1], poisson.h's edges:
  // wx on (j,i)->(j,i+1), wy on (j,i)->(j+1,i)): weight_reference_std^2 / var, capped at 1, where var is
  // the variance of the edge gradient reconstruct() uses: (P_a + P_b) / 4 of the edge's component
  // (P_uu for u edges, P_vv for v edges) when both texels are seen, the seen texel's when one is,
  // initial_gradient_std^2 (the prior: weight ~1e-3 at the defaults) when neither is, unless both
  // were viewed (mark_viewed): then viewed_edge_weight; 0 on edges that do not exist. The u-v
  // cross-covariance of a texel is left out (diagonal approximation).
  void edge_weights(ImageD* wx, ImageD* wy) const;

  // Log intensity from the gradient planes. Edge gradients for the solver (poisson.h's forward
  // differences, which sit between two pixel centres) are the mean of the two pixels' gradient
  // components when both are seen, the seen one's when one is, and 0 (no information) when
  // neither is; the u edge from the last column wraps to the first (kPeriodicU). Unseen pixels
  // receive the smooth (harmonic) fill of the solve and are marked 0 in `seen`.
  // weighting kNone: the solve is unweighted, so the zero gradients of unseen pixels are fitted
  // like data; where the seen region's gradients do not integrate to a field that is constant
  // across the unseen part, the mismatch spreads into the seen region (test: 48 of 64 rows seen,
  // RMS error 0.15 log units vs 0.014 fully seen). weighting kInformation removes it: a weighted
  // least-squares solve with edge_weights() (always a full solve, whatever the mode; the
  // unweighted solve it starts from is returned as unweighted_log_intensity).
  // kAuto/kIncremental re-solve only the bounding box (plus one pixel) of the pixels updated since
  // the previous call, holding the rest fixed: exact when the change is integrable, otherwise a
  // local approximation of the global least-squares solution; call with kFull now and then. The
  // box does not track u-wrap: updates on both sides of the seam give a full-width box (a full
  // solve once wider than poisson.max_region_side).
  MosaicReconstruction reconstruct(ReconstructMode mode = ReconstructMode::kAuto,
                                   PoissonWeighting weighting = PoissonWeighting::kNone);
  // The same solve as reconstruct(mode, kNone), written as a tracker's map: H x W row-major float
  // log intensity, NaN at unseen texels (frontend::LogIntensityMapView). Only the re-solved region
  // is written (the rest of *map is left as the earlier calls wrote it; every texel whose value or
  // seen state changed lies in the region), so a map kept across calls equals the full conversion
  // of reconstruct(mode)'s images without their full-size copies. A *map of another size is
  // resized and written whole. Returns the region written (x may exceed the width: columns wrap).
  PixelRect reconstruct_map(ReconstructMode mode, std::vector<float>* map);

  // The per-pixel state (gradients, covariances, counts, viewed marks) at one moment, to undo the
  // updates made after it (e.g. those made with a rotation later found wrong). restore() puts it
  // back; the next reconstruction is a full solve. Stats are not rolled back.
  class Checkpoint {
    friend class GradientMosaic;
    std::vector<GradientMosaicPixelState> state_;
  };
  Checkpoint checkpoint() const;
  // Throws std::invalid_argument for a checkpoint of another size (or an empty one).
  void restore(const Checkpoint& checkpoint);

 private:
  size_t index(int i, int j) const { return static_cast<size_t>(j) * options_.width + i; }
  void update_edges(int x0, int y0, int w, int h);  // edge gradients owned by those pixels
  PixelRect solve(ReconstructMode mode, PoissonWeighting weighting, MosaicReconstruction* out);

  GradientMosaicOptions options_;
  PoissonSolver solver_;
  WeightedPoissonSolver weighted_solver_;
  using PixelState = GradientMosaicPixelState;
  bool is_seen(const PixelState& p) const;  // seen_min_observations and seen_max_gradient_std
  std::vector<PixelState> state_;
  Stats stats_;
  ImageD edge_gu_, edge_gv_, log_intensity_;
  bool solved_once_ = false;
  int dirty_x0_, dirty_x1_, dirty_y0_, dirty_y1_;  // [x0, x1] x [y0, y1], empty when x1 < x0
};

// Velocity (mosaic px/s) of the mosaic point seen along a camera bearing while the camera rotates:
// d_w = R_w_c * bearing_c, d(d_w)/dt = omega_w x d_w, v = J_proj(d_w) * (omega_w x d_w).
// omega_w is the angular velocity in the world (mosaic) frame, rad/s (a gyro's body-frame rate
// omega_b gives omega_w = R_w_b * omega_b). bearing_c need not be unit. uv_out (optional) receives
// the mosaic position. At the poles the u component is 0 (see Equirectangular::project).
Eigen::Vector2d mosaic_pixel_velocity(const calib::Equirectangular& projection, const Eigen::Matrix3d& R_w_c,
                                      const Eigen::Vector3d& omega_w, const Eigen::Vector3d& bearing_c,
                                      Eigen::Vector2d* uv_out = nullptr);

}  // namespace evio::mapping
