// DART descriptor (Ramesh, Yang, Orchard, Thakor, Xiang, Xiang, "DART: Distribution Aware
// Retinal Transform for Event-based Cameras", TPAMI 2019, arXiv 1710.10800): a log-polar
// histogram of the recent events around an event, matched under cyclic wedge shifts (in-plane
// rotation) and ring shifts (scale), as the paper does in its log-polar domain.
//
// Grid. Rings i = 0..rings-1 cover pixel distances d in [r_i, r_{i+1}) with log-spaced radii
// r_i = inner_radius_px * (outer_radius_px / inner_radius_px)^(i / rings); the last ring is closed
// (d = outer_radius_px counts). Pixels with d < inner_radius_px (the event's own pixel, and more
// when inner_radius_px > 1) are not counted. Wedges j = 0..wedges-1 cover angles
// [j, j+1) * 360/wedges degrees, the angle measured COUNTER-CLOCKWISE AS SEEN ON SCREEN from the
// +x axis, in image coordinates (x right, y down): theta = atan2(-dy, dx) in [0, 360). So wedge 0
// starts at +x (right), wedge wedges/4 at -y (up). Bin index = ring * wedges + wedge.
//
// Descriptor. Bin value = number of pixels of the bin (inside the sensor) whose latest event
// (polarity per `polarity`) lies in [t_ns - window_ns, t_ns] (with kSoft binning each such pixel
// is shared between neighbouring bins, see DartBinning; optionally divided by the bin's pixel
// mass, `weighting`), then normalised (`normalisation`).
//
// Rotation and scale conventions. Rotating a pattern by +alpha degrees (counter-clockwise on
// screen, about the centre) moves the content of wedge j to wedge j + alpha/(360/wedges).
// Scaling it by f moves ring i to ring i + log(f) / log(ring_ratio), ring_ratio =
// (outer/inner)^(1/rings). dart_distance(a, b, &shift) reports shift such that
//   b[ring + shift.ring_shift][(wedge + shift.wedge_shift) mod wedges] ~ a[ring][wedge],
// i.e. b looks like a rotated by +wedge_shift * 360/wedges degrees and scaled by
// ring_ratio^ring_shift.
//
// Defaults and why. The paper describes a log-polar grid of a few circles and wedges around each
// event with descriptor counts normalised before matching; its exact per-experiment values could
// not be checked while writing this, so the defaults below are ours, chosen for eFAST corner
// neighbourhoods on a DAVIS240 (240x180) and measured in tests/frontend/test_dart.cc:
//   - outer_radius_px 10: eFAST looks at radius 4; corners of textured scenes on a DAVIS240 are
//     separated by ~10-20 px, so a 10 px context holds the junction's arms but rarely a second
//     corner (it is also the radius used by the rotation/scale tests).
//   - rings 7, inner_radius_px 10 / sqrt(2)^7 = 0.884: ring ratio exactly sqrt(2), so the test
//     scales 0.71, 1.41 and 2 are whole ring shifts (-1, +1, +2); ring 0 is the 4-neighbourhood
//     (d = 1), ring 1 the diagonal neighbours (d = sqrt 2).
//   - wedges 12 (30 deg): fine enough to tell junction arms apart, coarse enough that an outer
//     ring bin still holds several pixels (the 7..10 px ring has ~13 px per wedge).
//   - max_ring_shift 2: scale changes up to 2x (sqrt(2)^2) either way.
//   - window_ns 30 ms: edges moving at 100-300 px/s (typical hand-held DAVIS240 motion) leave a
//     trail of 3-9 px, a visible structure that is not yet smeared over the whole context.
//   - polarity kBoth: a corner's arms can fire with either polarity; both carry the structure.
//   - half_wedge_shifts true: with 30-degree wedges, a rotation by an odd multiple of 15 deg
//     falls between two whole-wedge shifts, and whole shifts alone lose almost every such match
//     (the rotation/scale test).
//   - binning kSoft: with hard binning a rotation that is not a whole number of wedges (15, 45,
//     75 deg) flips pixels between bins and most matches are lost (the rotation/scale test).
//   - normalisation kL2, weighting kCount: see the enums.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "evio/frontend/sae.h"

