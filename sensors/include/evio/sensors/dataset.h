// One interface over recorded datasets: format detection (by folder layout, extension and, for
// binary formats, magic bytes) with an override, a streaming event source, and whole-file access
// to IMU, frames, ground truth and calibration. Formats: ECD text folder, a bare ECD events.txt.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "evio/calib/calibration_io.h"
#include "evio/sensors/event_buffer.h"
#include "evio/sensors/measurements.h"
#include "evio/sensors/text_read_options.h"
#include "evio/sensors/trajectory.h"

namespace evio {

enum class DatasetFormat {
  kAuto,
  kEcdFolder,  // folder with events.txt [imu.txt groundtruth.txt images.txt calib.txt]
  kEcdEvents,  // a single text file of `t x y p` lines
};
const char* dataset_format_name(DatasetFormat f);  // "auto", "ecd", "ecd-events"
std::optional<DatasetFormat> dataset_format_from_name(const std::string& name);

struct DatasetOptions {
  DatasetFormat format = DatasetFormat::kAuto;  // kAuto: detect_dataset_format()
  TextReadOptions text;                         // time unit, bad-line policy, sensor size for text formats
  // Sensor size assumed for an ECD calib.txt, which does not store it (DAVIS240C), px.
  SensorSize ecd_calib_sensor{240, 180};

  bool Validate(std::string* why) const;
};

// Throws InputError naming what was looked at when the format cannot be recognised.
DatasetFormat detect_dataset_format(const std::string& path);

class DatasetReader {
 public:
  virtual ~DatasetReader() = default;

  virtual DatasetFormat format() const = 0;
  virtual const std::string& path() const = 0;
  // Sensor size when the format or the options state it; {0, 0} when unknown.
  virtual SensorSize sensor_size() const = 0;

  // Streams events in time order: appends up to max_events, returns how many, 0 at the end.
  virtual size_t read_events(EventBuffer* out, size_t max_events) = 0;
  // Fraction of the event stream consumed, in [0, 1].
  virtual double progress() const = 0;
  // Conventions the event reader applied (time unit, polarity mapping) and skipped lines.
  virtual const ReadReport& event_report() const = 0;

  // Whole-stream accessors; empty / nullopt when the dataset has none.
  virtual std::vector<ImuSample> read_imu() = 0;
  virtual std::vector<Frame> read_frames() = 0;  // references; decode with load_frame_image()
  virtual std::optional<Trajectory> read_groundtruth() = 0;
  virtual std::optional<calib::CameraCalibration> read_calibration() = 0;
};

std::unique_ptr<DatasetReader> open_dataset(const std::string& path, const DatasetOptions& options = {});

// What `evio info` prints: one streaming pass over the events plus the side streams.
struct DatasetSummary {
  std::string path;
  DatasetFormat format = DatasetFormat::kAuto;
  SensorSize sensor;                 // stated by the dataset/options; {0,0} if unknown
  ReadReport events_report;
  EventStatistics events;
  int64_t imu_samples = 0;
  int64_t imu_t_first_ns = 0, imu_t_last_ns = 0;
  int64_t frames = 0;
  int64_t frames_t_first_ns = 0, frames_t_last_ns = 0;
  int frame_width = 0, frame_height = 0;  // of the first frame, 0 if none
  int64_t poses = 0;
  int64_t gt_t_first_ns = 0, gt_t_last_ns = 0;
  double gt_path_length_m = 0;
  std::optional<calib::CameraCalibration> calibration;

  // Mean rate of n samples over [t_first, t_last], Hz (0 if fewer than 2).
  static double rate_hz(int64_t n, int64_t t_first_ns, int64_t t_last_ns);
};

// progress(fraction in [0,1]) is called about every 1% of the event stream when given.
DatasetSummary summarize_dataset(DatasetReader* reader, const std::function<void(double)>& progress = {});

}  // namespace evio
