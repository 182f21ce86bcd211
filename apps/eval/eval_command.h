// `evio eval GT EST [EST2 ...]`: trajectory evaluation against ground truth (evio::evaluation):
// a table on stdout, and with an output folder results.json (schema in docs/commands/eval.md), per estimate
// the aligned estimate, the matched ground truth (TUM) and per-pair errors (csv), and a summary
// over runs of the same label (csv, yaml, json, LaTeX rows). Optionally runs
// scripts/plot_trajectory.py on those outputs.
#pragma once

#include <iosfwd>
#include <optional>
#include <string>
#include <vector>

#include "evio/evaluation/rotation_error.h"
#include "evio/evaluation/run_summary.h"
#include "evio/evaluation/trajectory_evaluation.h"
#include "evio/sensors/trajectory.h"

namespace evio::apps {

struct EvalArgs {
  std::string groundtruth;               // TUM (`t x y z qx qy qz qw`, s) or csv with a header (ns)
  std::vector<std::string> estimates;    // same formats, one or more
  std::vector<std::string> labels;       // empty, or one method label per estimate (runs of a method share it)
  evaluation::EvaluationOptions options;
  TextReadOptions read;                  // time unit, unit check and bad-line policy of the estimates' reader
  TimeUnit groundtruth_time_unit = TimeUnit::kAuto;  // the ground truth's unit (other settings as `read`)
  std::string out;                       // output folder; empty: only the table (unless plot is set)
  std::string plot;                      // plot folder; empty: no plots. Numeric outputs go to `out`,
                                         // or to `plot` when `out` is empty
  std::string python = "/usr/bin/python3";  // interpreter for the plot script
  std::string plot_script;               // empty: <source>/scripts or <prefix>/share/evio/scripts
  // Relative rotation error over this interval (s, > 0; 0: not computed), from every 5th estimate
  // pose; with a gyro (imu file, or gyro_orientation given by a caller) also the measured gyro
  // integrated alone over the same intervals.
  double rre_interval_s = 1.0;
  std::string imu;                       // IMU file for the gyro's RRE (any dataset evio reads); empty: none
  std::optional<Trajectory> gyro_orientation;  // or the integrated gyro itself (evaluation::GyroIntegrator)
};

// Result of one estimate, with what the outputs need.
struct EstimateEvaluation {
  std::string file;
  std::string label;   // method label (the file's stem when no labels are given)
  std::string name;    // unique output prefix, e.g. "est0_run1"
  double estimate_length_m = 0;  // path length of the matched estimate after alignment, m
  evaluation::EvaluationResult result;
  std::optional<evaluation::RelativeRotationError> rre;       // rre_interval_s > 0
  std::optional<evaluation::RelativeRotationError> rre_gyro;  // the gyro alone over the same intervals
};

// Evaluates each estimate (throws evio::InputError when options are invalid or nothing associates).
std::vector<EstimateEvaluation> evaluate_all(const EvalArgs& args);

// results.json, exactly the schema of docs/commands/eval.md (numbers printed with %.17g).
std::string results_json(const EvalArgs& args, const std::vector<EstimateEvaluation>& results);

// Summary over runs: per label and metric, count/mean/median/min/max of the runs' values
// (evaluation::summarize_runs).
using SummaryRow = evaluation::RunSummary;
std::vector<SummaryRow> summarize(const std::vector<EstimateEvaluation>& results);
std::string summary_csv(const std::vector<SummaryRow>& rows);
std::string summary_yaml(const std::vector<SummaryRow>& rows);
std::string summary_json(const std::vector<SummaryRow>& rows);
// One LaTeX table row per label: `label & ATE [m] & rot [deg] & MPE [%] & RPE [%] & yaw [deg/m] \\`
// with the mean over runs of each metric (3 significant decimals), preceded by a comment header.
std::string summary_latex(const std::vector<SummaryRow>& rows);

// The printed table (one row per estimate).
std::string results_table(const EvalArgs& args, const std::vector<EstimateEvaluation>& results);

// Returns the process exit code; writes the table to out. Throws evio::InputError on bad input.
int run_eval(const EvalArgs& args, std::ostream& out);

}  // namespace evio::apps
