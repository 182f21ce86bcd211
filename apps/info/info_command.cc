#include "info_command.h"
#include "evio/calib/json.h"

#include <cinttypes>
#include <cstdio>
#include <filesystem>
#include <ostream>
#include <sstream>

#include "evio/sensors/time.h"

namespace evio::apps {
namespace {

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), f, v);
  return buf;
}

void print_text(const DatasetSummary& s, std::ostream& out) {
  const auto& ev = s.events;
  out << "path           " << s.path << "\n";
  out << "format         " << dataset_format_name(s.format) << "\n";
  if (s.sensor.known()) {
    out << "sensor         " << s.sensor.width << " x " << s.sensor.height << " px\n";
  } else if (ev.count > 0) {
    out << "sensor         unknown; events span x 0.." << ev.max_x << ", y 0.." << ev.max_y
        << " (give --sensor WxH to check bounds)\n";
  } else {
    out << "sensor         unknown\n";
  }
  out << "time unit      " << time_unit_name(s.events_report.time_unit) << " (" << s.events_report.time_unit_reason
      << ")\n";
  out << "events         " << ev.count << "\n";
  if (ev.count > 0) {
    out << "time span      " << format_seconds(ev.t_first_ns) << " .. " << format_seconds(ev.t_last_ns) << " s\n";
    out << "duration       " << fmt("%.6f", ns_to_seconds(ev.duration_ns())) << " s\n";
    out << "event rate     " << fmt("%.4g", ev.rate_hz() / 1e6) << " Mev/s (mean)\n";
    out << "polarity       " << ev.on << " ON / " << ev.off << " OFF (" << fmt("%.1f", 100.0 * ev.on_fraction())
        << "% ON), file convention " << polarity_convention_name(s.events_report.polarity) << "\n";
  }
  if (s.events_report.skipped_total() > 0) {
    out << "skipped lines  " << s.events_report.skipped_total() << "\n";
  }
  if (s.imu_samples > 0) {
    out << "imu            " << s.imu_samples << " samples, " << format_seconds(s.imu_t_first_ns) << " .. "
        << format_seconds(s.imu_t_last_ns) << " s, "
        << fmt("%.1f", DatasetSummary::rate_hz(s.imu_samples, s.imu_t_first_ns, s.imu_t_last_ns)) << " Hz\n";
  } else {
    out << "imu            none\n";
  }
  if (s.frames > 0) {
    out << "frames         " << s.frames << " (" << s.frame_width << " x " << s.frame_height << "), "
        << format_seconds(s.frames_t_first_ns) << " .. " << format_seconds(s.frames_t_last_ns) << " s, "
        << fmt("%.2f", DatasetSummary::rate_hz(s.frames, s.frames_t_first_ns, s.frames_t_last_ns)) << " Hz\n";
  } else {
    out << "frames         none\n";
  }
  if (s.triggers > 0) {
    out << "triggers       " << s.triggers << " (" << s.triggers_rising << " rising, " << s.triggers_falling
        << " falling edges)\n";
  }
  for (const StreamInfo& st : s.streams) {
    out << "stream         " << st.name << " [" << st.type << "]";
    if (st.messages >= 0) out << " " << st.messages << " " << st.count_unit;
    out << (st.selected ? " (read)" : "") << "\n";
  }
  if (s.poses > 0) {
    out << "ground truth   " << s.poses << " poses, " << format_seconds(s.gt_t_first_ns) << " .. "
        << format_seconds(s.gt_t_last_ns) << " s, "
        << fmt("%.1f", DatasetSummary::rate_hz(s.poses, s.gt_t_first_ns, s.gt_t_last_ns)) << " Hz, path "
        << fmt("%.3f", s.gt_path_length_m) << " m\n";
  } else {
    out << "ground truth   none\n";
  }
  if (s.calibration) {
    out << "calibration    " << calib::describe(*s.calibration) << "\n";
  } else {
    out << "calibration    none\n";
  }
}

