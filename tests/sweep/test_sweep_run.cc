// evio::sweep run steps (run.h): a cell's `evio <algorithm>` arguments (--gt where the algorithm
// takes it and the dataset has it), its command line, the cells still to run after earlier records,
// each pending cell's folder, command.txt and job, and a finished cell's record.
#include "evio/sweep/run.h"

#include <cmath>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "evio_test/temp_dir.h"
#include "evio_test/text_file.h"

namespace evio::sweep {
namespace {

namespace fs = std::filesystem;

// A recording with ground truth (rec), one without (bare) and a simulated scene (sim); vio (takes
// --gt) and flow (does not) on each.
std::vector<SweepCell> example_cells(const evio_test::TempDir& tmp) {
  fs::create_directories(tmp.file("rec"));
  fs::create_directories(tmp.file("bare"));
  tmp.write("rec/groundtruth.txt", "0 0 0 0 0 0 0 1\n");
  tmp.write("scene.yaml", "x: 1\n");
  const SweepSpec spec = parse_sweep_spec(
      "timeout_s: 7\ndatasets: [rec, bare, {name: sim, scene: scene.yaml}]\nalgorithms:\n"
      "  - {algorithm: vio, args: [--calib, c.yaml], grid: {frames.events_per_frame: [5000]}}\n"
      "  - {algorithm: flow, args: [--model, 'rotation x']}\n",
      "spec.yaml", tmp.path());
  return expand_sweep_cells(spec, tmp.file("sweep/data"));
}

TEST(SweepCellRun, ArgumentsAddGroundTruthWhereTheAlgorithmTakesItAndTheDatasetHasIt) {
  evio_test::TempDir tmp;
  const std::vector<SweepCell> cells = example_cells(tmp);
  ASSERT_EQ(cells.size(), 6u);
  EXPECT_EQ(cell_arguments(cells[0], "/d/cells/x"),
            (std::vector<std::string>{"vio", tmp.file("rec"), "--out", "/d/cells/x/out", "-q", "--calib", "c.yaml", "--gt",
                                      tmp.file("rec") + "/groundtruth.txt", "--set", "frames.events_per_frame=5000"}));
  EXPECT_EQ(cell_arguments(cells[1], "/d/cells/x"),  // no groundtruth.txt in the recording
            (std::vector<std::string>{"vio", tmp.file("bare"), "--out", "/d/cells/x/out", "-q", "--calib", "c.yaml", "--set",
                                      "frames.events_per_frame=5000"}));
  const std::vector<std::string> sim = cell_arguments(cells[2], "/d/cells/x");  // generated later: its ground truth is assumed
  ASSERT_GE(sim.size(), 9u);
  EXPECT_EQ(sim[7], "--gt");
  EXPECT_EQ(sim[8], tmp.file("sweep/data") + "/sim/groundtruth.txt");
  EXPECT_EQ(cell_arguments(cells[3], "/d/cells/y"),  // flow takes no --gt
            (std::vector<std::string>{"flow", tmp.file("rec"), "--out", "/d/cells/y/out", "-q", "--model", "rotation x"}));
  EXPECT_EQ(sweep_command_line(cell_arguments(cells[3], "/d/cells/y")),
            "evio flow " + tmp.file("rec") + " --out /d/cells/y/out -q --model 'rotation x'");
  EXPECT_EQ(sweep_cell_dir("/d", cells[3]), "/d/cells/" + cells[3].id);
}

TEST(SweepCellRun, PendingCellsAreThoseWithoutASuccessfulRecord) {
  evio_test::TempDir tmp;
  const std::vector<SweepCell> cells = example_cells(tmp);
  std::map<std::string, SweepRecord> latest;
  latest[cells[0].id].outcome = "ok";         // exit code 0: done
  latest[cells[1].id].outcome = "nonfinite";  // exit code 0 with NaN in an output: runs again
  latest[cells[2].id].exit_code = 1;          // failed: runs again
  latest["gone-00000000"].outcome = "ok";     // a cell no longer in the spec
  const std::vector<const SweepCell*> pending = pending_sweep_cells(cells, latest);
  ASSERT_EQ(pending.size(), 5u);
  for (size_t i = 0; i < pending.size(); ++i) EXPECT_EQ(pending[i], &cells[i + 1]);
  EXPECT_EQ(pending_sweep_cells(cells, {}).size(), cells.size());
}

TEST(SweepCellRun, JobsGetAFreshFolderWithTheirCommandAndRecordsTheirOutcome) {
  evio_test::TempDir tmp;
  const std::vector<SweepCell> cells = example_cells(tmp);
  const std::string dir = tmp.file("sweep");
  const std::string cell_dir = sweep_cell_dir(dir, cells[3]);
  tmp.write("sweep/cells/" + cells[3].id + "/stale.txt", "an earlier run's file\n");
  const std::vector<const SweepCell*> pending = {&cells[3], &cells[0]};
  const std::vector<SweepJob> jobs = prepare_cell_jobs(pending, dir, "/programs", -1);
  ASSERT_EQ(jobs.size(), 2u);
  EXPECT_FALSE(fs::exists(cell_dir + "/stale.txt"));
  const std::vector<std::string> args = cell_arguments(cells[3], cell_dir);
  EXPECT_EQ(jobs[0].program, "/programs/evio-flow");
  EXPECT_EQ(jobs[0].args, std::vector<std::string>(args.begin() + 1, args.end()));
  EXPECT_EQ(evio_test::read_text(cell_dir + "/command.txt"), sweep_command_line(args) + "\n");
  EXPECT_EQ(jobs[0].stdout_path, cell_dir + "/stdout.log");
  EXPECT_EQ(jobs[0].stderr_path, cell_dir + "/stderr.log");
  EXPECT_EQ(jobs[0].out_dir, cell_dir + "/out");
  EXPECT_EQ(jobs[0].timeout_s, 7);  // the spec's
  EXPECT_EQ(jobs[1].program, "/programs/evio-vio");
  EXPECT_EQ(prepare_cell_jobs(pending, dir, "/programs", 0)[1].timeout_s, 0);  // --timeout 0: none

  // The record of a cell that exited 1: the cell, the outcome, the error line of its stderr, null metrics.
  tmp.write("sweep/cells/" + cells[0].id + "/stderr.log", "progress\nevio: error: no events\n\n");
  SweepOutcome o;
  o.exit_code = 1;
  o.wall_s = 2.5;
  o.cpu_s = 2;
  o.peak_rss_mb = 40;
  o.host = "h";
  o.started_utc = "2026-01-01T00:00:00Z";
  const SweepRecord r = cell_record(cells[0], o, "local", sweep_cell_dir(dir, cells[0]), jobs[1].stderr_path);
  EXPECT_EQ(r.cell, cells[0].id);
  EXPECT_EQ(r.algorithm, "vio");
  EXPECT_EQ(r.dataset, "rec");
  EXPECT_EQ(r.dataset_path, tmp.file("rec"));
  EXPECT_EQ(r.params, cells[0].params);
  EXPECT_EQ(r.args, cells[0].args);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_EQ(r.wall_s, 2.5);
  EXPECT_EQ(r.cpu_s, 2);
  EXPECT_EQ(r.peak_rss_mb, 40);
  EXPECT_EQ(r.engine, "local");
  EXPECT_EQ(r.host, "h");
  EXPECT_EQ(r.started_utc, o.started_utc);
  EXPECT_EQ(r.outcome, "error");
  EXPECT_EQ(r.outcome_detail, "evio: error: no events");
  EXPECT_EQ(r.error_metric, "ate_rmse_m");
  EXPECT_TRUE(std::isnan(r.metric("ate_rmse_m")));
}

}  // namespace
}  // namespace evio::sweep
