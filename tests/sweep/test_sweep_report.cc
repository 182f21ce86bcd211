// evio::sweep report (report.h): the Pareto front of (CPU time, error). The report's tables and
// page are checked on whole sweeps of stand-in programs in tests/apps/test_sweep_command.cc.
#include "evio/sweep/report.h"

#include <cmath>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

namespace evio::sweep {
namespace {

TEST(SweepPareto, KeepsCellsNoOtherBeatsInTimeAndError) {
  // (time, error): 0 (1, 5) front, 1 (2, 3) front, 2 (3, 4) dominated by 1, 3 (2, 3.5) dominated by 1,
  // 4 (5, 1) front, 5 NaN error left out, 6 (5, 1) equal to 4: not strictly better.
  const std::vector<std::pair<double, double>> p = {{1, 5}, {2, 3}, {3, 4}, {2, 3.5}, {5, 1}, {0.5, NAN}, {5, 1}};
  EXPECT_EQ(pareto_front(p), (std::vector<size_t>{0, 1, 4}));
  EXPECT_TRUE(pareto_front({}).empty());
}

}  // namespace
}  // namespace evio::sweep
