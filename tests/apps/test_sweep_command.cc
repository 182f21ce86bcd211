// `evio sweep` (run_sweep) on whole sweeps of stand-in programs (shell scripts named evio-<alg> that
// write a stats.json, fail, crash, write NaN or hang on request), through the local engine and GNU
// parallel: every cell recorded once under --jobs 2, generated datasets made once, failed, timed-out
// and killed cells recorded (a killed cell with a negative exit code) and rerun by --resume, an
// interrupted or killed sweep taking its cells with it, each cell's own peak RSS, each cell's outcome,
// and the report (Markdown, CSV, LaTeX, HTML, plots, means over repeat keys, the outcome table)
// listing every cell. The library's parts alone: tests/sweep/.
#include "sweep_command.h"

#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <set>
#include <sstream>

#include <gtest/gtest.h>

#include "evio/calib/error.h"
#include "evio/sweep/results.h"
#include "evio_test/temp_dir.h"
#include "evio_test/text_file.h"

namespace evio::sweep {
namespace {

using apps::run_sweep;
using apps::SweepArgs;

namespace fs = std::filesystem;

// Stand-ins for evio-<algorithm> in a folder: DATASET --out DIR -q [--marker FILE] [--set k=v]...
// --set err=X writes X as the flow error (and the corners count), fail=1 exits 1, and --marker FILE
// hangs (30 s, as the same process) when FILE does not exist yet, after writing its pid there, so a
// rerun succeeds.
std::string fake_programs(const evio_test::TempDir& tmp) {
  const std::string dir = tmp.file("bin");
  fs::create_directories(dir);
  const std::string script =
      "#!/bin/sh\nds=$1; shift; out=; err=null; fail=; marker=\n"
      "while [ $# -gt 0 ]; do case \"$1\" in\n"
      "  --out) out=$2; shift 2;;\n  --marker) marker=$2; shift 2;;\n"
      "  --set) case \"$2\" in err=*) err=${2#err=};; fail=*) fail=${2#fail=};; esac; shift 2;;\n"
      "  *) shift;; esac; done\n"
      "mkdir -p \"$out\"\necho \"fake run on $ds\"\n"
      "if [ -n \"$marker\" ] && [ ! -e \"$marker\" ]; then echo $$ > \"$marker\"; exec sleep 30; fi\n"
      "if [ \"$fail\" = 1 ]; then echo 'evio: error: failing on purpose' >&2; exit 1; fi\n"
      "printf '{\"groundtruth\": {\"rms_error_degps\": %s}, \"duration_s\": 2, \"windows\": 3, \"corners\": %s, "
      "\"model\": {\"summary\": \"chose m%s\", \"chosen\": \"m%s\", \"share\": 0.5, \"tried\": [\"a\", \"b\"]}}\\n' "
      "\"$err\" \"$err\" \"$err\" \"$err\" > \"$out/stats.json\"\n";
  for (const char* alg : {"flow", "corners"}) {
    const std::string p = dir + "/evio-" + alg;
    std::ofstream(p) << script;
    fs::permissions(p, fs::perms::owner_all);
  }
  return dir;
}

SweepArgs fake_sweep(const evio_test::TempDir& tmp, const std::string& spec_text) {
  fs::create_directories(tmp.file("rec"));
  SweepArgs a;
  a.spec = tmp.write("spec.yaml", spec_text);
  a.out = tmp.file("sweep");
  a.jobs = 2;
  a.programs_dir = fake_programs(tmp);
  a.python = tmp.file("no_python");
  a.progress = false;
  a.runner = EVIO_SWEEP;  // the local engine runs each cell through `evio-sweep --run-cell`
  return a;
}

int run_quietly(const SweepArgs& a, std::string* error = nullptr) {
  std::ostringstream out;
  try {
    return run_sweep(a, out);
  } catch (const InputError& e) {
    if (error) *error = e.what();
    return 1;
  }
}

// `evio sweep --report DIR` after removing DIR/report: the report from results.jsonl alone.
int rewrite_report(const SweepArgs& a) {
  fs::remove_all(a.out + "/report");
  SweepArgs r;
  r.out = a.out;
  r.report_only = true;
  r.python = a.python;
  return run_quietly(r);
}

TEST(SweepRun, JobsTwoRecordsEveryCellOnceWithItsOutcomeAndMetrics) {
  evio_test::TempDir tmp;
  const SweepArgs a = fake_sweep(tmp,
                                 "datasets: [rec]\nalgorithms:\n  - {algorithm: flow, grid: {err: [1, 2, 3, 4, 5, 6]}}\n"
                                 "  - {algorithm: corners, grid: {err: [7], fail: [0, 1]}}\n");
  std::string error;
  EXPECT_EQ(run_quietly(a, &error), 1);
  EXPECT_NE(error.find("1 of 8 cells failed"), std::string::npos) << error;
  const std::vector<SweepRecord> recs = read_sweep_records(a.out + "/results.jsonl");
  ASSERT_EQ(recs.size(), 8u);
  std::set<std::string> cells;
  for (const SweepRecord& r : recs) {
    cells.insert(r.cell);
    EXPECT_TRUE(fs::exists(a.out + "/cells/" + r.cell + "/stdout.log"));
    EXPECT_TRUE(fs::exists(a.out + "/cells/" + r.cell + "/command.txt"));
    EXPECT_GE(r.wall_s, 0);
    EXPECT_GE(r.cpu_s, 0);
    EXPECT_GT(r.peak_rss_mb, 0);
    EXPECT_EQ(r.engine, "local");
    const bool fails = r.params.size() == 2 && r.params[1].second == "1";
    EXPECT_EQ(r.exit_code, fails ? 1 : 0) << r.cell;
    if (r.algorithm == "flow") {
      EXPECT_EQ(r.metric("angular_velocity_rms_degps"), std::stod(r.params[0].second));
      EXPECT_EQ(r.duration_s, 2);
      EXPECT_EQ(r.error_metric, "angular_velocity_rms_degps");
    } else {
      EXPECT_TRUE(r.error_metric.empty());
      if (!fails) {
        EXPECT_EQ(r.metric("corners"), 7);
      }
    }
  }
  EXPECT_EQ(cells.size(), 8u);
  EXPECT_NE(evio_test::read_text(a.out + "/cells/" + recs[0].cell + "/stdout.log").find("fake run on " + tmp.file("rec")), std::string::npos);

  // Without --resume the folder is not reused; with it only the failed cell runs again.
  EXPECT_EQ(run_quietly(a, &error), 1);
  EXPECT_NE(error.find("has results already"), std::string::npos) << error;
  SweepArgs resume = a;
  resume.resume = true;
  EXPECT_EQ(run_quietly(resume, &error), 1);
  EXPECT_EQ(read_sweep_records(a.out + "/results.jsonl").size(), 9u);
}

// Datasets made by an external generator (the crosscheck simulator's form): generated once into
// DIR/data/<name> with {out} replaced, their cells read that folder; a generator that exits 77
// (its simulator is not there) skips its dataset and cells with its message, and the rest runs.
TEST(SweepRun, GeneratedDatasetsRunOnceAndAMissingGeneratorSkipsItsCells) {
  evio_test::TempDir tmp;
  const std::string gen = tmp.write("gen.sh", "#!/bin/sh\nmkdir -p \"$1\" && echo \"$2\" >> \"$(dirname \"$1\")/generated.txt\"\n");
  const std::string absent = tmp.write("absent.sh", "#!/bin/sh\necho 'simulator not found at /nowhere' >&2\nexit 77\n");
  fs::permissions(gen, fs::perms::owner_all);
  fs::permissions(absent, fs::perms::owner_all);
  const SweepArgs a = fake_sweep(tmp,
                                 "datasets:\n  - {name: made, generate: [\"{spec_dir}/gen.sh\", \"{out}\", x]}\n"
                                 "  - {name: missing, generate: [\"{spec_dir}/absent.sh\", \"{out}\"]}\n"
                                 "algorithms:\n  - {algorithm: flow, grid: {err: [1, 2]}}\n");
  std::string error;
  ASSERT_EQ(run_quietly(a, &error), 0) << error;
  const std::vector<SweepRecord> recs = read_sweep_records(a.out + "/results.jsonl");
  ASSERT_EQ(recs.size(), 2u);
  for (const SweepRecord& r : recs) {
    EXPECT_EQ(r.dataset, "made");
    EXPECT_EQ(r.dataset_path, a.out + "/data/made");
  }
  EXPECT_EQ(evio_test::read_text(a.out + "/data/generated.txt"), "x\n");  // once for both cells
  EXPECT_NE(evio_test::read_text(a.out + "/data/made.command").find("gen.sh " + a.out + "/data/made x"), std::string::npos);
  EXPECT_FALSE(fs::exists(a.out + "/data/missing"));
  // A rerun with --resume generates nothing again (the folder and its command are there).
  SweepArgs resume = a;
  resume.resume = true;
  ASSERT_EQ(run_quietly(resume, &error), 0) << error;
  EXPECT_EQ(evio_test::read_text(a.out + "/data/generated.txt"), "x\n");
  // A spec error: a generator without {out}.
  SweepArgs bad = a;
  bad.spec = tmp.write("bad.yaml", "datasets:\n  - {name: m, generate: [gen.sh, x]}\nalgorithms:\n  - {algorithm: flow}\n");
  bad.out = tmp.file("bad");
  EXPECT_EQ(run_quietly(bad, &error), 1);
  EXPECT_NE(error.find("bad.yaml:2: `generate` has no {out}"), std::string::npos) << error;
}

TEST(SweepRun, TimedOutCellIsRecordedWithItsSignalAndRerunByResume) {
  evio_test::TempDir tmp;
  SweepArgs a = fake_sweep(tmp, "datasets: [rec]\nalgorithms:\n  - {algorithm: flow, grid: {err: [1]}}\n"
                                "  - {algorithm: flow, variant: slow, args: [--marker, '{spec_dir}/marker'], grid: {err: [2]}}\n");
  a.timeout_s = 0.5;
  std::string error;
  EXPECT_EQ(run_quietly(a, &error), 1);
  auto latest = latest_sweep_records(read_sweep_records(a.out + "/results.jsonl"));
  ASSERT_EQ(latest.size(), 2u);
  int killed = 0;
  for (const auto& [id, r] : latest) {
    if (r.variant == "slow") {
      EXPECT_EQ(r.exit_code, -9);
      EXPECT_TRUE(r.timed_out);
      ++killed;
    } else {
      EXPECT_EQ(r.exit_code, 0);
    }
  }
  EXPECT_EQ(killed, 1);
  a.resume = true;
  EXPECT_EQ(run_quietly(a, &error), 0) << error;
  const std::vector<SweepRecord> all = read_sweep_records(a.out + "/results.jsonl");
  EXPECT_EQ(all.size(), 3u);  // only the killed cell ran again
  latest = latest_sweep_records(all);
  for (const auto& [id, r] : latest) EXPECT_EQ(r.exit_code, 0) << id;
  EXPECT_TRUE(fs::exists(a.out + "/report/index.html"));
}

// A sweep of one cell that hangs, run by a child process: its pid, and the cell's once it hangs
// (0 if it never does).
std::pair<pid_t, pid_t> start_hanging_sweep(const evio_test::TempDir& tmp, SweepArgs* a) {
  *a = fake_sweep(tmp, "datasets: [rec]\nalgorithms:\n"
                       "  - {algorithm: flow, variant: slow, args: [--marker, '{spec_dir}/marker'], grid: {err: [2]}}\n");
  const pid_t pid = fork();
  if (pid == 0) _exit(run_quietly(*a));
  pid_t cell = 0;
  for (int i = 0; i < 500 && cell <= 0; ++i) {
    usleep(10000);
    std::ifstream(tmp.file("marker")) >> cell;
  }
  return {pid, cell};
}

// --resume runs the one cell, which succeeds this time, and records it.
void expect_resume_records_the_cell(SweepArgs a) {
  a.resume = true;
  EXPECT_EQ(run_quietly(a), 0);
  const std::vector<SweepRecord> recs = read_sweep_records(a.out + "/results.jsonl");
  ASSERT_EQ(recs.size(), 1u);
  EXPECT_EQ(recs[0].exit_code, 0);
}

TEST(SweepRun, InterruptedSweepKillsItsCellsRecordsNoneOfThemAndResumeRunsThem) {
  evio_test::TempDir tmp;
  SweepArgs a;
  const auto [pid, cell] = start_hanging_sweep(tmp, &a);
  ASSERT_GT(pid, 0);
  ASSERT_GT(cell, 0);
  kill(pid, SIGINT);  // as Ctrl-C would
  int status = 0;
  waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 130);
  EXPECT_TRUE(read_sweep_records(a.out + "/results.jsonl").empty());
  expect_resume_records_the_cell(a);
}

// A process that has ended (gone, or a zombie waiting for its new parent to reap it).
bool ended(pid_t pid) {
  std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
  std::string text((std::istreambuf_iterator<char>(stat)), std::istreambuf_iterator<char>());
  const size_t paren = text.rfind(')');
  return text.empty() || (paren != std::string::npos && paren + 2 < text.size() && text[paren + 2] == 'Z');
}

TEST(SweepRun, SweepKilledOutrightTakesItsCellsWithItAndResumeRunsThem) {
  evio_test::TempDir tmp;
  SweepArgs a;
  const auto [pid, cell] = start_hanging_sweep(tmp, &a);
  ASSERT_GT(pid, 0);
  ASSERT_GT(cell, 0);
  kill(pid, SIGKILL);
  waitpid(pid, nullptr, 0);
  bool gone = false;
  for (int i = 0; i < 500 && !gone; ++i) {
    gone = ended(cell);
    if (!gone) usleep(10000);
  }
  EXPECT_TRUE(gone) << "the cell " << cell << " outlived the sweep";
  if (!gone) kill(cell, SIGKILL);
  expect_resume_records_the_cell(a);
}

// A cell forked from a big sweep process must not be charged its memory: ru_maxrss survives fork and
// exec, so the local engine starts each cell from the small runner. Here the sweep holds 300 MiB
// (touched); the stand-in program's peak stays near the runner's ~13 MiB. Forking the cells from the
// sweep itself gave >= 300 MiB (after a one-hour vio cell, 327 MiB for corners cells of 56).
TEST(SweepRun, PeakRssIsTheCellsOwnNotTheSweeps) {
  evio_test::TempDir tmp;
  std::vector<char> ballast(300u << 20);
  for (size_t i = 0; i < ballast.size(); i += 4096) ballast[i] = static_cast<char>(i);
  const SweepArgs a = fake_sweep(tmp, "datasets: [rec]\nalgorithms:\n  - {algorithm: flow, grid: {err: [1, 2]}}\n");
  ASSERT_EQ(run_quietly(a), 0);
  const auto recs = read_sweep_records(a.out + "/results.jsonl");
  ASSERT_EQ(recs.size(), 2u);
  for (const SweepRecord& r : recs) {
    EXPECT_GT(r.peak_rss_mb, 0.5) << r.cell;
    EXPECT_LT(r.peak_rss_mb, 40) << r.cell;
  }
  EXPECT_EQ(ballast[4096], static_cast<char>(4096));
}

TEST(SweepRun, UnknownEngineIsAnError) {
  evio_test::TempDir tmp;
  SweepArgs a = fake_sweep(tmp, "datasets: [rec]\nalgorithms: [{algorithm: flow}]\n");
  a.engine = "condor";
  std::string error;
  EXPECT_EQ(run_quietly(a, &error), 1);
  EXPECT_NE(error.find("--engine condor: unknown (engines: local, parallel, slurm)"), std::string::npos) << error;
  EXPECT_FALSE(fs::exists(a.out + "/results.jsonl"));
}

bool have_parallel() { return std::system("parallel --version > /dev/null 2>&1") == 0; }

// The metrics of each cell, by cell id, as text ("name=value ..."; NaN compares equal to NaN).
std::map<std::string, std::string> metrics_by_cell(const std::string& results) {
  std::map<std::string, std::string> m;
  for (const auto& [id, r] : latest_sweep_records(read_sweep_records(results))) {
    for (const auto& [k, v] : r.metrics) m[id] += k + "=" + std::to_string(v) + " ";
  }
  return m;
}

TEST(SweepParallel, SameRecordsAsLocalAndAKilledCellIsRerunByResume) {
  if (!have_parallel()) GTEST_SKIP() << "GNU parallel is not installed (Debian package parallel)";
  evio_test::TempDir tmp;
  const std::string spec = "datasets: [rec]\nalgorithms:\n  - {algorithm: flow, grid: {err: [1, 2, 3]}}\n"
                           "  - {algorithm: corners, grid: {err: [7], fail: [0, 1]}}\n";
  SweepArgs local = fake_sweep(tmp, spec);
  local.out = tmp.file("local");
  EXPECT_EQ(run_quietly(local), 1);
  SweepArgs par = local;
  par.out = tmp.file("parallel");
  par.engine = "parallel";
  par.runner = EVIO_SWEEP;
  std::string error;
  EXPECT_EQ(run_quietly(par, &error), 1);
  EXPECT_NE(error.find("1 of 5 cells failed"), std::string::npos) << error;
  const std::vector<SweepRecord> recs = read_sweep_records(par.out + "/results.jsonl");
  ASSERT_EQ(recs.size(), 5u);
  for (const SweepRecord& r : recs) {
    EXPECT_EQ(r.engine, "parallel");
    EXPECT_GT(r.peak_rss_mb, 0);
    EXPECT_GE(r.cpu_s, 0);
    const auto l = latest_sweep_records(read_sweep_records(local.out + "/results.jsonl")).at(r.cell);
    EXPECT_EQ(r.exit_code, l.exit_code) << r.cell;
  }
  EXPECT_EQ(metrics_by_cell(par.out + "/results.jsonl"), metrics_by_cell(local.out + "/results.jsonl"));
  EXPECT_TRUE(fs::exists(par.out + "/parallel/run1.joblog"));

  // A cell killed (kill -9) while it runs under GNU parallel is recorded with -9 and rerun by --resume.
  evio_test::TempDir tmp2;
  SweepArgs a = fake_sweep(tmp2, "datasets: [rec]\nalgorithms:\n"
                                 "  - {algorithm: flow, variant: slow, args: [--marker, '{spec_dir}/marker'], grid: {err: [2]}}\n");
  a.engine = "parallel";
  a.runner = EVIO_SWEEP;
  const pid_t pid = fork();
  if (pid == 0) _exit(run_quietly(a));
  pid_t cell = 0;
  for (int i = 0; i < 1000 && cell <= 0; ++i) {
    usleep(10000);
    std::ifstream(tmp2.file("marker")) >> cell;
  }
  ASSERT_GT(cell, 0);
  kill(cell, SIGKILL);
  int status = 0;
  waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 1);
  std::vector<SweepRecord> killed = read_sweep_records(a.out + "/results.jsonl");
  ASSERT_EQ(killed.size(), 1u);
  EXPECT_EQ(killed[0].exit_code, -9);
  EXPECT_FALSE(killed[0].timed_out);
  a.resume = true;
  EXPECT_EQ(run_quietly(a), 0);
  killed = read_sweep_records(a.out + "/results.jsonl");
  ASSERT_EQ(killed.size(), 2u);
  EXPECT_EQ(killed[1].exit_code, 0);
  EXPECT_TRUE(fs::exists(a.out + "/parallel/run2.joblog"));
}

