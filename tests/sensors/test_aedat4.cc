// Tests of the AEDAT 4.0 reader: the real DAVIS346 sample (exact counts, physical plausibility)
// and small files written here by a test-only AEDAT 4.0 writer (flatbuffers laid out by hand,
// packets compressed with liblz4 / libzstd), including malformed files.
#include "evio/sensors/aedat4.h"

#include <lz4frame.h>
#include <zstd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio_test/fuzz_seed.h"
#include "evio_test/real_data.h"
#include "evio_test/temp_dir.h"

namespace evio {
namespace {

using Bytes = std::vector<uint8_t>;

// ---------------------------------------------------------------------------------------------
// Test-only flatbuffer builder. Objects are laid out front to back: root uoffset, identifier, then
// each table preceded by its vtable; vectors and sub-tables are appended after the table that
// points to them (uoffsets point forward, as the format requires).

struct FbField {
  int index;     // schema field index
  Bytes bytes;   // inline value (scalar or struct); 4 zero bytes for a uoffset patched later
  size_t align;  // alignment of the value
};

template <typename T>
FbField scalar_field(int index, T v) {
  Bytes b(sizeof(T));
  std::memcpy(b.data(), &v, sizeof(T));
  return FbField{index, b, sizeof(T)};
}
FbField offset_field(int index) { return FbField{index, Bytes(4, 0), 4}; }

class FbBuilder {
 public:
  explicit FbBuilder(const char* identifier) {
    put<uint32_t>(0);
    b_.insert(b_.end(), identifier, identifier + 4);
  }
  template <typename T>
  void put(T v) {
    const size_t at = b_.size();
    b_.resize(at + sizeof(T));
    std::memcpy(b_.data() + at, &v, sizeof(T));
  }
  template <typename T>
  void set(size_t at, T v) {
    std::memcpy(b_.data() + at, &v, sizeof(T));
  }
  void align(size_t a) {
    while (b_.size() % a != 0) b_.push_back(0);
  }
  // Writes vtable + table; returns the table position and the position of each field by index.
  size_t table(const std::vector<FbField>& fields, std::map<int, size_t>* positions = nullptr) {
    int max_index = -1;
    for (const FbField& f : fields) max_index = std::max(max_index, f.index);
    // Table body layout: soffset, then fields each aligned (relative to an 8-aligned table start).
    std::vector<uint16_t> offsets(static_cast<size_t>(max_index + 1), 0);
    size_t tsize = 4;
    std::vector<size_t> field_off(fields.size());
    for (size_t k = 0; k < fields.size(); ++k) {
      while (tsize % fields[k].align != 0) ++tsize;
      field_off[k] = tsize;
      offsets[static_cast<size_t>(fields[k].index)] = static_cast<uint16_t>(tsize);
      tsize += fields[k].bytes.size();
    }
    const size_t vsize = 4 + 2 * offsets.size();
    // vtable, then pad so that the table starts 8-aligned.
    align(2);
    size_t vt = b_.size();
    while ((vt + vsize) % 8 != 0) {
      b_.push_back(0);
      vt = b_.size();
    }
    put<uint16_t>(static_cast<uint16_t>(vsize));
    put<uint16_t>(static_cast<uint16_t>(tsize));
    for (uint16_t o : offsets) put<uint16_t>(o);
    const size_t t = b_.size();
    put<int32_t>(static_cast<int32_t>(t - vt));
    b_.resize(t + tsize, 0);
    for (size_t k = 0; k < fields.size(); ++k) {
      std::memcpy(b_.data() + t + field_off[k], fields[k].bytes.data(), fields[k].bytes.size());
      if (positions != nullptr) (*positions)[fields[k].index] = t + field_off[k];
    }
    return t;
  }
  // Vector of n elements of elem bytes; returns the position of its length field.
  size_t vector(const void* data, uint32_t n, size_t elem, size_t elem_align) {
    // Length at a position such that the elements are aligned.
    while ((b_.size() + 4) % std::max<size_t>(elem_align, 4) != 0) b_.push_back(0);
    const size_t at = b_.size();
    put<uint32_t>(n);
    const auto* p = static_cast<const uint8_t*>(data);
    b_.insert(b_.end(), p, p + n * elem);
    return at;
  }
  void patch(size_t at, size_t target) { set<uint32_t>(at, static_cast<uint32_t>(target - at)); }
  void set_root(size_t table) { set<uint32_t>(0, static_cast<uint32_t>(table)); }
  Bytes& bytes() { return b_; }
  size_t size() const { return b_.size(); }

  // Vector of tables: writes n uoffset slots now; patch each with patch_table(j, table).
  size_t table_vector(uint32_t n) {
    align(4);
    const size_t at = b_.size();
    put<uint32_t>(n);
    b_.resize(b_.size() + 4 * n, 0);
    return at;
  }
  void patch_table(size_t vec, uint32_t j, size_t table) { patch(vec + 4 + 4 * j, table); }

  Bytes size_prefixed() const {
    Bytes out(4);
    const uint32_t n = static_cast<uint32_t>(b_.size());
    std::memcpy(out.data(), &n, 4);
    out.insert(out.end(), b_.begin(), b_.end());
    return out;
  }

