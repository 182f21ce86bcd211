// ROS bag 2.0 container for the bag reader (rosbag.cc): records and their headers, chunks
// (bz2 / lz4 decompression), connections, the index (or a linear scan without one) and message
// iteration over chunks. Message decoding stays in rosbag.cc. Internal to evio::sensors.
#pragma once

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <algorithm>
#include <bzlib.h>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <lz4frame.h>
#include <string_view>
#include <unordered_map>
#include <utility>
#include <vector>
#include "byte_order.h"
#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio/sensors/evt.h"
#include "binary_file.h"
#include "text_common.h"

namespace evio::detail::rosbag {
using detail::load_le;


constexpr char kMagic[] = "#ROSBAG V2.0\n";
constexpr size_t kMagicSize = sizeof(kMagic) - 1;  // 13
constexpr char kBagForm[] =
    "ROS bag 2.0: \"#ROSBAG V2.0\\n\", then records <uint32 header_len><header: uint32 field_len + "
    "\"name=value\" fields><uint32 data_len><data>";

constexpr uint8_t kOpMessage = 0x02;
constexpr uint8_t kOpBagHeader = 0x03;
constexpr uint8_t kOpIndexData = 0x04;
constexpr uint8_t kOpChunk = 0x05;
constexpr uint8_t kOpChunkInfo = 0x06;
constexpr uint8_t kOpConnection = 0x07;

constexpr uint32_t kMaxHeaderBytes = uint32_t{1} << 20;      // one record header, bytes
constexpr uint32_t kMaxConnectionBytes = uint32_t{16} << 20;  // one connection record's data, bytes
constexpr uint64_t kMaxChunkBytes = uint64_t{1} << 30;       // one chunk, compressed or not, bytes


inline int64_t ros_time_ns(uint32_t sec, uint32_t nsec) {
  return static_cast<int64_t>(sec) * 1000000000 + static_cast<int64_t>(nsec);
}

inline std::string hex_op(uint8_t op) {
  static const char* d = "0123456789abcdef";
  return std::string("0x") + d[op >> 4] + d[op & 15];
}


// Where a buffer lies in the file, for messages: the data of an uncompressed chunk (or the file)
// maps to file offsets; a compressed chunk's data is named by its offset in the decompressed chunk.
struct Where {
  uint64_t base = 0;        // file offset of buffer byte 0 (uncompressed)
  bool compressed = false;  // then offsets are into the decompressed chunk
  std::string compression;
  uint64_t chunk_pos = 0;  // file offset of the chunk record

  std::string at(uint64_t off) const {
    if (!compressed) return "byte offset " + std::to_string(base + off);
    return "byte offset " + std::to_string(off) + " of the decompressed " + compression + " chunk at byte offset " +
           std::to_string(chunk_pos);
  }
};

// ---------------------------------------------------------------------------------------------
// Record headers: uint32 field_len, "name=value" (field_len bytes), repeated.

struct Field {
  std::string_view name, value;
};

class Header {
 public:
  // Parses `size` bytes at p, which start at offset `off` of the buffer described by `where`.
  void parse(const std::string& path, const uint8_t* p, size_t size, const Where& where, uint64_t off) {
    path_ = &path;
    where_ = &where;
    off_ = off;
    fields_.clear();
    size_t i = 0;
    while (i < size) {
      if (size - i < 4) {
        throw InputError(path, 0,
                         "record header ends inside a field length (" + std::to_string(size - i) +
                             " bytes left) at " + where.at(off + i),
                         kBagForm);
      }
      const uint32_t len = load_le<uint32_t>(p + i);
      if (len > size - i - 4) {
        throw InputError(path, 0,
                         "header field of " + std::to_string(len) + " bytes runs past the end of the " +
                             std::to_string(size) + "-byte record header at " + where.at(off + i),
                         kBagForm);
      }
      const char* f = reinterpret_cast<const char*>(p + i + 4);
      const void* eq = std::memchr(f, '=', len);
      if (eq == nullptr) {
        throw InputError(path, 0,
                         "header field without '=' (\"" + printable(std::string_view(f, len)) + "\") at " +
                             where.at(off + i),
                         "header fields \"name=value\" preceded by their uint32 length");
      }
      const size_t name_len = static_cast<size_t>(static_cast<const char*>(eq) - f);
      fields_.push_back(Field{std::string_view(f, name_len), std::string_view(f + name_len + 1, len - name_len - 1)});
      i += 4 + size_t{len};
    }
  }

