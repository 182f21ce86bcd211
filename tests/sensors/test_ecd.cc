#include "evio/sensors/ecd.h"

#include <random>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio_test/real_data.h"
#include "evio_test/temp_dir.h"

namespace evio {
namespace {

using evio_test::TempDir;

// Expects read_ecd_events to throw an InputError whose message contains every fragment.
void expect_event_error(const std::string& text, const std::vector<std::string>& fragments,
                        TextReadOptions opts = {}) {
  TempDir dir;
  const std::string path = dir.write("events.txt", text);
  try {
    read_ecd_events(path, opts);
    FAIL() << "no error for:\n" << text;
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(path), std::string::npos) << msg;
    for (const std::string& f : fragments) EXPECT_NE(msg.find(f), std::string::npos) << "'" << f << "' not in: " << msg;
  }
}

TEST(EcdEvents, ParsesBothPolarityConventions) {
  TempDir dir;
  ReadReport rep;
  auto ev = read_ecd_events(dir.write("a.txt", "0.1 1 2 0\n0.2 3 4 1\n"), {}, &rep);
  ASSERT_EQ(ev.size(), 2u);
  EXPECT_EQ(ev[0], (Event{100000000, 1, 2, -1}));
  EXPECT_EQ(ev[1], (Event{200000000, 3, 4, 1}));
  EXPECT_EQ(rep.polarity, PolarityConvention::kZeroOne);
  EXPECT_EQ(rep.time_unit, TimeUnit::kSeconds);
  ev = read_ecd_events(dir.write("b.txt", "0.1 1 2 -1\n0.2 3 4 +1\n0.3\t5\t6\t1\r\n# comment\n\n0.4 7 8 -1"), {}, &rep);
  ASSERT_EQ(ev.size(), 4u);
  EXPECT_EQ(ev[0].polarity, -1);
  EXPECT_EQ(ev[1].polarity, 1);
  EXPECT_EQ(ev[2], (Event{300000000, 5, 6, 1}));
  EXPECT_EQ(ev[3], (Event{400000000, 7, 8, -1}));  // last line without newline
  EXPECT_EQ(rep.polarity, PolarityConvention::kMinusPlusOne);
}

TEST(EcdEvents, EmptyFileGivesNoEvents) {
  TempDir dir;
  EXPECT_TRUE(read_ecd_events(dir.write("e.txt", "")).empty());
  EXPECT_TRUE(read_ecd_events(dir.write("c.txt", "# only a comment\n\n")).empty());
}

TEST(EcdEvents, WriteReadRoundTripIsLossless) {
  TempDir dir;
  std::mt19937_64 rng(3);
  EventBuffer in;
  int64_t t = 1700000000000000000LL;  // large epoch stamps keep their last nanosecond
  for (int i = 0; i < 20000; ++i) {
    t += static_cast<int64_t>(rng() % 1500);  // includes equal stamps
    in.push_back(Event{t, static_cast<uint16_t>(rng() % 1280), static_cast<uint16_t>(rng() % 720),
                       static_cast<int8_t>(rng() % 2 ? 1 : -1)});
  }
  for (PolarityConvention conv : {PolarityConvention::kZeroOne, PolarityConvention::kMinusPlusOne}) {
    const std::string path = dir.file(std::string("rt_") + (conv == PolarityConvention::kZeroOne ? "01" : "pm") + ".txt");
    EcdEventWriter w(path, conv);
    w.write(in.span().subspan(0, 7000));
    w.write(in.span().subspan(7000, 20000));
    w.close();
    TextReadOptions opts;
    opts.sensor = SensorSize{1280, 720};
    ReadReport rep;
    const EventBuffer out = read_ecd_events(path, opts, &rep);
    ASSERT_EQ(out.size(), in.size());
    for (size_t i = 0; i < in.size(); ++i) ASSERT_EQ(out[i], in[i]) << "event " << i;
    EXPECT_EQ(rep.polarity, conv);
  }
}

TEST(EcdEvents, StreamingInChunksEqualsWholeRead) {
  TempDir dir;
  std::string text;
  for (int i = 0; i < 5000; ++i) text += "0." + std::to_string(100000 + 3 * i) + " " + std::to_string(i % 240) + " 7 " + std::to_string(i % 2) + "\n";
  const std::string path = dir.write("events.txt", text);
  const EventBuffer whole = read_ecd_events(path);
  EcdEventReader reader(path);
  EventBuffer chunked;
  size_t calls = 0;
  while (reader.read(&chunked, 333) > 0) ++calls;
  EXPECT_EQ(calls, (5000 + 332) / 333);
  ASSERT_EQ(chunked.size(), whole.size());
  for (size_t i = 0; i < whole.size(); ++i) ASSERT_EQ(chunked[i], whole[i]);
  EXPECT_DOUBLE_EQ(reader.progress(), 1.0);
}

TEST(EcdEvents, MalformedInputNamesFileLineAndExpectedForm) {
  expect_event_error("0.1 1 2 0\n0.2 1 2\n", {":2:", "expected 4 columns, found 3", "`t x y p`"});
  expect_event_error("0.1 1 2 0 5\n", {":1:", "expected 4 columns, found 5"});
  expect_event_error("0.1 1 2 0\nabc 1 2 0\n", {":2:", "time is not a number"});
  expect_event_error("0.1 -1 2 0\n", {":1:", "x is not a non-negative integer"});
  expect_event_error("0.1 1.5 2 0\n", {":1:", "fractional pixel coordinate", "sub-pixel coordinates",
                                        "read by the sub-pixel path", "read_subpixel"});
  expect_event_error("0.1 3 -5.25 0\n", {":1:", "sub-pixel coordinates"});
  expect_event_error("0.1 1 2 2\n", {":1:", "polarity is not 0, 1, -1 or +1", "polarity 0/1 or -1/+1"});
  expect_event_error("0.1 1 2 0\n0.2 1 2 -1\n", {":2:", "polarity convention -1/+1 mixed with 0/1"});
}

TEST(EcdEvents, NonIncreasingTimestampsAreRejected) {
  expect_event_error("0.2 1 2 0\n0.2 1 3 0\n0.1 1 2 0\n", {":3:", "timestamp 0.100000000 s is earlier than"});
}

TEST(EcdEvents, CoordinatesOutsideTheSensorAreRejected) {
  TextReadOptions opts;
  opts.sensor = SensorSize{240, 180};
  expect_event_error("0.1 239 179 0\n0.2 240 10 1\n", {":2:", "pixel (240, 10) outside the 240x180 sensor"}, opts);
  expect_event_error("0.1 70000 1 0\n", {":1:", "outside the uint16 range"});
}

TEST(EcdEvents, WarnPolicySkipsAndCountsBadLines) {
  TempDir dir;
  const std::string path =
      dir.write("events.txt", "0.1 1 2 0\n0.2 1 2\n0.05 1 1 1\n0.3 300 2 1\n0.4 1 2 7\n0.5 3 3 1\n");
  TextReadOptions opts;
  opts.on_bad_line = BadLinePolicy::kWarnAndSkip;
  opts.sensor = SensorSize{240, 180};
  std::vector<std::string> warnings;
  set_log_sink([&](LogLevel l, const std::string& m) {
    if (l == LogLevel::kWarning) warnings.push_back(m);
  });
  ReadReport rep;
  const EventBuffer ev = read_ecd_events(path, opts, &rep);
  set_log_sink({});
  ASSERT_EQ(ev.size(), 2u);
  EXPECT_EQ(ev[1].t_ns, 500000000);
  EXPECT_EQ(rep.skipped_total(), 4);
  EXPECT_EQ(rep.skipped.at("malformed").count, 1);
  EXPECT_EQ(rep.skipped.at("malformed").first_line, 2);
  EXPECT_EQ(rep.skipped.at("time order").count, 1);
  EXPECT_EQ(rep.skipped.at("outside sensor").count, 1);
  EXPECT_EQ(rep.skipped.at("polarity").first_line, 5);
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find("skipped 4 bad line(s)"), std::string::npos) << warnings[0];
}

