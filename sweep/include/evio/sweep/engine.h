// evio sweep: engines run the cells' processes. An engine takes a list of jobs (one command line
// each, with its log files and timeout) and reports each job's outcome as it ends: exit code
// (negative: the signal that ended it), wall and CPU time and peak RSS of the child. `local` is a
// bounded pool of child processes on this machine (fork/exec, wait4); `parallel` (GNU parallel, on
// this machine or over ssh with --hosts) and `slurm` (a job array) are in cluster.h: they run
// each job through `evio-sweep --run-cell` (run_job below on the machine that runs it), which writes
// the outcome as JSON next to the job's logs, so every engine measures the same way.
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace evio::sweep {

struct SweepJob {
  std::string program;            // executable path
  std::vector<std::string> args;  // arguments after the program name
  std::string stdout_path;        // created/truncated; the child's stdout
  std::string stderr_path;        // created/truncated; the child's stderr
  double timeout_s = 0;           // wall time after which the child's process group is killed; 0: none
  std::string out_dir;            // the folder the program writes (its --out); engines that run the job
                                  // on another machine return it with the logs; empty: none
};

struct SweepOutcome {
  int exit_code = 0;        // the exit status, or -signal when a signal ended the child (-9 after a timeout)
  bool timed_out = false;   // killed by the engine after timeout_s
  double wall_s = 0;        // spawn to exit, s (polled every 20 ms)
  double cpu_s = 0;         // user + system CPU time of the child and its waited-for descendants, s
  double peak_rss_mb = 0;   // the child's peak resident set size (ru_maxrss), MiB
  std::string host;         // the machine it ran on
  std::string started_utc;  // ISO 8601 start time
};

class SweepEngine {
 public:
  virtual ~SweepEngine() = default;
  virtual std::string name() const = 0;
  // Runs every job; calls done(index into jobs, outcome) on the calling thread as each job ends, in
  // the order they end. Returns early (without calling done for the jobs it stopped) once
  // sweep_stop_requested() is true, after killing the jobs still running.
  virtual void run(const std::vector<SweepJob>& jobs, const std::function<void(size_t, const SweepOutcome&)>& done) = 0;
};

// How an engine runs; only `jobs` matters to `local`.
struct SweepEngineOptions {
  int jobs = 0;                    // at most that many jobs at once (<= 0: the number of cores; slurm: no limit)
  std::string dir;                 // the sweep folder (parallel, slurm: their files go to DIR/parallel/, DIR/slurm/)
  std::string runner;              // evio-sweep itself (runs `--run-cell`); default: /proc/self/exe
  bool local_runner = false;       // local: run each job through the runner too (the cells of a sweep; see below)
  std::string hosts;               // parallel: a GNU parallel --sshloginfile; empty: this machine only
  std::string slurm_partition;     // slurm: sbatch --partition; empty: the cluster's default
  std::string slurm_args;          // slurm: more #SBATCH options, split at spaces (e.g. "--mem=4G --qos=short")
};

// The engine called `name` (local, parallel, slurm). Throws std::invalid_argument naming the
// engines that exist for any other name, or saying what an engine needs that is missing.
std::unique_ptr<SweepEngine> make_sweep_engine(const std::string& name, const SweepEngineOptions& options);

// Peak RSS: ru_maxrss of a child is at least the resident size of the process it was forked from
// (Linux keeps the high-water mark across fork's copy of the address space and across exec), so a
// cell forked from the sweep itself would be charged the sweep's memory (it reads every cell's
// stats.json: 330 MiB after a one-hour vio run). With local_runner the local engine starts
// `RUNNER --run-cell ...` (a fresh ~13 MiB process) and takes the job's outcome from the outcome
// file the runner writes, as the parallel and slurm engines do: a cell's peak_rss_mb is its
// program's own peak (exact above the runner's ~13 MiB, which no evio command is below).

// This machine's host name ("unknown" when it cannot be read), and this program's path
// (/proc/self/exe; "evio-sweep" when it cannot be read): the runner's default.
std::string sweep_hostname();
std::string sweep_self_program();

// Runs one job to its end on this machine (what the local engine does per cell).
SweepOutcome run_job(const SweepJob& job);

// Set from a SIGINT/SIGTERM handler (async-signal-safe): engines stop and kill their children.
// clear_sweep_stop() before a new sweep in the same process.
void request_sweep_stop();
bool sweep_stop_requested();
void clear_sweep_stop();

}  // namespace evio::sweep
