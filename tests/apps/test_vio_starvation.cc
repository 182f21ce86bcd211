// `evio vio` when the events stop or nearly stop (issue 34): a 2 s blank-wall gap and a slow hover,
// on evio's own simulator and on the crosscheck simulator (../shared/crosscheck_sim, skipped when
// absent). Through a gap the estimate is IMU-only for no longer than the data's own gap plus 0.2 s
// and says so (stats.json imu_only_segments), the tracks come back on the landmarks of before
// (re-acquisition, no re-initialisation); in a hover the position stays put.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "evio/sensors/ecd.h"
#include "evio_test/temp_dir.h"
#include "evio_test/text_file.h"
#include "simulated_scene.h"
#include "vio_command.h"
#include "vio_run.h"

namespace evio::apps {
namespace {

struct Span {
  double begin = 0, end = 0;
};

// stats.json's imu_only_segments.
std::vector<Span> imu_only(const std::string& stats) {
  std::vector<Span> out;
  const size_t at = stats.find("\"imu_only_segments\": [");
  if (at == std::string::npos) return out;
  const std::string list = stats.substr(at, stats.find(']', at) - at);
  const std::regex seg("\"t_begin\": ([0-9.]+), \"t_end\": ([0-9.]+)");
  for (auto it = std::sregex_iterator(list.begin(), list.end(), seg); it != std::sregex_iterator(); ++it) {
    out.push_back({std::stod((*it)[1]), std::stod((*it)[2])});
  }
  return out;
}

// The longest run of 50 ms windows with fewer than `min_events` events (the data's own gap, s).
double longest_event_gap_s(const std::string& events_txt, size_t min_events) {
  const EventBuffer ev = read_ecd_events(events_txt);
  if (ev.empty()) return 0;
  const int64_t w = 50'000'000, t0 = ev.front().t_ns;
  std::vector<size_t> count(static_cast<size_t>((ev.back().t_ns - t0) / w) + 1, 0);
  for (const Event& e : ev) ++count[static_cast<size_t>((e.t_ns - t0) / w)];
  size_t run = 0, best = 0;
  for (size_t c : count) {
    run = c < min_events ? run + 1 : 0;
    best = std::max(best, run);
  }
  return 0.05 * static_cast<double>(best);
}

// Runs evio vio (vio_run.h); returns its stats.json.
std::string run(const std::string& dataset, const std::string& out, const std::string& config) {
  return evio_test::read_text(vio_on(dataset, out, config).out + "/stats.json");
}

double number(const std::string& json, const std::string& key) { return evio_test::json_number(json, key); }

// evio's simulator: poster_6dof with every event of [2.5, 4.5) s removed (what a pass over a wall
// without texture leaves: no events). The span is IMU-only and reported, and no longer than the gap
// plus 0.2 s; tracks of the landmarks from before come back (re-acquisition); the estimate stays.
TEST(VioStarvation, TwoSecondGapIsImuOnlyThenTheTracksComeBack) {
  evio_test::TempDir dir;
  const std::string seq = simulate_scene(dir, "poster_6dof.yaml", 7.0);
  const EventBuffer events = read_ecd_events(seq + "/events.txt");
  const int64_t t0 = events.front().t_ns;
  const std::string gap = dir.file("gap");
  std::filesystem::create_directories(gap);
  for (const char* f : {"calib.txt", "calib.yaml", "groundtruth.txt", "imu.txt"}) std::filesystem::copy_file(seq + "/" + f, gap + "/" + f);
  std::vector<Event> kept;
  for (const Event& e : events) {
    if (e.t_ns < t0 + 2'500'000'000 || e.t_ns >= t0 + 4'500'000'000) kept.push_back(e);
  }
  EcdEventWriter w(gap + "/events.txt");
  w.write(EventSpan(kept.data(), kept.size()));
  w.close();
  const std::string stats = run(gap, gap + "/vio", kSimulatorConfig);
  const std::vector<Span> spans = imu_only(stats);
  ASSERT_FALSE(spans.empty()) << stats;
  double longest = 0;
  bool covers = false;
  for (const Span& s : spans) {
    longest = std::max(longest, s.end - s.begin);
    covers = covers || (s.begin <= 2.6 && s.end >= 4.5);
  }
  EXPECT_TRUE(covers) << stats;
  EXPECT_LE(longest, 2.0 + 0.2) << stats;
  EXPECT_GT(number(stats, "reacquired"), 0) << stats;
  EXPECT_LT(number(stats, "t"), 2.5) << "initialised once, before the gap: " << stats;
  const double mpe = number(evio_test::read_text(gap + "/vio/eval.json"), "mean_position_error_percent");
  std::printf("2 s gap: IMU-only %.2f s, mean position error %.3f%%\n", longest, mpe);
  EXPECT_LT(mpe, 0.5);  // measured 0.357% (0.400% before the stall-aware initialisation)
}

// evio's simulator: the quadrotor_flight room seen from a hover (still for 1.2 s, then swaying by
// 2-3 cm and about 1 deg at 0.2-0.4 Hz: a few cm/s, a low event rate): the estimate stays within
// centimetres, never carried away by the IMU.
TEST(VioStarvation, SlowHoverStaysPut) {
  evio_test::TempDir dir;
  std::ostringstream tum;
  for (int k = 0; k <= 600; ++k) {
    const double t = 0.01 * k, s = std::max(0.0, t - 1.2);
    const double ramp = std::min(1.0, s / 0.5);  // eases in from rest
    const double yaw = ramp * 0.017 * std::sin(2 * M_PI * 0.25 * s);
    char line[200];
    std::snprintf(line, sizeof(line), "%.2f %.6f %.6f %.6f 0 0 %.9f %.9f\n", t, ramp * 0.02 * std::sin(2 * M_PI * 0.3 * s),
                  ramp * 0.03 * std::sin(2 * M_PI * 0.2 * s), 1.2 + ramp * 0.015 * std::sin(2 * M_PI * 0.4 * s), std::sin(yaw / 2),
                  std::cos(yaw / 2));
    tum << line;
  }
  const std::string traj = dir.write("hover.tum", tum.str());
  const std::string seq = simulate_scene(dir, "quadrotor_flight.yaml", 6.0, {"trajectory.path=" + traj});
  const std::string stats = run(seq, seq + "/vio", kSimulatorConfig);
  const std::string ev = evio_test::read_text(seq + "/vio/eval.json");
  const double ate = number(ev, "rmse");  // the first stats object: ate.trans_m
  std::printf("hover: ATE rmse %.4f m\n", ate);
  // Measured 0.011 m: static initialisation at 1.18 s, then 17 sparse frames (up to 0.5 s each).
  EXPECT_LT(ate, 0.015) << ev;
  EXPECT_GT(number(stats, "frames"), 12) << stats;
}

// The crosscheck simulator (skipped when it is not there): 4 s of its blank-wall variant (walls,
// floor and the box in front without texture: about 0.75 s with noise events only) and of a hover
// (3 cm/s, 4 deg/s), with the library defaults.
TEST(VioStarvation, CrosscheckBlankWallsAndHover) {
  evio_test::TempDir dir;
  const auto generate = [&](const std::string& name, const std::string& args) {
    const std::string out = dir.file(name);
    return std::pair<int, std::string>(crosscheck_generate(out, args, 4.0), out);
  };
  const std::string room =
      "'room={\"lo\": [-3.0, -2.5, 0.0], \"hi\": [3.0, 2.5, 3.0], \"faces\": {\"x-\": \"leuvenA.jpg\", \"x+\": \"blank.png\", "
      "\"y-\": \"messi5.jpg\", \"y+\": \"aero1.jpg\", \"z-\": \"blank.png\", \"z+\": \"board.jpg\"}, \"boxes\": [{\"lo\": [1.2, -0.9, 0.0], "
      "\"hi\": [1.9, -0.2, 0.8], \"texture\": \"blank.png\"}, {\"lo\": [-0.6, 1.2, 0.0], \"hi\": [0.2, 1.9, 1.1], \"texture\": "
      "\"fruits.jpg\"}, {\"lo\": [-2.0, -1.7, 0.0], \"hi\": [-1.3, -0.9, 0.6], \"texture\": \"box_in_scene.png\"}], \"texel\": 0.004}'";
  const auto [rc_blank, blank] = generate("blank", "planes_random6dof 31 --set " + room);
  if (rc_blank == 77) GTEST_SKIP() << "crosscheck simulator not available: " << evio_test::read_text(blank + ".log");
  ASSERT_EQ(rc_blank, 0) << evio_test::read_text(blank + ".log");
  const std::string sb = run(blank, blank + "/vio", "");
  const double gap = longest_event_gap_s(blank + "/events.txt", 1000);
  double longest = 0;
  for (const Span& s : imu_only(sb)) longest = std::max(longest, s.end - s.begin);
  std::printf("crosscheck blank walls: event gap %.2f s, longest IMU-only span %.2f s\n", gap, longest);
  EXPECT_GT(gap, 0.4);  // the sequence has its gap
  EXPECT_LE(longest, gap + 0.2) << sb;

  const auto [rc_hover, hover] = generate("hover", "planes_random6dof 32 --set traj.max_speed=0.03 --set traj.max_omega_deg=4");
  ASSERT_EQ(rc_hover, 0) << evio_test::read_text(hover + ".log");
  run(hover, hover + "/vio", "");
  const double ate = number(evio_test::read_text(hover + "/vio/eval.json"), "rmse");
  std::printf("crosscheck hover: ATE rmse %.4f m\n", ate);
  EXPECT_LT(ate, 0.01);  // measured 7.1 mm
}

}  // namespace
}  // namespace evio::apps
