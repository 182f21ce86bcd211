#include "evio/sensors/evt.h"

#include <algorithm>
#include <cstring>
#include <fstream>
#include <random>

#include <gtest/gtest.h>

#include "evio/calib/error.h"
#include "evio_test/fuzz_seed.h"
#include "evio_test/real_data.h"
#include "evio_test/temp_dir.h"

namespace evio {
namespace {

using evio_test::TempDir;

// ---- Test-only writers of EVT word streams (little-endian), built from the format tables. ----

struct Evt3Stream {
  std::vector<uint16_t> words;
  Evt3Stream& word(uint32_t type, uint32_t payload) {
    words.push_back(static_cast<uint16_t>((type << 12) | (payload & 0xFFF)));
    return *this;
  }
  Evt3Stream& time_high(uint32_t h) { return word(0x8, h); }
  Evt3Stream& time_low(uint32_t l) { return word(0x6, l); }
  Evt3Stream& addr_y(uint32_t y) { return word(0x0, y); }
  Evt3Stream& addr_x(uint32_t x, int pol) { return word(0x2, x | (pol > 0 ? 0x800u : 0u)); }
  Evt3Stream& vect_base(uint32_t x, int pol) { return word(0x3, x | (pol > 0 ? 0x800u : 0u)); }
  Evt3Stream& vect12(uint32_t mask) { return word(0x4, mask); }
  Evt3Stream& vect8(uint32_t mask) { return word(0x5, mask & 0xFF); }
  Evt3Stream& trigger(uint32_t id, uint32_t value) { return word(0xA, (id << 8) | (value & 1)); }
  // Sets time to t_us (24-bit counter value) with a time high + time low pair.
  Evt3Stream& time(uint32_t t_us) { return time_high((t_us >> 12) & 0xFFF).time_low(t_us & 0xFFF); }
  std::string bytes() const {
    std::string b;
    for (uint16_t w : words) {
      b += static_cast<char>(w & 0xFF);
      b += static_cast<char>(w >> 8);
    }
    return b;
  }
};

struct Evt2Stream {
  std::vector<uint32_t> words;
  Evt2Stream& word(uint32_t w) {
    words.push_back(w);
    return *this;
  }
  Evt2Stream& time_high(uint32_t h) { return word((0x8u << 28) | (h & 0x0FFFFFFF)); }
  Evt2Stream& cd(uint32_t ts, uint32_t x, uint32_t y, int pol) {
    return word(((pol > 0 ? 1u : 0u) << 28) | ((ts & 63) << 22) | ((x & 0x7FF) << 11) | (y & 0x7FF));
  }
  Evt2Stream& trigger(uint32_t ts, uint32_t id, uint32_t value) {
    return word((0xAu << 28) | ((ts & 63) << 22) | ((id & 0x1F) << 8) | (value & 1));
  }
  std::string bytes() const {
    std::string b;
    for (uint32_t w : words) {
      for (int k = 0; k < 4; ++k) b += static_cast<char>((w >> (8 * k)) & 0xFF);
    }
    return b;
  }
};

const uint8_t* u8(const std::string& s) { return reinterpret_cast<const uint8_t*>(s.data()); }

Event ev(int64_t t_us, int x, int y, int pol) {
  return Event{t_us * 1000, static_cast<uint16_t>(x), static_cast<uint16_t>(y), static_cast<int8_t>(pol)};
}

template <class Decoder>
struct Decoded {
  std::vector<Event> events;
  std::vector<Trigger> triggers;
  EvtDecodeStats stats;
};

template <class Decoder>
Decoded<Decoder> decode_all(const std::string& bytes, size_t piece = 0) {
  Decoder d;
  Decoded<Decoder> out;
  if (piece == 0) {
    d.decode(u8(bytes), bytes.size(), &out.events, &out.triggers);
  } else {
    for (size_t i = 0; i < bytes.size(); i += piece) {
      d.decode(u8(bytes) + i, std::min(piece, bytes.size() - i), &out.events, &out.triggers);
    }
  }
  out.stats = d.stats();
  return out;
}

void expect_same_stats(const EvtDecodeStats& a, const EvtDecodeStats& b) {
  EXPECT_EQ(a.words, b.words);
  EXPECT_EQ(a.cd_events, b.cd_events);
  EXPECT_EQ(a.triggers, b.triggers);
  EXPECT_EQ(a.other_words, b.other_words);
  EXPECT_EQ(a.time_wraps, b.time_wraps);
  EXPECT_EQ(a.events_before_time, b.events_before_time);
  EXPECT_EQ(a.first_word_before_time, b.first_word_before_time);
}

// ---- EVT 3.0 decoder ----

TEST(Evt3Decoder, DecodesEveryWordType) {
  Evt3Stream s;
  s.time(0x123456).addr_y(17).addr_x(5, +1).addr_x(2047, -1);
  s.addr_y(700).vect_base(100, +1).vect12(0b100000000101).vect8(0b10000001);
  s.vect_base(200, -1).vect8(0x01).time_low(0x457).trigger(3, 1).trigger(15, 0);
  s.word(0x7, 0x123).word(0xE, 0x014).word(0xF, 0xABC).word(0x1, 0).word(0xD, 0);  // continued/others/unassigned
  s.addr_x(9, +1);
  const auto d = decode_all<Evt3Decoder>(s.bytes());
  const int64_t t0 = 0x123456, t1 = 0x123457;
  const std::vector<Event> want = {ev(t0, 5, 17, 1),    ev(t0, 2047, 17, -1), ev(t0, 100, 700, 1), ev(t0, 102, 700, 1),
                                   ev(t0, 111, 700, 1), ev(t0, 112, 700, 1),  ev(t0, 119, 700, 1), ev(t0, 200, 700, -1),
                                   ev(t1, 9, 700, 1)};
  ASSERT_EQ(d.events.size(), want.size());
  for (size_t i = 0; i < want.size(); ++i) EXPECT_EQ(d.events[i], want[i]) << "event " << i;
  ASSERT_EQ(d.triggers.size(), 2u);
  EXPECT_EQ(d.triggers[0].t_ns, t1 * 1000);
  EXPECT_EQ(d.triggers[0].channel, 3);
  EXPECT_EQ(d.triggers[0].polarity, 1);
  EXPECT_EQ(d.triggers[1].channel, 15);
  EXPECT_EQ(d.triggers[1].polarity, -1);
  EXPECT_EQ(d.stats.words, static_cast<int64_t>(s.words.size()));
  EXPECT_EQ(d.stats.cd_events, 9);
  EXPECT_EQ(d.stats.triggers, 2);
  EXPECT_EQ(d.stats.other_words, 5);
  EXPECT_EQ(d.stats.events_before_time, 0);
}

TEST(Evt3Decoder, TimeHighWrapUnwrapsThe24BitCounter) {
  Evt3Stream s;
  s.time(0xFFFFFE).addr_y(1).addr_x(1, 1);
  s.time_high(0x000).addr_x(2, 1).time_low(0x003).addr_x(3, 1);  // wrap; time low 0 until the next time low
  s.time_high(0xFFF).time_low(0).addr_x(4, 1);                    // wraps again: 0xFFF after 0x000 is a decrease of 1
  Evt3Decoder d;
  std::vector<Event> e;
  d.decode(u8(s.bytes()), s.bytes().size(), &e, nullptr);
  ASSERT_EQ(e.size(), 4u);
  const int64_t wrap = int64_t{1} << 24;
  EXPECT_EQ(e[0].t_ns, 0xFFFFFE * 1000LL);
  EXPECT_EQ(e[1].t_ns, wrap * 1000);
  EXPECT_EQ(e[2].t_ns, (wrap + 3) * 1000);
  // 0x000 -> 0xFFF is an increase of 4095 (more than half the range), not a wrap: time moves forward.
  EXPECT_EQ(e[3].t_ns, (wrap + 0xFFF000) * 1000);
  EXPECT_EQ(d.stats().time_wraps, 1);
  EXPECT_EQ(d.current_time_us(), wrap + 0xFFF000);
  // Many wraps in a row keep accumulating.
  Evt3Stream many;
  for (int k = 0; k < 10; ++k) many.time_high(0x000).time_high(0x400).time_high(0x800).time_high(0xC00);
  many.time_high(0x000).time_low(0).addr_y(0).addr_x(0, 1);
  const auto dm = decode_all<Evt3Decoder>(many.bytes());
  EXPECT_EQ(dm.stats.time_wraps, 10);
  ASSERT_EQ(dm.events.size(), 1u);
  EXPECT_EQ(dm.events[0].t_ns, 10 * wrap * 1000);
}

TEST(Evt3Decoder, SmallTimeHighDecreaseIsNotAWrap) {
  Evt3Stream s;
  s.time(0x500000).addr_y(0).addr_x(0, 1).time(0x4FF000).addr_x(1, 1);
  const auto d = decode_all<Evt3Decoder>(s.bytes());
  ASSERT_EQ(d.events.size(), 2u);
  EXPECT_EQ(d.stats.time_wraps, 0);
  EXPECT_LT(d.events[1].t_ns, d.events[0].t_ns);  // the decoder reports it; readers treat it as bad data
}

TEST(Evt3Decoder, EventsBeforeTheFirstTimeBaseAreDroppedAndCounted) {
  Evt3Stream s;
  s.addr_y(3).addr_x(1, 1).vect_base(10, 1).vect12(0b111).trigger(1, 1);  // no time at all: 5 dropped
  s.time_high(0x001).addr_x(2, 1).vect8(0b11);  // time high without time low: 3 dropped, base x advanced by 12 then 8
  s.time_low(0x002).addr_x(4, -1).vect8(0b1);
  Evt3Decoder d;
  std::vector<Event> e;
  std::vector<Trigger> tr;
  EXPECT_FALSE(d.has_time());
  d.decode(u8(s.bytes()), s.bytes().size(), &e, &tr);
  EXPECT_TRUE(d.has_time());
  EXPECT_EQ(d.stats().events_before_time, 8);
  EXPECT_EQ(d.stats().first_word_before_time, 1);
  EXPECT_TRUE(tr.empty());
  ASSERT_EQ(e.size(), 2u);
  EXPECT_EQ(e[0], ev(0x1002, 4, 3, -1));
  EXPECT_EQ(e[1], ev(0x1002, 10 + 12 + 8, 3, 1));  // vector state kept through the prelude
}

TEST(Evt3Decoder, FeedingInPiecesOfAnySizeGivesTheSameOutput) {
  std::mt19937 rng(11);
  Evt3Stream s;
  s.word(0x2, 7);  // before time
  s.time(0);
  uint32_t t = 0;
  for (int i = 0; i < 3000; ++i) {
    switch (rng() % 9) {
      case 0: t += rng() % 5000; s.time(t & 0xFFFFFF); break;
      case 1: t += rng() % 200; s.time_low(t & 0xFFF); break;
      case 2: s.addr_y(rng() % 720); break;
      case 3: s.addr_x(rng() % 1280, rng() % 2 ? 1 : -1); break;
      case 4: s.vect_base(rng() % 1200, rng() % 2 ? 1 : -1); break;
      case 5: s.vect12(rng()); break;
      case 6: s.vect8(rng()); break;
      case 7: s.trigger(rng() % 16, rng() % 2); break;
      default: s.word(0xE, rng()); break;
    }
  }
  const std::string bytes = s.bytes();
  const auto whole = decode_all<Evt3Decoder>(bytes);
  ASSERT_GT(whole.events.size(), 1000u);
  ASSERT_GT(whole.triggers.size(), 100u);
  for (size_t piece = 1; piece <= 7; ++piece) {
    SCOPED_TRACE("piece size " + std::to_string(piece));
    const auto parts = decode_all<Evt3Decoder>(bytes, piece);
    ASSERT_EQ(parts.events.size(), whole.events.size());
    EXPECT_TRUE(std::equal(parts.events.begin(), parts.events.end(), whole.events.begin()));
    ASSERT_EQ(parts.triggers.size(), whole.triggers.size());
    for (size_t i = 0; i < whole.triggers.size(); ++i) {
      EXPECT_EQ(parts.triggers[i].t_ns, whole.triggers[i].t_ns);
      EXPECT_EQ(parts.triggers[i].channel, whole.triggers[i].channel);
      EXPECT_EQ(parts.triggers[i].polarity, whole.triggers[i].polarity);
    }
    expect_same_stats(parts.stats, whole.stats);
  }
}

TEST(Evt3Decoder, KeepsAPartialTrailingByteAndAppliesTheTimeOffset) {
  Evt3Stream s;
  s.time(1000).addr_y(2).addr_x(3, 1);
  const std::string b = s.bytes();
  Evt3Decoder d;
  d.set_time_offset_ns(-500);
  std::vector<Event> e;
  d.decode(u8(b), b.size() - 1, &e, nullptr);
  EXPECT_TRUE(e.empty());
  EXPECT_EQ(d.pending_bytes(), 1u);
  d.decode(u8(b) + b.size() - 1, 1, &e, nullptr);
  EXPECT_EQ(d.pending_bytes(), 0u);
  ASSERT_EQ(e.size(), 1u);
  EXPECT_EQ(e[0].t_ns, 1000 * 1000 - 500);
  EXPECT_EQ(d.current_time_us(), 1000);
  d.reset();
  EXPECT_FALSE(d.has_time());
  EXPECT_EQ(d.stats().words, 0);
  EXPECT_EQ(d.time_offset_ns(), -500);  // reset keeps the configured offset
  d.decode(u8(b), b.size(), &e, nullptr);
  EXPECT_EQ(e.size(), 2u);
}

TEST(Evt3Decoder, VectorBaseXNeverWrapsIntoTheSensor) {
  Evt3Stream s;
  s.time(5).addr_y(1).vect_base(2040, 1);
  for (int i = 0; i < 6000; ++i) s.vect12(0xFFF);  // base x would pass 65535 without saturation
  const auto d = decode_all<Evt3Decoder>(s.bytes());
  ASSERT_EQ(d.events.size(), 6000u * 12);
  for (const Event& e : d.events) ASSERT_GE(e.x, 2040);
}

// ---- EVT 2.0 decoder ----

TEST(Evt2Decoder, DecodesEveryWordType) {
  Evt2Stream s;
  s.cd(1, 2, 3, 1).trigger(0, 1, 1);  // before the first time high: dropped, counted
  s.time_high(1000).cd(5, 639, 479, 1).cd(63, 0, 0, -1).trigger(7, 31, 1).trigger(8, 2, 0);
  s.word(0xEu << 28).word(0xFu << 28).word(0x5u << 28);
  s.time_high(1001).cd(0, 10, 20, -1);
  const auto d = decode_all<Evt2Decoder>(s.bytes());
  const std::vector<Event> want = {ev(64000 + 5, 639, 479, 1), ev(64000 + 63, 0, 0, -1), ev(64064, 10, 20, -1)};
  ASSERT_EQ(d.events.size(), want.size());
  for (size_t i = 0; i < want.size(); ++i) EXPECT_EQ(d.events[i], want[i]) << "event " << i;
  ASSERT_EQ(d.triggers.size(), 2u);
  EXPECT_EQ(d.triggers[0].t_ns, 64007 * 1000);
  EXPECT_EQ(d.triggers[0].channel, 31);
  EXPECT_EQ(d.triggers[0].polarity, 1);
  EXPECT_EQ(d.triggers[1].t_ns, 64008 * 1000);
  EXPECT_EQ(d.triggers[1].channel, 2);
  EXPECT_EQ(d.triggers[1].polarity, -1);
  EXPECT_EQ(d.stats.events_before_time, 2);
  EXPECT_EQ(d.stats.first_word_before_time, 0);
  EXPECT_EQ(d.stats.other_words, 3);
  EXPECT_EQ(d.stats.cd_events, 3);
  EXPECT_EQ(d.stats.triggers, 2);
  EXPECT_EQ(d.stats.words, static_cast<int64_t>(s.words.size()));
}

TEST(Evt2Decoder, TimeHighWrapUnwrapsThe34BitCounter) {
  Evt2Stream s;
  s.time_high(0x0FFFFFFF).cd(63, 1, 1, 1).time_high(0).cd(1, 2, 2, 1).time_high(0x08000000).cd(0, 3, 3, 1);
  Evt2Decoder d;
  std::vector<Event> e;
  d.decode(u8(s.bytes()), s.bytes().size(), &e, nullptr);
  ASSERT_EQ(e.size(), 3u);
  const int64_t period = int64_t{1} << 34;
  EXPECT_EQ(e[0].t_ns, (period - 1) * 1000);
  EXPECT_EQ(e[1].t_ns, (period + 1) * 1000);
  EXPECT_EQ(e[2].t_ns, (period + (int64_t{0x08000000} << 6)) * 1000);
  EXPECT_EQ(d.stats().time_wraps, 1);
  EXPECT_EQ(d.current_time_us(), period + (int64_t{0x08000000} << 6));
}

TEST(Evt2Decoder, FeedingInPiecesOfAnySizeGivesTheSameOutput) {
  std::mt19937 rng(5);
  Evt2Stream s;
  s.cd(0, 1, 1, 1);
  uint32_t th = 100;
  s.time_high(th);
  for (int i = 0; i < 4000; ++i) {
    const uint32_t r = rng() % 10;
    if (r == 0) s.time_high(th += rng() % 3);
    else if (r == 1) s.trigger(rng() % 64, rng() % 32, rng() % 2);
    else if (r == 2) s.word((0xEu << 28) | (rng() & 0xFFFFFFF));
    else s.cd(rng() % 64, rng() % 640, rng() % 480, rng() % 2 ? 1 : -1);
  }
  const std::string bytes = s.bytes();
  const auto whole = decode_all<Evt2Decoder>(bytes);
  ASSERT_GT(whole.events.size(), 2500u);
  for (size_t piece = 1; piece <= 7; ++piece) {
    SCOPED_TRACE("piece size " + std::to_string(piece));
    const auto parts = decode_all<Evt2Decoder>(bytes, piece);
    ASSERT_EQ(parts.events.size(), whole.events.size());
    EXPECT_TRUE(std::equal(parts.events.begin(), parts.events.end(), whole.events.begin()));
    ASSERT_EQ(parts.triggers.size(), whole.triggers.size());
    for (size_t i = 0; i < whole.triggers.size(); ++i) EXPECT_EQ(parts.triggers[i].t_ns, whole.triggers[i].t_ns);
    expect_same_stats(parts.stats, whole.stats);
  }
}

// ---- RAW files ----

std::string write_raw(const TempDir& dir, const std::string& name, const std::string& header, const std::string& body) {
  const std::string path = dir.file(name);
  {
    std::ofstream f(path, std::ios::binary);
    f << header << body;
  }
  const bool evt2 = header.find("EVT2") != std::string::npos || header.find("evt 2") != std::string::npos;
  evio_test::export_fuzz_seed(path, evt2 ? "fuzz_evt2" : "fuzz_evt3");
  return path;
}

EventBuffer read_all(DatasetReader* r, size_t max_events = size_t{1} << 18) {
  EventBuffer out;
  while (r->read_events(&out, max_events) > 0) {
  }
  return out;
}

// Opens with open_evt_dataset and reads all events and triggers; expects an InputError whose
// message names the file and contains every fragment.
void expect_error(const std::string& path, const std::vector<std::string>& fragments, const DatasetOptions& opts = {}) {
  try {
    auto r = open_evt_dataset(path, opts);
    read_all(r.get());
    r->read_triggers();
    FAIL() << "no error for " << path;
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(path), std::string::npos) << msg;
    for (const std::string& f : fragments) EXPECT_NE(msg.find(f), std::string::npos) << "'" << f << "' not in: " << msg;
  }
}

const char* kEvt3Header = "% date 2024-01-01\n% format EVT3;height=720;width=1280\n% end\n";

TEST(EvtFile, ReadsEvt3WithGeometryFromTheFormatLine) {
  TempDir dir;
  Evt3Stream s;
  s.time(100).addr_y(719).addr_x(1279, 1).vect_base(0, -1).vect12(0b11).time_low(101).trigger(2, 1).addr_x(4, 1);
  const std::string path = write_raw(dir, "a.raw", kEvt3Header, s.bytes());
  const EvtRawHeader h = parse_evt_raw_header(path);
  EXPECT_EQ(h.version, 3);
  EXPECT_TRUE(h.has_end);
  EXPECT_EQ(h.lines, 3);
  EXPECT_EQ(h.data_offset, std::string(kEvt3Header).size());
  auto r = open_evt_dataset(path, {});
  EXPECT_EQ(r->format(), DatasetFormat::kEvt3);
  EXPECT_EQ(r->sensor_size().width, 1280);
  EXPECT_EQ(r->sensor_size().height, 720);
  const EventBuffer e = read_all(r.get());
  ASSERT_EQ(e.size(), 4u);
  EXPECT_EQ(e[0], ev(100, 1279, 719, 1));
  EXPECT_EQ(e[1], ev(100, 0, 719, -1));
  EXPECT_EQ(e[2], ev(100, 1, 719, -1));
  EXPECT_EQ(e[3], ev(101, 4, 719, 1));
  EXPECT_DOUBLE_EQ(r->progress(), 1.0);
  const ReadReport& rep = r->event_report();
  EXPECT_EQ(rep.records, 4);
  EXPECT_EQ(rep.time_unit, TimeUnit::kMicroseconds);
  EXPECT_EQ(rep.polarity, PolarityConvention::kZeroOne);
  EXPECT_EQ(rep.skipped_total(), 0);
  const std::vector<Trigger> tr = r->read_triggers();
  ASSERT_EQ(tr.size(), 1u);
  EXPECT_EQ(tr[0].t_ns, 101000);
  EXPECT_EQ(tr[0].channel, 2);
}

TEST(EvtFile, ReadsEvt2WithEitherGeometryForm) {
  TempDir dir;
  Evt2Stream s;
  s.time_high(10).cd(1, 639, 479, 1).cd(2, 0, 0, -1).trigger(3, 0, 1);
  for (const std::string header : {"% evt 2.0\n% geometry 640x480\n", "% format EVT2;width=640;height=480\n% end\n",
                                   "% evt 2.0\n% width 640\n% height 480\n"}) {
    SCOPED_TRACE(header);
    const std::string path = write_raw(dir, "b.raw", header, s.bytes());
    auto r = open_evt_dataset(path, {});
    EXPECT_EQ(r->format(), DatasetFormat::kEvt2);
    EXPECT_EQ(r->sensor_size().width, 640);
    EXPECT_EQ(r->sensor_size().height, 480);
    const EventBuffer e = read_all(r.get());
    ASSERT_EQ(e.size(), 2u);
    EXPECT_EQ(e[0], ev(641, 639, 479, 1));
    EXPECT_EQ(e[1], ev(642, 0, 0, -1));
    ASSERT_EQ(r->read_triggers().size(), 1u);
  }
}

TEST(EvtFile, SensorSizeFromOptionsOnlyWhenTheHeaderHasNone) {
  TempDir dir;
  Evt3Stream s;
  s.time(1).addr_y(600).addr_x(1000, 1);
  DatasetOptions opts;
  opts.text.sensor = SensorSize{320, 240};
  // The header's geometry wins over the options.
  auto r = open_evt_dataset(write_raw(dir, "g.raw", kEvt3Header, s.bytes()), opts);
  EXPECT_EQ(r->sensor_size().width, 1280);
  EXPECT_EQ(read_all(r.get()).size(), 1u);
  // No geometry in the header: the options apply (and this event is then outside the sensor).
  const std::string bare = write_raw(dir, "n.raw", "% evt 3.0\n% plugin_name hal_plugin_gen41_evk3\n", s.bytes());
  r = open_evt_dataset(bare, opts);
  EXPECT_EQ(r->sensor_size().width, 320);
  EXPECT_EQ(r->sensor_size().height, 240);
  // Neither: the plugin table of older files.
  r = open_evt_dataset(bare, {});
  EXPECT_EQ(r->sensor_size().width, 1280);
  EXPECT_EQ(r->sensor_size().height, 720);
  // Unknown plugin and no options: size unknown, coordinates unchecked.
  r = open_evt_dataset(write_raw(dir, "u.raw", "% evt 3.0\n", s.bytes()), {});
  EXPECT_FALSE(r->sensor_size().known());
  EXPECT_EQ(read_all(r.get()).size(), 1u);
}

TEST(EvtFile, HeaderWithoutVersionNeedsTheFormatOption) {
  TempDir dir;
  Evt3Stream s;
  s.time(1).addr_y(1).addr_x(1, 1);
  const std::string path = write_raw(dir, "nov.raw", "% geometry 640x480\n", s.bytes());
  expect_error(path, {"no event format version in the header", "expected: a header line '% evt 2.0'"});
  DatasetOptions opts;
  opts.format = DatasetFormat::kEvt3;
  auto r = open_evt_dataset(path, opts);
  EXPECT_EQ(read_all(r.get()).size(), 1u);
  // A headerless dump with the format given.
  r = open_evt_dataset(write_raw(dir, "dump.raw", "", s.bytes()), opts);
  EXPECT_EQ(read_all(r.get()).size(), 1u);
}

TEST(EvtFile, ReadsInAnyBatchSize) {
  TempDir dir;
  std::mt19937 rng(2);
  Evt3Stream s;
  uint32_t t = 0;
  s.time(0);
  for (int i = 0; i < 60000; ++i) {
    if (i % 50 == 0) s.time((t += 7) & 0xFFFFFF);
    s.addr_y(rng() % 720);
    if (rng() % 2) s.addr_x(rng() % 1280, 1);
    else s.vect_base(rng() % 1200, -1).vect12(rng());
  }
  const std::string path = write_raw(dir, "big.raw", kEvt3Header, s.bytes());
  auto r = open_evt_dataset(path, {});
  const EventBuffer all = read_all(r.get(), size_t{1} << 30);
  ASSERT_GT(all.size(), 100000u);  // several 64 KiB pieces
  EXPECT_TRUE(all.is_time_sorted());
  for (size_t batch : {size_t{1}, size_t{777}, size_t{100000}}) {
    auto r2 = open_evt_dataset(path, {});
    const EventBuffer b = read_all(r2.get(), batch);
    ASSERT_EQ(b.size(), all.size()) << "batch " << batch;
    EXPECT_TRUE(std::equal(b.begin(), b.end(), all.begin())) << "batch " << batch;
    EXPECT_EQ(r2->event_report().records, static_cast<int64_t>(all.size()));
  }
}

TEST(EvtFile, EventsBeforeTheTimeBaseAreCountedInTheReport) {
  TempDir dir;
  Evt2Stream s;
  s.cd(0, 1, 1, 1).cd(0, 2, 2, 1).time_high(5).cd(0, 3, 3, 1);
  const std::string header = "% evt 2.0\n% geometry 640x480\n";
  auto r = open_evt_dataset(write_raw(dir, "pre.raw", header, s.bytes()), {});
  EXPECT_EQ(read_all(r.get()).size(), 1u);
  const auto& sk = r->event_report().skipped;
  ASSERT_EQ(sk.count("before time base"), 1u);
  EXPECT_EQ(sk.at("before time base").count, 2);
  EXPECT_EQ(sk.at("before time base").first_line, static_cast<int64_t>(header.size()));
}

// ---- malformed files ----

TEST(EvtFile, MissingHeaderEndIsAnError) {
  TempDir dir;
  expect_error(write_raw(dir, "h.raw", "% evt 3.0\n% geometry 640x480", ""),
               {"file ends inside the header", "header line at byte offset 10 has no end of line",
                "expected: '%' header lines each ending in a newline"});
}

TEST(EvtFile, OverlongHeaderIsAnError) {
  TempDir dir;
  expect_error(write_raw(dir, "long.raw", "% evt 3.0\n% " + std::string((1 << 20) + 10, 'a'), ""),
               {"header longer than 1 MiB (no line ends it)"});
}

TEST(EvtFile, HeaderOnlyFileHasNoEvents) {
  TempDir dir;
  auto r = open_evt_dataset(write_raw(dir, "empty.raw", kEvt3Header, ""), {});
  EventBuffer e;
  EXPECT_EQ(r->read_events(&e, 100), 0u);
  EXPECT_DOUBLE_EQ(r->progress(), 1.0);
  EXPECT_TRUE(r->read_triggers().empty());
}

TEST(EvtFile, UnknownVersionIsAnError) {
  TempDir dir;
  expect_error(write_raw(dir, "v.raw", "% evt 2.1\n", ""),
               {"unsupported event format '2.1' in the header", "expected: a header line '% evt 2.0' / '% evt 3.0'"});
  expect_error(write_raw(dir, "w.raw", "% format EVT21;height=720;width=1280\n% end\n", ""),
               {"unsupported event format 'EVT21'"});
  expect_error(write_raw(dir, "x.raw", "% evt 2.0\n% format EVT3\n% end\n", ""),
               {"header names two formats: '% evt 2.0' and '% format EVT3' at byte offset 10"});
  DatasetOptions opts;
  opts.format = DatasetFormat::kEvt2;
  expect_error(write_raw(dir, "y.raw", kEvt3Header, ""), {"the header says EVT 3.0 but format evt2 was requested"}, opts);
}

TEST(EvtFile, MalformedGeometryIsAnError) {
  TempDir dir;
  expect_error(write_raw(dir, "g1.raw", "% evt 3.0\n% geometry 640by480\n", ""),
               {"malformed sensor size in header line '% geometry 640by480' at byte offset 10",
                "expected: a width and height in 1..2048 px"});
  expect_error(write_raw(dir, "g2.raw", "% format EVT3;height=720;width=4096\n", ""),
               {"malformed sensor size in header line '% format EVT3;height=720;width=4096' at byte offset 0"});
  expect_error(write_raw(dir, "g3.raw", "% evt 3.0\n% width 640\n", ""), {"header gives the sensor width only"});
}

TEST(EvtFile, TruncatedFinalWordIsAnError) {
  TempDir dir;
  Evt3Stream s3;
  s3.time(1).addr_y(1).addr_x(1, 1);
  const std::string h3 = kEvt3Header;
  const std::string p3 = write_raw(dir, "t3.raw", h3, s3.bytes() + std::string(1, '\x20'));
  expect_error(p3, {"truncated final word: the file ends 1 byte(s) into a 16-bit EVT 3.0 word at byte offset " +
                        std::to_string(h3.size() + s3.bytes().size()),
                    "expected: whole 16-bit little-endian words after the header"});
  Evt2Stream s2;
  s2.time_high(1).cd(0, 1, 1, 1);
  const std::string h2 = "% evt 2.0\n% geometry 640x480\n";
  expect_error(write_raw(dir, "t2.raw", h2, s2.bytes() + std::string(3, '\x10')),
               {"the file ends 3 byte(s) into a 32-bit EVT 2.0 word at byte offset " +
                std::to_string(h2.size() + s2.bytes().size())});
  // The trigger pass reports the same word without reading events first.
  try {
    open_evt_dataset(p3, {})->read_triggers();
    FAIL() << "no error from read_triggers";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("at byte offset " + std::to_string(h3.size() + s3.bytes().size())),
              std::string::npos)
        << e.what();
  }
  // Skipped and counted under the warn policy; the whole words before it are kept.
  DatasetOptions warn;
  warn.text.on_bad_line = BadLinePolicy::kWarnAndSkip;
  auto r = open_evt_dataset(p3, warn);
  EXPECT_EQ(read_all(r.get()).size(), 1u);
  EXPECT_EQ(r->event_report().skipped.at("truncated word").count, 1);
}

