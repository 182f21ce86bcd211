// Console reporter for evio's benchmarks: Google Benchmark's table without colour codes, plus
// items/s per benchmark family collected for the JSON lines each program prints at the end.
#pragma once

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <string>
#include <utility>
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

// Google Benchmark's table, then at the end one JSON line per run with the listed counters it has
// ({"benchmark": name, json_key: value, ...}; runs with none of them are left out).
class JsonLinesReporter : public benchmark::ConsoleReporter {
 public:
  // (counter name, JSON key) pairs, e.g. {{"items_per_second", "events_per_s"}}.
  explicit JsonLinesReporter(std::vector<std::pair<std::string, std::string>> counters)
      : ConsoleReporter(OO_Tabular), counters_(std::move(counters)) {}
  void ReportRuns(const std::vector<Run>& runs) override {
    ConsoleReporter::ReportRuns(runs);
    for (const Run& r : runs) {
      std::string fields;
      for (const auto& [counter, key] : counters_) {
        const auto it = r.counters.find(counter);
        if (it != r.counters.end()) fields += ",\"" + key + "\":" + std::to_string(it->second);
      }
      if (!fields.empty()) lines_.push_back("{\"benchmark\":\"" + r.benchmark_name() + "\"" + fields + "}");
    }
  }
  void Finalize() override {
    ConsoleReporter::Finalize();
    for (const auto& l : lines_) std::printf("%s\n", l.c_str());
  }

 private:
  std::vector<std::pair<std::string, std::string>> counters_;
  std::vector<std::string> lines_;
};

// Takes "NAME VALUE" out of argv (before benchmark::Initialize sees it) into *value.
inline void take_int_flag(int* argc, char** argv, const char* name, int64_t* value) {
  for (int i = 1; i + 1 < *argc; ++i) {
    if (std::strcmp(argv[i], name) == 0) {
      *value = std::atoll(argv[i + 1]);
      for (int j = i; j + 2 <= *argc; ++j) argv[j] = argv[j + 2];
      *argc -= 2;
      return;
    }
  }
}

}  // namespace evio::bench