  const std::string_view* find(std::string_view name) const {
    for (const Field& f : fields_) {
      if (f.name == name) return &f.value;
    }
    return nullptr;
  }
  std::string_view bytes(const char* name, size_t size) const {
    const std::string_view* v = find(name);
    if (v == nullptr) fail(std::string("required field '") + name + "' is missing");
    if (size != 0 && v->size() != size) {
      fail(std::string("field '") + name + "' has " + std::to_string(v->size()) + " bytes, expected " +
           std::to_string(size));
    }
    return *v;
  }
  uint8_t op() const { return static_cast<uint8_t>(bytes("op", 1)[0]); }
  uint32_t u32(const char* name) const { return load_le<uint32_t>(reinterpret_cast<const uint8_t*>(bytes(name, 4).data())); }
  uint64_t u64(const char* name) const { return load_le<uint64_t>(reinterpret_cast<const uint8_t*>(bytes(name, 8).data())); }
  // Packed ROS time (low 32 bits sec, high 32 bits nsec) -> ns.
  int64_t time_ns(const char* name) const {
    const uint64_t v = u64(name);
    return ros_time_ns(static_cast<uint32_t>(v), static_cast<uint32_t>(v >> 32));
  }
  std::string str(const char* name) const { return std::string(bytes(name, 0)); }

  [[noreturn]] void fail(const std::string& problem) const {
    throw InputError(*path_, 0, problem + " in the record header at " + where_->at(off_), kBagForm);
  }