 private:
  Bytes b_;
};

// ---------------------------------------------------------------------------------------------
// dv packet builders

struct RawEvent {
  int64_t t_us;
  int16_t x, y;
  bool on;
};

Bytes event_packet(const std::vector<RawEvent>& events) {
  FbBuilder fb("EVTS");
  std::map<int, size_t> pos;
  const size_t t = fb.table({offset_field(0)}, &pos);
  fb.set_root(t);
  Bytes el(events.size() * 16, 0);
  for (size_t i = 0; i < events.size(); ++i) {
    std::memcpy(&el[16 * i], &events[i].t_us, 8);
    std::memcpy(&el[16 * i + 8], &events[i].x, 2);
    std::memcpy(&el[16 * i + 10], &events[i].y, 2);
    el[16 * i + 12] = events[i].on ? 1 : 0;
  }
  const size_t v = fb.vector(el.data(), static_cast<uint32_t>(events.size()), 16, 8);
  fb.patch(pos[0], v);
  return fb.size_prefixed();
}

struct RawImu {
  int64_t t_us;
  float accel[3];                 // g
  float gyro[3];                  // deg/s
  bool omit_zero_fields = false;  // leave fields equal to 0 out of the table (schema default)
};

Bytes imu_packet(const std::vector<RawImu>& samples) {
  FbBuilder fb("IMUS");
  std::map<int, size_t> pos;
  const size_t root = fb.table({offset_field(0)}, &pos);
  fb.set_root(root);
  const size_t vec = fb.table_vector(static_cast<uint32_t>(samples.size()));
  fb.patch(pos[0], vec);
  for (uint32_t j = 0; j < samples.size(); ++j) {
    const RawImu& s = samples[j];
    std::vector<FbField> f = {scalar_field<int64_t>(0, s.t_us), scalar_field<float>(1, 25.0f)};
    for (int k = 0; k < 3; ++k) {
      if (!s.omit_zero_fields || s.accel[k] != 0.0f) f.push_back(scalar_field<float>(2 + k, s.accel[k]));
    }
    for (int k = 0; k < 3; ++k) {
      if (!s.omit_zero_fields || s.gyro[k] != 0.0f) f.push_back(scalar_field<float>(5 + k, s.gyro[k]));
    }
    fb.patch_table(vec, j, fb.table(f));
  }
  return fb.size_prefixed();
}

struct RawFrame {
  int64_t t_us = 0;
  bool with_exposure = true;
  int64_t soe_us = 0, eoe_us = 0;
  int8_t format = 0;  // 0 GRAY, 16 BGR, 24 BGRA
  int16_t w = 0, h = 0;
  Bytes pixels;
};

Bytes frame_packet(const RawFrame& fr) {
  FbBuilder fb("FRME");
  std::map<int, size_t> pos;
  std::vector<FbField> f = {scalar_field<int64_t>(0, fr.t_us), scalar_field<int64_t>(1, fr.t_us - 100),
                            scalar_field<int64_t>(2, fr.t_us + 100)};
  if (fr.with_exposure) {
    f.push_back(scalar_field<int64_t>(3, fr.soe_us));
    f.push_back(scalar_field<int64_t>(4, fr.eoe_us));
  }
  if (fr.format != 0) f.push_back(scalar_field<int8_t>(5, fr.format));  // GRAY is the default: left out
  f.push_back(scalar_field<int16_t>(6, fr.w));
  f.push_back(scalar_field<int16_t>(7, fr.h));
  f.push_back(offset_field(10));
  const size_t t = fb.table(f, &pos);
  fb.set_root(t);
  fb.patch(pos[10], fb.vector(fr.pixels.data(), static_cast<uint32_t>(fr.pixels.size()), 1, 1));
  return fb.size_prefixed();
}

Bytes trigger_packet(const std::vector<std::pair<int64_t, int8_t>>& triggers) {
  FbBuilder fb("TRIG");
  std::map<int, size_t> pos;
  const size_t root = fb.table({offset_field(0)}, &pos);
  fb.set_root(root);
  const size_t vec = fb.table_vector(static_cast<uint32_t>(triggers.size()));
  fb.patch(pos[0], vec);
  for (uint32_t j = 0; j < triggers.size(); ++j) {
    fb.patch_table(
        vec, j, fb.table({scalar_field<int64_t>(0, triggers[j].first), scalar_field<int8_t>(1, triggers[j].second)}));
  }
  return fb.size_prefixed();
}

// ---------------------------------------------------------------------------------------------
// The file writer

enum class Comp : int32_t { kNone = 0, kLz4 = 1, kLz4High = 2, kZstd = 3, kZstdHigh = 4 };

Bytes compress(Comp c, const Bytes& in) {
  if (c == Comp::kNone) return in;
  if (c == Comp::kLz4 || c == Comp::kLz4High) {
    LZ4F_preferences_t prefs;
    std::memset(&prefs, 0, sizeof(prefs));
    prefs.compressionLevel = c == Comp::kLz4High ? 9 : 0;  // >= 3 selects LZ4 HC
    Bytes out(LZ4F_compressFrameBound(in.size(), &prefs));
    const size_t n = LZ4F_compressFrame(out.data(), out.size(), in.data(), in.size(), &prefs);
    EXPECT_FALSE(LZ4F_isError(n));
    out.resize(n);
    return out;
  }
  Bytes out(ZSTD_compressBound(in.size()));
  const size_t n = ZSTD_compress(out.data(), out.size(), in.data(), in.size(), c == Comp::kZstdHigh ? 19 : 3);
  EXPECT_FALSE(ZSTD_isError(n));
  out.resize(n);
  return out;
}

struct StreamDef {
  int id;
  std::string type;  // EVTS, IMUS, FRME, TRIG
  std::string name;
  int w = 0, h = 0;
};

std::string info_xml(const std::vector<StreamDef>& streams) {
  std::string s = "<dv version=\"2.0\">\n    <node name=\"outInfo\" path=\"/mainloop/Recorder/outInfo/\">\n";
  for (const StreamDef& d : streams) {
    const std::string id = std::to_string(d.id);
    s += "        <node name=\"" + id + "\" path=\"/mainloop/Recorder/outInfo/" + id + "/\">\n";
    s += "            <attr key=\"originalOutputName\" type=\"string\">" + d.name + "</attr>\n";
    s += "            <attr key=\"typeDescription\" type=\"string\">a &quot;stream&quot; &amp; more</attr>\n";
    s += "            <attr key=\"typeIdentifier\" type=\"string\">" + d.type + "</attr>\n";
    s += "            <node name=\"info\" path=\"/mainloop/Recorder/outInfo/" + id + "/info/\">\n";
    if (d.w > 0) {
      s += "                <attr key=\"sizeX\" type=\"int\">" + std::to_string(d.w) + "</attr>\n";
      s += "                <attr key=\"sizeY\" type=\"int\">" + std::to_string(d.h) + "</attr>\n";
    }
    s += "                <attr key=\"source\" type=\"string\">test</attr>\n";
    s += "            </node>\n        </node>\n";
  }
  return s + "    </node>\n</dv>\n";
}

const std::vector<StreamDef> kStreams = {
    {0, "EVTS", "events", 346, 260}, {1, "FRME", "frames", 346, 260}, {2, "IMUS", "imu"}, {3, "TRIG", "triggers"}};

struct Packet {
  int32_t stream;
  Bytes flatbuffer;  // size-prefixed, uncompressed
  int64_t elements = 1, t_start_us = 0, t_end_us = 0;
};

Bytes io_header(Comp c, int64_t table_pos, const std::string& xml) {
  FbBuilder fb("IOHE");
  std::map<int, size_t> pos;
  const size_t t = fb.table(
      {scalar_field<int32_t>(0, static_cast<int32_t>(c)), offset_field(2), scalar_field<int64_t>(1, table_pos)}, &pos);
  fb.set_root(t);
  fb.patch(pos[2], fb.vector(xml.data(), static_cast<uint32_t>(xml.size()), 1, 1));
  fb.bytes().push_back(0);  // flatbuffer strings are zero-terminated
  return fb.bytes();
}

struct FileLayout {
  Bytes bytes;
  std::vector<int64_t> packet_offsets;  // header offset of each packet
  int64_t header_size = 0;
  int64_t table_pos = -1;
};

FileLayout build_file(Comp c, const std::vector<Packet>& packets, bool with_table,
                      const std::string& xml = info_xml(kStreams)) {
  FileLayout L;
  const int64_t hsize = static_cast<int64_t>(io_header(c, 0, xml).size());
  L.header_size = hsize;
  Bytes body;
  std::vector<int64_t> body_offsets;
  int64_t at = 14 + 4 + hsize;
  for (const Packet& p : packets) {
    const Bytes z = compress(c, p.flatbuffer);
    L.packet_offsets.push_back(at);
    const int32_t sid = p.stream, size = static_cast<int32_t>(z.size());
    body.insert(body.end(), reinterpret_cast<const uint8_t*>(&sid), reinterpret_cast<const uint8_t*>(&sid) + 4);
    body.insert(body.end(), reinterpret_cast<const uint8_t*>(&size), reinterpret_cast<const uint8_t*>(&size) + 4);
    body.insert(body.end(), z.begin(), z.end());
    at += 8 + static_cast<int64_t>(z.size());
  }
  Bytes table;
  if (with_table) {
    L.table_pos = at;
    FbBuilder fb("FTAB");
    std::map<int, size_t> pos;
    fb.set_root(fb.table({offset_field(0)}, &pos));
    const size_t vec = fb.table_vector(static_cast<uint32_t>(packets.size()));
    fb.patch(pos[0], vec);
    int64_t off = 14 + 4 + hsize;
    for (uint32_t j = 0; j < packets.size(); ++j) {
      const int32_t size = static_cast<int32_t>(compress(c, packets[j].flatbuffer).size());
      Bytes info(8);
      std::memcpy(info.data(), &packets[j].stream, 4);
      std::memcpy(info.data() + 4, &size, 4);
      fb.patch_table(
          vec, j,
          fb.table({scalar_field<int64_t>(0, off + 8), FbField{1, info, 4},
                    scalar_field<int64_t>(2, packets[j].elements), scalar_field<int64_t>(3, packets[j].t_start_us),
                    scalar_field<int64_t>(4, packets[j].t_end_us)}));
      off += 8 + size;
    }
    table = compress(c, fb.size_prefixed());
  }
  const Bytes header = io_header(c, L.table_pos, xml);
  const char magic[] = "#!AER-DAT4.0\r\n";
  L.bytes.assign(magic, magic + 14);
  const int32_t hs = static_cast<int32_t>(header.size());
  L.bytes.insert(L.bytes.end(), reinterpret_cast<const uint8_t*>(&hs), reinterpret_cast<const uint8_t*>(&hs) + 4);
  L.bytes.insert(L.bytes.end(), header.begin(), header.end());
  L.bytes.insert(L.bytes.end(), body.begin(), body.end());
  L.bytes.insert(L.bytes.end(), table.begin(), table.end());
  return L;
}

std::string write_bytes(const std::string& path, const Bytes& b) {
  {
    std::ofstream f(path, std::ios::binary);
    f.write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(b.size()));
  }
  evio_test::export_fuzz_seed(path, "fuzz_aedat4");
  return path;
}

// A small recording: 3 event packets, 2 IMU packets, 2 frames (GRAY and BGR), 1 trigger packet.
struct Sample {
  std::vector<Packet> packets;
  std::vector<RawEvent> events;
  std::vector<RawImu> imu;
};

Sample make_sample() {
  Sample s;
  int64_t t = 1633953690000000;
  for (int p = 0; p < 3; ++p) {
    std::vector<RawEvent> ev;
    for (int i = 0; i < 500 + 37 * p; ++i) {
      t += (i % 3 == 0) ? 0 : 7;  // equal timestamps are allowed
      ev.push_back(
          RawEvent{t, static_cast<int16_t>((i * 13 + p) % 346), static_cast<int16_t>((i * 7) % 260), i % 2 == 0});
    }
    s.events.insert(s.events.end(), ev.begin(), ev.end());
    s.packets.push_back({0, event_packet(ev), static_cast<int64_t>(ev.size()), ev.front().t_us, ev.back().t_us});
    if (p < 2) {
      std::vector<RawImu> imu;
      for (int k = 0; k < 4; ++k) {
        RawImu m{1633953690000000 + p * 1000 + k * 250, {0.01f * k, -1.0f, 0.05f}, {1.5f, -2.0f, 90.0f * k}};
        m.omit_zero_fields = (k == 0);  // accel X and gyro Z absent -> default 0
        imu.push_back(m);
      }
      s.imu.insert(s.imu.end(), imu.begin(), imu.end());
      s.packets.push_back({2, imu_packet(imu), 4, imu.front().t_us, imu.back().t_us});
    }
    if (p == 0) {
      RawFrame g;
      g.t_us = 1633953690000500;
      g.soe_us = 1633953690000100;
      g.eoe_us = 1633953690000901;  // midpoint ends in .5 us
      g.w = 4;
      g.h = 3;
      for (int i = 0; i < 12; ++i) g.pixels.push_back(static_cast<uint8_t>(i * 20));
      s.packets.push_back({1, frame_packet(g), 1, g.t_us, g.t_us});
      s.packets.push_back({3, trigger_packet({{1633953690000100, 8}, {1633953690000901, 9}, {1633953690000950, 2}}), 3,
                           1633953690000100, 1633953690000950});
    }
    if (p == 1) {
      RawFrame c;
      c.t_us = 1633953690002000;
      c.with_exposure = false;  // time falls back to `timestamp`
      c.format = 16;            // BGR
      c.w = 2;
      c.h = 1;
      c.pixels = {255, 0, 0, 0, 0, 255};  // blue, red
      s.packets.push_back({1, frame_packet(c), 1, c.t_us, c.t_us});
    }
  }
  return s;
}

struct ReadAll {
  EventBuffer events;
  std::vector<ImuSample> imu;
  std::vector<Frame> frames;
  std::vector<Trigger> triggers;
  std::vector<StreamInfo> streams;
  ReadReport report;
  SensorSize sensor;
};

ReadAll read_all(const std::string& path, const DatasetOptions& opts = {}, size_t chunk = 1 << 16) {
  ReadAll r;
  auto reader = open_aedat4_dataset(path, opts);
  r.sensor = reader->sensor_size();
  while (reader->read_events(&r.events, chunk) > 0) {
  }
  EXPECT_DOUBLE_EQ(reader->progress(), 1.0);
  r.report = reader->event_report();
  r.imu = reader->read_imu();
  r.frames = reader->read_frames();
  r.triggers = reader->read_triggers();
  r.streams = reader->streams();
  return r;
}

// Expects reading the file to throw an InputError containing the path and every fragment.
void expect_error(const std::string& path, const std::vector<std::string>& fragments, const DatasetOptions& opts = {}) {
  try {
    read_all(path, opts);
    FAIL() << "no error for " << path;
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(path), std::string::npos) << msg;
    EXPECT_NE(msg.find("(expected: "), std::string::npos) << msg;
    for (const std::string& f : fragments) EXPECT_NE(msg.find(f), std::string::npos) << "'" << f << "' not in: " << msg;
  }
}