std::string integer_events(int n, int64_t step, int64_t t0 = 0) {
  std::string s;
  for (int i = 0; i < n; ++i) s += std::to_string(t0 + i * step) + " 1 2 " + std::to_string(i % 2) + "\n";
  return s;
}

TEST(EcdEvents, AutoTimeUnitDetection) {
  TempDir dir;
  ReadReport rep;
  // Integers: microseconds (1 us steps).
  auto ev = read_ecd_events(dir.write("us.txt", integer_events(2000, 1)), {}, &rep);
  EXPECT_EQ(rep.time_unit, TimeUnit::kMicroseconds);
  EXPECT_EQ(ev[1].t_ns, 1000);
  // Integers that are all multiples of 1000: ns with us resolution.
  read_ecd_events(dir.write("ns.txt", integer_events(2000, 3000)), {}, &rep);
  EXPECT_EQ(rep.time_unit, TimeUnit::kNanoseconds);
  // Epoch nanoseconds.
  ev = read_ecd_events(dir.write("epoch.txt", integer_events(2000, 777, 1700000000000000000LL)), {}, &rep);
  EXPECT_EQ(rep.time_unit, TimeUnit::kNanoseconds);
  EXPECT_EQ(ev[0].t_ns, 1700000000000000000LL);
  // A header comment naming the unit wins.
  ev = read_ecd_events(dir.write("hdr.txt", "# t[us] x y p\n0.500 1 2 0\n1.250 1 2 1\n"), {}, &rep);
  EXPECT_EQ(rep.time_unit, TimeUnit::kMicroseconds);
  EXPECT_EQ(ev[0].t_ns, 500);
  EXPECT_EQ(ev[1].t_ns, 1250);
  EXPECT_NE(rep.time_unit_reason.find("header"), std::string::npos);
}

