#include "evio/sensors/dataset.h"

#include <fstream>
#include <sstream>

#include <gtest/gtest.h>

#include "evio/calib/error.h"
#include "evio_test/real_data.h"
#include "evio_test/temp_dir.h"

namespace evio {
namespace {

TEST(Dataset, DetectsFormats) {
  evio_test::TempDir dir;
  EXPECT_THROW(detect_dataset_format(dir.path()), InputError);  // folder without events(_undistorted).txt
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
  EXPECT_EQ(all_dataset_formats().size(), 9u);
  // ROS 2 bags: SQLite3 and MCAP magic, the extensions, metadata.yaml and a bag folder.
  EXPECT_EQ(detect_dataset_format(dir.write("i.bin", std::string("SQLite format 3\0", 16))), DatasetFormat::kRosbag2);
  EXPECT_EQ(detect_dataset_format(dir.write("j.bin", std::string("\x89MCAP0\r\n", 8))), DatasetFormat::kRosbag2);
  EXPECT_EQ(detect_dataset_format(dir.write("k.mcap", "")), DatasetFormat::kRosbag2);
  evio_test::TempDir bag;
  bag.write("metadata.yaml", "rosbag2_bagfile_information: {}\n");
  EXPECT_EQ(detect_dataset_format(bag.path()), DatasetFormat::kRosbag2);
  EXPECT_EQ(detect_dataset_format(bag.file("metadata.yaml")), DatasetFormat::kRosbag2);
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

// Integer events only: exercises DatasetReader's default read_subpixel_events.
class FakeIntegerReader : public DatasetReader {
 public:
  explicit FakeIntegerReader(std::vector<Event> events) : events_(std::move(events)) {}
  DatasetFormat format() const override { return DatasetFormat::kAedat2; }
  const std::string& path() const override { return path_; }
  SensorSize sensor_size() const override { return {}; }
  size_t read_events(EventBuffer* out, size_t max_events) override {
    size_t n = 0;
    for (; n < max_events && next_ < events_.size(); ++n) out->push_back(events_[next_++]);
    return n;
  }
  double progress() const override { return 0.0; }
  const ReadReport& event_report() const override { return report_; }
  std::vector<ImuSample> read_imu() override { return {}; }
  std::vector<Frame> read_frames() override { return {}; }
  std::optional<Trajectory> read_groundtruth() override { return std::nullopt; }
  std::optional<calib::CameraCalibration> read_calibration() override { return std::nullopt; }

 private:
  std::vector<Event> events_;
  size_t next_ = 0;
  std::string path_ = "fake";
  ReadReport report_;
};

TEST(DatasetSubpixel, DefaultConvertsIntegerEvents) {
  FakeIntegerReader reader({Event{10, 1, 2, -1}, Event{20, 3, 4, 1}, Event{30, 65535, 0, 1}});
  std::vector<SubpixelEvent> out;
  EXPECT_EQ(reader.read_subpixel_events(&out, 2), 2u);
  EXPECT_EQ(reader.read_subpixel_events(&out, 2), 1u);
  EXPECT_EQ(reader.read_subpixel_events(&out, 2), 0u);
  ASSERT_EQ(out.size(), 3u);
  EXPECT_EQ(out[0].t_ns, 10);
  EXPECT_EQ(out[0].x, 1.0f);
  EXPECT_EQ(out[0].y, 2.0f);
  EXPECT_EQ(out[0].polarity, -1);
  EXPECT_EQ(out[2].x, 65535.0f);
}

// read_imu_samples streams the IMU: an ECD folder reads imu.txt in chunks, other readers hand out
// read_imu()'s samples (the default); both give read_imu()'s samples, then 0.
class FakeImuReader final : public FakeIntegerReader {
 public:
  FakeImuReader() : FakeIntegerReader({}) {}
  std::vector<ImuSample> read_imu() override {
    std::vector<ImuSample> imu(10);
    for (int i = 0; i < 10; ++i) imu[i].t_ns = 1000 * (i + 1);
    return imu;
  }
};

TEST(DatasetImuStream, EcdFolderAndDefaultStreamTheSamplesOfReadImu) {
  evio_test::TempDir dir;
  dir.write("events.txt", "0.001 1 2 0\n");
  std::string text;
  for (int i = 1; i <= 25; ++i) text += "0.0" + std::to_string(10 + i) + " 0 0 9.8 0 0 " + std::to_string(i) + "\n";
  dir.write("imu.txt", text);
  auto ecd = open_dataset(dir.path());
  FakeImuReader fake;
  for (DatasetReader* r : {ecd.get(), static_cast<DatasetReader*>(&fake)}) {
    const std::vector<ImuSample> whole = r->read_imu();
    std::vector<ImuSample> streamed;
    size_t n = 0, calls = 0;
    while ((n = r->read_imu_samples(&streamed, 4)) > 0) {
      EXPECT_LE(n, 4u);
      ++calls;
    }
    EXPECT_EQ(r->read_imu_samples(&streamed, 4), 0u);
    ASSERT_EQ(streamed.size(), whole.size());
    EXPECT_EQ(calls, (whole.size() + 3) / 4);
    for (size_t i = 0; i < whole.size(); ++i) EXPECT_EQ(streamed[i].t_ns, whole[i].t_ns) << i;
  }
  EXPECT_EQ(ecd->read_imu().size(), 25u);  // read_imu is independent of the stream
}

TEST(DatasetSubpixel, EcdFileAndFolderReadSubpixelEvents) {
  evio_test::TempDir dir;
  const std::string text = "# t[us] x y p\n0.5 1.25 -2.5 0\n1.5 250.75 3 1\n";
  const std::string file = dir.write("events_undistorted.txt", text);
  EXPECT_EQ(detect_dataset_format(file), DatasetFormat::kEcdEvents);
  EXPECT_EQ(detect_dataset_format(dir.path()), DatasetFormat::kEcdFolder);
  for (const std::string& path : {file, dir.path()}) {
    DatasetOptions o;
    o.text.sensor = SensorSize{240, 180};
    auto reader = open_dataset(path, o);
    std::vector<SubpixelEvent> ev;
    while (reader->read_subpixel_events(&ev, 1) > 0) {
    }
    ASSERT_EQ(ev.size(), 2u) << path;
    EXPECT_EQ(ev[0].t_ns, 500);
    EXPECT_FLOAT_EQ(ev[0].y, -2.5f);
    EXPECT_FLOAT_EQ(ev[1].x, 250.75f);
    EXPECT_EQ(reader->event_report().time_unit, TimeUnit::kMicroseconds);
    // The integer path rejects the file and points to the sub-pixel one.
    auto integer = open_dataset(path, o);
    EventBuffer buf;
    try {
      integer->read_events(&buf, 10);
      FAIL() << path;
    } catch (const InputError& e) {
      const std::string msg = e.what();
      EXPECT_NE(msg.find(file + ":2:"), std::string::npos) << msg;
      EXPECT_NE(msg.find("sub-pixel coordinates"), std::string::npos) << msg;
      EXPECT_NE(msg.find("read_subpixel_events"), std::string::npos) << msg;
    }
  }
}

// The events of events_undistorted.txt as an independent plain-iostream parser sees them.
struct PlainEvent {
  double t_us = 0, x = 0, y = 0;
  int p = 0;
};
std::vector<PlainEvent> parse_plain(const std::string& path) {
  std::ifstream in(path);
  std::vector<PlainEvent> out;
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream s(line);
    PlainEvent e;
    if (s >> e.t_us >> e.x >> e.y >> e.p) out.push_back(e);
  }
  return out;
}

TEST(DatasetRealData, EcdDynamicUndistortedSubpixelEvents) {
  const auto dir = evio_test::real_data_dir("ecd_dynamic_10ms");
  if (!dir) GTEST_SKIP() << "real data not found (../shared/data/real/ecd_dynamic_10ms)";
  const std::string file = *dir + "/events_undistorted.txt";
  const std::vector<PlainEvent> plain = parse_plain(file);
  ASSERT_EQ(plain.size(), 18978u);
  int64_t plain_outside = 0;
  for (const PlainEvent& e : plain) plain_outside += (e.x < 0 || e.x >= 240 || e.y < 0 || e.y >= 180) ? 1 : 0;
  ASSERT_GT(plain_outside, 0);  // the file is known to hold some

  for (const std::string& path : {file, *dir}) {
    auto reader = open_dataset(path);
    EXPECT_EQ(reader->format(), path == file ? DatasetFormat::kEcdEvents : DatasetFormat::kEcdFolder);
    std::vector<SubpixelEvent> ev;
    while (reader->read_subpixel_events(&ev, 4096) > 0) {
    }
    const ReadReport& rep = reader->event_report();
    ASSERT_EQ(ev.size(), 18978u) << path;
    EXPECT_EQ(rep.records, 18978);
    EXPECT_EQ(rep.skipped_total(), 0);
    EXPECT_EQ(rep.time_unit, TimeUnit::kMicroseconds);
    EXPECT_NE(rep.time_unit_reason.find("header comment in line 1"), std::string::npos) << rep.time_unit_reason;
    EXPECT_EQ(rep.polarity, PolarityConvention::kZeroOne);
    EXPECT_EQ(ev.front().t_ns, 0);
    EXPECT_FLOAT_EQ(ev.front().x, 137.005638f);
    EXPECT_FLOAT_EQ(ev.front().y, 120.010244f);
    EXPECT_EQ(ev.front().polarity, -1);
    EXPECT_EQ(ev.back().t_ns, 9996999);  // last line: `9996.999 130.968122 177.690311 1`
    EXPECT_FLOAT_EQ(ev.back().x, 130.968122f);
    EXPECT_FLOAT_EQ(ev.back().y, 177.690311f);
    const PlainEvent& last = plain.back();
    EXPECT_EQ(ev.back().t_ns, std::llround(last.t_us * 1000.0));
    EXPECT_FLOAT_EQ(ev.back().x, static_cast<float>(last.x));
    EXPECT_FLOAT_EQ(ev.back().y, static_cast<float>(last.y));
    EXPECT_EQ(ev.back().polarity, last.p == 1 ? 1 : -1);
    int64_t outside = 0;
    for (const SubpixelEvent& e : ev) outside += (e.x < 0 || e.x >= 240 || e.y < 0 || e.y >= 180) ? 1 : 0;
    EXPECT_EQ(outside, plain_outside);
    for (size_t i = 1; i < ev.size(); ++i) ASSERT_LE(ev[i - 1].t_ns, ev[i].t_ns) << i;
  }
  // The integer path rejects the file at its first record and names the sub-pixel path.
  try {
    auto integer = open_dataset(file);
    EventBuffer buf;
    integer->read_events(&buf, 100);
    FAIL() << "integer read accepted sub-pixel coordinates";
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(file + ":2:"), std::string::npos) << msg;
    EXPECT_NE(msg.find("sub-pixel coordinates"), std::string::npos) << msg;
  }
  // The folder's calib.txt is its camera.
  auto folder = open_dataset(*dir);
  const auto calib = folder->read_calibration();
  ASSERT_TRUE(calib.has_value());
  EXPECT_NEAR(calib->camera.intrinsics().fx, 199.092366542, 1e-9);
  EXPECT_NEAR(calib->camera.intrinsics().cy, 110.712660011, 1e-9);
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