class Aedat4Fixture : public ::testing::Test {
 protected:
  void SetUp() override { set_log_level(LogLevel::kError); }
  void TearDown() override { set_log_level(LogLevel::kInfo); }
  evio_test::TempDir dir_;
};

// ---------------------------------------------------------------------------------------------
// Real sample

class RealAedat4 : public Aedat4Fixture {};

TEST_F(RealAedat4, DavisSampleCountsAndPlausibility) {
  const auto dir = evio_test::real_data_dir("davis346_aedat4");
  if (!dir) GTEST_SKIP() << "real sample davis346_aedat4 not present";
  const std::string path = *dir + "/davis.aedat4";
  const ReadAll r = read_all(path, {}, 4096);

  EXPECT_EQ(r.sensor.width, 346);
  EXPECT_EQ(r.sensor.height, 260);
  ASSERT_EQ(r.events.size(), 117667u);
  EXPECT_TRUE(r.events.is_time_sorted());
  int64_t on = 0;
  for (const Event& e : r.events) {
    ASSERT_LT(e.x, 346);
    ASSERT_LT(e.y, 260);
    ASSERT_TRUE(e.polarity == 1 || e.polarity == -1);
    on += e.polarity > 0;
  }
  EXPECT_GT(on, 0);
  EXPECT_LT(on, 117667);
  EXPECT_EQ(r.report.records, 117667);
  EXPECT_EQ(r.report.skipped_total(), 0);
  EXPECT_EQ(r.report.time_unit, TimeUnit::kMicroseconds);
  EXPECT_EQ(r.report.polarity, PolarityConvention::kZeroOne);
  // Timestamps are absolute (2021-10-11, epoch us): 1.6e18 ns.
  EXPECT_GT(r.events.front().t_ns, 1600000000LL * 1000000000LL);
  EXPECT_EQ(r.events.front().t_ns % 1000, 0);
  EXPECT_LT(r.events.back().t_ns - r.events.front().t_ns, 200000000);  // 0.13 s recording

  ASSERT_EQ(r.frames.size(), 3u);
  for (const Frame& f : r.frames) {
    EXPECT_EQ(f.image.cols, 346);
    EXPECT_EQ(f.image.rows, 260);
    EXPECT_EQ(f.image.type(), CV_8UC1);
    EXPECT_GT(cv::norm(f.image, cv::NORM_L1), 0.0);  // not blank
  }
  for (size_t i = 1; i < r.frames.size(); ++i) EXPECT_GT(r.frames[i].t_ns, r.frames[i - 1].t_ns);

  // IMU: ~1 kHz over 0.13 s; camera roughly static -> |a| near 1 g, small rotation rates.
  ASSERT_EQ(r.imu.size(), 130u);
  double mean_a = 0, max_g = 0;
  for (size_t i = 0; i < r.imu.size(); ++i) {
    mean_a += r.imu[i].accel.norm();
    max_g = std::max(max_g, r.imu[i].gyro.norm());
    if (i > 0) {
      EXPECT_GT(r.imu[i].t_ns, r.imu[i - 1].t_ns);
    }
  }
  mean_a /= static_cast<double>(r.imu.size());
  EXPECT_GT(mean_a, 9.81 - 0.5);
  EXPECT_LT(mean_a, 9.81 + 0.5);
  EXPECT_LT(max_g, 10.0);
  EXPECT_GT(max_g, 0.0);

  // Triggers: APS frame/exposure start/end markers (types 6..9), 15 in the file.
  ASSERT_EQ(r.triggers.size(), 15u);
  for (const Trigger& t : r.triggers) {
    EXPECT_GE(t.channel, 6);
    EXPECT_LE(t.channel, 9);
  }
  for (size_t i = 1; i < r.triggers.size(); ++i) EXPECT_GE(r.triggers[i].t_ns, r.triggers[i - 1].t_ns);
  // Each frame's time is its exposure midpoint: halfway between the exposure start (8) and end
  // (9) triggers that bracket it.
  for (const Frame& f : r.frames) {
    int64_t start = -1, end = -1;
    for (const Trigger& t : r.triggers) {
      if (t.channel == 8 && t.t_ns <= f.t_ns) start = t.t_ns;
      if (t.channel == 9 && t.t_ns >= f.t_ns && end < 0) end = t.t_ns;
    }
    ASSERT_GE(start, 0);
    ASSERT_GE(end, 0);
    EXPECT_EQ(f.t_ns, (start + end) / 2);
  }

  ASSERT_EQ(r.streams.size(), 4u);
  std::map<std::string, int64_t> packets;
  for (const StreamInfo& s : r.streams) {
    packets[s.type] = s.messages;
    EXPECT_TRUE(s.selected);
  }
  // Packets per stream as listed in the file data table (40 in all).
  EXPECT_EQ(packets["EVTS"], 13);
  EXPECT_EQ(packets["IMUS"], 13);
  EXPECT_EQ(packets["FRME"], 3);
  EXPECT_EQ(packets["TRIG"], 11);
}