 private:
  const std::string* path_ = nullptr;
  const Where* where_ = nullptr;
  uint64_t off_ = 0;
  std::vector<Field> fields_;
};

// ---------------------------------------------------------------------------------------------
// The file: positioned reads with explicit bounds.

using BagFile = detail::BinaryFile;

// A record read from the file: header parsed, data located (and checked to lie inside the file).
struct FileRecord {
  uint64_t pos = 0;
  std::string header_bytes;
  Header header;
  uint8_t op = 0;
  uint64_t data_pos = 0;
  uint32_t data_len = 0;
  uint64_t end() const { return data_pos + data_len; }
};

const Where kFileWhere{};

inline void read_record(const BagFile& file, uint64_t pos, FileRecord* r) {
  const std::string& path = file.path();
  r->pos = pos;
  if (pos >= file.size() || file.size() - pos < 8) {
    throw InputError(path, 0,
                     "truncated record at byte offset " + std::to_string(pos) + ": " +
                         std::to_string(pos < file.size() ? file.size() - pos : 0) +
                         " bytes left, a record needs at least 8 (header length and data length)",
                     kBagForm);
  }
  uint8_t len4[4];
  file.read(pos, len4, 4, "record header length");
  const uint32_t header_len = load_le<uint32_t>(len4);
  if (header_len > kMaxHeaderBytes) {
    throw InputError(path, 0,
                     "record header length " + std::to_string(header_len) + " at byte offset " + std::to_string(pos) +
                         " exceeds the 1 MiB limit for a record header",
                     kBagForm);
  }
  if (uint64_t{header_len} + 8 > file.size() - pos) {
    throw InputError(path, 0,
                     "truncated record at byte offset " + std::to_string(pos) + ": header of " +
                         std::to_string(header_len) + " bytes runs past the end of the file (" +
                         std::to_string(file.size()) + " bytes)",
                     kBagForm);
  }
  r->header_bytes.resize(header_len);
  file.read(pos + 4, r->header_bytes.data(), header_len, "record header");
  file.read(pos + 4 + header_len, len4, 4, "record data length");
  r->data_len = load_le<uint32_t>(len4);
  r->data_pos = pos + 8 + header_len;
  r->header.parse(path, reinterpret_cast<const uint8_t*>(r->header_bytes.data()), header_len, kFileWhere, pos + 4);
  r->op = r->header.op();
  if (r->data_len > file.size() - r->data_pos) {
    throw InputError(path, 0,
                     "truncated record (op=" + hex_op(r->op) + ") at byte offset " + std::to_string(pos) + ": data of " +
                         std::to_string(r->data_len) + " bytes at byte offset " + std::to_string(r->data_pos) +
                         " runs past the end of the file (" + std::to_string(file.size()) + " bytes)",
                     kBagForm);
  }
}

// A record inside a decompressed chunk.
struct MemRecord {
  uint64_t pos = 0;
  Header header;
  uint8_t op = 0;
  const uint8_t* data = nullptr;
  uint64_t data_off = 0;
  uint32_t data_len = 0;
  uint64_t next = 0;
};

void parse_mem_record(const std::string& path, const uint8_t* buf, size_t size, size_t pos, const Where& where,
                      MemRecord* r) {
  r->pos = pos;
  const size_t left = size - pos;
  if (left < 8) {
    throw InputError(path, 0,
                     "truncated record at " + where.at(pos) + ": " + std::to_string(left) +
                         " bytes left in the chunk, a record needs at least 8",
                     kBagForm);
  }
  const uint32_t header_len = load_le<uint32_t>(buf + pos);
  if (header_len > left - 8) {
    throw InputError(path, 0,
                     "truncated record at " + where.at(pos) + ": header of " + std::to_string(header_len) +
                         " bytes runs past the end of the chunk (" + std::to_string(left) + " bytes left)",
                     kBagForm);
  }
  r->header.parse(path, buf + pos + 4, header_len, where, pos + 4);
  r->op = r->header.op();
  r->data_off = pos + 8 + header_len;
  r->data_len = load_le<uint32_t>(buf + pos + 4 + header_len);
  if (r->data_len > size - r->data_off) {
    throw InputError(path, 0,
                     "truncated record (op=" + hex_op(r->op) + ") at " + where.at(pos) + ": data of " +
                         std::to_string(r->data_len) + " bytes runs past the end of the chunk (" +
                         std::to_string(size - r->data_off) + " bytes left)",
                     kBagForm);
  }
  r->data = buf + r->data_off;
  r->next = r->data_off + r->data_len;
}

// ---------------------------------------------------------------------------------------------
// Chunks: read and decompress one at a time into a reused buffer.

class ChunkLoader {
 public:
  explicit ChunkLoader(const BagFile& file) : file_(file) {}

  // Loads the chunk record at pos. Throws InputError on a bad record or bad compressed data.
  void load(uint64_t pos) {
    const std::string& path = file_.path();
    read_record(file_, pos, &rec_);
    if (rec_.op != kOpChunk) {
      throw InputError(path, 0,
                       "expected a chunk record (op=0x05) at byte offset " + std::to_string(pos) + ", found op=" +
                           hex_op(rec_.op),
                       kBagForm);
    }
    const std::string compression = rec_.header.str("compression");
    const uint32_t size = rec_.header.u32("size");
    if (size > kMaxChunkBytes || rec_.data_len > kMaxChunkBytes) {
      throw InputError(path, 0,
                       "chunk at byte offset " + std::to_string(pos) + " of " +
                           std::to_string(std::max<uint64_t>(size, rec_.data_len)) + " bytes exceeds the 1 GiB limit",
                       kBagForm);
    }
    where_ = Where{};
    where_.chunk_pos = pos;
    where_.compression = compression;
    if (compression == "none") {
      if (rec_.data_len != size) {
        throw InputError(path, 0,
                         "uncompressed chunk at byte offset " + std::to_string(pos) + " holds " +
                             std::to_string(rec_.data_len) + " bytes but its header says size=" + std::to_string(size),
                         "an uncompressed chunk whose data length equals its size field");
      }
      buf_.resize(size);
      file_.read(rec_.data_pos, buf_.data(), size, "chunk data");
      size_ = size;
      where_.base = rec_.data_pos;
      return;
    }
    where_.compressed = true;
    comp_.resize(rec_.data_len);
    file_.read(rec_.data_pos, comp_.data(), rec_.data_len, "chunk data");
    if (compression == "bz2") {
      decompress_bz2(size);
    } else if (compression == "lz4") {
      decompress_lz4(size);
    } else {
      throw InputError(path, 0,
                       "unsupported chunk compression '" + printable(compression) + "' at byte offset " +
                           std::to_string(pos),
                       "compression none, bz2 or lz4");
    }
  }

