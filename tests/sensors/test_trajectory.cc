#include "evio/sensors/trajectory.h"

#include <cmath>

#include <gtest/gtest.h>

#include "evio/calib/error.h"
#include "evio_test/real_data.h"
#include "evio_test/temp_dir.h"

namespace evio {
namespace {

using evio_test::TempDir;

Trajectory circle(int n, int64_t t0, int64_t dt) {
  Trajectory t;
  for (int i = 0; i < n; ++i) {
    const double a = 0.1 * i;
    t.push_back({t0 + i * dt, calib::SE3(calib::so3_exp_quat(Eigen::Vector3d(0.1 * a, -0.2 * a, a)),
                                         Eigen::Vector3d(std::cos(a), std::sin(a), 0.01 * i))});
  }
  return t;
}

TEST(Trajectory, RejectsNonIncreasingStamps) {
  Trajectory t;
  t.push_back({10, calib::SE3()});
  EXPECT_THROW(t.push_back({10, calib::SE3()}), std::invalid_argument);
  EXPECT_THROW(Trajectory({{5, calib::SE3()}, {4, calib::SE3()}}), std::invalid_argument);
}

TEST(Trajectory, InterpolatesExactlyAtStampsAndLinearlyBetween) {
  const int64_t t0 = 1700000000000000000LL;  // large stamps: the fraction comes from an int64 difference
  const Trajectory t = circle(20, t0, 10000000);
  EXPECT_FALSE(t.interpolate(t0 - 1).has_value());
  EXPECT_FALSE(t.interpolate(t.t_end_ns() + 1).has_value());
  for (size_t i = 0; i < t.size(); ++i) {
    const auto p = t.interpolate(t[i].t_ns);
    ASSERT_TRUE(p.has_value());
    EXPECT_EQ(p->translation, t[i].T_w_b.translation);
  }
  const auto mid = t.interpolate(t[3].t_ns + 5000000);
  ASSERT_TRUE(mid.has_value());
  EXPECT_TRUE(mid->translation.isApprox(0.5 * (t[3].T_w_b.translation + t[4].T_w_b.translation), 1e-12));
  const double angle_to_3 = t[3].T_w_b.rotation.angularDistance(mid->rotation);
  const double angle_to_4 = t[4].T_w_b.rotation.angularDistance(mid->rotation);
  EXPECT_NEAR(angle_to_3, angle_to_4, 1e-9);
  EXPECT_NEAR(angle_to_3 + angle_to_4, t[3].T_w_b.rotation.angularDistance(t[4].T_w_b.rotation), 1e-9);
  // One nanosecond after a stamp at 1.7e18 ns still moves (no double-seconds precision loss).
  const auto just_after = t.interpolate(t[3].t_ns + 1);
  EXPECT_GT((just_after->translation - t[3].T_w_b.translation).norm(), 0.0);
}

TEST(Trajectory, TumRoundTripIsLossless) {
  TempDir dir;
  const Trajectory t = circle(50, 1700000000123456789LL, 4999161);
  write_tum(dir.file("t.tum"), t);
  const Trajectory back = read_tum(dir.file("t.tum"));
  ASSERT_EQ(back.size(), t.size());
  for (size_t i = 0; i < t.size(); ++i) {
    EXPECT_EQ(back[i].t_ns, t[i].t_ns);
    EXPECT_EQ(back[i].T_w_b.translation, t[i].T_w_b.translation);
    EXPECT_NEAR(back[i].T_w_b.rotation.angularDistance(t[i].T_w_b.rotation), 0.0, 1e-15);
  }
  EXPECT_NEAR(back.path_length_m(), t.path_length_m(), 1e-12);
}

void expect_tum_error(const std::string& body, const std::vector<std::string>& frags) {
  TempDir dir;
  const std::string p = dir.write("gt.txt", body);
  try {
    read_tum(p);
    FAIL() << body;
  } catch (const InputError& e) {
    for (const auto& f : frags) EXPECT_NE(std::string(e.what()).find(f), std::string::npos) << e.what();
  }
}

TEST(Trajectory, TumMalformedInput) {
  expect_tum_error("0.1 0 0 0 0 0 0 1\n0.2 0 0 0 0 0 1\n", {"gt.txt:2:", "expected 8 columns, found 7", "`t tx ty tz qx qy qz qw`"});
  expect_tum_error("0.1 0 0 0 0 0 0 2\n", {":1:", "quaternion norm 2"});
  expect_tum_error("0.1 0 nan 0 0 0 0 1\n", {":1:", "NaN or infinite"});
  expect_tum_error("0.2 0 0 0 0 0 0 1\n0.1 0 0 0 0 0 0 1\n", {":2:", "not after the previous pose"});
}

TEST(Trajectory, EurocCsvFindsColumnsByName) {
  TempDir dir;
  // EuRoC order: w x y z, with extra velocity columns.
  const std::string euroc =
      "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z [],v_x\n"
      "1403636579758555392,4.688,-1.786,0.783,0.534108,-0.153029,-0.827383,-0.082152,0.1\n"
      "1403636579763555584,4.689,-1.787,0.784,0.534108,-0.153029,-0.827383,-0.082152,0.1\n";
  ReadReport rep;
  const Trajectory a = read_euroc_csv(dir.write("euroc.csv", euroc), {}, &rep);
  ASSERT_EQ(a.size(), 2u);
  EXPECT_EQ(a[0].t_ns, 1403636579758555392LL);
  EXPECT_EQ(rep.time_unit, TimeUnit::kNanoseconds);
  EXPECT_NEAR(a[0].T_w_b.rotation.w(), 0.534108, 1e-6);
  EXPECT_NEAR(a[0].T_w_b.rotation.x(), -0.153029, 1e-6);
  EXPECT_DOUBLE_EQ(a[1].T_w_b.translation.z(), 0.784);
  // x y z w order.
  const Trajectory b = read_euroc_csv(dir.write("b.csv", "# timestamp, x, y, z, qx, qy, qz, qw\n0,1,2,3,0,0,0.6,0.8\n"));
  ASSERT_EQ(b.size(), 1u);
  EXPECT_NEAR(b[0].T_w_b.rotation.z(), 0.6, 1e-12);
  EXPECT_NEAR(b[0].T_w_b.rotation.w(), 0.8, 1e-12);
  EXPECT_THROW(read_euroc_csv(dir.write("c.csv", "0,1,2,3,0,0,0,1\n")), InputError);
  EXPECT_THROW(read_euroc_csv(dir.write("d.csv", "# t, a, b\n0,1,2\n")), InputError);
  try {
    read_euroc_csv(dir.write("e.csv", "# timestamp, x, y, z, qx, qy, qz, qw\n0,1,2,3,0,0,0\n"));
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("e.csv:2:"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("expected 8 columns, found 7"), std::string::npos) << e.what();
  }
}

TEST(TrajectoryRealData, PosterSixDofMocap) {
  const auto dir = evio_test::real_data_dir("trajectories");
  if (!dir) GTEST_SKIP() << "real data not found (../shared/data/real/trajectories)";
  ReadReport rep;
  const Trajectory t = read_euroc_csv(*dir + "/poster_6dof_mocap.csv", {}, &rep);
  EXPECT_EQ(t.size(), 11610u);
  EXPECT_EQ(rep.skipped_total(), 0);
  EXPECT_EQ(t[0].t_ns, 0);
  EXPECT_EQ(t[1].t_ns, 4999161);
  EXPECT_NEAR(ns_to_seconds(t.duration_ns()), 59.8, 0.1);
  EXPECT_NEAR(t[0].T_w_b.translation.x(), 4.43507903856572, 1e-14);
  EXPECT_NEAR(t[0].T_w_b.rotation.w(), -0.48685248398779, 1e-6);
}

TEST(TrajectoryRealData, SliderDepthGroundTruth) {
  const auto dir = evio_test::real_data_dir("ecd_slider_depth_head");
  if (!dir) GTEST_SKIP() << "real data not found (../shared/data/real/ecd_slider_depth_head)";
  const Trajectory t = read_tum(*dir + "/groundtruth.txt");
  EXPECT_EQ(t.size(), 339u);
  EXPECT_EQ(t[0].t_ns, 22291582);
  EXPECT_DOUBLE_EQ(t[0].T_w_b.translation.x(), 0.1116875);
}

}  // namespace
}  // namespace evio
