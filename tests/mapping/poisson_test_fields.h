// Shared by the Poisson solver tests: solver options for a boundary, and smooth test fields.
#pragma once

#include <cmath>
#include <random>

#include "evio/mapping/poisson.h"

namespace evio::mapping::testing {

inline PoissonOptions boundary_options(PoissonBoundary b) {
  PoissonOptions o;
  o.boundary = b;
  return o;
}

// Sum of random sinusoids (not periodic in either direction unless periodic_u: then integer
// numbers of periods along u).
inline ImageD smooth_field(int W, int H, unsigned seed, bool periodic_u) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  ImageD L = ImageD::Zero(H, W);
  for (int k = 0; k < 8; ++k) {
    const double fu = periodic_u ? 2.0 * M_PI * std::floor(1 + 6 * U(rng)) / W : 2.0 * M_PI * (0.3 + 5 * U(rng)) / W;
    const double fv = 2.0 * M_PI * (0.3 + 5 * U(rng)) / H;
    const double a = 0.2 + U(rng), ph = 2 * M_PI * U(rng);
    for (int j = 0; j < H; ++j)
      for (int i = 0; i < W; ++i) L(j, i) += a * std::sin(fu * i + fv * j + ph);
  }
  return L;
}

}  // namespace evio::mapping::testing
