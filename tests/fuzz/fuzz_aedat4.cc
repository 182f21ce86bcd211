// libFuzzer target: the AEDAT 4.0 reader (header, infoNode XML, data table, LZ4/Zstd packets,
// flatbuffers) on arbitrary bytes. Inputs of odd length use the skip-bad-events policy.
#include <cstdint>

#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio/sensors/aedat4.h"
#include "fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  evio_fuzz::silence_log();
  evio_fuzz::MemFile file(data, size);
  if (!file.ok()) return 0;
  evio::DatasetOptions options;
  options.format = evio::DatasetFormat::kAedat4;
  if (size % 2 == 1) options.text.on_bad_line = evio::BadLinePolicy::kWarnAndSkip;
  try {
    auto reader = evio::open_aedat4_dataset(file.path(), options);
    reader->streams();
    evio::EventBuffer events;
    while (reader->read_events(&events, 4096) > 0) events.clear();
    reader->streams();
    reader->read_imu();
    reader->read_frames();
    reader->read_triggers();
    if (reader->seek_events(0)) {
      while (reader->read_events(&events, 4096) > 0) events.clear();
    }
  } catch (const evio::InputError&) {
  }
  return 0;
}
