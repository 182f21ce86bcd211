#include "convert_command.h"
#include "progress.h"

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <ostream>

#include "evio/calib/calibration_io.h"
#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio/sensors/ecd.h"
#include "evio/sensors/h5.h"
#include "evio/sensors/time.h"

namespace evio::apps {
namespace {
namespace fs = std::filesystem;

bool in_window(int64_t t, const ConvertArgs& a) {
  return (!a.t_start_ns || t >= *a.t_start_ns) && (!a.t_end_ns || t < *a.t_end_ns);
}

void write_triggers_txt(const std::string& path, const std::vector<Trigger>& triggers) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) throw InputError(path, 0, "cannot create", "a writable path");
  bool ok = std::fputs("# t[s] channel polarity(+1 rising, -1 falling)\n", f) >= 0;
  for (const Trigger& t : triggers) {
    ok = ok && std::fprintf(f, "%s %d %d\n", format_seconds(t.t_ns).c_str(), t.channel, t.polarity) > 0;
  }
  ok = (std::fclose(f) == 0) && ok;
  if (!ok) throw InputError(path, 0, "write failed", "a writable path with free space");
}

// The events into one writer (ECD events.txt or HDF5), opened after the first chunk, when the
// input's polarity convention and the sensor size are known. Seeks when the reader has an index,
// else skips by reading; stops at t_end.
class EventSink {
 public:
  EventSink(const ConvertArgs& args, ConvertTarget to, DatasetReader* reader) : args_(args), to_(to), reader_(reader) {}

  EventStatistics copy() {
    if (args_.t_start_ns) reader_->seek_events(*args_.t_start_ns);
    EventBuffer chunk;
    EventStatistics written;
    Progress progress("evio convert", args_.progress, "events written", 2.0);
    bool past_end = false;
    while (!past_end) {
      chunk.clear();
      const size_t got = reader_->read_events(&chunk, size_t{1} << 20);
      open();
      if (got == 0) break;
      EventSpan s = chunk.span();
      if (args_.t_start_ns || args_.t_end_ns) {
        const int64_t lo = args_.t_start_ns.value_or(INT64_MIN);
        const int64_t hi = args_.t_end_ns.value_or(INT64_MAX);
        past_end = !s.empty() && s.back().t_ns >= hi;
        s = s.slice(lo, hi);
      }
      if (h5_) {
        h5_->write(s);
      } else {
        ecd_->write(s);
      }
      written.add(s);
      progress.update(reader_->progress(), written.count);
    }
    open();
    return written;
  }
  // HDF5: the number of timestamps rounded to whole microseconds. ECD: 0.
  int64_t close() {
    if (h5_) return h5_->close();
    ecd_->close();
    return 0;
  }

 private:
  void open() {
    if (h5_ || ecd_) return;
    if (to_ == ConvertTarget::kH5) {
      H5WriteOptions o;
      o.time_unit = args_.h5_time_unit;
      o.compression = args_.h5_compression == "gzip"    ? H5WriteOptions::Compression::kGzip
                      : args_.h5_compression == "blosc" ? H5WriteOptions::Compression::kBlosc
                                                        : H5WriteOptions::Compression::kNone;
      o.sensor = reader_->sensor_size();
      h5_ = std::make_unique<H5EventWriter>(args_.out, o);
      return;
    }
    PolarityConvention pol = args_.polarity;
    if (pol == PolarityConvention::kUnknown) {
      pol = reader_->event_report().polarity == PolarityConvention::kMinusPlusOne ? PolarityConvention::kMinusPlusOne
                                                                                   : PolarityConvention::kZeroOne;
    }
    ecd_ = std::make_unique<EcdEventWriter>((fs::path(args_.out) / "events.txt").string(), pol);
  }

  const ConvertArgs& args_;
  ConvertTarget to_;
  DatasetReader* reader_;
  std::unique_ptr<EcdEventWriter> ecd_;
  std::unique_ptr<H5EventWriter> h5_;
};

// The DSEC layout holds events only: say what the input had besides them.
void warn_h5_drops(DatasetReader* reader) {
  const size_t imu = reader->read_imu().size(), frames = reader->read_frames().size(), triggers = reader->read_triggers().size();
  const auto gt = reader->read_groundtruth();
  if (imu + frames + triggers > 0 || (gt && !gt->empty())) {
    log_warning("HDF5 output holds events only; not written: " + std::to_string(imu) + " IMU samples, " +
                std::to_string(frames) + " frames, " + std::to_string(triggers) + " triggers, " +
                std::to_string(gt ? gt->size() : 0) + " poses (convert to an ECD folder to keep them)");
  }
}

