// libFuzzer target for the HDF5 event reader: the input bytes as an in-memory file opened with
// open_h5_dataset() (layout auto-detected), every event read, then a few seeks. Only
// evio::InputError may escape the reader and no HDF5 handle may stay open. The HDF5 library itself
// parses the container, so a crash inside libhdf5 is reported as such (its stack names libhdf5).
#include <cstddef>
#include <cstdint>

#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio/sensors/h5.h"
#include "fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  evio_fuzz::silence_log();
  evio_fuzz::MemFile file(data, size);
  if (!file.ok()) return 0;
  for (const evio::BadLinePolicy policy : {evio::BadLinePolicy::kError, evio::BadLinePolicy::kWarnAndSkip}) {
    try {
      evio::DatasetOptions options;
      options.format = evio::DatasetFormat::kHdf5;
      options.text.on_bad_line = policy;
      std::unique_ptr<evio::DatasetReader> reader = evio::open_h5_dataset(file.path(), options);
      evio::EventBuffer events;
      int64_t total = 0;
      while (reader->read_events(&events, 4096) > 0) {
        total += static_cast<int64_t>(events.size());
        events.clear();
      }
      (void)reader->event_report().summary();
      (void)reader->streams();
      (void)reader->read_imu();
      (void)reader->read_frames();
      (void)reader->read_triggers();
      (void)reader->read_groundtruth();
      (void)reader->read_calibration();
      for (const int64_t t : {int64_t{0}, int64_t{1000000}, int64_t{-5}, int64_t{1} << 62}) {
        reader->seek_events(t);
        events.clear();
        reader->read_events(&events, 16);
      }
      (void)total;
    } catch (const evio::InputError&) {
    }
    // Every HDF5 handle the reader opened is closed again (libhdf5's own allocations on its
    // error paths are outside our control; handles are not).
    if (evio::h5_open_object_count() != 0) __builtin_trap();
  }
  return 0;
}
