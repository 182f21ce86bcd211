#include "text_common.h"

#include <cstdio>
#include <sstream>

#include "evio/calib/log.h"
#include "evio/sensors/line_reader.h"

namespace evio {

const char* bad_line_policy_name(BadLinePolicy p) {
  return p == BadLinePolicy::kError ? "error" : "warn";
}

bool TextReadOptions::Validate(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why != nullptr) *why = m;
    return false;
  };
  if (sensor.width < 0 || sensor.height < 0) return fail("sensor size must be >= 0 px (0 = unknown)");
  if ((sensor.width == 0) != (sensor.height == 0)) return fail("give both sensor width and height, or neither");
  if (sensor.width > 65536 || sensor.height > 65536) return fail("sensor size above 65536 px does not fit uint16 coordinates");
  return true;
}

int64_t ReadReport::skipped_total() const {
  int64_t n = 0;
  for (const auto& kv : skipped) n += kv.second.count;
  return n;
}

std::string ReadReport::summary() const {
  std::ostringstream s;
  s << path << ": " << records << " records";
  if (time_unit != TimeUnit::kAuto) {
    s << ", time unit " << time_unit_name(time_unit);
    if (!time_unit_reason.empty()) s << " (" << time_unit_reason << ")";
  }
  if (polarity != PolarityConvention::kUnknown) s << ", polarity " << polarity_convention_name(polarity) << " -> -1/+1";
  if (skipped_total() > 0) {
    s << ", skipped";
    for (const auto& kv : skipped) s << " " << kv.second.count << " " << kv.first << " (first at line " << kv.second.first_line << ")";
  }
  return s.str();
}

