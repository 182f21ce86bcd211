#include "evio/sensors/rosbag.h"

#include <bzlib.h>
#include <lz4frame.h>

#include <cstring>
#include <fstream>
#include <iostream>
#include <map>
#include <set>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio_test/fuzz_seed.h"
#include "evio_test/real_data.h"
#include "evio_test/temp_dir.h"

namespace evio {
namespace {

using evio_test::TempDir;

// ---------------------------------------------------------------------------------------------
// A minimal ROS bag 2.0 writer for tests (layout as rosbag_storage writes it: version line, file
// header record padded to 4096 bytes, chunks each followed by their index data records, then at
// index_pos the connection records and chunk info records).

enum class Compression { kNone, kBz2, kLz4 };
const char* compression_name(Compression c) {
  return c == Compression::kNone ? "none" : c == Compression::kBz2 ? "bz2" : "lz4";
}

void put32(std::string* s, uint32_t v) { s->append(reinterpret_cast<const char*>(&v), 4); }
void put64(std::string* s, uint64_t v) { s->append(reinterpret_cast<const char*>(&v), 8); }
void put16(std::string* s, uint16_t v) { s->append(reinterpret_cast<const char*>(&v), 2); }
void putf64(std::string* s, double v) { s->append(reinterpret_cast<const char*>(&v), 8); }
void putstr(std::string* s, const std::string& v) {
  put32(s, static_cast<uint32_t>(v.size()));
  *s += v;
}
std::string bin32(uint32_t v) { return std::string(reinterpret_cast<const char*>(&v), 4); }
std::string bin64(uint64_t v) { return std::string(reinterpret_cast<const char*>(&v), 8); }
std::string packed_time(int64_t t_ns) {
  return bin64((static_cast<uint64_t>(t_ns % 1000000000) << 32) | static_cast<uint64_t>(t_ns / 1000000000));
}

using Fields = std::vector<std::pair<std::string, std::string>>;
std::string header_bytes(const Fields& fields) {
  std::string h;
  for (const auto& f : fields) putstr(&h, f.first + "=" + f.second);
  return h;
}
std::string record(const Fields& fields, const std::string& data) {
  std::string r;
  putstr(&r, header_bytes(fields));
  putstr(&r, data);
  return r;
}

std::string compress(Compression c, const std::string& raw) {
  if (c == Compression::kNone) return raw;
  if (c == Compression::kBz2) {
    std::string out(raw.size() + raw.size() / 100 + 600, '\0');
    unsigned n = static_cast<unsigned>(out.size());
    EXPECT_EQ(BZ2_bzBuffToBuffCompress(out.data(), &n, const_cast<char*>(raw.data()), static_cast<unsigned>(raw.size()), 9, 0, 0), BZ_OK);
    out.resize(n);
    return out;
  }
  // roslz4 writes an LZ4 frame: independent blocks, no content size, content checksum.
  LZ4F_preferences_t prefs;
  std::memset(&prefs, 0, sizeof(prefs));
  prefs.frameInfo.blockMode = LZ4F_blockIndependent;
  prefs.frameInfo.contentChecksumFlag = LZ4F_contentChecksumEnabled;
  prefs.frameInfo.blockSizeID = LZ4F_max64KB;
  std::string out(LZ4F_compressFrameBound(raw.size(), &prefs), '\0');
  const size_t n = LZ4F_compressFrame(out.data(), out.size(), raw.data(), raw.size(), &prefs);
  EXPECT_FALSE(LZ4F_isError(n));
  out.resize(n);
  return out;
}

struct WrittenMessage {
  uint64_t chunk_pos = 0;       // file offset of the chunk record
  uint64_t chunk_data_pos = 0;  // file offset of the chunk's data
  uint64_t record_off = 0;      // offset of the message record in the (decompressed) chunk
  uint64_t data_off = 0;        // offset of the message data in the (decompressed) chunk
};

class TestBagWriter {
 public:
  explicit TestBagWriter(Compression c = Compression::kNone, bool index = true, size_t per_chunk = 3)
      : compression_(c), index_(index), per_chunk_(per_chunk) {}

  uint32_t connection(const std::string& topic, const std::string& type) {
    conns_.push_back({topic, type});
    return static_cast<uint32_t>(conns_.size() - 1);
  }
  // Returns the message number.
  size_t message(uint32_t conn, int64_t t_ns, const std::string& data) {
    msgs_.push_back({conn, t_ns, data});
    return msgs_.size() - 1;
  }

