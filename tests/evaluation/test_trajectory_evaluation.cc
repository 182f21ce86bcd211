// Known-answer tests of evio::evaluation (association, alignment, ATE, RPE).
#include "evio/evaluation/trajectory_evaluation.h"

#include <cmath>
#include <random>
#include <stdexcept>

#include <gtest/gtest.h>

#include "evio_test/real_data.h"

namespace ev = evio::evaluation;
using evio::calib::SE3;
using evio::calib::Quat;

namespace {

// A 3-D curve with varying orientation, 100 Hz, t0 large (1.7e18 ns).
evio::Trajectory curve(size_t n = 500, int64_t t0 = 1700000000000000000LL) {
  std::vector<evio::StampedPose> p;
  for (size_t k = 0; k < n; ++k) {
    const double s = 0.01 * static_cast<double>(k);
    Eigen::Vector3d pos(std::cos(s) * 3, std::sin(1.3 * s) * 2, 0.5 * std::sin(0.7 * s) + 0.1 * s);
    Quat q = evio::calib::so3_exp_quat(Eigen::Vector3d(0.2 * std::sin(s), 0.1 * std::cos(2 * s), 0.8 * s));
    p.push_back({t0 + static_cast<int64_t>(k) * 10000000, SE3(q, pos)});
  }
  return evio::Trajectory(p);
}

evio::Trajectory transformed(const evio::Trajectory& t, const Eigen::Matrix3d& R, const Eigen::Vector3d& tr, double s) {
  std::vector<evio::StampedPose> p;
  for (const auto& x : t) p.push_back({x.t_ns, SE3(Quat(R) * x.T_w_b.rotation, s * (R * x.T_w_b.translation) + tr)});
  return evio::Trajectory(p);
}

Eigen::Matrix3d some_rotation() { return evio::calib::so3_exp(Eigen::Vector3d(0.3, -0.5, 1.1)); }

}  // namespace

TEST(Evaluation, IdenticalTrajectoriesGiveZeroErrors) {
  const auto gt = curve();
  ev::EvaluationOptions o;
  const auto r = ev::evaluate(gt, gt, o);
  EXPECT_EQ(r.matched_poses, gt.size());
  EXPECT_LT(r.ate.trans_m.max, 1e-9);
  EXPECT_LT(r.ate.rot_deg.max, 1e-6);
  ASSERT_EQ(r.rpe.size(), 5u);
  for (const auto& e : r.rpe) {
    EXPECT_GT(e.count, 0u);
    EXPECT_LT(e.trans_percent.max, 1e-9);
    EXPECT_LT(e.rot_deg.max, 1e-6);
  }
}

