// Rotational contrast maximisation on synthetic events of points at infinity seen by a camera
// rotating at a known constant angular velocity: the estimate recovers it; no events and invalid
// options are handled.
#include "evio/mapping/contrast_maximization.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "evio/calib/geometry.h"

namespace {

using evio::mapping::RotationalCmaxOptions;

struct Events {
  std::vector<Eigen::Vector3f> bearings;
  std::vector<int64_t> t_ns;
};

// Stars (world directions) in front of the camera; R_w_c(t) = Exp(omega t); each event is a star
// at a random time in [0, span], quantised to its pixel (240x180, f = 200).
Events make_events(const Eigen::Vector3d& omega, double span_s, int stars, int per_star, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(-1, 1), T(0, span_s);
  Events e;
  const double f = 200, W = 240, H = 180;
  for (int s = 0; s < stars; ++s) {
    const Eigen::Vector3d d_w = Eigen::Vector3d(0.55 * U(rng), 0.42 * U(rng), 1).normalized();
    for (int k = 0; k < per_star; ++k) {
      const double t = T(rng);
      const Eigen::Vector3d b = evio::calib::so3_exp(omega * t).transpose() * d_w;
      if (b.z() <= 0) continue;
      const double x = std::round(f * b.x() / b.z() + W / 2 - 0.5), y = std::round(f * b.y() / b.z() + H / 2 - 0.5);
      if (x < 0 || y < 0 || x >= W || y >= H) continue;
      e.bearings.emplace_back(static_cast<float>((x + 0.5 - W / 2) / f), static_cast<float>((y + 0.5 - H / 2) / f), 1.f);
      e.t_ns.push_back(static_cast<int64_t>(std::llround(t * 1e9)) + 1'000'000'000'000'000'000LL);
    }
  }
  return e;
}

TEST(RotationalCmax, RecoversConstantAngularVelocity) {
  const Eigen::Vector3d cases[] = {{0.5, -1.2, 2.0}, {3.0, 1.0, -0.5}, {0, 0, 8.0}, {-6.0, 4.0, 1.0}};
  for (const Eigen::Vector3d& omega : cases) {
    const double span = 0.01;  // 10 ms; up to ~8.7 rad/s (500 deg/s)
    const Events e = make_events(omega, span, 150, 60, 7);
    const auto r = evio::mapping::estimate_angular_velocity(e.bearings, e.t_ns, e.t_ns.front(), Eigen::Vector3d::Zero());
    // t_ref is the first event's time, not 0: the model's reference rotation differs from the
    // generator's by Exp(omega t0), which does not change a constant angular velocity.
    const double err = (r.omega_c - omega).norm();
    std::printf("omega (%.1f %.1f %.1f) rad/s: estimate (%.3f %.3f %.3f), error %.4f rad/s, %d evaluations, contrast %.3g vs %.3g unwarped\n",
                omega.x(), omega.y(), omega.z(), r.omega_c.x(), r.omega_c.y(), r.omega_c.z(), err, r.evaluations,
                r.contrast, r.contrast_zero);
    EXPECT_LT(err, 0.05 * std::max(1.0, omega.norm())) << omega.transpose();
    EXPECT_GT(r.contrast, r.contrast_zero);
  }
}

TEST(RotationalCmax, StillCameraGivesZeroAndNoEventsGiveTheGuess) {
  const Events e = make_events(Eigen::Vector3d::Zero(), 0.02, 100, 40, 3);
  const auto r = evio::mapping::estimate_angular_velocity(e.bearings, e.t_ns, e.t_ns.front(), Eigen::Vector3d(0.3, -0.2, 0.1));
  EXPECT_LT(r.omega_c.norm(), 0.02) << r.omega_c.transpose();
  const auto empty = evio::mapping::estimate_angular_velocity({}, {}, 0, Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(empty.omega_c, Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(empty.evaluations, 0);
}

TEST(RotationalCmax, RejectsBadInput) {
  RotationalCmaxOptions o;
  std::string why;
  EXPECT_TRUE(o.Validate(&why));
  o.min_step_radps = 2 * o.initial_step_radps;
  EXPECT_FALSE(o.Validate(&why));
  o = {};
  o.focal_px = std::nan("");
  EXPECT_FALSE(o.Validate(&why));
  EXPECT_THROW(evio::mapping::estimate_angular_velocity({Eigen::Vector3f(0, 0, 1)}, {}, 0, Eigen::Vector3d::Zero()),
               std::invalid_argument);
}

}  // namespace
