// `evio reconstruct`: outputs on a tiny synthetic ECD folder with APS frames (a bright bar moving
// over a grey wall): images.txt in the Event Camera Dataset layout, PNG + float TIFF per time,
// stats.json, the resolved config, --at and --rate, --method gradient, --corners, and errors.
#include "reconstruct_command.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <sstream>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "evio/calib/error.h"
#include "evio/sensors/image_io.h"
#include "evio_test/temp_dir.h"
#include "evio_test/text_file.h"

namespace evio::apps {
namespace {

namespace fs = std::filesystem;

// 0.2 s: a bar (x in [bx, bx + 10), grey 115) moving right at 200 px/s over grey 80; its leading edge gives
// ON events, its trailing edge OFF events (one per pixel per 5 ms step); frames every 50 ms.
std::string bar_folder(const evio_test::TempDir& dir) {
  std::string ev, images;
  auto bar_x = [](double t) { return 20 + static_cast<int>(200 * t); };
  for (int step = 1; step <= 40; ++step) {
    const double t = step * 0.005;
    const int x0 = bar_x(t - 0.005), x1 = bar_x(t);
    for (int x = x0; x < x1; ++x)
      for (int y = 60; y < 120; y += 1) {
        char line[64];
        std::snprintf(line, sizeof(line), "%.6f %d %d 1\n%.6f %d %d 0\n", t, x + 10, y, t, x, y);
        ev += line;
      }
  }
  fs::create_directories(dir.file("bar/images"));
  for (int k = 0; k < 5; ++k) {
    const double t = 0.05 * k;
    cv::Mat m(180, 240, CV_8UC1, cv::Scalar(80));
    m(cv::Rect(bar_x(t), 60, 10, 60)).setTo(115);  // log(115/255 + 1) - log(80/255 + 1) = 0.1: one event
    char name[64];
    std::snprintf(name, sizeof(name), "images/frame_%08d.png", k);
    EXPECT_TRUE(write_image(dir.file(std::string("bar/") + name), m));
    char line[96];
    std::snprintf(line, sizeof(line), "%.6f %s\n", t, name);
    images += line;
  }
  dir.write("bar/events.txt", ev);
  dir.write("bar/images.txt", images);
  dir.write("bar/calib.txt", "200 200 120 90 0 0 0 0 0\n");
  return dir.file("bar");
}

TEST(ReconstructCommand, WritesImagesListedLikeADataset) {
  evio_test::TempDir dir;
  for (const char* method : {"hf", "cf", "akf", "gradient"}) {
    ReconstructArgs a;
    a.dataset = bar_folder(dir);
    a.out = dir.file(std::string("out_") + method);
    a.method = method;
    a.use_frames = std::string(method) != "hf";
    a.at_ns = {120'000'000, 40'000'000, 170'000'000};
    a.progress = false;
    std::ostringstream out;
    ASSERT_EQ(run_reconstruct(a, out), 0) << out.str();
    const std::string list = evio_test::read_text(a.out + "/images.txt");
    EXPECT_NE(list.find("0.040000000 images/frame_00000000.png\n0.120000000 images/frame_00000001.png\n"
                        "0.170000000 images/frame_00000002.png\n"),
              std::string::npos)
        << list;
    const cv::Mat png = read_image(a.out + "/images/frame_00000002.png", cv::IMREAD_UNCHANGED);
    const cv::Mat tiff = read_image(a.out + "/images/frame_00000002.tiff", cv::IMREAD_UNCHANGED);
    ASSERT_EQ(png.type(), CV_8UC1);
    ASSERT_EQ(tiff.type(), CV_32FC1);
    ASSERT_EQ(tiff.cols, 240);
    // At 0.17 s the bar covers x in [54, 64): brighter than the wall behind it in both outputs.
    EXPECT_GT(tiff.at<float>(90, 59), tiff.at<float>(90, 30) + 0.05f) << method;
    EXPECT_GT(png.at<uint8_t>(90, 59), png.at<uint8_t>(90, 30)) << method;
    const std::string stats = evio_test::read_text(a.out + "/stats.json");
    EXPECT_NE(stats.find("\"method\": \"" + std::string(method) + "\""), std::string::npos);
    EXPECT_NE(stats.find("\"images\": 3"), std::string::npos) << stats;
    EXPECT_NE(stats.find(a.use_frames ? "\"frames_fused\": 5" : "\"frames_fused\": 0"), std::string::npos) << stats;
    EXPECT_NE(stats.find("\"time_per_event_ns\""), std::string::npos);
    EXPECT_TRUE(fs::exists(a.out + "/reconstruct_config.yaml"));
  }
}

// --corners: event Harris corner events in corners.txt as `evio corners` writes them (`t x y p`,
// polarity as in the input: 0/1 here), at the bar's four corners (y = 60 or 119, x on an edge).
TEST(ReconstructCommand, CornersWritesHarrisCornerEvents) {
  evio_test::TempDir dir;
  ReconstructArgs a;
  a.dataset = bar_folder(dir);
  a.out = dir.file("out");
  a.method = "gradient";
  a.corners = true;
  a.set = {"harris.threshold=3e-7"};  // edges of one 0.1 event: R ~ 1e-6 at the corners (measured: 63 corner events, all at corners; 1e-7: 533, a third at corners)
  a.at_ns = {100'000'000};
  a.progress = false;
  std::ostringstream out;
  ASSERT_EQ(run_reconstruct(a, out), 0) << out.str();
  std::istringstream corners(evio_test::read_text(a.out + "/corners.txt"));
  std::string header;
  std::getline(corners, header);
  EXPECT_EQ(header, "# t[s] x y p   (event Harris corner events, polarity as in the input)");
  double t;
  int x, y, p, n = 0, at_corner = 0;
  while (corners >> t >> x >> y >> p) {
    ++n;
    EXPECT_TRUE(p == 0 || p == 1);
    EXPECT_GE(t, 0.005);
    at_corner += std::abs(y - 60) <= 3 || std::abs(y - 119) <= 3;
  }
  std::printf("%d corner events, %d within 3 px of the bar's top or bottom edge\n", n, at_corner);
  EXPECT_GT(n, 30);
  EXPECT_GT(at_corner, 0.9 * n);
  const std::string stats = evio_test::read_text(a.out + "/stats.json");
  EXPECT_NE(stats.find("\"corner_events\": " + std::to_string(n)), std::string::npos) << stats;
  EXPECT_NE(stats.find("\"harris_time_per_event_ns\""), std::string::npos) << stats;
}

TEST(ReconstructCommand, RateConfigRoundTripAndErrors) {
  evio_test::TempDir dir;
  ReconstructArgs a;
  a.dataset = bar_folder(dir);
  a.out = dir.file("out");
  a.rate_hz = 50;
  a.cutoff_hz = 2.0;
  a.contrast_off = 0.2;
  a.progress = false;
  std::ostringstream out;
  ASSERT_EQ(run_reconstruct(a, out), 0) << out.str();
  // First event at 5 ms, last at 200 ms: images at 5, 25, ..., 185 ms.
  const std::string list = evio_test::read_text(a.out + "/images.txt");
  EXPECT_NE(list.find("0.005000000 images/frame_00000000.png"), std::string::npos) << list;
  EXPECT_NE(list.find("0.185000000 images/frame_00000009.png"), std::string::npos) << list;
  EXPECT_EQ(list.find("frame_00000010"), std::string::npos) << list;
  const ReconstructConfig c = load_reconstruct_config(a.out + "/reconstruct_config.yaml");
  EXPECT_EQ(c.cf.cutoff_hz, 2.0);
  EXPECT_EQ(c.cf.contrast_off, 0.2);
  EXPECT_EQ(c.akf.contrast_off, 0.2);
  EXPECT_EQ(c.rate_hz, 50.0);
  EXPECT_EQ(reconstruct_config_text(c), reconstruct_config_text(load_reconstruct_config("", {"rate_hz=50", "cf.cutoff_hz=2", "cf.contrast_off=0.2", "akf.contrast_off=0.2"})));

  ReconstructArgs bad = a;
  bad.method = "akf";
  EXPECT_THROW(resolve_reconstruct_config(bad), InputError);  // --cutoff-hz with akf
  bad = a;
  bad.method = "poisson";
  EXPECT_THROW(resolve_reconstruct_config(bad), InputError);
  bad = a;
  bad.cutoff_hz.reset();
  bad.use_frames = true;
  bad.dataset = dir.write("no_frames/events.txt", "0.001 1 1 1\n0.002 2 2 0\n");
  bad.dataset_options.text.sensor = {16, 16};
  try {
    run_reconstruct(bad, out);
    ADD_FAILURE() << "--use-frames without frames must fail";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("no APS frames"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace evio::apps