TEST(EvtFile, CoordinatesOutsideTheSensorAreBadData) {
  TempDir dir;
  Evt3Stream s;
  s.time(1).addr_y(10).addr_x(5, 1).addr_x(1280, 1).addr_y(720).addr_x(6, 1).addr_y(11).addr_x(7, 1);
  const std::string h = kEvt3Header;
  const std::string path = write_raw(dir, "o.raw", h, s.bytes());
  // The bad word is the 5th (index 4) after the header.
  expect_error(path, {"event at x=1280 y=10 outside the 1280x720 sensor at byte offset " + std::to_string(h.size() + 8),
                      "expected: x < 1280 and y < 720"});
  DatasetOptions warn;
  warn.text.on_bad_line = BadLinePolicy::kWarnAndSkip;
  auto r = open_evt_dataset(path, warn);
  const EventBuffer e = read_all(r.get());
  ASSERT_EQ(e.size(), 2u);
  EXPECT_EQ(e[0].x, 5);
  EXPECT_EQ(e[1].x, 7);
  const auto& sk = r->event_report().skipped.at("outside sensor");
  EXPECT_EQ(sk.count, 2);
  EXPECT_EQ(sk.first_line, static_cast<int64_t>(h.size() + 8));
}

TEST(EvtFile, TimeGoingBackIsBadData) {
  TempDir dir;
  Evt3Stream s;
  s.time(0x5000).addr_y(1).addr_x(1, 1).time(0x4000).addr_x(2, 1).time(0x5001).addr_x(3, 1);
  const std::string h = kEvt3Header;
  const std::string path = write_raw(dir, "t.raw", h, s.bytes());
  expect_error(path, {"event time goes back from 20480 us to 16384 us at byte offset " + std::to_string(h.size() + 12),
                      "expected: non-decreasing event time"});
  DatasetOptions warn;
  warn.text.on_bad_line = BadLinePolicy::kWarnAndSkip;
  auto r = open_evt_dataset(path, warn);
  const EventBuffer e = read_all(r.get());
  ASSERT_EQ(e.size(), 2u);
  EXPECT_EQ(e[1].t_ns, 0x5001 * 1000LL);
  EXPECT_EQ(r->event_report().skipped.at("time order").count, 1);
}