TEST(Evaluation, EachAlignmentRecoversKnownTransform) {
  const auto gt = curve();
  const Eigen::Matrix3d R = some_rotation();
  const Eigen::Vector3d t(1.5, -2.0, 0.7);
  struct Case { ev::Alignment a; Eigen::Matrix3d R; double s; };
  const Eigen::Matrix3d Rz = Eigen::AngleAxisd(0.9, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  for (const Case& c : {Case{ev::Alignment::kSE3, R, 1.0}, Case{ev::Alignment::kSim3, R, 2.5},
                        Case{ev::Alignment::kPosYaw, Rz, 1.0}}) {
    // estimate = inverse transform of gt, so alignment must give (R, t, s).
    const Eigen::Matrix3d Ri = c.R.transpose();
    const auto est = transformed(gt, Ri, -(Ri * t) / c.s, 1.0 / c.s);
    ev::EvaluationOptions o;
    o.alignment.method = c.a;
    const auto r = ev::evaluate(gt, est, o);
    EXPECT_LT((r.alignment.rotation - c.R).norm(), 1e-9) << ev::alignment_name(c.a);
    EXPECT_LT((r.alignment.translation - t).norm(), 1e-9) << ev::alignment_name(c.a);
    EXPECT_NEAR(r.alignment.scale, c.s, 1e-9);
    EXPECT_LT(r.ate.trans_m.max, 1e-9);
    EXPECT_LT(r.ate.rot_deg.max, 1e-6);
  }
}

// first_pose aligns the first pair's poses whatever the positions say: an exact transform is
// recovered; a camera turning in place with position noise (which an SE3 fit on positions
// follows, turning the whole estimate) keeps its orientation error zero; positions alone are
// refused.
TEST(Evaluation, FirstPoseAlignmentIgnoresPositionNoise) {
  const auto gt = curve();
  const Eigen::Matrix3d R = some_rotation();
  const Eigen::Vector3d t(1.5, -2.0, 0.7);
  ev::EvaluationOptions o;
  o.alignment.method = ev::Alignment::kFirstPose;
  {
    const auto r = ev::evaluate(gt, transformed(gt, R.transpose(), -(R.transpose() * t), 1.0), o);
    EXPECT_LT((r.alignment.rotation - R).norm(), 1e-9);
    EXPECT_LT((r.alignment.translation - t).norm(), 1e-9);
    EXPECT_EQ(r.alignment.pairs_used, 1u);
    EXPECT_LT(r.ate.trans_m.max, 1e-9);
    EXPECT_LT(r.ate.rot_deg.max, 1e-6);
  }
  // Turning in place (orientation along the curve's, positions within 2 cm of a point) with
  // 1 cm position noise in the estimate only: an SE3 fit on the positions turns the estimate.
  std::vector<evio::StampedPose> g, e;
  std::mt19937_64 rng(3);
  std::normal_distribution<double> N(0, 0.01);
  for (const auto& p : gt) {
    const Eigen::Vector3d c = 0.02 * p.T_w_b.translation.normalized();
    g.push_back({p.t_ns, SE3(p.T_w_b.rotation, c)});
    e.push_back({p.t_ns, SE3(p.T_w_b.rotation, c + Eigen::Vector3d(N(rng), N(rng), N(rng)))});
  }
  const auto first = ev::evaluate(evio::Trajectory(g), evio::Trajectory(e), o);
  EXPECT_LT(first.ate.rot_deg.max, 1e-6);
  ev::EvaluationOptions se3;
  se3.alignment.first_s = 5;
  const auto fitted = ev::evaluate(evio::Trajectory(g), evio::Trajectory(e), se3);
  std::printf("in place, 1 cm position noise: orientation ATE %.3g deg first_pose, %.3g deg se3 on 5 s\n", first.ate.rot_deg.rmse,
              fitted.ate.rot_deg.rmse);
  EXPECT_GT(fitted.ate.rot_deg.rmse, 1.4);  // measured 1.75 deg
  EXPECT_THROW(ev::align_positions({Eigen::Vector3d::Zero()}, {Eigen::Vector3d::Zero()}, ev::Alignment::kFirstPose),
               std::invalid_argument);
  EXPECT_EQ(ev::alignment_from_name("first_pose"), ev::Alignment::kFirstPose);
}

TEST(Evaluation, ConstantOffsetGivesAteEqualToOffset) {
  const auto gt = curve();
  const auto est = transformed(gt, Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.3, 0.4, 0), 1.0);
  ev::EvaluationOptions o;
  o.alignment.method = ev::Alignment::kNone;
  const auto r = ev::evaluate(gt, est, o);
  EXPECT_NEAR(r.ate.trans_m.rmse, 0.5, 1e-12);
  EXPECT_NEAR(r.ate.trans_m.median, 0.5, 1e-12);
  EXPECT_NEAR(r.ate.trans_m.std, 0.0, 1e-12);
  EXPECT_NEAR(r.mean_position_error_percent, 100 * 0.5 / r.groundtruth_length_m, 1e-12);
  // A constant offset does not change relative motion.
  for (const auto& e : r.rpe) EXPECT_LT(e.trans_m.max, 1e-9);
}

