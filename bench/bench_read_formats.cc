// Read rate (events/s, one core) of every reader through the generic DatasetReader interface:
// synthetic 20-million-event files written here (HDF5 uncompressed, HDF5 Blosc, EVT 3.0) and the
// real samples in ../shared/data/real when present (EVT 2.0/3.0, AEDAT 4.0 LZ4, ROS1 bag, AEDAT
// 2.0, ECD text). Prints Google Benchmark's table, then one JSON line per input.
//   bench_read_formats [--events N] [benchmark flags]      (synthetic files cached in $TMPDIR)
#include <benchmark/benchmark.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "evio/calib/log.h"
#include "evio/sensors/dataset.h"
#include "evio/sensors/h5.h"
#include "bench_reporter.h"
#include "make_ecd_sequence.h"

namespace {
namespace fs = std::filesystem;

int64_t g_events = 20000000;

// Minimal EVT 3.0 encoder: TIME_HIGH when the upper 12 bits of the 24-bit us counter change,
// TIME_LOW when the lower 12 change, ADDR_Y when y changes, then ADDR_X with polarity.
void write_evt3(const std::string& path, const evio::EventBuffer& events, int width, int height) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  std::fprintf(f, "%% evt 3.0\n%% format EVT3;height=%d;width=%d\n%% geometry %dx%d\n%% end\n", height, width, width,
               height);
  std::vector<uint16_t> words;
  words.reserve(4 << 20);
  int64_t last_high = -1, last_low = -1;  // last_high: us >> 12 unmasked, so a 24-bit wrap also emits
  int last_y = -1;
  for (const evio::Event& e : events) {
    const int64_t us = e.t_ns / 1000;
    const int64_t low = us & 0xfff;
    if ((us >> 12) != last_high) {
      words.push_back(static_cast<uint16_t>(0x8000 | ((us >> 12) & 0xfff)));
      last_high = us >> 12;
      last_low = -1;
    }
    if (low != last_low) {
      words.push_back(static_cast<uint16_t>(0x6000 | low));
      last_low = low;
    }
    if (e.y != last_y) {
      words.push_back(static_cast<uint16_t>(0x0000 | e.y));
      last_y = e.y;
    }
    words.push_back(static_cast<uint16_t>(0x2000 | (e.polarity > 0 ? 0x800 : 0) | e.x));
    if (words.size() >= (4u << 20) - 8) {
      std::fwrite(words.data(), 2, words.size(), f);
      words.clear();
    }
  }
  std::fwrite(words.data(), 2, words.size(), f);
  std::fclose(f);
}

struct Input {
  std::string name;
  std::string path;
};
std::vector<Input> g_inputs;
std::map<std::string, int64_t> g_counts;

void read_all(benchmark::State& state, const Input& in) {
  int64_t n = 0;
  for (auto _ : state) {
    auto reader = evio::open_dataset(in.path);
    evio::EventBuffer buf;
    buf.reserve(size_t{1} << 20);
    n = 0;
    for (;;) {
      buf.clear();
      const size_t got = reader->read_events(&buf, size_t{1} << 20);
      if (got == 0) break;
      n += static_cast<int64_t>(got);
    }
    benchmark::DoNotOptimize(n);
  }
  g_counts[in.name] = n;
  state.SetItemsProcessed(state.iterations() * n);
  state.counters["events"] = static_cast<double>(n);
}

}  // namespace

int main(int argc, char** argv) {
  evio::bench::take_int_flag(&argc, argv, "--events", &g_events);
  evio::set_log_level(evio::LogLevel::kWarning);
  const char* tmp = std::getenv("TMPDIR");
  const fs::path dir = fs::path(tmp != nullptr ? tmp : "/tmp") / ("evio_bench_formats_" + std::to_string(g_events));
  fs::create_directories(dir);
  const std::string h5 = (dir / "events.h5").string(), h5b = (dir / "events_blosc.h5").string(),
                    evt3 = (dir / "events.raw").string();
  if (!fs::exists(h5) || !fs::exists(h5b) || !fs::exists(evt3)) {
    std::fprintf(stderr, "generating %lld synthetic events in %s ...\n", static_cast<long long>(g_events), dir.c_str());
    evio::bench::SequenceSpec spec;
    spec.events = g_events;
    spec.width = 1280;
    spec.height = 720;
    spec.event_rate_hz = 5e6;
    const evio::EventBuffer events = evio::bench::make_synthetic_events(spec);
    for (const auto& [path, comp] : {std::pair{h5, evio::H5WriteOptions::Compression::kNone},
                                     std::pair{h5b, evio::H5WriteOptions::Compression::kBlosc}}) {
      evio::H5WriteOptions o;
      o.compression = comp;
      o.sensor = evio::SensorSize{spec.width, spec.height};
      evio::H5EventWriter w(path, o);
      w.write(events.span());
      w.close();
    }
    write_evt3(evt3, events, spec.width, spec.height);
  }
  g_inputs = {{"h5_synthetic_uncompressed", h5}, {"h5_synthetic_blosc", h5b}, {"evt3_synthetic", evt3}};
  const fs::path real = fs::path(EVIO_SOURCE_DIR) / ".." / "shared" / "data" / "real";
  for (const auto& [name, rel] : std::vector<std::pair<std::string, std::string>>{
           {"evt2_real", "prophesee_raw/evt2_sample.raw"},
           {"evt3_real", "prophesee_raw/evt3_sample.raw"},
           {"aedat4_real_lz4", "davis346_aedat4/davis.aedat4"},
           {"rosbag_real_evt3", "rosbag_eventpacket/test_events_1.bag"},
           {"aedat2_real", "dvs128_aedat2/DVS128-2017-03-21-short.aedat"},
           {"ecd_text_real", "ecd_slider_depth_head"}}) {
    if (fs::exists(real / rel)) g_inputs.push_back({name, (real / rel).string()});
  }
  for (const Input& in : g_inputs) {
    benchmark::RegisterBenchmark(in.name.c_str(), [in](benchmark::State& s) { read_all(s, in); })
        ->Unit(benchmark::kMillisecond)
        ->MinTime(1.0)
        ->UseRealTime();
  }
  benchmark::Initialize(&argc, argv);
  evio::bench::CollectingReporter reporter;
  benchmark::RunSpecifiedBenchmarks(&reporter);
  for (const auto& [name, r] : reporter.rate) {
    std::printf("{\"bench\": \"read/%s\", \"events\": %lld, \"events_per_s\": %.4g}\n", name.c_str(),
                static_cast<long long>(g_counts[name]), r);
  }
  return 0;
}
