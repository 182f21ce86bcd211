// `evio flow`: outputs on tiny synthetic ECD folders (dots moving with a constant flow; a camera
// rotating at a constant rate past points at infinity, with its ground truth), the config round
// trip, input errors, and the real ECD 10 ms window (acceptance: from zero, the flow and the
// rotation model reach the best objective a dense coarse-to-fine grid finds, within 1%).
#include "flow_command.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <random>
#include <sstream>

#include <gtest/gtest.h>

#include "evio/calib/error.h"
#include "evio/calib/geometry.h"
#include "evio/mapping/cmax.h"
#include "evio/sensors/dataset.h"
#include "evio_test/real_data.h"
#include "evio_test/temp_dir.h"
#include "evio_test/text_file.h"
#include "simulated_scene.h"

namespace evio::apps {
namespace {

namespace fs = std::filesystem;
using evio_test::json_number;
using evio_test::read_text;

std::string seconds(int64_t t_ns) {
  char b[40];
  std::snprintf(b, sizeof(b), "%lld.%09lld", static_cast<long long>(t_ns / 1'000'000'000),
                static_cast<long long>(t_ns % 1'000'000'000));
  return b;
}

// 300 dots moving at v px/s over a 240x180 sensor, one event every 20 us from a dot drawn at
// random (integer pixels, 0/1 polarity), plus a distortion-free calib.txt.
std::string flow_folder(const evio_test::TempDir& dir, const Eigen::Vector2d& v, int n) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> ux(30, 210), uy(30, 150);
  std::vector<Eigen::Vector2d> dots(300);
  for (auto& d : dots) d = {ux(rng), uy(rng)};
  std::uniform_int_distribution<size_t> pick(0, dots.size() - 1);
  std::string ev;
  for (int k = 0; k < n; ++k) {
    const int64_t t = 1'000'000'000 + static_cast<int64_t>(k) * 20'000;
    const Eigen::Vector2d p = dots[pick(rng)] + v * (static_cast<double>(k) * 20e-6);
    ev += seconds(t) + " " + std::to_string(std::lround(p.x())) + " " + std::to_string(std::lround(p.y())) + " " +
          ((k % 2) ? "1" : "0") + "\n";
  }
  dir.write("flow/events.txt", ev);
  dir.write("flow/calib.txt", "200 200 120 90 0 0 0 0 0\n");
  return dir.file("flow");
}

// A camera rotating at w (camera frame, rad/s) past 400 points at infinity: events at the rounded
// projections, one every 20 us; groundtruth.txt = T_w_c at 200 Hz; calib.txt pinhole 240x180.
std::string rotation_folder(const evio_test::TempDir& dir, const Eigen::Vector3d& w, int n) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> ux(-0.5, 0.5), uy(-0.4, 0.4);
  std::vector<Eigen::Vector3d> pts(400);
  for (auto& p : pts) p = Eigen::Vector3d(ux(rng), uy(rng), 1.0).normalized();
  std::string ev;
  const int64_t t0 = 2'000'000'000;
  for (int k = 0; k < n; ++k) {
    const double s = static_cast<double>(k) * 20e-6;
    const Eigen::Vector3d b = calib::so3_exp(w * s).transpose() * pts[static_cast<size_t>(k) % pts.size()];
    const double x = 120 + 200 * b.x() / b.z(), y = 90 + 200 * b.y() / b.z();
    if (b.z() <= 0 || x < 0 || y < 0 || x > 239 || y > 179) continue;
    ev += seconds(t0 + static_cast<int64_t>(k) * 20'000) + " " + std::to_string(std::lround(x)) + " " +
          std::to_string(std::lround(y)) + " 1\n";
  }
  std::string gt;
  for (int64_t t = -20'000'000; t <= static_cast<int64_t>(n) * 20'000 + 20'000'000; t += 5'000'000) {
    const Eigen::Quaterniond q(calib::so3_exp(w * (static_cast<double>(t) * 1e-9)));
    gt += seconds(t0 + t) + " 0 0 0 " + std::to_string(q.x()) + " " + std::to_string(q.y()) + " " + std::to_string(q.z()) +
          " " + std::to_string(q.w()) + "\n";
  }
  dir.write("rot/events.txt", ev);
  dir.write("rot/groundtruth.txt", gt);
  dir.write("rot/calib.txt", "200 200 120 90 0 0 0 0 0\n");
  return dir.file("rot");
}

std::vector<std::vector<std::string>> csv_rows(const std::string& text) {
  std::vector<std::vector<std::string>> rows;
  std::istringstream in(text);
  std::string line;
  std::getline(in, line);  // header
  while (std::getline(in, line)) {
    std::vector<std::string> cells;
    std::istringstream l(line);
    for (std::string c; std::getline(l, c, ',');) cells.push_back(c);
    rows.push_back(cells);
  }
  return rows;
}

std::string first_line(const std::string& text) { return text.substr(0, text.find('\n')); }

TEST(FlowCommand, FlowModelOutputs) {
  evio_test::TempDir dir;
  const Eigen::Vector2d v(250, -120);
  FlowArgs a;
  a.dataset = flow_folder(dir, v, 9000);
  a.out = dir.file("out");
  a.model = "flow";
  a.window_events = 2000;
  a.set = {"window.max_duration_ms=0"};  // 2000 events span 40 ms here
  a.png = true;
  a.png_every = 2;
  a.progress = false;
  std::ostringstream out;
  ASSERT_EQ(run_flow(a, out), 0);
  const std::string csv = read_text(a.out + "/motion.csv");
  EXPECT_EQ(first_line(csv), "t_start_s,t_end_s,model,p0,p1,contrast_zero,contrast_final,iterations,time_ms");
  const auto rows = csv_rows(csv);
  ASSERT_EQ(rows.size(), 5u);  // 4 windows of 2000 events and the last 1000
  for (const auto& r : rows) {
    ASSERT_EQ(r.size(), 9u);
    EXPECT_EQ(r[2], "flow");
    EXPECT_NEAR(std::stod(r[3]), v.x(), 6.0);
    EXPECT_NEAR(std::stod(r[4]), v.y(), 6.0);
    EXPECT_GT(std::stod(r[6]), std::stod(r[5]));
    EXPECT_GE(std::stoi(r[7]), 1);
  }
  EXPECT_EQ(rows[0][0], "1.000000000");
  EXPECT_EQ(rows[0][1], "1.039980000");  // the window's last event
  const std::string stats = read_text(a.out + "/stats.json");
  EXPECT_EQ(json_number(stats, "events"), 9000);
  EXPECT_EQ(json_number(stats, "windows"), 5);
  EXPECT_EQ(json_number(stats, "warm_starts"), 4);
  EXPECT_GT(json_number(stats, "time_per_event_us"), 0);
  EXPECT_GT(json_number(stats, "iterations"), 0);
  EXPECT_GT(json_number(stats, "mean"), 0);  // time per window
  EXPECT_NE(stats.find("\"objective\": \"variance\""), std::string::npos) << stats;
  EXPECT_NE(stats.find("\"parameters\": [\"vx_pxps\", \"vy_pxps\"]"), std::string::npos);
  EXPECT_NE(stats.find("\"used\": \"none\""), std::string::npos);  // no distortion: as is
  EXPECT_EQ(json_number(stats, "pngs"), 6);
  EXPECT_TRUE(fs::exists(a.out + "/iwe/window_000000_before.png"));
  EXPECT_TRUE(fs::exists(a.out + "/iwe/window_000004_after.png"));
  EXPECT_FALSE(fs::exists(a.out + "/iwe/window_000001_after.png"));
  EXPECT_FALSE(fs::exists(a.out + "/motion_eval.csv"));
  // The resolved config reads back to the same text, with the camera's pinhole and the flags.
  const std::string cfg = read_text(a.out + "/flow_config.yaml");
  EXPECT_NE(cfg.find("events: 2000"), std::string::npos) << cfg;
  EXPECT_EQ(flow_config_text(load_flow_config(a.out + "/flow_config.yaml")), cfg);
  EXPECT_NE(out.str().find("wrote"), std::string::npos);
}

TEST(FlowCommand, TimeWindowsAndTimeSpan) {
  evio_test::TempDir dir;
  FlowArgs a;
  a.dataset = flow_folder(dir, Eigen::Vector2d(100, 0), 9000);  // 1.0 .. 1.18 s
  a.out = dir.file("out");
  a.window_ns = 50'000'000;
  a.t_start_ns = 1'020'000'000;
  a.t_end_ns = 1'150'000'000;
  a.progress = false;
  std::ostringstream out;
  ASSERT_EQ(run_flow(a, out), 0);
  const auto rows = csv_rows(read_text(a.out + "/motion.csv"));
  ASSERT_EQ(rows.size(), 3u);  // [1.02, 1.07), [1.07, 1.12), [1.12, last event]
  EXPECT_EQ(rows[0][0], "1.020000000");
  EXPECT_EQ(rows[0][1], "1.070000000");
  EXPECT_EQ(rows[2][1], "1.149980000");
  EXPECT_EQ(json_number(read_text(a.out + "/stats.json"), "events"), 6500);
}

TEST(FlowCommand, RotationWithGroundTruth) {
  evio_test::TempDir dir;
  const Eigen::Vector3d w(0.6, -1.1, 0.9);
  FlowArgs a;
  a.dataset = rotation_folder(dir, w, 12000);
  a.out = dir.file("out");
  a.model = "rotation";
  a.window_events = 3000;
  a.set = {"window.max_duration_ms=0"};  // 3000 events span 60 ms here
  a.progress = false;
  std::ostringstream out;
  ASSERT_EQ(run_flow(a, out), 0);
  const std::string csv = read_text(a.out + "/motion.csv");
  EXPECT_EQ(first_line(csv), "t_start_s,t_end_s,model,p0,p1,p2,contrast_zero,contrast_final,iterations,time_ms");
  const std::string eval = read_text(a.out + "/motion_eval.csv");
  EXPECT_EQ(first_line(eval), "t_start_s,t_end_s,wx_radps,wy_radps,wz_radps,gt_wx_radps,gt_wy_radps,gt_wz_radps,error_degps");
  EXPECT_EQ(eval.find("nan"), std::string::npos) << "a window without a reference has empty fields, not nan";
  const auto rows = csv_rows(eval);
  ASSERT_GE(rows.size(), 3u);
  for (const auto& r : rows) {
    EXPECT_NEAR(std::stod(r[5]), w.x(), 1e-3);  // the ground truth's rate, camera frame
    EXPECT_NEAR(std::stod(r[6]), w.y(), 1e-3);
    EXPECT_NEAR(std::stod(r[7]), w.z(), 1e-3);
  }
  const std::string stats = read_text(a.out + "/stats.json");
  EXPECT_LT(json_number(stats, "rms_error_degps"), 3.0) << stats;
  EXPECT_NEAR(json_number(stats, "groundtruth_rms_degps"), w.norm() * 180 / M_PI, 0.1);
  EXPECT_NE(stats.find("no camera-IMU extrinsics"), std::string::npos);
  EXPECT_NE(out.str().find("angular velocity error RMS"), std::string::npos);
}

TEST(FlowCommand, InputErrors) {
  evio_test::TempDir dir;
  FlowArgs a;
  a.dataset = flow_folder(dir, Eigen::Vector2d(100, 0), 500);
  a.out = dir.file("out");
  a.progress = false;
  std::ostringstream out;
  {
    FlowArgs b = a;
    b.t_start_ns = 2'000'000'000;
    b.t_end_ns = 1'000'000'000;
    EXPECT_THROW(run_flow(b, out), InputError);
  }
  {
    FlowArgs b = a;
    b.set = {"window.events=0"};
    try {
      run_flow(b, out);
      ADD_FAILURE() << "no error";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("window.events"), std::string::npos) << e.what();
    }
  }
  {
    FlowArgs b = a;
    b.set = {"cmax.fx=300"};  // the camera's, not a key
    EXPECT_THROW(run_flow(b, out), InputError);
  }
  {
    FlowArgs b = a;
    b.model = "spin";
    EXPECT_THROW(run_flow(b, out), InputError);
  }
  {
    // The rotation model without a calibration (a bare events file with --sensor).
    FlowArgs b = a;
    b.dataset = a.dataset + "/events.txt";
    b.dataset_options.text.sensor = {240, 180};
    b.model = "rotation";
    try {
      run_flow(b, out);
      ADD_FAILURE() << "no error";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("no camera calibration"), std::string::npos) << e.what();
    }
  }
}

// ---- the real ECD 10 ms window ---------------------------------------------------------------

struct RealWindow {
  mapping::CmaxEvents events;
  mapping::CmaxOptions options;
};

// The window as `evio flow` builds it (one window: all events, warped to the middle of the first
// and last stamps), with the command's default maximiser options on the dataset's camera.
RealWindow real_window(const std::string& dir, mapping::WarpModel model) {
  auto reader = open_dataset(dir);
  std::vector<SubpixelEvent> ev;
  while (reader->read_subpixel_events(&ev, 1 << 16) > 0) {
  }
  const auto cal = reader->read_calibration();
  EXPECT_TRUE(cal);
  mapping::CmaxOptions o = FlowConfig{}.cmax;
  o.model = model;
  o.width = cal->camera.width();
  o.height = cal->camera.height();
  const auto& k = cal->camera.intrinsics();
  o.geometry.fx = k.fx, o.geometry.fy = k.fy, o.geometry.cx = k.cx, o.geometry.cy = k.cy;
  const int64_t t_ref = ev.front().t_ns + (ev.back().t_ns - ev.front().t_ns) / 2;
  RealWindow w{mapping::CmaxEvents(t_ref, o.geometry), o};
  for (const SubpixelEvent& e : ev) w.events.push_back(e.x, e.y, e.t_ns, e.polarity);
  return w;
}

// Coarse-to-fine grid maximum of the level-0 objective: a full grid of `steps` per axis over
// +-range around zero, then twice a grid of +-2 steps at a fifth of the step around the best.
double grid_best(mapping::ContrastMaximizer& m, const mapping::CmaxEvents& ev, int dof, double range, int steps,
                 Eigen::VectorXd* best_p) {
  double best = -1;
  Eigen::VectorXd best_at = Eigen::VectorXd::Zero(dof);
  auto search = [&](const Eigen::VectorXd& centre, double half, int n) {
    const double step = 2 * half / (n - 1);
    Eigen::VectorXi idx = Eigen::VectorXi::Zero(dof);
    const Eigen::VectorXd c = centre;
    for (;;) {
      Eigen::VectorXd p(dof);
      for (int d = 0; d < dof; ++d) p[d] = c[d] - half + step * idx[d];
      const double f = m.objective(ev, p, 0);
      if (f > best) {
        best = f;
        best_at = p;
      }
      int d = 0;
      while (d < dof && ++idx[d] == n) idx[d++] = 0;
      if (d == dof) break;
    }
    return step;
  };
  double step = search(Eigen::VectorXd::Zero(dof), range, steps);
  for (int r = 0; r < 3; ++r) step = search(best_at, 2 * step, 11);
  *best_p = best_at;
  return best;
}

void real_window_reaches_grid_optimum(const std::string& model, double range, int steps) {
  const auto dir = evio_test::real_data_dir("ecd_dynamic_10ms");
  if (!dir) GTEST_SKIP() << "real data ecd_dynamic_10ms not found ($EVIO_REAL_DATA or ../shared/data/real)";
  evio_test::TempDir tmp;
  FlowArgs a;
  a.dataset = *dir;
  a.out = tmp.file("out");
  a.model = model;
  a.window_events = 1'000'000;  // one window: the whole file
  a.progress = false;
  std::ostringstream out;
  ASSERT_EQ(run_flow(a, out), 0);
  const auto rows = csv_rows(read_text(a.out + "/motion.csv"));
  ASSERT_EQ(rows.size(), 1u);
  const auto& r = rows[0];
  const std::string stats = read_text(a.out + "/stats.json");
  EXPECT_NE(stats.find("\"used\": \"none\""), std::string::npos) << "sub-pixel input is used as it is: " << stats;
  const mapping::WarpModel m = *mapping::warp_model_from_name(model);
  const int dof = mapping::warp_dof(m);
  ASSERT_EQ(static_cast<int>(r.size()), 3 + dof + 4);
  Eigen::VectorXd p(dof);
  for (int d = 0; d < dof; ++d) p[d] = std::stod(r[static_cast<size_t>(3 + d)]);
  const double zero = std::stod(r[static_cast<size_t>(3 + dof)]), final_value = std::stod(r[static_cast<size_t>(4 + dof)]);

  RealWindow w = real_window(*dir, m);
  EXPECT_EQ(static_cast<double>(w.events.size()), json_number(stats, "events_used"));
  mapping::ContrastMaximizer cm(w.options);
  EXPECT_NEAR(cm.objective(w.events, p, 0), final_value, 1e-6 * final_value);  // the csv's value is the objective at p
  const auto t0 = std::chrono::steady_clock::now();
  Eigen::VectorXd best_p;
  const double best = grid_best(cm, w.events, dof, range, steps, &best_p);
  const double grid_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::ostringstream msg;
  msg << "ECD 10 ms window, " << model << ": from zero " << p.transpose() << " objective " << final_value << " (zero "
      << zero << "); grid best " << best << " at " << best_p.transpose() << " (" << grid_s << " s); ratio "
      << final_value / best << "\n";
  std::fputs(msg.str().c_str(), stdout);
  EXPECT_GT(final_value, zero * 1.05);  // it moved from zero
  EXPECT_GE(final_value, 0.99 * best);
}

TEST(FlowCommandReal, EcdWindowFlowReachesTheGridOptimum) { real_window_reaches_grid_optimum("flow", 1500, 61); }

TEST(FlowCommandReal, EcdWindowRotationReachesTheGridOptimum) { real_window_reaches_grid_optimum("rotation", 10, 21); }

// --model auto on simulated scenes whose right model is known (datasets/, 1 s each, calibrated:
// candidates flow, rotation, similarity): windows won per model, from model_selection.csv, which
// must agree with stats.json's model block.
std::map<std::string, int> auto_model_wins(const std::string& scene, double duration_s, std::string* stats) {
  evio_test::TempDir dir;
  FlowArgs a;
  a.dataset = simulate_scene(dir, scene, duration_s);
  a.out = dir.file("out");
  a.model = "auto";
  a.progress = false;
  std::ostringstream out;
  EXPECT_EQ(run_flow(a, out), 0);
  std::printf("%s: %s", scene.c_str(), out.str().c_str());
  *stats = read_text(a.out + "/stats.json");
  const std::string cfg = read_text(a.out + "/flow_config.yaml");  // reads back, selection on
  EXPECT_NE(cfg.find("model_selection: true"), std::string::npos) << cfg;
  EXPECT_EQ(flow_config_text(load_flow_config(a.out + "/flow_config.yaml")), cfg);
  const std::string csv = read_text(a.out + "/model_selection.csv");
  EXPECT_EQ(first_line(csv), "t_start_s,t_end_s,chosen,flow_objective,flow_gain,flow_score,rotation_objective,rotation_gain,"
                             "rotation_score,similarity_objective,similarity_gain,similarity_score");
  std::map<std::string, int> wins;
  for (const auto& r : csv_rows(csv)) {
    EXPECT_EQ(r.size(), 12u);
    ++wins[r[2]];
  }
  for (const auto& [m, n] : wins)
    EXPECT_NE(stats->find("{\"model\": \"" + m + "\", \"parameters\": " +
                          std::to_string(mapping::warp_dof(*mapping::warp_model_from_name(m))) + ", \"windows_chosen\": " +
                          std::to_string(n)),
              std::string::npos) << *stats;
  EXPECT_NE(stats->find("\"selection\": \"auto\""), std::string::npos);
  EXPECT_NE(stats->find("\"objective\": \"normalized_gradient_magnitude\""), std::string::npos);
  return wins;
}

int total(const std::map<std::string, int>& wins) {
  int n = 0;
  for (const auto& [m, k] : wins) n += k;
  return n;
}

TEST(FlowCommandModel, AutoPicksFlowOnPlanarTranslation) {
  std::string stats;
  const auto wins = auto_model_wins("poster_translation.yaml", 1.0, &stats);
  const int n = total(wins);
  ASSERT_GT(n, 5);
  const double flow = wins.count("flow") ? wins.at("flow") : 0;
  EXPECT_GE(flow / n, 0.9) << stats;  // measured 40 of 40 windows (rotation and similarity gains below 0.001)
  EXPECT_NE(stats.find("\"chosen\": \"flow\""), std::string::npos) << stats;
}

TEST(FlowCommandModel, AutoPicksRotationOnPureRotation) {
  std::string stats;
  const auto wins = auto_model_wins("poster_rotation.yaml", 1.0, &stats);
  const int n = total(wins);
  ASSERT_GT(n, 5);
  const double rot = wins.count("rotation") ? wins.at("rotation") : 0;
  EXPECT_GE(rot / n, 0.9) << stats;  // measured 40 of 40 windows (rotation gain 0.07-0.12 over flow, above similarity's)
  EXPECT_NE(stats.find("\"chosen\": \"rotation\""), std::string::npos) << stats;
}

}  // namespace
}  // namespace evio::apps
