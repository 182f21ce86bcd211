// Time in evio is int64 nanoseconds (t_ns). This header converts between file time units and ns
// exactly: decimal text is parsed digit by digit (no detour through double), so a timestamp
// written with 9 decimals in seconds round-trips to the nanosecond even at 1.7e18 ns.
#pragma once

#include <cstdint>
#include <optional>
#include <string>

namespace evio {

enum class TimeUnit { kAuto, kSeconds, kMilliseconds, kMicroseconds, kNanoseconds };

const char* time_unit_name(TimeUnit unit);                        // "auto", "s", "ms", "us", "ns"
std::optional<TimeUnit> time_unit_from_name(const std::string& name);  // accepts the names above
// Power of ten that turns one unit into ns: s -> 9, ms -> 6, us -> 3, ns -> 0. kAuto -> -1.
int time_unit_exponent(TimeUnit unit);

// Seconds as double from a difference of two times (for rates and printing only).
inline double ns_to_seconds(int64_t dt_ns) { return static_cast<double>(dt_ns) * 1e-9; }

// Parses one decimal token [+-]digits[.digits] at p (stopping at the first character that is not
// part of it) and returns value * 10^exponent ns (exponent = time_unit_exponent(unit)), rounding
// half away from zero on digits beyond ns resolution. Returns false (and leaves *out untouched) on an empty
// token, exponent notation or overflow of int64 ns; the caller decides what to do then.
// On success p points just past the token.
bool parse_decimal_time_ns(const char*& p, const char* end, int exponent, int64_t* out);

// Fallback for exponent notation ("1.5e-3"): parses a double and rounds to ns (not exact).
bool parse_float_time_ns(const char*& p, const char* end, int exponent, int64_t* out);

// Writes t_ns as seconds with exactly 9 decimals ("-0.000000001", "1700000000.123456789").
// Returns a pointer past the last character written; buf needs 32 bytes.
char* format_seconds(int64_t t_ns, char* buf);
std::string format_seconds(int64_t t_ns);

}  // namespace evio