TEST(Evaluation, LinearDriftGivesAnalyticRpe) {
  // Straight line, 1 m spacing, 101 poses; estimate position = gt * (1 + k).
  const double k = 0.03;
  std::vector<evio::StampedPose> g, e;
  for (int i = 0; i <= 100; ++i) {
    const int64_t t = 1000000000LL * i;
    g.push_back({t, SE3(Quat::Identity(), Eigen::Vector3d(i, 0, 0))});
    e.push_back({t, SE3(Quat::Identity(), Eigen::Vector3d(i * (1 + k), 0, 0))});
  }
  ev::EvaluationOptions o;
  o.alignment.method = ev::Alignment::kNone;
  o.rpe.lengths = {10, 20, 50};
  o.rpe.lengths_in_percent = false;
  const auto r = ev::evaluate(evio::Trajectory(g), evio::Trajectory(e), o);
  ASSERT_EQ(r.rpe.size(), 3u);
  for (const auto& x : r.rpe) {
    // rpg protocol: an end within 0.2 * length of the target counts, so starts i < 100 - 0.8 L
    // are used; the last ones end at the final pose, 0.8 L + 1 m after their start.
    const double L = x.length_m;
    EXPECT_EQ(x.count, static_cast<size_t>(100 - 0.8 * L));
    EXPECT_NEAR(x.trans_percent.max, 100 * k, 1e-9);
    EXPECT_NEAR(x.trans_percent.median, 100 * k, 1e-9);
    EXPECT_NEAR(x.trans_percent.min, 100 * k * (0.8 * L + 1) / L, 1e-9);
    EXPECT_NEAR(x.trans_m.max, k * L, 1e-9);
  }
  // Percent lengths: 10% of 100 m = 10 m.
  o.rpe.lengths = {10};
  o.rpe.lengths_in_percent = true;
  const auto r2 = ev::evaluate(evio::Trajectory(g), evio::Trajectory(e), o);
  ASSERT_EQ(r2.rpe.size(), 1u);
  EXPECT_DOUBLE_EQ(r2.rpe[0].length_m, 10.0);
  EXPECT_EQ(r2.rpe[0].count, 92u);
}

TEST(Evaluation, RollOffsetSurvivesPosYawButNotSe3) {
  const auto gt = curve();
  const Eigen::Matrix3d Rx = Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitX()).toRotationMatrix();
  const auto est = transformed(gt, Rx, Eigen::Vector3d(0.2, 0, 0), 1.0);
  ev::EvaluationOptions o;
  o.alignment.method = ev::Alignment::kPosYaw;
  const auto r = ev::evaluate(gt, est, o);
  EXPECT_GT(r.ate.rot_deg.mean, 1.0);
  o.alignment.method = ev::Alignment::kSE3;
  const auto r2 = ev::evaluate(gt, est, o);
  EXPECT_LT(r2.ate.rot_deg.max, 1e-6);
  EXPECT_LT(r2.ate.trans_m.max, 1e-9);
}

TEST(Evaluation, AssociationOffsetMaxDtAndUnitHint) {
  const auto gt = curve(100);
  std::vector<evio::StampedPose> shifted;
  for (const auto& p : gt) shifted.push_back({p.t_ns + 5000000, p.T_w_b});  // +5 ms, halfway between gt poses
  const evio::Trajectory est(shifted);
  ev::AssociationOptions a;
  a.max_dt_s = 0.004;
  // Without the offset every estimate is 5 ms from its gt neighbours: none within 4 ms -> an
  // error that says how far apart they are.
  try {
    ev::associate(gt, est, a);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("closest stamps"), std::string::npos) << e.what();
  }
  a.time_offset_s = -0.005;
  const auto pairs = ev::associate(gt, est, a);
  EXPECT_EQ(pairs.size(), 100u);
  EXPECT_EQ(pairs.t_ns[0], gt[0].t_ns);
  // Estimate in seconds-as-ns: factor 1e9.
  std::vector<evio::StampedPose> secs;
  for (int i = 0; i < 10; ++i) secs.push_back({1700000000LL + i, SE3()});
  try {
    ev::associate(gt, evio::Trajectory(secs), ev::AssociationOptions());
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("1e9"), std::string::npos) << e.what();
  }
}

