#include "sweep_command.h"

#include <signal.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "evio/calib/error.h"
#include "evio/calib/plugin.h"
#include "evio/sweep/engine.h"
#include "evio/sweep/report.h"
#include "evio/sweep/results.h"
#include "evio/sweep/run.h"
#include "evio/sweep/spec.h"

namespace evio::apps {
namespace fs = std::filesystem;

namespace {

// SIGINT/SIGTERM stop the sweep (children are killed, not recorded) for the scope's lifetime.
class StopOnSignals {
 public:
  StopOnSignals() {
    sweep::clear_sweep_stop();
    struct sigaction sa {};
    sa.sa_handler = [](int) { sweep::request_sweep_stop(); };
    sigemptyset(&sa.sa_mask);
    sigaction(SIGINT, &sa, &old_int_);
    sigaction(SIGTERM, &sa, &old_term_);
  }
  ~StopOnSignals() {
    sigaction(SIGINT, &old_int_, nullptr);
    sigaction(SIGTERM, &old_term_, nullptr);
  }

 private:
  struct sigaction old_int_ {}, old_term_ {};
};

int write_report(const SweepArgs& args, const sweep::SweepReportSettings& settings, std::ostream& out) {
  sweep::SweepReportOptions ro;
  ro.dir = args.out;
  ro.title = settings.name;
  ro.extremes = settings.extremes;
  ro.mean_over = settings.mean_over;
  ro.python = args.python;
  const sweep::SweepReportResult r = sweep::write_sweep_report(ro);
  out << "report of " << r.cells << " cells: " << (fs::path(args.out) / "report" / "index.html").string() << ", pareto.md, pareto.tex, cells.csv"
      << (r.plots ? ", plots/" : "") << "\n";
  if (!r.plots && !r.plot_note.empty()) std::fprintf(stderr, "evio sweep: plots are missing: %s\n", r.plot_note.c_str());
  return 0;
}

// The engine of --engine, with the options the flags give; a bad combination is an InputError.
std::unique_ptr<sweep::SweepEngine> make_engine(const SweepArgs& args) {
  try {
    sweep::SweepEngineOptions eo;
    eo.jobs = args.jobs;
    eo.dir = args.out;
    eo.hosts = args.hosts;
    eo.runner = args.runner;
    eo.local_runner = true;  // the cells' peak RSS is their own, not the sweep's (evio/sweep/engine.h)
    eo.slurm_partition = args.slurm_partition;
    eo.slurm_args = args.slurm_args;
    if (!args.hosts.empty() && args.engine != "parallel") throw std::invalid_argument("--hosts needs --engine parallel");
    return sweep::make_sweep_engine(args.engine, eo);
  } catch (const std::invalid_argument& e) {
    throw InputError("evio sweep", 0, e.what(), "--engine local, parallel (with --hosts FILE) or slurm");
  }
}

void print_progress(const std::string& line) { std::fprintf(stderr, "%s\n", line.c_str()); }

}  // namespace

int run_sweep(const SweepArgs& args, std::ostream& out) {
  if (args.out.empty()) throw InputError("evio sweep", 0, "no output folder", "--out DIR");
  if (args.report_only) {  // the report the sweep wrote: its spec's report keys from the copy in DIR
    const fs::path copy = fs::path(args.out) / "spec.yaml";
    std::error_code ec;
    return write_report(args, fs::exists(copy, ec) ? sweep::load_sweep_report_settings(copy.string()) : sweep::SweepReportSettings{}, out);
  }
  const sweep::SweepSpec spec = sweep::load_sweep_spec(args.spec);
  const fs::path dir = fs::absolute(args.out).lexically_normal();  // absolute: parallel and slurm run cells from DIR
  const std::vector<sweep::SweepCell> cells = sweep::expand_sweep_cells(spec, (dir / "data").string());
  const std::string programs = args.programs_dir.empty() ? executable_dir() : args.programs_dir;
  if (args.list) {
    for (const sweep::SweepCell& c : cells) {
      out << c.id << "\t" << sweep::sweep_command_line(sweep::cell_arguments(c, sweep::sweep_cell_dir(dir.string(), c))) << "\n";
    }
    return 0;
  }
  const std::unique_ptr<sweep::SweepEngine> engine = make_engine(args);
  const std::string results = (dir / "results.jsonl").string();
  std::error_code ec;
  if (fs::exists(results, ec) && !args.resume) {
    throw InputError(results, 0, "the sweep folder has results already",
                     "--resume to continue it (cells with exit code 0 are kept, the others rerun), or a new --out");
  }
  fs::create_directories(dir / "cells");
  const fs::path spec_copy = dir / "spec.yaml";
  if (!fs::exists(spec_copy, ec) || !fs::equivalent(args.spec, spec_copy, ec)) {  // a copy for the record
    fs::copy_file(args.spec, spec_copy, fs::copy_options::overwrite_existing);
  }

  std::vector<const sweep::SweepCell*> pending =
      sweep::pending_sweep_cells(cells, sweep::latest_sweep_records(sweep::read_sweep_records(results)));
  if (args.progress) {
    std::fprintf(stderr, "evio sweep: %zu cells, %zu to run (engine %s)\n", cells.size(), pending.size(), engine->name().c_str());
  }
  StopOnSignals stop_on_signals;
  // Simulated scenes are generated here (their scene files are local), then read by the cells wherever they run.
  sweep::SweepEngineOptions local;
  local.jobs = args.jobs;
  const sweep::SweepProgress progress = args.progress ? print_progress : sweep::SweepProgress();
  const std::map<std::string, std::string> skipped = sweep::generate_sweep_datasets(
      spec, pending, (dir / "data").string(), programs, sweep::make_sweep_engine("local", local).get(), progress);
  if (!skipped.empty()) {
    for (const auto& [name, why] : skipped) std::fprintf(stderr, "evio sweep: dataset %s skipped: %s\n", name.c_str(), why.c_str());
    pending.erase(std::remove_if(pending.begin(), pending.end(), [&](const sweep::SweepCell* c) { return skipped.count(c->dataset) > 0; }),
                  pending.end());
    out << "skipped " << skipped.size() << " dataset(s) whose generator cannot run here (see stderr)\n";
  }

  const std::vector<sweep::SweepJob> jobs = sweep::prepare_cell_jobs(pending, dir.string(), programs, args.timeout_s);
  const auto start = std::chrono::steady_clock::now();
  size_t done = 0, failed = 0;
  if (!sweep::sweep_stop_requested()) {
    engine->run(jobs, [&](size_t i, const sweep::SweepOutcome& o) {
      const sweep::SweepCell& c = *pending[i];
      const sweep::SweepRecord r = sweep::cell_record(c, o, engine->name(), sweep::sweep_cell_dir(dir.string(), c), jobs[i].stderr_path);
      sweep::append_sweep_record(results, r);
      ++done;
      failed += spec.accept_errors ? sweep::sweep_outcome_is_defect(r.outcome) : r.outcome != "ok";
      if (args.progress) {
        const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        const double eta = s / static_cast<double>(done) * static_cast<double>(jobs.size() - done);
        std::fprintf(stderr, "evio sweep: %zu/%zu cells done (%zu failed), %.0f s elapsed, ETA %.0f s: %s exit %d%s in %.1f s: %s\n",
                     done, jobs.size(), failed, s, eta, c.id.c_str(), o.exit_code, o.timed_out ? " (timeout)" : "", o.wall_s,
                     r.outcome.c_str());
      }
    });
  }
  if (sweep::sweep_stop_requested()) {
    std::fprintf(stderr, "evio sweep: interrupted: %zu of %zu cells recorded; `evio sweep %s --out %s --resume` runs the rest\n", done,
                 jobs.size(), args.spec.c_str(), args.out.c_str());
    return 130;
  }
  out << "ran " << done << " cells (" << failed << " failed); results: " << results << "\n";
  if (!args.no_report) write_report(args, sweep::SweepReportSettings{spec.name, spec.report_extremes, spec.mean_over}, out);
  if (failed > 0) {
    throw InputError(results, 0, std::to_string(failed) + " of " + std::to_string(done) + " cells failed" +
                                     (spec.accept_errors ? " with a crash, hang or non-finite output" : "") + " (their stderr.log in " +
                                     (dir / "cells").string() + "/<cell>/)", "`--resume` reruns the failed cells");
  }
  return 0;
}

}  // namespace evio::apps
