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
  if (to == ConvertTarget::kEcd) {
    std::error_code ec;
    fs::create_directories(args.out, ec);
    if (!fs::is_directory(args.out, ec)) throw InputError(args.out, 0, "cannot create output folder", "a writable folder path");
  } else if (!fs::path(args.out).parent_path().empty()) {
    std::error_code ec;
    fs::create_directories(fs::path(args.out).parent_path(), ec);
  }

  // Events: seek when the reader has an index, else skip by reading; stop at t_end.
  if (args.t_start_ns) reader->seek_events(*args.t_start_ns);
  // Writers are opened after the first chunk, when the input's polarity convention and the
  // sensor size are known.
  std::unique_ptr<EcdEventWriter> ecd_writer;
  std::unique_ptr<H5EventWriter> h5_writer;
  auto open_writer = [&] {
    if (to == ConvertTarget::kH5) {
      H5WriteOptions o;
      o.time_unit = args.h5_time_unit;
      o.compression = args.h5_compression == "gzip"    ? H5WriteOptions::Compression::kGzip
                      : args.h5_compression == "blosc" ? H5WriteOptions::Compression::kBlosc
                                                       : H5WriteOptions::Compression::kNone;
      o.sensor = reader->sensor_size();
      h5_writer = std::make_unique<H5EventWriter>(args.out, o);
      return;
    }
    PolarityConvention pol = args.polarity;
    if (pol == PolarityConvention::kUnknown) {
      pol = reader->event_report().polarity == PolarityConvention::kMinusPlusOne ? PolarityConvention::kMinusPlusOne
                                                                                  : PolarityConvention::kZeroOne;
    }
    ecd_writer = std::make_unique<EcdEventWriter>((fs::path(args.out) / "events.txt").string(), pol);
  };
  EventBuffer chunk;
  EventStatistics written;
  Progress progress("evio convert", args.progress, "events written", 2.0);
  bool past_end = false;
  bool opened = false;
  while (!past_end) {
    chunk.clear();
    const size_t got = reader->read_events(&chunk, size_t{1} << 20);
    if (!opened) {
      open_writer();
      opened = true;
    }
    if (got == 0) break;
    EventSpan s = chunk.span();
    if (args.t_start_ns || args.t_end_ns) {
      const int64_t lo = args.t_start_ns.value_or(INT64_MIN);
      const int64_t hi = args.t_end_ns.value_or(INT64_MAX);
      past_end = !s.empty() && s.back().t_ns >= hi;
      s = s.slice(lo, hi);
    }
    if (h5_writer) {
      h5_writer->write(s);
    } else {
      ecd_writer->write(s);
    }
    written.add(s);
    progress.update(reader->progress(), written.count);
  }
  if (!opened) open_writer();

  if (h5_writer) {
    const int64_t rounded = h5_writer->close();
    out << "wrote " << args.out << " (HDF5, DSEC layout, t in " << time_unit_name(args.h5_time_unit) << ", "
        << args.h5_compression << "): " << written.count << " events";
    if (written.count > 0) {
      out << " " << format_seconds(written.t_first_ns) << " .. " << format_seconds(written.t_last_ns) << " s";
    }
    if (rounded > 0) out << ", " << rounded << " timestamps rounded to whole microseconds";
    out << "\n";
    // The DSEC layout holds events only: say what the input had besides them.
    const size_t imu = reader->read_imu().size(), frames = reader->read_frames().size(),
                 triggers = reader->read_triggers().size();
    const auto gt = reader->read_groundtruth();
    if (imu + frames + triggers > 0 || (gt && !gt->empty())) {
      log_warning("HDF5 output holds events only; not written: " + std::to_string(imu) + " IMU samples, " +
                  std::to_string(frames) + " frames, " + std::to_string(triggers) + " triggers, " +
                  std::to_string(gt ? gt->size() : 0) + " poses (convert to an ECD folder to keep them)");
    }
    return 0;
  }
  ecd_writer->close();

  // Side streams, sliced to the same window.
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

  out << "wrote " << args.out << " (ECD folder): " << written.count << " events";
  if (written.count > 0) {
    out << " " << format_seconds(written.t_first_ns) << " .. " << format_seconds(written.t_last_ns) << " s";
  }
  out << ", " << imu.size() << " IMU samples, " << frames.size() << " frames, " << triggers.size() << " triggers, "
      << poses << " poses" << (calib_written ? ", calib.txt" : "") << "\n";
  return 0;
}

}  // namespace evio::apps
