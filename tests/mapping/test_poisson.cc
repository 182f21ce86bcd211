// Poisson reconstruction (mapping/poisson.h): exactness of the full solve on integrable gradient
// fields (constant, ramp, random smooth, periodic in u; even sizes through OpenCV's transforms and
// odd sizes through the dense fallback), the normal equations on non-integrable fields, weights,
// and the region (incremental) solve against the full solve.
#include <cmath>
#include <cstdio>
#include <random>

#include <gtest/gtest.h>

#include "evio/mapping/poisson.h"
#include "poisson_test_fields.h"

namespace {

using evio::mapping::testing::smooth_field;
const auto opts = evio::mapping::testing::boundary_options;

using evio::mapping::ImageD;
using evio::mapping::ImageF;
using evio::mapping::PixelRect;
using evio::mapping::PoissonBoundary;
using evio::mapping::PoissonOptions;
using evio::mapping::PoissonSolver;

double max_abs_diff_up_to_offset(const ImageD& a, const ImageD& b) {
  const ImageD d = a - b;
  return (d.array() - d.mean()).abs().maxCoeff();
}

TEST(Poisson, ZeroGradientGivesZeroMeanConstant) {
  for (PoissonBoundary b : {PoissonBoundary::kNeumann, PoissonBoundary::kPeriodicU}) {
    for (auto [W, H] : {std::pair{64, 32}, std::pair{33, 17}}) {
      PoissonSolver s(W, H, opts(b));
      ImageD L;
      s.solve(ImageD::Zero(H, W), ImageD::Zero(H, W), &L);
      ASSERT_EQ(L.rows(), H);
      ASSERT_EQ(L.cols(), W);
      EXPECT_LT(L.cwiseAbs().maxCoeff(), 1e-14);
    }
  }
}

TEST(Poisson, RampNeumannExactDoubleAndFloat) {
  const int W = 256, H = 128;
  ImageD L(H, W);
  for (int j = 0; j < H; ++j)
    for (int i = 0; i < W; ++i) L(j, i) = 0.013 * i - 0.021 * j + 3.0;
  ImageD gx, gy, R;
  evio::mapping::forward_gradient(L, PoissonBoundary::kNeumann, &gx, &gy);
  PoissonSolver s(W, H, opts(PoissonBoundary::kNeumann));
  s.solve(gx, gy, &R);
  const double err_d = max_abs_diff_up_to_offset(R, L);
  EXPECT_LT(err_d, 1e-9);
  EXPECT_NEAR(R.mean(), 0.0, 1e-12);
  ImageF Rf;
  s.solve(ImageF(gx.cast<float>()), ImageF(gy.cast<float>()), &Rf);
  const double err_f = max_abs_diff_up_to_offset(Rf.cast<double>(), L);
  EXPECT_LT(err_f, 1e-4);
  std::printf("ramp 256x128 Neumann: max error double %.3g, float %.3g\n", err_d, err_f);
}

TEST(Poisson, RampInVPeriodicU) {
  const int W = 128, H = 64;
  ImageD L(H, W);
  for (int j = 0; j < H; ++j)
    for (int i = 0; i < W; ++i) L(j, i) = -0.05 * j + 0.3 * std::cos(2 * M_PI * 2 * i / W);
  ImageD gx, gy, R;
  evio::mapping::forward_gradient(L, PoissonBoundary::kPeriodicU, &gx, &gy);
  PoissonSolver(W, H, opts(PoissonBoundary::kPeriodicU)).solve(gx, gy, &R);
  EXPECT_LT(max_abs_diff_up_to_offset(R, L), 1e-10);
}

TEST(Poisson, RandomSmoothFieldRoundTrip) {
  for (PoissonBoundary b : {PoissonBoundary::kNeumann, PoissonBoundary::kPeriodicU}) {
    for (auto [W, H] : {std::pair{512, 256}, std::pair{100, 64}, std::pair{45, 31}, std::pair{64, 9}}) {
      const ImageD L = smooth_field(W, H, 7 + W, b == PoissonBoundary::kPeriodicU);
      ImageD gx, gy, R;
      evio::mapping::forward_gradient(L, b, &gx, &gy);
      PoissonSolver(W, H, opts(b)).solve(gx, gy, &R);
      const double err = max_abs_diff_up_to_offset(R, L);
      EXPECT_LT(err, 1e-10) << W << "x" << H << " boundary " << static_cast<int>(b);
      EXPECT_NEAR(R.mean(), 0.0, 1e-12);
      std::printf("smooth %dx%d %s: max error %.3g\n", W, H, b == PoissonBoundary::kNeumann ? "Neumann" : "periodic-u",
                  err);
    }
  }
}

// The periodic solve must use the wrap-around edge: a field periodic in u but with a jump across
// the seam under the Neumann discretisation is reproduced only by kPeriodicU.
TEST(Poisson, PeriodicUsesTheSeamEdge) {
  const int W = 128, H = 64;
  const ImageD L = smooth_field(W, H, 3, true);
  ImageD gx, gy, R;
  evio::mapping::forward_gradient(L, PoissonBoundary::kPeriodicU, &gx, &gy);
  // Corrupt the seam edge: the periodic solution changes, the Neumann one ignores it.
  ImageD gx2 = gx;
  gx2.col(W - 1).array() += 1.0;
  ImageD Rn1, Rn2, Rp2;
  PoissonSolver(W, H, opts(PoissonBoundary::kNeumann)).solve(gx, gy, &Rn1);
  PoissonSolver(W, H, opts(PoissonBoundary::kNeumann)).solve(gx2, gy, &Rn2);
  PoissonSolver(W, H, opts(PoissonBoundary::kPeriodicU)).solve(gx2, gy, &Rp2);
  EXPECT_LT((Rn1 - Rn2).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_GT(max_abs_diff_up_to_offset(Rp2, L), 0.1);
}

// Non-integrable (random) gradients: the result satisfies the normal equations lap L = div g.
TEST(Poisson, NormalEquationsOnNonIntegrableField) {
  std::mt19937 rng(11);
  std::normal_distribution<double> N(0.0, 1.0);
  for (PoissonBoundary b : {PoissonBoundary::kNeumann, PoissonBoundary::kPeriodicU}) {
    for (auto [W, H] : {std::pair{96, 48}, std::pair{31, 20}}) {
      ImageD gx(H, W), gy(H, W), R;
      for (int k = 0; k < gx.size(); ++k) gx.data()[k] = N(rng), gy.data()[k] = N(rng);
      PoissonSolver(W, H, opts(b)).solve(gx, gy, &R);
      const ImageD res = evio::mapping::laplacian(R, b) - evio::mapping::divergence(gx, gy, b);
      EXPECT_LT(res.cwiseAbs().maxCoeff(), 1e-10) << W << "x" << H;
    }
  }
}

TEST(Poisson, WeightsZeroGradientWhereZero) {
  const int W = 64, H = 32;
  const ImageD L = smooth_field(W, H, 5, true);
  ImageD gx, gy;
  evio::mapping::forward_gradient(L, PoissonBoundary::kPeriodicU, &gx, &gy);
  ImageD w = ImageD::Ones(H, W);
  w.block(8, 10, 12, 20).setZero();
  w.block(0, 40, 5, 5).setConstant(0.5);
  ImageD gxw = gx.cwiseProduct(w), gyw = gy.cwiseProduct(w);
  PoissonSolver s(W, H, opts(PoissonBoundary::kPeriodicU));
  ImageD Rw, Rm;
  s.solve(gx, gy, &Rw, &w);
  s.solve(gxw, gyw, &Rm);
  EXPECT_LT((Rw - Rm).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_GT(max_abs_diff_up_to_offset(Rw, L), 1e-3);  // the masked gradients did change the result
}

TEST(Poisson, RejectsBadInput) {
  EXPECT_THROW(PoissonSolver(1, 8), std::invalid_argument);
  PoissonOptions o;
  o.max_region_side = 0;
  std::string why;
  EXPECT_FALSE(o.Validate(&why));
  EXPECT_FALSE(why.empty());
  EXPECT_THROW(PoissonSolver(8, 8, o), std::invalid_argument);
  PoissonSolver s(16, 8, opts(PoissonBoundary::kNeumann));
  ImageD L = ImageD::Zero(8, 16);
  EXPECT_THROW(s.solve(ImageD::Zero(8, 15), ImageD::Zero(8, 16), &L), std::invalid_argument);
  const ImageD z = ImageD::Zero(8, 16);
  EXPECT_THROW(s.solve_region(z, z, PixelRect{-2, 0, 4, 4}, &L), std::invalid_argument);  // no u-wrap in Neumann
  EXPECT_THROW(s.solve_region(z, z, PixelRect{14, 0, 4, 4}, &L), std::invalid_argument);
  EXPECT_THROW(s.solve_region(z, z, PixelRect{0, 0, 0, 4}, &L), std::invalid_argument);
  EXPECT_THROW(s.solve_region(z, z, PixelRect{0, 9, 4, 4}, &L), std::invalid_argument);
  EXPECT_THROW(s.solve_region(z, z, PixelRect{0, 0, 17, 4}, &L), std::invalid_argument);
}

// Region solve: L_b = L_a + (random bump inside the rectangle), so the gradients change only on
// edges incident to the rectangle. Starting from the full solution for L_a, the region solve must
// reproduce the full solution for L_b up to a constant, and leave the outside untouched.
struct RegionCase {
  PoissonBoundary boundary;
  PixelRect rect;
  const char* name;
};

TEST(Poisson, RegionSolveMatchesFullSolve) {
  const int W = 256, H = 128;
  const RegionCase cases[] = {
      {PoissonBoundary::kPeriodicU, {60, 40, 48, 32}, "periodic interior"},
      {PoissonBoundary::kPeriodicU, {W - 20, 10, 50, 30}, "periodic across the seam"},
      {PoissonBoundary::kPeriodicU, {-10, -5, 40, 40}, "periodic negative x, clipped top"},
      {PoissonBoundary::kPeriodicU, {0, 100, W, 28}, "periodic full width at the bottom"},
      {PoissonBoundary::kNeumann, {0, 0, 40, 30}, "Neumann top-left corner"},
      {PoissonBoundary::kNeumann, {W - 33, 64, 33, 64}, "Neumann bottom-right corner"},
      {PoissonBoundary::kNeumann, {100, 50, 128, 20}, "Neumann interior"},
  };
  std::mt19937 rng(3);
  std::normal_distribution<double> N(0.0, 0.3);
  for (const RegionCase& c : cases) {
    PoissonSolver s(W, H, opts(c.boundary));
    const ImageD La_true = smooth_field(W, H, 21, c.boundary == PoissonBoundary::kPeriodicU);
    ImageD Lb_true = La_true;
    const int y0 = std::max(c.rect.y, 0), y1 = std::min(c.rect.y + c.rect.height, H);
    for (int j = y0; j < y1; ++j)
      for (int t = 0; t < c.rect.width; ++t) Lb_true(j, ((c.rect.x + t) % W + W) % W) += N(rng);
    ImageD gxa, gya, gxb, gyb, La, Lb_full;
    evio::mapping::forward_gradient(La_true, c.boundary, &gxa, &gya);
    evio::mapping::forward_gradient(Lb_true, c.boundary, &gxb, &gyb);
    s.solve(gxa, gya, &La);
    s.solve(gxb, gyb, &Lb_full);
    ImageD Lb_region = La;
    s.solve_region(gxb, gyb, c.rect, &Lb_region);
    const double err = max_abs_diff_up_to_offset(Lb_region, Lb_full);
    EXPECT_LT(err, 1e-9) << c.name;
    // Outside the rectangle nothing moved beyond rounding: the solver grows the rectangle to sides
    // of multiples of 16 px, and there the exact solution is the old one.
    ImageD moved = (Lb_region - La).cwiseAbs();
    for (int j = y0; j < y1; ++j)
      for (int t = 0; t < c.rect.width; ++t) moved(j, ((c.rect.x + t) % W + W) % W) = 0;
    EXPECT_LT(moved.maxCoeff(), 1e-12) << c.name;
    std::printf("region %-34s max error vs full solve (up to offset) %.3g\n", c.name, err);
  }
}

// Non-integrable change inside the rectangle: the region solution satisfies the normal equations
// on the rectangle's pixels (with the outside held fixed).
TEST(Poisson, RegionSolveSatisfiesLocalNormalEquations) {
  const int W = 128, H = 64;
  const PixelRect rect{100, 20, 50, 30};  // straddles the seam
  PoissonSolver s(W, H, opts(PoissonBoundary::kPeriodicU));
  const ImageD La_true = smooth_field(W, H, 4, true);
  ImageD gx, gy, L;
  evio::mapping::forward_gradient(La_true, PoissonBoundary::kPeriodicU, &gx, &gy);
  s.solve(gx, gy, &L);
  std::mt19937 rng(9);
  std::normal_distribution<double> N(0.0, 0.5);
  for (int j = 20; j < 50; ++j)
    for (int t = 0; t < 50; ++t) gx(j, (100 + t) % W) += N(rng), gy(j, (100 + t) % W) += N(rng);
  s.solve_region(gx, gy, rect, &L);
  const ImageD res = evio::mapping::laplacian(L, PoissonBoundary::kPeriodicU) -
                     evio::mapping::divergence(gx, gy, PoissonBoundary::kPeriodicU);
  double worst = 0.0;
  for (int j = 20; j < 50; ++j)
    for (int t = 0; t < 50; ++t) worst = std::max(worst, std::abs(res(j, (100 + t) % W)));
  EXPECT_LT(worst, 1e-10);
}

TEST(Poisson, RegionLargerThanLimitFallsBackToFullSolve) {
  const int W = 64, H = 32;
  PoissonOptions o = opts(PoissonBoundary::kPeriodicU);
  o.max_region_side = 16;
  PoissonSolver s(W, H, o);
  const ImageD Lt = smooth_field(W, H, 8, true);
  ImageD gx, gy, full;
  evio::mapping::forward_gradient(Lt, PoissonBoundary::kPeriodicU, &gx, &gy);
  s.solve(gx, gy, &full);
  ImageD L = ImageD::Constant(H, W, 5.0);
  s.solve_region(gx, gy, PixelRect{0, 0, 20, 8}, &L);
  EXPECT_LT((L - full).cwiseAbs().maxCoeff(), 1e-12);
}

}  // namespace