TEST(EvtFile, TriggersGoingBackInTimeAreBadData) {
  TempDir dir;
  Evt3Stream s;
  s.time(0x3000).trigger(1, 1).time(0x2000).trigger(1, 0).time(0x3001).trigger(2, 1);
  const std::string path = write_raw(dir, "tr.raw", kEvt3Header, s.bytes());
  try {
    open_evt_dataset(path, {})->read_triggers();
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("trigger time goes back from 12288000 ns to 8192000 ns"), std::string::npos)
        << e.what();
  }
  DatasetOptions warn;
  warn.text.on_bad_line = BadLinePolicy::kWarnAndSkip;
  const std::vector<Trigger> tr = open_evt_dataset(path, warn)->read_triggers();
  ASSERT_EQ(tr.size(), 2u);
  EXPECT_EQ(tr[0].t_ns, 0x3000 * 1000LL);
  EXPECT_EQ(tr[1].t_ns, 0x3001 * 1000LL);
  EXPECT_EQ(tr[1].channel, 2);
}

TEST(EvtFile, NonexistentFileIsAnError) {
  expect_error("/nonexistent/evt.raw", {"cannot open"});
}

// ---- real samples ----

struct SampleCheck {
  int64_t events = 0;
  bool sorted = true;
  bool inside = true;
};