TEST(EcdEvents, TimeUnitThatDoesNotFitTheDataIsRejected) {
  TextReadOptions opts;
  opts.time_unit = TimeUnit::kSeconds;  // integer microseconds read as seconds: 1 event per second
  expect_event_error(integer_events(2000, 1), {"time unit 's' gives a mean event rate of 1 Hz", "lines 1-2000",
                                               "--time-unit"}, opts);
  opts.time_unit = TimeUnit::kNanoseconds;  // integer us at 4 Mev/s read as ns: 4e9 ev/s
  std::string us4;
  for (int i = 0; i < 2000; ++i) us4 += std::to_string(i / 4) + " 1 2 0\n";
  expect_event_error(us4, {"time unit 'ns' gives a mean event rate of 4.01e+09 Hz", "between 10 and 2e+09 Hz"}, opts);
  // The check can be disabled.
  opts.time_unit = TimeUnit::kSeconds;
  opts.check_time_unit = false;
  TempDir dir;
  EXPECT_EQ(read_ecd_events(dir.write("x.txt", integer_events(2000, 1)), opts).size(), 2000u);
}

// Expects read_ecd_subpixel_events to throw an InputError whose message contains every fragment.
void expect_subpixel_error(const std::string& text, const std::vector<std::string>& fragments) {
  TempDir dir;
  const std::string path = dir.write("events_undistorted.txt", text);
  try {
    read_ecd_subpixel_events(path);
    FAIL() << "no error for:\n" << text;
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(path), std::string::npos) << msg;
    for (const std::string& f : fragments) EXPECT_NE(msg.find(f), std::string::npos) << "'" << f << "' not in: " << msg;
  }
}

