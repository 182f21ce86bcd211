#include "evio/sensors/dataset.h"

#include <gtest/gtest.h>

#include "evio/calib/error.h"
#include "evio_test/real_data.h"
#include "evio_test/temp_dir.h"

namespace evio {
namespace {

TEST(Dataset, DetectsFormats) {
  evio_test::TempDir dir;
  EXPECT_THROW(detect_dataset_format(dir.path()), InputError);  // folder without events.txt
  EXPECT_THROW(detect_dataset_format(dir.file("nope")), InputError);
  dir.write("x.bin", "abc");
  try {
    detect_dataset_format(dir.file("x.bin"));
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("unknown file format"), std::string::npos);
  }
  // Magic bytes decide over the extension; HDF5 may sit behind a 512-byte user block.
  EXPECT_EQ(detect_dataset_format(dir.write("a.bin", "#!AER-DAT4.0\r\n")), DatasetFormat::kAedat4);
  EXPECT_EQ(detect_dataset_format(dir.write("b.txt", "#!AER-DAT2.0\r\n")), DatasetFormat::kAedat2);
  EXPECT_EQ(detect_dataset_format(dir.write("c.dat", "#ROSBAG V2.0\n")), DatasetFormat::kRosbag);
  EXPECT_EQ(detect_dataset_format(dir.write("d", std::string("\x89HDF\r\n\x1a\n", 8) + "rest")), DatasetFormat::kHdf5);
  EXPECT_EQ(detect_dataset_format(dir.write("e", std::string(512, '\0') + std::string("\x89HDF\r\n\x1a\n", 8))),
            DatasetFormat::kHdf5);
  EXPECT_EQ(detect_dataset_format(dir.write("f.raw", "% evt 3.0\n% end\n")), DatasetFormat::kEvt3);
  EXPECT_EQ(detect_dataset_format(dir.write("g.raw", "% format EVT2;height=480;width=640\n% end\n")), DatasetFormat::kEvt2);
  try {
    detect_dataset_format(dir.write("h.raw", "% date 2020\n% end\n"));
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("names no EVT version"), std::string::npos) << e.what();
  }
  dir.write("events.txt", "0.1 1 2 0\n");
  EXPECT_EQ(detect_dataset_format(dir.path()), DatasetFormat::kEcdFolder);
  EXPECT_EQ(detect_dataset_format(dir.file("events.txt")), DatasetFormat::kEcdEvents);
  EXPECT_EQ(dataset_format_from_name("auto"), DatasetFormat::kAuto);
  for (DatasetFormat f : all_dataset_formats()) EXPECT_EQ(dataset_format_from_name(dataset_format_name(f)), f);
  EXPECT_EQ(all_dataset_formats().size(), 8u);
}

TEST(Dataset, SummaryOfAFolderWithoutSideFiles) {
  evio_test::TempDir dir;
  dir.write("events.txt", "0.1 1 2 0\n0.3 5 9 1\n");
  auto reader = open_dataset(dir.path());
  const DatasetSummary s = summarize_dataset(reader.get());
  EXPECT_EQ(s.format, DatasetFormat::kEcdFolder);
  EXPECT_EQ(s.events.count, 2);
  EXPECT_EQ(s.events.max_x, 5);
  EXPECT_EQ(s.imu_samples, 0);
  EXPECT_EQ(s.frames, 0);
  EXPECT_EQ(s.poses, 0);
  EXPECT_FALSE(s.calibration.has_value());
}

TEST(Dataset, RejectsInvalidOptions) {
  evio_test::TempDir dir;
  dir.write("events.txt", "");
  DatasetOptions o;
  o.text.sensor = SensorSize{240, 0};
  EXPECT_THROW(open_dataset(dir.path(), o), InputError);
}

TEST(DatasetRealData, SliderDepthHeadSummary) {
  const auto dir = evio_test::real_data_dir("ecd_slider_depth_head");
  if (!dir) GTEST_SKIP() << "real data not found (../shared/data/real/ecd_slider_depth_head)";
  DatasetOptions o;
  o.text.sensor = SensorSize{240, 180};
  auto reader = open_dataset(*dir, o);
  int calls = 0;
  const DatasetSummary s = summarize_dataset(reader.get(), [&](double) { ++calls; });
  EXPECT_EQ(s.events.count, 50000);
  EXPECT_EQ(s.events.on + s.events.off, 50000);
  EXPECT_EQ(s.poses, 339);
  EXPECT_EQ(s.frames, 87);
  EXPECT_EQ(s.frame_width, 240);
  EXPECT_EQ(s.frame_height, 180);
  EXPECT_EQ(s.imu_samples, 0);
  ASSERT_TRUE(s.calibration.has_value());
  EXPECT_NEAR(s.calibration->camera.intrinsics().fx, 335.419462958, 1e-9);
  EXPECT_GT(calls, 0);
}

}  // namespace
}  // namespace evio
