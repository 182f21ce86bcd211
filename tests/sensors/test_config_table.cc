// yaml_config::Table::check (sensors/config_table.h): a struct value against the table's ranges,
// key by key, in the reader's words; Interval's texts are the reader's expected forms.
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "evio/calib/error.h"
#include "evio/sensors/config_table.h"

namespace evio::yaml_config {
namespace {

enum class Mode { kA, kB };

struct Inner {
  double gain = 0.5;
  int64_t period_ns = 1'000'000;
};

struct Options {
  int count = 3;
  size_t length = 10;
  double gate_px = 4.0;
  double limit = std::numeric_limits<double>::infinity();
  double wait_s = 0.01;
  Mode mode = Mode::kA;
  std::vector<Mode> modes = {Mode::kA};
  Eigen::Vector3d normal = Eigen::Vector3d(0, 0, 1);
  bool flag = false;
  Inner inner;
  Inner nested;
};

const Table<Inner>& inner_table() {
  static const Table<Inner> t = Table<Inner>("inner settings")
                                    .number("gain", &Inner::gain, Interval::open_closed(0, 1), "")
                                    .duration_ms("period_ms", &Inner::period_ns, Range::kNonNegative);
  return t;
}

const Table<Options>& options_table() {
  static const Table<Options> t = Table<Options>("test settings")
                                      .integer("count", &Options::count, 1, 8)
                                      .integer("length", &Options::length, 1, 1000)
                                      .number("gate_px", &Options::gate_px, Interval::open_closed(0, 64), "px")
                                      .number("limit", &Options::limit, Range::kNonNegative, "", /*allow_infinity=*/true)
                                      .seconds_as_ms("wait_ms", &Options::wait_s, Range::kPositive)
                                      .choice("mode", &Options::mode, {{"a", Mode::kA}, {"b", Mode::kB}})
                                      .choice_list("modes", &Options::modes, {{"a", Mode::kA}, {"b", Mode::kB}})
                                      .vector3("normal", &Options::normal, "")
                                      .boolean("flag", &Options::flag)
                                      .include(inner_table(), &Options::inner, {}, "inner_")
                                      .section("nested", inner_table(), &Options::nested);
  return t;
}

std::string why_of(const Options& o) {
  std::string why;
  EXPECT_FALSE(options_table().check(o, &why));
  return why;
}

// The InputError message of reading `set` (a --set override) over the defaults; "" when it reads.
std::string read_error(const std::string& set) {
  try {
    read_config(options_table(), Options{}, "", {set}, "test");
  } catch (const InputError& e) {
    return e.what();
  }
  return {};
}

TEST(Interval, TextsAreTheReadersExpectedForms) {
  EXPECT_EQ(Interval(Range::kPositive).number_text(), "a number > 0");
  EXPECT_EQ(Interval(Range::kNonNegative).number_text(), "a number >= 0");
  EXPECT_EQ(Interval(Range::kUnit).number_text(), "a number in [0, 1]");
  EXPECT_EQ(Interval(Range::kAny).number_text(), "a number");
  EXPECT_EQ(Interval::open_closed(0, 64).text(), "in (0, 64]");
  EXPECT_EQ(Interval::closed_open(0, 100).text(), "in [0, 100)");
  EXPECT_EQ(Interval::open(0, 1).text(), "in (0, 1)");
  EXPECT_EQ(Interval::closed(0, 0.9).text(), "in [0, 0.9]");
  EXPECT_EQ(Interval::at_least(1).text(), ">= 1");
  EXPECT_TRUE(Interval::open_closed(0, 1).contains(1));
  EXPECT_FALSE(Interval::open_closed(0, 1).contains(0));
  EXPECT_FALSE(Interval(Range::kPositive).contains(0));
  EXPECT_TRUE(Interval(Range::kAny).contains(-1e300));
}

TEST(ConfigTableCheck, DefaultsPass) {
  std::string why;
  EXPECT_TRUE(options_table().check(Options{}, &why)) << why;
  EXPECT_TRUE(options_table().check(Options{}, nullptr));
}

TEST(ConfigTableCheck, EachKindNamesTheKeyTheValueAndTheRange) {
  Options o;
  o.count = 9;
  EXPECT_EQ(why_of(o), "count: is out of range (9) (expected: an integer in [1, 8])");
  o = Options{};
  o.length = 0;
  EXPECT_EQ(why_of(o), "length: is out of range (0) (expected: an integer in [1, 1000])");
  o = Options{};
  o.gate_px = 64.5;
  EXPECT_EQ(why_of(o), "gate_px: is out of range (64.5) (expected: a number in (0, 64] (px))");
  o.gate_px = std::nan("");
  EXPECT_EQ(why_of(o), "gate_px: is out of range (.nan) (expected: a number in (0, 64] (px))");
  o = Options{};
  o.limit = -1;
  EXPECT_EQ(why_of(o), "limit: is out of range (-1) (expected: a number >= 0 or .inf)");
  o = Options{};
  o.wait_s = 0;
  EXPECT_EQ(why_of(o), "wait_ms: is out of range (0) (expected: a number > 0 (ms))");
  o = Options{};
  o.mode = static_cast<Mode>(7);
  EXPECT_EQ(why_of(o), "mode: value 7 has no name (expected: a | b)");
  o = Options{};
  o.modes = {};
  EXPECT_NE(why_of(o).find("modes: is empty"), std::string::npos);
  o.modes = {Mode::kB, Mode::kB};
  EXPECT_NE(why_of(o).find("modes: 'b' is listed twice"), std::string::npos);
  o = Options{};
  o.normal.x() = std::numeric_limits<double>::infinity();
  EXPECT_NE(why_of(o).find("normal: is not finite ([.inf, 0, 1])"), std::string::npos);
  // Included keys by their prefixed name, sections' keys under the section.
  o = Options{};
  o.inner.period_ns = -1;
  EXPECT_EQ(why_of(o), "inner_period_ms: is out of range (-1e-06) (expected: a number >= 0 (ms))");
  o = Options{};
  o.nested.gain = 0;
  EXPECT_EQ(why_of(o), "nested.gain: is out of range (0) (expected: a number in (0, 1])");
}

TEST(ConfigTableCheck, TheReaderUsesTheSameRanges) {
  EXPECT_NE(read_error("gate_px=64.5").find("gate_px: is out of range (64.5) (expected: a number in (0, 64] (px))"),
            std::string::npos);
  EXPECT_EQ(read_error("gate_px=64"), "");
  EXPECT_NE(read_error("nested.gain=0").find("nested.gain: is out of range (0)"), std::string::npos);
  EXPECT_EQ(read_error("limit=.inf"), "");
}

TEST(ConfigTableCheck, NumericKeysListEveryBoundAndSetTheField) {
  const auto keys = options_table().numeric_keys();
  std::vector<std::string> names;
  for (const auto& k : keys) names.push_back(k.key);
  EXPECT_EQ(names, (std::vector<std::string>{"count", "length", "gate_px", "limit", "wait_ms", "inner_gain",
                                             "inner_period_ms", "nested.gain", "nested.period_ms"}));
  Options o;
  for (const auto& k : keys) {
    if (k.key == "inner_period_ms") {
      EXPECT_EQ(k.step, 1e-6);
      EXPECT_TRUE(k.set(o, 2.5));
    }
    if (k.key == "nested.gain") {
      EXPECT_TRUE(k.set(o, 0.25));
    }
    if (k.key == "length") {
      EXPECT_EQ(k.step, 1);
      EXPECT_FALSE(k.set(o, -1));  // size_t cannot hold it
      EXPECT_FALSE(k.set(o, 1.5));
    }
  }
  EXPECT_EQ(o.inner.period_ns, 2'500'000);
  EXPECT_EQ(o.nested.gain, 0.25);
}

}  // namespace
}  // namespace evio::yaml_config
