// Contrast maximisation core: warp Jacobians and objective gradients against central finite
// differences, recovery of known motions from zero on synthetic events, and the extremes (no
// events, one event, one pixel, one timestamp, 1.7e18 ns stamps, very fast motion).
#include "evio/mapping/cmax.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

namespace {

using evio::mapping::CmaxEvents;
using evio::mapping::CmaxObjective;
using evio::mapping::CmaxOptions;
using evio::mapping::ContrastMaximizer;
using evio::mapping::WarpGeometry;
using evio::mapping::WarpModel;

const std::vector<WarpModel>& kModels = evio::mapping::warp_models();
const CmaxObjective kObjectives[] = {CmaxObjective::kVariance, CmaxObjective::kMeanSquare,
                                     CmaxObjective::kGradientMagnitude, CmaxObjective::kNormalizedGradientMagnitude};

WarpGeometry davis() {
  WarpGeometry g;
  g.fx = 200, g.fy = 198, g.cx = 121.3, g.cy = 88.7, g.depth_m = 2.0;
  return g;
}

// Parameters of a plausible motion for each model (about 5-10 px over 10 ms; the accelerations
// bend the path by 1.5-2 px over the 10 ms).
Eigen::VectorXd some_params(WarpModel m) {
  Eigen::VectorXd p(evio::mapping::warp_dof(m));
  switch (m) {
    case WarpModel::kFlow: p << 400, -250; break;
    case WarpModel::kSimilarity: p << 300, -200, 1.5, 2.0; break;
    case WarpModel::kRotation: p << 0.8, -1.5, 2.5; break;
    case WarpModel::kSixDof: p << 0.6, -0.3, 0.9, 0.8, -1.5, 2.5; break;
    case WarpModel::kFlowAccel: p << 400, -250, 3e4, 4e4; break;
    case WarpModel::kSimilarityAccel: p << 300, -200, 1.5, 2.0, -4e4, 3e4; break;
  }
  return p;
}

// A textured scene moving with flow field `motion` (a model and parameters): 300 short edges (4 px,
// random orientation), so both flow components are constrained (long straight edges are not:
// the aperture problem); each event is a point of the scene at a random time, placed where the motion takes it
// (the inverse of the warp to t_ref = window start, by fixed-point iteration).
CmaxEvents moving_scene(WarpModel m, const Eigen::VectorXd& p, const WarpGeometry& g, int n, uint64_t seed,
                        int64_t t0_ns = 1'000'000'000, double span_s = 0.01) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(0, 1);
  std::vector<Eigen::Vector4d> seg;
  for (int i = 0; i < 300; ++i) {
    const double x = 15 + 210 * U(rng), y = 12 + 156 * U(rng), a = M_PI * U(rng);
    seg.emplace_back(x, y, x + 4 * std::cos(a), y + 4 * std::sin(a));
  }
  CmaxEvents ev(t0_ns, g);
  CmaxEvents probe(t0_ns, g);
  for (int k = 0; k < n; ++k) {
    const Eigen::Vector4d& s = seg[k % seg.size()];
    const double a = U(rng);
    const Eigen::Vector2d X(s[0] + a * (s[2] - s[0]), s[1] + a * (s[3] - s[1]));  // position at t0
    const int64_t t = t0_ns + static_cast<int64_t>(span_s * 1e9 * U(rng));
    // Find x with warp(x, t) = X.
    Eigen::Vector2d x = X;
    for (int it = 0; it < 30; ++it) {
      probe.clear();
      probe.push_back(static_cast<float>(x.x()), static_cast<float>(x.y()), t, 1);
      Eigen::Vector2d w;
      if (!evio::mapping::warp_event(m, probe, 0, p, &w)) break;
      x += X - w;
    }
    ev.push_back(static_cast<float>(x.x()), static_cast<float>(x.y()), t, (k % 3) ? 1 : -1);
  }
  return ev;
}

TEST(CmaxWarp, JacobiansMatchFiniteDifferences) {
  const WarpGeometry g = davis();
  for (WarpModel m : kModels) {
    for (bool plane : {false, true}) {
      WarpGeometry gg = g;
      if (plane) gg.plane_normal_c = Eigen::Vector3d(0.2, -0.1, 1), gg.plane_distance_m = 1.5;
      CmaxEvents ev(0, gg);
      std::mt19937_64 rng(3);
      std::uniform_real_distribution<double> U(0, 1);
      for (int k = 0; k < 50; ++k)
        ev.push_back(static_cast<float>(240 * U(rng)), static_cast<float>(180 * U(rng)),
                     static_cast<int64_t>(-5e6 + 1e7 * U(rng)), 1);
      const Eigen::VectorXd p = some_params(m);
      double worst = 0;
      for (size_t k = 0; k < ev.size(); ++k) {
        for (double shift : {0.0, -0.004}) {
          Eigen::Vector2d w;
          Eigen::Matrix<double, 2, Eigen::Dynamic> J;
          ASSERT_TRUE(evio::mapping::warp_event(m, ev, k, p, &w, &J, shift));
          for (int i = 0; i < p.size(); ++i) {
            const double h = 1e-6 * std::max(1.0, std::abs(p[i]));
            Eigen::VectorXd pp = p, pm = p;
            pp[i] += h, pm[i] -= h;
            Eigen::Vector2d wp, wm;
            evio::mapping::warp_event(m, ev, k, pp, &wp, nullptr, shift);
            evio::mapping::warp_event(m, ev, k, pm, &wm, nullptr, shift);
            const Eigen::Vector2d fd = (wp - wm) / (2 * h);
            worst = std::max(worst, (fd - J.col(i)).norm() / std::max(1e-3, J.col(i).norm()));
          }
        }
      }
      EXPECT_LT(worst, 1e-5) << evio::mapping::warp_model_name(m) << (plane ? " plane" : " depth");
    }
  }
}

TEST(CmaxWarp, ZeroParametersAreTheIdentityAndNamesRoundTrip) {
  const WarpGeometry g = davis();
  CmaxEvents ev(0, g);
  ev.push_back(17.25f, 133.5f, 4'000'000, 1);
  for (WarpModel m : kModels) {
    Eigen::Vector2d w;
    ASSERT_TRUE(evio::mapping::warp_event(m, ev, 0, Eigen::VectorXd::Zero(evio::mapping::warp_dof(m)), &w));
    EXPECT_NEAR(w.x(), 17.25, 1e-4);
    EXPECT_NEAR(w.y(), 133.5, 1e-4);
    EXPECT_EQ(evio::mapping::warp_model_from_name(evio::mapping::warp_model_name(m)), m);
    EXPECT_EQ(static_cast<int>(evio::mapping::warp_parameter_names(m).size()), evio::mapping::warp_dof(m));
  }
  for (CmaxObjective o : kObjectives)
    EXPECT_EQ(evio::mapping::cmax_objective_from_name(evio::mapping::cmax_objective_name(o)), o);
  EXPECT_FALSE(evio::mapping::warp_model_from_name("affine"));
  EXPECT_EQ(evio::mapping::warp_model_names(), "flow, similarity, rotation, 6dof, flow_accel, similarity_accel");
}

// The accelerated warps follow one trajectory x(t) = x0 + v t + a t^2 / 2 (t from t_ref): warped
// to t_ref + shift, an event lands where that trajectory is at shift; and the parameters carried
// to a later reference time (warp_params_at) describe the same trajectory.
TEST(CmaxWarp, AcceleratedWarpsFollowOneTrajectory) {
  const WarpGeometry g = davis();
  for (WarpModel m : {WarpModel::kFlowAccel, WarpModel::kSimilarityAccel}) {
    EXPECT_NE(evio::mapping::warp_velocity_model(m), m);
    const Eigen::VectorXd p = some_params(m);
    const int64_t t_ref = 2'000'000'000, later = 3'000'000;  // the second reference 3 ms later
    CmaxEvents ev(t_ref, g), ev2(t_ref + later, g);
    for (int64_t dt : {-4'000'000, 1'000'000, 6'000'000}) {
      ev.push_back(100.5f, 60.25f, t_ref + dt, 1);
      ev2.push_back(100.5f, 60.25f, t_ref + dt, 1);
    }
    const Eigen::VectorXd p2 = evio::mapping::warp_params_at(m, p, later * 1e-9);
    for (size_t k = 0; k < ev.size(); ++k) {
      Eigen::Vector2d at0, at_shift, at_later;
      ASSERT_TRUE(evio::mapping::warp_event(m, ev, k, p, &at0));
      ASSERT_TRUE(evio::mapping::warp_event(m, ev, k, p, &at_shift, nullptr, later * 1e-9));
      ASSERT_TRUE(evio::mapping::warp_event(m, ev2, k, p2, &at_later));
      EXPECT_LT((at_shift - at_later).norm(), 1e-4) << evio::mapping::warp_model_name(m) << " event " << k;
      if (m == WarpModel::kFlowAccel) {  // x0 + v s + a s^2 / 2 at s = 3 ms
        const double s = later * 1e-9;
        const Eigen::Vector2d expect = at0 + s * p.head<2>() + 0.5 * s * s * p.tail<2>();
        EXPECT_LT((at_shift - expect).norm(), 1e-4) << "event " << k;
      }
    }
    // The first-order models are not carried.
    EXPECT_TRUE(evio::mapping::warp_params_at(WarpModel::kFlow, p.head<2>(), 0.1).isApprox(p.head<2>()));
  }
}

// The analytic gradient is exact for the piecewise-smooth objective (bilinear votes have kinks at
// pixel borders): central differences with steps that move events by ~0.005 px agree to the share
// of events crossing a border in the step (measured worst 1.5%); a wrong factor or sign in any
// Jacobian entry, the blur adjoint or a level's scale is an error of 50% or more.
TEST(CmaxObjective, GradientMatchesFiniteDifferences) {
  const WarpGeometry g = davis();
  double worst = 0;
  for (WarpModel m : kModels) {
    const Eigen::VectorXd truth = some_params(m);
    const CmaxEvents ev = moving_scene(m, truth, g, 4000, 11);
    std::vector<float> weights(ev.size());
    for (size_t k = 0; k < ev.size(); ++k) weights[k] = 0.25f + 0.75f * static_cast<float>((k * 7919) % 100) / 100.0f;
    for (CmaxObjective o : kObjectives) {
      for (int level : {0, 1}) {
        for (bool polarity : {false, true}) {
          CmaxOptions opt;
          opt.model = m, opt.objective = o, opt.geometry = g, opt.use_polarity = polarity;
          ContrastMaximizer cm(opt);
          const Eigen::VectorXd p = 0.6 * truth;  // off the optimum: a clear gradient
          Eigen::VectorXd grad;
          cm.objective(ev, p, level, weights.data(), &grad);
          Eigen::VectorXd fd(p.size());
          for (int i = 0; i < p.size(); ++i) {
            const double h = 1e-3 * std::max(1.0, std::abs(p[i]));
            Eigen::VectorXd pp = p, pm = p;
            pp[i] += h, pm[i] -= h;
            fd[i] = (cm.objective(ev, pp, level, weights.data()) - cm.objective(ev, pm, level, weights.data())) / (2 * h);
          }
          const double err = (fd - grad).norm() / grad.norm();
          worst = std::max(worst, err);
          EXPECT_LT(err, 2.5e-2) << evio::mapping::warp_model_name(m) << " " << evio::mapping::cmax_objective_name(o)
                               << " level " << level << " polarity " << polarity << "\n analytic " << grad.transpose()
                               << "\n numeric  " << fd.transpose();
        }
      }
    }
  }
  std::printf("worst relative gradient error against central differences: %.4f\n", worst);
}

TEST(CmaxMaximize, RecoversEachModelFromZero) {
  const WarpGeometry g = davis();
  for (WarpModel m : kModels) {
    const Eigen::VectorXd truth = some_params(m);
    const CmaxEvents ev = moving_scene(m, truth, g, 20000, 5);
    CmaxOptions opt;
    opt.model = m, opt.geometry = g;
    const auto r = evio::mapping::maximize_contrast(ev, opt);
    // Compare displacements over the window (what the events constrain), at the scene's corners.
    double worst = 0;
    CmaxEvents probe(ev.t_ref_ns(), g);
    for (float x : {10.f, 230.f})
      for (float y : {10.f, 170.f})
        for (int64_t dt : {5'000'000, 10'000'000}) probe.push_back(x, y, ev.t_ref_ns() + dt, 1);
    for (size_t k = 0; k < probe.size(); ++k) {
      Eigen::Vector2d a, b;
      evio::mapping::warp_event(m, probe, k, truth, &a);
      evio::mapping::warp_event(m, probe, k, r.params, &b);
      worst = std::max(worst, (a - b).norm());
    }
    std::printf("%s: truth %s, estimate %s, worst displacement error over 5 and 10 ms %.3f px, %d iterations, %d evaluations\n",
                evio::mapping::warp_model_name(m), ::testing::PrintToString(truth.transpose().eval()).c_str(),
                ::testing::PrintToString(r.params.transpose().eval()).c_str(), worst, r.iterations, r.evaluations);
    // Measured 0.057 (flow), 0.101 (similarity), 0.085 (rotation), 0.216 (6dof), 0.091 (flow_accel:
    // with t_ref at the window's start, dt and dt^2 are nearly collinear, so v and a trade off),
    // 0.117 (similarity_accel) px.
    const double bound = m == WarpModel::kFlow       ? 0.08
                         : m == WarpModel::kRotation ? 0.1
                         : m == WarpModel::kSixDof   ? 0.3
                                                     : 0.15;
    EXPECT_LT(worst, bound) << evio::mapping::warp_model_name(m);
    EXPECT_GT(r.objective, r.objective_zero);
  }
}

TEST(CmaxMaximize, Extremes) {
  const WarpGeometry g = davis();
  for (WarpModel m : kModels) {
    CmaxOptions opt;
    opt.model = m, opt.geometry = g;
    ContrastMaximizer cm(opt);
    const int dof = evio::mapping::warp_dof(m);
    // No events: the initial guess back, finite objectives.
    CmaxEvents none(5, g);
    auto r = cm.maximize(none, Eigen::VectorXd::Constant(dof, 0.5));
    EXPECT_EQ(r.stop, "no_events");
    EXPECT_TRUE(r.params.isApprox(Eigen::VectorXd::Constant(dof, 0.5)));
    // One event; all events on one pixel; all at one timestamp (dt = 0: the warp cannot move
    // anything, zero gradient); 1.7e18 ns stamps.
    const int64_t big = 1'700'000'000'000'000'000LL;
    CmaxEvents one(big, g), pixel(big, g), instant(big, g);
    one.push_back(100, 80, big + 3'000'000, 1);
    for (int k = 0; k < 5000; ++k) {
      pixel.push_back(57, 33, big + k * 2000, k % 2 ? 1 : -1);
      instant.push_back(static_cast<float>(k % 240), static_cast<float>((k * 7) % 180), big, 1);
    }
    for (const CmaxEvents* e : {&one, &pixel, &instant}) {
      r = cm.maximize(*e);
      EXPECT_TRUE(r.params.allFinite()) << evio::mapping::warp_model_name(m);
      EXPECT_TRUE(std::isfinite(r.objective));
      EXPECT_GE(r.objective, r.objective_zero - 1e-12);
    }
    EXPECT_EQ(cm.maximize(instant).params.norm(), 0.0);
  }
  // 1000 deg/s about the optical axis over 10 ms (0.17 rad): recovered from zero.
  CmaxOptions opt;
  opt.model = WarpModel::kRotation, opt.geometry = g;
  Eigen::VectorXd w(3);
  w << 0.0, 0.0, 1000.0 * M_PI / 180.0;
  const CmaxEvents fast = moving_scene(WarpModel::kRotation, w, g, 20000, 9);
  const auto r = evio::mapping::maximize_contrast(fast, opt);
  EXPECT_NEAR(r.params[2], w[2], 0.02 * w[2]) << r.params.transpose();
  EXPECT_LT(r.params.head<2>().norm(), 0.1);
  // A 10x burst (ten times the events, same motion) gives the same answer.
  Eigen::VectorXd v(2);
  v << 600, 300;
  CmaxOptions fo;
  fo.geometry = g;
  const auto r1 = evio::mapping::maximize_contrast(moving_scene(WarpModel::kFlow, v, g, 5000, 4), fo);
  const auto r10 = evio::mapping::maximize_contrast(moving_scene(WarpModel::kFlow, v, g, 50000, 4), fo);
  std::printf("1000 deg/s: wz %.4f rad/s (truth %.4f); flow from 5000 events: error %.2f px/s, from 50000: %.2f px/s\n",
              r.params[2], w[2], (r1.params - v).norm(), (r10.params - v).norm());
  EXPECT_LT((r1.params - v).norm(), 20.0) << r1.params.transpose();
  EXPECT_LT((r10.params - v).norm(), 4.0) << r10.params.transpose();
}

TEST(CmaxMaximize, RejectsBadOptionsAndSizes) {
  CmaxOptions o;
  std::string why;
  o.pyramid_levels = 0;
  EXPECT_FALSE(o.Validate(&why));
  EXPECT_NE(why.find("pyramid_levels"), std::string::npos);
  EXPECT_THROW(ContrastMaximizer{o}, std::invalid_argument);
  o = CmaxOptions();
  o.geometry.fx = -1;
  EXPECT_FALSE(o.Validate(&why));
  EXPECT_NE(why.find("fx"), std::string::npos);
  ContrastMaximizer cm{CmaxOptions()};
  CmaxEvents ev(0, WarpGeometry());
  ev.push_back(1, 1, 1, 1);
  EXPECT_THROW(cm.maximize(ev, Eigen::VectorXd::Zero(3)), std::invalid_argument);
  EXPECT_THROW(cm.objective(ev, Eigen::VectorXd::Zero(5), 0), std::invalid_argument);
}

}  // namespace