TEST(SweepReport, TablesAndPageListEveryCellAndSayWhenPlotsAreMissing) {
  evio_test::TempDir tmp;
  SweepArgs a = fake_sweep(tmp, "name: fake sweep\ndatasets: [rec]\nalgorithms:\n  - {algorithm: flow, grid: {err: [3, 1, 2]}}\n"
                                "  - {algorithm: corners, grid: {err: [5]}}\n");
  ASSERT_EQ(run_quietly(a), 0);
  const auto latest = latest_sweep_records(read_sweep_records(a.out + "/results.jsonl"));
  const std::string md = evio_test::read_text(a.out + "/report/pareto.md");
  const std::string csv = evio_test::read_text(a.out + "/report/cells.csv");
  const std::string tex = evio_test::read_text(a.out + "/report/pareto.tex");
  const std::string page = evio_test::read_text(a.out + "/report/index.html");
  for (const auto& [id, r] : latest) {
    EXPECT_NE(md.find(id), std::string::npos) << id;
    EXPECT_NE(csv.find(id), std::string::npos) << id;
    EXPECT_NE(page.find(id), std::string::npos) << id;
  }
  EXPECT_NE(md.find("# fake sweep"), std::string::npos);
  EXPECT_NE(md.find("## flow on rec"), std::string::npos);
  EXPECT_NE(md.find("Pareto front of angular velocity RMS deg/s against CPU time"), std::string::npos);
  EXPECT_NE(md.find("## corners on rec"), std::string::npos);
  EXPECT_NE(md.find("No ground-truth error from this command"), std::string::npos);
  EXPECT_NE(tex.find("\\begin{tabular}"), std::string::npos);
  EXPECT_NE(tex.find("flow on rec"), std::string::npos);
  EXPECT_NE(page.find("Plots are missing"), std::string::npos);
  EXPECT_EQ(page.find("<script"), std::string::npos);
  EXPECT_TRUE(fs::exists(a.out + "/report/flow__rec.csv"));
  EXPECT_TRUE(fs::exists(a.out + "/report/corners__rec.csv"));
  ASSERT_EQ(rewrite_report(a), 0);
  EXPECT_TRUE(fs::exists(a.out + "/report/index.html"));
}

