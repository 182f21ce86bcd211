// MCAP container (sensors/src/mcap_container.h) against the test writer (evio_test/mcap_writer.h):
// every layout (compression x summary x chunked), channel and time selection, and damaged files
// (truncation, corrupted chunks, bad magic, unknown records, huge length fields).
#include "../../sensors/src/mcap_container.h"

#include <sys/resource.h>

#include <algorithm>
#include <fstream>
#include <iterator>
#include <random>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio_test/mcap_writer.h"
#include "evio_test/temp_dir.h"

namespace evio::detail::mcap {
namespace {

using evio_test::McapWriter;
using evio_test::McapWriterOptions;
using evio_test::TempDir;

constexpr size_t kChunkSize = 4096;

struct Msg {
  uint16_t channel = 0;
  uint64_t log = 0, pub = 0;
  uint32_t seq = 0;
  std::string data;
  bool operator==(const Msg& o) const {
    return channel == o.channel && log == o.log && pub == o.pub && seq == o.seq && data == o.data;
  }
};

std::ostream& operator<<(std::ostream& os, const Msg& m) {
  return os << "{channel " << m.channel << ", log " << m.log << ", pub " << m.pub << ", seq " << m.seq << ", "
            << m.data.size() << " bytes}";
}

// Three channels: 1 and 2 throughout, 3 only in the last quarter. Sizes: empty messages, messages
// larger than a chunk, and random ones in between; payload bytes random.
std::vector<Msg> make_messages(uint32_t seed, size_t n) {
  std::mt19937 rng(seed);
  std::vector<Msg> out;
  uint64_t t = 1'000'000'000;
  for (size_t i = 0; i < n; ++i) {
    Msg m;
    m.channel = i >= 3 * n / 4 && i % 3 == 0 ? 3 : static_cast<uint16_t>(1 + i % 2);
    t += 1000 + rng() % 1000;
    m.log = t;
    m.pub = t - rng() % 500;
    m.seq = static_cast<uint32_t>(i);
    const size_t size = i % 11 == 0 ? 0 : i % 37 == 5 ? kChunkSize + 1 + rng() % 5000 : rng() % 600;
    for (size_t k = 0; k < size; ++k) m.data.push_back(static_cast<char>(rng() % 4 == 0 ? rng() : k % 7));
    out.push_back(std::move(m));
  }
  return out;
}

std::string write_file(const std::string& path, const McapWriterOptions& o, const std::vector<Msg>& msgs) {
  McapWriter w(path, o);
  const uint16_t imu = w.add_schema("sensor_msgs/msg/Imu", "ros2msg", "std_msgs/Header header\nfloat64 x");
  const uint16_t events = w.add_schema("event_camera_msgs/msg/EventPacket", "ros2msg", "uint8[] events");
  EXPECT_EQ(w.add_channel(imu, "/imu", "cdr"), 1);
  EXPECT_EQ(w.add_channel(events, "/events", "cdr", {{"offered_qos_profiles", "- history: 3"}, {"k", ""}}), 2);
  EXPECT_EQ(w.add_channel(0, "/late", "json"), 3);
  for (const Msg& m : msgs) w.write(m.channel, m.log, m.data, m.pub, m.seq);
  w.close();
  return path;
}

std::string read_bytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

void write_bytes(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << bytes;
}

// Messages of `ids` from start_ns; *loaded receives the chunks decompressed.
std::vector<Msg> read_all(const File& f, std::vector<uint16_t> ids, uint64_t start_ns = 0, size_t* loaded = nullptr) {
  MessageCursor cursor(f, std::move(ids), start_ns);
  std::vector<Msg> out;
  Message m;
  double last = 0.0;
  while (cursor.next(&m)) {
    Msg x;
    x.channel = m.channel->id;
    x.log = m.log_time_ns;
    x.pub = m.publish_time_ns;
    x.seq = m.sequence;
    x.data.assign(reinterpret_cast<const char*>(m.data), m.size);
    out.push_back(std::move(x));
    EXPECT_GE(cursor.progress(), last);
    last = cursor.progress();
  }
  EXPECT_EQ(cursor.progress(), 1.0);
  if (loaded != nullptr) *loaded = cursor.chunks_loaded();
  return out;
}

std::vector<Msg> only(const std::vector<Msg>& msgs, const std::set<uint16_t>& ids, uint64_t start_ns = 0) {
  std::vector<Msg> out;
  for (const Msg& m : msgs) {
    if (ids.count(m.channel) != 0 && m.log >= start_ns) out.push_back(m);
  }
  return out;
}

// Collects log messages (warnings about linear scans) while alive.
struct LogCapture {
  std::vector<std::string> lines;
  LogCapture() {
    set_log_sink([this](LogLevel level, const std::string& m) {
      if (level >= LogLevel::kWarning) lines.push_back(m);
    });
  }
  ~LogCapture() { set_log_sink({}); }
  bool any(const std::string& s) const {
    return std::any_of(lines.begin(), lines.end(),
                       [&](const std::string& l) { return l.find(s) != std::string::npos; });
  }
};

struct Layout {
  std::string compression;
  bool summary;
  size_t chunk_size;
  std::string name() const {
    return "compression '" + compression + "', " + (summary ? "summary" : "no summary") + ", " +
           (chunk_size ? "chunked" : "unchunked");
  }
};

std::vector<Layout> all_layouts() {
  std::vector<Layout> out;
  for (const char* c : {"", "lz4", "zstd"}) {
    for (const bool summary : {true, false}) {
      for (const size_t chunk : {kChunkSize, size_t{0}}) out.push_back(Layout{c, summary, chunk});
    }
  }
  return out;
}

McapWriterOptions options(const Layout& l) {
  McapWriterOptions o;
  o.compression = l.compression;
  o.summary = l.summary;
  o.chunk_size = l.chunk_size;
  return o;
}

uint64_t file_offset_in(const std::string& at) {
  const std::string key = "byte offset ";
  const size_t i = at.find(key);
  EXPECT_NE(i, std::string::npos) << at;
  return i == std::string::npos ? 0 : std::stoull(at.substr(i + key.size()));
}

// ---------------------------------------------------------------------------------------------

TEST(McapRoundTrip, EveryLayoutGivesTheWrittenMessagesAndCounts) {
  TempDir dir;
  const std::vector<Msg> msgs = make_messages(7, 400);
  for (const Layout& l : all_layouts()) {
    SCOPED_TRACE(l.name());
    const std::string path = write_file(dir.file("a.mcap"), options(l), msgs);
    LogCapture log;
    const File f(path);
    EXPECT_EQ(f.profile(), "ros2");
    EXPECT_EQ(f.library(), "evio_test McapWriter");
    EXPECT_EQ(f.has_summary(), l.summary);
    EXPECT_EQ(log.any("linear scan"), !l.summary);
    EXPECT_EQ(f.damage(), nullptr);
    EXPECT_EQ(f.chunks().empty(), l.chunk_size == 0);
    EXPECT_EQ(f.has_unchunked_messages(), l.chunk_size == 0);
    if (l.chunk_size != 0) {
      EXPECT_GT(f.chunks().size(), 20u);
    }
    for (const ChunkInfo& c : f.chunks()) EXPECT_EQ(c.compression, l.compression);

    ASSERT_EQ(f.schemas().size(), 2u);
    EXPECT_EQ(f.schemas()[1].name, "event_camera_msgs/msg/EventPacket");
    EXPECT_EQ(f.schemas()[1].encoding, "ros2msg");
    EXPECT_EQ(f.schemas()[1].data, "uint8[] events");
    ASSERT_EQ(f.channels().size(), 3u);
    const Channel* events = f.find_channel(2);
    ASSERT_NE(events, nullptr);
    EXPECT_EQ(events->topic, "/events");
    EXPECT_EQ(events->message_encoding, "cdr");
    EXPECT_EQ(events->schema_name, "event_camera_msgs/msg/EventPacket");
    ASSERT_EQ(events->metadata.size(), 2u);
    EXPECT_EQ(events->metadata[0].first, "offered_qos_profiles");
    EXPECT_EQ(events->metadata[0].second, "- history: 3");
    EXPECT_EQ(f.find_channel(3)->schema_name, "");
    EXPECT_EQ(f.find_channel(3)->message_encoding, "json");
    EXPECT_EQ(f.find_channel(4), nullptr);
    for (const uint16_t id : {1, 2, 3}) {
      EXPECT_EQ(f.find_channel(id)->messages, static_cast<int64_t>(only(msgs, {id}).size())) << "channel " << id;
    }
    EXPECT_TRUE(f.statistics().known);
    EXPECT_EQ(f.statistics().message_count, msgs.size());
    EXPECT_EQ(f.statistics().message_start_ns, msgs.front().log);
    EXPECT_EQ(f.statistics().message_end_ns, msgs.back().log);

    const std::vector<Msg> got = read_all(f, {1, 2, 3});
    ASSERT_EQ(got.size(), msgs.size());
    for (size_t i = 0; i < msgs.size(); ++i) ASSERT_EQ(got[i], msgs[i]) << "message " << i;
  }
}

TEST(McapRoundTrip, MessageAtNamesTheFileOffsetOrTheDecompressedChunk) {
  TempDir dir;
  const std::vector<Msg> msgs = make_messages(3, 120);
  for (const Layout& l : all_layouts()) {
    SCOPED_TRACE(l.name());
    const std::string path = write_file(dir.file("a.mcap"), options(l), msgs);
    const std::string bytes = read_bytes(path);
    LogCapture quiet;
    const File f(path);
    MessageCursor cursor(f, {1, 2, 3});
    Message m;
    size_t checked = 0;
    while (cursor.next(&m)) {
      if (m.size < 2) continue;
      const std::string at = m.at(1);
      if (l.chunk_size != 0 && !l.compression.empty()) {
        // In a decompressed chunk: the chunk's offset is named, and the chunk starts there.
        EXPECT_NE(at.find("of the decompressed " + l.compression + " chunk at byte offset "), std::string::npos) << at;
        const uint64_t chunk_pos = std::stoull(at.substr(at.rfind(' ') + 1));
        EXPECT_TRUE(std::any_of(f.chunks().begin(), f.chunks().end(), [&](const ChunkInfo& c) {
          return c.pos == chunk_pos;
        })) << at;
      } else {
        // A file offset: the message's bytes lie there.
        EXPECT_NE(at.find("of the file"), std::string::npos) << at;
        const uint64_t off = file_offset_in(at);
        ASSERT_LE(off + m.size - 1, bytes.size());
        EXPECT_EQ(bytes.compare(off - 1, m.size, reinterpret_cast<const char*>(m.data), m.size), 0) << at;
      }
      ++checked;
    }
    EXPECT_GT(checked, 50u);
  }
}

TEST(McapRoundTrip, SummaryAndLinearScanFindTheSameChunks) {
  TempDir dir;
  const std::vector<Msg> msgs = make_messages(11, 300);
  for (const char* c : {"", "lz4", "zstd"}) {
    SCOPED_TRACE(c);
    McapWriterOptions o;
    o.compression = c;
    o.chunk_size = kChunkSize;
    const File indexed(write_file(dir.file("indexed.mcap"), o, msgs));
    o.summary = false;
    LogCapture quiet;
    const File scanned(write_file(dir.file("scanned.mcap"), o, msgs));
    ASSERT_TRUE(indexed.has_summary());
    ASSERT_FALSE(scanned.has_summary());
    ASSERT_EQ(indexed.chunks().size(), scanned.chunks().size());
    for (size_t i = 0; i < indexed.chunks().size(); ++i) {
      const ChunkInfo& a = indexed.chunks()[i];
      const ChunkInfo& b = scanned.chunks()[i];
      EXPECT_EQ(a.pos, b.pos);
      EXPECT_EQ(a.length, b.length);
      EXPECT_EQ(a.start_ns, b.start_ns);
      EXPECT_EQ(a.end_ns, b.end_ns);
      EXPECT_EQ(a.compression, b.compression);
      EXPECT_EQ(a.compressed_size, b.compressed_size);
      EXPECT_EQ(a.uncompressed_size, b.uncompressed_size);
      EXPECT_EQ(a.message_index_offsets, b.message_index_offsets);
      EXPECT_EQ(a.message_index_length, b.message_index_length);
      EXPECT_TRUE(a.channels_known);
      EXPECT_TRUE(b.channels_known);
      EXPECT_EQ(a.channel_ids, b.channel_ids);
    }
    EXPECT_EQ(read_all(indexed, {1, 2, 3}), read_all(scanned, {1, 2, 3}));
  }
}

// ---------------------------------------------------------------------------------------------

TEST(McapCursor, SelectsChannelsAndSkipsChunksWithoutThem) {
  TempDir dir;
  const std::vector<Msg> msgs = make_messages(5, 400);
  for (const Layout& l : all_layouts()) {
    SCOPED_TRACE(l.name());
    LogCapture quiet;
    const File f(write_file(dir.file("a.mcap"), options(l), msgs));
    EXPECT_EQ(read_all(f, {2}), only(msgs, {2}));
    EXPECT_EQ(read_all(f, {3, 1}), only(msgs, {1, 3}));
    EXPECT_TRUE(read_all(f, {}).empty());
    EXPECT_TRUE(read_all(f, {9}).empty());  // a channel the file does not have
    size_t loaded = 0;
    EXPECT_EQ(read_all(f, {3}, 0, &loaded), only(msgs, {3}));
    if (l.chunk_size != 0) {
      // Channel 3 is in the last quarter only: the earlier chunks are not decompressed.
      EXPECT_GT(loaded, 0u);
      EXPECT_LT(loaded, f.chunks().size() / 2);
    }
  }
}

TEST(McapCursor, WithoutMessageIndexesEveryChunkIsRead) {
  TempDir dir;
  const std::vector<Msg> msgs = make_messages(6, 300);
  McapWriterOptions o;
  o.compression = "lz4";
  o.chunk_size = kChunkSize;
  o.message_index = false;
  const File f(write_file(dir.file("a.mcap"), o, msgs));
  ASSERT_TRUE(f.has_summary());
  for (const ChunkInfo& c : f.chunks()) {
    EXPECT_TRUE(c.message_index_offsets.empty());
    EXPECT_FALSE(c.channels_known);
  }
  size_t loaded = 0;
  EXPECT_EQ(read_all(f, {3}, 0, &loaded), only(msgs, {3}));
  EXPECT_EQ(loaded, f.chunks().size());
}

TEST(McapCursor, StartTimeSkipsEarlierChunksAndMessages) {
  TempDir dir;
  const std::vector<Msg> msgs = make_messages(9, 400);
  const uint64_t start = msgs[msgs.size() / 2].log + 1;  // not a message's time
  for (const Layout& l : all_layouts()) {
    SCOPED_TRACE(l.name());
    LogCapture quiet;
    const File f(write_file(dir.file("a.mcap"), options(l), msgs));
    size_t loaded = 0;
    const std::vector<Msg> got = read_all(f, {1, 2, 3}, start, &loaded);
    EXPECT_EQ(got, only(msgs, {1, 2, 3}, start));
    EXPECT_EQ(got.size(), msgs.size() - msgs.size() / 2 - 1);
    if (l.chunk_size != 0) {
      EXPECT_LE(loaded, f.chunks().size() / 2 + 2);
      EXPECT_GT(loaded, 0u);
    }
    EXPECT_EQ(read_all(f, {1}, start), only(msgs, {1}, start));
    EXPECT_TRUE(read_all(f, {1, 2, 3}, msgs.back().log + 1).empty());
  }
}

// ---------------------------------------------------------------------------------------------

bool is_prefix(const std::vector<Msg>& got, const std::vector<Msg>& all) {
  return got.size() <= all.size() && std::equal(got.begin(), got.end(), all.begin());
}

TEST(McapDamage, TruncatedFileGivesAPrefixThenAnErrorNamingTheRecord) {
  TempDir dir;
  const std::vector<Msg> msgs = make_messages(13, 400);
  for (const Layout& l : {Layout{"zstd", true, kChunkSize}, Layout{"", false, 0}}) {
    SCOPED_TRACE(l.name());
    const std::string full = read_bytes(write_file(dir.file("full.mcap"), options(l), msgs));
    // The data section ends with the Data End record (13 bytes): right before the summary, or
    // before the Footer (29 bytes) and the magic when there is no summary.
    uint64_t summary_start = 0;
    for (int k = 0; k < 8; ++k) summary_start |= uint64_t{static_cast<uint8_t>(full[full.size() - 28 + k])} << (8 * k);
    const uint64_t data_end = summary_start != 0 ? summary_start : full.size() - 37;
    ASSERT_EQ(full[data_end - 13], 0x0f);
    size_t partial = 0;
    for (size_t i = 1; i <= 20; ++i) {
      const size_t cut = i * full.size() / 21;
      SCOPED_TRACE("cut at " + std::to_string(cut) + " of " + std::to_string(full.size()));
      const std::string path = dir.file("cut.mcap");
      write_bytes(path, full.substr(0, cut));
      LogCapture log;
      std::vector<Msg> got;
      try {
        const File f(path);
        EXPECT_FALSE(f.has_summary());
        EXPECT_TRUE(log.any("linear scan"));
        MessageCursor cursor(f, {1, 2, 3});
        Message m;
        while (cursor.next(&m)) {
          got.push_back(Msg{m.channel->id, m.log_time_ns, m.publish_time_ns, m.sequence,
                            std::string(reinterpret_cast<const char*>(m.data), m.size)});
        }
        // No error: the data section was whole (the cut removed only summary or footer bytes).
        EXPECT_GE(cut, data_end);
        EXPECT_EQ(got, msgs);
        EXPECT_EQ(f.damage(), nullptr);
      } catch (const InputError& e) {
        const std::string what = e.what();
        EXPECT_NE(what.find("byte offset"), std::string::npos) << what;
        EXPECT_TRUE(what.find("record") != std::string::npos || what.find("magic") != std::string::npos) << what;
        EXPECT_NE(what.find("cut.mcap"), std::string::npos) << what;
        EXPECT_TRUE(is_prefix(got, msgs)) << got.size() << " messages";
        EXPECT_LT(cut, data_end);
        if (!got.empty() && got.size() < msgs.size()) ++partial;
      }
    }
    EXPECT_GE(partial, 15u);
  }
}

// The chunk whose records are damaged is named, in the summary's reading and the linear scan's.
TEST(McapDamage, CorruptedChunkDataNamesTheChunk) {
  TempDir dir;
  const std::vector<Msg> msgs = make_messages(17, 300);
  for (const Layout& l :
       {Layout{"", true, kChunkSize}, Layout{"lz4", true, kChunkSize}, Layout{"zstd", true, kChunkSize},
        Layout{"zstd", false, kChunkSize}, Layout{"lz4", false, kChunkSize}}) {
    SCOPED_TRACE(l.name());
    std::string bytes = read_bytes(write_file(dir.file("a.mcap"), options(l), msgs));
    LogCapture quiet;
    ChunkInfo victim;
    {
      const File f(dir.file("a.mcap"));
      ASSERT_GT(f.chunks().size(), 4u);
      victim = f.chunks()[2];
    }
    // The records field is the tail of the Chunk record.
    const uint64_t records = victim.pos + victim.length - victim.compressed_size;
    for (uint64_t k = records + victim.compressed_size / 3; k < records + victim.compressed_size / 3 + 8; ++k) {
      bytes[k] = static_cast<char>(bytes[k] ^ 0x5a);
    }
    write_bytes(dir.file("bad.mcap"), bytes);
    const File f(dir.file("bad.mcap"));
    MessageCursor cursor(f, {1, 2, 3});
    Message m;
    size_t n = 0;
    try {
      while (cursor.next(&m)) ++n;
      FAIL() << "no error after " << n << " messages";
    } catch (const InputError& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("Chunk (op=0x06) record at byte offset " + std::to_string(victim.pos)), std::string::npos)
          << what;
    }
    EXPECT_GT(n, 0u);  // the messages of the chunks before it
  }
}

TEST(McapDamage, BadMagicIsAnError) {
  TempDir dir;
  const std::vector<Msg> msgs = make_messages(19, 50);
  std::string bytes = read_bytes(write_file(dir.file("a.mcap"), McapWriterOptions{}, msgs));
  auto open_error = [&](const std::string& content) -> std::string {
    write_bytes(dir.file("bad.mcap"), content);
    try {
      File f(dir.file("bad.mcap"));
    } catch (const InputError& e) {
      return e.what();
    }
    return "";
  };
  std::string b = bytes;
  b[1] = 'X';
  EXPECT_NE(open_error(b).find("not an MCAP file: magic"), std::string::npos) << open_error(b);
  b = bytes;
  b[5] = '1';
  EXPECT_NE(open_error(b).find("unsupported MCAP major version '1'"), std::string::npos) << open_error(b);
  EXPECT_NE(open_error("").find("not an MCAP file"), std::string::npos);
  EXPECT_NE(open_error(bytes.substr(0, 12)).find("truncated record at byte offset 8"), std::string::npos)
      << open_error(bytes.substr(0, 12));
  b = bytes;
  b[8] = 0x03;  // a Schema record where the Header belongs
  EXPECT_NE(open_error(b).find("expected the Header (op=0x01) record at byte offset 8"), std::string::npos);

  // The closing magic damaged: the footer is not trusted, the data section is scanned and whole.
  b = bytes;
  b[b.size() - 3] ^= 1;
  write_bytes(dir.file("tail.mcap"), b);
  LogCapture log;
  const File f(dir.file("tail.mcap"));
  EXPECT_FALSE(f.has_summary());
  EXPECT_TRUE(log.any("does not end with a Footer record and the magic"));
  EXPECT_EQ(f.damage(), nullptr);
  EXPECT_EQ(read_all(f, {1, 2, 3}), msgs);
}

TEST(McapRecords, UnknownAndUnneededRecordsAreSkipped) {
  TempDir dir;
  const std::vector<Msg> msgs = make_messages(23, 200);
  for (const Layout& l : all_layouts()) {
    SCOPED_TRACE(l.name());
    const std::string path = dir.file("a.mcap");
    {
      McapWriter w(path, options(l));
      w.write_record(0x80, "an application record");  // before any schema
      const uint16_t s = w.add_schema("a", "ros2msg", "int32 x");
      w.add_channel(s, "/one");
      w.add_channel(s, "/two");
      w.add_channel(0, "/three", "json");
      for (size_t i = 0; i < msgs.size(); ++i) {
        const Msg& m = msgs[i];
        w.write(m.channel, m.log, m.data, m.pub, m.seq);
        if (i == 50) w.write_record(0xff, std::string(1000, 'u'), true);               // inside the open chunk
        if (i == 60) w.write_record(0x0c, std::string("\x04\0\0\0name\0\0\0\0", 12));  // Metadata
        if (i == 70) w.write_record(0x7f, "");                                         // reserved opcode, empty content
      }
      w.close();
    }
    LogCapture quiet;
    const File f(path);
    EXPECT_EQ(f.damage(), nullptr);
    EXPECT_EQ(read_all(f, {1, 2, 3}), msgs);
  }
}

// Length fields past the end of the file are errors that allocate nothing.
TEST(McapDamage, LengthLargerThanTheFileIsAnErrorWithoutAllocating) {
  TempDir dir;
  const std::vector<Msg> msgs = make_messages(29, 100);
  McapWriterOptions unchunked;
  unchunked.chunk_size = 0;
  unchunked.summary = false;
  const std::string bytes = read_bytes(write_file(dir.file("a.mcap"), unchunked, msgs));
  auto put64 = [](std::string* s, size_t at, uint64_t v) {
    for (int i = 0; i < 8; ++i) (*s)[at + i] = static_cast<char>(v >> (8 * i));
  };
  LogCapture quiet;

  // The Header's length.
  std::string b = bytes;
  put64(&b, 9, uint64_t{1} << 62);
  write_bytes(dir.file("bad.mcap"), b);
  try {
    File f(dir.file("bad.mcap"));
    FAIL() << "opened";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("Header (op=0x01) record at byte offset 8 of the file: content length"),
              std::string::npos)
        << e.what();
  }

