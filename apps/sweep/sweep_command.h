// evio sweep: the speed-accuracy sweep of evio's algorithms. A spec (evio/sweep/spec.h) names datasets,
// algorithms and parameter grids; every cell (dataset x algorithm entry x grid point) runs as its
// own `evio <algorithm>` child process in DIR/cells/<cell>/ through an engine (evio/sweep/engine.h);
// its outcome, resources and metrics are appended to DIR/results.jsonl (evio/sweep/results.h) and the
// report (evio/sweep/report.h) is written to DIR/report/. --resume reruns only cells without a
// successful record.
#pragma once

#include <ostream>
#include <string>

namespace evio::apps {

struct SweepArgs {
  std::string spec;                     // SPEC.yaml (not needed with report_only)
  std::string out;                      // the sweep folder DIR
  std::string engine = "local";         // how cells run (evio/sweep/engine.h)
  int jobs = 0;                         // cells at once (per host with hosts); <= 0: the number of cores
  std::string hosts;                    // parallel: GNU parallel --sshloginfile; empty: this machine
  std::string slurm_partition;          // slurm: sbatch --partition; empty: the default partition
  std::string slurm_args;               // slurm: more sbatch options, split at spaces
  bool resume = false;                  // continue DIR: skip cells recorded with exit code 0
  double timeout_s = -1;                // per cell, s, overrides the spec's (0: none); < 0: the spec's
  bool list = false;                    // print the cells and their commands, run nothing
  bool report_only = false;             // write DIR/report/ from DIR/results.jsonl, run nothing
  bool no_report = false;               // skip the report at the end
  std::string python = "/usr/bin/python3";  // for scripts/plot_sweep.py
  std::string runner;                   // evio-sweep, run as `--run-cell` by parallel and slurm; default: this program
  std::string programs_dir;             // where evio-<algorithm> programs are; default: this program's folder
  bool progress = true;                 // a line on stderr per finished cell
};

// Returns the exit code: 0 when every cell run now succeeded, 1 (InputError thrown) on a bad spec or
// when cells failed (they are recorded; --resume reruns them), 130 when interrupted.
int run_sweep(const SweepArgs& args, std::ostream& out);

}  // namespace evio::apps