  const uint8_t* data() const { return buf_.data(); }
  size_t size() const { return size_; }
  const Where& where() const { return where_; }
  uint64_t record_pos() const { return rec_.pos; }
  uint64_t record_end() const { return rec_.end(); }

 private:
  [[noreturn]] void bad_data(const std::string& what, const std::string& detail) const {
    throw InputError(file_.path(), 0,
                     "corrupted " + what + " data in the chunk at byte offset " + std::to_string(rec_.pos) + " (" + detail +
                         ")",
                     std::string("a valid ") + what + " stream that decompresses to the chunk's size field");
  }

  static std::string bz2_error_name(int rc) {
    switch (rc) {
      case BZ_DATA_ERROR: return "libbz2 BZ_DATA_ERROR (checksum mismatch)";
      case BZ_DATA_ERROR_MAGIC: return "libbz2 BZ_DATA_ERROR_MAGIC (no bz2 stream header)";
      case BZ_MEM_ERROR: return "libbz2 BZ_MEM_ERROR";
      case BZ_PARAM_ERROR: return "libbz2 BZ_PARAM_ERROR";
      default: return "libbz2 error " + std::to_string(rc);
    }
  }

  // Grows the output as data is actually produced (a bogus size field costs no memory up front).
  size_t grow(size_t used, uint32_t size) {
    const size_t want = std::min<size_t>(size, std::max<size_t>(used * 2, size_t{1} << 16));
    if (buf_.size() < want) buf_.resize(want);
    return std::min<size_t>(buf_.size(), size);
  }

  void decompress_bz2(uint32_t size) {
    bz_stream s;
    std::memset(&s, 0, sizeof(s));
    if (BZ2_bzDecompressInit(&s, 0, 0) != BZ_OK) bad_data("bz2", "libbz2 initialisation failed");
    s.next_in = reinterpret_cast<char*>(comp_.data());
    s.avail_in = static_cast<unsigned>(comp_.size());
    size_t used = 0;
    int rc = BZ_OK;
    for (;;) {
      const size_t cap = grow(used, size);
      s.next_out = reinterpret_cast<char*>(buf_.data() + used);
      s.avail_out = static_cast<unsigned>(cap - used);
      const unsigned before = s.avail_out;
      rc = BZ2_bzDecompress(&s);
      used += before - s.avail_out;
      if (rc == BZ_STREAM_END) break;
      if (rc != BZ_OK) {
        BZ2_bzDecompressEnd(&s);
        bad_data("bz2", bz2_error_name(rc) + " after " + std::to_string(used) + " output bytes");
      }
      if (used == size && s.avail_out == 0) {
        // Output is full: the stream must end here.
        char extra;
        s.next_out = &extra;
        s.avail_out = 1;
        rc = BZ2_bzDecompress(&s);
        if (rc == BZ_STREAM_END && s.avail_out == 1) break;
        BZ2_bzDecompressEnd(&s);
        bad_data("bz2", "decompresses to more than size=" + std::to_string(size) + " bytes");
      }
      if (s.avail_in == 0 && before == s.avail_out) {
        BZ2_bzDecompressEnd(&s);
        bad_data("bz2", "stream ends early after " + std::to_string(used) + " of " + std::to_string(size) + " bytes");
      }
    }
    BZ2_bzDecompressEnd(&s);
    if (used != size) {
      bad_data("bz2", "decompressed to " + std::to_string(used) + " bytes, the chunk header says size=" +
                          std::to_string(size));
    }
    size_ = used;
  }