TEST(EcdSubpixelEvents, ReadsFractionalNegativeAndIntegerCoordinates) {
  TempDir dir;
  const std::string path = dir.write("ev.txt",
                                     "# t[us] x y p\n"
                                     "0.000 137.005638 120.010244 0\n"
                                     "0.000 227.521278 -5.836659 0\n"
                                     "0.999 -0.25 300.5 1\n"
                                     "2 12 7 1\n"
                                     "3.5\t1e2,+4.75 0\n");
  TextReadOptions opts;
  opts.sensor = SensorSize{240, 180};  // not applied to sub-pixel events
  ReadReport rep;
  const std::vector<SubpixelEvent> ev = read_ecd_subpixel_events(path, opts, &rep);
  ASSERT_EQ(ev.size(), 5u);
  EXPECT_EQ(rep.time_unit, TimeUnit::kMicroseconds);
  EXPECT_NE(rep.time_unit_reason.find("header"), std::string::npos) << rep.time_unit_reason;
  EXPECT_EQ(rep.polarity, PolarityConvention::kZeroOne);
  EXPECT_EQ(rep.records, 5);
  EXPECT_EQ(ev[0].t_ns, 0);
  EXPECT_FLOAT_EQ(ev[0].x, 137.005638f);
  EXPECT_FLOAT_EQ(ev[0].y, 120.010244f);
  EXPECT_EQ(ev[0].polarity, -1);
  EXPECT_FLOAT_EQ(ev[1].y, -5.836659f);
  EXPECT_EQ(ev[2].t_ns, 999);
  EXPECT_FLOAT_EQ(ev[2].x, -0.25f);
  EXPECT_FLOAT_EQ(ev[2].y, 300.5f);
  EXPECT_EQ(ev[2].polarity, 1);
  EXPECT_EQ(ev[3].t_ns, 2000);
  EXPECT_FLOAT_EQ(ev[3].x, 12.0f);
  EXPECT_EQ(ev[4].t_ns, 3500);
  EXPECT_FLOAT_EQ(ev[4].x, 100.0f);
  EXPECT_FLOAT_EQ(ev[4].y, 4.75f);

  // Integer files read the same through both paths.
  const std::string ints = dir.write("int.txt", "0.1 1 2 0\n0.2 3 4 1\n");
  const EventBuffer a = read_ecd_events(ints);
  const std::vector<SubpixelEvent> b = read_ecd_subpixel_events(ints);
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) {
    const SubpixelEvent c = to_subpixel(a[i]);
    EXPECT_EQ(b[i].t_ns, c.t_ns);
    EXPECT_EQ(b[i].x, c.x);
    EXPECT_EQ(b[i].y, c.y);
    EXPECT_EQ(b[i].polarity, c.polarity);
  }
}

TEST(EcdSubpixelEvents, StreamsInChunks) {
  TempDir dir;
  std::string text = "# t[us] x y p\n";
  for (int i = 0; i < 3000; ++i) text += std::to_string(i) + ".5 " + std::to_string(i % 240) + ".25 -1.5 " + std::to_string(i % 2) + "\n";
  EcdEventReader reader(dir.write("ev.txt", text));
  std::vector<SubpixelEvent> ev;
  size_t calls = 0;
  while (reader.read_subpixel(&ev, 1000) > 0) ++calls;
  EXPECT_EQ(calls, 3u);
  ASSERT_EQ(ev.size(), 3000u);
  EXPECT_EQ(ev[2999].t_ns, 2999500);
  EXPECT_FLOAT_EQ(ev[2999].x, 119.25f);
  EXPECT_EQ(reader.report().records, 3000);
  EXPECT_DOUBLE_EQ(reader.progress(), 1.0);
}

TEST(EcdSubpixelEvents, BadLinesNameFileLineAndExpectedForm) {
  expect_subpixel_error("0.1 1 2 0\n0.1 12.5x 3 1\n", {":2:", "x is not a number", "`t x y p`", "finite integers or decimals"});
  expect_subpixel_error("0.1 1 nan 0\n", {":1:", "y is not a finite float"});
  expect_subpixel_error("0.1 inf 2 0\n", {":1:", "x is not a finite float"});
  expect_subpixel_error("0.1 1e300 2 0\n", {":1:", "beyond the float range"});
  expect_subpixel_error("0.1 1.5 2\n", {":1:", "expected 4 columns, found 3"});
  expect_subpixel_error("0.1 1.5 2 0 9\n", {":1:", "expected 4 columns, found 5"});
  expect_subpixel_error("abc 1.5 2 0\n", {":1:", "time is not a number"});
  expect_subpixel_error("0.1 1.5 2 2\n", {":1:", "polarity is not 0, 1, -1 or +1"});
  expect_subpixel_error("0.1 1.5 2 0\n0.2 1.5 2 -1\n", {":2:", "polarity convention -1/+1 mixed with 0/1"});
  expect_subpixel_error("0.2 1.5 2 0\n0.1 1.5 2 0\n", {":2:", "is earlier than the previous event's"});
}

