#include "evio/sensors/dataset.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio/sensors/aedat2.h"
#include "evio/sensors/aedat4.h"
#include "evio/sensors/ecd.h"
#include "evio/sensors/evt.h"
#include "evio/sensors/h5.h"
#include "evio/sensors/rosbag.h"
#include "evio/sensors/rosbag2.h"

namespace evio {
namespace fs = std::filesystem;

const char* dataset_format_name(DatasetFormat f) {
  switch (f) {
    case DatasetFormat::kAuto: return "auto";
    case DatasetFormat::kEcdFolder: return "ecd";
    case DatasetFormat::kEcdEvents: return "ecd-events";
    case DatasetFormat::kHdf5: return "h5";
    case DatasetFormat::kAedat4: return "aedat4";
    case DatasetFormat::kEvt2: return "evt2";
    case DatasetFormat::kEvt3: return "evt3";
    case DatasetFormat::kRosbag: return "rosbag";
    case DatasetFormat::kAedat2: return "aedat2";
    case DatasetFormat::kRosbag2: return "rosbag2";
  }
  return "?";
}

const std::vector<DatasetFormat>& all_dataset_formats() {
  static const std::vector<DatasetFormat> all = {
      DatasetFormat::kEcdFolder, DatasetFormat::kEcdEvents, DatasetFormat::kHdf5,   DatasetFormat::kAedat4,
      DatasetFormat::kEvt2,      DatasetFormat::kEvt3,      DatasetFormat::kRosbag, DatasetFormat::kAedat2,
      DatasetFormat::kRosbag2};
  return all;
}

std::optional<DatasetFormat> dataset_format_from_name(const std::string& name) {
  if (name == "auto") return DatasetFormat::kAuto;
  for (DatasetFormat f : all_dataset_formats()) {
    if (name == dataset_format_name(f)) return f;
  }
  return std::nullopt;
}

bool DatasetOptions::Validate(std::string* why) const {
  if (!text.Validate(why)) return false;
  if (ecd_calib_sensor.width <= 0 || ecd_calib_sensor.height <= 0) {
    if (why != nullptr) *why = "ecd_calib_sensor must be a positive size in px";
    return false;
  }
  return true;
}

DatasetFormat detect_dataset_format(const std::string& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw InputError(path, 0, "no such file or directory", "a dataset folder or file");
  if (fs::is_directory(path, ec)) {
    if (fs::is_regular_file(fs::path(path) / "events.txt", ec) ||
        fs::is_regular_file(fs::path(path) / "events_undistorted.txt", ec)) {
      return DatasetFormat::kEcdFolder;
    }
    if (is_rosbag2_folder(path)) return DatasetFormat::kRosbag2;
    throw InputError(path, 0, "folder of unknown layout (no events.txt, events_undistorted.txt or metadata.yaml)",
                     "an Event Camera Dataset folder (events.txt or events_undistorted.txt "
                     "[imu.txt groundtruth.txt images.txt calib.txt]) or a ROS 2 bag folder (metadata.yaml, "
                     ".db3 or .mcap files)");
  }
  // Magic bytes first, extension second.
  char head[16] = {};
  if (std::FILE* f = std::fopen(path.c_str(), "rb")) {
    const size_t n = std::fread(head, 1, sizeof(head), f);
    std::fclose(f);
    const std::string h(head, n);
    if (h.rfind("#!AER-DAT4", 0) == 0) return DatasetFormat::kAedat4;
    if (h.rfind("#!AER-DAT", 0) == 0) return DatasetFormat::kAedat2;  // the reader names unsupported versions
    if (h.rfind("#ROSBAG V2.0", 0) == 0) return DatasetFormat::kRosbag;
    if (h.rfind("\x89HDF\r\n\x1a\n", 0) == 0) return DatasetFormat::kHdf5;
    if (h.rfind(std::string("SQLite format 3\0", 16), 0) == 0) return DatasetFormat::kRosbag2;
    if (h.rfind("\x89MCAP0\r\n", 0) == 0) return DatasetFormat::kRosbag2;
    if (h.rfind("%", 0) == 0) {
      const EvtRawHeader header = parse_evt_raw_header(path);
      if (header.version == 2) return DatasetFormat::kEvt2;
      if (header.version == 3) return DatasetFormat::kEvt3;
      throw InputError(path, 0,
                       header.version_text.empty() ? "Prophesee RAW header names no EVT version"
                                                   : "Prophesee RAW version '" + header.version_text + "' is not supported",
                       "EVT 2.0 or 3.0 ('% evt 2.0|3.0' or '% format EVT2|EVT3'); for a header without a version "
                       "give --format evt2|evt3");
    }
  } else {
    throw InputError(path, 0, std::string("cannot open: ") + std::strerror(errno), "a readable dataset file");
  }
  // HDF5 files with a user block carry the signature at 512, 1024, 2048, ... bytes.
  if (std::FILE* f = std::fopen(path.c_str(), "rb")) {
    bool hdf5 = false;
    for (long off = 512; off <= (long{1} << 30) && !hdf5; off *= 2) {
      char sig[8];
      if (std::fseek(f, off, SEEK_SET) != 0 || std::fread(sig, 1, 8, f) != 8) break;
      hdf5 = std::memcmp(sig, "\x89HDF\r\n\x1a\n", 8) == 0;
    }
    std::fclose(f);
    if (hdf5) return DatasetFormat::kHdf5;
  }
  const std::string ext = fs::path(path).extension().string();
  if (ext == ".h5" || ext == ".hdf5" || ext == ".hdf") return DatasetFormat::kHdf5;
  if (ext == ".txt" || ext == ".dat" || ext == ".csv") return DatasetFormat::kEcdEvents;
  if (fs::path(path).filename() == "metadata.yaml" || ext == ".db3" || ext == ".mcap") return DatasetFormat::kRosbag2;
  throw InputError(path, 0, "unknown file format (no known magic bytes, extension '" + ext + "')",
                   "an ECD folder or events .txt, HDF5, AEDAT 4.0/2.0, Prophesee RAW EVT 2.0/3.0, ROS1 bag or ROS 2 bag; "
                   "or name the format with --format");
}

size_t DatasetReader::read_subpixel_events(std::vector<SubpixelEvent>* out, size_t max_events) {
  EventBuffer chunk;
  const size_t n = read_events(&chunk, max_events);
  out->reserve(out->size() + n);
  for (const Event& e : chunk) out->push_back(to_subpixel(e));
  return n;
}

size_t DatasetReader::read_imu_samples(std::vector<ImuSample>* out, size_t max_samples) {
  if (!imu_stream_) imu_stream_ = read_imu();
  const size_t n = std::min(max_samples, imu_stream_->size() - imu_stream_next_);
  out->insert(out->end(), imu_stream_->begin() + static_cast<std::ptrdiff_t>(imu_stream_next_),
              imu_stream_->begin() + static_cast<std::ptrdiff_t>(imu_stream_next_ + n));
  imu_stream_next_ += n;
  if (imu_stream_next_ == imu_stream_->size()) {  // all handed out: free them
    *imu_stream_ = std::vector<ImuSample>();
    imu_stream_next_ = 0;
  }
  return n;
}

namespace {

// ECD folder, or a bare events file (then only events).
class EcdDatasetReader final : public DatasetReader {
 public:
  EcdDatasetReader(const std::string& path, DatasetFormat format, const DatasetOptions& options)
      : format_(format), path_(path), options_(options) {
    if (format == DatasetFormat::kEcdFolder) {
      folder_ = find_ecd_folder(path);
    } else {
      folder_.events = path;
    }
    events_ = std::make_unique<EcdEventReader>(folder_.events, options_.text);
    log_info(folder_.events + ": time unit " + time_unit_name(events_->time_unit()) + " (" +
             events_->report().time_unit_reason + ")");
  }

