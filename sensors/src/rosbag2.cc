#include "evio/sensors/rosbag2.h"

#include <sqlite3.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>
#include <zstd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "frame_decompress.h"
#include "mcap_container.h"
#include "ros_messages.h"

namespace evio {
namespace fs = std::filesystem;
namespace {

using detail::DecompressLimit;
using detail::ros::MessageView;
using detail::ros::Topic;

constexpr char kMetadataForm[] =
    "rosbag2 metadata.yaml: rosbag2_bagfile_information with storage_identifier (sqlite3 | mcap), "
    "relative_file_paths, topics_with_message_count, compression_format ('' | zstd), compression_mode "
    "('' | file | message)";
constexpr char kSqliteForm[] =
    "a rosbag2 SQLite3 file: tables topics(id, name, type, serialization_format) and messages(id, topic_id, "
    "timestamp, data)";
constexpr uint64_t kMaxMessageBytes = uint64_t{1} << 30;  // one decompressed message, bytes

// ---------------------------------------------------------------------------------------------
// zstd: whole-file decompression to a temporary file (compression_mode file) and per message.

class TempFile {
 public:
  TempFile() {
    const char* dir = std::getenv("TMPDIR");
    std::string tmpl = std::string(dir != nullptr && *dir != '\0' ? dir : "/tmp") + "/evio_rosbag2_XXXXXX";
    std::vector<char> name(tmpl.begin(), tmpl.end());
    name.push_back('\0');
    fd_ = ::mkstemp(name.data());
    if (fd_ < 0) throw InputError(tmpl, 0, std::string("cannot create a temporary file: ") + std::strerror(errno));
    path_ = name.data();
  }
  ~TempFile() {
    if (fd_ >= 0) ::close(fd_);
    if (!path_.empty()) ::unlink(path_.c_str());
  }
  TempFile(const TempFile&) = delete;
  TempFile& operator=(const TempFile&) = delete;
  const std::string& path() const { return path_; }
  int fd() const { return fd_; }