TEST_F(RealAedat4, ChunkedReadsAndSeekAgreeWithOneRead) {
  const auto dir = evio_test::real_data_dir("davis346_aedat4");
  if (!dir) GTEST_SKIP() << "real sample davis346_aedat4 not present";
  const std::string path = *dir + "/davis.aedat4";
  const ReadAll whole = read_all(path, {}, size_t{1} << 20);
  const ReadAll small = read_all(path, {}, 333);
  ASSERT_EQ(whole.events.size(), small.events.size());
  for (size_t i = 0; i < whole.events.size(); ++i) ASSERT_EQ(whole.events[i], small.events[i]) << i;

  auto reader = open_aedat4_dataset(path, {});
  const int64_t target = whole.events[whole.events.size() / 2].t_ns + 1;
  ASSERT_TRUE(reader->seek_events(target));
  EventBuffer after;
  while (reader->read_events(&after, 1000) > 0) {
  }
  const auto first = std::lower_bound(whole.events.begin(), whole.events.end(), target,
                                      [](const Event& e, int64_t t) { return e.t_ns < t; });
  ASSERT_EQ(after.size(), static_cast<size_t>(whole.events.end() - first));
  for (size_t i = 0; i < after.size(); ++i) ASSERT_EQ(after[i], first[static_cast<ptrdiff_t>(i)]);
}

