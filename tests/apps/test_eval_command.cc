#include "eval_command.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>

#include <gtest/gtest.h>

#include "evio/calib/error.h"
#include "evio_test/temp_dir.h"

namespace evio::apps {
namespace {

// A circle of radius 2 m in the x-y plane at 1 m height, 100 poses over 10 s, yaw along the path.
std::string circle_tum(const Eigen::Vector3d& offset, int n = 100) {
  std::string s = "# t x y z qx qy qz qw\n";
  for (int i = 0; i < n; ++i) {
    const double a = 2 * M_PI * i / n;
    const double yaw = a + M_PI / 2;
    char line[256];
    std::snprintf(line, sizeof(line), "%d.%01d %.17g %.17g %.17g 0 0 %.17g %.17g\n", i / 10, i % 10,
                  2 * std::cos(a) + offset.x(), 2 * std::sin(a) + offset.y(), 1.0 + offset.z(), std::sin(yaw / 2),
                  std::cos(yaw / 2));
    s += line;
  }
  return s;
}

std::string read(const std::string& path) {
  std::ifstream f(path);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

// Value of "key": NUMBER after the first occurrence of `after` at or after `from` in json.
double json_number(const std::string& json, const std::string& after, const std::string& key, size_t from = 0) {
  const size_t a = json.find(after, from);
  if (a == std::string::npos) return std::nan("");
  const size_t k = json.find("\"" + key + "\": ", a);
  if (k == std::string::npos) return std::nan("");
  return std::strtod(json.c_str() + k + key.size() + 4, nullptr);
}

TEST(EvalCommand, ConstantOffsetWithoutAlignmentGivesItsNormEverywhere) {
  evio_test::TempDir dir;
  EvalArgs args;
  args.groundtruth = dir.write("gt.tum", circle_tum(Eigen::Vector3d::Zero()));
  args.estimates = {dir.write("est.tum", circle_tum(Eigen::Vector3d(0.3, 0, 0.4)))};
  args.options.alignment.method = evaluation::Alignment::kNone;
  args.out = dir.file("out");
  std::ostringstream table;
  ASSERT_EQ(run_eval(args, table), 0);
  const std::string j = read(dir.file("out/results.json"));
  for (const char* key : {"\"estimates\": [", "\"file\": ", "\"align\": \"none\"", "\"matched_poses\": 100",
                          "\"ate\": {\"trans_m\": {\"rmse\": ", "\"rot_deg\": {\"rmse\": ", "\"median\": ",
                          "\"std\": ", "\"min\": ", "\"max\": ", "\"mean_position_error_percent\": ",
                          "\"rpe\": [", "\"length_m\": ", "\"trans_percent\": {", "\"yaw_deg_per_m\": {",
                          "\"alignment\": {\"rotation\": [[", "\"translation\": [", "\"scale\": ", "\"protocol\": "}) {
    EXPECT_NE(j.find(key), std::string::npos) << key << "\n" << j;
  }
  EXPECT_DOUBLE_EQ(json_number(j, "\"trans_m\"", "rmse"), 0.5);
  EXPECT_DOUBLE_EQ(json_number(j, "\"trans_m\"", "max"), 0.5);
  EXPECT_NEAR(json_number(j, "\"trans_m\"", "std"), 0.0, 1e-12);
  EXPECT_NEAR(json_number(j, "\"rot_deg\"", "max"), 0.0, 1e-6);
  // Mean error 0.5 m over the matched path (99 chords of the circle).
  const double path = 99 * 2 * 2 * std::sin(M_PI / 100);
  EXPECT_NEAR(json_number(j, "\"ate\"", "mean_position_error_percent"), 100 * 0.5 / path, 1e-9);
  // A constant translation leaves every relative motion exact.
  EXPECT_NEAR(json_number(j, "\"rpe\": [", "max"), 0.0, 1e-9);
  EXPECT_NEAR(json_number(j, "\"trans_m\"", "max", j.find("\"rpe\": [")), 0.0, 1e-12);
  EXPECT_DOUBLE_EQ(json_number(j, "\"alignment\"", "scale"), 1.0);
  // The table has one row with the file as label, 100 matched poses and the 0.5 m ATE.
  EXPECT_TRUE(std::regex_search(table.str(), std::regex("est.tum +100 +0.5000 +0.5000 +0.5000"))) << table.str();
  // Aligned estimate and matched ground truth as TUM, errors as csv.
  EXPECT_TRUE(std::filesystem::exists(dir.file("out/est0_est_aligned.tum")));
  EXPECT_TRUE(std::filesystem::exists(dir.file("out/est0_est_groundtruth.tum")));
  const std::string csv = read(dir.file("out/est0_est_errors.csv"));
  const std::string header = "# t [s], trans_error [m], rot_error [deg]\n0.000000000,";
  ASSERT_EQ(csv.rfind(header, 0), 0u) << csv.substr(0, 200);
  EXPECT_NEAR(std::strtod(csv.c_str() + header.size(), nullptr), 0.5, 1e-12) << csv.substr(0, 200);
}

TEST(EvalCommand, Se3AlignmentRecoversTheOffset) {
  evio_test::TempDir dir;
  EvalArgs args;
  args.groundtruth = dir.write("gt.tum", circle_tum(Eigen::Vector3d::Zero()));
  args.estimates = {dir.write("est.tum", circle_tum(Eigen::Vector3d(0.3, -0.2, 0.4)))};
  const auto r = evaluate_all(args);
  ASSERT_EQ(r.size(), 1u);
  EXPECT_NEAR(r[0].result.ate.trans_m.rmse, 0.0, 1e-9);
  EXPECT_NEAR(r[0].result.alignment.translation.x(), -0.3, 1e-9);
  EXPECT_NEAR(r[0].result.alignment.translation.y(), 0.2, 1e-9);
  EXPECT_NEAR(r[0].result.alignment.translation.z(), -0.4, 1e-9);
  EXPECT_EQ(r[0].label, args.estimates[0]);
  EXPECT_EQ(r[0].name, "est0_est");
}

EstimateEvaluation fake(const std::string& label, double ate_rmse, double mpe) {
  EstimateEvaluation e;
  e.label = label;
  e.result.ate.trans_m.rmse = ate_rmse;
  e.result.mean_position_error_percent = mpe;
  evaluation::RelativeError q;
  q.count = 3;
  q.trans_percent.mean = 2 * mpe;
  e.result.rpe = {q};
  return e;
}

TEST(EvalCommand, SummaryOverRunsOfOneLabel) {
  const std::vector<EstimateEvaluation> runs = {fake("ours", 0.1, 1.0), fake("ours", 0.4, 3.0),
                                                fake("ours", 0.2, 2.0), fake("theirs_v2", 1.0, 5.0)};
  const auto rows = summarize(runs);
  ASSERT_EQ(rows.size(), 10u);  // 2 labels x 5 metrics
  EXPECT_EQ(rows[0].label, "ours");
  EXPECT_EQ(rows[0].metric, "ate_trans_rmse_m");
  EXPECT_EQ(rows[0].runs, 3u);
  EXPECT_NEAR(rows[0].mean, 0.7 / 3, 1e-15);
  EXPECT_DOUBLE_EQ(rows[0].median, 0.2);
  EXPECT_DOUBLE_EQ(rows[0].min, 0.1);
  EXPECT_DOUBLE_EQ(rows[0].max, 0.4);
  EXPECT_EQ(rows[3].metric, "rpe_trans_percent_mean");
  EXPECT_DOUBLE_EQ(rows[3].median, 4.0);
  EXPECT_EQ(rows[5].label, "theirs_v2");
  EXPECT_EQ(rows[5].runs, 1u);

  const std::string csv = summary_csv(rows);
  EXPECT_EQ(csv.rfind("label,metric,runs,mean,median,min,max\nours,ate_trans_rmse_m,3,", 0), 0u) << csv;
  EXPECT_NE(csv.find("ours,mean_position_error_percent,3,2,2,1,3\n"), std::string::npos) << csv;
  const std::string yaml = summary_yaml(rows);
  EXPECT_NE(yaml.find("  \"theirs_v2\":\n    ate_trans_rmse_m: {runs: 1, mean: 1, median: 1, min: 1, max: 1}"),
            std::string::npos) << yaml;
  const std::string json = summary_json(rows);
  EXPECT_NE(json.find("{\"label\": \"ours\", \"metrics\": {\"ate_trans_rmse_m\": {\"runs\": 3,"), std::string::npos)
      << json;
  // LaTeX: one row per label, the mean of each metric, '_' escaped; "--" for a metric no run
  // reports (yaw drift: NaN, these results have no path length).
  const std::string tex = summary_latex(rows);
  EXPECT_NE(tex.find("\nours & 0.233 & 0.000 & 2.000 & 4.000 & -- \\\\\n"), std::string::npos) << tex;
  EXPECT_NE(tex.find("\ntheirs\\_v2 & 1.000 & 0.000 & 5.000 & 10.000 & -- \\\\\n"), std::string::npos) << tex;
}

TEST(EvalCommand, LabelsGroupRunsAndMustMatchTheEstimates) {
  evio_test::TempDir dir;
  EvalArgs args;
  args.groundtruth = dir.write("gt.tum", circle_tum(Eigen::Vector3d::Zero()));
  args.estimates = {dir.write("a.tum", circle_tum(Eigen::Vector3d(0.1, 0, 0))),
                    dir.write("b.tum", circle_tum(Eigen::Vector3d(0.3, 0, 0)))};
  args.options.alignment.method = evaluation::Alignment::kNone;
  args.labels = {"m"};
  EXPECT_THROW(evaluate_all(args), InputError);
  args.labels = {"m", "m"};
  const auto rows = summarize(evaluate_all(args));
  ASSERT_EQ(rows.size(), 5u);
  EXPECT_EQ(rows[0].runs, 2u);
  EXPECT_NEAR(rows[0].mean, 0.2, 1e-12);
  EXPECT_NEAR(rows[0].min, 0.1, 1e-12);
  EXPECT_NEAR(rows[0].max, 0.3, 1e-12);
}

TEST(EvalCommand, ReadsCsvGroundTruthByContent) {
  evio_test::TempDir dir;
  std::string csv = "#timestamp [ns], x, y, z, qx, qy, qz, qw\n";
  for (int i = 0; i < 20; ++i) {
    csv += std::to_string(int64_t{i} * 100000000) + "," + std::to_string(0.1 * i) + ",0,0,0,0,0,1\n";
  }
  const Trajectory t = read_trajectory(dir.write("gt.txt", csv));
  ASSERT_EQ(t.size(), 20u);
  EXPECT_EQ(t[19].t_ns, 1900000000);
  EXPECT_NEAR(t.path_length_m(), 1.9, 1e-12);
}

TEST(EvalCommand, BadInputIsAnInputError) {
  evio_test::TempDir dir;
  const std::string gt = dir.write("gt.tum", circle_tum(Eigen::Vector3d::Zero()));
  auto fails = [&](const std::string& text, const std::string& expect) {
    EvalArgs args;
    args.groundtruth = gt;
    args.estimates = {dir.write("bad.tum", text)};
    try {
      evaluate_all(args);
      ADD_FAILURE() << "no error for " << text;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(expect), std::string::npos) << e.what();
    }
  };
  fails("", "no poses");
  fails("# only a comment\n", "no poses");
  fails("1.0 0 0 0 0 0 0 1\n", "only 1 pose");
  fails("1.0 0 0 0 0 0 0 1\n0.5 0 0 0 0 0 0 1\n", "not after the previous");
  fails("1.0 0 0 0 0 0 0 1\n1.5 nan 0 0 0 0 0 1\n", "bad.tum:2");
  fails("1.0 0 0 0 0 0 0 1\n1.5 0 0 0 0 0 1\n", "expected 8 columns, found 7");
  fails("1.0 0 0 0 0 0 0 1\n1.5 0 0 0 0 0 0 2\n", "quaternion norm");
  // Stamps in ns against a ground truth in s: nothing associates, and the message says why.
  fails("1000000000.0 0 0 0 0 0 0 1\n1100000000.0 0 0 0 0 0 0 1\n1200000000.0 0 0 0 0 0 0 1\n", "bad.tum");
}

}  // namespace
}  // namespace evio::apps