 private:
  int fd_ = -1;
  std::string path_;
};

std::string zstd_error(size_t rc) { return ZSTD_getErrorName(rc); }

// Streams the zstd file `src` into a temporary file.
std::unique_ptr<TempFile> decompress_file(const std::string& src) {
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> in(std::fopen(src.c_str(), "rb"), &std::fclose);
  if (!in) throw InputError(src, 0, std::string("cannot open: ") + std::strerror(errno), "a zstd-compressed bag file");
  auto out = std::make_unique<TempFile>();
  std::unique_ptr<ZSTD_DCtx, size_t (*)(ZSTD_DCtx*)> ctx(ZSTD_createDCtx(), &ZSTD_freeDCtx);
  std::vector<char> ibuf(ZSTD_DStreamInSize()), obuf(ZSTD_DStreamOutSize());
  uint64_t consumed = 0;
  size_t rc = 0;
  bool any = false;
  for (;;) {
    const size_t n = std::fread(ibuf.data(), 1, ibuf.size(), in.get());
    if (n == 0) break;
    any = true;
    ZSTD_inBuffer ib{ibuf.data(), n, 0};
    while (ib.pos < ib.size) {
      ZSTD_outBuffer ob{obuf.data(), obuf.size(), 0};
      rc = ZSTD_decompressStream(ctx.get(), &ob, &ib);
      if (ZSTD_isError(rc)) {
        throw InputError(src, 0,
                         "zstd data corrupt near byte offset " + std::to_string(consumed + ib.pos) + ": " + zstd_error(rc),
                         "a zstd-compressed bag file (compression_mode file)");
      }
      const char* p = obuf.data();
      size_t left = ob.pos;
      while (left > 0) {
        const ssize_t w = ::write(out->fd(), p, left);
        if (w <= 0) throw InputError(out->path(), 0, std::string("cannot write the decompressed bag: ") + std::strerror(errno));
        p += w;
        left -= static_cast<size_t>(w);
      }
    }
    consumed += n;
  }
  if (!any || rc != 0) {
    throw InputError(src, 0, "zstd stream ends inside a frame at byte offset " + std::to_string(consumed) +
                                 " (truncated file)",
                     "a zstd-compressed bag file (compression_mode file)");
  }
  return out;
}

// zstd-compressed messages (compression_mode message): one frame per message, up to 1 GiB.
const DecompressLimit kMessageLimit{kMaxMessageBytes, "zstd-compressed messages of at most 1 GiB"};
constexpr char kZstdMessageForm[] = "zstd-compressed messages (compression_mode message)";

// ---------------------------------------------------------------------------------------------
// One storage file: its topics (local ids) and a cursor over some of them.

struct LocalTopic {
  int64_t id = 0;  // storage's topic id (SQLite topics.id, MCAP channel id)
  Topic topic;
};

class StorageCursor {
 public:
  virtual ~StorageCursor() = default;
  // Next message: its local topic id and data (valid until the next call).
  virtual bool next(int64_t* local_id, const uint8_t** data, size_t* size) = 0;
  virtual std::string at(uint64_t k) const = 0;
  virtual double progress() const = 0;
};

class Storage {
 public:
  virtual ~Storage() = default;
  virtual const std::vector<LocalTopic>& topics() const = 0;
  // start_ns > INT64_MIN: from the first message at or after it (SQLite3 timestamp, MCAP log time).
  virtual std::unique_ptr<StorageCursor> cursor(const std::vector<int64_t>& ids, int64_t start_ns) const = 0;
  virtual std::string describe() const = 0;
  virtual bool seekable() const = 0;
};

// SQLite3 storage.
class SqliteDb {
 public:
  explicit SqliteDb(const std::string& path) : path_(path) {
    // Read-only and immutable: no lock, no journal, so bags on read-only media open too.
    std::string uri = "file:";
    for (const char c : fs::absolute(path).string()) {
      if (c == '%' || c == '?' || c == '#') {
        static const char* d = "0123456789abcdef";
        uri += '%';
        uri += d[(static_cast<unsigned char>(c) >> 4) & 15];
        uri += d[static_cast<unsigned char>(c) & 15];
      } else {
        uri += c;
      }
    }
    uri += "?immutable=1";
    const int rc = sqlite3_open_v2(uri.c_str(), &db_, SQLITE_OPEN_READONLY | SQLITE_OPEN_URI, nullptr);
    if (rc != SQLITE_OK) {
      const std::string msg = db_ != nullptr ? sqlite3_errmsg(db_) : sqlite3_errstr(rc);
      sqlite3_close(db_);
      db_ = nullptr;
      throw InputError(path, 0, "cannot open as SQLite3: " + msg, kSqliteForm);
    }
  }
  ~SqliteDb() { sqlite3_close(db_); }
  SqliteDb(const SqliteDb&) = delete;
  SqliteDb& operator=(const SqliteDb&) = delete;

  sqlite3* get() const { return db_; }
  const std::string& path() const { return path_; }
  [[noreturn]] void fail(const std::string& what) const {
    throw InputError(path_, 0, what + ": " + sqlite3_errmsg(db_), kSqliteForm);
  }

 private:
  std::string path_;
  sqlite3* db_ = nullptr;
};

class Statement {
 public:
  Statement(const SqliteDb& db, const std::string& sql, const char* what) : db_(db), what_(what) {
    if (sqlite3_prepare_v2(db.get(), sql.c_str(), -1, &st_, nullptr) != SQLITE_OK) {
      db.fail(std::string("cannot query ") + what);
    }
  }
  ~Statement() { sqlite3_finalize(st_); }
  Statement(const Statement&) = delete;
  Statement& operator=(const Statement&) = delete;
  bool step() {
    const int rc = sqlite3_step(st_);
    if (rc == SQLITE_ROW) return true;
    if (rc == SQLITE_DONE) return false;
    db_.fail(std::string("reading ") + what_ + " failed");
  }
  sqlite3_stmt* get() const { return st_; }
  int64_t i64(int col) const { return sqlite3_column_int64(st_, col); }
  std::string text(int col) const {
    const unsigned char* t = sqlite3_column_text(st_, col);
    return t != nullptr ? std::string(reinterpret_cast<const char*>(t)) : std::string();
  }