// ---------------------------------------------------------------------------------------------
// Written files: every compression, with and without the file data table

class Aedat4Files : public Aedat4Fixture {};

class WrittenAedat4 : public Aedat4Fixture, public ::testing::WithParamInterface<std::tuple<Comp, bool>> {};

TEST_P(WrittenAedat4, RoundTripsEveryStream) {
  const auto [comp, with_table] = GetParam();
  const Sample s = make_sample();
  const FileLayout L = build_file(comp, s.packets, with_table);
  const std::string path = write_bytes(dir_.file("rec.aedat4"), L.bytes);
  const ReadAll r = read_all(path, {}, 100);

  EXPECT_EQ(r.sensor.width, 346);
  EXPECT_EQ(r.sensor.height, 260);
  ASSERT_EQ(r.events.size(), s.events.size());
  for (size_t i = 0; i < s.events.size(); ++i) {
    const Event& e = r.events[i];
    ASSERT_EQ(e.t_ns, s.events[i].t_us * 1000) << i;
    ASSERT_EQ(e.x, s.events[i].x);
    ASSERT_EQ(e.y, s.events[i].y);
    ASSERT_EQ(e.polarity, s.events[i].on ? 1 : -1);
  }

  ASSERT_EQ(r.imu.size(), s.imu.size());
  for (size_t i = 0; i < s.imu.size(); ++i) {
    EXPECT_EQ(r.imu[i].t_ns, s.imu[i].t_us * 1000);
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(r.imu[i].accel[k], s.imu[i].accel[k] * 9.80665, 1e-5);
      EXPECT_NEAR(r.imu[i].gyro[k], s.imu[i].gyro[k] * 3.14159265358979323846 / 180.0, 1e-6);
    }
  }
  EXPECT_EQ(r.imu[0].accel.x(), 0.0);  // absent field -> default 0
  EXPECT_EQ(r.imu[0].gyro.z(), 0.0);

  ASSERT_EQ(r.frames.size(), 2u);
  EXPECT_EQ(r.frames[0].t_ns, 1633953690000500500LL);  // (SOE + EOE) / 2 in ns
  ASSERT_EQ(r.frames[0].image.type(), CV_8UC1);
  ASSERT_EQ(r.frames[0].image.cols, 4);
  ASSERT_EQ(r.frames[0].image.rows, 3);
  for (int i = 0; i < 12; ++i) EXPECT_EQ(r.frames[0].image.at<uint8_t>(i / 4, i % 4), i * 20);
  EXPECT_EQ(r.frames[1].t_ns, 1633953690002000000LL);  // no exposure stamps -> timestamp
  ASSERT_EQ(r.frames[1].image.type(), CV_8UC1);
  ASSERT_EQ(r.frames[1].image.cols, 2);
  EXPECT_EQ(r.frames[1].image.at<uint8_t>(0, 0), 29);  // pure blue: 0.114 * 255
  EXPECT_EQ(r.frames[1].image.at<uint8_t>(0, 1), 77);  // pure red: 0.299 * 255

  ASSERT_EQ(r.triggers.size(), 3u);
  EXPECT_EQ(r.triggers[0].channel, 8);
  EXPECT_EQ(r.triggers[0].polarity, 1);
  EXPECT_EQ(r.triggers[1].channel, 9);
  EXPECT_EQ(r.triggers[2].channel, 2);
  EXPECT_EQ(r.triggers[2].polarity, -1);  // external input falling edge
  EXPECT_EQ(r.triggers[2].t_ns, 1633953690000950000LL);

  ASSERT_EQ(r.streams.size(), 4u);
  EXPECT_EQ(r.streams[0].type, "EVTS");
  EXPECT_EQ(r.streams[0].name, "events (id 0)");
  EXPECT_EQ(r.streams[0].messages, 3);
  EXPECT_EQ(r.streams[1].messages, 2);
  EXPECT_EQ(r.streams[2].messages, 2);
  EXPECT_EQ(r.streams[3].messages, 1);
}