namespace detail {

std::string quote_line(std::string_view line) {
  constexpr size_t kMax = 96;
  std::string s = "\"";
  s.append(line.substr(0, kMax));
  if (line.size() > kMax) s += "...";
  return s + "\"";
}

int count_tokens(std::string_view line) {
  int n = 0;
  const char* p = line.data();
  const char* end = p + line.size();
  for (;;) {
    p = skip_space(p, end);
    if (p == end) break;
    ++n;
    while (p < end && !is_space(*p)) ++p;
  }
  return n;
}

void BadLineHandler::bad(const char* kind, int64_t line, const std::string& problem, const std::string& expected) {
  if (policy_ == BadLinePolicy::kError) {
    throw InputError(path_, line, problem, expected + "; or skip such lines with --on-bad-line warn");
  }
  auto& s = report_->skipped[kind];
  if (s.count == 0) {
    s.first_line = line;
    s.first_message = problem;
  }
  ++s.count;
}

void BadLineHandler::finish() const {
  if (report_ == nullptr || report_->skipped_total() == 0) return;
  std::ostringstream s;
  s << path_ << ": skipped " << report_->skipped_total() << " bad line(s):";
  for (const auto& kv : report_->skipped) {
    s << " " << kv.second.count << " " << kv.first << " (first: line " << kv.second.first_line << ", "
      << kv.second.first_message << ");";
  }
  log_warning(s.str());
}

TimeColumnScan scan_time_column(const std::string& path, int column, int64_t max_records) {
  TimeColumnScan scan;
  LineReader reader(path, size_t{1} << 20);
  std::string_view line;
  while (scan.records < max_records && reader.next(&line)) {
    if (is_comment_or_blank(line)) {
      if (scan.records == 0 && scan.header_unit == TimeUnit::kAuto) {
        for (TimeUnit u : {TimeUnit::kSeconds, TimeUnit::kMilliseconds, TimeUnit::kMicroseconds, TimeUnit::kNanoseconds}) {
          const std::string tag = std::string("[") + time_unit_name(u) + "]";
          const size_t at = line.find(tag);
          // Only a tag on the first column's name counts: "t[us]", "timestamp [ns]", "time[s]".
          if (at != std::string_view::npos && line.find('[') == at) {
            scan.header_unit = u;
            scan.header_unit_line = reader.line_number();
          }
        }
      }
      continue;
    }
    const char* p = line.data();
    const char* end = p + line.size();
    for (int c = 0;; ++c) {
      p = skip_space(p, end);
      if (c == column) break;
      while (p < end && !is_space(*p)) ++p;
    }
    const char* tok = p;
    while (p < end && !is_space(*p)) ++p;
    const std::string_view t(tok, static_cast<size_t>(p - tok));
    if (t.empty()) continue;  // malformed: the real parse reports it
    ++scan.records;
    if (scan.records == 1) {
      scan.first_line = reader.line_number();
      scan.first_token = std::string(t);
    }
    scan.last_line = reader.line_number();
    scan.last_token = std::string(t);
    if (t.find_first_of(".eE") != std::string_view::npos) {
      if (scan.decimal_line == 0) scan.decimal_line = reader.line_number();
      continue;
    }
    uint64_t v = 0;
    const char* b = t.data();
    if (*b == '-' || *b == '+') ++b;
    if (std::from_chars(b, t.data() + t.size(), v).ec != std::errc()) continue;
    scan.max_integer = std::max(scan.max_integer, v);
    scan.any_nonzero = scan.any_nonzero || v != 0;
    scan.all_multiple_of_1000 = scan.all_multiple_of_1000 && (v % 1000 == 0);
  }
  return scan;
}

TimeUnit resolve_time_unit(const TimeColumnScan& scan, TimeUnit given, std::string* reason) {
  if (given != TimeUnit::kAuto) {
    *reason = "given";
    return given;
  }
  if (scan.records == 0) {
    *reason = "no records";
    return TimeUnit::kSeconds;
  }
  if (scan.header_unit != TimeUnit::kAuto) {
    *reason = std::string("auto: header comment in line ") + std::to_string(scan.header_unit_line) + " says [" +
              time_unit_name(scan.header_unit) + "]";
    return scan.header_unit;
  }
  if (scan.decimal_line > 0) {
    *reason = "auto: decimal point in line " + std::to_string(scan.decimal_line);
    return TimeUnit::kSeconds;
  }
  if (scan.max_integer > 100000000000000000ULL) {
    *reason = "auto: integers above 1e17";
    return TimeUnit::kNanoseconds;
  }
  if (scan.records >= 100 && scan.any_nonzero && scan.all_multiple_of_1000) {
    *reason = "auto: integers, the first " + std::to_string(scan.records) + " all multiples of 1000";
    return TimeUnit::kNanoseconds;
  }
  *reason = "auto: integer timestamps";
  return TimeUnit::kMicroseconds;
}

void check_rate(const std::string& path, const char* what, const TimeColumnScan& scan, TimeUnit unit,
                double min_hz, double max_hz, int64_t min_count) {
  if (scan.records < min_count) return;
  const int e = time_unit_exponent(unit);
  int64_t t0 = 0, t1 = 0;
  const char* p0 = scan.first_token.data();
  const char* p1 = scan.last_token.data();
  if (!parse_time(p0, p0 + scan.first_token.size(), e, &t0) || !parse_time(p1, p1 + scan.last_token.size(), e, &t1)) {
    return;  // malformed tokens: the line parser reports them
  }
  const int64_t span_ns = t1 - t0;
  if (span_ns <= 0) return;
  const double rate = static_cast<double>(scan.records - 1) / (static_cast<double>(span_ns) * 1e-9);
  if (rate >= min_hz && rate <= max_hz) return;
  char buf[512];
  std::snprintf(buf, sizeof(buf),
                "time unit '%s' gives a mean %s rate of %.3g Hz over lines %lld-%lld (%lld records spanning %.6g s)",
                time_unit_name(unit), what, rate, static_cast<long long>(scan.first_line),
                static_cast<long long>(scan.last_line), static_cast<long long>(scan.records),
                static_cast<double>(span_ns) * 1e-9);
  char exp[320];
  std::snprintf(exp, sizeof(exp),
                "%s %s rate between %g and %g Hz; give the file's unit with --time-unit s|ms|us|ns, "
                "or disable this check with --no-time-unit-check",
                what[0] == 'I' || what[0] == 'e' ? "an" : "a", what, min_hz, max_hz);
  throw InputError(path, 0, buf, exp);
}

int prepare_time_unit(const std::string& path, const TextReadOptions& options, int column, const char* what,
                      double min_hz, double max_hz, int64_t min_count, ReadReport* report) {
  const TimeColumnScan scan = scan_time_column(path, column);
  report->time_unit = resolve_time_unit(scan, options.time_unit, &report->time_unit_reason);
  if (options.check_time_unit) check_rate(path, what, scan, report->time_unit, min_hz, max_hz, min_count);
  return time_unit_exponent(report->time_unit);
}

std::string printable(std::string_view s) {
  static const char* d = "0123456789abcdef";
  std::string out;
  for (size_t i = 0; i < s.size() && i < 40; ++i) {
    const auto c = static_cast<unsigned char>(s[i]);
    if (c >= 0x20 && c < 0x7f) {
      out += static_cast<char>(c);
    } else if (c == '\n') {
      out += "\\n";
    } else {
      out += "\\x";
      out += d[c >> 4];
      out += d[c & 15];
    }
  }
  if (s.size() > 40) out += "...";
  return out;
}

}  // namespace detail
}  // namespace evio
