#include "evio/sensors/aedat2.h"

#include <gtest/gtest.h>

#include "evio/calib/error.h"
#include "evio_test/fuzz_seed.h"
#include "evio_test/real_data.h"
#include "evio_test/temp_dir.h"

namespace evio {
namespace {

std::string be32(uint32_t v) {
  return std::string{static_cast<char>(v >> 24), static_cast<char>(v >> 16), static_cast<char>(v >> 8),
                     static_cast<char>(v)};
}

// A jAER DVS128 address for image coordinates (origin top left).
uint32_t dvs128_addr(int x, int y, bool on) {
  return static_cast<uint32_t>((127 - y) << 8 | (127 - x) << 1 | (on ? 1 : 0));
}

std::string header(const std::string& chip = "ch.unizh.ini.jaer.chip.retina.DVS128") {
  return "#!AER-DAT2.0\r\n# Timestamps tick: 1 us\r\n# AEChip: " + chip + "\r\n";
}

std::vector<Event> read_all(const std::string& path, DatasetOptions o = {}) {
  auto r = open_aedat2_dataset(path, o);
  EventBuffer b;
  while (r->read_events(&b, 3) > 0) {
  }
  return b.events();
}

void expect_error(const std::string& bytes, const std::vector<std::string>& frags, DatasetOptions o = {}) {
  evio_test::TempDir dir;
  const std::string p = dir.write("x.aedat", bytes);
  evio_test::export_fuzz_seed(p, "fuzz_aedat2");
  try {
    read_all(p, o);
    FAIL() << "no error";
  } catch (const InputError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find(p), std::string::npos) << m;
    for (const auto& f : frags) EXPECT_NE(m.find(f), std::string::npos) << "'" << f << "' not in " << m;
  }
}

TEST(Aedat2, DecodesDvs128AddressesTriggersAndWrap) {
  evio_test::TempDir dir;
  std::string data = header();
  data += be32(dvs128_addr(0, 0, true)) + be32(10);
  data += be32(dvs128_addr(127, 5, false)) + be32(10);
  data += be32(0x8000u | 1u) + be32(15);  // external event
  data += be32(dvs128_addr(64, 127, true)) + be32(0xFFFFFFF0u);
  data += be32(dvs128_addr(1, 2, false)) + be32(0x10u);  // wrapped: 2^32 + 16 us
  const std::string p = dir.write("a.aedat", data);
  evio_test::export_fuzz_seed(p, "fuzz_aedat2");
  auto reader = open_aedat2_dataset(p);
  EXPECT_EQ(reader->sensor_size().width, 128);
  EventBuffer b;
  while (reader->read_events(&b, 2) > 0) {
  }
  ASSERT_EQ(b.size(), 4u);
  EXPECT_EQ(b[0], (Event{10000, 0, 0, 1}));
  EXPECT_EQ(b[1], (Event{10000, 127, 5, -1}));
  EXPECT_EQ(b[2], (Event{int64_t{0xFFFFFFF0} * 1000, 64, 127, 1}));
  EXPECT_EQ(b[3], (Event{((int64_t{1} << 32) + 16) * 1000, 1, 2, -1}));
  const auto trig = reader->read_triggers();
  ASSERT_EQ(trig.size(), 1u);
  EXPECT_EQ(trig[0].t_ns, 15000);
  EXPECT_EQ(reader->event_report().records, 4);
  EXPECT_EQ(reader->event_report().time_unit, TimeUnit::kMicroseconds);
}

TEST(Aedat2, MalformedInput) {
  expect_error("#!AER-DAT3.1\r\n", {"unsupported version '3.1' at byte offset 0"});
  expect_error("hello", {"no \"#!AER-DAT2.0\" line at byte offset 0"});
  expect_error("# comment\r\n", {"first line is not an AER-DAT version line"});
  expect_error(header() + be32(1) + be32(2) + "abc", {"not a whole number of 8-byte records", "truncated at byte offset"});
  expect_error(header("eu.seebetter.ini.chips.davis.DAVIS240C"), {"chip 'eu.seebetter.ini.chips.davis.DAVIS240C' is not supported"});
  expect_error(header() + be32(dvs128_addr(1, 1, true)) + be32(100) + be32(dvs128_addr(1, 1, true)) + be32(50),
               {"timestamp 0.000050000 s is earlier than the previous 0.000100000 s at byte offset", "AEDAT 2.0"});
  expect_error(header() + be32(0x10000u) + be32(1), {"address 0x00010000 has bits above 15 set"});
}

TEST(Aedat2, WarnPolicySkipsOutOfOrderRecords) {
  evio_test::TempDir dir;
  const std::string p = dir.write("w.aedat", header() + be32(dvs128_addr(1, 1, true)) + be32(100) +
                                                  be32(dvs128_addr(2, 2, true)) + be32(50) +
                                                  be32(dvs128_addr(3, 3, true)) + be32(120));
  DatasetOptions o;
  o.text.on_bad_line = BadLinePolicy::kWarnAndSkip;
  auto r = open_aedat2_dataset(p, o);
  EventBuffer b;
  while (r->read_events(&b, 100) > 0) {
  }
  ASSERT_EQ(b.size(), 2u);
  EXPECT_EQ(b[1].x, 3);
  EXPECT_EQ(r->event_report().skipped.at("time order").count, 1);
}

TEST(Aedat2RealData, Dvs128ShortRecording) {
  const auto dir = evio_test::real_data_dir("dvs128_aedat2");
  if (!dir) GTEST_SKIP() << "real data not found (../shared/data/real/dvs128_aedat2)";
  auto r = open_dataset(*dir + "/DVS128-2017-03-21-short.aedat");
  EXPECT_EQ(r->format(), DatasetFormat::kAedat2);
  EventBuffer b;
  while (r->read_events(&b, 50000) > 0) {
  }
  EXPECT_EQ(b.size(), 130114u);
  EXPECT_TRUE(b.is_time_sorted());
  EventStatistics s;
  s.add(b.span());
  EXPECT_LE(s.max_x, 127);
  EXPECT_LE(s.max_y, 127);
  EXPECT_EQ(s.on, 55123);
  EXPECT_EQ(b.front().t_ns, int64_t{113476330} * 1000);
  EXPECT_EQ(b.back().t_ns, int64_t{119657829} * 1000);
  EXPECT_TRUE(r->read_triggers().empty());
}

}  // namespace
}  // namespace evio