SampleCheck read_sample(const std::string& path, int width, int height, DatasetFormat format) {
  auto r = open_evt_dataset(path, {});
  EXPECT_EQ(r->format(), format);
  EXPECT_EQ(r->sensor_size().width, width);
  EXPECT_EQ(r->sensor_size().height, height);
  SampleCheck c;
  EventBuffer chunk;
  int64_t last = INT64_MIN;
  while (true) {
    chunk.clear();
    if (r->read_events(&chunk, 50000) == 0) break;
    for (const Event& e : chunk) {
      c.sorted &= e.t_ns >= last;
      last = e.t_ns;
      c.inside &= e.x < width && e.y < height;
      EXPECT_TRUE(e.polarity == 1 || e.polarity == -1);
    }
    c.events += static_cast<int64_t>(chunk.size());
  }
  EXPECT_EQ(r->event_report().records, c.events);
  EXPECT_EQ(r->event_report().skipped_total(), 0);
  EXPECT_DOUBLE_EQ(r->progress(), 1.0);
  EXPECT_TRUE(r->read_triggers().empty());  // these recordings have no trigger input events
  return c;
}

TEST(EvtReal, Evt2SampleHasExactCount) {
  const auto dir = evio_test::real_data_dir("prophesee_raw");
  if (!dir) GTEST_SKIP() << "real data not found (../shared/data/real/prophesee_raw)";
  const SampleCheck c = read_sample(*dir + "/evt2_sample.raw", 640, 480, DatasetFormat::kEvt2);
  EXPECT_EQ(c.events, 539481);
  EXPECT_TRUE(c.sorted);
  EXPECT_TRUE(c.inside);
}