// The "model" object of each cell's stats.json reaches its results.jsonl line (as JSON, numbers
// numbers and strings strings) and the report's model-selection table (Markdown, HTML, LaTeX).
TEST(SweepReport, ModelSelectionReachesResultsAndReport) {
  evio_test::TempDir tmp;
  SweepArgs a = fake_sweep(tmp, "datasets: [rec]\nalgorithms:\n  - {algorithm: flow, grid: {err: [3, 4]}}\n"
                                "  - {algorithm: corners, grid: {err: [5], fail: [1]}}\n");
  run_quietly(a);
  const std::string lines = evio_test::read_text(a.out + "/results.jsonl");
  EXPECT_NE(lines.find("\"model\": {\"summary\": \"chose m3\", \"chosen\": \"m3\", \"share\": 0.5, \"tried\": [\"a\", \"b\"]}"),
            std::string::npos) << lines;
  EXPECT_NE(lines.find("\"model\": null"), std::string::npos) << lines;  // the failed cell wrote no stats.json
  const auto latest = latest_sweep_records(read_sweep_records(a.out + "/results.jsonl"));
  ASSERT_EQ(latest.size(), 3u);
  int with_model = 0;
  for (const auto& [id, r] : latest) {
    if (r.algorithm == "flow") {
      ++with_model;
      EXPECT_EQ(sweep_model_summary(r), "chose m" + r.params[0].second);
      // Read back and written again, the line is the same.
      EXPECT_NE(sweep_record_json(r).find("\"chosen\": \"m" + r.params[0].second + "\", \"share\": 0.5"), std::string::npos);
    } else {
      EXPECT_TRUE(r.model_json.empty());
    }
  }
  EXPECT_EQ(with_model, 2);
  const std::string md = evio_test::read_text(a.out + "/report/pareto.md");
  const std::string page = evio_test::read_text(a.out + "/report/index.html");
  const std::string tex = evio_test::read_text(a.out + "/report/pareto.tex");
  EXPECT_NE(md.find("## Model selection"), std::string::npos);
  for (const char* s : {"chose m3", "chose m4", "(failed: 1)"}) {
    EXPECT_NE(md.find(s), std::string::npos) << s;
    EXPECT_NE(page.find(s), std::string::npos) << s;
  }
  EXPECT_NE(page.find("<h2 id=\"model-selection\">"), std::string::npos);
  EXPECT_NE(page.find("href=\"#model-selection\""), std::string::npos);
  EXPECT_NE(tex.find("Model selection per cell"), std::string::npos);
}

