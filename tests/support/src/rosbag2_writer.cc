#include "evio_test/rosbag2_writer.h"

#include <sqlite3.h>
#include <zstd.h>

#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <stdexcept>

#include "evio_test/mcap_writer.h"

namespace evio_test {

CdrWriter::CdrWriter(bool big_endian) : big_(big_endian) {
  out_.push_back('\0');
  out_.push_back(big_endian ? '\0' : '\1');
  out_.push_back('\0');
  out_.push_back('\0');
}

void CdrWriter::align(size_t n) {
  while ((out_.size() - 4) % n != 0) out_.push_back('\0');
}

void CdrWriter::put(const void* p, size_t n) {
  align(n);
  const char* c = static_cast<const char*>(p);
  if (big_) {
    for (size_t i = 0; i < n; ++i) out_.push_back(c[n - 1 - i]);
  } else {
    out_.append(c, n);
  }
}

void CdrWriter::u8(uint8_t v) { out_.push_back(static_cast<char>(v)); }
void CdrWriter::u16(uint16_t v) { put(&v, 2); }
void CdrWriter::u32(uint32_t v) { put(&v, 4); }
void CdrWriter::i32(int32_t v) { put(&v, 4); }
void CdrWriter::u64(uint64_t v) { put(&v, 8); }
void CdrWriter::f64(double v) { put(&v, 8); }
void CdrWriter::string(const std::string& s) {
  u32(static_cast<uint32_t>(s.size() + 1));
  out_ += s;
  out_.push_back('\0');
}
void CdrWriter::bytes(const std::string& b) {
  u32(static_cast<uint32_t>(b.size()));
  out_ += b;
}
void CdrWriter::header(int64_t stamp_ns, const std::string& frame_id) {
  int64_t sec = stamp_ns / 1000000000;
  int64_t nsec = stamp_ns % 1000000000;
  if (nsec < 0) {
    nsec += 1000000000;
    --sec;
  }
  i32(static_cast<int32_t>(sec));
  u32(static_cast<uint32_t>(nsec));
  string(frame_id);
}

std::string cdr_event_array(int64_t stamp_ns, uint32_t width, uint32_t height, const std::vector<evio::Event>& events,
                            bool big_endian) {
  CdrWriter w(big_endian);
  w.header(stamp_ns);
  w.u32(height);
  w.u32(width);
  w.u32(static_cast<uint32_t>(events.size()));
  for (const evio::Event& e : events) {
    w.u16(e.x);
    w.u16(e.y);
    w.i32(static_cast<int32_t>(e.t_ns / 1000000000));
    w.u32(static_cast<uint32_t>(e.t_ns % 1000000000));
    w.u8(e.polarity > 0 ? 1 : 0);
  }
  return w.data();
}

std::string cdr_event_packet(int64_t stamp_ns, uint32_t width, uint32_t height, const std::string& encoding,
                             const std::string& payload, bool big_endian, uint64_t time_base) {
  CdrWriter w(big_endian);
  w.header(stamp_ns);
  w.u32(height);
  w.u32(width);
  w.u64(7);  // seq
  w.u64(time_base);
  w.string(encoding);
  w.u8(0);  // is_bigendian (of the payload)
  w.bytes(payload);
  return w.data();
}

std::string mono_payload(int64_t stamp_ns, const std::vector<evio::Event>& events) {
  std::string out;
  for (const evio::Event& e : events) {
    const auto dt = static_cast<uint64_t>(e.t_ns - stamp_ns);
    if (dt >= (uint64_t{1} << 32)) throw std::invalid_argument("mono_payload: dt beyond 32 bits");
    const uint64_t w = dt | (uint64_t{e.x} << 32) | (uint64_t{e.y} << 48) | (e.polarity > 0 ? uint64_t{1} << 63 : 0);
    out.append(reinterpret_cast<const char*>(&w), 8);
  }
  return out;
}

std::string cdr_imu(const evio::ImuSample& s, bool big_endian) {
  CdrWriter w(big_endian);
  w.header(s.t_ns, "imu");
  for (double q : {0.0, 0.0, 0.0, 1.0}) w.f64(q);
  for (int i = 0; i < 9; ++i) w.f64(0.0);
  for (int i = 0; i < 3; ++i) w.f64(s.gyro[i]);
  for (int i = 0; i < 9; ++i) w.f64(0.0);
  for (int i = 0; i < 3; ++i) w.f64(s.accel[i]);
  for (int i = 0; i < 9; ++i) w.f64(0.0);
  return w.data();
}

std::string cdr_image(int64_t stamp_ns, uint32_t width, uint32_t height, const std::string& encoding, uint32_t step,
                      const std::string& data, bool big_endian) {
  CdrWriter w(big_endian);
  w.header(stamp_ns);
  w.u32(height);
  w.u32(width);
  w.string(encoding);
  w.u8(0);
  w.u32(step);
  w.bytes(data);
  return w.data();
}

// ---------------------------------------------------------------------------------------------

namespace {

void check_sqlite(int rc, sqlite3* db, const char* what) {
  if (rc != SQLITE_OK && rc != SQLITE_DONE && rc != SQLITE_ROW) {
    throw std::runtime_error(std::string("rosbag2 writer: ") + what + ": " + sqlite3_errmsg(db));
  }
}

std::string zstd_compress(const std::string& raw) {
  std::string out(ZSTD_compressBound(raw.size()), '\0');
  const size_t n = ZSTD_compress(out.data(), out.size(), raw.data(), raw.size(), 3);
  if (ZSTD_isError(n)) throw std::runtime_error("rosbag2 writer: zstd failed");
  out.resize(n);
  return out;
}

std::string read_all(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
}

}  // namespace

struct Rosbag2Writer::Impl {
  std::string path;
  sqlite3* db = nullptr;
  sqlite3_stmt* insert = nullptr;
  std::unique_ptr<McapWriter> mcap;
  std::vector<int64_t> ids;  // per topic: SQLite topic id / MCAP channel id in this file, -1 before use
};

Rosbag2Writer::Rosbag2Writer(const std::string& folder, Rosbag2WriterOptions options)
    : folder_(folder), o_(std::move(options)) {}

Rosbag2Writer::~Rosbag2Writer() {
  try {
    close();
  } catch (...) {
  }
}

size_t Rosbag2Writer::add_topic(const std::string& name, const std::string& type) {
  topic_names_.push_back(name);
  topic_types_.push_back(type);
  counts_.push_back(0);
  if (impl_) impl_->ids.push_back(-1);
  return topic_names_.size() - 1;
}

void Rosbag2Writer::open_next() {
  impl_ = std::make_unique<Impl>();
  const std::string ext = o_.storage == "mcap" ? ".mcap" : ".db3";
  impl_->path = folder_ + "/bag_" + std::to_string(files_.size()) + ext;
  impl_->ids.assign(topic_names_.size(), -1);
  if (o_.storage == "mcap") {
    McapWriterOptions mo;
    mo.compression = o_.mcap_compression;
    mo.chunk_size = o_.mcap_chunk_size;
    mo.summary = o_.mcap_summary;
    impl_->mcap = std::make_unique<McapWriter>(impl_->path, mo);
  } else {
    sqlite3* db = nullptr;
    check_sqlite(sqlite3_open(impl_->path.c_str(), &db), db, "open");
    impl_->db = db;
    const char* schema =
        "CREATE TABLE schema(schema_version INTEGER PRIMARY KEY, ros_distro TEXT NOT NULL);"
        "INSERT INTO schema VALUES (3, 'evio-test');"
        "CREATE TABLE topics(id INTEGER PRIMARY KEY, name TEXT NOT NULL, type TEXT NOT NULL, "
        "serialization_format TEXT NOT NULL, offered_qos_profiles TEXT NOT NULL);"
        "CREATE TABLE messages(id INTEGER PRIMARY KEY, topic_id INTEGER NOT NULL, timestamp INTEGER NOT NULL, "
        "data BLOB NOT NULL);"
        "CREATE INDEX timestamp_idx ON messages (timestamp ASC);"
        "BEGIN;";
    check_sqlite(sqlite3_exec(db, schema, nullptr, nullptr, nullptr), db, "schema");
    check_sqlite(sqlite3_prepare_v2(db, "INSERT INTO messages (topic_id, timestamp, data) VALUES (?, ?, ?)", -1,
                                    &impl_->insert, nullptr),
                 db, "prepare");
  }
  files_.push_back(impl_->path);
  in_file_ = 0;
}

void Rosbag2Writer::write(size_t topic, int64_t timestamp_ns, const std::string& cdr) {
  if (closed_) throw std::logic_error("rosbag2 writer: write after close");
  if (!impl_ || (o_.split_messages > 0 && in_file_ == o_.split_messages)) {
    close_current();
    open_next();
  }
  const std::string data = o_.compression_mode == "message" ? zstd_compress(cdr) : cdr;
  Impl& im = *impl_;
  if (im.ids[topic] < 0) {
    if (im.mcap) {
      const uint16_t schema = im.mcap->add_schema(topic_types_[topic], "ros2msg", "");
      im.ids[topic] = im.mcap->add_channel(schema, topic_names_[topic], "cdr");
    } else {
      const int64_t id = static_cast<int64_t>(topic) + 1;
      const std::string sql = "INSERT INTO topics VALUES (" + std::to_string(id) + ", '" + topic_names_[topic] +
                              "', '" + topic_types_[topic] + "', 'cdr', '')";
      check_sqlite(sqlite3_exec(im.db, sql.c_str(), nullptr, nullptr, nullptr), im.db, "topic");
      im.ids[topic] = id;
    }
  }
  if (im.mcap) {
    im.mcap->write(static_cast<uint16_t>(im.ids[topic]), static_cast<uint64_t>(timestamp_ns), data,
                   static_cast<uint64_t>(timestamp_ns), static_cast<uint32_t>(counts_[topic]));
  } else {
    sqlite3_reset(im.insert);
    sqlite3_bind_int64(im.insert, 1, im.ids[topic]);
    sqlite3_bind_int64(im.insert, 2, timestamp_ns);
    sqlite3_bind_blob(im.insert, 3, data.data(), static_cast<int>(data.size()), SQLITE_TRANSIENT);
    check_sqlite(sqlite3_step(im.insert), im.db, "insert");
  }
  ++counts_[topic];
  ++in_file_;
  t_min_ = std::min(t_min_, timestamp_ns);
  t_max_ = std::max(t_max_, timestamp_ns);
}

void Rosbag2Writer::close_current() {
  if (!impl_) return;
  if (impl_->mcap) {
    impl_->mcap->close();
  } else {
    sqlite3_finalize(impl_->insert);
    check_sqlite(sqlite3_exec(impl_->db, "COMMIT;", nullptr, nullptr, nullptr), impl_->db, "commit");
    sqlite3_close(impl_->db);
  }
  if (o_.compression_mode == "file") {
    const std::string raw = read_all(impl_->path);
    std::ofstream(impl_->path + ".zstd", std::ios::binary) << zstd_compress(raw);
    std::remove(impl_->path.c_str());
    files_.back() = impl_->path + ".zstd";
  }
  impl_.reset();
}

void Rosbag2Writer::close() {
  if (closed_) return;
  closed_ = true;
  if (!impl_ && files_.empty()) open_next();  // an empty bag still has a storage file
  close_current();
  if (!o_.metadata) return;
  std::ofstream y(folder_ + "/metadata.yaml");
  y << "rosbag2_bagfile_information:\n  version: 8\n  storage_identifier: " << o_.storage
    << "\n  duration:\n    nanoseconds: " << (t_max_ >= t_min_ ? t_max_ - t_min_ : 0)
    << "\n  starting_time:\n    nanoseconds_since_epoch: " << (t_max_ >= t_min_ ? t_min_ : 0)
    << "\n  message_count: ";
  int64_t total = 0;
  for (int64_t c : counts_) total += c;
  y << total << "\n  topics_with_message_count:\n";
  for (size_t i = 0; i < topic_names_.size(); ++i) {
    y << "    - topic_metadata:\n        name: " << topic_names_[i] << "\n        type: " << topic_types_[i]
      << "\n        serialization_format: cdr\n        offered_qos_profiles: ''\n      message_count: " << counts_[i]
      << "\n";
  }
  y << "  compression_format: " << (o_.compression_mode.empty() ? "''" : "zstd")
    << "\n  compression_mode: " << (o_.compression_mode.empty() ? "''" : o_.compression_mode == "file" ? "FILE" : "MESSAGE")
    << "\n  relative_file_paths:\n";
  for (const std::string& f : files_) y << "    - " << f.substr(folder_.size() + 1) << "\n";
}

}  // namespace evio_test