 private:
  const SqliteDb& db_;
  const char* what_;
  sqlite3_stmt* st_ = nullptr;
};

class SqliteCursor final : public StorageCursor {
 public:
  // Progress is by timestamp over [t_first, t_last], the messages table's range.
  SqliteCursor(const SqliteDb& db, const std::vector<int64_t>& ids, int64_t start_ns, int64_t t_first, int64_t t_last,
               bool zstd_messages)
      : db_(db), t_first_(t_first), t_last_(t_last), zstd_(zstd_messages) {
    std::string in;
    for (int64_t id : ids) in += (in.empty() ? "" : ",") + std::to_string(id);
    const std::string from = start_ns == INT64_MIN ? "" : " AND timestamp >= " + std::to_string(start_ns);
    st_ = std::make_unique<Statement>(db,
                                      "SELECT id, topic_id, timestamp, data FROM messages WHERE topic_id IN (" + in +
                                          ")" + from + " ORDER BY timestamp, id",
                                      "the messages table");
  }
  bool next(int64_t* local_id, const uint8_t** data, size_t* size) override {
    if (!st_->step()) {
      done_ = true;
      return false;
    }
    row_ = st_->i64(0);
    *local_id = st_->i64(1);
    stamp_ = st_->i64(2);
    const void* blob = sqlite3_column_blob(st_->get(), 3);
    const int n = sqlite3_column_bytes(st_->get(), 3);
    *data = static_cast<const uint8_t*>(blob);
    *size = static_cast<size_t>(std::max(n, 0));
    if (zstd_) {
      decoder_.decode(*data, *size, &buf_, kMessageLimit, db_.path(), at_raw(), kZstdMessageForm);
      *data = buf_.data();
      *size = buf_.size();
    }
    return true;
  }
  std::string at(uint64_t k) const override {
    return "byte " + std::to_string(k) + " of the " + (zstd_ ? "decompressed " : "") + at_raw();
  }
  double progress() const override {
    if (done_) return 1.0;
    if (t_last_ <= t_first_ || row_ == 0) return 0.0;
    return std::clamp(static_cast<double>(stamp_ - t_first_) / static_cast<double>(t_last_ - t_first_), 0.0, 1.0);
  }

 private:
  std::string at_raw() const {
    return "data of messages row id " + std::to_string(row_) + " (timestamp " + std::to_string(stamp_) + " ns)";
  }

  const SqliteDb& db_;
  std::unique_ptr<Statement> st_;
  int64_t t_first_ = 0, t_last_ = 0, row_ = 0, stamp_ = 0;
  bool zstd_ = false, done_ = false;
  detail::ZstdFrameDecoder decoder_;  // one context for every message
  std::vector<uint8_t> buf_;
};

class SqliteStorage final : public Storage {
 public:
  // count_topics: count each topic's messages (a pass over the table's rows; metadata.yaml states
  // the counts when there is one).
  SqliteStorage(const std::string& path, bool zstd_messages, bool count_topics) : db_(path), zstd_(zstd_messages) {
    Statement st(db_, "SELECT id, name, type, serialization_format FROM topics ORDER BY id", "the topics table");
    while (st.step()) {
      LocalTopic t;
      t.id = st.i64(0);
      t.topic = Topic{st.text(1), st.text(2), st.text(3), -1};
      topics_.push_back(std::move(t));
    }
    Statement range(db_, "SELECT MIN(timestamp), MAX(timestamp) FROM messages", "the messages table");  // timestamp_idx
    if (range.step()) {
      t_first_ = range.i64(0);
      t_last_ = range.i64(1);
    }
    if (!count_topics) return;
    Statement count(db_, "SELECT topic_id, COUNT(*) FROM messages GROUP BY topic_id", "the messages table");
    while (count.step()) {
      for (LocalTopic& t : topics_) {
        if (t.id == count.i64(0)) t.topic.messages = count.i64(1);
      }
    }
    for (LocalTopic& t : topics_) {
      if (t.topic.messages < 0) t.topic.messages = 0;
    }
  }
  const std::vector<LocalTopic>& topics() const override { return topics_; }
  std::unique_ptr<StorageCursor> cursor(const std::vector<int64_t>& ids, int64_t start_ns) const override {
    return std::make_unique<SqliteCursor>(db_, ids, start_ns, t_first_, t_last_, zstd_);
  }
  std::string describe() const override { return "SQLite3"; }
  bool seekable() const override { return true; }

