// Trajectory re-propagation from the optimised keyframes: with IMU-consistent final keyframes the
// re-propagated frames are the true states whatever the (wrong) anchor they were predicted from;
// with final keyframes off the IMU motion the trajectory still passes through every keyframe and
// the correction is spread over the interval (no jump at the keyframe).
#include "evio/backend/trajectory_smoothing.h"

#include <cmath>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "evio/calib/geometry.h"

namespace evio::backend {
namespace {

const Eigen::Vector3d kG(0, 0, -9.81);

// True motion: constant body rate and constant world acceleration.
VioState truth(int64_t t_ns) {
  const double t = 1e-9 * static_cast<double>(t_ns);
  VioState s;
  s.t_ns = t_ns;
  const Eigen::Vector3d p0(1, 2, 3), v0(0.5, -0.2, 0.1), a(0.3, 0.4, -0.2), w(0.4, -0.3, 0.6);
  s.T_w_b = calib::SE3(calib::so3_exp_quat(Eigen::Vector3d(0.1, 0.2, 0.3)) * calib::so3_exp_quat(w * t), p0 + v0 * t + 0.5 * a * t * t);
  s.v_w = v0 + a * t;
  return s;
}

// What an estimator predicts for time t from keyframe state `anchor` taken at ta: the true IMU
// motion between ta and t applied to the anchor.
VioState predict(const VioState& anchor, int64_t t_ns) {
  const VioState a = truth(anchor.t_ns), b = truth(t_ns);
  const double dt = 1e-9 * static_cast<double>(t_ns - anchor.t_ns);
  const Eigen::Quaterniond qa = a.T_w_b.rotation;
  const Eigen::Quaterniond dR = qa.conjugate() * b.T_w_b.rotation;
  const Eigen::Vector3d dv = qa.conjugate() * (b.v_w - a.v_w - kG * dt);
  const Eigen::Vector3d dp = qa.conjugate() * (b.T_w_b.translation - a.T_w_b.translation - a.v_w * dt - 0.5 * kG * dt * dt);
  const Eigen::Quaterniond qk = anchor.T_w_b.rotation;
  VioState out = anchor;
  out.t_ns = t_ns;
  out.T_w_b = calib::SE3(qk * dR, anchor.T_w_b.translation + anchor.v_w * dt + 0.5 * kG * dt * dt + qk * dp);
  out.v_w = anchor.v_w + kG * dt + qk * dv;
  return out;
}

VioState perturbed(VioState s, double dp, double dv, double dtheta) {
  s.T_w_b = calib::SE3(calib::so3_exp_quat(Eigen::Vector3d(dtheta, -dtheta, 0.5 * dtheta)) * s.T_w_b.rotation,
                       s.T_w_b.translation + Eigen::Vector3d(dp, -dp, 0.5 * dp));
  s.v_w += Eigen::Vector3d(-dv, dv, dv);
  return s;
}

// Frames every 10 ms, keyframes every 100 ms; each frame predicted from the newest keyframe's
// state at the time, which is off the truth (the estimate before later solves).
std::vector<FramePrediction> frames_with_wrong_anchors(int n) {
  std::vector<FramePrediction> out;
  for (int i = 1; i <= n; ++i) {
    const int64_t t = i * 10'000'000LL, ta = (i - 1) / 10 * 100'000'000LL;
    FramePrediction f;
    f.predicted = true;
    f.anchor = perturbed(truth(ta), 0.05, 0.1, 0.03);
    f.prediction = predict(f.anchor, t);
    f.state = f.prediction;
    out.push_back(f);
  }
  return out;
}

double position_error(const VioState& a, const VioState& b) { return (a.T_w_b.translation - b.T_w_b.translation).norm(); }
double rotation_error(const VioState& a, const VioState& b) {
  return calib::so3_log(a.T_w_b.rotation.conjugate() * b.T_w_b.rotation).norm();
}

TEST(RepropagateTrajectory, ConsistentKeyframesGiveTheTrueStates) {
  const auto frames = frames_with_wrong_anchors(60);
  std::map<int64_t, VioState> kf;
  for (int64_t t = 0; t <= 600'000'000; t += 100'000'000) kf[t] = truth(t);
  const auto out = repropagate_trajectory(frames, kf, kG);
  ASSERT_EQ(out.size(), frames.size());
  double causal = 0;
  for (size_t i = 0; i < out.size(); ++i) {
    const VioState x = truth(frames[i].state.t_ns);
    EXPECT_EQ(out[i].t_ns, x.t_ns);
    EXPECT_LT(position_error(out[i], x), 1e-9) << i;
    EXPECT_LT(rotation_error(out[i], x), 1e-9) << i;
    EXPECT_LT((out[i].v_w - x.v_w).norm(), 1e-9) << i;
    causal = std::max(causal, position_error(frames[i].state, x));
  }
  EXPECT_GT(causal, 0.05);  // the causal states were off
}

TEST(RepropagateTrajectory, PassesThroughKeyframesAndSpreadsTheMismatch) {
  const auto frames = frames_with_wrong_anchors(60);
  std::map<int64_t, VioState> kf;
  // Every other keyframe 2 cm and 0.5 deg off the IMU-consistent motion.
  for (int64_t t = 0; t <= 600'000'000; t += 100'000'000)
    kf[t] = (t / 100'000'000) % 2 ? perturbed(truth(t), 0.02, 0.0, 0.5 * M_PI / 180) : truth(t);
  const auto out = repropagate_trajectory(frames, kf, kG);
  double max_step_error = 0;
  for (size_t i = 0; i < out.size(); ++i) {
    const auto k = kf.find(out[i].t_ns);
    if (k != kf.end()) {
      EXPECT_LT(position_error(out[i], k->second), 1e-12);
    }
    if (i > 0) {
      const Eigen::Vector3d step = out[i].T_w_b.translation - out[i - 1].T_w_b.translation;
      const Eigen::Vector3d true_step = truth(out[i].t_ns).T_w_b.translation - truth(out[i - 1].t_ns).T_w_b.translation;
      max_step_error = std::max(max_step_error, (step - true_step).norm());
    }
  }
  // A 2 cm (x 1.22) correction spread over 10 frames: about 2.4 mm per step, not one 24 mm jump.
  EXPECT_LT(max_step_error, 0.004);
  EXPECT_GT(max_step_error, 0.001);
}

TEST(RepropagateTrajectory, FramesWithoutAFinalAnchorKeepTheirCausalState) {
  auto frames = frames_with_wrong_anchors(5);
  frames[2].predicted = false;
  const auto out = repropagate_trajectory(frames, {}, kG);
  ASSERT_EQ(out.size(), 5u);
  for (size_t i = 0; i < 5; ++i) EXPECT_LT(position_error(out[i], frames[i].state), 1e-12);
}

}  // namespace
}  // namespace evio::backend
