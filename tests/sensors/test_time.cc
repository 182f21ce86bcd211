#include "evio/sensors/time.h"

#include <cstring>
#include <limits>

#include <gtest/gtest.h>

namespace evio {
namespace {

int64_t parse(const char* s, TimeUnit u, bool* ok = nullptr) {
  const char* p = s;
  int64_t t = -12345;
  const bool r = parse_decimal_time_ns(p, s + std::strlen(s), time_unit_exponent(u), &t);
  if (ok != nullptr) *ok = r;
  return t;
}

TEST(Time, ParsesSecondsExactly) {
  EXPECT_EQ(parse("0.003811000", TimeUnit::kSeconds), 3811000);
  EXPECT_EQ(parse("1.5", TimeUnit::kSeconds), 1500000000);
  EXPECT_EQ(parse("1700000000.123456789", TimeUnit::kSeconds), 1700000000123456789LL);
  EXPECT_EQ(parse("-0.000000001", TimeUnit::kSeconds), -1);
  EXPECT_EQ(parse("42", TimeUnit::kSeconds), 42000000000LL);
  EXPECT_EQ(parse(".5", TimeUnit::kSeconds), 500000000);
}

TEST(Time, RoundsDigitsBeyondNanoseconds) {
  EXPECT_EQ(parse("0.0000000014", TimeUnit::kSeconds), 1);
  EXPECT_EQ(parse("0.0000000015", TimeUnit::kSeconds), 2);
  EXPECT_EQ(parse("-0.0000000015", TimeUnit::kSeconds), -2);
  EXPECT_EQ(parse("12.5", TimeUnit::kNanoseconds), 13);
}

TEST(Time, OtherUnits) {
  EXPECT_EQ(parse("1234", TimeUnit::kMicroseconds), 1234000);
  EXPECT_EQ(parse("0.250", TimeUnit::kMicroseconds), 250);
  EXPECT_EQ(parse("7", TimeUnit::kMilliseconds), 7000000);
  EXPECT_EQ(parse("1700000000123456789", TimeUnit::kNanoseconds), 1700000000123456789LL);
}

TEST(Time, RejectsOverflowEmptyAndExponent) {
  bool ok = true;
  parse("9300000000.0", TimeUnit::kSeconds, &ok);  // 9.3e18 ns > int64
  EXPECT_FALSE(ok);
  parse("", TimeUnit::kSeconds, &ok);
  EXPECT_FALSE(ok);
  parse("-", TimeUnit::kSeconds, &ok);
  EXPECT_FALSE(ok);
  parse("abc", TimeUnit::kSeconds, &ok);
  EXPECT_FALSE(ok);
  parse("1e-3", TimeUnit::kSeconds, &ok);
  EXPECT_FALSE(ok);
  const char* s = "1.5e-3 x";
  const char* p = s;
  int64_t t = 0;
  ASSERT_TRUE(parse_float_time_ns(p, s + std::strlen(s), 9, &t));
  EXPECT_EQ(t, 1500000);
  EXPECT_EQ(*p, ' ');
}

TEST(Time, FormatRoundTripsToTheNanosecond) {
  for (int64_t t : {int64_t{0}, int64_t{1}, int64_t{-1}, int64_t{999999999}, int64_t{1000000000},
                    int64_t{1700000000123456789LL}, std::numeric_limits<int64_t>::max(),
                    std::numeric_limits<int64_t>::min() + 1}) {
    const std::string s = format_seconds(t);
    bool ok = false;
    EXPECT_EQ(parse(s.c_str(), TimeUnit::kSeconds, &ok), t) << s;
    EXPECT_TRUE(ok) << s;
  }
  EXPECT_EQ(format_seconds(-1), "-0.000000001");
  EXPECT_EQ(format_seconds(3811000), "0.003811000");
  EXPECT_EQ(format_seconds(std::numeric_limits<int64_t>::min()), "-9223372036.854775808");
}

TEST(Time, UnitNames) {
  for (TimeUnit u : {TimeUnit::kAuto, TimeUnit::kSeconds, TimeUnit::kMilliseconds, TimeUnit::kMicroseconds,
                     TimeUnit::kNanoseconds}) {
    EXPECT_EQ(time_unit_from_name(time_unit_name(u)), u);
  }
  EXPECT_FALSE(time_unit_from_name("sec").has_value());
}

}  // namespace
}  // namespace evio