// The side streams of an ECD folder, sliced to the same window; returns the summary's counts.
std::string write_side_streams(const ConvertArgs& args, DatasetReader* reader) {
  std::vector<ImuSample> imu;
  for (const ImuSample& s : reader->read_imu()) {
    if (in_window(s.t_ns, args)) imu.push_back(s);
  }
  if (!imu.empty()) write_ecd_imu((fs::path(args.out) / "imu.txt").string(), imu);
  std::vector<Frame> frames;
  for (Frame& f : reader->read_frames()) {
    if (in_window(f.t_ns, args)) frames.push_back(std::move(f));
  }
  if (!frames.empty()) write_ecd_images(args.out, frames);
  std::vector<Trigger> triggers;
  for (const Trigger& t : reader->read_triggers()) {
    if (in_window(t.t_ns, args)) triggers.push_back(t);
  }
  if (!triggers.empty()) write_triggers_txt((fs::path(args.out) / "triggers.txt").string(), triggers);
  int64_t poses = 0;
  if (const auto gt = reader->read_groundtruth()) {
    Trajectory sliced;
    for (const StampedPose& p : *gt) {
      if (in_window(p.t_ns, args)) sliced.push_back(p);
    }
    poses = static_cast<int64_t>(sliced.size());
    if (!sliced.empty()) write_tum((fs::path(args.out) / "groundtruth.txt").string(), sliced);
  }
  bool calib_written = false;
  if (const auto cal = reader->read_calibration()) {
    if (cal->camera.intrinsics().model != calib::DistortionModel::kEquidistant) {
      calib::write_ecd_calib((fs::path(args.out) / "calib.txt").string(), cal->camera);
      calib_written = true;
    } else {
      log_warning("calibration not written: ECD calib.txt cannot hold an equidistant model");
    }
  }
  return ", " + std::to_string(imu.size()) + " IMU samples, " + std::to_string(frames.size()) + " frames, " +
         std::to_string(triggers.size()) + " triggers, " + std::to_string(poses) + " poses" + (calib_written ? ", calib.txt" : "");
}

std::string event_span_text(const EventStatistics& written) {
  return written.count > 0 ? " " + format_seconds(written.t_first_ns) + " .. " + format_seconds(written.t_last_ns) + " s" : "";
}

}  // namespace

int run_convert(const ConvertArgs& args, std::ostream& out) {
  if (args.t_start_ns && args.t_end_ns && *args.t_end_ns <= *args.t_start_ns) {
    throw InputError("", 0, "--t-end must be after --t-start");
  }
  ConvertTarget to = args.to;
  if (to == ConvertTarget::kAuto) {
    const std::string ext = fs::path(args.out).extension().string();
    to = (ext == ".h5" || ext == ".hdf5") ? ConvertTarget::kH5 : ConvertTarget::kEcd;
  }
  auto reader = open_dataset(args.in, args.dataset);
  std::error_code ec;
  if (to == ConvertTarget::kEcd) {
    fs::create_directories(args.out, ec);
    if (!fs::is_directory(args.out, ec)) throw InputError(args.out, 0, "cannot create output folder", "a writable folder path");
  } else if (!fs::path(args.out).parent_path().empty()) {
    fs::create_directories(fs::path(args.out).parent_path(), ec);
  }
  EventSink sink(args, to, reader.get());
  const EventStatistics written = sink.copy();
  const int64_t rounded = sink.close();
  if (to == ConvertTarget::kH5) {
    out << "wrote " << args.out << " (HDF5, DSEC layout, t in " << time_unit_name(args.h5_time_unit) << ", "
        << args.h5_compression << "): " << written.count << " events" << event_span_text(written);
    if (rounded > 0) out << ", " << rounded << " timestamps rounded to whole microseconds";
    out << "\n";
    warn_h5_drops(reader.get());
    return 0;
  }
  const std::string side = write_side_streams(args, reader.get());
  out << "wrote " << args.out << " (ECD folder): " << written.count << " events" << event_span_text(written) << side << "\n";
  return 0;
}

}  // namespace evio::apps