std::string param_name(const ::testing::TestParamInfo<std::tuple<Comp, bool>>& info) {
  static const char* names[] = {"none", "lz4", "lz4high", "zstd", "zstdhigh"};
  return std::string(names[static_cast<int>(std::get<0>(info.param))]) + (std::get<1>(info.param) ? "_table" : "_scan");
}

INSTANTIATE_TEST_SUITE_P(Compressions, WrittenAedat4,
                         ::testing::Combine(::testing::Values(Comp::kNone, Comp::kLz4, Comp::kLz4High, Comp::kZstd,
                                                              Comp::kZstdHigh),
                                            ::testing::Bool()),
                         param_name);

TEST_F(Aedat4Files, StreamCountsNeedAFullPassWithoutDataTable) {
  const Sample s = make_sample();
  const std::string path = write_bytes(dir_.file("a.aedat4"), build_file(Comp::kLz4, s.packets, false).bytes);
  auto reader = open_aedat4_dataset(path, {});
  EXPECT_EQ(reader->streams()[0].messages, -1);
  EXPECT_FALSE(reader->seek_events(0));  // no index to seek with
  EXPECT_EQ(reader->read_imu().size(), s.imu.size());
  EXPECT_EQ(reader->streams()[0].messages, 3);
}

TEST_F(Aedat4Files, FileWithoutEventStreamHasNoEvents) {
  const Sample s = make_sample();
  std::vector<Packet> imu_only;
  for (const Packet& p : s.packets) {
    if (p.stream == 2) imu_only.push_back(p);
  }
  const std::string xml = info_xml({{2, "IMUS", "imu"}});
  const std::string path = write_bytes(dir_.file("imu.aedat4"), build_file(Comp::kZstd, imu_only, true, xml).bytes);
  const ReadAll r = read_all(path);
  EXPECT_TRUE(r.events.empty());
  EXPECT_FALSE(r.sensor.known());
  EXPECT_EQ(r.imu.size(), s.imu.size());
  EXPECT_TRUE(r.frames.empty());
}

TEST_F(Aedat4Files, BadEventsAreErrorsOrCountedSkips) {
  std::vector<RawEvent> ev = {{1000, 1, 1, true},   {2000, 2, 2, false}, {1500, 3, 3, true},
                              {2500, 346, 0, true}, {2600, -1, 5, true}, {2700, 4, 4, false}};
  const std::vector<Packet> packets = {{0, event_packet(ev)}};
  const FileLayout L = build_file(Comp::kNone, packets, false);
  const std::string path = write_bytes(dir_.file("bad.aedat4"), L.bytes);
  const std::string at = "byte offset " + std::to_string(L.packet_offsets[0]);
  expect_error(path, {"event 2 of the packet at " + at, "earlier than the previous event", "non-decreasing time",
                      "--on-bad-line warn"});

  DatasetOptions warn;
  warn.text.on_bad_line = BadLinePolicy::kWarnAndSkip;
  const ReadAll r = read_all(path, warn);
  ASSERT_EQ(r.events.size(), 3u);
  EXPECT_EQ(r.events[2].t_ns, 2700000);
  EXPECT_EQ(r.report.skipped.at("time order").count, 1);
  EXPECT_EQ(r.report.skipped.at("outside sensor").count, 2);
  EXPECT_EQ(r.report.skipped.at("outside sensor").first_line, L.packet_offsets[0]);
  EXPECT_NE(r.report.skipped.at("outside sensor").first_message.find("pixel (346, 0) outside the 346x260 sensor"),
            std::string::npos);
}

TEST_F(Aedat4Files, BadImuSamplesAreErrorsOrSkips) {
  std::vector<RawImu> imu = {RawImu{100, {0, 0, 1}, {0, 0, 0}}, RawImu{100, {0, 0, 1}, {0, 0, 0}},
                             RawImu{200, {std::nanf(""), 0, 1}, {0, 0, 0}}, RawImu{300, {0, 0, 1}, {0, 0, 0}}};
  const FileLayout L = build_file(Comp::kLz4, {{2, imu_packet(imu)}}, false);
  const std::string path = write_bytes(dir_.file("imu.aedat4"), L.bytes);
  const std::string at = "of the packet at byte offset " + std::to_string(L.packet_offsets[0]);
  expect_error(path, {"IMU sample 1 " + at + ": timestamp 0.000100000 s is not after the previous sample's",
                      "strictly increasing", "--on-bad-line warn"});
  DatasetOptions warn;
  warn.text.on_bad_line = BadLinePolicy::kWarnAndSkip;
  const ReadAll r = read_all(path, warn);
  ASSERT_EQ(r.imu.size(), 2u);
  EXPECT_EQ(r.imu[1].t_ns, 300000);
  EXPECT_NEAR(r.imu[1].accel.z(), 9.80665, 1e-9);
}

// ---------------------------------------------------------------------------------------------
// Malformed files

class MalformedAedat4 : public Aedat4Fixture {
 protected:
  // An uncompressed recording without data table: one event packet then one IMU packet.
  FileLayout simple(Comp c = Comp::kNone, bool table = false) {
    const std::vector<Packet> packets = {{0, event_packet({{10, 1, 2, true}, {20, 3, 4, false}})},
                                         {2, imu_packet({RawImu{15, {0, 0, 1}, {0, 0, 0}}})}};
    return build_file(c, packets, table);
  }
  std::string write(const Bytes& b) { return write_bytes(dir_.file("m.aedat4"), b); }
  static void put_i32(Bytes* b, int64_t at, int32_t v) { std::memcpy(b->data() + at, &v, 4); }
  static void put_u32(Bytes* b, int64_t at, uint32_t v) { std::memcpy(b->data() + at, &v, 4); }
  static std::string off(int64_t v) { return "at byte offset " + std::to_string(v); }
};

