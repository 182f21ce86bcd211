// DART descriptor (see the header). The pixel -> bin map is built once per extractor (integer
// offsets inside the outer radius, ring by squared distance against squared log-spaced radii with
// a 1e-9 relative tolerance so that pixels on a boundary, e.g. d = 5 with the default grid, fall
// deterministically into the outer ring; wedge by atan2 with the same tolerance so that the
// grid's 90-degree symmetric pixels land on wedge boundaries consistently). compute() walks the
// table once; neighbourhoods fully inside the sensor skip the bounds check.
#include "evio/frontend/dart.h"
#include "evio/frontend/option_tables.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace evio::frontend {

namespace {
constexpr double kPi = 3.14159265358979323846;
constexpr double kTol = 1e-9;
}  // namespace

double DartOptions::ring_radius(int i) const {
  return inner_radius_px * std::pow(outer_radius_px / inner_radius_px, static_cast<double>(i) / rings);
}

bool DartOptions::Validate(std::string* why) const {
  if (!dart_table().check(*this, why)) return false;
  if (rings * wedges > kDartMaxBins)
    return validation_failed(why, "rings * wedges = " + std::to_string(rings * wedges) + " (expected <= " +
                                      std::to_string(kDartMaxBins) + " bins)");
  if (!(outer_radius_px > inner_radius_px))
    return validation_failed(why, "outer_radius_px " + yaml_config::yaml_number(outer_radius_px) +
                                      " (expected above inner_radius_px " + yaml_config::yaml_number(inner_radius_px) + ")");
  if (max_ring_shift >= rings)
    return validation_failed(why, "max_ring_shift " + std::to_string(max_ring_shift) + " (expected below rings " +
                                      std::to_string(rings) + ")");
  return true;
}

DartExtractor::DartExtractor(const DartOptions& options) : options_(options) {
  std::string why;
  if (!options.Validate(&why)) throw std::invalid_argument("DART options: " + why);
  bin_pixels_.assign(static_cast<size_t>(options_.rings * options_.wedges), 0);
  const int r = static_cast<int>(std::floor(options_.outer_radius_px + kTol));
  for (int dy = -r; dy <= r; ++dy) {
    for (int dx = -r; dx <= r; ++dx) {
      int ring = 0, wedge = 0;
      if (!bin_of(dx, dy, &ring, &wedge)) continue;
      DartBinPixel p;
      p.dx = static_cast<int16_t>(dx);
      p.dy = static_cast<int16_t>(dy);
      p.bin = static_cast<int16_t>(ring * options_.wedges + wedge);
      if (options_.binning == DartBinning::kHard) {
        p.soft_bin = {p.bin, p.bin, p.bin, p.bin};
        p.soft_weight = {1.0f, 0.0f, 0.0f, 0.0f};
      } else {
        // Fractional ring / wedge coordinates relative to the bin centres.
        const int R = options_.rings, W = options_.wedges;
        const double d = std::hypot(static_cast<double>(dx), static_cast<double>(dy));
        const double rho = std::log(d / options_.inner_radius_px) /
                               std::log(options_.outer_radius_px / options_.inner_radius_px) * R - 0.5;
        int r0 = static_cast<int>(std::floor(rho));
        double fr = rho - r0;
        if (r0 < 0) {
          r0 = 0;
          fr = 0.0;
        }
        if (r0 >= R - 1) {
          r0 = R - 1;
          fr = 0.0;
        }
        const int r1 = std::min(r0 + 1, R - 1);
        double theta = std::atan2(-static_cast<double>(dy), static_cast<double>(dx));
        if (theta < 0.0) theta += 2.0 * kPi;
        const double phi = theta / (2.0 * kPi / W) - 0.5;
        const int j = static_cast<int>(std::floor(phi));
        const double fw = phi - j;
        const int w0 = ((j % W) + W) % W, w1 = (w0 + 1) % W;
        p.soft_bin = {static_cast<int16_t>(r0 * W + w0), static_cast<int16_t>(r0 * W + w1),
                      static_cast<int16_t>(r1 * W + w0), static_cast<int16_t>(r1 * W + w1)};
        p.soft_weight = {static_cast<float>((1 - fr) * (1 - fw)), static_cast<float>((1 - fr) * fw),
                         static_cast<float>(fr * (1 - fw)), static_cast<float>(fr * fw)};
      }
      lut_.push_back(p);
      ++bin_pixels_[static_cast<size_t>(p.bin)];
      reach_ = std::max(reach_, std::max(std::abs(dx), std::abs(dy)));
    }
  }
  bin_mass_.assign(bin_pixels_.size(), 0.0f);
  for (const DartBinPixel& p : lut_)
    for (int i = 0; i < 4; ++i) bin_mass_[static_cast<size_t>(p.soft_bin[i])] += p.soft_weight[i];
  inv_bin_mass_.resize(bin_mass_.size());
  for (size_t i = 0; i < bin_mass_.size(); ++i) inv_bin_mass_[i] = bin_mass_[i] > 0.0f ? 1.0f / bin_mass_[i] : 0.0f;
}