// `mean_over:` averages the cells that differ only in the repeat keys: mean, sd, min and max of the
// headline error per remaining grid point, cells ok out of cells, a Pareto front of the means that
// leaves out rows with a failed repeat, and every metric's mean/sd/n in __means.csv; `--report DIR`
// rewrites the same from the spec's copy in DIR.
TEST(SweepReport, MeansOverRepeatKeysWithTheirSpreadAndFront) {
  evio_test::TempDir tmp;
  const SweepArgs a = fake_sweep(tmp, "mean_over: [err, fail]\ndatasets: [rec]\nalgorithms:\n"
                                      "  - {algorithm: flow, variant: v1, grid: {err: [1, 2, 6]}}\n"
                                      "  - {algorithm: flow, variant: v2, grid: {err: [4, 5]}}\n"
                                      "  - {algorithm: flow, variant: v3, grid: {err: [0.5], fail: [0, 1]}}\n");
  EXPECT_EQ(run_quietly(a), 1);  // v3's second repeat fails on purpose
  const std::string csv_path = a.out + "/report/flow__rec__means.csv";
  auto check = [&] {
    const std::string csv = evio_test::read_text(csv_path);
    std::map<std::string, std::vector<std::string>> rows;  // variant -> fields
    std::istringstream in(csv);
    std::string line;
    std::getline(in, line);
    EXPECT_EQ(line.rfind("variant,params,cells ok,CPU s mean,wall s mean,peak RSS MiB max,angular_velocity_rms_degps_mean,"
                         "angular_velocity_rms_degps_sd,angular_velocity_rms_degps_n,", 0), 0u) << line;
    while (std::getline(in, line)) {
      std::vector<std::string> f;
      std::stringstream ls(line);
      for (std::string x; std::getline(ls, x, ',');) f.push_back(x);
      if (line.back() == ',') f.emplace_back();  // an empty last field
      rows[f[0]] = f;
    }
    ASSERT_EQ(rows.size(), 3u) << csv;
    EXPECT_EQ(rows["v1"][1], "(defaults)");
    EXPECT_EQ(rows["v1"][2], "3/3");
    EXPECT_NEAR(std::stod(rows["v1"][6]), 3.0, 1e-12);
    EXPECT_NEAR(std::stod(rows["v1"][7]), std::sqrt(7.0), 1e-8);  // sample sd of 1, 2, 6
    EXPECT_EQ(rows["v1"][8], "3");
    EXPECT_EQ(rows["v2"][2], "2/2");
    EXPECT_NEAR(std::stod(rows["v2"][6]), 4.5, 1e-12);
    EXPECT_EQ(rows["v3"][2], "1/2");
    EXPECT_NEAR(std::stod(rows["v3"][6]), 0.5, 1e-12);
    EXPECT_EQ(rows["v3"][7], "-");  // one value: no sd
    EXPECT_EQ(rows["v1"].back(), "yes");  // the lowest mean of the complete rows
    EXPECT_EQ(rows["v3"].back(), "");     // lowest mean, but a repeat failed
  };
  check();
  const std::string md = evio_test::read_text(a.out + "/report/pareto.md");
  EXPECT_NE(md.find("Means over err, fail"), std::string::npos) << md;
  EXPECT_NE(md.find("| v1 | (defaults) | 3/3 | 3 | 2.646 | 1 | 6 |"), std::string::npos) << md;
  EXPECT_NE(evio_test::read_text(a.out + "/report/index.html").find("Means over err, fail"), std::string::npos);
  EXPECT_NE(evio_test::read_text(a.out + "/report/pareto.tex").find("means over err, fail"), std::string::npos);
  ASSERT_EQ(rewrite_report(a), 0);
  check();
}

