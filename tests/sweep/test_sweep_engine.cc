// evio::sweep engines (engine.h, cluster.h): the per-job runner of the parallel and slurm engines
// (`evio-sweep --run-cell`: its arguments, its outcome file, its exit code, a timeout), GNU
// parallel's joblog, and the Slurm job-array script and exit codes.
#include "evio/sweep/cluster.h"

#include <unistd.h>

#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "evio/calib/error.h"
#include "evio/sweep/engine.h"
#include "evio_test/temp_dir.h"
#include "evio_test/text_file.h"

namespace evio::sweep {
namespace {

namespace fs = std::filesystem;

TEST(SweepRunner, OutcomeJsonAndRunnerArgumentsReadBack) {
  SweepOutcome o;
  o.exit_code = -9;
  o.timed_out = true;
  o.wall_s = 1.25;
  o.cpu_s = 0.5;
  o.peak_rss_mb = 12.5;
  o.host = "node \"7\"";
  o.started_utc = "2026-11-27T20:00:00Z";
  SweepOutcome back;
  ASSERT_TRUE(parse_sweep_outcome(sweep_outcome_json(o), &back));
  EXPECT_EQ(back.exit_code, -9);
  EXPECT_TRUE(back.timed_out);
  EXPECT_EQ(back.wall_s, 1.25);
  EXPECT_EQ(back.cpu_s, 0.5);
  EXPECT_EQ(back.peak_rss_mb, 12.5);
  EXPECT_EQ(back.host, o.host);
  EXPECT_EQ(back.started_utc, o.started_utc);
  EXPECT_FALSE(parse_sweep_outcome("", &back));
  EXPECT_FALSE(parse_sweep_outcome("{\"exit_code\": 0, \"wall", &back));  // a torn file is no outcome

  SweepJob j;
  j.program = "/p/evio-flow";
  j.args = {"rec", "--out", "c/out", "--set", "a=b c"};
  j.stdout_path = "c/stdout.log";
  j.stderr_path = "c/stderr.log";
  j.timeout_s = 2.5;
  EXPECT_EQ(sweep_outcome_path(j), "c/outcome.json");
  std::string outcome;
  const SweepJob parsed = parse_run_cell_arguments(run_cell_arguments(j), &outcome);
  EXPECT_EQ(outcome, "c/outcome.json");
  EXPECT_EQ(parsed.program, j.program);
  EXPECT_EQ(parsed.args, j.args);
  EXPECT_EQ(parsed.stdout_path, j.stdout_path);
  EXPECT_EQ(parsed.stderr_path, j.stderr_path);
  EXPECT_EQ(parsed.timeout_s, 2.5);
  try {
    parse_run_cell_arguments({"--run-cell", "o.json", "--stdout", "x", "--", "p"}, &outcome);
    ADD_FAILURE() << "incomplete arguments accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("expected: --run-cell OUTCOME.json --timeout S"), std::string::npos) << e.what();
  }
}

TEST(SweepRunner, RunCellWritesTheOutcomeAndExitsWithTheJobsCode) {
  evio_test::TempDir tmp;
  SweepJob j;
  j.program = "/bin/sh";
  j.args = {"-c", "echo out; echo err >&2; exit 3"};
  j.stdout_path = tmp.file("a/b/stdout.log");  // the runner creates the folders
  j.stderr_path = tmp.file("a/b/stderr.log");
  EXPECT_EQ(run_cell(run_cell_arguments(j)), 3);
  SweepOutcome o;
  ASSERT_TRUE(parse_sweep_outcome(evio_test::read_text(tmp.file("a/b/outcome.json")), &o));
  EXPECT_EQ(o.exit_code, 3);
  EXPECT_GE(o.wall_s, 0);
  EXPECT_FALSE(o.host.empty());
  EXPECT_EQ(evio_test::read_text(j.stdout_path), "out\n");
  EXPECT_EQ(evio_test::read_text(j.stderr_path), "err\n");
  EXPECT_FALSE(fs::exists(tmp.file("a/b/outcome.json.tmp" + std::to_string(getpid()))));
  // Past its timeout the job is killed: -9 in the outcome, 128 + 9 as the runner's code.
  j.args = {"-c", "sleep 5"};
  j.timeout_s = 0.2;
  EXPECT_EQ(run_cell(run_cell_arguments(j)), 137);
  ASSERT_TRUE(parse_sweep_outcome(evio_test::read_text(tmp.file("a/b/outcome.json")), &o));
  EXPECT_EQ(o.exit_code, -9);
  EXPECT_TRUE(o.timed_out);
  EXPECT_LT(o.wall_s, 3);
}

TEST(SweepParallel, JoblogLinesAreReadOnceComplete) {
  const std::string log =
      "Seq\tHost\tStarttime\tJobRuntime\tSend\tReceive\tExitval\tSignal\tCommand\n"
      "2\t:\t1764273600.123\t0.512\t0\t0\t0\t0\teval a\n"
      "1\tevio-b\t1764273600.100\t1.250\t10\t20\t137\t0\teval b\n"
      "3\t:\t1764273600.200\t0.100\t0\t0\t255\t9\teval c\n"
      "4\t:\t1764273600.300\t0.1";  // still being written
  const std::vector<ParallelJoblogEntry> e = parse_parallel_joblog(log);
  ASSERT_EQ(e.size(), 3u);
  EXPECT_EQ(e[0].seq, 2u);
  EXPECT_EQ(e[0].host, ":");
  EXPECT_EQ(e[1].seq, 1u);
  EXPECT_EQ(e[1].host, "evio-b");
  EXPECT_EQ(e[1].runtime_s, 1.25);
  EXPECT_EQ(e[1].exit_value, 137);
  EXPECT_EQ(e[2].signal, 9);
}

TEST(SweepSlurm, ArrayScriptAndExitCodes) {
  SweepEngineOptions o;
  o.jobs = 3;
  o.dir = "/shared/sweep";
  o.slurm_partition = "short";
  o.slurm_args = "--mem=4G  --qos=low";
  const std::string s = slurm_array_script(o, 10, "/shared/sweep/slurm/run1.jobs", "/shared/sweep/slurm/run1", 150);
  EXPECT_EQ(s.rfind("#!/bin/bash\n", 0), 0u);
  for (const char* line : {"#SBATCH --array=0-9%3\n", "#SBATCH --output=/shared/sweep/slurm/run1-%a.out\n",
                           "#SBATCH --error=/shared/sweep/slurm/run1-%a.err\n", "#SBATCH --chdir=/shared/sweep\n",
                           "#SBATCH --time=4\n", "#SBATCH --partition=short\n", "#SBATCH --mem=4G\n", "#SBATCH --qos=low\n",
                           "sed -n \"$((SLURM_ARRAY_TASK_ID + 1))p\" /shared/sweep/slurm/run1.jobs"}) {
    EXPECT_NE(s.find(line), std::string::npos) << line << " not in\n" << s;
  }
  o.jobs = 0;
  o.slurm_partition.clear();
  const std::string t = slurm_array_script(o, 1, "j", "l", -1);
  EXPECT_NE(t.find("#SBATCH --array=0-0\n"), std::string::npos) << t;
  EXPECT_EQ(t.find("--time"), std::string::npos) << t;
  EXPECT_EQ(t.find("--partition"), std::string::npos) << t;
  EXPECT_EQ(slurm_exit_code("0:0"), 0);
  EXPECT_EQ(slurm_exit_code("1:0"), 1);
  EXPECT_EQ(slurm_exit_code("0:9"), -9);
}

}  // namespace
}  // namespace evio::sweep
