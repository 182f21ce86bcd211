#include "convert_command.h"

#include <sstream>

#include <gtest/gtest.h>

#include "evio/calib/error.h"
#include "evio/sensors/ecd.h"
#include "evio_test/real_data.h"
#include "evio_test/temp_dir.h"

namespace evio::apps {
namespace {

std::string make_ecd_folder(const evio_test::TempDir& dir) {
  std::string ev, imu, gt;
  for (int i = 0; i < 3000; ++i) ev += "0." + std::to_string(100000 + 37 * i) + " " + std::to_string(i % 200) + " " + std::to_string(i % 150) + " " + std::to_string(i % 2) + "\n";
  for (int i = 0; i < 200; ++i) imu += "0." + std::to_string(100000 + 1000 * i) + " 0 0 9.81 0 0 0.1\n";
  for (int i = 0; i < 30; ++i) gt += "0." + std::to_string(100000 + 5000 * i) + " " + std::to_string(i) + " 0 0 0 0 0 1\n";
  dir.write("in/events.txt", ev);
  dir.write("in/imu.txt", imu);
  dir.write("in/groundtruth.txt", gt);
  return dir.file("in");
}

TEST(ConvertCommand, EcdToEcdSlicesEveryStreamToTheWindow) {
  evio_test::TempDir dir;
  ConvertArgs a;
  a.in = make_ecd_folder(dir);
  a.out = dir.file("out");
  a.t_start_ns = 150000000;  // 0.15 s
  a.t_end_ns = 200000000;    // 0.20 s
  a.progress = false;
  std::ostringstream out;
  ASSERT_EQ(run_convert(a, out), 0);
  const EventBuffer all = read_ecd_events(a.in + "/events.txt");
  const EventSpan expected = all.slice(*a.t_start_ns, *a.t_end_ns);
  const EventBuffer got = read_ecd_events(a.out + "/events.txt");
  ASSERT_EQ(got.size(), expected.size());
  ASSERT_GT(got.size(), 1000u);
  for (size_t i = 0; i < got.size(); ++i) ASSERT_EQ(got[i], expected[i]);
  const auto imu = read_ecd_imu(a.out + "/imu.txt");
  EXPECT_EQ(imu.size(), 50u);  // 0.150 .. 0.199 s at 1 kHz
  EXPECT_EQ(imu.front().t_ns, 150000000);
  const Trajectory gt = read_tum(a.out + "/groundtruth.txt");
  EXPECT_EQ(gt.size(), 10u);
  EXPECT_NE(out.str().find("events"), std::string::npos);
}

TEST(ConvertCommand, WholeRecordingKeepsEverythingAndThePolarityConvention) {
  evio_test::TempDir dir;
  dir.write("in/events.txt", "0.1 1 2 -1\n0.2 3 4 1\n");
  ConvertArgs a;
  a.in = dir.file("in");
  a.out = dir.file("out");
  a.progress = false;
  std::ostringstream out;
  ASSERT_EQ(run_convert(a, out), 0);
  ReadReport rep;
  const EventBuffer got = read_ecd_events(a.out + "/events.txt", {}, &rep);
  ASSERT_EQ(got.size(), 2u);
  EXPECT_EQ(rep.polarity, PolarityConvention::kMinusPlusOne);
  a.out = dir.file("out01");
  a.polarity = PolarityConvention::kZeroOne;
  ASSERT_EQ(run_convert(a, out), 0);
  read_ecd_events(a.out + "/events.txt", {}, &rep);
  EXPECT_EQ(rep.polarity, PolarityConvention::kZeroOne);
}

TEST(ConvertCommand, RejectsAnEmptyWindow) {
  evio_test::TempDir dir;
  ConvertArgs a;
  a.in = make_ecd_folder(dir);
  a.out = dir.file("out");
  a.t_start_ns = 2;
  a.t_end_ns = 1;
  std::ostringstream out;
  EXPECT_THROW(run_convert(a, out), InputError);
}

TEST(ConvertCommandRealData, Aedat2ToEcdPreservesCountAndSpan) {
  const auto dir = evio_test::real_data_dir("dvs128_aedat2");
  if (!dir) GTEST_SKIP() << "real data not found (../shared/data/real/dvs128_aedat2)";
  evio_test::TempDir tmp;
  ConvertArgs a;
  a.in = *dir + "/DVS128-2017-03-21-short.aedat";
  a.out = tmp.file("out");
  a.progress = false;
  std::ostringstream out;
  ASSERT_EQ(run_convert(a, out), 0);
  const EventBuffer got = read_ecd_events(a.out + "/events.txt");
  EXPECT_EQ(got.size(), 130114u);
  EXPECT_EQ(got.front().t_ns, int64_t{113476330} * 1000);
  EXPECT_EQ(got.back().t_ns, int64_t{119657829} * 1000);
}

}  // namespace
}  // namespace evio::apps
