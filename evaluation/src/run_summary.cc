#include "evio/evaluation/run_summary.h"

#include <algorithm>
#include <cmath>

namespace evio::evaluation {
namespace {

double median_of(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 == 1 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

}  // namespace

double rpe_trans_percent_mean(const EvaluationResult& r) {
  double s = 0;
  size_t n = 0;
  for (const auto& e : r.rpe) {
    if (e.count == 0) continue;
    s += e.trans_percent.mean;
    ++n;
  }
  return n == 0 ? std::nan("") : s / static_cast<double>(n);
}

std::vector<RunSummary> summarize_runs(const std::vector<std::pair<std::string, const EvaluationResult*>>& runs) {
  std::vector<std::string> labels;  // first-appearance order
  for (const auto& [label, result] : runs) {
    if (std::find(labels.begin(), labels.end(), label) == labels.end()) labels.push_back(label);
  }
  using Getter = double (*)(const EvaluationResult&);
  const std::vector<std::pair<const char*, Getter>> metrics = {
      {"ate_trans_rmse_m", [](const EvaluationResult& r) { return r.ate.trans_m.rmse; }},
      {"ate_rot_rmse_deg", [](const EvaluationResult& r) { return r.ate.rot_deg.rmse; }},
      {"mean_position_error_percent", [](const EvaluationResult& r) { return r.mean_position_error_percent; }},
      {"rpe_trans_percent_mean", [](const EvaluationResult& r) { return rpe_trans_percent_mean(r); }},
      {"yaw_drift_deg_per_m", [](const EvaluationResult& r) { return r.yaw_drift_deg_per_m; }},
  };
  std::vector<RunSummary> rows;
  for (const std::string& label : labels) {
    for (const auto& [name, get] : metrics) {
      std::vector<double> v;
      for (const auto& [l, result] : runs) {
        if (l != label) continue;
        const double x = get(*result);
        if (std::isfinite(x)) v.push_back(x);
      }
      RunSummary row;
      row.label = label;
      row.metric = name;
      row.runs = v.size();
      if (!v.empty()) {
        double s = 0;
        for (double x : v) s += x;
        row.mean = s / static_cast<double>(v.size());
        row.median = median_of(v);
        row.min = *std::min_element(v.begin(), v.end());
        row.max = *std::max_element(v.begin(), v.end());
      }
      rows.push_back(row);
    }
  }
  return rows;
}

}  // namespace evio::evaluation
