// Weighted Poisson solver (mapping/weighted_poisson.h): exact recovery of a known image from its
// exact gradients (full and uneven weights, both boundaries, every preconditioner), agreement with
// the unweighted spectral solve for uniform weights, a masked case where the unweighted solve's
// zero gradients in the unseen part pull the seen part and the weighted one does not, PCG
// convergence within the iteration cap, and options / input validation.
#include <cmath>
#include <cstdio>
#include <random>
#include <stdexcept>
#include <string>

#include <gtest/gtest.h>

#include "evio/mapping/poisson.h"
#include "evio/mapping/weighted_poisson.h"
#include "poisson_test_fields.h"

namespace {

using evio::mapping::testing::smooth_field;
const auto boundary = evio::mapping::testing::boundary_options;

using evio::mapping::forward_gradient;
using evio::mapping::ImageD;
using evio::mapping::PoissonBoundary;
using evio::mapping::PoissonOptions;
using evio::mapping::PoissonPreconditioner;
using evio::mapping::PoissonSolver;
using evio::mapping::WeightedPoissonOptions;
using evio::mapping::WeightedPoissonSolver;
using evio::mapping::WeightedPoissonStats;

// RMS of a - b over rows [j0, j1) after removing the mean difference there.
double rms_up_to_offset(const ImageD& a, const ImageD& b, int j0, int j1) {
  const ImageD d = (a - b).middleRows(j0, j1 - j0);
  return std::sqrt((d.array() - d.mean()).square().mean());
}

TEST(WeightedPoisson, ExactGradientsAreRecoveredWithAnyWeightsAndPreconditioner) {
  const int W = 96, H = 64;
  for (const PoissonBoundary b : {PoissonBoundary::kNeumann, PoissonBoundary::kPeriodicU}) {
    const ImageD L = smooth_field(W, H, 3, b == PoissonBoundary::kPeriodicU);
    ImageD gx, gy;
    forward_gradient(L, b, &gx, &gy);
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> U(0.05, 1.0);
    ImageD uneven_x(H, W), uneven_y(H, W);
    for (Eigen::Index k = 0; k < uneven_x.size(); ++k) uneven_x.data()[k] = U(rng), uneven_y.data()[k] = U(rng);
    const ImageD ones = ImageD::Ones(H, W);
    const ImageD zero_start = ImageD::Zero(H, W);  // forces the PCG to do the work
    for (const PoissonPreconditioner p : {PoissonPreconditioner::kNone, PoissonPreconditioner::kJacobi,
                                          PoissonPreconditioner::kSpectral, PoissonPreconditioner::kScaledSpectral}) {
      WeightedPoissonOptions o;
      o.preconditioner = p;
      o.tolerance = 1e-12;
      o.max_iterations = 2000;
      const WeightedPoissonSolver solver(W, H, o, boundary(b));
      for (const bool uneven : {false, true}) {
        ImageD out;
        const WeightedPoissonStats st =
            solver.solve(gx, gy, uneven ? uneven_x : ones, uneven ? uneven_y : ones, &out, &zero_start);
        const double err = rms_up_to_offset(out, L, 0, H);
        std::printf("%s, %s, %s weights: %d iterations, RMS error %.2e\n",
                    b == PoissonBoundary::kNeumann ? "Neumann" : "periodic-u",
                    evio::mapping::poisson_preconditioner_name(p), uneven ? "uneven" : "unit", st.iterations, err);
        EXPECT_TRUE(st.converged);
        EXPECT_LT(err, 1e-9);
        EXPECT_NEAR(out.mean(), 0.0, 1e-12);
        if ((p == PoissonPreconditioner::kSpectral || p == PoissonPreconditioner::kScaledSpectral) && !uneven) {
          EXPECT_LE(st.iterations, 2);  // the exact inverse
        }
      }
    }
  }
}

TEST(WeightedPoisson, UniformWeightsGiveTheSpectralSolveOfANonIntegrableField) {
  const int W = 64, H = 48;
  std::mt19937 rng(11);
  std::normal_distribution<double> N(0.0, 0.3);
  ImageD gx(H, W), gy(H, W);
  for (Eigen::Index k = 0; k < gx.size(); ++k) gx.data()[k] = N(rng), gy.data()[k] = N(rng);
  const PoissonSolver spectral(W, H);
  ImageD ref;
  spectral.solve(gx, gy, &ref);
  WeightedPoissonOptions o;
  o.tolerance = 1e-10;
  o.preconditioner = PoissonPreconditioner::kJacobi;  // not the spectral solver itself
  o.max_iterations = 2000;
  const WeightedPoissonSolver solver(W, H, o);
  const ImageD half = ImageD::Constant(H, W, 0.5);  // the scale of uniform weights does not matter
  const ImageD zero_start = ImageD::Zero(H, W);
  ImageD out;
  const WeightedPoissonStats st = solver.solve(gx, gy, half, half, &out, &zero_start);
  EXPECT_TRUE(st.converged);
  EXPECT_LT((out - ref).cwiseAbs().maxCoeff(), 1e-7);
  // Seeded by the spectral solve (the default start), nothing is left to do.
  const WeightedPoissonStats seeded = solver.solve(gx, gy, half, half, &out);
  EXPECT_EQ(seeded.iterations, 0);
  EXPECT_LT(seeded.initial_relative_residual, 1e-10);
}

// Rows [8, 56) of a 128 x 64 periodic-u field are seen: their edges carry the exact gradients at
// weight 1; every other edge is "unseen": gradient 0 (what GradientMosaic gives the solver) at
// weight 0. The unweighted solve fits those zeros like data and bends the seen band; the weighted
// one reproduces the band up to the weight floor's pull.
struct MaskedCase {
  static constexpr int W = 128, H = 64, j0 = 8, j1 = 56;
  ImageD L, gx, gy, wx, wy;
  MaskedCase() {
    L = smooth_field(W, H, 7, true);
    forward_gradient(L, PoissonBoundary::kPeriodicU, &gx, &gy);
    wx = ImageD::Zero(H, W);
    wy = ImageD::Zero(H, W);
    for (int j = 0; j < H; ++j)
      for (int i = 0; i < W; ++i) {
        const bool seen = j >= j0 && j < j1;
        const bool seen_down = seen && j + 1 < j1;
        if (seen) wx(j, i) = 1.0; else gx(j, i) = 0.0;
        if (seen_down) wy(j, i) = 1.0; else gy(j, i) = 0.0;
      }
  }
};

TEST(WeightedPoisson, UnseenRegionDoesNotPullSeenTexels) {
  const MaskedCase c;
  const PoissonSolver spectral(c.W, c.H);
  ImageD unweighted;
  spectral.solve(c.gx, c.gy, &unweighted);
  const double err_unweighted = rms_up_to_offset(unweighted, c.L, c.j0, c.j1);
  for (const double floor : {1e-2, 1e-3, 1e-4}) {
    WeightedPoissonOptions o;
    o.weight_floor = floor;
    o.tolerance = 1e-8;
    o.max_iterations = 1000;
    const WeightedPoissonSolver solver(c.W, c.H, o);
    ImageD weighted;
    const WeightedPoissonStats st = solver.solve(c.gx, c.gy, c.wx, c.wy, &weighted);
    const double err = rms_up_to_offset(weighted, c.L, c.j0, c.j1);
    std::printf("masked band: unweighted RMS error %.4f, weighted (floor %g) %.2e after %d iterations\n",
                err_unweighted, floor, err, st.iterations);
    EXPECT_TRUE(st.converged);
    // Measured 0.288 unweighted; weighted 4.53e-3, 4.55e-4, 4.56e-5 (the pull scales with the floor).
    EXPECT_GT(err_unweighted, 0.25);
    EXPECT_LT(err, 0.55 * floor);
  }
}

TEST(WeightedPoisson, PcgConvergesWithinTheCapAndStopsAtIt) {
  const MaskedCase c;
  const WeightedPoissonOptions defaults;
  const WeightedPoissonSolver solver(c.W, c.H, defaults);
  ImageD out;
  const WeightedPoissonStats st = solver.solve(c.gx, c.gy, c.wx, c.wy, &out);
  std::printf("masked band, defaults: %d iterations, relative residual %.2e -> %.2e\n", st.iterations,
              st.initial_relative_residual, st.relative_residual);
  EXPECT_TRUE(st.converged);
  EXPECT_LE(st.relative_residual, defaults.tolerance);
  EXPECT_GT(st.initial_relative_residual, defaults.tolerance);
  // Measured 3 iterations at the defaults (spectral preconditioner).
  EXPECT_LE(st.iterations, 4);
  EXPECT_LE(st.iterations, defaults.max_iterations);

  WeightedPoissonOptions capped;
  capped.max_iterations = 2;
  capped.tolerance = 1e-12;
  const WeightedPoissonStats cs = WeightedPoissonSolver(c.W, c.H, capped).solve(c.gx, c.gy, c.wx, c.wy, &out);
  EXPECT_EQ(cs.iterations, 2);
  EXPECT_FALSE(cs.converged);
  EXPECT_LT(cs.relative_residual, cs.initial_relative_residual);
  capped.max_iterations = 0;  // the warm start itself
  ImageD start;
  PoissonSolver(c.W, c.H).solve(c.gx, c.gy, &start);
  const WeightedPoissonStats zs = WeightedPoissonSolver(c.W, c.H, capped).solve(c.gx, c.gy, c.wx, c.wy, &out);
  EXPECT_EQ(zs.iterations, 0);
  EXPECT_LT((out - start).cwiseAbs().maxCoeff(), 1e-12);

  // The spectral preconditioner (the default) needs fewer iterations than the others on this case.
  int iters[4];
  for (int p = 0; p < 4; ++p) {
    WeightedPoissonOptions o;
    o.preconditioner = static_cast<PoissonPreconditioner>(p);
    o.max_iterations = 5000;
    const WeightedPoissonStats s = WeightedPoissonSolver(c.W, c.H, o).solve(c.gx, c.gy, c.wx, c.wy, &out);
    EXPECT_TRUE(s.converged) << p;
    iters[p] = s.iterations;
    std::printf("masked band, preconditioner %s: %d iterations\n",
                evio::mapping::poisson_preconditioner_name(o.preconditioner), s.iterations);
  }
  EXPECT_EQ(defaults.preconditioner, PoissonPreconditioner::kSpectral);
  EXPECT_LT(iters[2], iters[0]);
  EXPECT_LT(iters[2], iters[1]);
  EXPECT_LT(iters[2], iters[3]);
}

TEST(WeightedPoisson, OptionsAndInputsAreValidated) {
  std::string why;
  EXPECT_TRUE(WeightedPoissonOptions{}.Validate(&why)) << why;
  auto rejected = [](const WeightedPoissonOptions& o, const std::string& field) {
    std::string w;
    EXPECT_FALSE(o.Validate(&w)) << field;
    EXPECT_NE(w.find(field), std::string::npos) << w;
    EXPECT_THROW(WeightedPoissonSolver(8, 8, o), std::invalid_argument) << field;
  };
  WeightedPoissonOptions o;
  o.weight_floor = 0;
  rejected(o, "weight_floor");
  o.weight_floor = 1.5;
  rejected(o, "weight_floor");
  o = {};
  o.weight_floor = std::nan("");
  rejected(o, "weight_floor");
  o = {};
  o.tolerance = 0;
  rejected(o, "tolerance");
  o.tolerance = 1;
  rejected(o, "tolerance");
  o = {};
  o.max_iterations = -1;
  rejected(o, "max_iterations");
  o = {};
  o.preconditioner = static_cast<PoissonPreconditioner>(17);
  rejected(o, "preconditioner");

  EXPECT_THROW(WeightedPoissonSolver(1, 8), std::invalid_argument);
  const WeightedPoissonSolver solver(8, 6);
  const ImageD g = ImageD::Zero(6, 8), w = ImageD::Ones(6, 8);
  ImageD out;
  EXPECT_THROW(solver.solve(g, g, w, w, nullptr), std::invalid_argument);
  EXPECT_THROW(solver.solve(ImageD::Zero(6, 7), g, w, w, &out), std::invalid_argument);
  EXPECT_THROW(solver.solve(g, g, ImageD::Ones(5, 8), w, &out), std::invalid_argument);
  const ImageD bad_start = ImageD::Zero(8, 6);
  EXPECT_THROW(solver.solve(g, g, w, w, &out, &bad_start), std::invalid_argument);
  ImageD negative = w;
  negative(2, 3) = -0.1;
  EXPECT_THROW(solver.solve(g, g, negative, w, &out), std::invalid_argument);
  ImageD nan = w;
  nan(1, 1) = std::nan("");
  EXPECT_THROW(solver.solve(g, g, w, nan, &out), std::invalid_argument);
  // Zero data: zero image, converged without iterations.
  const WeightedPoissonStats st = solver.solve(g, g, w, w, &out);
  EXPECT_TRUE(st.converged);
  EXPECT_EQ(st.iterations, 0);
  EXPECT_EQ(out.cwiseAbs().maxCoeff(), 0.0);
}

}  // namespace