  std::string bytes() {
    written_.assign(msgs_.size(), WrittenMessage());
    chunk_pos_.clear();
    std::string body;  // everything after the file header record
    const uint64_t body_start = 13 + 4104;
    std::vector<std::pair<uint64_t, std::map<uint32_t, uint32_t>>> chunk_infos;
    std::vector<std::pair<int64_t, int64_t>> chunk_times;
    std::set<uint32_t> announced;
    for (size_t first = 0; first < msgs_.size(); first += per_chunk_) {
      const size_t last = std::min(msgs_.size(), first + per_chunk_);
      std::string inner;
      std::map<uint32_t, std::vector<std::pair<int64_t, uint32_t>>> index;
      const uint64_t chunk_pos = body_start + body.size();
      for (size_t i = first; i < last; ++i) {
        const Msg& m = msgs_[i];
        if (announced.insert(m.conn).second) inner += connection_record(m.conn);
        written_[i].chunk_pos = chunk_pos;
        written_[i].record_off = inner.size();
        const std::string hdr = header_bytes({{"op", std::string(1, '\x02')}, {"conn", bin32(m.conn)}, {"time", packed_time(m.t_ns)}});
        written_[i].data_off = inner.size() + 8 + hdr.size();
        index[m.conn].emplace_back(m.t_ns, static_cast<uint32_t>(inner.size()));
        put32(&inner, static_cast<uint32_t>(hdr.size()));
        inner += hdr;
        putstr(&inner, m.data);
      }
      const std::string data = compress(compression_, inner);
      const std::string chunk_header = header_bytes(
          {{"op", std::string(1, '\x05')}, {"compression", compression_name(compression_)}, {"size", bin32(static_cast<uint32_t>(inner.size()))}});
      for (size_t i = first; i < last; ++i) written_[i].chunk_data_pos = chunk_pos + 8 + chunk_header.size();
      chunk_pos_.push_back(chunk_pos);
      put32(&body, static_cast<uint32_t>(chunk_header.size()));
      body += chunk_header;
      putstr(&body, data);
      std::map<uint32_t, uint32_t> counts;
      for (const auto& kv : index) {
        std::string entries;
        for (const auto& e : kv.second) {
          put32(&entries, static_cast<uint32_t>(e.first / 1000000000));
          put32(&entries, static_cast<uint32_t>(e.first % 1000000000));
          put32(&entries, e.second);
        }
        body += record({{"op", std::string(1, '\x04')}, {"ver", bin32(1)}, {"conn", bin32(kv.first)},
                        {"count", bin32(static_cast<uint32_t>(kv.second.size()))}},
                       entries);
        counts[kv.first] = static_cast<uint32_t>(kv.second.size());
      }
      chunk_infos.emplace_back(chunk_pos, counts);
      chunk_times.emplace_back(msgs_[first].t_ns, msgs_[last - 1].t_ns);
    }
    uint64_t index_pos = 0;
    if (index_) {
      index_pos = body_start + body.size();
      for (uint32_t c = 0; c < conns_.size(); ++c) body += connection_record(c);
      for (size_t k = 0; k < chunk_infos.size(); ++k) {
        std::string data;
        for (const auto& kv : chunk_infos[k].second) {
          put32(&data, kv.first);
          put32(&data, kv.second);
        }
        body += record({{"op", std::string(1, '\x06')}, {"ver", bin32(1)}, {"chunk_pos", bin64(chunk_infos[k].first)},
                        {"start_time", packed_time(chunk_times[k].first)}, {"end_time", packed_time(chunk_times[k].second)},
                        {"count", bin32(static_cast<uint32_t>(chunk_infos[k].second.size()))}},
                       data);
      }
    }
    const std::string fh = header_bytes({{"op", std::string(1, '\x03')},
                                         {"index_pos", bin64(index_pos)},
                                         {"conn_count", bin32(index_ ? static_cast<uint32_t>(conns_.size()) : 0)},
                                         {"chunk_count", bin32(index_ ? static_cast<uint32_t>(chunk_infos.size()) : 0)}});
    std::string out = "#ROSBAG V2.0\n";
    put32(&out, static_cast<uint32_t>(fh.size()));
    out += fh;
    putstr(&out, std::string(4096 - fh.size(), ' '));
    EXPECT_EQ(out.size(), body_start);
    return out + body;
  }

  const WrittenMessage& written(size_t i) const { return written_.at(i); }
  uint64_t chunk_pos(size_t k) const { return chunk_pos_.at(k); }

 private:
  struct Msg {
    uint32_t conn;
    int64_t t_ns;
    std::string data;
  };
  std::string connection_record(uint32_t c) const {
    std::string fields = header_bytes({{"topic", conns_[c].first},
                                       {"type", conns_[c].second},
                                       {"md5sum", std::string(32, '0')},
                                       {"message_definition", "# test\n"}});
    std::string r;
    putstr(&r, header_bytes({{"op", std::string(1, '\x07')}, {"conn", bin32(c)}, {"topic", conns_[c].first}}));
    putstr(&r, fields);
    return r;
  }

