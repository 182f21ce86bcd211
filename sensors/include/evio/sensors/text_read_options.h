// Options and reports shared by evio's text readers (ECD folders, TUM, EuRoC csv). Every reader
// validates each line; what happens with a bad line is a policy: stop with an error naming file,
// line and expected form (default), or skip it and count it (the report says how many and where).
#pragma once

#include <cstdint>
#include <map>
#include <string>

#include "evio/sensors/measurements.h"
#include "evio/sensors/time.h"

namespace evio {

enum class BadLinePolicy {
  kError,        // throw evio::InputError at the first bad line
  kWarnAndSkip,  // skip bad lines, count them per kind, log one warning with counts at the end
};
const char* bad_line_policy_name(BadLinePolicy p);  // "error", "warn"

struct TextReadOptions {
  // Unit of the time column. kAuto: a unit tag on the first column in a leading comment
  // ("# t[us] x y p", "#timestamp [ns],...") decides; otherwise a decimal point anywhere in the first 10,000 records means
  // seconds; integers mean microseconds, or nanoseconds when they exceed 1e17 or are all
  // multiples of 1000 (us resolution written in ns). The report says which unit and why.
  TimeUnit time_unit = TimeUnit::kAuto;
  BadLinePolicy on_bad_line = BadLinePolicy::kError;
  // Sensor size in pixels. When known, events outside [0,width) x [0,height) are bad lines.
  SensorSize sensor;
  // Rejects a time unit under which the first records imply an implausible rate (events outside
  // 10..2e9 ev/s over >= 1000 events; IMU and poses outside 0.1..1e5 Hz over >= 10 samples).
  bool check_time_unit = true;

  bool Validate(std::string* why) const;
};

// What a reader did: unit and polarity conventions it applied, lines it read and skipped.
struct ReadReport {
  struct Skipped {
    int64_t count = 0;
    int64_t first_line = 0;
    std::string first_message;
  };

  std::string path;
  TimeUnit time_unit = TimeUnit::kAuto;  // the unit actually applied
  std::string time_unit_reason;          // "given", "decimal point in line 1", ...
  PolarityConvention polarity = PolarityConvention::kUnknown;
  int64_t lines = 0;    // lines read, including comments and blank lines
  int64_t records = 0;  // records accepted
  std::map<std::string, Skipped> skipped;  // by kind: "malformed", "time order", "outside sensor", ...

  int64_t skipped_total() const;
  // One line, e.g. "events.txt: 50000 records, time unit s (decimal point in line 1), polarity 0/1".
  std::string summary() const;
};

}  // namespace evio
