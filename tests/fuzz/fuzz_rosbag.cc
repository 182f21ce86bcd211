// libFuzzer target: the ROS1 bag reader (container, chunk decompression, message decoding) on
// arbitrary bytes, with the bad-data policy set to skip so the whole file is exercised.
#include <cstdint>

#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio/sensors/rosbag.h"
#include "fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  evio_fuzz::silence_log();
  evio_fuzz::MemFile file(data, size);
  if (!file.ok()) return 0;
  for (const auto policy : {evio::BadLinePolicy::kError, evio::BadLinePolicy::kWarnAndSkip}) {
    try {
      evio::DatasetOptions options;
      options.format = evio::DatasetFormat::kRosbag;
      options.text.on_bad_line = policy;
      auto reader = evio::open_rosbag_dataset(file.path(), options);
      reader->streams();
      evio::EventBuffer events;
      while (reader->read_events(&events, 4096) > 0) events.clear();
      reader->read_triggers();
      reader->read_imu();
      reader->read_frames();
    } catch (const evio::InputError&) {
    }
  }
  return 0;
}