namespace evio::frontend {

constexpr int kDartMaxRings = 16;
constexpr int kDartMaxWedges = 64;
constexpr int kDartMaxBins = 256;  // rings * wedges must not exceed this

enum class DartPolarity {
  kBoth,  // a pixel's latest event of either polarity
  kSame,  // only the plane of the event's polarity
};

enum class DartNormalisation {
  kNone,  // raw values
  kL1,    // values sum to 1
  kL2,    // unit Euclidean length
};
// Note: dart_distance renormalises the compared (overlapping) rings itself, so distances do not
// depend on `normalisation`; it sets what the stored bins mean for other users.

enum class DartBinning {
  kHard,  // each pixel adds 1 to its own bin (ring, wedge)
  kSoft,  // each pixel's 1 is split bilinearly between the two nearest wedge centres (in angle)
          // and the two nearest ring centres (in log radius; at the first/last ring all of it
          // stays there), over up to 4 bins. The pixel's "own" bin still defines which pixels
          // belong to the grid. Rotations and scales that are not whole bins then move mass
          // gradually instead of flipping pixels between bins.
};

enum class DartWeighting {
  kCount,    // bin value = number of recent pixels (outer, larger bins weigh more)
  kDensity,  // bin value = recent pixels / pixels of the bin (every bin weighs alike)
};

struct DartOptions {
  int rings = 7;                        // number of log-spaced rings (rings * wedges <= kDartMaxBins)
  int wedges = 12;                      // number of angular wedges
  double inner_radius_px = 0.8838834764831844;  // inner radius of ring 0, px (10 / sqrt(2)^7)
  double outer_radius_px = 10.0;        // outer radius of the last ring, px, > inner_radius_px
  int64_t window_ns = 30'000'000;       // a pixel is recent when its latest event is in
                                        // [t - window_ns, t], ns (default 30 ms)
  DartPolarity polarity = DartPolarity::kBoth;
  DartNormalisation normalisation = DartNormalisation::kL2;
  DartWeighting weighting = DartWeighting::kCount;
  DartBinning binning = DartBinning::kSoft;
  int max_ring_shift = 2;               // dart_distance searches ring shifts -S..S, S < rings
  bool half_wedge_shifts = true;        // dart_distance also tries rotations by k + 1/2 wedges
  bool Validate(std::string* why) const;

  // Radius of ring boundary i (0..rings), px.
  double ring_radius(int i) const;
};

// Fixed-size descriptor: bins[ring * wedges + wedge], the rest zero. No heap allocation.
struct DartDescriptor {
  std::array<float, kDartMaxBins> bins{};
  int rings = 0;
  int wedges = 0;
  int max_ring_shift = 0;  // from the options it was computed with
  bool half_wedge_shifts = false;  // from the options it was computed with
  int recent_pixels = 0;   // pixels counted (before weighting/normalisation)
  float at(int ring, int wedge) const { return bins[static_cast<size_t>(ring) * static_cast<size_t>(wedges) + static_cast<size_t>(wedge)]; }
};

// One entry of the pixel -> bin lookup table.
struct DartBinPixel {
  int16_t dx = 0;
  int16_t dy = 0;
  int16_t bin = 0;  // ring * wedges + wedge (the pixel's own bin)
  std::array<int16_t, 4> soft_bin{};  // kSoft: bins sharing the pixel (weight 0 entries unused)
  std::array<float, 4> soft_weight{};  // their weights, summing to 1
};

class DartExtractor {
 public:
  // Throws std::invalid_argument when the options do not validate.
  explicit DartExtractor(const DartOptions& options);