TEST(EcdSubpixelEvents, WarnPolicySkipsAndCountsBadLines) {
  TempDir dir;
  TextReadOptions opts;
  opts.on_bad_line = BadLinePolicy::kWarnAndSkip;
  set_log_sink([](LogLevel, const std::string&) {});
  ReadReport rep;
  const auto ev = read_ecd_subpixel_events(
      dir.write("ev.txt", "0.1 1.5 2 0\n0.2 nan 2 0\n0.3 12.5x 3 1\n0.05 1 1 1\n0.4 -3.5 2.5 1\n"), opts, &rep);
  set_log_sink({});
  ASSERT_EQ(ev.size(), 2u);
  EXPECT_FLOAT_EQ(ev[1].x, -3.5f);
  EXPECT_EQ(rep.skipped.at("non-finite").count, 1);
  EXPECT_EQ(rep.skipped.at("malformed").first_line, 3);
  EXPECT_EQ(rep.skipped.at("time order").count, 1);
}

TEST(EcdImu, ReadsAndValidates) {
  TempDir dir;
  std::string text;
  for (int i = 0; i < 20; ++i) text += "0.00" + std::to_string(10 + i) + " 0.1 0.2 9.8 0.01 0.02 0.03\n";
  const auto imu = read_ecd_imu(dir.write("imu.txt", text));
  ASSERT_EQ(imu.size(), 20u);
  EXPECT_EQ(imu[0].t_ns, 1000000);
  EXPECT_DOUBLE_EQ(imu[0].accel.z(), 9.8);
  EXPECT_DOUBLE_EQ(imu[0].gyro.x(), 0.01);
  // Round trip.
  write_ecd_imu(dir.file("imu2.txt"), imu);
  const auto back = read_ecd_imu(dir.file("imu2.txt"));
  ASSERT_EQ(back.size(), imu.size());
  for (size_t i = 0; i < imu.size(); ++i) {
    EXPECT_EQ(back[i].t_ns, imu[i].t_ns);
    EXPECT_EQ(back[i].accel, imu[i].accel);
    EXPECT_EQ(back[i].gyro, imu[i].gyro);
  }
  auto expect_err = [&](const std::string& body, const std::vector<std::string>& frags) {
    const std::string p = dir.write("bad.txt", body);
    try {
      read_ecd_imu(p);
      FAIL() << body;
    } catch (const InputError& e) {
      for (const auto& f : frags) EXPECT_NE(std::string(e.what()).find(f), std::string::npos) << e.what();
    }
  };
  expect_err("0.1 0 0 9.8 0 0 0\n0.2 0 0 nan 0 0 0\n", {"bad.txt:2:", "NaN or infinite", "`t ax ay az gx gy gz`"});
  expect_err("0.1 0 0 9.8 0 0 inf\n", {":1:", "NaN or infinite"});
  expect_err("0.1 0 0 9.8 0 0\n", {":1:", "expected 7 columns, found 6"});
  expect_err("0.1 0 0 9.8 0 0 0\n0.1 0 0 9.8 0 0 0\n", {":2:", "is not after the previous sample", "strictly increasing"});
  expect_err("0.1 0 0 x 0 0 0\n", {":1:", "a value is not a number"});
}

// EcdImuReader streams imu.txt in chunks (how `evio vio` reads a long recording): the chunks are the
// whole read's samples, each at most the size asked for, and the end comes as 0.
TEST(EcdImu, StreamingInChunksEqualsWholeRead) {
  TempDir dir;
  std::string text = "# t ax ay az gx gy gz\n";
  for (int i = 0; i < 1000; ++i) {
    text += std::to_string(i) + ".00" + std::to_string(i % 10) + " 0.1 0.2 9.8 0.01 0.02 " + std::to_string(i) + "\n";
  }
  const std::string path = dir.write("imu.txt", text);
  const auto whole = read_ecd_imu(path);
  ASSERT_EQ(whole.size(), 1000u);
  EcdImuReader reader(path);
  std::vector<ImuSample> streamed;
  for (;;) {
    std::vector<ImuSample> chunk;
    const size_t n = reader.read(&chunk, 64);
    ASSERT_EQ(n, chunk.size());
    ASSERT_LE(n, 64u);
    if (n == 0) break;
    streamed.insert(streamed.end(), chunk.begin(), chunk.end());
  }
  EXPECT_EQ(reader.read(&streamed, 64), 0u);  // stays at the end
  ASSERT_EQ(streamed.size(), whole.size());
  for (size_t i = 0; i < whole.size(); ++i) {
    EXPECT_EQ(streamed[i].t_ns, whole[i].t_ns);
    EXPECT_EQ(streamed[i].gyro, whole[i].gyro);
  }
  EXPECT_EQ(reader.report().records, 1000);
}

