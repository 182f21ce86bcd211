// evio sweep: the command line of `evio sweep` (run as evio-sweep by the `evio` dispatcher).
#include <cstdio>
#include <iostream>

#include "cli_common.h"
#include "evio/calib/error.h"
#include "evio/sweep/cluster.h"
#include "sweep_command.h"

int main(int argc, char** argv) try {
  // The per-cell runner of the parallel and slurm engines (evio/sweep/cluster.h), not for users.
  if (argc > 1 && std::string(argv[1]) == "--run-cell") {
    try {
      return evio::sweep::run_cell(std::vector<std::string>(argv + 1, argv + argc));
    } catch (const evio::InputError& e) {
      std::fprintf(stderr, "evio: error: %s\n", e.what());
      return 125;
    }
  }
  evio::apps::CommandLine cli("sweep");
  evio::apps::SweepArgs sweep;
  cli->footer(
      "Spec (docs/commands/sweep.md): datasets (recordings by path, or simulator scenes generated once into\n"
      "DIR/data/), algorithms (vio, mosaic, corners, flow, segment, reconstruct) with fixed args and parameter grids\n"
      "of config keys (passed as --set key=value). Each cell runs as `evio <algorithm>` in DIR/cells/<cell>/ (logs,\n"
      "command.txt, out/). DIR/results.jsonl: one JSON line per finished cell (cell, algorithm, dataset, params,\n"
      "exit_code (negative: the signal), wall_s, cpu_s, peak_rss_mb, metrics, outcome: ok | error (exit 1, its stderr\n"
      "line in outcome_detail) | crash (a signal or another exit code) | hang (timeout) | nonfinite (NaN/Inf in an\n"
      "output)). DIR/report/: pareto.md, pareto.tex, cells.csv, per-group CSVs, plots/ and index.html (self-contained);\n"
      "the outcome table (outcomes.csv) when a cell is not ok or the spec has `report: [extremes]`; with the spec's\n"
      "`mean_over: [KEY]` (repeats, e.g. tracker.seed) also the cells averaged over those keys (<group>__means.csv). Exit code 1 when a\n"
      "cell failed (outcome not ok; with the spec's `accept_errors: true` only crash, hang and nonfinite fail; recorded,\n"
      "--resume reruns it), 130 when interrupted (--resume runs the rest).");
  CLI::Option* spec_opt = cli->add_option("SPEC", sweep.spec, "Sweep spec YAML")->check(CLI::ExistingFile);
  CLI::Option* out_opt = cli->add_option("-o,--out", sweep.out, "Sweep folder (created; results.jsonl, cells/, data/, report/)");
  CLI::Option* report_opt = cli->add_option("--report", sweep.out, "Only write DIR/report/ from DIR/results.jsonl (no SPEC)");
  report_opt->excludes(spec_opt)->excludes(out_opt);
  cli->add_option("-j,--jobs", sweep.jobs, "Cells run at once (default: the number of cores); parallel: per host; slurm: array tasks at once (default: no limit)")->check(CLI::PositiveNumber);
  cli->add_option("--engine", sweep.engine,
                  "How cells run: local (a bounded process pool on this machine), parallel (GNU parallel, here or with "
                  "--hosts over ssh; files in DIR/parallel/), slurm (one sbatch job-array task per cell; DIR must be on a "
                  "file system the compute nodes share; files in DIR/slurm/)")
      ->capture_default_str();
  cli->add_option("--hosts", sweep.hosts,
                  "--engine parallel: GNU parallel --sshloginfile (one ssh login a line, [N/]user@host or a Host of "
                  "~/.ssh/config, ':' for this machine); the programs and the data the cells read are sent once per host, "
                  "each cell's folder is returned (docs/commands/sweep.md)")
      ->check(CLI::ExistingFile);
  cli->add_option("--slurm-partition", sweep.slurm_partition, "--engine slurm: sbatch --partition (default: the cluster's)");
  cli->add_option("--slurm-args", sweep.slurm_args,
                  "--engine slurm: more sbatch options, separated by spaces, each put in the script as an #SBATCH line "
                  "(e.g. \"--mem=4G --qos=short\"); the time limit per task is the cell timeout + 1 min (minutes, rounded up)");
  cli->add_flag("--resume", sweep.resume,
                "Continue the sweep in DIR: cells recorded with exit code 0 (outcome not nonfinite) are skipped, failed, "
                "killed, non-finite and unrecorded cells run (again)");
  cli->add_option("--timeout", sweep.timeout_s, "Per-cell wall-time limit, s (0: none), instead of the spec's timeout_s; a "
                                                "cell past it is killed (SIGKILL) and recorded with exit code -9")
      ->check(CLI::NonNegativeNumber);
  cli->add_flag("--list", sweep.list, "Print each cell's id and command, run nothing");
  cli->add_flag("--no-report", sweep.no_report, "Do not write the report at the end");
  cli->add_option("--python", sweep.python, "Python with matplotlib for scripts/plot_sweep.py")->capture_default_str();
  return cli.run(argc, argv, [&] {
    sweep.report_only = report_opt->count() > 0;
    if (!sweep.report_only && (sweep.spec.empty() || sweep.out.empty())) {
      std::fprintf(stderr, "evio sweep: SPEC and --out DIR are required (or --report DIR)\nRun with --help for more information.\n");
      return 2;
    }
    sweep.progress = !cli.quiet();
    return evio::apps::run_sweep(sweep, std::cout);
  });
} catch (const std::exception& e) {  // setting the options up failed (a programming error)
  std::fprintf(stderr, "evio: internal error: %s\n", e.what());
  return 3;
}
