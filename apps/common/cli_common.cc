#include "cli_common.h"

#include <cstdio>
#include <iostream>

#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio/sensors/time.h"
#include "subcommands.h"

namespace evio::apps {
namespace {

// Parses "WxH" into a sensor size; an empty string on success, else the expected form.
std::string parse_sensor(const std::string& s, SensorSize* out) {
  int w = 0, h = 0;
  char x = 0, extra = 0;
  if (std::sscanf(s.c_str(), "%d%c%d%c", &w, &x, &h, &extra) != 3 || (x != 'x' && x != 'X') || w <= 0 || h <= 0) {
    return "expected WIDTHxHEIGHT in pixels, e.g. 240x180; got '" + s + "'";
  }
  out->width = w;
  out->height = h;
  return {};
}

}  // namespace

CommandLine::CommandLine(const char* name)
    : app_(subcommand_summary(name) ? subcommand_summary(name) : "", std::string("evio ") + name) {
  app_.set_version_flag("--version", kVersion);
  app_.add_flag("-q,--quiet", quiet_, "Print only warnings and errors on stderr (no progress, no conventions)");
  app_.add_flag("-v,--verbose", verbose_, "Also print debug messages on stderr");
}

void CommandLine::add_print_config(bool* flag, const std::vector<CLI::Option*>& needed) {
  app_.add_flag("--print-config", *flag,
                "Print the resolved config (defaults, then --config, then --set: every key with its value, unit and "
                "range, as written to the output folder) and exit");
  app_.parse_complete_callback([flag, needed] {
    if (*flag) return;
    for (const CLI::Option* o : needed) {
      if (o->count() == 0) throw CLI::RequiredError(o->get_name());
    }
  });
}

void CommandLine::add_set(std::vector<std::string>* sets, const std::string& example) {
  app_.add_option("--set", *sets,
                  "Change one config value: key.sub=value (dotted key of the --config YAML, value in YAML syntax), "
                  "applied after --config, e.g. --set " + example + "; repeatable. The output folder's resolved "
                  "config lists every key")
      ->expected(1)
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
}

int CommandLine::run(int argc, char** argv, const std::function<int()>& body) {
  try {
    app_.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app_.exit(e) == 0 ? 0 : 2;
  }
  if (quiet_) set_log_level(LogLevel::kWarning);
  if (verbose_) set_log_level(LogLevel::kDebug);
  try {
    return body();
  } catch (const InputError& e) {
    std::fprintf(stderr, "evio: error: %s\n", e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "evio: internal error: %s\n", e.what());
    return 3;
  }
}

CLI::Validator time_unit_check() { return CLI::IsMember({"auto", "s", "ms", "us", "ns"}); }

void add_dataset_options(CLI::App* cmd, DatasetOptions* opts) {
  cmd->add_option_function<std::string>(
         "--format", [opts](const std::string& s) { opts->format = *dataset_format_from_name(s); },
         "Dataset format; auto detects it from the folder layout, magic bytes and extension (rosbag = ROS1 bag, "
         "rosbag2 = ROS 2 bag folder or .db3 / .mcap file)")
      ->check(CLI::IsMember({"auto", "ecd", "ecd-events", "h5", "aedat4", "evt2", "evt3", "rosbag", "aedat2", "rosbag2"}))
      ->default_str("auto");
  cmd->add_option_function<std::string>(
         "--time-unit", [opts](const std::string& s) { opts->text.time_unit = *time_unit_from_name(s); },
         "Unit of the time column of text files: s, ms, us, ns; auto = decimal point means s, "
         "integers mean us (ns above 1e17 or when all are multiples of 1000)")
      ->check(time_unit_check())
      ->default_str("auto");
  cmd->add_option_function<std::string>(
      "--sensor",
      [opts](const std::string& s) {
        const std::string err = parse_sensor(s, &opts->text.sensor);
        if (!err.empty()) throw CLI::ValidationError("--sensor", err);
      },
      "Sensor size WIDTHxHEIGHT in pixels; events outside it are bad lines (default: unknown, not checked)");
  cmd->add_option_function<std::string>(
         "--on-bad-line",
         [opts](const std::string& s) {
           opts->text.on_bad_line = s == "warn" ? BadLinePolicy::kWarnAndSkip : BadLinePolicy::kError;
         },
         "What to do with a malformed, out-of-order or out-of-sensor line: error = stop with file, "
         "line and expected form; warn = skip it and report counts")
      ->check(CLI::IsMember({"error", "warn"}))
      ->default_str("error");
  cmd->add_flag_callback(
      "--no-time-unit-check", [opts] { opts->text.check_time_unit = false; },
      "Accept a time unit even when the first records imply an implausible event rate (outside 10 Hz..2 GHz) "
      "or IMU/pose rate (outside 0.1 Hz..100 kHz)");
  cmd->add_option("--events-topic", opts->topics.events,
                  "ROS1/ROS 2 bag: topic of dvs_msgs/EventArray, prophesee_event_msgs/EventArray or "
                  "event_camera_msgs/EventPacket (evt3, evt2, mono) (default: the only one)");
  cmd->add_option("--imu-topic", opts->topics.imu, "ROS1/ROS 2 bag: topic of sensor_msgs/Imu (default: the only one)");
  cmd->add_option("--image-topic", opts->topics.image,
                  "ROS1/ROS 2 bag: topic of sensor_msgs/Image, mono8/mono16/rgb8/bgr8 (default: the only one)");
}

int64_t parse_seconds_flag(const std::string& flag, const std::string& s) {
  const char* p = s.c_str();
  int64_t t = 0;
  if (!parse_decimal_time_ns(p, s.c_str() + s.size(), 9, &t) || *p != '\0') {
    throw CLI::ValidationError(flag, "expected a time in seconds, e.g. 12.5; got '" + s + "'");
  }
  return t;
}

}  // namespace evio::apps