  void decompress_lz4(uint32_t size) {
    LZ4F_dctx* ctx = nullptr;
    if (LZ4F_isError(LZ4F_createDecompressionContext(&ctx, LZ4F_VERSION))) bad_data("lz4", "context creation failed");
    struct Free {
      LZ4F_dctx* c;
      ~Free() { LZ4F_freeDecompressionContext(c); }
    } guard{ctx};
    size_t in = 0, used = 0;
    for (;;) {
      const size_t cap = grow(used, size);
      size_t out_n = cap - used;
      size_t in_n = comp_.size() - in;
      char extra;
      // At a full output buffer, offer one spare byte so overlong data is detected.
      void* dst = out_n > 0 ? static_cast<void*>(buf_.data() + used) : static_cast<void*>(&extra);
      if (out_n == 0) out_n = 1;
      const size_t hint = LZ4F_decompress(ctx, dst, &out_n, comp_.data() + in, &in_n, nullptr);
      if (LZ4F_isError(hint)) bad_data("lz4", std::string("liblz4: ") + LZ4F_getErrorName(hint));
      if (dst == &extra && out_n > 0) bad_data("lz4", "decompresses to more than size=" + std::to_string(size) + " bytes");
      in += in_n;
      used += dst == &extra ? 0 : out_n;
      if (hint == 0) break;  // frame complete (content checksum verified)
      if (in == comp_.size() && out_n == 0 && in_n == 0) {
        bad_data("lz4", "frame ends early after " + std::to_string(used) + " of " + std::to_string(size) + " bytes");
      }
    }
    if (in != comp_.size()) {
      bad_data("lz4", std::to_string(comp_.size() - in) + " bytes after the end of the lz4 frame");
    }
    if (used != size) {
      bad_data("lz4", "decompressed to " + std::to_string(used) + " bytes, the chunk header says size=" +
                          std::to_string(size));
    }
    size_ = used;
  }

  const BagFile& file_;
  FileRecord rec_;
  std::vector<uint8_t> buf_, comp_;
  size_t size_ = 0;
  Where where_;
};

// ---------------------------------------------------------------------------------------------
// Index: connections and chunks.

struct Connection {
  uint32_t id = 0;
  std::string topic, type, md5sum;
  int64_t messages = 0;
};

struct ChunkInfo {
  uint64_t pos = 0;
  std::vector<std::pair<uint32_t, uint32_t>> counts;  // connection id, messages in this chunk
};

struct Bag {
  explicit Bag(const std::string& p) : path(p), file(p, kBagForm) {}

  std::string path;
  BagFile file;
  bool indexed = false;
  std::vector<Connection> connections;
  std::unordered_map<uint32_t, size_t> by_id;
  std::vector<ChunkInfo> chunks;  // file order