 private:
  SqliteDb db_;
  bool zstd_;
  int64_t t_first_ = 0, t_last_ = 0;
  std::vector<LocalTopic> topics_;
};

// MCAP storage.
class McapCursor final : public StorageCursor {
 public:
  McapCursor(const detail::mcap::File& file, std::vector<uint16_t> ids, int64_t start_ns, bool zstd_messages)
      : path_(file.path()),
        cursor_(file, std::move(ids), start_ns <= 0 ? 0 : static_cast<uint64_t>(start_ns)),
        zstd_(zstd_messages) {}
  bool next(int64_t* local_id, const uint8_t** data, size_t* size) override {
    if (!cursor_.next(&m_)) return false;
    *local_id = m_.channel->id;
    *data = m_.data;
    *size = m_.size;
    if (zstd_) {
      decoder_.decode(m_.data, m_.size, &buf_, kMessageLimit, path_, "the data of the message at " + m_.at(0),
                   kZstdMessageForm);
      *data = buf_.data();
      *size = buf_.size();
    }
    return true;
  }
  std::string at(uint64_t k) const override {
    if (zstd_) return "byte " + std::to_string(k) + " of the decompressed data of the message at " + m_.at(0);
    return m_.at(static_cast<size_t>(k));
  }
  double progress() const override { return cursor_.progress(); }

 private:
  const std::string& path_;
  detail::mcap::MessageCursor cursor_;
  detail::mcap::Message m_;
  bool zstd_;
  detail::ZstdFrameDecoder decoder_;  // one context for every message
  std::vector<uint8_t> buf_;
};

class McapStorage final : public Storage {
 public:
  McapStorage(const std::string& path, bool zstd_messages) : file_(path), zstd_(zstd_messages) {
    for (const detail::mcap::Channel& c : file_.channels()) {
      LocalTopic t;
      t.id = c.id;
      t.topic = Topic{c.topic, c.schema_name, c.message_encoding, c.messages};
      topics_.push_back(std::move(t));
    }
  }
  const std::vector<LocalTopic>& topics() const override { return topics_; }
  std::unique_ptr<StorageCursor> cursor(const std::vector<int64_t>& ids, int64_t start_ns) const override {
    std::vector<uint16_t> channels;
    for (int64_t id : ids) channels.push_back(static_cast<uint16_t>(id));
    return std::make_unique<McapCursor>(file_, std::move(channels), start_ns, zstd_);
  }
  bool seekable() const override { return file_.has_summary(); }
  std::string describe() const override {
    return "MCAP (profile '" + file_.profile() + "', " + std::to_string(file_.chunks().size()) + " chunk(s)" +
           (file_.has_summary() ? "" : ", no summary") + ")";
  }