  Compression compression_;
  bool index_;
  size_t per_chunk_;
  std::vector<std::pair<std::string, std::string>> conns_;
  std::vector<Msg> msgs_;
  std::vector<WrittenMessage> written_;
  std::vector<uint64_t> chunk_pos_;
};

// ---------------------------------------------------------------------------------------------
// Message serialisers.

std::string ros_header(int64_t stamp_ns, const std::string& frame_id = "cam0") {
  std::string s;
  put32(&s, 7);
  put32(&s, static_cast<uint32_t>(stamp_ns / 1000000000));
  put32(&s, static_cast<uint32_t>(stamp_ns % 1000000000));
  putstr(&s, frame_id);
  return s;
}
constexpr size_t kHeaderBytes = 16 + 4;  // ros_header() with frame_id "cam0"

std::string event_array(int64_t stamp_ns, uint32_t width, uint32_t height, const std::vector<Event>& events) {
  std::string s = ros_header(stamp_ns);
  put32(&s, height);
  put32(&s, width);
  put32(&s, static_cast<uint32_t>(events.size()));
  for (const Event& e : events) {
    put16(&s, e.x);
    put16(&s, e.y);
    put32(&s, static_cast<uint32_t>(e.t_ns / 1000000000));
    put32(&s, static_cast<uint32_t>(e.t_ns % 1000000000));
    s += static_cast<char>(e.polarity > 0 ? 1 : 0);
  }
  return s;
}

std::string imu_message(const ImuSample& m) {
  std::string s = ros_header(m.t_ns);
  for (double q : {0.0, 0.0, 0.0, 1.0}) putf64(&s, q);
  for (int i = 0; i < 9; ++i) putf64(&s, -1.0);
  for (int i = 0; i < 3; ++i) putf64(&s, m.gyro[i]);
  for (int i = 0; i < 9; ++i) putf64(&s, 0.01);
  for (int i = 0; i < 3; ++i) putf64(&s, m.accel[i]);
  for (int i = 0; i < 9; ++i) putf64(&s, 0.02);
  return s;
}

std::string image_message(int64_t stamp_ns, uint32_t width, uint32_t height, const std::string& encoding, uint32_t step,
                          const std::string& data) {
  std::string s = ros_header(stamp_ns);
  put32(&s, height);
  put32(&s, width);
  putstr(&s, encoding);
  s += '\0';
  put32(&s, step);
  putstr(&s, data);
  return s;
}

std::string event_packet(int64_t stamp_ns, uint32_t width, uint32_t height, const std::string& encoding,
                         const std::vector<uint16_t>& words) {
  std::string s = ros_header(stamp_ns);
  put32(&s, height);
  put32(&s, width);
  put64(&s, 42);  // seq
  put64(&s, 0);   // time_base (undefined for evt3)
  putstr(&s, encoding);
  s += '\0';
  put32(&s, static_cast<uint32_t>(words.size() * 2));
  for (uint16_t w : words) put16(&s, w);
  return s;
}

// EVT 3.0 words.
uint16_t time_high(uint32_t us) { return static_cast<uint16_t>(0x8000 | ((us >> 12) & 0xFFF)); }
uint16_t time_low(uint32_t us) { return static_cast<uint16_t>(0x6000 | (us & 0xFFF)); }
uint16_t addr_y(uint16_t y) { return static_cast<uint16_t>(0x0000 | y); }
uint16_t addr_x(uint16_t x, bool on) { return static_cast<uint16_t>(0x2000 | (on ? 0x800 : 0) | x); }
uint16_t ext_trigger(uint32_t id, bool rising) { return static_cast<uint16_t>(0xA000 | (id << 8) | (rising ? 1 : 0)); }

// ---------------------------------------------------------------------------------------------

std::string write_file(const TempDir& dir, const std::string& name, const std::string& bytes) {
  const std::string path = dir.file(name);
  std::ofstream(path, std::ios::binary).write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  evio_test::export_fuzz_seed(path, "fuzz_rosbag");
  return path;
}

EventBuffer read_all_events(DatasetReader* r, size_t step = 1 << 16) {
  EventBuffer out;
  while (r->read_events(&out, step) > 0) {
  }
  return out;
}

// Expects opening and fully reading `path` to throw an InputError containing every fragment.
void expect_error(const std::string& path, const std::vector<std::string>& fragments, DatasetOptions opts = {}) {
  try {
    auto r = open_rosbag_dataset(path, opts);
    read_all_events(r.get());
    r->read_imu();
    r->read_frames();
    r->read_triggers();
    FAIL() << "no error for " << path;
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(path), std::string::npos) << msg;
    for (const std::string& f : fragments) EXPECT_NE(msg.find(f), std::string::npos) << "'" << f << "' not in: " << msg;
  }
}

// A bag with events (dvs_msgs/EventArray), IMU, images and an unrelated topic, and its contents.
struct SampleBag {
  TestBagWriter writer;
  std::vector<Event> events;
  std::vector<ImuSample> imu;
  std::vector<std::pair<int64_t, cv::Mat>> frames;
  size_t event_messages = 0;

