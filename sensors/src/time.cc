#include "evio/sensors/time.h"

#include <charconv>
#include <cmath>
#include <limits>

namespace evio {

const char* time_unit_name(TimeUnit unit) {
  switch (unit) {
    case TimeUnit::kAuto: return "auto";
    case TimeUnit::kSeconds: return "s";
    case TimeUnit::kMilliseconds: return "ms";
    case TimeUnit::kMicroseconds: return "us";
    case TimeUnit::kNanoseconds: return "ns";
  }
  return "?";
}

std::optional<TimeUnit> time_unit_from_name(const std::string& name) {
  if (name == "auto") return TimeUnit::kAuto;
  if (name == "s") return TimeUnit::kSeconds;
  if (name == "ms") return TimeUnit::kMilliseconds;
  if (name == "us") return TimeUnit::kMicroseconds;
  if (name == "ns") return TimeUnit::kNanoseconds;
  return std::nullopt;
}

int time_unit_exponent(TimeUnit unit) {
  switch (unit) {
    case TimeUnit::kSeconds: return 9;
    case TimeUnit::kMilliseconds: return 6;
    case TimeUnit::kMicroseconds: return 3;
    case TimeUnit::kNanoseconds: return 0;
    case TimeUnit::kAuto: return -1;
  }
  return -1;
}

namespace {
constexpr int64_t kPow10[] = {1,          10,          100,          1000,          10000,
                              100000,     1000000,     10000000,     100000000,     1000000000};
}  // namespace

bool parse_decimal_time_ns(const char*& p, const char* end, int exponent, int64_t* out) {
  if (exponent < 0 || exponent > 9) return false;
  const char* s = p;
  bool negative = false;
  if (s < end && (*s == '-' || *s == '+')) {
    negative = (*s == '-');
    ++s;
  }
  // Integer part: accumulate in uint64 with an overflow guard.
  uint64_t ip = 0;
  const char* digits_begin = s;
  while (s < end && static_cast<unsigned>(*s - '0') < 10u) {
    if (ip > (std::numeric_limits<uint64_t>::max() - 9) / 10) return false;
    ip = ip * 10 + static_cast<unsigned>(*s - '0');
    ++s;
  }
  bool any_digit = s != digits_begin;
  // Fractional part: keep the first `exponent` digits, round on the next one, ignore the rest.
  uint64_t frac = 0;
  int kept = 0;
  bool round_up = false;
  if (s < end && *s == '.') {
    ++s;
    const char* fb = s;
    while (s < end && static_cast<unsigned>(*s - '0') < 10u) {
      if (kept < exponent) {
        frac = frac * 10 + static_cast<unsigned>(*s - '0');
        ++kept;
      } else if (kept == exponent) {
        round_up = *s >= '5';
        ++kept;  // only the first dropped digit decides (round half away from zero)
      }
      ++s;
    }
    any_digit = any_digit || s != fb;
  }
  if (!any_digit) return false;
  if (s < end && (*s == 'e' || *s == 'E')) return false;  // exponent notation: caller falls back
  if (kept > exponent) kept = exponent;
  frac *= static_cast<uint64_t>(kPow10[exponent - kept]);
  const uint64_t scale = static_cast<uint64_t>(kPow10[exponent]);
  if (ip > static_cast<uint64_t>(std::numeric_limits<int64_t>::max()) / scale) return false;
  uint64_t v = ip * scale;
  const uint64_t add = frac + (round_up ? 1 : 0);
  if (v > static_cast<uint64_t>(std::numeric_limits<int64_t>::max()) - add) return false;
  v += add;
  *out = negative ? -static_cast<int64_t>(v) : static_cast<int64_t>(v);
  p = s;
  return true;
}

bool parse_float_time_ns(const char*& p, const char* end, int exponent, int64_t* out) {
  if (exponent < 0 || exponent > 9) return false;
  const char* s = p;
  if (s < end && *s == '+') ++s;
  double v = 0;
  const auto r = std::from_chars(s, end, v);
  if (r.ec != std::errc() || !std::isfinite(v)) return false;
  const double ns = v * static_cast<double>(kPow10[exponent]);
  if (!(std::fabs(ns) < 9.2e18)) return false;
  *out = std::llround(ns);
  p = r.ptr;
  return true;
}

char* format_seconds(int64_t t_ns, char* buf) {
  char* w = buf;
  uint64_t u;
  if (t_ns < 0) {
    *w++ = '-';
    u = static_cast<uint64_t>(-(t_ns + 1)) + 1;  // safe for INT64_MIN
  } else {
    u = static_cast<uint64_t>(t_ns);
  }
  const uint64_t sec = u / 1000000000ULL;
  uint64_t frac = u % 1000000000ULL;
  w = std::to_chars(w, w + 24, sec).ptr;
  *w++ = '.';
  for (int i = 8; i >= 0; --i) {
    w[i] = static_cast<char>('0' + frac % 10);
    frac /= 10;
  }
  return w + 9;
}

std::string format_seconds(int64_t t_ns) {
  char buf[32];
  return std::string(buf, format_seconds(t_ns, buf));
}

}  // namespace evio
