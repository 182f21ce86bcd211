#include "convert_command.h"

#include <sstream>

#include <gtest/gtest.h>

#include "evio/calib/error.h"
#include "evio/sensors/dataset.h"
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

TEST(ConvertCommand, EcdToH5ToEcdIsLossless) {
  evio_test::TempDir dir;
  // Sub-microsecond stamps and epoch times: only the ns unit keeps them.
  std::string ev;
  for (int i = 0; i < 5000; ++i) {
    ev += "1700000000." + std::to_string(100000000 + 1237 * i) + " " + std::to_string(i % 640) + " " +
          std::to_string(i % 480) + " " + std::to_string(i % 3 == 0) + "\n";
  }
  dir.write("in/events.txt", ev);
  ConvertArgs a;
  a.in = dir.file("in");
  a.out = dir.file("mid.h5");
  a.progress = false;
  std::ostringstream out;
  ASSERT_EQ(run_convert(a, out), 0);
  EXPECT_NE(out.str().find("HDF5"), std::string::npos) << out.str();
  a.in = a.out;
  a.out = dir.file("back");
  ASSERT_EQ(run_convert(a, out), 0);
  const EventBuffer original = read_ecd_events(dir.file("in/events.txt"));
  const EventBuffer back = read_ecd_events(dir.file("back/events.txt"));
  ASSERT_EQ(back.size(), original.size());
  for (size_t i = 0; i < back.size(); ++i) ASSERT_EQ(back[i], original[i]) << i;

  // Microseconds (DSEC) round every stamp that is not a whole us, and says how many.
  a.in = dir.file("in");
  a.out = dir.file("us.h5");
  a.h5_time_unit = TimeUnit::kMicroseconds;
  std::ostringstream out_us;
  ASSERT_EQ(run_convert(a, out_us), 0);
  int64_t not_whole_us = 0;
  for (const Event& e : original) not_whole_us += e.t_ns % 1000 != 0;
  ASSERT_GT(not_whole_us, 0);
  EXPECT_NE(out_us.str().find(std::to_string(not_whole_us) + " timestamps rounded"), std::string::npos) << out_us.str();
}

TEST(ConvertCommand, H5OutputSlicesWithTheIndex) {
  evio_test::TempDir dir;
  ConvertArgs a;
  a.in = make_ecd_folder(dir);
  a.out = dir.file("all.h5");
  a.progress = false;
  std::ostringstream out;
  ASSERT_EQ(run_convert(a, out), 0);
  // Slice the h5 (seek through ms_to_idx) back to ECD and compare with slicing the text.
  a.in = a.out;
  a.out = dir.file("slice");
  a.t_start_ns = 123456789;
  a.t_end_ns = 187654321;
  ASSERT_EQ(run_convert(a, out), 0);
  const EventBuffer all = read_ecd_events(dir.file("in/events.txt"));
  const EventSpan expected = all.slice(*a.t_start_ns, *a.t_end_ns);
  const EventBuffer got = read_ecd_events(a.out + "/events.txt");
  ASSERT_EQ(got.size(), expected.size());
  for (size_t i = 0; i < got.size(); ++i) ASSERT_EQ(got[i], expected[i]);
}

// Every real sample converted to h5 and to an ECD folder keeps its event count and time span.
TEST(ConvertCommandRealData, EverySampleToH5AndEcd) {
  const std::vector<std::pair<std::string, int64_t>> samples = {
      {"davis346_aedat4/davis.aedat4", 117667},
      {"prophesee_raw/evt2_sample.raw", 539481},
      {"prophesee_raw/evt3_sample.raw", 219596},
      {"rosbag_eventpacket/test_events_1.bag", 343474},
      {"rosbag2_sqlite/test_events_1", 343474},
      {"dvs128_aedat2/DVS128-2017-03-21-short.aedat", 130114},
      {"ecd_slider_depth_head", 50000}};
  int tried = 0;
  for (const auto& [rel, count] : samples) {
    const auto path = evio_test::real_data_dir(rel);
    if (!path) continue;
    ++tried;
    SCOPED_TRACE(rel);
    EventBuffer in_events;
    {
      auto r = open_dataset(*path);
      while (r->read_events(&in_events, size_t{1} << 20) > 0) {
      }
    }
    ASSERT_EQ(static_cast<int64_t>(in_events.size()), count);
    evio_test::TempDir tmp;
    for (const std::string out_name : {"out.h5", "out_ecd"}) {
      ConvertArgs a;
      a.in = *path;
      a.out = tmp.file(out_name);
      a.progress = false;
      std::ostringstream out;
      ASSERT_EQ(run_convert(a, out), 0);
      auto r = open_dataset(a.out);
      EventBuffer got;
      while (r->read_events(&got, size_t{1} << 20) > 0) {
      }
      ASSERT_EQ(got.size(), in_events.size()) << out_name;
      EXPECT_EQ(got.front().t_ns, in_events.front().t_ns) << out_name;
      EXPECT_EQ(got.back().t_ns, in_events.back().t_ns) << out_name;
      size_t differ = 0;
      for (size_t i = 0; i < got.size(); ++i) differ += !(got[i] == in_events[i]);
      EXPECT_EQ(differ, 0u) << out_name;
    }
  }
  if (tried == 0) GTEST_SKIP() << "real data not found (../shared/data/real)";
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
