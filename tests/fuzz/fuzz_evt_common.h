// Shared body of the fuzz_evt2 / fuzz_evt3 targets: the Prophesee RAW reader with the format
// fixed, under both bad-data policies, and the decoder alone, which must give the same output
// whether the bytes come in one call or in pieces.
#pragma once

#include <cstdint>
#include <cstdlib>
#include <string>
#include <vector>

#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio/sensors/evt.h"
#include "fuzz_support.h"

namespace evio_fuzz {

inline void read_evt_file(const std::string& path, evio::DatasetFormat format, evio::BadLinePolicy policy) {
  evio::DatasetOptions opts;
  opts.format = format;
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

// Decoder = evio::Evt2Decoder or evio::Evt3Decoder.
template <typename Decoder>
int fuzz_evt(const uint8_t* data, size_t size, evio::DatasetFormat format) {
  silence_log();
  MemFile file(data, size);
  if (!file.ok()) return 0;
  read_evt_file(file.path(), format, evio::BadLinePolicy::kError);
  read_evt_file(file.path(), format, evio::BadLinePolicy::kWarnAndSkip);

  // The decoder alone: one call versus pieces of 1..7 bytes (size taken from the first byte) over
  // the first 16 KiB, then the rest in one call.
  Decoder whole, parts;
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

}  // namespace evio_fuzz