  DatasetFormat format() const override { return format_; }
  const std::string& path() const override { return path_; }
  SensorSize sensor_size() const override { return options_.text.sensor; }
  size_t read_events(EventBuffer* out, size_t max_events) override { return events_->read(out, max_events); }
  size_t read_subpixel_events(std::vector<SubpixelEvent>* out, size_t max_events) override {
    return events_->read_subpixel(out, max_events);
  }
  double progress() const override { return events_->progress(); }
  const ReadReport& event_report() const override { return events_->report(); }

  std::vector<ImuSample> read_imu() override {
    return folder_.imu.empty() ? std::vector<ImuSample>() : read_ecd_imu(folder_.imu, side_options());
  }
  size_t read_imu_samples(std::vector<ImuSample>* out, size_t max_samples) override {
    if (folder_.imu.empty()) return 0;
    if (!imu_stream_) imu_stream_ = std::make_unique<EcdImuReader>(folder_.imu, side_options());
    return imu_stream_->read(out, max_samples);
  }
  std::vector<Frame> read_frames() override {
    return folder_.images.empty() ? std::vector<Frame>() : read_ecd_image_list(folder_.images, side_options());
  }
  std::optional<Trajectory> read_groundtruth() override {
    if (folder_.groundtruth.empty()) return std::nullopt;
    return read_tum(folder_.groundtruth, side_options());
  }
  std::optional<calib::CameraCalibration> read_calibration() override {
    if (folder_.calib.empty()) return std::nullopt;
    const SensorSize s = options_.text.sensor.known() ? options_.text.sensor : options_.ecd_calib_sensor;
    return calib::load_ecd_calib(folder_.calib, s.width, s.height);
  }

