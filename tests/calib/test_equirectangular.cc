#include "evio/calib/equirectangular.h"
#include <gtest/gtest.h>
using evio::calib::Equirectangular;
TEST(Equirectangular, RoundTripAndPixelCentres) {
  Equirectangular e(1024, 512);
  for (int j = 0; j < 512; j += 37)
    for (int i = 0; i < 1024; i += 53) {
      const Eigen::Vector3d d = e.pixel_direction(i, j);
      EXPECT_NEAR(d.norm(), 1.0, 1e-12);
      const Eigen::Vector2d uv = e.project(d);
      EXPECT_NEAR(uv.x(), i + 0.5, 1e-9);
      EXPECT_NEAR(uv.y(), j + 0.5, 1e-9);
    }
  // +x looks at the centre column, +z at the top row, -x at the seam (u = 0 == W).
  EXPECT_NEAR(e.project(Eigen::Vector3d(1, 0, 0)).x(), 512.0, 1e-9);
  EXPECT_NEAR(e.project(Eigen::Vector3d(0, 0, 1)).y(), 0.0, 1e-9);
  EXPECT_NEAR(e.project(Eigen::Vector3d(0, 0, -1)).y(), 512.0, 1e-9);
  const double u_seam = e.project(Eigen::Vector3d(-1, 1e-15, 0)).x();
  EXPECT_TRUE(u_seam < 1e-6 || u_seam > 1024 - 1e-6);
}
TEST(Equirectangular, JacobianMatchesFiniteDifferences) {
  Equirectangular e(2048, 1024);
  const Eigen::Vector3d dirs[] = {{1, 0.3, 0.2}, {-0.4, 0.9, -0.7}, {0.1, -0.2, 3.0}, {2, 2, 0}};
  for (const auto& d : dirs) {
    Eigen::Matrix<double, 2, 3> J;
    e.project(d, &J);
    for (int k = 0; k < 3; ++k) {
      const double h = 1e-6;
      Eigen::Vector3d a = d, b = d;
      a[k] += h;
      b[k] -= h;
      const Eigen::Vector2d num = (e.project(a) - e.project(b)) / (2 * h);
      EXPECT_NEAR(J(0, k), num.x(), 1e-4 * (1 + std::abs(num.x())));
      EXPECT_NEAR(J(1, k), num.y(), 1e-4 * (1 + std::abs(num.y())));
    }
  }
  Eigen::Matrix<double, 2, 3> J;
  e.project(Eigen::Vector3d(0, 0, 1), &J);  // pole: finite
  EXPECT_TRUE(J.allFinite());
}
