// evio::sweep results (results.h): an algorithm's metrics from its output files, a record as one
// JSON line that reads back (a torn line skipped), atomic appends to results.jsonl from concurrent
// processes, and the first non-finite number in text outputs and float TIFFs.
#include "evio/sweep/results.h"

#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "evio_test/temp_dir.h"

namespace evio::sweep {
namespace {

namespace fs = std::filesystem;

TEST(SweepResults, VioMetricsReadBothTrajectoriesOfEvalJson) {
  evio_test::TempDir tmp;
  tmp.write("eval.json",
            "{\"estimates\": [{\"ate\": {\"trans_m\": {\"rmse\": 0.02}}, \"mean_position_error_percent\": 0.25,"
            " \"yaw_drift_deg_per_m\": 0.03, \"final_yaw_error_deg\": -0.5},"
            " {\"mean_position_error_percent\": 0.375}]}\n");
  tmp.write("stats.json", "{\"sequence_duration_s\": 10, \"keyframes\": 40}\n");
  SweepRecord r;
  read_cell_metrics("vio", tmp.path(), &r);
  EXPECT_EQ(r.metric("ate_rmse_m"), 0.02);
  EXPECT_EQ(r.metric("mean_position_error_percent"), 0.25);
  EXPECT_EQ(r.metric("mean_position_error_percent_causal"), 0.375);  // trajectory_causal.tum
  EXPECT_EQ(r.metric("final_yaw_error_deg"), -0.5);
  EXPECT_EQ(r.metric("keyframes"), 40);
  EXPECT_TRUE(std::isnan(r.metric("rotation_only_keyframes")));
  EXPECT_EQ(r.duration_s, 10);
}

SweepRecord example_record(const std::string& cell, int exit_code) {
  SweepRecord r;
  r.cell = cell;
  r.algorithm = "flow";
  r.dataset = "d \"quoted\"";
  r.params = {{"window.events", "30000"}, {"cmax.model", "rotation"}, {"list", "[1, 2]"}};
  r.args = {"--model", "rotation"};
  r.exit_code = exit_code;
  r.timed_out = exit_code == -9;
  r.wall_s = 1.5;
  r.cpu_s = 1.25;
  r.peak_rss_mb = 33;
  r.duration_s = 2;
  r.metrics = {{"angular_velocity_rms_degps", 1.3125}, {"windows", NAN}};
  r.error_metric = "angular_velocity_rms_degps";
  r.note = "a note";
  return r;
}

TEST(SweepResults, RecordIsOneJsonLineThatReadsBack) {
  const SweepRecord r = example_record("flow-d-00000001", -9);
  const std::string line = sweep_record_json(r);
  ASSERT_EQ(line.back(), '\n');
  EXPECT_EQ(line.find('\n'), line.size() - 1);
  for (const char* key : {"\"cell\": ", "\"algorithm\": ", "\"dataset\": ", "\"params\": {", "\"exit_code\": -9", "\"wall_s\": 1.5",
                          "\"cpu_s\": 1.25", "\"peak_rss_mb\": 33", "\"metrics\": {", "\"windows\": null", "\"window.events\": 30000",
                          "\"cmax.model\": \"rotation\"", "\"real_time_factor\": 0.75"}) {
    EXPECT_NE(line.find(key), std::string::npos) << key << " in " << line;
  }
  evio_test::TempDir tmp;
  const std::string path = tmp.file("results.jsonl");
  append_sweep_record(path, r);
  { std::ofstream(path, std::ios::app) << "{\"cell\": \"torn"; }  // a torn line is skipped
  append_sweep_record(path, example_record("flow-d-00000001", 0));
  const std::vector<SweepRecord> back = read_sweep_records(path);
  ASSERT_EQ(back.size(), 2u);  // the torn line is skipped, the record after it is whole
  EXPECT_EQ(back[0].exit_code, -9);
  EXPECT_TRUE(back[0].timed_out);
  EXPECT_EQ(back[0].dataset, "d \"quoted\"");
  EXPECT_EQ(back[0].params, r.params);
  EXPECT_EQ(back[0].args, r.args);
  EXPECT_EQ(back[0].metric("angular_velocity_rms_degps"), 1.3125);
  EXPECT_TRUE(std::isnan(back[0].metric("windows")));
  EXPECT_EQ(back[0].error_metric, "angular_velocity_rms_degps");
  EXPECT_EQ(back[1].exit_code, 0);
  EXPECT_EQ(latest_sweep_records(back).at("flow-d-00000001").exit_code, 0);
}

TEST(SweepResults, ConcurrentAppendsFromProcessesNeverInterleave) {
  evio_test::TempDir tmp;
  const std::string path = tmp.file("results.jsonl");
  const int kProcs = 4, kLines = 100;
  std::vector<pid_t> pids;
  for (int p = 0; p < kProcs; ++p) {
    const pid_t pid = fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
      for (int i = 0; i < kLines; ++i) {
        SweepRecord r = example_record("cell-" + std::to_string(p) + "-" + std::to_string(i), 0);
        r.args.assign(1, std::string(9000, 'a' + p));  // longer than PIPE_BUF
        append_sweep_record(path, r);
      }
      _exit(0);
    }
    pids.push_back(pid);
  }
  for (pid_t pid : pids) {
    int status = 0;
    waitpid(pid, &status, 0);
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
  }
  const std::vector<SweepRecord> back = read_sweep_records(path);
  ASSERT_EQ(back.size(), static_cast<size_t>(kProcs * kLines));
  for (const SweepRecord& r : back) {
    ASSERT_EQ(r.args.size(), 1u);
    EXPECT_EQ(r.args[0], std::string(9000, r.args[0][0]));
  }
  EXPECT_EQ(latest_sweep_records(back).size(), static_cast<size_t>(kProcs * kLines));
}

TEST(SweepExtremes, NonfiniteNumbersAreFoundInTextOutputsAndFloatTiffs) {
  evio_test::TempDir tmp;
  const std::string out = tmp.file("out");
  fs::create_directories(out + "/images");
  std::ofstream(out + "/images.txt") << "0.1 images/frame_00000000.png\n";
  std::ofstream(out + "/stats.json") << "{\"images\": 2, \"info\": \"nanoflann infinity-free\", \"t\": 1e-9}\n";
  cv::Mat img(4, 5, CV_32F, cv::Scalar(0.5));
  ASSERT_TRUE(cv::imwrite(out + "/images/frame_00000000.tiff", img));
  EXPECT_EQ(find_nonfinite_output("reconstruct", out), "");
  img.at<float>(2, 3) = std::numeric_limits<float>::infinity();
  ASSERT_TRUE(cv::imwrite(out + "/images/frame_00000001.tiff", img));
  EXPECT_EQ(find_nonfinite_output("reconstruct", out), "images/frame_00000001.tiff: pixel (3, 2) is Inf");
  // mosaic: NaN marks the panorama's unseen pixels; it counts only where panorama_seen.png says seen.
  cv::Mat pano(4, 5, CV_32F, cv::Scalar(std::numeric_limits<float>::quiet_NaN()));
  pano.at<float>(1, 1) = -2.0f;
  cv::Mat seen(4, 5, CV_8U, cv::Scalar(0));
  seen.at<uint8_t>(1, 1) = 255;
  ASSERT_TRUE(cv::imwrite(out + "/panorama_log.tiff", pano));
  ASSERT_TRUE(cv::imwrite(out + "/panorama_seen.png", seen));
  EXPECT_EQ(find_nonfinite_output("mosaic", out), "");
  seen.at<uint8_t>(3, 4) = 255;
  ASSERT_TRUE(cv::imwrite(out + "/panorama_seen.png", seen));
  EXPECT_EQ(find_nonfinite_output("mosaic", out), "panorama_log.tiff: pixel (4, 3) is NaN where panorama_seen.png marks it seen");
  std::ofstream(out + "/stats.json") << "{\"images\": 2, \"mean\": NaN}\n";
  std::ofstream(out + "/trajectory.tum") << "1.0 0 0 0 0 0 0 1\n2.0 inf 0 0 0 0 0 1\n";
  EXPECT_EQ(find_nonfinite_output("vio", out), "trajectory.tum:2: inf");
  EXPECT_EQ(find_nonfinite_output("flow", out), "stats.json:1: NaN");
  EXPECT_EQ(find_nonfinite_output("corners", tmp.file("absent")), "");
}

}  // namespace
}  // namespace evio::sweep
