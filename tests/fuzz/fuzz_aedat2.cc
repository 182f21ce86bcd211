// libFuzzer target: the jAER AEDAT 2.0 reader on arbitrary bytes.
#include <cstdint>

#include "evio/calib/error.h"
#include "evio/sensors/aedat2.h"
#include "fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  evio_fuzz::silence_log();
  evio_fuzz::MemFile file(data, size);
  if (!file.ok()) return 0;
  try {
    auto reader = evio::open_aedat2_dataset(file.path());
    evio::EventBuffer events;
    while (reader->read_events(&events, 4096) > 0) events.clear();
    reader->read_triggers();
  } catch (const evio::InputError&) {
  }
  return 0;
}
