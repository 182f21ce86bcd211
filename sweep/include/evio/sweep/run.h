// evio sweep: the steps of running a spec's cells in a sweep folder DIR, between the spec (spec.h)
// and the engines (engine.h): each cell's `evio <algorithm>` command and its job, the simulated
// datasets generated once, the cells still to run, and each finished cell's record (results.h).
// DIR holds spec.yaml (the spec's copy), results.jsonl, data/<dataset>/ (generated datasets, with
// <dataset>.command and their logs), cells/<cell>/ (command.txt, stdout.log, stderr.log,
// outcome.json, out/) and report/ (report.h).
#pragma once

#include <functional>
#include <map>
#include <string>
#include <vector>

#include "evio/sweep/engine.h"
#include "evio/sweep/results.h"
#include "evio/sweep/spec.h"

namespace evio::sweep {

// A line of progress ("evio sweep: ...", no newline); an empty function prints nothing.
using SweepProgress = std::function<void(const std::string&)>;

// The command line `evio ARGS...` with each argument quoted for a POSIX shell where it needs it.
std::string sweep_command_line(const std::vector<std::string>& args);

// The cell's folder: DIR/cells/<cell id>.
std::string sweep_cell_dir(const std::string& dir, const SweepCell& c);

// The arguments of a cell's `evio <algorithm>` (after `evio`): the dataset, --out CELL_DIR/out, -q,
// the entry's args, --gt DATASET/groundtruth.txt when the algorithm takes it, the args do not set it
// and the dataset has one (or is simulated), then --set key=value per grid parameter.
std::vector<std::string> cell_arguments(const SweepCell& c, const std::string& cell_dir);

// The cells without a record of success in `latest` (latest_sweep_records of results.jsonl): no
// record, an exit code other than 0, or a non-finite output. In the order of `cells`.
std::vector<const SweepCell*> pending_sweep_cells(const std::vector<SweepCell>& cells, const std::map<std::string, SweepRecord>& latest);

// Generates the simulated datasets the pending cells read, once, through `engine`: data_dir/<name>/
// with the command that made it in data_dir/<name>.command (`evio simulate` from programs_dir for a
// scene, the spec's generator otherwise); a dataset already made by the same command is kept, one
// made by another command is an InputError. Returns the datasets skipped (generator exit code
// kSweepGeneratorSkip) with the reason (the last line of the generator's stderr). Throws InputError
// when a generation fails; returns early when sweep_stop_requested().
std::map<std::string, std::string> generate_sweep_datasets(const SweepSpec& spec, const std::vector<const SweepCell*>& pending,
                                                           const std::string& data_dir, const std::string& programs_dir,
                                                           SweepEngine* engine, const SweepProgress& progress);

// The jobs of the pending cells, in their order: each cell's folder in DIR/cells/ made afresh (an
// earlier run's removed) with its command.txt; the job runs programs_dir/evio-<algorithm> with
// cell_arguments, its logs in the cell's folder. timeout_s >= 0 replaces each cell's own timeout.
std::vector<SweepJob> prepare_cell_jobs(const std::vector<const SweepCell*>& pending, const std::string& dir,
                                        const std::string& programs_dir, double timeout_s);

// The record of a finished cell: the cell, the engine's outcome, the metrics read from
// CELL_DIR/out (read_cell_metrics) and the outcome class (classify_cell_outcome, from the job's
// stderr log and the outputs).
SweepRecord cell_record(const SweepCell& c, const SweepOutcome& o, const std::string& engine, const std::string& cell_dir,
                        const std::string& stderr_path);

}  // namespace evio::sweep
