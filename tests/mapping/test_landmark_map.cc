// Landmark map export round trip through PCL (PLY and PCD, binary and ASCII) and errors.
#include <gtest/gtest.h>

#include "evio/calib/error.h"
#include "evio/mapping/landmark_map.h"
#include "evio_test/temp_dir.h"

namespace evio::mapping {
namespace {

TEST(LandmarkMap, RoundTripEveryFormat) {
  evio_test::TempDir dir;
  std::vector<MapPoint> pts;
  for (int i = 0; i < 100; ++i) pts.push_back({Eigen::Vector3d(0.01 * i, -2.0 + 0.5 * i, 5.6), static_cast<float>(i % 7)});
  for (const auto& [name, fmt] : std::vector<std::pair<std::string, MapFormat>>{
           {"a.ply", MapFormat::kPlyBinary}, {"b.ply", MapFormat::kPlyAscii}, {"c.pcd", MapFormat::kPcdBinary}, {"d.pcd", MapFormat::kPcdAscii}}) {
    const std::string p = dir.file(name);
    write_landmark_map(p, pts, fmt);
    const auto back = read_landmark_map(p);
    ASSERT_EQ(back.size(), pts.size()) << name;
    for (size_t i = 0; i < pts.size(); ++i) {
      EXPECT_LT((back[i].p_w - pts[i].p_w).norm(), 1e-5) << name;  // stored as float
      EXPECT_EQ(back[i].intensity, pts[i].intensity) << name;
    }
  }
  EXPECT_EQ(map_format_for("x/map.ply"), MapFormat::kPlyBinary);
  EXPECT_THROW(map_format_for("map.obj"), std::invalid_argument);
}

TEST(LandmarkMap, EmptyMapsAreValidFiles) {
  evio_test::TempDir dir;
  for (const char* name : {"e.ply", "e.pcd"}) {
    write_landmark_map(dir.file(name), {});
    EXPECT_TRUE(read_landmark_map(dir.file(name)).empty()) << name;
  }
  write_landmark_map(dir.file("ea.ply"), {}, MapFormat::kPlyAscii);
  EXPECT_TRUE(read_landmark_map(dir.file("ea.ply")).empty());
}

TEST(LandmarkMap, ErrorsNameTheFile) {
  std::vector<MapPoint> pts = {{Eigen::Vector3d(1, 2, 3), 0}};
  EXPECT_THROW(write_landmark_map("/nonexistent_dir/x.ply", pts), InputError);
  pts.push_back({Eigen::Vector3d(NAN, 0, 0), 0});
  EXPECT_THROW(write_landmark_map("/tmp/x.ply", pts), std::invalid_argument);
  EXPECT_THROW(read_landmark_map("/nonexistent_dir/x.ply"), InputError);
}

}  // namespace
}  // namespace evio::mapping
