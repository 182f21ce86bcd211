#include "evio/mapping/rotation_relocalization.h"

#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "evio/calib/equirectangular.h"
#include "evio/calib/geometry.h"

namespace evio::mapping {
namespace {

constexpr int kW = 1024, kH = 512;

// Log intensity of a smooth random scene: a sum of Gaussian blobs on the sphere (direction d).
struct BlobScene {
  std::vector<Eigen::Vector3d> centres;
  std::vector<double> amp, width;
  explicit BlobScene(unsigned seed) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> g(0, 1);
    std::uniform_real_distribution<double> u(0.02, 0.08);
    for (int k = 0; k < 600; ++k) {
      centres.push_back(Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized());
      amp.push_back(g(rng));
      width.push_back(u(rng));
    }
  }
  double value(const Eigen::Vector3d& d) const {
    double v = 0;
    for (size_t k = 0; k < centres.size(); ++k) {
      const double c = (d - centres[k]).squaredNorm();
      if (c < 25 * width[k] * width[k]) v += amp[k] * std::exp(-0.5 * c / (width[k] * width[k]));
    }
    return v;
  }
};

// The mosaic of the scene, known (not NaN) within |longitude| < 100 deg and |latitude| < 50 deg.
std::vector<float> known_mosaic(const BlobScene& scene) {
  const calib::Equirectangular proj(kW, kH);
  std::vector<float> m(static_cast<size_t>(kW) * kH, std::numeric_limits<float>::quiet_NaN());
  for (int j = 0; j < kH; ++j)
    for (int i = 0; i < kW; ++i) {
      const Eigen::Vector3d d = proj.pixel_direction(i, j);
      const double lon = std::atan2(d.y(), d.x()), lat = std::asin(d.z());
      if (std::abs(lon) < 100 * M_PI / 180 && std::abs(lat) < 50 * M_PI / 180)
        m[static_cast<size_t>(j) * kW + i] = static_cast<float>(scene.value(d));
    }
  return m;
}

// "Events" of a 240 x 180 camera (f = 200 px) at R_w_c: the bearings of the pixels whose scene
// gradient (finite difference over one pixel) is largest, the strongest 1500.
std::vector<Eigen::Vector3f> edge_bearings(const BlobScene& scene, const Eigen::Matrix3d& R_w_c) {
  std::vector<std::pair<double, Eigen::Vector3f>> all;
  for (int y = 0; y < 180; y += 2)
    for (int x = 0; x < 240; x += 2) {
      const Eigen::Vector3d b = Eigen::Vector3d((x - 120) / 200.0, (y - 90) / 200.0, 1).normalized();
      const Eigen::Vector3d bx = Eigen::Vector3d((x + 1 - 120) / 200.0, (y - 90) / 200.0, 1).normalized();
      const Eigen::Vector3d by = Eigen::Vector3d((x - 120) / 200.0, (y + 1 - 90) / 200.0, 1).normalized();
      const double v = scene.value(R_w_c * b);
      const double g = std::hypot(scene.value(R_w_c * bx) - v, scene.value(R_w_c * by) - v);
      all.push_back({g, b.cast<float>()});
    }
  std::sort(all.begin(), all.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
  std::vector<Eigen::Vector3f> out;
  for (size_t k = 0; k < 1500 && k < all.size(); ++k) out.push_back(all[k].second);
  return out;
}

TEST(RotationRelocalization, FindsTheViewAnywhereOnTheKnownMosaic) {
  const BlobScene scene(7);
  const std::vector<float> map = known_mosaic(scene);
  const RotationRelocalizationOptions o;
  const RelocalizationMap rmap(map.data(), kW, kH, o);
  // Three views inside the known part, with different axes and rolls.
  const Eigen::Vector3d rv[] = {{0.3, -1.2, 0.4}, {1.9, 0.2, -0.7}, {-0.5, 2.4, 1.1}};
  for (const Eigen::Vector3d& v : rv) {
    // Look along a known direction: start from the axis-roll frame of lon 30 deg, lat 10 deg and
    // rotate by a random-ish rotation whose axis keeps the view inside the known band.
    const double lon = std::atan2(v.y(), v.x()) * 0.5, lat = 0.3 * std::sin(v.z());
    const Eigen::Vector3d d(std::cos(lat) * std::cos(lon), std::cos(lat) * std::sin(lon), std::sin(lat));
    const Eigen::Vector3d ref = Eigen::Vector3d::UnitZ().cross(d).normalized();
    Eigen::Matrix3d R;
    const double phi = v.norm();
    R.col(0) = std::cos(phi) * ref + std::sin(phi) * d.cross(ref);
    R.col(1) = d.cross(R.col(0));
    R.col(2) = d;
    const std::vector<Eigen::Vector3f> b = edge_bearings(scene, R);
    const RotationRelocalizationResult res = rmap.search(b);
    ASSERT_TRUE(res.valid);
    const double err_deg = calib::so3_log(res.R_w_c.transpose() * R).norm() * 180 / M_PI;
    std::printf("view lon %.1f lat %.1f roll %.1f deg: error %.3f deg, score %.4f (runner-up %.4f, at the truth %.4f), %d coarse candidates\n",
                lon * 180 / M_PI, lat * 180 / M_PI, phi * 180 / M_PI, err_deg, res.score, res.runner_up_score,
                rmap.score(R, b), res.coarse_candidates);
    EXPECT_LT(err_deg, 0.3);
    EXPECT_GE(res.score, rmap.score(R, b) * 0.999);
    EXPECT_LT(res.runner_up_score, res.score);
  }
}

TEST(RotationRelocalization, NothingToSearchIsNotValidAndBadOptionsAreRejected) {
  const std::vector<float> unknown(static_cast<size_t>(kW) * kH, std::numeric_limits<float>::quiet_NaN());
  const RelocalizationMap rmap(unknown.data(), kW, kH, {});
  EXPECT_FALSE(rmap.search({}).valid);
  const RotationRelocalizationResult r = rmap.search({Eigen::Vector3f(0, 0, 1)});
  EXPECT_FALSE(r.valid);
  EXPECT_EQ(r.coarse_candidates, 0);
  RotationRelocalizationOptions o;
  o.refine_final_step_deg = 5;  // above the initial step
  std::string why;
  EXPECT_FALSE(o.Validate(&why));
  EXPECT_NE(why.find("refine"), std::string::npos);
  EXPECT_THROW(RelocalizationMap(unknown.data(), kW, kH, o), std::invalid_argument);
}

}  // namespace
}  // namespace evio::mapping
