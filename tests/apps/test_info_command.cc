#include "info_command.h"

#include <sstream>

#include <gtest/gtest.h>

#include "evio/calib/error.h"
#include "evio_test/real_data.h"
#include "evio_test/temp_dir.h"

namespace evio::apps {
namespace {

TEST(InfoCommand, PrintsCountsRatesAndSpans) {
  evio_test::TempDir dir;
  std::string events;
  for (int i = 0; i < 1000; ++i) events += "0." + std::to_string(100000 + i) + " " + std::to_string(i % 240) + " 5 " + std::to_string(i % 4 == 0) + "\n";
  dir.write("events.txt", events);
  std::string imu;
  for (int i = 0; i < 100; ++i) imu += "0." + std::to_string(100 + i) + " 0 0 9.81 0 0 0.5\n";
  dir.write("imu.txt", imu);
  InfoArgs args;
  args.path = dir.path();
  std::ostringstream text;
  ASSERT_EQ(run_info(args, text), 0);
  const std::string t = text.str();
  EXPECT_NE(t.find("events         1000\n"), std::string::npos) << t;
  EXPECT_NE(t.find("250 ON / 750 OFF (25.0% ON), file convention 0/1"), std::string::npos) << t;
  EXPECT_NE(t.find("imu            100 samples, 0.100000000 .. 0.199000000 s, 1000.0 Hz"), std::string::npos) << t;
  EXPECT_NE(t.find("frames         none"), std::string::npos) << t;
  args.json = true;
  std::ostringstream json;
  ASSERT_EQ(run_info(args, json), 0);
  EXPECT_NE(json.str().find("\"count\": 1000, \"on\": 250, \"off\": 750"), std::string::npos) << json.str();
  EXPECT_NE(json.str().find("\"imu\": {\"count\": 100, \"rate_hz\": 1000"), std::string::npos) << json.str();
}

TEST(InfoCommand, BadInputThrowsInputError) {
  InfoArgs args;
  args.path = "/nonexistent/evio";
  std::ostringstream out;
  EXPECT_THROW(run_info(args, out), InputError);
}

TEST(InfoCommandRealData, SliderDepthHead) {
  const auto dir = evio_test::real_data_dir("ecd_slider_depth_head");
  if (!dir) GTEST_SKIP() << "real data not found (../shared/data/real/ecd_slider_depth_head)";
  InfoArgs args;
  args.path = *dir;
  args.dataset.text.sensor = SensorSize{240, 180};
  std::ostringstream out;
  ASSERT_EQ(run_info(args, out), 0);
  const std::string t = out.str();
  EXPECT_NE(t.find("events         50000\n"), std::string::npos) << t;
  EXPECT_NE(t.find("frames         87 (240 x 180)"), std::string::npos) << t;
  EXPECT_NE(t.find("ground truth   339 poses"), std::string::npos) << t;
}

// Containers fill Frame::image themselves; the summary must not try to decode a path.
TEST(InfoCommandRealData, Aedat4WithFramesImuAndTriggers) {
  const auto dir = evio_test::real_data_dir("davis346_aedat4");
  if (!dir) GTEST_SKIP() << "real data not found (../shared/data/real/davis346_aedat4)";
  InfoArgs args;
  args.path = *dir + "/davis.aedat4";
  std::ostringstream out;
  ASSERT_EQ(run_info(args, out), 0);
  const std::string t = out.str();
  EXPECT_NE(t.find("events         117667\n"), std::string::npos) << t;
  EXPECT_NE(t.find("frames         3 (346 x 260)"), std::string::npos) << t;
  EXPECT_NE(t.find("imu            130 samples"), std::string::npos) << t;
  EXPECT_NE(t.find("triggers       15"), std::string::npos) << t;
}

TEST(InfoCommandRealData, RosbagListsTopics) {
  const auto dir = evio_test::real_data_dir("rosbag_eventpacket");
  if (!dir) GTEST_SKIP() << "real data not found (../shared/data/real/rosbag_eventpacket)";
  InfoArgs args;
  args.path = *dir + "/test_events_1.bag";
  std::ostringstream out;
  ASSERT_EQ(run_info(args, out), 0);
  EXPECT_NE(out.str().find("stream         /event_camera/events [event_camera_msgs/EventPacket] 517 messages (read)"),
            std::string::npos)
      << out.str();
  EXPECT_NE(out.str().find("events         343474\n"), std::string::npos) << out.str();
}

// The ROS 2 copy of the same recording (rosbag2, SQLite3): the counts of shared/data/README.md,
// the topic with its ROS 2 type, and the clock stated.
TEST(InfoCommandRealData, Rosbag2ListsTopicsAndCounts) {
  const auto dir = evio_test::real_data_dir("rosbag2_sqlite/test_events_1");
  if (!dir) GTEST_SKIP() << "real data not found (../shared/data/real/rosbag2_sqlite/test_events_1)";
  InfoArgs args;
  args.path = *dir;
  std::ostringstream out;
  ASSERT_EQ(run_info(args, out), 0);
  const std::string t = out.str();
  EXPECT_NE(t.find("format         rosbag2"), std::string::npos) << t;
  EXPECT_NE(t.find("stream         /event_camera/events [event_camera_msgs/msg/EventPacket] 517 messages (read)"),
            std::string::npos)
      << t;
  EXPECT_NE(t.find("events         343474\n"), std::string::npos) << t;
  EXPECT_NE(t.find("125183 ON / 218291 OFF"), std::string::npos) << t;
  EXPECT_NE(t.find("triggers       4157 (2079 rising, 2078 falling edges)"), std::string::npos) << t;
  EXPECT_NE(t.find("header.stamp of the first packet"), std::string::npos) << t;
}

}  // namespace
}  // namespace evio::apps