bool DartExtractor::bin_of(int dx, int dy, int* ring, int* wedge) const {
  const double d2 = static_cast<double>(dx) * dx + static_cast<double>(dy) * dy;
  const double rin = options_.ring_radius(0);
  const double rout = options_.outer_radius_px;
  if (d2 < rin * rin * (1.0 - kTol) || d2 > rout * rout * (1.0 + kTol)) return false;
  int i = 0;
  while (i + 1 < options_.rings) {
    const double rb = options_.ring_radius(i + 1);
    if (d2 >= rb * rb * (1.0 - kTol)) {
      ++i;
    } else {
      break;
    }
  }
  double theta = std::atan2(-static_cast<double>(dy), static_cast<double>(dx));  // CCW on screen
  if (theta < 0.0) theta += 2.0 * kPi;
  int w = static_cast<int>(std::floor(theta / (2.0 * kPi / options_.wedges) + kTol));
  if (w >= options_.wedges) w -= options_.wedges;
  *ring = i;
  *wedge = w;
  return true;
}

bool DartExtractor::compute(const SurfaceOfActiveEvents& sae, int x, int y, int64_t t_ns, int8_t polarity,
                            DartDescriptor* out) const {
  const int nb = options_.rings * options_.wedges;
  out->bins.fill(0.0f);
  out->rings = options_.rings;
  out->wedges = options_.wedges;
  out->max_ring_shift = options_.max_ring_shift;
  out->half_wedge_shifts = options_.half_wedge_shifts;
  out->recent_pixels = 0;
  // Oldest recent time, saturated so that t_ns - window never overflows.
  const int64_t lo = t_ns < std::numeric_limits<int64_t>::min() + options_.window_ns + 1
                         ? std::numeric_limits<int64_t>::min() + 1
                         : t_ns - options_.window_ns;
  const int w = sae.width();
  const int h = sae.height();
  const bool both = options_.polarity == DartPolarity::kBoth;
  const int64_t* pa = sae.plane(both ? int8_t{1} : polarity);
  const int64_t* pb = sae.plane(both ? int8_t{-1} : polarity);
  std::array<float, kDartMaxBins> counts{};
  int total = 0;
  const bool soft = options_.binning == DartBinning::kSoft;
  const bool inside = x - reach_ >= 0 && y - reach_ >= 0 && x + reach_ < w && y + reach_ < h;
  const ptrdiff_t centre = static_cast<ptrdiff_t>(y) * w + x;
  for (const DartBinPixel& p : lut_) {
    if (!inside) {
      const int px = x + p.dx, py = y + p.dy;
      if (px < 0 || py < 0 || px >= w || py >= h) continue;
    }
    const ptrdiff_t k = centre + static_cast<ptrdiff_t>(p.dy) * w + p.dx;
    const int64_t t = std::max(pa[k], pb[k]);
    if (t < lo || t > t_ns) continue;
    ++total;
    if (soft) {
      for (int i = 0; i < 4; ++i) counts[static_cast<size_t>(p.soft_bin[i])] += p.soft_weight[i];
    } else {
      counts[static_cast<size_t>(p.bin)] += 1.0f;
    }
  }
  out->recent_pixels = total;
  if (total == 0) return false;
  double norm = 0.0;
  for (int b = 0; b < nb; ++b) {
    float v = counts[static_cast<size_t>(b)];
    if (options_.weighting == DartWeighting::kDensity) v *= inv_bin_mass_[static_cast<size_t>(b)];
    out->bins[static_cast<size_t>(b)] = v;
    norm += options_.normalisation == DartNormalisation::kL1 ? v : static_cast<double>(v) * v;
  }
  if (options_.normalisation != DartNormalisation::kNone) {
    const double n = options_.normalisation == DartNormalisation::kL2 ? std::sqrt(norm) : norm;
    const float inv = static_cast<float>(1.0 / n);
    for (int b = 0; b < nb; ++b) out->bins[static_cast<size_t>(b)] *= inv;
  }
  return true;
}

float dart_distance_aligned(const DartDescriptor& a, const DartDescriptor& b) {
  if (a.rings != b.rings || a.wedges != b.wedges || a.rings <= 0 || a.wedges <= 0) {
    return std::numeric_limits<float>::infinity();
  }
  const int n = a.rings * a.wedges;
  float dot = 0.0f, sa = 0.0f, sb = 0.0f;
  for (int i = 0; i < n; ++i) {
    dot += a.bins[static_cast<size_t>(i)] * b.bins[static_cast<size_t>(i)];
    sa += a.bins[static_cast<size_t>(i)] * a.bins[static_cast<size_t>(i)];
    sb += b.bins[static_cast<size_t>(i)] * b.bins[static_cast<size_t>(i)];
  }
  if (!(sa > 0.0f) || !(sb > 0.0f)) return std::sqrt(2.0f);
  return std::sqrt(std::max(0.0f, 2.0f - 2.0f * dot / std::sqrt(sa * sb)));
}