  // Descriptor of the neighbourhood of (x, y) at time t_ns (polarity +1/-1 selects the plane for
  // DartPolarity::kSame). Pixels outside the SAE's sensor are ignored. Returns false (and leaves
  // *out zeroed with rings/wedges set) when no pixel of the grid is recent.
  bool compute(const SurfaceOfActiveEvents& sae, int x, int y, int64_t t_ns, int8_t polarity,
               DartDescriptor* out) const;

  const DartOptions& options() const { return options_; }
  // Every pixel of the grid (inner_radius <= d <= outer_radius) with its bin, in row-major order.
  const std::vector<DartBinPixel>& lookup_table() const { return lut_; }
  // Pixels per bin (own bins) in the full (unclipped) grid.
  const std::vector<int>& bin_pixel_counts() const { return bin_pixels_; }
  // Pixel mass per bin in the full grid as compute() adds it (kHard: bin_pixel_counts(); kSoft: sum
  // of soft weights); kDensity divides by it.
  const std::vector<float>& bin_mass() const { return bin_mass_; }
  // Ring and wedge of an offset, or false when d is outside [inner, outer] (the LUT's rule).
  bool bin_of(int dx, int dy, int* ring, int* wedge) const;

 private:
  DartOptions options_;
  int reach_ = 0;  // max |dx|, |dy| in the LUT
  std::vector<DartBinPixel> lut_;
  std::vector<int> bin_pixels_;
  std::vector<float> bin_mass_;
  std::vector<float> inv_bin_mass_;
};

struct DartShift {
  int wedge_shift = 0;          // 0..wedges-1, see the convention above (half shifts: rounded down)
  int ring_shift = 0;           // -S..S
  float wedge_shift_fine = 0;   // k or k + 0.5 wedges: rotation = wedge_shift_fine * 360/wedges deg
};

// Distance in [0, sqrt(2)] minimised over every cyclic wedge shift and ring shifts -S..S,
// S = min(a.max_ring_shift, b.max_ring_shift, rings - 1). For a shift, only the rings present in
// both are compared (a's rings max(0,-s)..rings-1-max(0,s) against b's rings shifted by s); each
// side's overlapping part is scaled to unit L2 length and the Euclidean distance of the two unit
// vectors is taken (sqrt(2 - 2 cos)); an all-zero side gives sqrt(2). When both descriptors
// have half_wedge_shifts, rotations by k + 1/2 wedges are tried too, comparing b against a
// rotated by linear interpolation between adjacent wedges (0.5 * (a[w-k] + a[w-k-1])); this
// smooths a, so the distance is then not exactly symmetric in (a, b). Descriptors of different
// grid shapes give +infinity. *best (optional) receives the minimising shift; ties go to the
// smallest |ring_shift|, then the smallest wedge_shift.
float dart_distance(const DartDescriptor& a, const DartDescriptor& b, DartShift* best = nullptr);

// Distance without any shift (the cosine distance sqrt(2 - 2 cos) of the whole grids, in
// [0, sqrt(2)]): for tracking, where the pattern neither turns nor scales between consecutive
// corner events; about 20x cheaper than dart_distance. Different shapes give +infinity, an
// all-zero side sqrt(2).
float dart_distance_aligned(const DartDescriptor& a, const DartDescriptor& b);

// Default absolute acceptance threshold of dart_match with a single candidate: sqrt(2 - 2*0.85),
// i.e. cosine similarity >= 0.85 over the compared rings.
constexpr float kDartSingleMatchMaxDistance = 0.5477226f;

// Index of the candidate nearest to `query` (dart_distance(query, candidate)) when
// best < ratio * second best (Lowe's ratio test, ratio in (0, 1]); -1 otherwise. With one
// candidate, it is accepted when its distance is below `single_max_distance`; with none, -1.
// *best_distance (optional) receives the nearest distance (+infinity without candidates).
int dart_match(const DartDescriptor& query, const std::vector<DartDescriptor>& candidates, float ratio,
               float* best_distance = nullptr, float single_max_distance = kDartSingleMatchMaxDistance);

}  // namespace evio::frontend
