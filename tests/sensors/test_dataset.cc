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
  dir.write("events.txt", "0.1 1 2 0\n");
  EXPECT_EQ(detect_dataset_format(dir.path()), DatasetFormat::kEcdFolder);
  EXPECT_EQ(detect_dataset_format(dir.file("events.txt")), DatasetFormat::kEcdEvents);
  for (DatasetFormat f : {DatasetFormat::kAuto, DatasetFormat::kEcdFolder, DatasetFormat::kEcdEvents}) {
    EXPECT_EQ(dataset_format_from_name(dataset_format_name(f)), f);
  }
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