 private:
  // Side files of an ECD folder are in seconds like events.txt; each file still detects its unit.
  TextReadOptions side_options() const {
    TextReadOptions o = options_.text;
    o.sensor = SensorSize{};
    return o;
  }

  DatasetFormat format_;
  std::string path_;
  DatasetOptions options_;
  EcdFolder folder_;
  std::unique_ptr<EcdEventReader> events_;
  std::unique_ptr<EcdImuReader> imu_stream_;
};

}  // namespace

std::unique_ptr<DatasetReader> open_dataset(const std::string& path, const DatasetOptions& options) {
  std::string why;
  if (!options.Validate(&why)) throw InputError(path, 0, "invalid dataset options: " + why);
  const DatasetFormat f = options.format == DatasetFormat::kAuto ? detect_dataset_format(path) : options.format;
  switch (f) {
    case DatasetFormat::kEcdFolder:
    case DatasetFormat::kEcdEvents:
      return std::make_unique<EcdDatasetReader>(path, f, options);
    case DatasetFormat::kAedat2:
      return open_aedat2_dataset(path, options);
    case DatasetFormat::kAedat4:
      return open_aedat4_dataset(path, options);
    case DatasetFormat::kEvt2:
    case DatasetFormat::kEvt3:
      return open_evt_dataset(path, options);  // the RAW header names the version
    case DatasetFormat::kHdf5:
      return open_h5_dataset(path, options);
    case DatasetFormat::kRosbag:
      return open_rosbag_dataset(path, options);
    case DatasetFormat::kRosbag2:
      return open_rosbag2_dataset(path, options);
    case DatasetFormat::kAuto:
      break;
  }
  throw InputError(path, 0, "no reader for this format");
}

double DatasetSummary::rate_hz(int64_t n, int64_t t_first_ns, int64_t t_last_ns) {
  if (n < 2 || t_last_ns <= t_first_ns) return 0.0;
  return static_cast<double>(n - 1) / (static_cast<double>(t_last_ns - t_first_ns) * 1e-9);
}

DatasetSummary summarize_dataset(DatasetReader* reader, const std::function<void(double)>& progress) {
  DatasetSummary s;
  s.path = reader->path();
  s.format = reader->format();
  s.sensor = reader->sensor_size();
  EventBuffer chunk;
  double next_report = 0.01;
  for (;;) {
    chunk.clear();
    if (reader->read_events(&chunk, size_t{1} << 18) == 0) break;
    s.events.add(chunk.span());
    if (progress && reader->progress() >= next_report) {
      progress(reader->progress());
      next_report = reader->progress() + 0.01;
    }
  }
  s.events_report = reader->event_report();
  const std::vector<ImuSample> imu = reader->read_imu();
  s.imu_samples = static_cast<int64_t>(imu.size());
  if (!imu.empty()) {
    s.imu_t_first_ns = imu.front().t_ns;
    s.imu_t_last_ns = imu.back().t_ns;
  }
  std::vector<Frame> frames = reader->read_frames();
  s.frames = static_cast<int64_t>(frames.size());
  if (!frames.empty()) {
    s.frames_t_first_ns = frames.front().t_ns;
    s.frames_t_last_ns = frames.back().t_ns;
    if (frames.front().image.empty()) load_frame_image(&frames.front());  // file-based formats (ECD)
    s.frame_width = frames.front().image.cols;
    s.frame_height = frames.front().image.rows;
  }
  const std::vector<Trigger> triggers = reader->read_triggers();
  s.triggers = static_cast<int64_t>(triggers.size());
  for (const Trigger& t : triggers) (t.polarity > 0 ? s.triggers_rising : s.triggers_falling) += 1;
  s.streams = reader->streams();
  if (const auto gt = reader->read_groundtruth()) {
    s.poses = static_cast<int64_t>(gt->size());
    s.gt_t_first_ns = gt->t_begin_ns();
    s.gt_t_last_ns = gt->t_end_ns();
    s.gt_path_length_m = gt->path_length_m();
  }
  s.calibration = reader->read_calibration();
  return s;
}

}  // namespace evio
