// evaluation::summarize_runs: statistics over runs per method label, non-finite values left out.
#include "evio/evaluation/run_summary.h"

#include <cmath>

#include <gtest/gtest.h>

namespace evio::evaluation {
namespace {

EvaluationResult with_ate(double trans_m, double mpe_percent) {
  EvaluationResult r;
  r.ate.trans_m.rmse = trans_m;
  r.mean_position_error_percent = mpe_percent;
  return r;
}

TEST(RunSummary, StatisticsPerLabelAndMetricWithoutNonFiniteRuns) {
  const EvaluationResult a1 = with_ate(0.1, 1.0), a2 = with_ate(0.3, std::nan("")), a3 = with_ate(0.2, 3.0);
  const EvaluationResult b1 = with_ate(1.0, 2.0);
  const std::vector<RunSummary> rows = summarize_runs({{"a", &a1}, {"b", &b1}, {"a", &a2}, {"a", &a3}});
  ASSERT_EQ(rows.size(), 10u);  // 2 labels x 5 metrics, labels in first-appearance order
  EXPECT_EQ(rows[0].label, "a");
  EXPECT_EQ(rows[0].metric, "ate_trans_rmse_m");
  EXPECT_EQ(rows[0].runs, 3u);
  EXPECT_NEAR(rows[0].mean, 0.2, 1e-12);
  EXPECT_NEAR(rows[0].median, 0.2, 1e-12);
  EXPECT_DOUBLE_EQ(rows[0].min, 0.1);
  EXPECT_DOUBLE_EQ(rows[0].max, 0.3);
  EXPECT_EQ(rows[2].metric, "mean_position_error_percent");
  EXPECT_EQ(rows[2].runs, 2u);  // the NaN run is left out
  EXPECT_DOUBLE_EQ(rows[2].median, 2.0);
  EXPECT_EQ(rows[3].metric, "rpe_trans_percent_mean");
  EXPECT_EQ(rows[3].runs, 0u);  // no sub-trajectory errors: NaN in every run
  EXPECT_EQ(rows[5].label, "b");
  EXPECT_DOUBLE_EQ(rows[5].mean, 1.0);
  EXPECT_TRUE(summarize_runs({}).empty());
}

}  // namespace
}  // namespace evio::evaluation