TEST(EcdImages, ListsFramesAndRejectsMissingFiles) {
  TempDir dir;
  Frame f;
  f.t_ns = 1000;
  f.image = cv::Mat(4, 6, CV_8UC1, cv::Scalar(77));
  Frame g = f;
  g.t_ns = 2000;
  write_ecd_images(dir.path(), {f, g});
  auto frames = read_ecd_image_list(dir.file("images.txt"));
  ASSERT_EQ(frames.size(), 2u);
  EXPECT_EQ(frames[1].t_ns, 2000);
  load_frame_image(&frames[1]);
  EXPECT_EQ(frames[1].image.cols, 6);
  EXPECT_EQ(frames[1].image.at<uint8_t>(2, 3), 77);
  dir.write("images2.txt", "0.1 images/frame_00000000.png\n0.2 images/nope.png\n");
  try {
    read_ecd_image_list(dir.file("images2.txt"));
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("images2.txt:2:"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("nope.png does not exist"), std::string::npos) << e.what();
  }
  Frame bad;
  bad.path = dir.write("broken.png", "not a png");
  EXPECT_THROW(load_frame_image(&bad), InputError);
  Frame no_path;
  EXPECT_THROW(load_frame_image(&no_path), InputError);
}

TEST(EcdFolder, AcceptsEventsUndistortedWithoutEventsTxt) {
  TempDir dir;
  dir.write("events_undistorted.txt", "");
  dir.write("calib.txt", "");
  EXPECT_EQ(find_ecd_folder(dir.path()).events, dir.file("events_undistorted.txt"));
  EXPECT_EQ(find_ecd_folder(dir.path()).calib, dir.file("calib.txt"));
  dir.write("events.txt", "");
  EXPECT_EQ(find_ecd_folder(dir.path()).events, dir.file("events.txt"));  // events.txt wins
}

TEST(EcdFolder, FindsFilesAndRequiresEvents) {
  TempDir dir;
  EXPECT_THROW(find_ecd_folder(dir.path()), InputError);
  EXPECT_THROW(find_ecd_folder(dir.file("missing")), InputError);
  dir.write("events.txt", "");
  dir.write("imu.txt", "");
  const EcdFolder f = find_ecd_folder(dir.path());
  EXPECT_FALSE(f.events.empty());
  EXPECT_FALSE(f.imu.empty());
  EXPECT_TRUE(f.groundtruth.empty());
  EXPECT_THROW(EcdEventReader(dir.file("nope.txt")), InputError);
}

TEST(EcdRealData, SliderDepthHeadEventsExactly) {
  const auto dir = evio_test::real_data_dir("ecd_slider_depth_head");
  if (!dir) GTEST_SKIP() << "real data not found (../shared/data/real/ecd_slider_depth_head)";
  TextReadOptions opts;
  opts.sensor = SensorSize{240, 180};
  ReadReport rep;
  const EventBuffer ev = read_ecd_events(*dir + "/events.txt", opts, &rep);
  EXPECT_EQ(ev.size(), 50000u);
  EXPECT_EQ(rep.skipped_total(), 0);
  EXPECT_EQ(rep.time_unit, TimeUnit::kSeconds);
  EXPECT_EQ(rep.polarity, PolarityConvention::kZeroOne);
  EXPECT_EQ(ev.front(), (Event{3811000, 96, 133, -1}));
  EXPECT_EQ(ev.back(), (Event{174156000, 70, 103, 1}));
  EXPECT_TRUE(ev.is_time_sorted());
  const auto frames = read_ecd_image_list(*dir + "/images.txt");
  EXPECT_EQ(frames.size(), 87u);
  EXPECT_EQ(frames[1].t_ns, 38766001);
}

}  // namespace
}  // namespace evio