TEST_F(MalformedAedat4, WrongMagic) {
  Bytes b = simple().bytes;
  b[9] = '2';  // "#!AER-DAT2.0"
  expect_error(write(b), {"wrong magic \"#!AER-DAT2.0\\x0d\\x0a\" at byte offset 0", "\"#!AER-DAT4.0\\r\\n\""});
  expect_error(write(Bytes{'#', '!', 'A'}), {"too short for the AEDAT 4.0 magic at byte offset 0"});
}

TEST_F(MalformedAedat4, TruncatedHeader) {
  const FileLayout L = simple();
  Bytes b(L.bytes.begin(), L.bytes.begin() + 16);
  expect_error(write(b), {"truncated header: no int32 header size at byte offset 14", "IOHeader flatbuffer"});
  b.assign(L.bytes.begin(), L.bytes.begin() + 18 + L.header_size - 5);
  expect_error(write(b), {"truncated header: the " + std::to_string(L.header_size) + "-byte IOHeader at byte offset 18",
                          "extends beyond the end of the file"});
  b = L.bytes;
  put_i32(&b, 14, -4);
  expect_error(write(b), {"header size -4 at byte offset 14 is not in [8, "});
}

TEST_F(MalformedAedat4, TruncatedPacket) {
  const FileLayout L = simple();
  const int64_t p1 = L.packet_offsets[1];
  Bytes b(L.bytes.begin(), L.bytes.begin() + p1 + 8 + 10);
  expect_error(write(b),
               {"truncated packet " + off(p1), "extends beyond the end of the file", "packets of int32 stream id"});
  b.assign(L.bytes.begin(), L.bytes.begin() + p1 + 5);
  expect_error(write(b), {"truncated packet header " + off(p1) + ": 5 bytes left of the 8-byte header"});
  // With a data table, cutting the file moves dataTablePosition beyond the end.
  const FileLayout T = simple(Comp::kLz4, true);
  b.assign(T.bytes.begin(), T.bytes.begin() + T.table_pos - 3);
  expect_error(write(b), {"IOHeader flatbuffer " + off(18),
                          "dataTablePosition " + std::to_string(T.table_pos) + " is outside the packet area"});
}

TEST_F(MalformedAedat4, PacketSizeBeyondEndOfFile) {
  FileLayout L = simple(Comp::kZstd);
  const int64_t p0 = L.packet_offsets[0];
  put_i32(&L.bytes, p0 + 4, 1000000);
  expect_error(write(L.bytes), {"truncated packet " + off(p0) + ": size 1000000 extends beyond the end of the file"});
  put_i32(&L.bytes, p0 + 4, 0x7fffffff);
  expect_error(write(L.bytes), {"packet " + off(p0) + " has size 2147483647, not in [1, 268435456]"});
  put_i32(&L.bytes, p0 + 4, -8);
  expect_error(write(L.bytes), {"packet " + off(p0) + " has size -8"});
}

TEST_F(MalformedAedat4, CorruptedLz4Payload) {
  FileLayout L = simple(Comp::kLz4);
  const int64_t p0 = L.packet_offsets[0];
  for (int k = 7; k < 16; ++k) L.bytes[static_cast<size_t>(p0 + 8 + k)] ^= 0x5a;  // block header and data
  expect_error(write(L.bytes), {"packet " + off(p0) + " (stream 0, EventPacket)", "LZ4", "LZ4 frame"});
  // A frame cut short inside its packet: shrink the packet size and shift nothing else.
  FileLayout C = simple(Comp::kLz4);
  const int64_t c0 = C.packet_offsets[0];
  int32_t size = 0;
  std::memcpy(&size, C.bytes.data() + c0 + 4, 4);
  Bytes b(C.bytes.begin(), C.bytes.begin() + c0 + 8 + size - 6);
  put_i32(&b, c0 + 4, size - 6);
  expect_error(write(b), {"packet " + off(c0), "truncated LZ4 frame"});
}

TEST_F(MalformedAedat4, CorruptedZstdPayload) {
  FileLayout L = simple(Comp::kZstd);
  const int64_t p0 = L.packet_offsets[0];
  L.bytes[static_cast<size_t>(p0 + 8)] ^= 0xff;  // frame magic
  expect_error(write(L.bytes), {"packet " + off(p0) + " (stream 0, EventPacket): corrupt Zstd data", "Zstd frame"});
  FileLayout C = simple(Comp::kZstd);
  const int64_t c0 = C.packet_offsets[0];
  int32_t size = 0;
  std::memcpy(&size, C.bytes.data() + c0 + 4, 4);
  Bytes b(C.bytes.begin(), C.bytes.begin() + c0 + 8 + size - 4);
  put_i32(&b, c0 + 4, size - 4);
  expect_error(write(b), {"packet " + off(c0), "Zstd"});
}

TEST_F(MalformedAedat4, FlatbufferOffsetOutsideBuffer) {
  FileLayout L = simple();
  const int64_t p0 = L.packet_offsets[0];
  const int64_t fb0 = p0 + 8 + 4;  // after the packet header and the size prefix
  put_u32(&L.bytes, fb0, 100000);  // root offset
  expect_error(write(L.bytes),
               {"packet " + off(p0) + " (stream 0, EventPacket): root table offset 100000 points outside",
                "size-prefixed EventPacket flatbuffer", "identifier EVTS"});
  L = simple();
  // The root table's soffset: vtable before the buffer start.
  uint32_t root = 0;
  std::memcpy(&root, L.bytes.data() + fb0, 4);
  put_i32(&L.bytes, fb0 + root, 5000);
  expect_error(write(L.bytes), {"packet " + off(p0), "has its vtable at", "outside the"});
  // The elements vector's uoffset pointing past the end.
  L = simple();
  std::memcpy(&root, L.bytes.data() + fb0, 4);
  put_u32(&L.bytes, fb0 + root + 4, 0x10000);
  expect_error(write(L.bytes), {"packet " + off(p0), "elements vector offset at", "outside the"});
}

