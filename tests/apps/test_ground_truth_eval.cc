// Ground-truth scoring of `evio corners`, `evio reconstruct` and `evio segment` on short simulated
// folders (evio simulate): eval.json appears by itself next to the outputs (the folder's
// scene_resolved.yaml / event_labels.txt), with values in the measured ranges, and not with --no-gt.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "corners_command.h"
#include "evio/calib/error.h"
#include "evio_test/temp_dir.h"
#include "evio_test/text_file.h"
#include "reconstruct_command.h"
#include "segment_command.h"
#include "simulated_scene.h"

namespace evio::apps {
namespace {

namespace fs = std::filesystem;
using evio_test::json_number;
using evio_test::read_text;

TEST(GroundTruthEval, CornersAndReconstructOnTheCheckerboard) {
  evio_test::TempDir dir;
  const std::string seq = simulate_scene(dir, "checkerboard_6dof.yaml", 1.0);
  {
    CornersArgs a;
    a.dataset = seq;
    a.out = dir.file("corners");
    a.progress = false;
    std::ostringstream out;
    ASSERT_EQ(run_corners(a, out), 0);
    std::printf("%s", out.str().c_str());
    const std::string ev = read_text(a.out + "/eval.json");
    ASSERT_FALSE(ev.empty()) << out.str();
    EXPECT_EQ(json_number(ev, "true_corners"), 30);  // the 6 x 5 grid nodes
    const double p = json_number(ev, "precision"), chance = json_number(ev, "chance"),
                 r = json_number(ev, "pair_recall"), f = json_number(ev, "f_score");
    // Measured: precision 0.751 (tests/frontend's board, eFAST: 0.764), chance 0.089, pair recall
    // 0.943, F 0.836.
    EXPECT_GT(p, 0.68);
    EXPECT_LT(p, 0.82);
    EXPECT_GT(p, 5 * chance);
    EXPECT_GT(r, 0.88);
    EXPECT_NEAR(f, 2 * p * r / (p + r), 1e-6);
    EXPECT_NEAR(json_number(ev, "f_error"), 1 - f, 1e-9);
    const std::string stats = read_text(a.out + "/stats.json");
    EXPECT_EQ(json_number(ev, "corner_events"), json_number(stats, "corners"));
    EXPECT_EQ(json_number(ev, "events"), json_number(stats, "events"));
    a.out = dir.file("corners_no_gt");
    a.no_gt = true;
    ASSERT_EQ(run_corners(a, out), 0);
    EXPECT_FALSE(fs::exists(a.out + "/eval.json"));
  }
  {
    ReconstructArgs a;
    a.dataset = seq;
    a.out = dir.file("reconstruct");
    a.method = "cf";
    a.rate_hz = 10;
    a.progress = false;
    std::ostringstream out;
    ASSERT_EQ(run_reconstruct(a, out), 0);
    std::printf("%s", out.str().c_str());
    const std::string ev = read_text(a.out + "/eval.json");
    ASSERT_FALSE(ev.empty()) << out.str();
    // 10 images at 0.1 s steps from the first event, every one scored (none is flat: the first
    // holds the first event).
    EXPECT_EQ(json_number(ev, "images_scored"), 10);
    EXPECT_EQ(json_number(ev, "images_unscored"), 0);
    EXPECT_EQ(json_number(read_text(a.out + "/stats.json"), "images"), 10);
    const double ssim = json_number(ev, "ssim"), psnr = json_number(ev, "psnr_db");
    // Measured: PSNR 12.79 dB, SSIM 0.479 (the first image, one event in: 8.13 dB).
    EXPECT_GT(ssim, 0.42);
    EXPECT_LT(ssim, 0.54);
    EXPECT_GT(psnr, 11.0);
    EXPECT_LT(psnr, 14.5);
    EXPECT_NEAR(json_number(ev, "ssim_error"), 1 - ssim, 1e-9);
    EXPECT_LE(json_number(ev, "ssim_min"), ssim);
  }
}

// With output.clock_offset_ns the written stamps sit at 1.7e18 ns: the scoring maps them back to the
// simulator's time, so corners and reconstruct score as without the offset (before the fix, reconstruct
// stopped with "SplineTrajectory::evaluate: t_ns 1700000000000005748 outside [0, ...]").
TEST(GroundTruthEval, ClockOffsetStampsScoreAsWithout) {
  evio_test::TempDir plain_dir, offset_dir;
  const std::string plain = simulate_scene(plain_dir, "checkerboard_6dof.yaml", 0.3);
  const std::string offset = simulate_scene(offset_dir, "checkerboard_6dof.yaml", 0.3, {"output.clock_offset_ns=1700000000000000000"});
  std::map<std::string, double> got[2];
  for (int k = 0; k < 2; ++k) {
    const std::string seq = k == 0 ? plain : offset;
    const evio_test::TempDir& dir = k == 0 ? plain_dir : offset_dir;
    CornersArgs c;
    c.dataset = seq;
    c.out = dir.file("corners");
    c.progress = false;
    std::ostringstream out;
    ASSERT_EQ(run_corners(c, out), 0);
    const std::string ce = read_text(c.out + "/eval.json");
    ASSERT_FALSE(ce.empty()) << out.str();
    for (const char* key : {"precision", "pair_recall", "corner_events"}) got[k][key] = json_number(ce, key);
    ReconstructArgs r;
    r.dataset = seq;
    r.out = dir.file("reconstruct");
    r.method = "cf";
    r.rate_hz = 10;
    r.progress = false;
    ASSERT_EQ(run_reconstruct(r, out), 0);
    const std::string re = read_text(r.out + "/eval.json");
    ASSERT_FALSE(re.empty()) << out.str();
    for (const char* key : {"ssim", "psnr_db", "images_scored"}) got[k][key] = json_number(re, key);
  }
  EXPECT_GT(got[0]["corner_events"], 100);
  EXPECT_GT(got[0]["images_scored"], 1);
  for (const auto& [key, v] : got[0]) {
    // Equal but for float rounding of the filters' time base (measured: equal to the printed digits).
    EXPECT_NEAR(got[1][key], v, 1e-3 * std::max(1.0, std::abs(v))) << key;
  }
}

// Labels of a file with one integer per line.
std::vector<long> read_ints(const std::string& path, int column) {
  std::ifstream f(path);
  std::vector<long> v;
  std::string line;
  while (std::getline(f, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream in(line);
    std::string w;
    for (int c = 0; c <= column; ++c) in >> w;
    v.push_back(std::stol(w));
  }
  return v;
}

TEST(GroundTruthEval, SegmentOnThreeObjects) {
  evio_test::TempDir dir;
  const std::string seq = simulate_scene(dir, "dynamic_3objects.yaml", 0.5, {"ground_truth.period_s=0"});
  SegmentArgs a;
  a.dataset = seq;
  a.out = dir.file("segment");
  a.png = false;
  a.progress = false;
  std::ostringstream out;
  ASSERT_EQ(run_segment(a, out), 0);
  std::printf("%s", out.str().c_str());
  const std::string ev = read_text(a.out + "/eval.json");
  ASSERT_FALSE(ev.empty()) << out.str();
  const double acc = json_number(ev, "accuracy"), in_windows = json_number(ev, "accuracy_in_windows");
  // Measured: accuracy 0.933 over 272,446 events, all inside the 5 segmented windows (background
  // 0.29, objects 1.00, 0.49 and 0.996).
  EXPECT_GT(acc, 0.88);
  EXPECT_GE(in_windows, acc);
  EXPECT_NEAR(json_number(ev, "label_error"), 1 - acc, 1e-9);
  // Independent check: one mapping of clusters to objects for the whole run (majority over all
  // windows) can only do as well as the per-window mappings, never better.
  const std::vector<long> pred = read_ints(a.out + "/labels.txt", 4), truth = read_ints(seq + "/event_labels.txt", 0);
  ASSERT_EQ(pred.size(), truth.size());
  std::map<long, std::map<long, long>> votes;
  long scored = 0;
  for (size_t k = 0; k < pred.size(); ++k) {
    if (truth[k] == 65535) continue;
    ++scored;
    if (pred[k] >= 0) ++votes[pred[k]][truth[k]];
  }
  long global_correct = 0;
  for (const auto& [c, v] : votes) {
    long most = 0;
    for (const auto& [l, n] : v) most = std::max(most, n);
    global_correct += most;
  }
  EXPECT_EQ(json_number(ev, "events_scored"), scored);
  EXPECT_GE(acc + 1e-12, static_cast<double>(global_correct) / static_cast<double>(scored));
  // Labels of another length are an error naming the file.
  std::ofstream(seq + "/short_labels.txt") << "0\n1\n";
  a.gt = seq + "/short_labels.txt";
  a.out = dir.file("segment_short");
  EXPECT_THROW(run_segment(a, out), InputError);
}

}  // namespace
}  // namespace evio::apps