 private:
  detail::mcap::File file_;
  bool zstd_;
  std::vector<LocalTopic> topics_;
};

// ---------------------------------------------------------------------------------------------
// The bag: metadata.yaml (when there is one) and its storage files in order.

struct BagPlan {
  std::string path;                // as given
  std::string storage;             // "sqlite3" or "mcap"
  std::vector<std::string> files;  // storage files in order
  std::string compression_mode;    // "", "file" or "message" (lower case)
  std::vector<Topic> topics;       // from metadata.yaml (counts over all files); empty without it
  bool has_metadata = false;
};

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

std::string storage_of_file(const std::string& file) {
  const std::string ext = fs::path(file).extension().string();
  char head[16] = {};
  if (std::FILE* f = std::fopen(file.c_str(), "rb")) {
    const size_t n = std::fread(head, 1, sizeof(head), f);
    std::fclose(f);
    const std::string h(head, n);
    if (h.rfind(std::string("SQLite format 3\0", 16), 0) == 0) return "sqlite3";
    if (h.rfind("\x89MCAP0\r\n", 0) == 0) return "mcap";
  }
  if (ext == ".db3") return "sqlite3";
  if (ext == ".mcap") return "mcap";
  return "";
}

void read_metadata(const std::string& yaml_path, BagPlan* plan) {
  YAML::Node root;
  try {
    root = YAML::LoadFile(yaml_path);
  } catch (const YAML::Exception& e) {
    throw InputError(yaml_path, e.mark.line >= 0 ? e.mark.line + 1 : 0, std::string("not valid YAML: ") + e.msg,
                     kMetadataForm);
  }
  const YAML::Node info = root["rosbag2_bagfile_information"];
  if (!info || !info.IsMap()) throw InputError(yaml_path, 0, "no rosbag2_bagfile_information map", kMetadataForm);
  auto line_of = [](const YAML::Node& n) { return n.Mark().line >= 0 ? n.Mark().line + 1 : 0; };
  try {
    plan->storage = info["storage_identifier"] ? lower(info["storage_identifier"].as<std::string>()) : "";
    if (info["relative_file_paths"]) {
      for (const YAML::Node& f : info["relative_file_paths"]) plan->files.push_back(f.as<std::string>());
    }
    const std::string format = info["compression_format"] ? lower(info["compression_format"].as<std::string>()) : "";
    plan->compression_mode = info["compression_mode"] ? lower(info["compression_mode"].as<std::string>()) : "";
    if (plan->compression_mode == "none") plan->compression_mode.clear();
    if (!plan->compression_mode.empty() && format != "zstd") {
      throw InputError(yaml_path, line_of(info["compression_format"]),
                       "compression_format '" + format + "' is not supported", "zstd (or none)");
    }
    if (plan->compression_mode != "" && plan->compression_mode != "file" && plan->compression_mode != "message") {
      throw InputError(yaml_path, line_of(info["compression_mode"]),
                       "compression_mode '" + plan->compression_mode + "' is not supported", "file or message");
    }
    if (info["topics_with_message_count"]) {
      for (const YAML::Node& t : info["topics_with_message_count"]) {
        const YAML::Node md = t["topic_metadata"];
        if (!md) throw InputError(yaml_path, line_of(t), "topics_with_message_count entry without topic_metadata", kMetadataForm);
        Topic topic;
        topic.name = md["name"].as<std::string>();
        topic.type = md["type"].as<std::string>();
        topic.encoding = md["serialization_format"] ? md["serialization_format"].as<std::string>() : "cdr";
        topic.messages = t["message_count"] ? t["message_count"].as<int64_t>() : -1;
        plan->topics.push_back(std::move(topic));
      }
    }
  } catch (const YAML::Exception& e) {
    throw InputError(yaml_path, e.mark.line >= 0 ? e.mark.line + 1 : 0, std::string("unexpected value: ") + e.msg,
                     kMetadataForm);
  }
  plan->has_metadata = true;
}

BagPlan plan_bag(const std::string& path) {
  BagPlan plan;
  plan.path = path;
  std::error_code ec;
  fs::path folder;
  if (fs::is_directory(path, ec)) {
    folder = path;
  } else if (fs::path(path).filename() == "metadata.yaml") {
    folder = fs::path(path).parent_path();
  } else {
    // One storage file.
    plan.storage = storage_of_file(path);
    if (plan.storage.empty()) {
      throw InputError(path, 0, "neither an SQLite3 nor an MCAP file", "a rosbag2 .db3 or .mcap file, or a bag folder");
    }
    plan.files.push_back(path);
    return plan;
  }
  const fs::path yaml = folder / "metadata.yaml";
  if (fs::is_regular_file(yaml, ec)) {
    read_metadata(yaml.string(), &plan);
    for (std::string& f : plan.files) f = (folder / f).string();
    if (plan.files.empty()) throw InputError(yaml.string(), 0, "relative_file_paths lists no file", kMetadataForm);
  } else {
    for (const auto& e : fs::directory_iterator(folder, ec)) {
      const std::string ext = e.path().extension().string();
      if (ext == ".db3" || ext == ".mcap") plan.files.push_back(e.path().string());
    }
    std::sort(plan.files.begin(), plan.files.end());
    if (plan.files.empty()) {
      throw InputError(folder.string(), 0, "no metadata.yaml and no .db3 or .mcap file", "a rosbag2 bag folder");
    }
  }
  for (const std::string& f : plan.files) {
    if (!fs::is_regular_file(f, ec)) {
      throw InputError(f, 0, "storage file listed by the bag is missing", "the files of relative_file_paths");
    }
    if (plan.compression_mode == "file") continue;
    const std::string s = storage_of_file(f);
    if (s.empty()) throw InputError(f, 0, "neither an SQLite3 nor an MCAP file", "rosbag2 storage files");
    if (!plan.storage.empty() && s != plan.storage) {
      throw InputError(f, 0, "storage file is " + s + " but the bag's storage_identifier is " + plan.storage,
                       "storage files of the bag's storage_identifier");
    }
    plan.storage = s;
  }
  if (plan.storage != "sqlite3" && plan.storage != "mcap") {
    throw InputError(yaml.string(), 0, "storage_identifier '" + plan.storage + "' is not supported", "sqlite3 or mcap");
  }
  return plan;
}

// The bag as a message source over its files: topics matched by (name, type) across files.
class Rosbag2Source;

class Rosbag2Cursor final : public detail::ros::MessageCursor {
 public:
  Rosbag2Cursor(const Rosbag2Source& src, std::vector<size_t> topics, int64_t start_ns)
      : src_(src), topics_(std::move(topics)), start_ns_(start_ns) {}
  bool next(MessageView* m) override;
  std::string at(uint64_t k) const override;
  double progress() const override {
    if (done_) return 1.0;
    const double files = static_cast<double>(file_count());
    const double in_file = cursor_ ? cursor_->progress() : 0.0;
    return files > 0 ? std::min(1.0, (static_cast<double>(file_) - (cursor_ ? 1.0 : 0.0) + in_file) / files) : 1.0;
  }