TEST(SweepReport, SaysSoWhenNoCellHasAFiniteError) {
  evio_test::TempDir tmp;
  const SweepArgs a = fake_sweep(tmp, "datasets: [rec]\nalgorithms: [{algorithm: flow}]\n");  // err: null
  ASSERT_EQ(run_quietly(a), 0);
  const std::string md = evio_test::read_text(a.out + "/report/pareto.md");
  EXPECT_NE(md.find("No successful cell has a finite angular velocity RMS deg/s: no Pareto front."), std::string::npos) << md;
  EXPECT_EQ(md.find("Pareto front of"), std::string::npos) << md;
}

TEST(SweepReport, PlotsAreEmbeddedWhenMatplotlibIsThere) {
  if (std::system("/usr/bin/python3 -c 'import matplotlib' > /dev/null 2>&1") != 0) GTEST_SKIP() << "no matplotlib in /usr/bin/python3";
  // Single cells, and means over a repeat key (drawn with their spread and their own front).
  for (const char* spec : {"datasets: [rec]\nalgorithms:\n  - {algorithm: flow, grid: {err: [3, 1]}}\n",
                           "mean_over: [err]\ndatasets: [rec]\nalgorithms:\n  - {algorithm: flow, grid: {k: [a, b], err: [3, 1, 2]}}\n"}) {
    evio_test::TempDir tmp;
    SweepArgs a = fake_sweep(tmp, spec);
    a.python = "/usr/bin/python3";
    ASSERT_EQ(run_quietly(a), 0) << spec;
    EXPECT_TRUE(fs::exists(a.out + "/report/plots/flow__rec.png")) << spec;
    EXPECT_EQ(evio_test::read_text(a.out + "/report/plot_errors.log"), "") << spec;
    const bool means = std::string(spec).find("mean_over") != std::string::npos;
    EXPECT_EQ(evio_test::read_text(a.out + "/report/plot.log"),
              means ? "flow__rec: 6 cells, 2 means with +-1 sd, the front of the means\n" : "flow__rec: 2 cells\n") << spec;
    const std::string page = evio_test::read_text(a.out + "/report/index.html");
    EXPECT_NE(page.find("<img alt=\"flow on rec\" src=\"data:image/png;base64,iVBORw0KGgo"), std::string::npos) << spec;
    EXPECT_EQ(page.find("Plots are missing"), std::string::npos) << spec;
  }
}