void print_json(const DatasetSummary& s, std::ostream& out) {
  const auto& ev = s.events;
  std::ostringstream o;
  o.precision(17);
  o << "{\"path\": \"" << json_escape(s.path) << "\", \"format\": \"" << dataset_format_name(s.format) << "\"";
  o << ", \"sensor\": " << (s.sensor.known() ? "[" + std::to_string(s.sensor.width) + ", " + std::to_string(s.sensor.height) + "]" : "null");
  o << ", \"time_unit\": \"" << time_unit_name(s.events_report.time_unit) << "\"";
  o << ", \"events\": {\"count\": " << ev.count << ", \"on\": " << ev.on << ", \"off\": " << ev.off
    << ", \"t_first_s\": " << format_seconds(ev.t_first_ns) << ", \"t_last_s\": " << format_seconds(ev.t_last_ns)
    << ", \"duration_s\": " << ns_to_seconds(ev.duration_ns()) << ", \"rate_hz\": " << ev.rate_hz()
    << ", \"max_x\": " << ev.max_x << ", \"max_y\": " << ev.max_y
    << ", \"polarity_convention\": \"" << polarity_convention_name(s.events_report.polarity)
    << "\", \"skipped_lines\": " << s.events_report.skipped_total() << "}";
  o << ", \"imu\": {\"count\": " << s.imu_samples
    << ", \"rate_hz\": " << DatasetSummary::rate_hz(s.imu_samples, s.imu_t_first_ns, s.imu_t_last_ns) << "}";
  o << ", \"frames\": {\"count\": " << s.frames << ", \"width\": " << s.frame_width << ", \"height\": " << s.frame_height
    << ", \"rate_hz\": " << DatasetSummary::rate_hz(s.frames, s.frames_t_first_ns, s.frames_t_last_ns) << "}";
  o << ", \"triggers\": " << s.triggers << ", \"triggers_rising\": " << s.triggers_rising
    << ", \"triggers_falling\": " << s.triggers_falling << ", \"streams\": [";
  for (size_t i = 0; i < s.streams.size(); ++i) {
    o << (i ? ", " : "") << "{\"name\": \"" << json_escape(s.streams[i].name) << "\", \"type\": \""
      << json_escape(s.streams[i].type) << "\", \"count\": " << s.streams[i].messages << ", \"count_unit\": \""
      << s.streams[i].count_unit << "\", \"selected\": " << (s.streams[i].selected ? "true" : "false") << "}";
  }
  o << "]";
  o << ", \"ground_truth\": {\"count\": " << s.poses << ", \"t_first_s\": " << format_seconds(s.gt_t_first_ns)
    << ", \"t_last_s\": " << format_seconds(s.gt_t_last_ns) << ", \"path_length_m\": " << s.gt_path_length_m << "}";
  o << ", \"calibration\": "
    << (s.calibration ? json_string(calib::describe(*s.calibration)) : std::string("null")) << "}\n";
  out << o.str();
}

}  // namespace

int run_info(const InfoArgs& args, std::ostream& out) {
  auto reader = open_dataset(args.path, args.dataset);
  std::function<void(double)> progress;
  std::error_code ec;
  const bool big = std::filesystem::is_regular_file(reader->event_report().path, ec) &&
                   std::filesystem::file_size(reader->event_report().path, ec) > (uint64_t{64} << 20);
  if (args.progress && big) {
    progress = [last = -1](double f) mutable {
      const int pct = static_cast<int>(f * 100);
      if (pct / 10 != last / 10) {
        std::fprintf(stderr, "evio info: %3d%% of events read\n", pct);
        last = pct;
      }
    };
  }
  const DatasetSummary s = summarize_dataset(reader.get(), progress);
  if (args.json) {
    print_json(s, out);
  } else {
    print_text(s, out);
  }
  return 0;
}

}  // namespace evio::apps