  // A Message record in place of Data End with a huge length: every message, then the error.
  b = bytes;
  const size_t data_end = b.size() - 8 - 29 - 13;  // Data End: 9 + 4 bytes before the Footer
  ASSERT_EQ(b[data_end], 0x0f);
  b = b.substr(0, data_end);
  b += '\x05';
  b += std::string(8, '\0');
  put64(&b, data_end + 1, uint64_t{1} << 62);
  b += std::string(40, 'm');
  write_bytes(dir.file("bad.mcap"), b);
  const File f(dir.file("bad.mcap"));
  ASSERT_NE(f.damage(), nullptr);
  std::vector<Msg> got;
  try {
    MessageCursor cursor(f, {1, 2, 3});
    Message m;
    while (cursor.next(&m))
      got.push_back(Msg{m.channel->id, m.log_time_ns, m.publish_time_ns, m.sequence,
                        std::string(reinterpret_cast<const char*>(m.data), m.size)});
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("Message (op=0x05) record at byte offset " + std::to_string(data_end) +
                                         " of the file: content length 4611686018427387904 runs past"),
              std::string::npos)
        << e.what();
  }
  EXPECT_EQ(got, msgs);

  // Chunks whose uncompressed_size is false: above the 1 GiB limit, or below it (900 MB) but far
  // more than the data: errors, and the output buffer grows with the data only.
  McapWriterOptions chunked;
  chunked.compression = "zstd";
  chunked.summary = false;
  chunked.chunk_size = kChunkSize;
  const std::string cb = read_bytes(write_file(dir.file("c.mcap"), chunked, msgs));
  uint64_t chunk_pos = 0;
  {
    const File c(dir.file("c.mcap"));
    chunk_pos = c.chunks()[1].pos;
  }
  for (const uint64_t size : {uint64_t{1} << 40, uint64_t{900} << 20}) {
    b = cb;
    put64(&b, chunk_pos + 9 + 16, size);
    write_bytes(dir.file("bad.mcap"), b);
    struct rusage before {};
    getrusage(RUSAGE_SELF, &before);
    const File c(dir.file("bad.mcap"));
    ASSERT_NE(c.damage(), nullptr);
    const std::string what = c.damage()->what();
    EXPECT_NE(what.find("Chunk (op=0x06) record at byte offset " + std::to_string(chunk_pos)), std::string::npos)
        << what;
    EXPECT_NE(what.find(size > (uint64_t{1} << 30) ? "exceed the 1 GiB limit for a chunk"
                                                   : "uncompressed_size says 943718400"),
              std::string::npos)
        << what;
    struct rusage after {};
    getrusage(RUSAGE_SELF, &after);
    EXPECT_LT(after.ru_maxrss - before.ru_maxrss, 100 * 1024) << "kB of peak memory growth";
    EXPECT_THROW(read_all(c, {1, 2, 3}), InputError);
  }
}

TEST(McapSummary, DamagedSummaryFallsBackToTheLinearScan) {
  TempDir dir;
  const std::vector<Msg> msgs = make_messages(31, 200);
  McapWriterOptions o;
  o.compression = "lz4";
  o.chunk_size = kChunkSize;
  std::string bytes = read_bytes(write_file(dir.file("a.mcap"), o, msgs));
  bytes[bytes.size() - 8 - 29 - 40] ^= 0x10;  // inside the Summary Offset records: summary_crc fails
  write_bytes(dir.file("bad.mcap"), bytes);
  LogCapture log;
  const File f(dir.file("bad.mcap"));
  EXPECT_FALSE(f.has_summary());
  EXPECT_TRUE(log.any("its summary section is unusable (the summary section's CRC-32 is"));
  EXPECT_EQ(f.damage(), nullptr);
  EXPECT_EQ(read_all(f, {1, 2, 3}), msgs);
  EXPECT_EQ(f.find_channel(2)->messages, static_cast<int64_t>(only(msgs, {2}).size()));
}

}  // namespace
}  // namespace evio::detail::mcap