// ---- the numerical-extremes suite: each cell's outcome, the outcome table, accept_errors ----

// Stand-ins for evio-flow and evio-corners that end as --set end=ok|error|crash|nan|hang says.
std::string outcome_programs(const evio_test::TempDir& tmp) {
  const std::string dir = tmp.file("outcome_bin");
  fs::create_directories(dir);
  const std::string script =
      "#!/bin/sh\nds=$1; shift; out=; end=ok\n"
      "while [ $# -gt 0 ]; do case \"$1\" in\n"
      "  --out) out=$2; shift 2;;\n  --set) case \"$2\" in end=*) end=${2#end=};; esac; shift 2;;\n"
      "  *) shift;; esac; done\nmkdir -p \"$out\"\n"
      "printf 't_s,omega_x\\n0.1,0.5\\n' > \"$out/motion.csv\"\n"
      "echo '{\"windows\": 1, \"time_per_event_ns\": 3, \"note\": \"inference on nanoseconds\"}' > \"$out/stats.json\"\n"
      "case $end in\n"
      "  error) echo 'progress line' >&2; echo \"evio: error: $ds/events.txt: no events (expected: at least 1 event)\" >&2; exit 1;;\n"
      "  crash) kill -SEGV $$;;\n  hang) exec sleep 30;;\n"
      "  nan) printf 't_s,omega_x\\n0.1,0.5\\n0.2,-nan\\n' > \"$out/motion.csv\";;\n"
      "  exit2) exit 2;;\nesac\n";
  for (const char* alg : {"flow", "corners"}) {
    const std::string p = dir + "/evio-" + alg;
    std::ofstream(p) << script;
    fs::permissions(p, fs::perms::owner_all);
  }
  return dir;
}