TEST(EvtReal, Evt3SampleHasExactCount) {
  const auto dir = evio_test::real_data_dir("prophesee_raw");
  if (!dir) GTEST_SKIP() << "real data not found (../shared/data/real/prophesee_raw)";
  const SampleCheck c = read_sample(*dir + "/evt3_sample.raw", 1280, 720, DatasetFormat::kEvt3);
  EXPECT_EQ(c.events, 219596);
  EXPECT_TRUE(c.sorted);
  EXPECT_TRUE(c.inside);
}

TEST(EvtReal, DecoderStatsOnTheSamples) {
  const auto dir = evio_test::real_data_dir("prophesee_raw");
  if (!dir) GTEST_SKIP() << "real data not found (../shared/data/real/prophesee_raw)";
  for (const char* name : {"evt2_sample.raw", "evt3_sample.raw"}) {
    const std::string path = *dir + "/" + name;
    const EvtRawHeader h = parse_evt_raw_header(path);
    std::ifstream f(path, std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    bytes.erase(0, h.data_offset);
    std::vector<Event> e;
    std::vector<Trigger> tr;
    EvtDecodeStats st;
    if (h.version == 3) {
      Evt3Decoder d;
      d.decode(u8(bytes), bytes.size(), &e, &tr);
      st = d.stats();
      EXPECT_EQ(st.words, static_cast<int64_t>(bytes.size() / 2));
    } else {
      Evt2Decoder d;
      d.decode(u8(bytes), bytes.size(), &e, &tr);
      st = d.stats();
      EXPECT_EQ(st.words, static_cast<int64_t>(bytes.size() / 4));
    }
    EXPECT_EQ(st.cd_events, h.version == 3 ? 219596 : 539481) << name;
    EXPECT_EQ(static_cast<int64_t>(e.size()), st.cd_events);
    EXPECT_EQ(st.triggers, 0);
    EXPECT_EQ(st.events_before_time, 0);
    EXPECT_EQ(st.time_wraps, 0);
  }
}

}  // namespace
}  // namespace evio