TEST_F(MalformedAedat4, VectorLengthTooLarge) {
  FileLayout L = simple();
  const int64_t p0 = L.packet_offsets[0];
  const int64_t fb0 = p0 + 8 + 4;
  uint32_t root = 0, voff = 0;
  std::memcpy(&root, L.bytes.data() + fb0, 4);
  std::memcpy(&voff, L.bytes.data() + fb0 + root + 4, 4);
  const int64_t len_at = fb0 + root + 4 + voff;
  put_u32(&L.bytes, len_at, 0x7fffffff);
  expect_error(write(L.bytes), {"packet " + off(p0), "elements vector length 2147483647", "needs 34359738352 bytes"});
  put_u32(&L.bytes, len_at, 3);  // one more 16-byte event than stored
  expect_error(write(L.bytes), {"elements vector length 3"});
}

TEST_F(MalformedAedat4, UnknownStreamId) {
  FileLayout L = simple();
  const int64_t p1 = L.packet_offsets[1];
  put_i32(&L.bytes, p1, 9);
  expect_error(write(L.bytes), {"packet " + off(p1) + " has unknown stream id 9 (the infoNode lists 0, 1, 2, 3)",
                                "listed in the header's infoNode"});
  // The same through the data table.
  FileLayout T = simple(Comp::kNone, true);
  put_i32(&T.bytes, T.packet_offsets[1], 9);
  expect_error(write(T.bytes), {"packet header " + off(T.packet_offsets[1]) + " (stream 9",
                                "does not match the file data table (stream 2"});
}

TEST_F(MalformedAedat4, WrongIdentifierAndSizePrefix) {
  FileLayout L = simple();
  const int64_t p0 = L.packet_offsets[0];
  std::memcpy(L.bytes.data() + p0 + 8 + 4 + 4, "IMUS", 4);
  expect_error(write(L.bytes), {"packet " + off(p0), "file identifier \"IMUS\" at offset 4 is not \"EVTS\""});
  L = simple();
  put_u32(&L.bytes, p0 + 8, 7);
  expect_error(write(L.bytes), {"packet " + off(p0), "flatbuffer size prefix 7 does not match"});
}

TEST_F(MalformedAedat4, BadInfoNodeAndHeaderFields) {
  const Sample s = make_sample();
  auto with_xml = [&](const std::string& xml) {
    return write(build_file(Comp::kNone, {s.packets[0]}, false, xml).bytes);
  };
  expect_error(with_xml("<dv><node name=\"outInfo\"><node name=\"0\"><attr key=\"typeIdentifier\">EVTS</attr>"),
               {"malformed infoNode XML at byte offset", "is never closed"});
  expect_error(with_xml("<dv><node name=\"0\"><attr key=\"typeIdentifier\">EVTS</attr><node name=\"info\">"
                        "<attr key=\"sizeX\">-3</attr></node></node></dv>"),
               {"sizeX \"-3\" of stream 0 is not a size in px"});
  expect_error(with_xml("<dv></dv>"), {"no stream"});
  expect_error(with_xml("<dv><node name=\"x\"><attr key=\"typeIdentifier\">EVTS</attr></node></dv>"),
               {"stream node name \"x\" is not a stream id"});
  expect_error(with_xml("<dv><node name=\"0\"><attr key=\"typeIdentifier\">EVTS</attr></node>"
                        "<node name=\"0\"><attr key=\"typeIdentifier\">IMUS</attr></node></dv>"),
               {"stream id 0 is listed twice"});
  // Unknown compression enum value.
  FileLayout L = simple();
  uint32_t root = 0;
  std::memcpy(&root, L.bytes.data() + 18, 4);
  int32_t soff = 0;
  std::memcpy(&soff, L.bytes.data() + 18 + root, 4);
  uint16_t comp_off = 0;
  std::memcpy(&comp_off, L.bytes.data() + 18 + root - soff + 4, 2);
  put_i32(&L.bytes, 18 + root + comp_off, 7);
  expect_error(write(L.bytes), {"IOHeader flatbuffer " + off(18) + ": unknown compression type 7", "identifier IOHE"});
}

TEST_F(MalformedAedat4, CorruptDataTable) {
  FileLayout T = simple(Comp::kNone, true);
  // The first entry's ByteOffset (first field of the first FileDataDefinition) moved past the table.
  const int64_t tb = T.table_pos + 4;  // after the size prefix
  uint32_t root = 0, voff = 0, eoff = 0;
  std::memcpy(&root, T.bytes.data() + tb, 4);
  std::memcpy(&voff, T.bytes.data() + tb + root + 4, 4);
  const int64_t vec = tb + root + 4 + voff;
  std::memcpy(&eoff, T.bytes.data() + vec + 4, 4);
  const int64_t entry = vec + 4 + eoff;
  int32_t soff = 0;
  std::memcpy(&soff, T.bytes.data() + entry, 4);
  uint16_t f0 = 0;
  std::memcpy(&f0, T.bytes.data() + entry - soff + 4, 2);
  const int64_t bogus = 1 << 20;
  std::memcpy(T.bytes.data() + entry + f0, &bogus, 8);
  expect_error(write(T.bytes), {"file data table " + off(T.table_pos), "entry 0 places a",
                                "-byte packet at byte offset 1048576, outside the packet area", "identifier FTAB"});
}

TEST_F(MalformedAedat4, BadFrames) {
  RawFrame f;
  f.t_us = 100;
  f.soe_us = 90;
  f.eoe_us = 110;
  f.w = 4;
  f.h = 3;
  f.pixels.assign(11, 7);  // one byte short
  FileLayout L = build_file(Comp::kLz4, {{1, frame_packet(f)}}, false);
  expect_error(write(L.bytes), {"packet " + off(L.packet_offsets[0]) + " (stream 1, Frame)",
                                "pixels vector has 11 bytes, expected sizeX * sizeY * channels = 4 * 3 * 1 = 12"});
  f.pixels.assign(12, 7);
  f.format = 8;
  L = build_file(Comp::kLz4, {{1, frame_packet(f)}}, false);
  expect_error(write(L.bytes), {"unsupported frame format 8"});
}

}  // namespace
}  // namespace evio