 private:
  size_t file_count() const;

  const Rosbag2Source& src_;
  std::vector<size_t> topics_;
  int64_t start_ns_;
  size_t file_ = 0;  // next file to open
  std::unique_ptr<StorageCursor> cursor_;
  const std::vector<size_t>* local_to_global_ = nullptr;
  std::vector<int64_t> local_ids_;
  bool done_ = false;
};

class Rosbag2Source final : public detail::ros::MessageSource {
 public:
  explicit Rosbag2Source(BagPlan plan) : plan_(std::move(plan)) {
    topics_ = plan_.topics;
    for (const std::string& f : plan_.files) open_file(f);
  }

  const std::string& path() const override { return plan_.path; }
  const std::vector<Topic>& topics() const override { return topics_; }
  std::unique_ptr<detail::ros::MessageCursor> cursor(const std::vector<size_t>& topics, int64_t start_ns) const override {
    return std::make_unique<Rosbag2Cursor>(*this, topics, start_ns);
  }
  bool seekable() const override {
    for (const OpenFile& f : files_) {
      if (!f.storage->seekable()) return false;
    }
    return true;
  }
  DatasetFormat format() const override { return DatasetFormat::kRosbag2; }
  std::string describe() const override {
    std::string s = "ROS 2 bag: " + std::to_string(files_.size()) + (files_.size() == 1 ? " file, " : " files, first ") +
                    files_[0].storage->describe() + "; " + std::to_string(topics_.size()) + " topic(s)";
    if (!plan_.has_metadata) s += ", no metadata.yaml";
    if (!plan_.compression_mode.empty()) s += ", zstd compression per " + plan_.compression_mode;
    return s;
  }
  std::string container_name() const override {
    return std::string("rosbag2 ") + (plan_.storage == "mcap" ? "MCAP" : "SQLite3");
  }

  struct OpenFile {
    std::string path;
    std::unique_ptr<TempFile> decompressed;
    std::unique_ptr<Storage> storage;
    std::vector<size_t> local_to_global;  // by position in storage->topics()
  };
  const std::vector<OpenFile>& files() const { return files_; }