  const Connection* find(uint32_t id) const {
    const auto it = by_id.find(id);
    return it == by_id.end() ? nullptr : &connections[it->second];
  }
};

// A connection record: header conn, topic; data = connection header fields (type, md5sum, ...).
void add_connection(Bag* bag, const Header& h, const uint8_t* data, size_t size, const Where& where,
                    uint64_t data_off) {
  Connection c;
  c.id = h.u32("conn");
  c.topic = h.str("topic");
  Header fields;
  fields.parse(bag->path, data, size, where, data_off);
  const std::string_view* type = fields.find("type");
  if (type == nullptr) {
    throw InputError(bag->path, 0, "connection record for topic '" + printable(c.topic) + "' without a 'type' field at " + where.at(data_off),
                     "connection data with type=, md5sum= and message_definition= fields");
  }
  c.type = std::string(*type);
  if (const std::string_view* md5 = fields.find("md5sum")) c.md5sum = std::string(*md5);
  if (bag->by_id.count(c.id) != 0) return;  // repeated in every chunk that uses it
  bag->by_id.emplace(c.id, bag->connections.size());
  bag->connections.push_back(std::move(c));
}

// A connection record found in the file (index or linear scan): its data read (at most 16 MiB)
// and the connection added.
inline void read_connection(Bag* bag, const FileRecord& r, std::vector<uint8_t>* data) {
  if (r.data_len > kMaxConnectionBytes) {
    throw InputError(bag->path, 0,
                     "connection record data of " + std::to_string(r.data_len) + " bytes at byte offset " +
                         std::to_string(r.data_pos) + " exceeds the 16 MiB limit",
                     kBagForm);
  }
  data->resize(r.data_len);
  bag->file.read(r.data_pos, data->data(), r.data_len, "connection data");
  add_connection(bag, r.header, data->data(), data->size(), kFileWhere, r.data_pos);
}

inline void read_index(Bag* bag, uint64_t index_pos, uint32_t conn_count, uint32_t chunk_count, uint64_t chunks_begin) {
  const BagFile& file = bag->file;
  FileRecord r;
  std::vector<uint8_t> data;
  uint64_t pos = index_pos;
  for (uint32_t i = 0; i < conn_count; ++i) {
    read_record(file, pos, &r);
    if (r.op != kOpConnection) {
      throw InputError(bag->path, 0,
                       "expected connection record " + std::to_string(i + 1) + " of " + std::to_string(conn_count) +
                           " (op=0x07) at byte offset " + std::to_string(pos) + ", found op=" + hex_op(r.op),
                       "the index at index_pos: conn_count connection records, then chunk_count chunk info records");
    }
    read_connection(bag, r, &data);
    pos = r.end();
  }
  for (uint32_t i = 0; i < chunk_count; ++i) {
    read_record(file, pos, &r);
    if (r.op != kOpChunkInfo) {
      throw InputError(bag->path, 0,
                       "expected chunk info record " + std::to_string(i + 1) + " of " + std::to_string(chunk_count) +
                           " (op=0x06) at byte offset " + std::to_string(pos) + ", found op=" + hex_op(r.op),
                       "the index at index_pos: conn_count connection records, then chunk_count chunk info records");
    }
    const uint32_t ver = r.header.u32("ver");
    if (ver != 1) r.header.fail("chunk info version " + std::to_string(ver) + " (only version 1 exists)");
    ChunkInfo ci;
    ci.pos = r.header.u64("chunk_pos");
    const uint32_t n = r.header.u32("count");
    if (uint64_t{n} * 8 != r.data_len) {
      throw InputError(bag->path, 0,
                       "chunk info record at byte offset " + std::to_string(pos) + " lists " + std::to_string(n) +
                           " connections but holds " + std::to_string(r.data_len) + " data bytes",
                       "count pairs of uint32 connection id, uint32 message count (8 bytes each)");
    }
    if (ci.pos < chunks_begin || ci.pos >= index_pos) {
      throw InputError(bag->path, 0,
                       "chunk info record at byte offset " + std::to_string(pos) + " points to chunk_pos " +
                           std::to_string(ci.pos) + ", outside the chunk area [" + std::to_string(chunks_begin) + ", " +
                           std::to_string(index_pos) + ")",
                       kBagForm);
    }
    data.resize(r.data_len);
    file.read(r.data_pos, data.data(), r.data_len, "chunk info data");
    for (uint32_t k = 0; k < n; ++k) {
      const uint32_t conn = load_le<uint32_t>(data.data() + 8 * k);
      const uint32_t count = load_le<uint32_t>(data.data() + 8 * k + 4);
      if (bag->find(conn) == nullptr) {
        throw InputError(bag->path, 0,
                         "chunk info record at byte offset " + std::to_string(pos) + " names connection " +
                             std::to_string(conn) + ", which has no connection record",
                         kBagForm);
      }
      ci.counts.emplace_back(conn, count);
    }
    bag->chunks.push_back(std::move(ci));
    pos = r.end();
  }
  std::sort(bag->chunks.begin(), bag->chunks.end(),
            [](const ChunkInfo& a, const ChunkInfo& b) { return a.pos < b.pos; });
  for (size_t i = 1; i < bag->chunks.size(); ++i) {
    if (bag->chunks[i].pos == bag->chunks[i - 1].pos) {
      throw InputError(bag->path, 0, "two chunk info records point to the chunk at byte offset " +
                                         std::to_string(bag->chunks[i].pos), kBagForm);
    }
  }
}

// Unindexed bag: walks every record from `pos`, decompressing each chunk once.
inline void scan_linearly(Bag* bag, uint64_t pos) {
  const BagFile& file = bag->file;
  ChunkLoader loader(file);
  FileRecord r;
  MemRecord m;
  std::vector<uint8_t> data;
  while (pos < file.size()) {
    read_record(file, pos, &r);
    switch (r.op) {
      case kOpChunk: {
        loader.load(pos);
        ChunkInfo ci;
        ci.pos = pos;
        std::unordered_map<uint32_t, uint32_t> counts;
        for (size_t off = 0; off < loader.size(); off = m.next) {
          parse_mem_record(bag->path, loader.data(), loader.size(), off, loader.where(), &m);
          if (m.op == kOpConnection) {
            add_connection(bag, m.header, m.data, m.data_len, loader.where(), m.data_off);
          } else if (m.op == kOpMessage) {
            const uint32_t conn = m.header.u32("conn");
            if (bag->find(conn) == nullptr) {
              throw InputError(bag->path, 0,
                               "message on connection " + std::to_string(conn) +
                                   " before any connection record for it at " + loader.where().at(off),
                               "a connection record (op=0x07) before the first message of each connection");
            }
            ++counts[conn];
          } else {
            throw InputError(bag->path, 0, "unexpected record op=" + hex_op(m.op) + " inside a chunk at " +
                                               loader.where().at(off),
                             "connection (op=0x07) and message data (op=0x02) records inside chunks");
          }
        }
        for (const auto& kv : counts) ci.counts.emplace_back(kv.first, kv.second);
        std::sort(ci.counts.begin(), ci.counts.end());
        bag->chunks.push_back(std::move(ci));
        break;
      }
      case kOpConnection:
        read_connection(bag, r, &data);
        break;
      case kOpIndexData:
      case kOpChunkInfo:
        break;
      case kOpMessage:
        throw InputError(bag->path, 0, "message data record outside a chunk at byte offset " + std::to_string(pos),
                         "bag 2.0 message data records inside chunk records (op=0x05)");
      default:
        throw InputError(bag->path, 0, "unexpected record op=" + hex_op(r.op) + " at byte offset " + std::to_string(pos),
                         "chunk (0x05), index data (0x04), connection (0x07) or chunk info (0x06) records");
    }
    pos = r.end();
  }
}

inline std::shared_ptr<Bag> open_bag(const std::string& path) {
  auto bag = std::make_shared<Bag>(path);
  const BagFile& file = bag->file;
  char magic[kMagicSize] = {};
  const size_t n = static_cast<size_t>(std::min<uint64_t>(file.size(), kMagicSize));
  file.read(0, magic, n, "magic");
  const std::string_view got(magic, n);
  if (got != std::string_view(kMagic, kMagicSize)) {
    if (got.substr(0, 9) == "#ROSBAG V" || got.substr(0, 11) == "#ROSRECORD ") {
      const size_t nl = got.find('\n');
      throw InputError(path, 0,
                       "unsupported bag version \"" + printable(got.substr(0, nl)) + "\" at byte offset 0",
                       "ROS bag format 2.0 (\"#ROSBAG V2.0\"); migrate older bags with `rosbag fix`");
    }
    throw InputError(path, 0, "not a ROS bag: magic \"" + printable(got) + "\" at byte offset 0", kBagForm);
  }
  FileRecord h;
  read_record(file, kMagicSize, &h);
  if (h.op != kOpBagHeader) {
    throw InputError(path, 0,
                     "expected the bag header record (op=0x03) at byte offset 13, found op=" + hex_op(h.op), kBagForm);
  }
  const uint64_t index_pos = h.header.u64("index_pos");
  const uint32_t conn_count = h.header.u32("conn_count");
  const uint32_t chunk_count = h.header.u32("chunk_count");
  const uint64_t chunks_begin = h.end();
  if (index_pos == 0) {
    scan_linearly(bag.get(), chunks_begin);
    log_info(path + ": bag has no index (index_pos=0, the recording was not closed); read " +
             std::to_string(bag->chunks.size()) + " chunk(s) by a linear scan");
  } else {
    if (index_pos < chunks_begin || index_pos >= file.size()) {
      throw InputError(path, 0,
                       "bag header index_pos " + std::to_string(index_pos) + " at byte offset 13 points outside the file's records [" +
                           std::to_string(chunks_begin) + ", " + std::to_string(file.size()) + ")" +
                           (index_pos >= file.size() ? ": the file is truncated" : ""),
                       "a complete bag whose index_pos points to its connection and chunk info records "
                       "(repair a truncated bag with `rosbag reindex`)");
    }
    bag->indexed = true;
    read_index(bag.get(), index_pos, conn_count, chunk_count, chunks_begin);
  }
  for (const ChunkInfo& ci : bag->chunks) {
    for (const auto& c : ci.counts) bag->connections[bag->by_id.at(c.first)].messages += c.second;
  }
  return bag;
}

// ---------------------------------------------------------------------------------------------
// Message iteration over the chunks holding some connections.

struct Message {
  const Connection* conn = nullptr;
  const uint8_t* data = nullptr;
  uint32_t size = 0;
  uint64_t off = 0;  // offset of data in the chunk (see where)
  const Where* where = nullptr;
};

class MessageCursor {
 public:
  MessageCursor(const Bag& bag, std::vector<uint32_t> conns) : bag_(bag), conns_(std::move(conns)), loader_(bag.file) {
    std::sort(conns_.begin(), conns_.end());
    for (size_t i = 0; i < bag.chunks.size(); ++i) {
      for (const auto& c : bag.chunks[i].counts) {
        if (c.second > 0 && selected(c.first)) {
          chunk_list_.push_back(i);
          break;
        }
      }
    }
  }

