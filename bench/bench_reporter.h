// Console reporter for evio's benchmarks: Google Benchmark's table without colour codes, plus
// items/s per benchmark family collected for the JSON lines each program prints at the end.
#pragma once

#include <map>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

namespace evio::bench {

class CollectingReporter : public benchmark::ConsoleReporter {
 public:
  CollectingReporter() : ConsoleReporter(OO_Tabular) {}
  std::map<std::string, double> rate;  // items_per_second by benchmark family name
  void ReportRuns(const std::vector<Run>& runs) override {
    ConsoleReporter::ReportRuns(runs);
    for (const Run& r : runs) {
      const auto it = r.counters.find("items_per_second");
      if (it != r.counters.end()) rate[r.run_name.function_name] = it->second;
    }
  }
};

}  // namespace evio::bench
