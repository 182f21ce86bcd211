// A synthetic segmentation scene shared by the CMax tests: 400 short edges (4 px, random
// orientation) over a 240x180 sensor; those inside two discs (centres (70, 90) r 35 and (170, 80)
// r 30) move with their own constant flows, the rest stay still. Events are points of the edges at
// uniform times in [0, span_s), in order of generation, each with its object label (0 still, 1, 2).
#pragma once

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

namespace evio_test {

struct PatchEvent {
  int64_t t_ns = 0;   // t0_ns + t
  double x = 0, y = 0;  // sub-pixel position at t
  int label = 0;
};

inline std::vector<PatchEvent> moving_patches(int n, uint64_t seed, const double v1[2], const double v2[2],
                                              int64_t t0_ns = 0, double span_s = 0.03, bool time_ordered = false) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(0, 1);
  struct Edge {
    double x, y, a;
    int label;
  };
  std::vector<Edge> edges;
  for (int i = 0; i < 400; ++i) {
    const double x = 240 * U(rng), y = 180 * U(rng);
    int label = 0;
    if (std::hypot(x - 70, y - 90) < 35) label = 1;
    if (std::hypot(x - 170, y - 80) < 30) label = 2;
    edges.push_back({x, y, M_PI * U(rng), label});
  }
  const double v[3][2] = {{0, 0}, {v1[0], v1[1]}, {v2[0], v2[1]}};
  std::vector<PatchEvent> out;
  out.reserve(static_cast<size_t>(n));
  for (int k = 0; k < n; ++k) {
    const Edge& e = edges[static_cast<size_t>(k) % edges.size()];
    const double a = 4 * U(rng);
    const double t = time_ordered ? span_s * k / n : span_s * U(rng);
    PatchEvent p;
    p.t_ns = t0_ns + static_cast<int64_t>(t * 1e9);
    p.x = e.x + a * std::cos(e.a) + v[e.label][0] * t;
    p.y = e.y + a * std::sin(e.a) + v[e.label][1] * t;
    p.label = e.label;
    out.push_back(p);
  }
  return out;
}

}  // namespace evio_test