  bool next(Message* m) {
    for (;;) {
      if (!loaded_ || off_ >= loader_.size()) {
        if (next_chunk_ == chunk_list_.size()) {
          done_ = true;
          return false;
        }
        loader_.load(bag_.chunks[chunk_list_[next_chunk_++]].pos);
        loaded_ = true;
        off_ = 0;
        continue;
      }
      parse_mem_record(bag_.path, loader_.data(), loader_.size(), off_, loader_.where(), &rec_);
      const uint64_t at = off_;
      off_ = rec_.next;
      if (rec_.op == kOpConnection) continue;  // known from the index
      if (rec_.op != kOpMessage) {
        throw InputError(bag_.path, 0, "unexpected record op=" + hex_op(rec_.op) + " inside a chunk at " +
                                           loader_.where().at(at),
                         "connection (op=0x07) and message data (op=0x02) records inside chunks");
      }
      const uint32_t id = rec_.header.u32("conn");
      if (!selected(id)) {
        if (bag_.find(id) == nullptr) {
          throw InputError(bag_.path, 0, "message on unknown connection " + std::to_string(id) + " at " +
                                             loader_.where().at(at),
                           "messages of connections listed in the bag's connection records");
        }
        continue;
      }
      m->conn = bag_.find(id);
      m->data = rec_.data;
      m->size = rec_.data_len;
      m->off = rec_.data_off;
      m->where = &loader_.where();
      return true;
    }
  }

  // Fraction of the selected chunks consumed, by bytes of the current chunk.
  double progress() const {
    if (done_ || chunk_list_.empty()) return 1.0;
    if (!loaded_) return 0.0;
    const double in_chunk = loader_.size() > 0 ? static_cast<double>(off_) / static_cast<double>(loader_.size()) : 1.0;
    return (static_cast<double>(next_chunk_ - 1) + in_chunk) / static_cast<double>(chunk_list_.size());
  }

 private:
  bool selected(uint32_t id) const { return std::binary_search(conns_.begin(), conns_.end(), id); }

  const Bag& bag_;
  std::vector<uint32_t> conns_;
  std::vector<size_t> chunk_list_;
  size_t next_chunk_ = 0;
  ChunkLoader loader_;
  MemRecord rec_;
  size_t off_ = 0;
  bool loaded_ = false;
  bool done_ = false;
};

}  // namespace evio::detail::rosbag
