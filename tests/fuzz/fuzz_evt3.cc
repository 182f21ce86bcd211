// libFuzzer target: the Prophesee RAW EVT 3.0 reader (format fixed to evt3) and the Evt3Decoder on
// arbitrary bytes. Checks that feeding the decoder in pieces gives the same output as one call.
#include <cstdint>
#include <cstdlib>
#include <vector>

#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio/sensors/evt.h"
#include "fuzz_support.h"

namespace {

// Readers log one line per file opened; keep libFuzzer's output readable and fast.
[[maybe_unused]] const bool kQuiet = [] {
  evio::set_log_sink([](evio::LogLevel, const std::string&) {});
  return true;
}();

void read_file(const std::string& path, evio::BadLinePolicy policy) {
  evio::DatasetOptions opts;
  opts.format = evio::DatasetFormat::kEvt3;
  opts.text.on_bad_line = policy;
  opts.text.sensor = evio::SensorSize{64, 48};  // used when the header has no geometry
  try {
    auto reader = evio::open_evt_dataset(path, opts);
    evio::EventBuffer events;
    while (reader->read_events(&events, 4096) > 0) events.clear();
    reader->read_triggers();
    reader->progress();
  } catch (const evio::InputError&) {
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  evio_fuzz::MemFile file(data, size);
  if (!file.ok()) return 0;
  read_file(file.path(), evio::BadLinePolicy::kError);
  read_file(file.path(), evio::BadLinePolicy::kWarnAndSkip);

  // The decoder alone: one call versus pieces of 1..7 bytes (size taken from the first byte) over
  // the first 16 KiB, then the rest in one call.
  evio::Evt3Decoder whole, parts;
  std::vector<evio::Event> e1, e2;
  std::vector<evio::Trigger> t1, t2;
  whole.decode(data, size, &e1, &t1);
  const size_t piece = size > 0 ? 1 + data[0] % 7 : 1;
  const size_t split = size < 16384 ? size : 16384;
  for (size_t i = 0; i < split; i += piece) parts.decode(data + i, split - i < piece ? split - i : piece, &e2, &t2);
  parts.decode(data + split, size - split, &e2, &t2);
  if (!(e1 == e2) || t1.size() != t2.size() || whole.stats().words != parts.stats().words ||
      whole.stats().cd_events != static_cast<int64_t>(e1.size()) || whole.pending_bytes() != parts.pending_bytes()) {
    std::abort();
  }
  return 0;
}
