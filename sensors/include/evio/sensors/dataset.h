// One interface over recorded datasets: format detection (by folder layout, extension and, for
// binary formats, magic bytes) with an override, a streaming event source, and whole-file access
// to IMU, frames, triggers, ground truth and calibration. Formats: ECD text folder, a bare ECD
// events.txt, HDF5 (DSEC and configurable layouts), AEDAT 4.0, Prophesee EVT 2.0/3.0, ROS1 bag,
// ROS 2 bag (rosbag2: SQLite3 or MCAP storage), jAER AEDAT 2.0.
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
  kEcdFolder,  // "ecd": folder with events.txt or, without it, events_undistorted.txt (sub-pixel);
               // [imu.txt groundtruth.txt images.txt calib.txt]
  kEcdEvents,  // "ecd-events": a single text file of `t x y p` lines (integer or sub-pixel x y)
  kHdf5,       // "h5": HDF5 events (DSEC/TUM-VIE layout or a configured layout)
  kAedat4,     // "aedat4": iniVation AEDAT 4.0
  kEvt2,       // "evt2": Prophesee RAW EVT 2.0
  kEvt3,       // "evt3": Prophesee RAW EVT 3.0
  kRosbag,     // "rosbag": ROS1 bag v2.0
  kAedat2,     // "aedat2": jAER AEDAT 2.0 (DVS128)
  kRosbag2,    // "rosbag2": ROS 2 bag folder (metadata.yaml + .db3 / .mcap files) or one .db3 / .mcap file
};
const char* dataset_format_name(DatasetFormat f);
std::optional<DatasetFormat> dataset_format_from_name(const std::string& name);
// All formats but kAuto, in declaration order (for help texts and tests).
const std::vector<DatasetFormat>& all_dataset_formats();

// HDF5 layout: where the event arrays are and how to read them. The default is DSEC/TUM-VIE
// (`events/x`, `events/y`, `events/t` in us relative to `t_offset`, `events/p` 0/1, `ms_to_idx`).
struct H5Layout {
  enum class Kind {
    kAuto,     // DSEC if events/t exists, else event_utils if events/ts exists, else MVSEC matrix
    kColumns,  // one 1-D dataset per field (DSEC, event_utils, custom names)
    kMatrix,   // one N x 4 dataset with columns x y t p (MVSEC: float64, t in s, polarity -1/+1)
  };
  Kind kind = Kind::kAuto;
  std::string x = "events/x", y = "events/y", t = "events/t", p = "events/p";  // kColumns datasets
  std::string matrix = "davis/left/events";  // kMatrix dataset
  std::string t_offset = "t_offset";         // optional scalar added to t (in the time unit); "" = none
  std::string ms_to_idx = "ms_to_idx";       // optional index: first event at or after each ms; "" = none
  TimeUnit time_unit = TimeUnit::kAuto;      // kAuto: us for DSEC, s for float ts / MVSEC
  PolarityConvention polarity = PolarityConvention::kUnknown;  // kUnknown: accept 0/1 and -1/+1
};

// ROS bag (ROS1 and rosbag2) topic selection; empty strings pick the single topic of the matching
// message type.
struct BagTopics {
  std::string events;  // dvs_msgs/EventArray, prophesee_event_msgs/EventArray or event_camera_msgs/EventPacket
  std::string imu;     // sensor_msgs/Imu
  std::string image;   // sensor_msgs/Image (mono8, mono16, rgb8, bgr8, rgba8, bgra8)
};

struct DatasetOptions {
  DatasetFormat format = DatasetFormat::kAuto;  // kAuto: detect_dataset_format()
  TextReadOptions text;                         // time unit, bad-line policy, sensor size for text formats
  // Sensor size assumed for an ECD calib.txt, which does not store it (DAVIS240C), px.
  SensorSize ecd_calib_sensor{240, 180};
  H5Layout h5;       // HDF5 layout (auto-detected by default)
  BagTopics topics;  // ROS bag topic selection (ROS1 and rosbag2)