float dart_distance(const DartDescriptor& a, const DartDescriptor& b, DartShift* best) {
  const float inf = std::numeric_limits<float>::infinity();
  if (a.rings != b.rings || a.wedges != b.wedges || a.rings <= 0 || a.wedges <= 0) {
    if (best) *best = DartShift{};
    return inf;
  }
  const int R = a.rings, W = a.wedges;
  const int S = std::min(std::min(a.max_ring_shift, b.max_ring_shift), R - 1);
  const bool half = a.half_wedge_shifts && b.half_wedge_shifts && W > 1;
  // Per-ring squared norms of a and b, and a's lag-1 cyclic autocorrelation (the squared norm of
  // a half-wedge-rotated a is 0.5 * (|a|^2 + autocorrelation)).
  std::array<float, kDartMaxRings> na{}, nb{}, aca{};
  for (int r = 0; r < R; ++r) {
    float sa = 0.0f, sb = 0.0f, ac = 0.0f;
    for (int j = 0; j < W; ++j) {
      sa += a.at(r, j) * a.at(r, j);
      sb += b.at(r, j) * b.at(r, j);
      ac += a.at(r, j) * a.at(r, (j + 1) % W);
    }
    na[static_cast<size_t>(r)] = sa;
    nb[static_cast<size_t>(r)] = sb;
    aca[static_cast<size_t>(r)] = ac;
  }
  // b's rings with each wedge row duplicated, so a cyclic shift is a plain offset.
  std::array<float, 2 * kDartMaxBins> b2;
  for (int r = 0; r < R; ++r)
    for (int j = 0; j < 2 * W; ++j) b2[static_cast<size_t>(r * 2 * W + j)] = b.at(r, j % W);

  float best_d2 = inf;
  DartShift best_shift{};
  std::array<float, kDartMaxWedges> dots{};
  // Order: s = 0, +1, -1, +2, -2 ... so ties keep the smallest |s| (strict improvement only).
  for (int m = 0; m <= 2 * S; ++m) {
    const int s = (m % 2 == 1) ? (m + 1) / 2 : -(m / 2);
    const int ra0 = std::max(0, -s), ra1 = R - std::max(0, s);  // a's rings [ra0, ra1)
    float sa = 0.0f, sb = 0.0f, sac = 0.0f;
    for (int r = ra0; r < ra1; ++r) {
      sa += na[static_cast<size_t>(r)];
      sac += aca[static_cast<size_t>(r)];
      sb += nb[static_cast<size_t>(r + s)];
    }
    if (!(sa > 0.0f) || !(sb > 0.0f)) {
      if (2.0f < best_d2) {
        best_d2 = 2.0f;
        best_shift = DartShift{0, s, 0.0f};
      }
      continue;
    }
    const float inv = 1.0f / std::sqrt(sa * sb);
    for (int k = 0; k < W; ++k) {
      float dot = 0.0f;
      for (int r = ra0; r < ra1; ++r) {
        const float* pa = a.bins.data() + r * W;
        const float* pb = b2.data() + (r + s) * 2 * W + k;
        for (int j = 0; j < W; ++j) dot += pa[j] * pb[j];
      }
      dots[static_cast<size_t>(k)] = dot;
      const float d2 = std::max(0.0f, 2.0f - 2.0f * dot * inv);
      if (d2 < best_d2) {
        best_d2 = d2;
        best_shift = DartShift{k, s, static_cast<float>(k)};
      }
    }
    if (!half) continue;
    // a rotated by k + 1/2 wedges, linearly interpolated: 0.5 * (a[w - k] + a[w - k - 1]); its dot
    // with b is 0.5 * (dot(k) + dot(k + 1)).
    const float sh = 0.5f * (sa + sac);
    if (!(sh > 0.0f)) continue;
    const float invh = 1.0f / std::sqrt(sh * sb);
    for (int k = 0; k < W; ++k) {
      const float dot = 0.5f * (dots[static_cast<size_t>(k)] + dots[static_cast<size_t>((k + 1) % W)]);
      const float d2 = std::max(0.0f, 2.0f - 2.0f * dot * invh);
      if (d2 < best_d2) {
        best_d2 = d2;
        best_shift = DartShift{k, s, static_cast<float>(k) + 0.5f};
      }
    }
  }
  if (best) *best = best_shift;
  return std::sqrt(best_d2);
}

int dart_match(const DartDescriptor& query, const std::vector<DartDescriptor>& candidates, float ratio,
               float* best_distance, float single_max_distance) {
  const float inf = std::numeric_limits<float>::infinity();
  float d1 = inf, d2 = inf;
  int i1 = -1;
  for (size_t i = 0; i < candidates.size(); ++i) {
    const float d = dart_distance(query, candidates[i]);
    if (d < d1) {
      d2 = d1;
      d1 = d;
      i1 = static_cast<int>(i);
    } else if (d < d2) {
      d2 = d;
    }
  }
  if (best_distance) *best_distance = d1;
  if (i1 < 0 || !std::isfinite(d1)) return -1;
  if (candidates.size() == 1) return d1 < single_max_distance ? i1 : -1;
  return d1 < ratio * d2 ? i1 : -1;
}

}  // namespace evio::frontend
