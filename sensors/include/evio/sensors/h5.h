// HDF5 event files (HDF5 C API 1.10): a streaming reader for the DSEC / TUM-VIE layout
// (`events/{x,y,t,p}`, `t_offset`, `ms_to_idx`), the event_utils / E2VID layout (`events/{xs,ys,ts,ps}`)
// and the MVSEC layout (`davis/left/events`, N x 4 float64 columns x, y, t[s], p -1/+1), and a
// writer of evio's own files in the DSEC layout with a `unit` attribute that keeps int64 ns exact.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "evio/sensors/dataset.h"
#include "evio/sensors/event_buffer.h"
#include "evio/sensors/measurements.h"
#include "evio/sensors/time.h"

namespace evio {

// Opens an HDF5 event file for streaming. The layout is options.h5 (auto-detected by default: DSEC
// when the dataset options.h5.t exists, else event_utils when `events/ts` exists, else the
// options.h5.matrix dataset; otherwise an InputError lists the top-level objects found).
//  - Columns may have any integer, float or enum (h5py bool) type; x and y must be whole numbers in
//    [0, 65535], p one of 0/1 or -1/+1 (options.h5.polarity can require one convention).
//  - Time unit: options.h5.time_unit, else options.text.time_unit, else the string attribute `unit`
//    ("s", "ms", "us", "ns") of the time dataset, else s for float timestamps and us for integer
//    ones (DSEC), ns for integers above 1e17. `t_offset` (scalar, optional) is added to every t,
//    in its own `unit` attribute or else in the unit of t.
//  - Sensor size: root (or `events` group) attributes or scalar datasets `width`/`height` or
//    `sensor_width`/`sensor_height`, else options.text.sensor, else unknown.
//  - Bad data (time going backwards, pixel outside the sensor, polarity not 0/1/-1/+1, non-finite
//    or non-integer values) follows options.text.on_bad_line; errors name the event index.
//  - A dataset compressed with a filter that is not available (e.g. Blosc, id 32001, without its
//    plugin) is an InputError naming the dataset, the filter and how to install it.
// Throws InputError when the file is missing, not HDF5, truncated or of an unknown layout.
std::unique_ptr<DatasetReader> open_h5_dataset(const std::string& path, const DatasetOptions& options = {});

// Number of HDF5 objects (files, groups, datasets, types, attributes) open in this process: 0
// when no reader or writer exists; tests and the fuzzer use it to check that nothing leaks.
int64_t h5_open_object_count();

// The reader behind open_h5_dataset(), for callers that want its HDF5-specific diagnostics.
class H5EventReader final : public DatasetReader {
 public:
  // What the last seek_events() call did (for tests and `evio info`).
  struct SeekStats {
    bool used_index = false;    // ms_to_idx bracketed the position
    int64_t index_values_read = 0;  // ms_to_idx entries read
    int64_t t_values_read = 0;      // timestamps read (binary search and the final scan)
  };

  H5EventReader(const std::string& path, const DatasetOptions& options);
  ~H5EventReader() override;
  H5EventReader(const H5EventReader&) = delete;
  H5EventReader& operator=(const H5EventReader&) = delete;

  DatasetFormat format() const override { return DatasetFormat::kHdf5; }
  const std::string& path() const override;
  SensorSize sensor_size() const override;
  size_t read_events(EventBuffer* out, size_t max_events) override;
  double progress() const override;
  const ReadReport& event_report() const override;
  // Uses ms_to_idx when present (reading only the index entries and the timestamps of one
  // millisecond), else a binary search on the time dataset; always returns true.
  bool seek_events(int64_t t_ns) override;

  // HDF5 event files carry no IMU, frames, triggers, ground truth or calibration.
  std::vector<ImuSample> read_imu() override { return {}; }
  std::vector<Frame> read_frames() override { return {}; }
  std::optional<Trajectory> read_groundtruth() override { return std::nullopt; }
  std::optional<calib::CameraCalibration> read_calibration() override { return std::nullopt; }
  // The datasets read (name, element type and unit, element count).
  std::vector<StreamInfo> streams() const override;

  // "DSEC", "event_utils", "MVSEC", "columns" or "matrix" (the last two for configured layouts).
  const std::string& layout_name() const;
  // Number of events in the file (length of the columns).
  int64_t event_count() const;
  const SeekStats& last_seek_stats() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Options of H5EventWriter. Units in the comments.
struct H5WriteOptions {
  enum class Compression {
    kNone,   // plain chunks (fastest to read)
    kGzip,   // HDF5 byte shuffle + deflate (built into every HDF5)
    kBlosc,  // Blosc filter 32001 (LZ4, byte shuffle); needs the plugin (Debian hdf5-filter-plugin-blosc-serial)
  };
  // Unit of events/t and t_offset: kNanoseconds (lossless for evio's int64 ns) or kMicroseconds
  // (DSEC's unit; times not on a whole microsecond are rounded half up and counted).
  TimeUnit time_unit = TimeUnit::kNanoseconds;
  Compression compression = Compression::kNone;
  int gzip_level = 4;                  // deflate level, 1..9 (kGzip)
  int blosc_level = 5;                 // Blosc clevel, 1..9 (kBlosc)
  int64_t chunk_events = int64_t{1} << 16;  // events per HDF5 chunk, 1024..2^24
  SensorSize sensor;                   // written as root attributes `width`/`height` (px) when known

  bool Validate(std::string* why) const;
};
const char* h5_compression_name(H5WriteOptions::Compression c);  // "none", "gzip", "blosc"

// Streams events into a new HDF5 file in the DSEC layout: events/x, events/y (uint16), events/p
// (uint8, 1 = ON, 0 = OFF), events/t (int64, relative to t_offset, string attribute `unit` "ns" or
// "us"), t_offset (int64 scalar = the first event's time, same `unit` attribute) and ms_to_idx
// (uint64: index of the first event with t - t_offset >= i ms), all chunked and extendible.
// Events must come in non-decreasing time. Errors (HDF5, disk full, order) throw InputError.
class H5EventWriter {
 public:
  using Options = H5WriteOptions;

  // Creates (truncates) the file; throws InputError on invalid options, an unavailable Blosc
  // filter or when the file cannot be created.
  explicit H5EventWriter(const std::string& path, const Options& options = {});
  // Closes silently when close() was not called (errors are lost then).
  ~H5EventWriter();
  H5EventWriter(const H5EventWriter&) = delete;
  H5EventWriter& operator=(const H5EventWriter&) = delete;

  void write(EventSpan events);
  // Flushes the buffers, writes t_offset and the attributes and closes the file; returns the
  // number of events whose time was rounded to whole microseconds (0 with kNanoseconds).
  // Throws InputError on failure. Further calls do nothing and return the same count.
  int64_t close();

  int64_t events_written() const;
  int64_t rounded_events() const;
  const std::string& path() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace evio
