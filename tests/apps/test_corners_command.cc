// `evio corners`: outputs and their consistency on a synthetic ECD folder (a bright square moving
// over a 64x48 sensor, so it has corners), config parsing errors, missing sensor size, and the
// real ECD slice (reduction rate, same corners as the library detector).
#include "corners_command.h"

#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>

#include <gtest/gtest.h>

#include "evio/calib/error.h"
#include "evio/sensors/ecd.h"
#include "evio_test/real_data.h"
#include "evio_test/temp_dir.h"
#include "evio_test/text_file.h"

namespace evio::apps {
namespace {

std::string read(const std::string& p) { return evio_test::read_text(p); }

size_t data_lines(const std::string& text) {
  size_t n = 0;
  std::istringstream in(text);
  for (std::string l; std::getline(in, l);) n += !l.empty() && l[0] != '#';
  return n;
}

// A 14x14 square moving diagonally; leading edges ON, trailing edges OFF, written with 0/1
// polarity and seconds, plus a distortion-free calib.txt for a 64x48 sensor.
std::string synthetic_folder(const evio_test::TempDir& dir) {
  std::string ev;
  int64_t t = 1'000'000;
  char line[96];
  for (int s = 0; s < 300; ++s) {
    const int x0 = 8 + s % 34, y0 = 6 + (s / 2) % 24;
    for (int y = y0; y < y0 + 14; ++y) {
      for (int x = x0; x < x0 + 14; ++x) {
        const bool leading = x == x0 + 13 || y == y0 + 13, trailing = x == x0 || y == y0;
        if (!leading && !trailing) continue;
        std::snprintf(line, sizeof(line), "%lld.%09lld %d %d %d\n", static_cast<long long>(t / 1'000'000'000),
                      static_cast<long long>(t % 1'000'000'000), x, y, leading ? 1 : 0);
        ev += line;
        t += 1000;
      }
    }
  }
  dir.write("seq/events.txt", ev);
  dir.write("seq/calib.txt", "60 60 32 24 0 0 0 0 0\n");
  return dir.file("seq");
}

TEST(CornersCommand, OutputsAreConsistentWithEachOther) {
  evio_test::TempDir dir;
  CornersArgs a;
  a.dataset = synthetic_folder(dir);
  a.calib = a.dataset + "/calib.txt";
  a.out = dir.file("out");
  a.frames_every_ns = 2'000'000;
  a.progress = false;
  a.config = dir.write("c.yaml", "tracker:\n  min_length: 3\nframes:\n  window_ms: 5\n");
  std::ostringstream out;
  ASSERT_EQ(run_corners(a, out), 0);
  const std::string stats = read(a.out + "/stats.json");
  std::smatch m;
  ASSERT_TRUE(std::regex_search(stats, m, std::regex("\"corners\": ([0-9]+)")));
  const size_t corners = std::stoul(m[1]);
  EXPECT_GT(corners, 50u);
  const std::string ctext = read(a.out + "/corners.txt");
  EXPECT_EQ(data_lines(ctext), corners);
  // t[s] x y p with the input's 0/1 polarity convention.
  EXPECT_TRUE(std::regex_search(ctext, std::regex("\n[0-9]+\\.[0-9]{9} [0-9]+ [0-9]+ [01]\n")));
  EXPECT_FALSE(std::regex_search(ctext, std::regex(" -1\n")));
  ASSERT_TRUE(std::regex_search(stats, m, std::regex("\"events\": ([0-9]+)")));
  const double events = std::stod(m[1]);
  ASSERT_TRUE(std::regex_search(stats, m, std::regex("\"reduction_rate\": ([0-9.e+-]+)")));
  EXPECT_NEAR(std::stod(m[1]), events / corners, 1e-9 * events);
  EXPECT_TRUE(std::regex_search(stats, std::regex("\"ns_per_event\": [0-9.e+-]+")));
  // Tracks: every line is `id t x y xu yu`, undistorted = distorted for a distortion-free camera.
  const std::string ttext = read(a.out + "/tracks.txt");
  EXPECT_GT(data_lines(ttext), 10u);
  std::istringstream in(ttext);
  for (std::string l; std::getline(in, l);) {
    if (l.empty() || l[0] == '#') continue;
    std::istringstream ls(l);
    long long id;
    double t, x, y, xu, yu;
    ASSERT_TRUE(static_cast<bool>(ls >> id >> t >> x >> y >> xu >> yu)) << l;
    EXPECT_NEAR(x, xu, 1e-3);
    EXPECT_NEAR(y, yu, 1e-3);
  }
  // Overlays: one per 2 ms of the ~15.6 ms sequence, plus the last.
  size_t pngs = 0;
  for (const auto& f : std::filesystem::directory_iterator(a.out + "/frames")) pngs += f.path().extension() == ".png";
  EXPECT_GE(pngs, 7u);
  EXPECT_LE(pngs, 9u);
  EXPECT_TRUE(std::regex_search(out.str(), std::regex("reduction [0-9.]+x")));
}

TEST(CornersCommand, FilteredSaeGivesFewerCorners) {
  evio_test::TempDir dir;
  CornersArgs a;
  a.dataset = synthetic_folder(dir);
  a.calib = a.dataset + "/calib.txt";
  a.progress = false;
  a.out = dir.file("plain");
  std::ostringstream o1, o2;
  ASSERT_EQ(run_corners(a, o1), 0);
  a.filter_sae = true;
  a.out = dir.file("filtered");
  ASSERT_EQ(run_corners(a, o2), 0);
  EXPECT_LT(data_lines(read(dir.file("filtered/corners.txt"))), data_lines(read(dir.file("plain/corners.txt"))));
  EXPECT_NE(read(dir.file("filtered/stats.json")).find("\"filter_sae\": true"), std::string::npos);
}

TEST(CornersCommand, ConfigErrorsNameFileLineAndExpectedForm) {
  evio_test::TempDir dir;
  const auto expect_error = [&](const std::string& yaml, const std::string& what) {
    const std::string p = dir.write("bad.yaml", yaml);
    try {
      load_corners_config(p);
      ADD_FAILURE() << "no error for " << yaml;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
    }
  };
  expect_error("efast:\n  filter_sae: true\n  window: 3\n", "bad.yaml:3");
  expect_error("efast:\n  filter_sae: true\n  window: 3\n", "unknown key 'window'");
  expect_error("tracker:\n  max_distance_px: -1\n", "tracker.max_distance_px");
  expect_error("background_activity:\n  radius: 9\n", "background_activity.radius");
  expect_error("frames: [1, 2]\n", "frames");
  expect_error("tracker:\n  velocity_window_ms: 2\n  min_velocity_span_ms: 5\n", "min_velocity_span_ms");
  const CornersConfig c = load_corners_config(dir.write("ok.yaml",
      "refractory: {period_ms: 2}\nbackground_activity: {window_ms: 5, radius: 2, min_support: 3}\n"
      "efast: {filter_sae: true, filter_window_ms: 30}\nframes: {every_ms: 25}\n"));
  EXPECT_TRUE(c.refractory_enabled);
  EXPECT_EQ(c.refractory.period_ns, 2'000'000);
  EXPECT_TRUE(c.background_activity_enabled);
  EXPECT_EQ(c.background_activity.min_support, 3);
  EXPECT_TRUE(c.efast.filter_sae);
  EXPECT_EQ(c.efast.filter_window_ns, 30'000'000);
  EXPECT_EQ(c.frames_every_ns, 25'000'000);
}

TEST(CornersCommand, UnknownSensorSizeIsAnError) {
  evio_test::TempDir dir;
  dir.write("ev.txt", "0.000001 1 1 1\n0.000002 2 2 0\n");
  CornersArgs a;
  a.dataset = dir.file("ev.txt");
  a.out = dir.file("out");
  a.progress = false;
  std::ostringstream o;
  try {
    run_corners(a, o);
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("--calib"), std::string::npos) << e.what();
  }
  // With --sensor it runs (no calibration: tracks without undistorted columns).
  a.dataset_options.text.sensor = {16, 16};
  ASSERT_EQ(run_corners(a, o), 0);
  EXPECT_NE(read(a.out + "/tracks.txt").find("# track_id t[s] x y   "), std::string::npos);
}

TEST(CornersCommandRealData, EcdSliceReductionMatchesTheLibraryDetector) {
  const auto dir = evio_test::real_data_dir("ecd_slider_depth_head");
  if (!dir) GTEST_SKIP() << "real data not found";
  evio_test::TempDir tmp;
  CornersArgs a;
  a.dataset = *dir;
  a.out = tmp.file("out");
  a.progress = false;
  std::ostringstream o;
  ASSERT_EQ(run_corners(a, o), 0);
  // The library detector over the raw events (no filters configured): the same count.
  const EventBuffer ev = read_ecd_events(*dir + "/events.txt");
  frontend::EfastDetector d(240, 180);
  size_t corners = 0;
  for (const Event& e : ev) corners += d.process(e);
  EXPECT_EQ(data_lines(read(a.out + "/corners.txt")), corners);
  const double reduction = static_cast<double>(ev.size()) / corners;
  std::printf("ecd_slider_depth_head: %zu events, %zu corners, reduction %.1fx\n", ev.size(), corners, reduction);
  EXPECT_GT(reduction, 10.0);  // the paper: 10-20x on ECD scenes
  EXPECT_LT(reduction, 30.0);
}

}  // namespace
}  // namespace evio::apps
