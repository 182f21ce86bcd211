// evio sweep: the engines that hand the jobs to tools users already run, and the per-job runner
// they share.
//
// Runner: `evio-sweep --run-cell OUTCOME.json --timeout S --stdout F --stderr F -- PROGRAM ARGS...`
// runs one job with run_job() (the local engine's way: timeout, logs, wait4 rusage) on the machine
// it is started on and writes its SweepOutcome as JSON (temp file + rename: a reader sees the whole
// file or none). Its exit code is the job's (128 + signal when a signal ended it).
//
// parallel: GNU parallel runs the runner of every job (DIR/parallel/runN.jobs: the job's folder, a
// tab, the runner's command; --joblog DIR/parallel/runN.joblog). Without hosts it runs here. With a
// --sshloginfile it spreads the jobs over those logins by ssh: the runner, the evio programs
// (DIR/parallel/bin/), evio's plugins (DIR/parallel/lib/evio/) and every file or folder a job reads
// are sent once per host (--basefile; paths inside DIR go to the same relative path under the
// remote work dir, other absolute paths to the same absolute path); the job runs in the work dir
// ~/.evio-sweep/<this host>-<hash of DIR> and its folder (logs, outcome, output) is returned
// (--return); the work dir is removed at the end (not --cleanup, which would also delete the inputs
// sent to their absolute paths). A job is reported when its joblog line appears (its files are
// back by then): the outcome file, or the joblog's exit value / signal when the runner left none.
//
// slurm: one job-array task per job (DIR/slurm/runN.sh, `sbatch --parsable`, --array=0-(n-1)%jobs,
// --time from the longest timeout); the folder is assumed shared with the compute nodes (as Slurm
// clusters are set up). A task is reported when its outcome file appears, or, once it has left the
// queue without one, with the exit code from `scontrol show job` (or sacct). Stop: scancel.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "evio/sweep/engine.h"

namespace evio::sweep {

// The argument quoted for a POSIX shell (as is when it needs no quoting).
std::string sweep_shell_quote(const std::string& s);
// The outcome file of a job: its stdout log's path with "stdout.log" replaced by "outcome.json".
std::string sweep_outcome_path(const SweepJob& job);
// The outcome as one JSON object, and back (false when the text is not one).
std::string sweep_outcome_json(const SweepOutcome& o);
bool parse_sweep_outcome(const std::string& text, SweepOutcome* o);

// The outcome of a job whose runner left no outcome file: exit_code (125 when it is 0: nothing was
// measured, so it is not a success), no CPU time or RSS, and a line saying why in its stderr log.
SweepOutcome sweep_outcome_without_file(const SweepJob& job, int exit_code, double wall_s, const std::string& host, const std::string& why);

// The runner's arguments (after the runner program) for a job, and back: the job and its outcome
// path from `--run-cell ...` arguments; throws InputError naming the expected form.
std::vector<std::string> run_cell_arguments(const SweepJob& job);
SweepJob parse_run_cell_arguments(const std::vector<std::string>& args, std::string* outcome_path);
// The runner: runs the job, writes its outcome file (parent folders created). Returns the job's
// exit code (128 + signal for a signal), 125 when the outcome cannot be written.
int run_cell(const std::vector<std::string>& args);

// One finished job of a GNU parallel --joblog.
struct ParallelJoblogEntry {
  size_t seq = 0;          // 1-based line of the jobs file
  std::string host;        // the sshlogin (":" here)
  double runtime_s = 0;
  int exit_value = 0;
  int signal = 0;
};
// The complete lines of a joblog (the header and a last line without '\n' are skipped).
std::vector<ParallelJoblogEntry> parse_parallel_joblog(const std::string& text);

// Slurm's "exit:signal" ExitCode as an outcome exit code (-signal when a signal ended it).
int slurm_exit_code(const std::string& exit_code_field);
// The job-array script of `count` jobs whose runner commands are lines of jobs_file.
std::string slurm_array_script(const SweepEngineOptions& o, size_t count, const std::string& jobs_file, const std::string& log_stem,
                               double max_timeout_s);

std::unique_ptr<SweepEngine> make_parallel_engine(const SweepEngineOptions& options);
std::unique_ptr<SweepEngine> make_slurm_engine(const SweepEngineOptions& options);

}  // namespace evio::sweep
