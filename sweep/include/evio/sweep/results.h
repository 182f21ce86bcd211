// evio sweep: one cell's result record (a line of results.jsonl), the metrics each algorithm's
// outputs give (error against ground truth where the command evaluates it, its own stats
// otherwise), and the atomic append / tolerant read of results.jsonl.
#pragma once

#include <cmath>
#include <map>
#include <string>
#include <utility>
#include <vector>

namespace evio::sweep {

struct SweepRecord {
  std::string cell, algorithm, variant, dataset, dataset_path;
  std::vector<std::pair<std::string, std::string>> params;  // config key -> YAML value
  std::vector<std::string> args;
  int exit_code = 0;          // negative: killed by that signal
  bool timed_out = false;
  double wall_s = 0, cpu_s = 0, peak_rss_mb = 0;
  double duration_s = NAN;    // the data's duration from the cell's stats.json, s (NaN: unknown)
  std::vector<std::pair<std::string, double>> metrics;  // name -> value (NaN: null)
  std::string error_metric;   // the headline error in metrics (empty: the command does not evaluate)
  std::string note;           // where the metrics come from / why there is no error metric
  std::string engine, host, started_utc;
  // The model the algorithm chose, with the numbers behind it: the "model" object of the cell's
  // stats.json as compact JSON ("" when the command wrote none); its "summary" is one line of text.
  std::string model_json;
  // How the cell ended (classify_cell_outcome): "ok", "error", "crash", "hang" or "nonfinite"; empty in
  // records written before outcomes existed. outcome_detail: the error line of stderr ("error"), the
  // exit code or signal ("crash"), the timeout ("hang"), the file and value ("nonfinite").
  std::string outcome, outcome_detail;

  double metric(const std::string& name) const;  // NaN when absent
};

// How an algorithm's cell is measured.
struct SweepAlgorithmInfo {
  std::string name;
  bool gt_flag = false;       // pass --gt DATASET/groundtruth.txt when it exists and args do not set --gt
  std::string error_metric;   // headline error (lower is better); empty: none
  std::string error_label;    // e.g. "ATE RMSE m"
  std::string note;           // what the metrics are
};
const SweepAlgorithmInfo& sweep_algorithm_info(const std::string& algorithm);

// Reads the metrics of a finished cell from its output folder (stats.json, eval.json): fills
// metrics, error_metric, duration_s and note. Missing files or keys give null metrics.
void read_cell_metrics(const std::string& algorithm, const std::string& out_dir, SweepRecord* r);

// The "summary" text of the record's model object ("" when none).
std::string sweep_model_summary(const SweepRecord& r);
// The first non-finite number (NaN, Inf) in the algorithm's output files in out_dir (its trajectories,
// motion.csv, corners, labels, stats.json, eval.json, 32-bit TIFF images), as "FILE:LINE: VALUE"
// (FILE relative to out_dir; TIFF: "FILE: pixel (x, y) is NaN|Inf ..."); empty when every number is
// finite or absent. NaN in mosaic's panorama_log.tiff is its "not seen" value: only NaN where
// panorama_seen.png marks the pixel seen counts. Binary PLY maps are not read.
std::string find_nonfinite_output(const std::string& algorithm, const std::string& out_dir);

// Sets r->outcome and r->outcome_detail from r->exit_code and r->timed_out, the cell's stderr file and
// its outputs: "hang" (killed after the timeout), "crash" (a signal, or an exit code other than 0 and
// 1), "error" (exit code 1; the detail is the last non-empty line of stderr, the command's one-line
// error), "nonfinite" (exit code 0 with a non-finite number in an output), "ok" (exit code 0, every
// output number finite).
void classify_cell_outcome(const std::string& algorithm, const std::string& out_dir, const std::string& stderr_path,
                           SweepRecord* r);
// The outcomes that are failures of the program (not of the input): crash, hang, nonfinite.
bool sweep_outcome_is_defect(const std::string& outcome);

// The record as one JSON line, '\n' included.
std::string sweep_record_json(const SweepRecord& r);
// Appends the line with one write() on an O_APPEND descriptor under an exclusive flock, so records of
// concurrent cells (or concurrent sweeps) never interleave. Throws std::runtime_error on failure.
void append_sweep_record(const std::string& results_path, const SweepRecord& r);
// Every parsable record in file order (a torn or garbled line is skipped with a warning naming it);
// an absent file gives none.
std::vector<SweepRecord> read_sweep_records(const std::string& results_path);
// Whole-file text I/O of the sweep's own files: read gives "" for a missing file; write throws
// InputError naming the file when it cannot be written.
std::string sweep_read_file(const std::string& path);
void sweep_write_file(const std::string& path, const std::string& text);

// The last record of each cell.
std::map<std::string, SweepRecord> latest_sweep_records(const std::vector<SweepRecord>& records);

}  // namespace evio::sweep
