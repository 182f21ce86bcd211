// ECD events.txt parsing rate (events/s, one core) on a generated 10-million-event file, against
// an iostream baseline (`ifstream >> t >> x >> y >> p`) run in the same process, and the writer's
// rate. Prints Google Benchmark's table, then one JSON line per result with the ratio.
//   bench_ecd_parse [--events N] [benchmark flags]      (file cached in $TMPDIR)
#include <benchmark/benchmark.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <string>

#include "evio/sensors/ecd.h"
#include "bench_reporter.h"
#include "make_ecd_sequence.h"

namespace {

int64_t g_events = 10000000;
std::string g_path;

void parse_evio(benchmark::State& state) {
  int64_t n = 0;
  for (auto _ : state) {
    evio::EcdEventReader reader(g_path);
    evio::EventBuffer buf;
    buf.reserve(1 << 16);
    n = 0;
    for (;;) {
      buf.clear();
      const size_t got = reader.read(&buf, 1 << 16);
      if (got == 0) break;
      n += static_cast<int64_t>(got);
    }
    benchmark::DoNotOptimize(n);
  }
  if (n != g_events) state.SkipWithError("wrong event count");
  state.SetItemsProcessed(state.iterations() * n);
  state.SetBytesProcessed(state.iterations() * static_cast<int64_t>(std::filesystem::file_size(g_path)));
}

void parse_iostream_baseline(benchmark::State& state) {
  int64_t n = 0;
  for (auto _ : state) {
    std::ifstream in(g_path);
    double t;
    int x, y, p;
    int64_t sum = 0;
    n = 0;
    while (in >> t >> x >> y >> p) {
      sum += static_cast<int64_t>(t * 1e9) + x + y + p;
      ++n;
    }
    benchmark::DoNotOptimize(sum);
  }
  state.SetItemsProcessed(state.iterations() * n);
}

void write_evio(benchmark::State& state) {
  evio::EventBuffer events = evio::read_ecd_events(g_path);
  const std::string out = g_path + ".write_bench";
  for (auto _ : state) {
    evio::EcdEventWriter w(out);
    w.write(events.span());
    w.close();
  }
  std::filesystem::remove(out);
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(events.size()));
}

}  // namespace

int main(int argc, char** argv) {
  evio::bench::take_int_flag(&argc, argv, "--events", &g_events);
  const char* tmp = std::getenv("TMPDIR");
  const std::string dir = std::string(tmp != nullptr ? tmp : "/tmp") + "/evio_bench_ecd_" + std::to_string(g_events);
  g_path = dir + "/events.txt";
  if (!std::filesystem::exists(g_path)) {
    std::fprintf(stderr, "generating %lld events in %s ...\n", static_cast<long long>(g_events), g_path.c_str());
    evio::bench::SequenceSpec spec;
    spec.events = g_events;
    spec.side_files = false;
    evio::bench::make_ecd_sequence(dir, spec);
  }
  benchmark::RegisterBenchmark("ecd_parse/evio", parse_evio)->Unit(benchmark::kMillisecond)->MinTime(2.0)->UseRealTime();
  benchmark::RegisterBenchmark("ecd_parse/iostream_baseline", parse_iostream_baseline)
      ->Unit(benchmark::kMillisecond)->Iterations(1)->UseRealTime();
  benchmark::RegisterBenchmark("ecd_write/evio", write_evio)->Unit(benchmark::kMillisecond)->Iterations(2)->UseRealTime();
  benchmark::Initialize(&argc, argv);
  evio::bench::CollectingReporter reporter;  // plain output (no colour codes) so logs and JSON lines stay clean
  benchmark::RunSpecifiedBenchmarks(&reporter);
  const double base = reporter.rate["ecd_parse/iostream_baseline"];
  for (const auto& [name, r] : reporter.rate) {
    std::printf("{\"bench\": \"%s\", \"events\": %lld, \"events_per_s\": %.4g, \"ratio_vs_iostream\": %.3g}\n",
                name.c_str(), static_cast<long long>(g_events), r, base > 0 ? r / base : 0.0);
  }
  return 0;
}