TEST(Evaluation, InterpolationModeMatchesMidpoints) {
  const auto gt = curve(100);
  std::vector<evio::StampedPose> mid;
  for (size_t k = 0; k + 1 < gt.size(); ++k) {
    mid.push_back({gt[k].t_ns + 5000000, evio::calib::se3_interpolate(gt[k].T_w_b, gt[k + 1].T_w_b, 0.5)});
  }
  ev::EvaluationOptions o;
  o.association.interpolate_groundtruth = true;
  o.alignment.method = ev::Alignment::kNone;
  const auto r = ev::evaluate(gt, evio::Trajectory(mid), o);
  EXPECT_EQ(r.matched_poses, 99u);
  EXPECT_LT(r.ate.trans_m.max, 1e-12);
}

TEST(Evaluation, DegenerateInputs) {
  std::vector<evio::StampedPose> one = {{0, SE3()}};
  ev::EvaluationOptions o;
  EXPECT_THROW(ev::evaluate(evio::Trajectory(one), evio::Trajectory(one), o), std::invalid_argument);
  // Stationary: zero-length RPE skipped; a percentage of no distance is NaN (null in JSON), the
  // absolute errors are finite.
  std::vector<evio::StampedPose> still;
  for (int i = 0; i < 10; ++i) still.push_back({i * 1000000LL, SE3()});
  o.alignment.method = ev::Alignment::kNone;
  const auto r = ev::evaluate(evio::Trajectory(still), evio::Trajectory(still), o);
  EXPECT_TRUE(r.rpe.empty());
  EXPECT_TRUE(std::isnan(r.mean_position_error_percent));
  EXPECT_TRUE(std::isnan(r.yaw_drift_deg_per_m));
  EXPECT_EQ(r.ate.trans_m.rmse, 0.0);
  EXPECT_EQ(r.final_yaw_error_deg, 0.0);
  // Rotating in place (all positions equal): se3 falls back to the first pair's poses, so a
  // known rotation of the estimate's world is undone and the rotation errors vanish.
  std::vector<evio::StampedPose> spin_gt, spin_est;
  const auto q_off = evio::calib::so3_exp_quat(Eigen::Vector3d(0.2, -0.4, 1.0));
  for (int i = 0; i < 50; ++i) {
    const auto q = evio::calib::so3_exp_quat(Eigen::Vector3d(0.3 * std::sin(0.1 * i), 0.02 * i, 0.5 * std::cos(0.07 * i)));
    spin_gt.push_back({i * 10000000LL, SE3(q, Eigen::Vector3d(1, 2, 3))});
    spin_est.push_back({i * 10000000LL, SE3(q_off * q, Eigen::Vector3d(-1, 0, 4))});
  }
  o.alignment.method = ev::Alignment::kSE3;
  const auto spin = ev::evaluate(evio::Trajectory(spin_gt), evio::Trajectory(spin_est), o);
  EXPECT_LT(spin.ate.rot_deg.max, 1e-9);
  EXPECT_LT(spin.ate.trans_m.max, 1e-12);
  const auto s = ev::compute_stats({1, 2, 3, 4});
  EXPECT_DOUBLE_EQ(s.median, 2.5);
  EXPECT_DOUBLE_EQ(s.std, std::sqrt(1.25));
}

TEST(Evaluation, RealPosterMocapPerturbedCopy) {
  const auto dir = evio_test::real_data_dir("trajectories");
  if (!dir) GTEST_SKIP() << "real trajectories not present";
  const auto gt = evio::read_euroc_csv(*dir + "/poster_6dof_mocap.csv");
  const auto est = transformed(gt, Eigen::Matrix3d::Identity(), Eigen::Vector3d(0.01, -0.02, 0.02), 1.0);
  ev::EvaluationOptions o;
  o.alignment.method = ev::Alignment::kNone;
  const auto r = ev::evaluate(gt, est, o);
  EXPECT_EQ(r.matched_poses, gt.size());
  EXPECT_NEAR(r.ate.trans_m.mean, 0.03, 1e-9);
  for (const auto& e : r.rpe) EXPECT_LT(e.trans_m.max, 1e-9);
  o.alignment.method = ev::Alignment::kSE3;
  EXPECT_LT(ev::evaluate(gt, est, o).ate.trans_m.max, 1e-9);
}