TEST(SweepExtremes, EveryCellGetsItsOutcomeAndTheReportTablesThem) {
  evio_test::TempDir tmp;
  SweepArgs a = fake_sweep(tmp, "timeout_s: 2\nreport: [extremes]\naccept_errors: true\ndatasets: [rec]\nalgorithms:\n"
                                "  - {algorithm: flow, grid: {end: [ok, error, crash, nan, hang, exit2]}}\n"
                                "  - {algorithm: corners, grid: {end: [ok]}}\n");
  a.programs_dir = outcome_programs(tmp);
  std::string error;
  EXPECT_EQ(run_quietly(a, &error), 1);
  EXPECT_NE(error.find("4 of 7 cells failed with a crash, hang or non-finite output"), std::string::npos) << error;
  const std::vector<SweepRecord> recs = read_sweep_records(a.out + "/results.jsonl");
  ASSERT_EQ(recs.size(), 7u);
  std::map<std::string, const SweepRecord*> by_end;
  for (const SweepRecord& r : recs) by_end[r.algorithm == "corners" ? "corners" : r.params.at(0).second] = &r;
  ASSERT_EQ(by_end.size(), 7u);
  EXPECT_EQ(by_end["ok"]->outcome, "ok");
  EXPECT_EQ(by_end["ok"]->outcome_detail, "");
  EXPECT_EQ(by_end["corners"]->outcome, "ok");
  EXPECT_EQ(by_end["error"]->outcome, "error");
  EXPECT_EQ(by_end["error"]->outcome_detail, "evio: error: " + tmp.file("rec") + "/events.txt: no events (expected: at least 1 event)");
  EXPECT_EQ(by_end["crash"]->outcome, "crash");
  EXPECT_EQ(by_end["crash"]->outcome_detail, "killed by signal 11");
  EXPECT_EQ(by_end["exit2"]->outcome, "crash");
  EXPECT_EQ(by_end["exit2"]->outcome_detail, "exit code 2");
  EXPECT_EQ(by_end["nan"]->outcome, "nonfinite");
  EXPECT_EQ(by_end["nan"]->outcome_detail, "motion.csv:3: -nan");
  EXPECT_EQ(by_end["hang"]->outcome, "hang");

  const std::string md = evio_test::read_text(a.out + "/report/pareto.md");
  EXPECT_NE(md.find("## Outcomes"), std::string::npos);
  EXPECT_NE(md.find("Outcomes: 2 ok, 1 error, 2 crash, 1 hang, 1 nonfinite"), std::string::npos) << md;
  EXPECT_NE(md.find("| dataset | corners | flow |"), std::string::npos) << md;
  EXPECT_NE(md.find(by_end["error"]->cell + ": evio: error: "), std::string::npos) << md;
  EXPECT_NE(md.find(by_end["nan"]->cell + ": motion.csv:3: -nan"), std::string::npos) << md;
  for (const char* o : {"error [", "crash [", "hang [", "nonfinite ["}) EXPECT_NE(md.find(o), std::string::npos) << o;
  const std::string page = evio_test::read_text(a.out + "/report/index.html");
  EXPECT_NE(page.find("<td class=\"crash\" title=\""), std::string::npos);
  EXPECT_NE(page.find("<td class=\"ok\">ok</td>"), std::string::npos);
  const std::string ocsv = evio_test::read_text(a.out + "/report/outcomes.csv");
  EXPECT_NE(ocsv.find(by_end["crash"]->cell + ",crash,-11,killed by signal 11"), std::string::npos) << ocsv;

  // Only ok and error cells: the suite passes with accept_errors, fails without it.
  SweepArgs pass = fake_sweep(tmp, "report: [extremes]\naccept_errors: true\ndatasets: [rec]\nalgorithms:\n"
                                   "  - {algorithm: flow, grid: {end: [ok, error]}}\n");
  pass.programs_dir = a.programs_dir;
  pass.out = tmp.file("pass");
  EXPECT_EQ(run_quietly(pass, &error), 0) << error;
  SweepArgs strict = pass;
  strict.spec = tmp.write("strict.yaml", "datasets: [rec]\nalgorithms:\n  - {algorithm: flow, grid: {end: [ok, error]}}\n");
  strict.out = tmp.file("strict");
  EXPECT_EQ(run_quietly(strict, &error), 1);
  EXPECT_NE(error.find("1 of 2 cells failed ("), std::string::npos) << error;
  EXPECT_NE(evio_test::read_text(pass.out + "/report/pareto.md").find("## Outcomes"), std::string::npos);
}

TEST(SweepExtremes, AllOkSweepHasNoOutcomeTableUnlessAsked) {
  evio_test::TempDir tmp;
  SweepArgs a = fake_sweep(tmp, "datasets: [rec]\nalgorithms:\n  - {algorithm: flow, grid: {end: [ok]}}\n");
  a.programs_dir = outcome_programs(tmp);
  ASSERT_EQ(run_quietly(a), 0);
  EXPECT_EQ(evio_test::read_text(a.out + "/report/pareto.md").find("## Outcomes"), std::string::npos);
  a.spec = tmp.write("asked.yaml", "report: [extremes]\ndatasets: [rec]\nalgorithms:\n  - {algorithm: flow, grid: {end: [ok]}}\n");
  a.out = tmp.file("asked");
  ASSERT_EQ(run_quietly(a), 0);
  const std::string md = evio_test::read_text(a.out + "/report/pareto.md");
  EXPECT_NE(md.find("## Outcomes"), std::string::npos);
  EXPECT_NE(md.find("| rec | ok |"), std::string::npos) << md;
}

}  // namespace
}  // namespace evio::sweep
