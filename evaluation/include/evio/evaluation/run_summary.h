// Summaries over runs: the evaluation results of several estimates grouped by method label, and
// per label and metric the count, mean, median, min and max of the runs' values (non-finite
// values, e.g. a metric a run could not compute, are left out of the statistics).
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "evio/evaluation/trajectory_evaluation.h"

namespace evio::evaluation {

struct RunSummary {
  std::string label;
  std::string metric;  // ate_trans_rmse_m, ate_rot_rmse_deg, mean_position_error_percent,
                       // rpe_trans_percent_mean, yaw_drift_deg_per_m
  size_t runs = 0;     // runs with a finite value
  double mean = 0, median = 0, min = 0, max = 0;
};

// Mean over the sub-trajectory lengths of the mean relative translation error in % (NaN when none).
double rpe_trans_percent_mean(const EvaluationResult& r);

// One row per (label, metric), labels in first-appearance order, metrics in the order above.
std::vector<RunSummary> summarize_runs(const std::vector<std::pair<std::string, const EvaluationResult*>>& runs);

}  // namespace evio::evaluation
