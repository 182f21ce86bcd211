// `evio segment`: outputs on a tiny synthetic ECD folder (two patches of short edges moving with
// different flows over a still background; integer pixels), labels.txt in input order with one
// line per input event, segments.json / stats.json fields, the config round trip and input errors.
#include "segment_command.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <random>
#include <sstream>

#include <gtest/gtest.h>

#include "evio/calib/error.h"
#include "evio_test/temp_dir.h"
#include "evio_test/text_file.h"

namespace evio::apps {
namespace {

namespace fs = std::filesystem;
using evio_test::read_text;

std::string seconds(int64_t t_ns) {
  char b[40];
  std::snprintf(b, sizeof(b), "%lld.%09lld", static_cast<long long>(t_ns / 1'000'000'000),
                static_cast<long long>(t_ns % 1'000'000'000));
  return b;
}

// Short edges; those in two discs move at (150, -60) and (-100, -120) px/s, the rest stay; one
// event every 2 us; labels 0 (still), 1, 2 returned in input order.
std::string patches_folder(const evio_test::TempDir& dir, int n, std::vector<int>* truth) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> U(0, 1);
  struct Edge { double x, y, a; int label; };
  std::vector<Edge> edges;
  for (int i = 0; i < 400; ++i) {
    const double x = 5 + 230 * U(rng), y = 5 + 170 * U(rng);
    int label = 0;
    if (std::hypot(x - 70, y - 90) < 35) label = 1;
    if (std::hypot(x - 170, y - 80) < 30) label = 2;
    edges.push_back({x, y, M_PI * U(rng), label});
  }
  const double v[3][2] = {{0, 0}, {150, -60}, {-100, -120}};
  std::string ev;
  for (int k = 0; k < n; ++k) {
    const Edge& e = edges[static_cast<size_t>(k) % edges.size()];
    const double t = k * 2e-6, a = 4 * U(rng);
    const long x = std::lround(e.x + a * std::cos(e.a) + v[e.label][0] * t);
    const long y = std::lround(e.y + a * std::sin(e.a) + v[e.label][1] * t);
    if (x < 0 || y < 0 || x > 239 || y > 179) continue;
    ev += seconds(1'000'000'000 + static_cast<int64_t>(k) * 2000) + " " + std::to_string(x) + " " + std::to_string(y) +
          ((k % 2) ? " 1\n" : " 0\n");
    truth->push_back(e.label);
  }
  dir.write("patches/events.txt", ev);
  dir.write("patches/calib.txt", "200 200 120 90 0 0 0 0 0\n");
  return dir.file("patches");
}

TEST(SegmentCommand, OutputsLabelsInInputOrder) {
  evio_test::TempDir dir;
  std::vector<int> truth;
  SegmentArgs a;
  a.dataset = patches_folder(dir, 65000, &truth);
  a.out = dir.file("out");
  a.window_events = 30000;
  a.progress = false;
  std::ostringstream out;
  ASSERT_EQ(run_segment(a, out), 0) << out.str();
  // labels.txt: one line per input event, same t x y p as the input, in input order.
  const std::string events = read_text(fs::path(a.dataset) / "events.txt");
  const std::string labels = read_text(fs::path(a.out) / "labels.txt");
  std::istringstream in(events), lab(labels);
  std::string le, ll;
  size_t n = 0, unlabelled = 0;
  std::map<int, std::map<int, int>> votes;
  while (std::getline(in, le)) {
    ASSERT_TRUE(std::getline(lab, ll)) << "labels.txt is short at line " << n + 1;
    ASSERT_EQ(ll.substr(0, le.size()), le) << "line " << n + 1;
    const int label = std::stoi(ll.substr(le.size() + 1));
    if (label < 0) {
      ++unlabelled;
    } else {
      ++votes[truth[n]][label];
    }
    ++n;
  }
  EXPECT_FALSE(std::getline(lab, ll)) << "labels.txt has extra lines";
  EXPECT_EQ(n, truth.size());
  // Two full windows; the 5k-event tail is under half a window and gets -1.
  EXPECT_GE(unlabelled, 5000u);
  EXPECT_LT(unlabelled, 6500u);
  // Each object has one dominant label over both windows (persistent), and they differ.
  std::map<int, int> label_of;
  for (const auto& [object, v] : votes) {
    int best = -1, most = 0, all = 0;
    for (const auto& [l, c] : v) {
      all += c;
      if (c > most) most = c, best = l;
    }
    EXPECT_GE(static_cast<double>(most) / all, 0.75) << "object " << object;
    label_of[object] = best;
  }
  EXPECT_NE(label_of[1], label_of[0]);
  EXPECT_NE(label_of[2], label_of[0]);
  EXPECT_NE(label_of[1], label_of[2]);
  const std::string seg = read_text(fs::path(a.out) / "segments.json");
  for (const char* key : {"\"windows\"", "\"clusters\"", "\"vx_pxps\"", "\"models_tried\"", "\"count_steps\"", "\"gain\""})
    EXPECT_NE(seg.find(key), std::string::npos) << key;
  const std::string stats = read_text(fs::path(a.out) / "stats.json");
  for (const char* key : {"\"windows\": 2", "\"events_in_no_window\"", "\"time_per_event_us\"", "\"undistortion\": \"none\"",
                          "\"objective\": \"normalized_gradient_magnitude\"", "\"dithered\": true"})
    EXPECT_NE(stats.find(key), std::string::npos) << key << "\n" << stats;
  EXPECT_TRUE(fs::exists(fs::path(a.out) / "images" / "window_000000.png"));
  EXPECT_TRUE(fs::exists(fs::path(a.out) / "segment_config.yaml"));
  // The resolved config reads back.
  const SegmentConfig back = load_segment_config((fs::path(a.out) / "segment_config.yaml").string());
  EXPECT_EQ(back.window.window_events, 30000);
  EXPECT_EQ(segment_config_text(back), read_text(fs::path(a.out) / "segment_config.yaml"));
}

TEST(SegmentCommand, FlagsAndErrors) {
  SegmentArgs a;
  a.clusters = "3";
  a.models = "flow,rotation";
  const SegmentConfig c = resolve_segment_config(a);
  EXPECT_EQ(c.segmentation.clusters, 3);
  ASSERT_EQ(c.segmentation.models.size(), 2u);
  a.clusters = "auto";
  EXPECT_EQ(resolve_segment_config(a).segmentation.clusters, 0);
  a.clusters = "many";
  EXPECT_THROW(resolve_segment_config(a), InputError);
  a.clusters = "";
  a.models = "flow,affine";
  EXPECT_THROW(resolve_segment_config(a), InputError);
  a.models = "";
  a.set = {"segmentation.models=[similarity, flow, similarity]"};
  EXPECT_THROW(resolve_segment_config(a), InputError);  // listed twice
  a.set = {"segmentation.models=similarity,6dof"};
  EXPECT_EQ(resolve_segment_config(a).segmentation.models.size(), 2u);
}

}  // namespace
}  // namespace evio::apps