  SampleBag(Compression c, bool index) : writer(c, index, 3) {
    const uint32_t ev = writer.connection("/dvs/events", "dvs_msgs/EventArray");
    const uint32_t im = writer.connection("/dvs/imu", "sensor_msgs/Imu");
    const uint32_t fr = writer.connection("/dvs/image_raw", "sensor_msgs/Image");
    const uint32_t other = writer.connection("/rosout", "rosgraph_msgs/Log");
    const int64_t t0 = 1600000000LL * 1000000000LL + 123456789;
    int64_t t = t0;
    for (int m = 0; m < 7; ++m) {
      std::vector<Event> batch;
      for (int i = 0; i < 50 + 13 * m; ++i) {
        t += (i * 7 + m) % 5 * 1000;  // equal stamps included
        batch.push_back(Event{t, static_cast<uint16_t>((i * 37 + m) % 240), static_cast<uint16_t>((i * 11 + m) % 180),
                              static_cast<int8_t>((i + m) % 3 == 0 ? 1 : -1)});
      }
      events.insert(events.end(), batch.begin(), batch.end());
      writer.message(ev, batch.back().t_ns, event_array(batch.front().t_ns, 240, 180, batch));
      ++event_messages;
      ImuSample s;
      s.t_ns = t0 + m * 1000000;
      s.gyro = Eigen::Vector3d(0.1 * m, -0.2, 0.3);
      s.accel = Eigen::Vector3d(0.0, 9.81, -0.5 * m);
      imu.push_back(s);
      writer.message(im, s.t_ns, imu_message(s));
      if (m % 3 == 0) {
        const uint32_t w = 6, h = 4, step = 8;  // rows padded to 8 bytes
        cv::Mat img(h, w, CV_8UC1);
        std::string data;
        for (uint32_t y = 0; y < h; ++y) {
          for (uint32_t x = 0; x < step; ++x) {
            const uint8_t v = static_cast<uint8_t>(x < w ? 10 * y + x + m : 255);
            data += static_cast<char>(v);
            if (x < w) img.at<uint8_t>(static_cast<int>(y), static_cast<int>(x)) = v;
          }
        }
        frames.emplace_back(t0 + m * 1000000 + 500, img);
        writer.message(fr, t0 + m * 1000000 + 500, image_message(t0 + m * 1000000 + 500, w, h, "mono8", step, data));
      }
      writer.message(other, t, std::string("\x05\x00\x00\x00hello", 9));
    }
  }
};

// ---------------------------------------------------------------------------------------------
// The real sample.

TEST(Rosbag, RealEventPacketSampleGivesTheKnownCounts) {
  const auto dir = evio_test::real_data_dir("rosbag_eventpacket");
  if (!dir) GTEST_SKIP() << "real sample rosbag_eventpacket not present";
  const std::string path = *dir + "/test_events_1.bag";
  auto r = open_rosbag_dataset(path, {});
  const SensorSize s = r->sensor_size();
  EXPECT_EQ(s.width, 640);
  EXPECT_EQ(s.height, 480);

  const std::vector<StreamInfo> streams = r->streams();
  ASSERT_EQ(streams.size(), 1u);
  EXPECT_EQ(streams[0].name, "/event_camera/events");
  EXPECT_EQ(streams[0].type, "event_camera_msgs/EventPacket");
  // 240 + 109 + 168 messages in the three chunks (index data records, counted independently).
  EXPECT_EQ(streams[0].messages, 517);
  EXPECT_TRUE(streams[0].selected);

  EventBuffer chunk;
  EventStatistics stats;
  int64_t last = INT64_MIN;
  bool sorted = true, inside = true;
  while (r->read_events(&chunk, 100000) > 0) {
    for (const Event& e : chunk) {
      sorted = sorted && e.t_ns >= last;
      last = e.t_ns;
      inside = inside && e.x < s.width && e.y < s.height;
    }
    stats.add(chunk.span());
    chunk.clear();
  }
  EXPECT_EQ(stats.count, 343474);
  EXPECT_EQ(stats.off, 218291);
  EXPECT_EQ(stats.on, 125183);
  EXPECT_TRUE(sorted);
  EXPECT_TRUE(inside);
  EXPECT_DOUBLE_EQ(r->progress(), 1.0);
  EXPECT_EQ(r->event_report().records, 343474);
  EXPECT_EQ(r->event_report().lines, 517);
  EXPECT_EQ(r->event_report().skipped_total(), 0);
  // The first packet's header stamp is 1675956550.318678998; events follow it within the ~2 s slice.
  EXPECT_GE(stats.t_first_ns, 1675956550318678998LL);
  EXPECT_LT(stats.t_last_ns - stats.t_first_ns, 3000000000LL);

  // EXT_TRIGGER (type 0xA) words in all payloads, counted independently by a script: 4157.
  const std::vector<Trigger> triggers = r->read_triggers();
  EXPECT_EQ(triggers.size(), 4157u);
  std::cout << "[ info ] real sample: " << stats.count << " CD events, " << triggers.size() << " trigger events\n";
  for (const Trigger& t : triggers) {
    ASSERT_TRUE(t.polarity == 1 || t.polarity == -1);
    ASSERT_GE(t.t_ns, stats.t_first_ns - 1000000);
    ASSERT_LE(t.t_ns, stats.t_last_ns + 1000000);
  }
  // A fresh reader that has not streamed the events gives the same triggers.
  auto r2 = open_rosbag_dataset(path, {});
  const std::vector<Trigger> again = r2->read_triggers();
  ASSERT_EQ(again.size(), triggers.size());
  for (size_t i = 0; i < again.size(); ++i) EXPECT_EQ(again[i].t_ns, triggers[i].t_ns);
}

TEST(Rosbag, RealSampleStreamsInSmallPiecesLikeInOne) {
  const auto dir = evio_test::real_data_dir("rosbag_eventpacket");
  if (!dir) GTEST_SKIP() << "real sample rosbag_eventpacket not present";
  auto a = open_rosbag_dataset(*dir + "/test_events_1.bag", {});
  auto b = open_rosbag_dataset(*dir + "/test_events_1.bag", {});
  const EventBuffer whole = read_all_events(a.get(), size_t{1} << 22);
  const EventBuffer pieces = read_all_events(b.get(), 777);
  ASSERT_EQ(whole.size(), pieces.size());
  for (size_t i = 0; i < whole.size(); ++i) ASSERT_EQ(whole[i], pieces[i]) << i;
}

// ---------------------------------------------------------------------------------------------
// Round trips through every chunk compression, with and without index.

class RosbagRoundTrip : public ::testing::TestWithParam<std::tuple<Compression, bool>> {};

TEST_P(RosbagRoundTrip, EventsImuAndImagesComeBackExactly) {
  const Compression c = std::get<0>(GetParam());
  const bool index = std::get<1>(GetParam());
  TempDir dir;
  SampleBag bag(c, index);
  const std::string path = write_file(dir, "sample.bag", bag.writer.bytes());
  std::vector<std::string> infos;
  set_log_sink([&](LogLevel, const std::string& m) { infos.push_back(m); });
  auto r = open_rosbag_dataset(path, {});
  set_log_sink({});
  bool logged_scan = false;
  for (const std::string& m : infos) logged_scan = logged_scan || m.find("no index") != std::string::npos;
  EXPECT_EQ(logged_scan, !index);

  EXPECT_EQ(r->format(), DatasetFormat::kRosbag);
  EXPECT_EQ(r->sensor_size().width, 240);
  EXPECT_EQ(r->sensor_size().height, 180);
  const std::vector<StreamInfo> streams = r->streams();
  ASSERT_EQ(streams.size(), 4u);
  std::map<std::string, StreamInfo> by_name;
  for (const StreamInfo& s : streams) by_name[s.name] = s;
  EXPECT_EQ(by_name["/dvs/events"].type, "dvs_msgs/EventArray");
  EXPECT_EQ(by_name["/dvs/events"].messages, 7);
  EXPECT_TRUE(by_name["/dvs/events"].selected);
  EXPECT_EQ(by_name["/dvs/imu"].messages, 7);
  EXPECT_TRUE(by_name["/dvs/imu"].selected);
  EXPECT_EQ(by_name["/dvs/image_raw"].messages, 3);
  EXPECT_TRUE(by_name["/dvs/image_raw"].selected);
  EXPECT_EQ(by_name["/rosout"].type, "rosgraph_msgs/Log");
  EXPECT_FALSE(by_name["/rosout"].selected);

  const EventBuffer events = read_all_events(r.get(), 64);
  ASSERT_EQ(events.size(), bag.events.size());
  for (size_t i = 0; i < events.size(); ++i) ASSERT_EQ(events[i], bag.events[i]) << "event " << i;
  EXPECT_EQ(r->event_report().records, static_cast<int64_t>(bag.events.size()));
  EXPECT_EQ(r->event_report().polarity, PolarityConvention::kZeroOne);
  EXPECT_EQ(r->event_report().time_unit, TimeUnit::kNanoseconds);
  EXPECT_TRUE(r->read_triggers().empty());

  const std::vector<ImuSample> imu = r->read_imu();
  ASSERT_EQ(imu.size(), bag.imu.size());
  for (size_t i = 0; i < imu.size(); ++i) {
    EXPECT_EQ(imu[i].t_ns, bag.imu[i].t_ns);
    EXPECT_EQ(imu[i].gyro, bag.imu[i].gyro);
    EXPECT_EQ(imu[i].accel, bag.imu[i].accel);
  }
  const std::vector<Frame> frames = r->read_frames();
  ASSERT_EQ(frames.size(), bag.frames.size());
  for (size_t i = 0; i < frames.size(); ++i) {
    EXPECT_EQ(frames[i].t_ns, bag.frames[i].first);
    ASSERT_EQ(frames[i].image.type(), CV_8UC1);
    ASSERT_EQ(frames[i].image.size(), bag.frames[i].second.size());
    EXPECT_EQ(cv::countNonZero(frames[i].image != bag.frames[i].second), 0) << "frame " << i;
  }
  EXPECT_FALSE(r->read_groundtruth().has_value());
  EXPECT_FALSE(r->read_calibration().has_value());
}

INSTANTIATE_TEST_SUITE_P(AllChunkKinds, RosbagRoundTrip,
                         ::testing::Combine(::testing::Values(Compression::kNone, Compression::kBz2, Compression::kLz4),
                                            ::testing::Bool()),
                         [](const ::testing::TestParamInfo<std::tuple<Compression, bool>>& i) {
                           return std::string(compression_name(std::get<0>(i.param))) +
                                  (std::get<1>(i.param) ? "_indexed" : "_unindexed");
                         });

TEST(Rosbag, ProgressRisesToOne) {
  TempDir dir;
  SampleBag bag(Compression::kLz4, true);
  auto r = open_rosbag_dataset(write_file(dir, "p.bag", bag.writer.bytes()), {});
  EXPECT_DOUBLE_EQ(r->progress(), 0.0);
  EventBuffer b;
  double last = 0;
  while (r->read_events(&b, 40) > 0) {
    EXPECT_GE(r->progress(), last);
    last = r->progress();
  }
  EXPECT_DOUBLE_EQ(r->progress(), 1.0);
}

// ---------------------------------------------------------------------------------------------
// event_camera_msgs/EventPacket with an evt3 payload.

TEST(Rosbag, Evt3PacketsKeepDecoderStateAndUseTheFirstHeaderStamp) {
  TempDir dir;
  TestBagWriter w(Compression::kBz2, true, 2);
  const uint32_t c = w.connection("/event_camera/events", "event_camera_msgs/EventPacket");
  const int64_t stamp0 = 1700000000LL * 1000000000LL + 5000;
  const uint32_t us0 = 0x123456;  // sensor time of the first time words, us
  // Packet 1: time base, y=7, an ON event at x=3, a trigger, an OFF event 10 us later.
  w.message(c, stamp0, event_packet(stamp0, 64, 32, "evt3",
                                    {time_high(us0), time_low(us0), addr_y(7), addr_x(3, true), ext_trigger(2, true),
                                     time_low(us0 + 10), addr_x(4, false)}));
  // Packet 2 relies on the state of packet 1: time high and y carry over.
  w.message(c, stamp0 + 999999, event_packet(stamp0 + 999999, 64, 32, "evt3", {time_low(us0 + 20), addr_x(5, true)}));
  // Packet 3: a new row and a new time high.
  w.message(c, stamp0 + 2000000, event_packet(stamp0 + 2000000, 64, 32, "evt3",
                                              {time_high(us0 + 4096), time_low(us0 + 4096), addr_y(9), addr_x(63, false)}));
  auto r = open_rosbag_dataset(write_file(dir, "evt3.bag", w.bytes()), {});
  EXPECT_EQ(r->sensor_size().width, 64);
  EXPECT_EQ(r->sensor_size().height, 32);
  const EventBuffer ev = read_all_events(r.get());
  ASSERT_EQ(ev.size(), 4u);
  // t = stamp0 + (sensor time - first sensor time)
  EXPECT_EQ(ev[0], (Event{stamp0, 3, 7, 1}));
  EXPECT_EQ(ev[1], (Event{stamp0 + 10000, 4, 7, -1}));
  EXPECT_EQ(ev[2], (Event{stamp0 + 20000, 5, 7, 1}));
  EXPECT_EQ(ev[3], (Event{stamp0 + 4096000, 63, 9, -1}));
  const std::vector<Trigger> tr = r->read_triggers();
  ASSERT_EQ(tr.size(), 1u);
  EXPECT_EQ(tr[0].t_ns, stamp0);
  EXPECT_EQ(tr[0].channel, 2);
  EXPECT_EQ(tr[0].polarity, 1);
}

TEST(Rosbag, EventPacketWithAnotherEncodingIsAnError) {
  TempDir dir;
  TestBagWriter w;
  const uint32_t c = w.connection("/ev", "event_camera_msgs/EventPacket");
  const size_t m = w.message(c, 1000000000, event_packet(1000000000, 64, 32, "libcaer_cmp", {0, 0, 0, 0}));
  const std::string path = write_file(dir, "libcaer.bag", w.bytes());
  const WrittenMessage& at = w.written(m);
  // The encoding string starts after header, height, width, seq and time_base.
  const uint64_t off = at.chunk_data_pos + at.data_off + kHeaderBytes + 8 + 16;
  expect_error(path, {"encoding 'libcaer_cmp' is not supported", "byte offset " + std::to_string(off),
                      "event_camera_msgs/EventPacket: std_msgs/Header header"});
}

// ---------------------------------------------------------------------------------------------
// Topic selection.

TEST(Rosbag, TopicSelection) {
  TempDir dir;
  TestBagWriter w;
  const uint32_t a = w.connection("/left/events", "dvs_msgs/EventArray");
  const uint32_t b = w.connection("/right/events", "dvs_msgs/EventArray");
  const uint32_t i = w.connection("/imu", "sensor_msgs/Imu");
  const uint32_t z = w.connection("/compressed", "sensor_msgs/CompressedImage");
  w.message(a, 1000, event_array(1000, 10, 10, {Event{1000, 1, 1, 1}}));
  w.message(b, 2000, event_array(2000, 20, 20, {Event{2000, 2, 2, -1}, Event{2001, 3, 3, 1}}));
  ImuSample s;
  s.t_ns = 3000;
  w.message(i, 3000, imu_message(s));
  w.message(z, 4000, "\x01\x02\x03");
  const std::string path = write_file(dir, "two.bag", w.bytes());

  expect_error(path, {"several events topics: /left/events (dvs_msgs/EventArray), /right/events (dvs_msgs/EventArray)",
                      "BagTopics::events"});
  DatasetOptions o;
  o.topics.events = "/right/events";
  auto r = open_rosbag_dataset(path, o);
  EXPECT_EQ(r->sensor_size().width, 20);
  EXPECT_EQ(read_all_events(r.get()).size(), 2u);
  EXPECT_EQ(r->read_imu().size(), 1u);
  EXPECT_TRUE(r->read_frames().empty());  // sensor_msgs/CompressedImage is not an image topic: ignored

  o.topics.events = "/nope";
  expect_error(path, {"topic '/nope' chosen for events is not in the bag", "/left/events (dvs_msgs/EventArray)",
                      "/compressed (sensor_msgs/CompressedImage)"},
               o);
  o.topics.events = "/imu";
  expect_error(path, {"topic '/imu' chosen for events has type sensor_msgs/Imu",
                      "dvs_msgs/EventArray, prophesee_event_msgs/EventArray or event_camera_msgs/EventPacket"},
               o);
  o.topics.events = "/left/events";
  o.topics.image = "/compressed";
  expect_error(path, {"topic '/compressed' chosen for image has type sensor_msgs/CompressedImage",
                      "of type sensor_msgs/Image"},
               o);
}

TEST(Rosbag, BagWithoutEventTopicHasNoEvents) {
  TempDir dir;
  TestBagWriter w;
  const uint32_t i = w.connection("/imu", "sensor_msgs/Imu");
  ImuSample s;
  s.t_ns = 5;
  w.message(i, 5, imu_message(s));
  auto r = open_rosbag_dataset(write_file(dir, "imu.bag", w.bytes()), {});
  EventBuffer b;
  EXPECT_EQ(r->read_events(&b, 10), 0u);
  EXPECT_FALSE(r->sensor_size().known());
  EXPECT_EQ(r->read_imu().size(), 1u);
}

TEST(Rosbag, SensorSizeFromOptionsWhenTheMessageStatesNone) {
  TempDir dir;
  TestBagWriter w;
  const uint32_t c = w.connection("/ev", "dvs_msgs/EventArray");
  w.message(c, 10, event_array(10, 0, 0, {Event{10, 3, 3, 1}, Event{11, 12, 3, 1}}));
  const std::string path = write_file(dir, "nosize.bag", w.bytes());
  DatasetOptions o;
  o.text.sensor = SensorSize{10, 10};
  auto r = open_rosbag_dataset(path, o);
  EXPECT_EQ(r->sensor_size().width, 10);
  expect_error(path, {"pixel (12, 3) outside the 10x10 sensor"}, o);
  auto unbounded = open_rosbag_dataset(path, {});
  EXPECT_FALSE(unbounded->sensor_size().known());
  EXPECT_EQ(read_all_events(unbounded.get()).size(), 2u);
}

// ---------------------------------------------------------------------------------------------
// Images.

TEST(Rosbag, ColourImagesAreConvertedToGreyAndOtherEncodingsRejected) {
  TempDir dir;
  TestBagWriter w;
  const uint32_t c = w.connection("/img", "sensor_msgs/Image");
  // One pixel each: pure red, green, blue, white, as rgb8 and as bgr8.
  const std::string rgb("\xff\x00\x00\x00\xff\x00\x00\x00\xff\xff\xff\xff", 12);
  const std::string bgr("\x00\x00\xff\x00\xff\x00\xff\x00\x00\xff\xff\xff", 12);
  w.message(c, 10, image_message(10, 4, 1, "rgb8", 12, rgb));
  w.message(c, 20, image_message(20, 4, 1, "bgr8", 12, bgr));
  auto r = open_rosbag_dataset(write_file(dir, "rgb.bag", w.bytes()), {});
  const std::vector<Frame> f = r->read_frames();
  ASSERT_EQ(f.size(), 2u);
  for (const Frame& x : f) {
    ASSERT_EQ(x.image.cols, 4);
    EXPECT_EQ(x.image.at<uint8_t>(0, 0), 76);   // 0.299 * 255
    EXPECT_EQ(x.image.at<uint8_t>(0, 1), 150);  // 0.587 * 255
    EXPECT_EQ(x.image.at<uint8_t>(0, 2), 29);   // 0.114 * 255
    EXPECT_EQ(x.image.at<uint8_t>(0, 3), 255);
  }

  TestBagWriter w2;
  const uint32_t c2 = w2.connection("/img", "sensor_msgs/Image");
  const size_t m = w2.message(c2, 10, image_message(10, 2, 1, "yuv422", 4, std::string(4, '\0')));
  const std::string path = write_file(dir, "yuv422.bag", w2.bytes());
  const uint64_t off = w2.written(m).chunk_data_pos + w2.written(m).data_off + kHeaderBytes + 8;
  expect_error(path, {"image encoding 'yuv422' is not supported", "byte offset " + std::to_string(off),
                      "sensor_msgs/Image: std_msgs/Header header"});

  TestBagWriter w3;
  const uint32_t c3 = w3.connection("/img", "sensor_msgs/Image");
  w3.message(c3, 10, image_message(10, 4, 3, "mono8", 4, std::string(11, '\0')));
  expect_error(write_file(dir, "short_image.bag", w3.bytes()), {"data of 11 bytes is shorter than step x height = 12"});
}

// ---------------------------------------------------------------------------------------------
// Bad event data: the on_bad_line policy.

TEST(Rosbag, EventsOutsideTheSensorOrBackInTimeFollowThePolicy) {
  TempDir dir;
  TestBagWriter w;
  const uint32_t c = w.connection("/ev", "dvs_msgs/EventArray");
  w.message(c, 100, event_array(100, 10, 8, {Event{100, 1, 1, 1}, Event{200, 10, 1, 1}, Event{300, 2, 2, -1}}));
  const size_t m2 = w.message(c, 400, event_array(400, 10, 8, {Event{250, 3, 3, 1}, Event{400, 4, 4, 1}}));
  const std::string path = write_file(dir, "bad.bag", w.bytes());
  const uint64_t msg1_events = w.written(0).chunk_data_pos + w.written(0).data_off + kHeaderBytes + 12;
  expect_error(path, {"event 1 of a message on /ev: pixel (10, 1) outside the 10x8 sensor", "byte offset " + std::to_string(msg1_events + 13),
                      "--on-bad-line warn"});

  DatasetOptions o;
  o.text.on_bad_line = BadLinePolicy::kWarnAndSkip;
  std::vector<std::string> warnings;
  set_log_sink([&](LogLevel l, const std::string& msg) {
    if (l == LogLevel::kWarning) warnings.push_back(msg);
  });
  auto r = open_rosbag_dataset(path, o);
  const EventBuffer ev = read_all_events(r.get());
  set_log_sink({});
  ASSERT_EQ(ev.size(), 3u);
  EXPECT_EQ(ev[2], (Event{400, 4, 4, 1}));
  EXPECT_EQ(r->event_report().skipped.at("outside sensor").count, 1);
  const auto& order = r->event_report().skipped.at("time order");
  EXPECT_EQ(order.count, 1);
  const uint64_t msg2_events = w.written(m2).chunk_data_pos + w.written(m2).data_off + kHeaderBytes + 12;
  EXPECT_NE(order.first_message.find("byte offset " + std::to_string(msg2_events)), std::string::npos)
      << order.first_message;
  ASSERT_EQ(warnings.size(), 1u);
}

// ---------------------------------------------------------------------------------------------
// Malformed files: every error names the file, a byte offset and the expected form.

TEST(Rosbag, WrongMagic) {
  TempDir dir;
  expect_error(write_file(dir, "a.bag", "#ROSBAG V1.2\nxxxxxxxxxxxxxxxxxxxxxxxxxxxxx"),
               {"unsupported bag version \"#ROSBAG V1.2\" at byte offset 0", "ROS bag format 2.0"});
  expect_error(write_file(dir, "b.bag", std::string("\x89HDF\r\n\x1a\n", 8) + std::string(40, '\0')),
               {"not a ROS bag: magic \"\\x89HDF", "at byte offset 0", "#ROSBAG V2.0"});
  expect_error(write_file(dir, "c.bag", ""), {"byte offset 0"});
}

TEST(Rosbag, TruncatedFiles) {
  TempDir dir;
  {
    SampleBag bag(Compression::kNone, true);
    const std::string bytes = bag.writer.bytes();
    // Cut inside the second chunk: the index is gone, index_pos points past the end.
    const std::string cut = bytes.substr(0, bag.writer.chunk_pos(1) + 40);
    expect_error(write_file(dir, "cut_indexed.bag", cut),
                 {"index_pos", "at byte offset 13", "the file is truncated", "rosbag reindex"});
  }
  {
    SampleBag bag(Compression::kBz2, false);
    const std::string bytes = bag.writer.bytes();
    const uint64_t pos = bag.writer.chunk_pos(1);
    expect_error(write_file(dir, "cut_unindexed.bag", bytes.substr(0, pos + 60)),
                 {"truncated record (op=0x05) at byte offset " + std::to_string(pos), "runs past the end of the file (" +
                  std::to_string(pos + 60) + " bytes)", "#ROSBAG V2.0"});
    expect_error(write_file(dir, "cut_in_header.bag", bytes.substr(0, pos + 20)),
                 {"truncated record at byte offset " + std::to_string(pos) + ": header of"});
    expect_error(write_file(dir, "cut_header.bag", bytes.substr(0, pos + 6)),
                 {"truncated record at byte offset " + std::to_string(pos), "6 bytes left"});
  }
}

TEST(Rosbag, HeaderFieldWithoutEquals) {
  TempDir dir;
  SampleBag bag(Compression::kNone, true);
  std::string bytes = bag.writer.bytes();
  // The message record header's first field is "op=\x02"; break its '='.
  const WrittenMessage& m = bag.writer.written(1);
  const uint64_t field = m.chunk_data_pos + m.record_off + 4;
  ASSERT_EQ(bytes.substr(field + 4, 3), "op=");
  bytes[field + 6] = ':';
  expect_error(write_file(dir, "noeq.bag", bytes),
               {"header field without '=' (\"op:\\x02\") at byte offset " + std::to_string(field), "name=value"});
}

TEST(Rosbag, ChunkSizeBeyondEndOfFile) {
  TempDir dir;
  SampleBag bag(Compression::kNone, true);
  std::string bytes = bag.writer.bytes();
  const uint64_t pos = bag.writer.chunk_pos(1);
  const uint64_t data_len_at = bag.writer.written(3).chunk_data_pos - 4;
  const uint32_t huge = 0x7fff0000u;
  std::memcpy(&bytes[data_len_at], &huge, 4);
  expect_error(write_file(dir, "huge_chunk.bag", bytes),
               {"truncated record (op=0x05) at byte offset " + std::to_string(pos),
                "data of 2147418112 bytes at byte offset " + std::to_string(data_len_at + 4), "runs past the end of the file"});
}

TEST(Rosbag, CorruptedCompressedChunks) {
  for (Compression c : {Compression::kBz2, Compression::kLz4}) {
    TempDir dir;
    SampleBag bag(c, true);
    std::string bytes = bag.writer.bytes();
    const uint64_t pos = bag.writer.chunk_pos(1);
    const uint64_t data = bag.writer.written(3).chunk_data_pos;
    for (int i = 0; i < 6; ++i) bytes[data + 30 + static_cast<uint64_t>(i)] ^= 0x5a;
    const std::string name = compression_name(c);
    expect_error(write_file(dir, name + ".bag", bytes),
                 {"corrupted " + name + " data in the chunk at byte offset " + std::to_string(pos),
                  "a valid " + name + " stream"});
  }
}

TEST(Rosbag, DeclaredUncompressedSizeMustMatch) {
  TempDir dir;
  SampleBag bag(Compression::kLz4, true);
  std::string bytes = bag.writer.bytes();
  // The chunk header's "size" field value: find it in the record header of chunk 0.
  const uint64_t pos = bag.writer.chunk_pos(0);
  const size_t at = bytes.find("size=", pos) + 5;
  uint32_t size;
  std::memcpy(&size, &bytes[at], 4);
  size += 100;
  std::memcpy(&bytes[at], &size, 4);
  expect_error(write_file(dir, "size.bag", bytes),
               {"corrupted lz4 data in the chunk at byte offset " + std::to_string(pos),
                "the chunk header says size=" + std::to_string(size)});
}

TEST(Rosbag, MessageShorterThanItsArrays) {
  TempDir dir;
  for (Compression c : {Compression::kNone, Compression::kBz2}) {
    TestBagWriter w(c);
    const uint32_t ev = w.connection("/ev", "dvs_msgs/EventArray");
    std::string msg = event_array(10, 20, 20, {Event{10, 1, 1, 1}, Event{11, 2, 2, 1}, Event{12, 3, 3, 1}});
    const uint32_t claimed = 10;
    std::memcpy(&msg[kHeaderBytes + 8], &claimed, 4);
    const size_t m = w.message(ev, 10, msg);
    const std::string path = write_file(dir, "short.bag", w.bytes());
    const uint64_t in_chunk = w.written(m).data_off + kHeaderBytes + 8;
    const std::string where = c == Compression::kNone
                                  ? "at byte offset " + std::to_string(w.written(m).chunk_data_pos + in_chunk)
                                  : "at byte offset " + std::to_string(in_chunk) + " of the decompressed bz2 chunk at byte offset " +
                                        std::to_string(w.written(m).chunk_pos);
    expect_error(path, {"dvs_msgs/EventArray message on /ev: events array of 10 x 13 bytes runs past the end of the " +
                            std::to_string(msg.size()) + "-byte message (39 bytes left)",
                        where, "Event = uint16 x, uint16 y, time ts"});
  }
}

TEST(Rosbag, ArrayCountImplyingGigabytesIsRejectedWithoutAllocating) {
  TempDir dir;
  TestBagWriter w;
  const uint32_t ev = w.connection("/ev", "event_camera_msgs/EventPacket");
  std::string msg = event_packet(10, 20, 20, "evt3", {time_high(0), time_low(0)});
  const uint32_t claimed = 0xffffffffu;
  std::memcpy(&msg[msg.size() - 4 - 4], &claimed, 4);
  const size_t m = w.message(ev, 10, msg);
  const std::string path = write_file(dir, "giga.bag", w.bytes());
  const uint64_t off = w.written(m).chunk_data_pos + w.written(m).data_off + msg.size() - 8;
  expect_error(path, {"events array of 4294967295 x 1 bytes runs past the end", "byte offset " + std::to_string(off)});

  TestBagWriter w2;
  const uint32_t im = w2.connection("/img", "sensor_msgs/Image");
  std::string img = image_message(10, 60000, 60000, "mono8", 60000, "");
  w2.message(im, 10, img);
  expect_error(write_file(dir, "giga_image.bag", w2.bytes()), {"data of 0 bytes is shorter than step x height = 3600000000"});
}

TEST(Rosbag, ImuMessageOfTheWrongSize) {
  TempDir dir;
  TestBagWriter w;
  const uint32_t c = w.connection("/imu", "sensor_msgs/Imu");
  ImuSample s;
  s.t_ns = 10;
  const size_t m = w.message(c, 10, imu_message(s) + "xy");
  const std::string path = write_file(dir, "imu.bag", w.bytes());
  const uint64_t end = w.written(m).chunk_data_pos + w.written(m).data_off + kHeaderBytes + 296;
  expect_error(path,
               {"sensor_msgs/Imu message on /imu: 2 unexpected bytes after the last field at byte offset " +
                std::to_string(end)});
}

TEST(Rosbag, IndexPointingToAMissingConnection) {
  TempDir dir;
  SampleBag bag(Compression::kNone, true);
  std::string bytes = bag.writer.bytes();
  // The first chunk info's data: connection id 0 -> 9.
  const size_t info = bytes.find(std::string("chunk_pos=", 10));
  ASSERT_NE(info, std::string::npos);
  uint32_t hlen;
  // Walk back to the record start: its header begins with the "op=\x06" field.
  const size_t op = bytes.rfind(std::string("op=\x06", 4), info);
  ASSERT_NE(op, std::string::npos);
  const size_t start = op - 4 - 4;
  std::memcpy(&hlen, &bytes[start], 4);
  const size_t data = start + 4 + hlen + 4;
  const uint32_t bogus = 9;
  std::memcpy(&bytes[data], &bogus, 4);
  expect_error(write_file(dir, "conn.bag", bytes),
               {"chunk info record at byte offset " + std::to_string(start), "names connection 9"});
}

}  // namespace
}  // namespace evio
