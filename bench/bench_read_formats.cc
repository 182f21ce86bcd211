// Read rate (events/s, one core) of every reader through the generic DatasetReader interface:
// synthetic 20-million-event files written here (HDF5 uncompressed, HDF5 Blosc, EVT 3.0) and the
// real samples in ../shared/data/real when present (EVT 2.0/3.0, AEDAT 4.0 LZ4, ROS1 bag, ROS 2
// bag, AEDAT 2.0, ECD text). With the tests' support library (EVIO_BUILD_TESTS), also ROS 2 bags
// written here: the real rosbag2 sample's messages repackaged as MCAP (none, lz4, zstd chunks), and
// the synthetic events as dvs_msgs/msg/EventArray messages of 10,000 events (MCAP zstd, SQLite3).
// Prints Google Benchmark's table, then one JSON line per input.
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
#ifdef EVIO_BENCH_ROSBAG2_WRITER
#include <sqlite3.h>

#include "evio_test/mcap_writer.h"
#include "evio_test/rosbag2_writer.h"
#endif

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

#ifdef EVIO_BENCH_ROSBAG2_WRITER
// The messages of a rosbag2 SQLite3 file, repackaged as one MCAP file with the given compression.
void repackage_as_mcap(const std::string& db3, const std::string& mcap, const std::string& compression) {
  sqlite3* db = nullptr;
  if (sqlite3_open_v2(db3.c_str(), &db, SQLITE_OPEN_READONLY, nullptr) != SQLITE_OK) return;
  evio_test::McapWriterOptions o;
  o.compression = compression;
  o.chunk_size = 1 << 20;
  evio_test::McapWriter w(mcap, o);
  std::map<int64_t, uint16_t> channels;
  sqlite3_stmt* st = nullptr;
  sqlite3_prepare_v2(db, "SELECT id, name, type FROM topics", -1, &st, nullptr);
  while (sqlite3_step(st) == SQLITE_ROW) {
    const std::string name = reinterpret_cast<const char*>(sqlite3_column_text(st, 1));
    const std::string type = reinterpret_cast<const char*>(sqlite3_column_text(st, 2));
    channels[sqlite3_column_int64(st, 0)] = w.add_channel(w.add_schema(type, "ros2msg", ""), name, "cdr");
  }
  sqlite3_finalize(st);
  sqlite3_prepare_v2(db, "SELECT topic_id, timestamp, data FROM messages ORDER BY timestamp, id", -1, &st, nullptr);
  while (sqlite3_step(st) == SQLITE_ROW) {
    const auto* data = static_cast<const char*>(sqlite3_column_blob(st, 2));
    const std::string bytes(data, static_cast<size_t>(sqlite3_column_bytes(st, 2)));
    const auto t = static_cast<uint64_t>(sqlite3_column_int64(st, 1));
    w.write(channels[sqlite3_column_int64(st, 0)], t, bytes, t);
  }
  sqlite3_finalize(st);
  sqlite3_close(db);
  w.close();
}

// Synthetic events as dvs_msgs/msg/EventArray messages of 10,000 events in a ROS 2 bag folder.
void write_event_array_bag(const std::string& folder, const evio::EventBuffer& events, const std::string& storage) {
  fs::create_directories(folder);
  evio_test::Rosbag2WriterOptions o;
  o.storage = storage;
  o.mcap_compression = "zstd";
  o.mcap_chunk_size = 4 << 20;
  evio_test::Rosbag2Writer w(folder, o);
  const size_t topic = w.add_topic("/dvs/events", "dvs_msgs/msg/EventArray");
  for (size_t i = 0; i < events.size(); i += 10000) {
    const std::vector<evio::Event> batch(events.begin() + static_cast<std::ptrdiff_t>(i),
                                         events.begin() + static_cast<std::ptrdiff_t>(std::min(events.size(), i + 10000)));
    w.write(topic, batch.back().t_ns, evio_test::cdr_event_array(batch.front().t_ns, 1280, 720, batch));
  }
  w.close();
}
#endif

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
  const std::string bag_mcap = (dir / "eventarray_mcap").string(), bag_sqlite = (dir / "eventarray_sqlite").string();
  bool bags = false;
#ifdef EVIO_BENCH_ROSBAG2_WRITER
  bags = true;
#endif
  if (!fs::exists(h5) || !fs::exists(h5b) || !fs::exists(evt3) ||
      (bags && (!fs::exists(bag_mcap + "/metadata.yaml") || !fs::exists(bag_sqlite + "/metadata.yaml")))) {
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
#ifdef EVIO_BENCH_ROSBAG2_WRITER
    fs::remove_all(bag_mcap);
    fs::remove_all(bag_sqlite);
    write_event_array_bag(bag_mcap, events, "mcap");
    write_event_array_bag(bag_sqlite, events, "sqlite3");
#endif
  }
  g_inputs = {{"h5_synthetic_uncompressed", h5}, {"h5_synthetic_blosc", h5b}, {"evt3_synthetic", evt3}};
  if (bags) {
    g_inputs.push_back({"rosbag2_mcap_zstd_synthetic_eventarray", bag_mcap});
    g_inputs.push_back({"rosbag2_sqlite_synthetic_eventarray", bag_sqlite});
  }
  const fs::path real = fs::path(EVIO_SOURCE_DIR) / ".." / "shared" / "data" / "real";
  for (const auto& [name, rel] : std::vector<std::pair<std::string, std::string>>{
           {"evt2_real", "prophesee_raw/evt2_sample.raw"},
           {"evt3_real", "prophesee_raw/evt3_sample.raw"},
           {"aedat4_real_lz4", "davis346_aedat4/davis.aedat4"},
           {"rosbag_real_evt3", "rosbag_eventpacket/test_events_1.bag"},
           {"rosbag2_sqlite_real_evt3", "rosbag2_sqlite/test_events_1"},
           {"aedat2_real", "dvs128_aedat2/DVS128-2017-03-21-short.aedat"},
           {"ecd_text_real", "ecd_slider_depth_head"}}) {
    if (fs::exists(real / rel)) g_inputs.push_back({name, (real / rel).string()});
  }
#ifdef EVIO_BENCH_ROSBAG2_WRITER
  // The same real messages as MCAP files, one per chunk compression.
  const fs::path db3 = real / "rosbag2_sqlite" / "test_events_1" / "test_events_1.db3";
  if (fs::exists(db3)) {
    for (const std::string comp : {"", "lz4", "zstd"}) {
      const std::string name = "rosbag2_mcap_" + (comp.empty() ? std::string("none") : comp) + "_real_evt3";
      const std::string path = (dir / (name + ".mcap")).string();
      if (!fs::exists(path)) repackage_as_mcap(db3.string(), path, comp);
      g_inputs.push_back({name, path});
    }
  }
#endif
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