 private:
  void open_file(const std::string& f) {
    OpenFile of;
    of.path = f;
    std::string storage_path = f;
    if (plan_.compression_mode == "file") {
      of.decompressed = decompress_file(f);
      storage_path = of.decompressed->path();
      log_info(f + ": zstd-compressed bag file decompressed to " + storage_path);
    }
    const bool per_message = plan_.compression_mode == "message";
    if (plan_.storage == "sqlite3") {
      of.storage = std::make_unique<SqliteStorage>(storage_path, per_message, !plan_.has_metadata);
    } else {
      of.storage = std::make_unique<McapStorage>(storage_path, per_message);
    }
    for (const LocalTopic& lt : of.storage->topics()) {
      auto it = std::find_if(topics_.begin(), topics_.end(), [&](const Topic& t) {
        return t.name == lt.topic.name && detail::ros::canonical_type(t.type) ==
                                              detail::ros::canonical_type(lt.topic.type);
      });
      if (it == topics_.end()) {
        topics_.push_back(lt.topic);
        it = topics_.end() - 1;
      } else if (!plan_.has_metadata) {
        it->messages = it->messages < 0 || lt.topic.messages < 0 ? -1 : it->messages + lt.topic.messages;
      } else if (it->messages < 0) {
        it->messages = lt.topic.messages;
      }
      if (lt.topic.encoding != it->encoding) it->encoding = lt.topic.encoding;  // the storage states it per message
      of.local_to_global.push_back(static_cast<size_t>(it - topics_.begin()));
    }
    files_.push_back(std::move(of));
  }

  BagPlan plan_;
  std::vector<Topic> topics_;
  std::vector<OpenFile> files_;
};

size_t Rosbag2Cursor::file_count() const { return src_.files().size(); }

bool Rosbag2Cursor::next(MessageView* m) {
  for (;;) {
    if (cursor_) {
      int64_t local = 0;
      const uint8_t* data = nullptr;
      size_t size = 0;
      if (cursor_->next(&local, &data, &size)) {
        const auto& file = src_.files()[file_ - 1];
        const auto& locals = file.storage->topics();
        size_t k = 0;
        while (k < locals.size() && locals[k].id != local) ++k;
        if (k == locals.size()) {
          throw InputError(file.path, 0, "message on topic id " + std::to_string(local) + " not listed by the file",
                           "messages of the topics in the file's topics table or Channel records");
        }
        m->topic = (*local_to_global_)[k];
        m->data = data;
        m->size = size;
        return true;
      }
      cursor_.reset();
    }
    if (file_ == src_.files().size()) {
      done_ = true;
      return false;
    }
    const auto& file = src_.files()[file_++];
    local_ids_.clear();
    const auto& locals = file.storage->topics();
    for (size_t k = 0; k < locals.size(); ++k) {
      if (std::find(topics_.begin(), topics_.end(), file.local_to_global[k]) != topics_.end()) {
        local_ids_.push_back(locals[k].id);
      }
    }
    if (local_ids_.empty()) continue;
    local_to_global_ = &file.local_to_global;
    cursor_ = file.storage->cursor(local_ids_, start_ns_);
  }
}

std::string Rosbag2Cursor::at(uint64_t k) const {
  if (!cursor_ || file_ == 0) return "the end of the bag";
  const auto& file = src_.files()[file_ - 1];
  std::string s = cursor_->at(k) + " in " + file.path;
  if (file.decompressed) s += " (decompressed)";
  return s;
}

}  // namespace

bool is_rosbag2_folder(const std::string& path) {
  std::error_code ec;
  if (!fs::is_directory(path, ec)) return false;
  if (fs::is_regular_file(fs::path(path) / "metadata.yaml", ec)) return true;
  for (const auto& e : fs::directory_iterator(path, ec)) {
    const std::string ext = e.path().extension().string();
    if (ext == ".db3" || ext == ".mcap") return true;
  }
  return false;
}

std::unique_ptr<DatasetReader> open_rosbag2_dataset(const std::string& path, const DatasetOptions& options) {
  std::string why;
  if (!options.Validate(&why)) throw InputError(path, 0, "invalid dataset options: " + why);
  return detail::ros::open_ros_dataset(std::make_unique<Rosbag2Source>(plan_bag(path)), options);
}

}  // namespace evio
