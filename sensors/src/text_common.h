// Internal helpers of the text readers: tokenising, the bad-line policy, time-unit detection
// and the rate plausibility check. Not installed.
#pragma once

#include <charconv>
#include <cmath>
#include <string>
#include <string_view>

#include "evio/calib/error.h"
#include "evio/sensors/text_read_options.h"

namespace evio::detail {

inline bool is_space(char c) { return c == ' ' || c == '\t' || c == ','; }

inline const char* skip_space(const char* p, const char* end) {
  while (p < end && is_space(*p)) ++p;
  return p;
}

// Blank lines and lines starting with '#' or '%' are not records.
inline bool is_comment_or_blank(std::string_view line) {
  const char* p = skip_space(line.data(), line.data() + line.size());
  return p == line.data() + line.size() || *p == '#' || *p == '%';
}

// The line in double quotes, cut after 96 characters (for error messages).
std::string quote_line(std::string_view line);

// Bytes for error messages: printable ASCII as is, '\n' as \n, other bytes as \xNN, cut after 40
// characters (with "...").
std::string printable(std::string_view s);

// Number of whitespace/comma separated tokens (for error messages).
int count_tokens(std::string_view line);

inline bool parse_double(const char*& p, const char* end, double* v) {
  if (p < end && *p == '+') ++p;
  const auto r = std::from_chars(p, end, *v);
  if (r.ec != std::errc()) return false;
  p = r.ptr;
  return true;
}

// Time token in the given unit: exact decimal parse, exponent notation as fallback.
inline bool parse_time(const char*& p, const char* end, int exponent, int64_t* t_ns) {
  return parse_decimal_time_ns(p, end, exponent, t_ns) || parse_float_time_ns(p, end, exponent, t_ns);
}

// Applies TextReadOptions::on_bad_line: throws InputError, or counts the line in the report.
class BadLineHandler {
 public:
  BadLineHandler(const std::string& path, BadLinePolicy policy, ReadReport* report)
      : path_(path), policy_(policy), report_(report) {}
  void bad(const char* kind, int64_t line, const std::string& problem, const std::string& expected);
  // Logs one warning with the skip counts, if any.
  void finish() const;

 private:
  const std::string& path_;
  BadLinePolicy policy_;
  ReadReport* report_;
};

// What the first records of a file say about its time column (0-based `column`).
struct TimeColumnScan {
  int64_t records = 0;
  int64_t first_line = 0, last_line = 0;
  std::string first_token, last_token;
  int64_t decimal_line = 0;  // first line with a decimal point or exponent, 0 if none
  uint64_t max_integer = 0;
  bool all_multiple_of_1000 = true;
  bool any_nonzero = false;
  // Unit named in a comment before the first record, e.g. "# t[us] x y p" -> kMicroseconds.
  TimeUnit header_unit = TimeUnit::kAuto;
  int64_t header_unit_line = 0;
};
TimeColumnScan scan_time_column(const std::string& path, int column, int64_t max_records = 10000);

// TimeUnit::kAuto resolved from a scan (rules in TextReadOptions::time_unit); `given` otherwise.
TimeUnit resolve_time_unit(const TimeColumnScan& scan, TimeUnit given, std::string* reason);

// With options.check_time_unit: throws InputError when the scanned records imply a rate outside
// [min_hz, max_hz] under `unit` (judged only from min_count records and a positive span).
void check_rate(const std::string& path, const char* what, const TimeColumnScan& scan, TimeUnit unit,
                double min_hz, double max_hz, int64_t min_count);

// Scan + resolve + check for a reader; fills report->time_unit/_reason and returns the exponent.
int prepare_time_unit(const std::string& path, const TextReadOptions& options, int column, const char* what,
                      double min_hz, double max_hz, int64_t min_count, ReadReport* report);

}  // namespace evio::detail