  bool Validate(std::string* why) const;
};

// By folder layout (ECD files; rosbag2's metadata.yaml or .db3 / .mcap files), magic bytes (AEDAT
// "#!AER-DAT4.0", "#!AER-DAT2.0", "#ROSBAG V2.0", HDF5 signature, SQLite "SQLite format 3", MCAP
// "\x89MCAP0", Prophesee "% " header with its evt version) and extension. Throws InputError naming
// what was looked at when the format cannot be recognised.
DatasetFormat detect_dataset_format(const std::string& path);

// A named stream inside a container (bag topic, AEDAT4 stream), for `evio info`.
struct StreamInfo {
  std::string name;   // topic or stream name
  std::string type;   // message / stream type, e.g. "dvs_msgs/EventArray", "EVTS"
  int64_t messages = 0;  // messages / packets / elements in the file (-1 if unknown without a full pass)
  std::string count_unit = "messages";  // what `messages` counts: "messages", "packets", "elements"
  bool selected = false;  // read by this reader
};

class DatasetReader {
 public:
  virtual ~DatasetReader() = default;

  virtual DatasetFormat format() const = 0;
  virtual const std::string& path() const = 0;
  // Sensor size when the format or the options state it; {0, 0} when unknown.
  virtual SensorSize sensor_size() const = 0;

  // Streams events in time order: appends up to max_events, returns how many, 0 at the end.
  virtual size_t read_events(EventBuffer* out, size_t max_events) = 0;
  // The same stream as sub-pixel events; use one of read_events and read_subpixel_events per
  // reader. The default converts read_events' integer events, so every format supports it; the
  // ECD readers override it to take fractional, negative or out-of-sensor coordinates
  // (events_undistorted.txt), which read_events rejects.
  virtual size_t read_subpixel_events(std::vector<SubpixelEvent>* out, size_t max_events);
  // Fraction of the event stream consumed, in [0, 1].
  virtual double progress() const = 0;
  // Conventions the event reader applied (time unit, polarity mapping) and skipped lines.
  virtual const ReadReport& event_report() const = 0;

  // Positions the event stream so the next event returned is the first with t >= t_ns.
  // Returns false when the reader cannot seek (then the caller skips by reading); readers with
  // an index (HDF5 ms_to_idx) seek without reading the events before t_ns.
  virtual bool seek_events(int64_t /*t_ns*/) { return false; }

  // Whole-stream accessors; empty / nullopt when the dataset has none. They are independent of
  // the event stream's position.
  virtual std::vector<ImuSample> read_imu() = 0;
  // The IMU as a stream, for long recordings: appends up to max_samples samples in time order and
  // returns how many, 0 at the end; independent of the event stream and of read_imu(). ECD folders
  // read imu.txt as they go (memory bounded by max_samples); the default hands out read_imu()'s
  // samples, loaded whole on the first call.
  virtual size_t read_imu_samples(std::vector<ImuSample>* out, size_t max_samples);
  // Frames in time order. Containers fill Frame::image; file-based formats (ECD) give Frame::path
  // only, to be decoded with load_frame_image().
  virtual std::vector<Frame> read_frames() = 0;
  virtual std::vector<Trigger> read_triggers() { return {}; }
  virtual std::optional<Trajectory> read_groundtruth() = 0;
  virtual std::optional<calib::CameraCalibration> read_calibration() = 0;
  // Streams/topics inside the container with their types; empty for single-stream formats.
  virtual std::vector<StreamInfo> streams() const { return {}; }

 private:
  std::optional<std::vector<ImuSample>> imu_stream_;  // the default read_imu_samples()
  size_t imu_stream_next_ = 0;
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
  int64_t triggers = 0;
  int64_t triggers_rising = 0, triggers_falling = 0;  // by Trigger::polarity (+1 / -1)
  std::vector<StreamInfo> streams;
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
