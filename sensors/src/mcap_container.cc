// MCAP container: records, summary, linear scan, chunk decompression and message iteration
// (model and conventions in mcap_container.h).
#include "mcap_container.h"

#include <algorithm>
#include <array>
#include <cstring>

#include <lz4frame.h>
#include <zstd.h>

#include "byte_order.h"
#include "evio/calib/log.h"
#include "text_common.h"

namespace evio::detail::mcap {

const char kMcapForm[] =
    "MCAP (https://mcap.dev/spec): magic \"\\x89MCAP0\\r\\n\", records <uint8 opcode><uint64 content "
    "length><content> (Header first, then the data section ending with Data End, optional summary), "
    "Footer, magic; integers little-endian, strings and maps uint32 byte length + bytes";

namespace {

constexpr char kLz4[] = "lz4";
constexpr char kZstd[] = "zstd";
constexpr size_t kChunkFixed = kRecordPrefix + 8 + 8 + 8 + 4 + 4;  // prefix .. compression length: 41 bytes
constexpr size_t kMaxCompressionName = 255;                        // bytes of a chunk's compression string

std::string hex(uint64_t v, int digits) {
  static const char* d = "0123456789abcdef";
  std::string s = "0x";
  for (int i = digits - 1; i >= 0; --i) s += d[(v >> (4 * i)) & 15];
  return s;
}

// The layout of a record, quoted as the expected form in errors about it.
std::string record_form(uint8_t op) {
  std::string f;
  switch (op) {
    case kOpHeader:
      f = "string profile, string library";
      break;
    case kOpFooter:
      f = "20 bytes: uint64 summary_start, uint64 summary_offset_start, uint32 summary_crc";
      break;
    case kOpSchema:
      f = "uint16 id, string name, string encoding, uint32-length-prefixed data";
      break;
    case kOpChannel:
      f = "uint16 id, uint16 schema_id, string topic, string message_encoding, map<string,string> metadata";
      break;
    case kOpMessage:
      f = "uint16 channel_id, uint32 sequence, uint64 log_time, uint64 publish_time, then the data to the "
          "end of the record";
      break;
    case kOpChunk:
      f = "uint64 message_start_time, uint64 message_end_time, uint64 uncompressed_size, uint32 "
          "uncompressed_crc, string compression, uint64-length-prefixed records";
      break;
    case kOpMessageIndex:
      f = "uint16 channel_id, array<uint64 log_time, uint64 offset>";
      break;
    case kOpChunkIndex:
      f = "uint64 message_start_time, uint64 message_end_time, uint64 chunk_start_offset, uint64 chunk_length, "
          "map<uint16,uint64> message_index_offsets, uint64 message_index_length, string compression, uint64 "
          "compressed_size, uint64 uncompressed_size";
      break;
    case kOpStatistics:
      f = "uint64 message_count, uint16 schema_count, uint32 channel_count, uint32 attachment_count, uint32 "
          "metadata_count, uint32 chunk_count, uint64 message_start_time, uint64 message_end_time, "
          "map<uint16,uint64> channel_message_counts";
      break;
    default:
      return kMcapForm;
  }
  return "an MCAP " + op_name(op) + " record: " + f + " (strings and maps: uint32 byte length + bytes)";
}

// The fields of one record's content, read in order with bounds checks; errors name the record,
// its offset and the field.
class Fields {
 public:
  Fields(const std::string& path, const uint8_t* p, size_t n, uint8_t op, const Where& where, uint64_t pos)
      : path_(path), p_(p), n_(n), op_(op), where_(where), pos_(pos) {}

  uint16_t u16(const char* name) { return fixed<uint16_t>(name, "uint16"); }
  uint32_t u32(const char* name) { return fixed<uint32_t>(name, "uint32"); }
  uint64_t u64(const char* name) { return fixed<uint64_t>(name, "uint64"); }

  // uint32 byte length + bytes (String, and Bytes prefixed by a uint32 length).
  std::string str(const char* name) {
    const uint32_t len = u32(name);
    need(len, name, "a string of " + std::to_string(len) + " bytes");
    std::string s(reinterpret_cast<const char*>(p_ + i_), len);
    i_ += len;
    return s;
  }

  // uint32 byte length + entries: a reader over the entries (same record, offsets continued).
  Fields map(const char* name) {
    const uint32_t len = u32(name);
    need(len, name, "a map of " + std::to_string(len) + " bytes");
    Fields sub(path_, p_ + i_, len, op_, where_, pos_);
    sub.base_ = base_ + i_;
    i_ += len;
    return sub;
  }

  bool empty() const { return i_ == n_; }

 private:
  template <typename T>
  T fixed(const char* name, const char* type) {
    need(sizeof(T), name, std::string("a ") + type);
    const T v = load_le<T>(p_ + i_);
    i_ += sizeof(T);
    return v;
  }

  void need(uint64_t k, const char* name, const std::string& what) const {
    if (k <= n_ - i_) return;
    throw InputError(path_, 0,
                     op_name(op_) + " record at " + where_.at(pos_) + ": field '" + name + "' (" + what +
                         ") at content byte " + std::to_string(base_ + i_) + " runs past the end of the " +
                         std::to_string(base_ + n_) + "-byte " + (base_ == 0 ? "record content" : "field"),
                     record_form(op_));
  }

  const std::string& path_;
  const uint8_t* p_;
  size_t n_;
  size_t i_ = 0;
  size_t base_ = 0;  // offset of p_ in the record content (for a map's entries)
  uint8_t op_;
  const Where& where_;
  uint64_t pos_;
};

const Where kFile{};

// A record's opcode and content length, read at file offset `pos` and checked to lie before `end`
// (`limit` names that bound in errors).
struct RecordHead {
  uint8_t op = 0;
  uint64_t length = 0;  // content bytes
};

RecordHead read_head(const BinaryFile& file, uint64_t pos, uint64_t end, const char* limit) {
  const std::string& path = file.path();
  if (pos > end || end - pos < kRecordPrefix) {
    throw InputError(path, 0,
                     "truncated record at " + kFile.at(pos) + ": " + std::to_string(pos < end ? end - pos : 0) +
                         " bytes left before " + limit +
                         ", a record needs at least 9 (uint8 opcode, uint64 "
                         "content length)",
                     kMcapForm);
  }
  uint8_t b[kRecordPrefix];
  file.read(pos, b, kRecordPrefix, "record opcode and length");
  RecordHead h;
  h.op = b[0];
  h.length = load_le<uint64_t>(b + 1);
  if (h.length > end - pos - kRecordPrefix) {
    throw InputError(path, 0,
                     op_name(h.op) + " record at " + kFile.at(pos) + ": content length " + std::to_string(h.length) +
                         " runs past " + limit + " at byte offset " + std::to_string(end) + " (" +
                         std::to_string(end - pos - kRecordPrefix) + " bytes left)",
                     kMcapForm);
  }
  return h;
}

// A record's whole content, read from the file (at most kMaxRecordBytes).
void read_content(const BinaryFile& file, uint64_t pos, const RecordHead& h, std::vector<uint8_t>* content) {
  if (h.length > kMaxRecordBytes) {
    throw InputError(file.path(), 0,
                     op_name(h.op) + " record at " + kFile.at(pos) + ": content length " + std::to_string(h.length) +
                         " exceeds the 256 MiB limit for this record type",
                     record_form(h.op));
  }
  content->resize(h.length);
  file.read(pos + kRecordPrefix, content->data(), h.length, "record content");
}

// A record inside a decompressed chunk (or any byte buffer).
struct MemRecord {
  uint8_t op = 0;
  size_t pos = 0;  // of the opcode byte
  const uint8_t* content = nullptr;
  size_t length = 0;
  size_t next = 0;  // offset after the record
};

MemRecord parse_mem_record(const std::string& path, const uint8_t* buf, size_t size, size_t pos, const Where& where) {
  const size_t left = size - pos;
  if (left < kRecordPrefix) {
    throw InputError(path, 0,
                     "truncated record at " + where.at(pos) + ": " + std::to_string(left) +
                         " bytes left in the chunk's records, a record needs at least 9 (uint8 opcode, uint64 "
                         "content length)",
                     kMcapForm);
  }
  MemRecord r;
  r.op = buf[pos];
  r.pos = pos;
  const uint64_t len = load_le<uint64_t>(buf + pos + 1);
  if (len > left - kRecordPrefix) {
    throw InputError(path, 0,
                     op_name(r.op) + " record at " + where.at(pos) + ": content length " + std::to_string(len) +
                         " runs past the end of the chunk's records (" + std::to_string(left - kRecordPrefix) +
                         " bytes left)",
                     kMcapForm);
  }
  r.content = buf + pos + kRecordPrefix;
  r.length = static_cast<size_t>(len);
  r.next = pos + kRecordPrefix + r.length;
  return r;
}

// The fixed fields of a Message record's content (at least kMessagePrefix bytes, checked).
struct MessageHead {
  uint16_t channel = 0;
  uint32_t sequence = 0;
  uint64_t log_time = 0, publish_time = 0;
};

void check_message_length(const std::string& path, uint64_t length, const Where& where, uint64_t pos) {
  if (length < kMessagePrefix) {
    throw InputError(path, 0,
                     "Message (op=0x05) record at " + where.at(pos) + ": " + std::to_string(length) +
                         " content bytes, fewer than its 22 bytes of fixed fields",
                     record_form(kOpMessage));
  }
  if (length - kMessagePrefix > kMaxDataBytes) {
    throw InputError(path, 0,
                     "Message (op=0x05) record at " + where.at(pos) + ": " + std::to_string(length - kMessagePrefix) +
                         " data bytes exceed the 1 GiB limit for a message",
                     record_form(kOpMessage));
  }
}

MessageHead message_head(const uint8_t* p) {
  MessageHead h;
  h.channel = load_le<uint16_t>(p);
  h.sequence = load_le<uint32_t>(p + 2);
  h.log_time = load_le<uint64_t>(p + 6);
  h.publish_time = load_le<uint64_t>(p + 14);
  return h;
}

Schema parse_schema(Fields f) {
  Schema s;
  s.id = f.u16("id");
  s.name = f.str("name");
  s.encoding = f.str("encoding");
  s.data = f.str("data");
  return s;
}

Channel parse_channel(Fields f) {
  Channel c;
  c.id = f.u16("id");
  c.schema_id = f.u16("schema_id");
  c.topic = f.str("topic");
  c.message_encoding = f.str("message_encoding");
  Fields m = f.map("metadata");
  while (!m.empty()) {
    std::string key = m.str("metadata key");
    c.metadata.emplace_back(std::move(key), m.str("metadata value"));
  }
  return c;
}

// Map<uint16, uint64> entries.
std::vector<std::pair<uint16_t, uint64_t>> parse_u16_u64_map(Fields f, const char* name) {
  std::vector<std::pair<uint16_t, uint64_t>> out;
  Fields m = f.map(name);
  while (!m.empty()) {
    const uint16_t k = m.u16(name);
    out.emplace_back(k, m.u64(name));
  }
  return out;
}

ChunkInfo parse_chunk_index(Fields f, uint64_t* message_index_length) {
  ChunkInfo c;
  c.start_ns = f.u64("message_start_time");
  c.end_ns = f.u64("message_end_time");
  c.pos = f.u64("chunk_start_offset");
  c.length = f.u64("chunk_length");
  Fields m = f.map("message_index_offsets");
  while (!m.empty()) {
    const uint16_t id = m.u16("message_index_offsets");
    c.message_index_offsets.emplace_back(id, m.u64("message_index_offsets"));
  }
  *message_index_length = f.u64("message_index_length");
  c.compression = f.str("compression");
  c.compressed_size = f.u64("compressed_size");
  c.uncompressed_size = f.u64("uncompressed_size");
  for (const auto& e : c.message_index_offsets) c.channel_ids.push_back(e.first);
  std::sort(c.channel_ids.begin(), c.channel_ids.end());
  c.channel_ids.erase(std::unique(c.channel_ids.begin(), c.channel_ids.end()), c.channel_ids.end());
  c.channels_known = !c.message_index_offsets.empty();  // empty: no message index available
  return c;
}

// CRC-32 of the file bytes [begin, end), read in blocks.
uint32_t crc_of_range(const BinaryFile& file, uint64_t begin, uint64_t end) {
  std::vector<uint8_t> block(std::min<uint64_t>(end - begin, uint64_t{1} << 20));
  uint32_t crc = 0;
  for (uint64_t pos = begin; pos < end;) {
    const size_t n = static_cast<size_t>(std::min<uint64_t>(block.size(), end - pos));
    file.read(pos, block.data(), n, "summary section");
    crc = crc32(block.data(), n, crc);
    pos += n;
  }
  return crc;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Helpers.

std::string op_name(uint8_t op) {
  static const char* const names[] = {
      nullptr,    "Header",         "Footer",         "Schema",     "Channel",          "Message",
      "Chunk",    "Message Index",  "Chunk Index",    "Attachment", "Attachment Index", "Statistics",
      "Metadata", "Metadata Index", "Summary Offset", "Data End"};
  const std::string code = "op=" + hex(op, 2);
  if (op >= 1 && op <= 0x0f) return std::string(names[op]) + " (" + code + ")";
  return "unknown (" + code + ")";
}


// Slicing-by-8: table k gives the CRC of a byte followed by k zero bytes, so eight input bytes are
// folded per step with eight lookups (the same result as the byte-wise loop, ~4x faster).
uint32_t crc32(const uint8_t* p, size_t n, uint32_t crc) {
  static const std::array<std::array<uint32_t, 256>, 8> table = [] {
    std::array<std::array<uint32_t, 256>, 8> t{};
    for (uint32_t i = 0; i < 256; ++i) {
      uint32_t c = i;
      for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[0][i] = c;
    }
    for (uint32_t i = 0; i < 256; ++i) {
      for (size_t k = 1; k < 8; ++k) t[k][i] = (t[k - 1][i] >> 8) ^ t[0][t[k - 1][i] & 0xff];
    }
    return t;
  }();
  crc = ~crc;
  for (; n >= 8; n -= 8, p += 8) {
    const uint32_t lo = load_le<uint32_t>(p) ^ crc, hi = load_le<uint32_t>(p + 4);
    crc = table[7][lo & 0xff] ^ table[6][(lo >> 8) & 0xff] ^ table[5][(lo >> 16) & 0xff] ^ table[4][lo >> 24] ^
          table[3][hi & 0xff] ^ table[2][(hi >> 8) & 0xff] ^ table[1][(hi >> 16) & 0xff] ^ table[0][hi >> 24];
  }
  for (; n > 0; --n, ++p) crc = table[0][(crc ^ *p) & 0xff] ^ (crc >> 8);
  return ~crc;
}

std::string Where::at(uint64_t off) const {
  if (compression == nullptr) return "byte offset " + std::to_string(base + off) + " of the file";
  return "byte offset " + std::to_string(off) + " of the decompressed " + compression + " chunk at byte offset " +
         std::to_string(chunk_pos);
}

std::string Message::at(size_t k) const {
  Where w;
  w.compression = chunk_compression;
  w.chunk_pos = chunk_pos;
  return w.at(data_pos + k);
}

// ---------------------------------------------------------------------------------------------
// Chunks.

void ChunkLoader::read_fields(uint64_t pos, uint64_t record_length) {
  const std::string& path = file_.path();
  header_ = ChunkHeader{};
  header_.pos = pos;
  header_.length = record_length;
  where_ = Where{};
  size_ = 0;
  const std::string at = kFile.at(pos);
  if (record_length < kChunkFixed || pos > file_.size() || record_length > file_.size() - pos) {
    throw InputError(path, 0,
                     "Chunk (op=0x06) record at " + at + ": a record of " + std::to_string(record_length) +
                         " bytes cannot hold its fixed fields (41 bytes) or runs past the end of the file",
                     record_form(kOpChunk));
  }
  // The fixed fields, the compression name and the records length in one read.
  uint8_t b[kChunkFixed + kMaxCompressionName + 8];
  const size_t n = static_cast<size_t>(std::min<uint64_t>(record_length, sizeof(b)));
  file_.read(pos, b, n, "Chunk record fields");
  if (b[0] != kOpChunk || load_le<uint64_t>(b + 1) != record_length - kRecordPrefix) {
    throw InputError(path, 0,
                     "expected a Chunk (op=0x06) record of " + std::to_string(record_length) + " bytes at " + at +
                         ", found a " + op_name(b[0]) + " record of " + std::to_string(load_le<uint64_t>(b + 1)) +
                         " content bytes",
                     "a Chunk record where its Chunk Index record points");
  }
  header_.start_ns = load_le<uint64_t>(b + 9);
  header_.end_ns = load_le<uint64_t>(b + 17);
  header_.uncompressed_size = load_le<uint64_t>(b + 25);
  header_.uncompressed_crc = load_le<uint32_t>(b + 33);
  const uint32_t name_len = load_le<uint32_t>(b + 37);
  if (name_len > kMaxCompressionName || kChunkFixed + uint64_t{name_len} + 8 > record_length) {
    throw InputError(path, 0,
                     "Chunk (op=0x06) record at " + at + ": compression name of " + std::to_string(name_len) +
                         " bytes is longer than 255 bytes or runs past the record's end",
                     record_form(kOpChunk));
  }
  header_.compression.assign(reinterpret_cast<const char*>(b + kChunkFixed), name_len);
  header_.records_size = load_le<uint64_t>(b + kChunkFixed + name_len);
  header_.records_pos = pos + kChunkFixed + name_len + 8;
  const uint64_t room = record_length - (kChunkFixed + name_len + 8);
  if (header_.records_size > room) {
    throw InputError(path, 0,
                     "Chunk (op=0x06) record at " + at + ": records field of " + std::to_string(header_.records_size) +
                         " bytes runs past the end of the record (" + std::to_string(room) + " bytes left)",
                     record_form(kOpChunk));
  }
  const std::string& c = header_.compression;
  if (!c.empty() && c != kLz4 && c != kZstd) {
    throw InputError(path, 0, "Chunk (op=0x06) record at " + at + ": unsupported compression '" + printable(c) + "'",
                     "chunk compression \"\" (none), \"lz4\" (LZ4 frame format) or \"zstd\"");
  }
  if (header_.uncompressed_size > kMaxDataBytes || header_.records_size > kMaxDataBytes) {
    throw InputError(path, 0,
                     "Chunk (op=0x06) record at " + at + ": " +
                         std::to_string(std::max(header_.uncompressed_size, header_.records_size)) +
                         " bytes of records exceed the 1 GiB limit for a chunk",
                     "chunks of at most 1 GiB, compressed or not");
  }
}

void ChunkLoader::decompress() {
  const ChunkHeader& h = header_;
  if (h.compression.empty()) {
    if (h.records_size != h.uncompressed_size) {
      throw InputError(file_.path(), 0,
                       "Chunk (op=0x06) record at " + kFile.at(h.pos) + ": uncompressed records of " +
                           std::to_string(h.records_size) + " bytes, but uncompressed_size says " +
                           std::to_string(h.uncompressed_size),
                       "an uncompressed chunk whose records length equals its uncompressed_size");
    }
    if (buf_.size() < h.records_size) buf_.resize(h.records_size);
    file_.read(h.records_pos, buf_.data(), h.records_size, "chunk records");
    size_ = h.records_size;
    where_.base = h.records_pos;
  } else {
    where_.compression = h.compression == kLz4 ? kLz4 : kZstd;
    where_.chunk_pos = h.pos;
    comp_.resize(h.records_size);
    file_.read(h.records_pos, comp_.data(), h.records_size, "compressed chunk records");
    if (comp_.empty()) {
      if (h.uncompressed_size != 0)
        bad_data("no compressed data for " + std::to_string(h.uncompressed_size) + " bytes");
      size_ = 0;
    } else if (where_.compression == kLz4) {
      decompress_lz4();
    } else {
      decompress_zstd();
    }
  }
  if (h.uncompressed_crc != 0) {
    const uint32_t crc = crc32(buf_.data(), size_);
    if (crc != h.uncompressed_crc) {
      throw InputError(file_.path(), 0,
                       "Chunk (op=0x06) record at " + kFile.at(h.pos) + ": the CRC-32 of its " + std::to_string(size_) +
                           " uncompressed record bytes is " + hex(crc, 8) +
                           ", the chunk says uncompressed_crc=" + hex(h.uncompressed_crc, 8) + " (corrupted data)",
                       "chunk records matching their uncompressed_crc");
    }
  }
}

void ChunkLoader::bad_data(const std::string& detail) const {
  throw InputError(file_.path(), 0,
                   "Chunk (op=0x06) record at " + kFile.at(header_.pos) + ": corrupted " + header_.compression +
                       " data (" + detail + ")",
                   "a valid " + header_.compression + " stream that decompresses to the chunk's uncompressed_size");
}

// The output buffer once `used` bytes are produced: doubles from 64 KiB as data is produced, up to
// uncompressed_size + 1 (the spare byte reveals data longer than announced).
void ChunkLoader::grow(size_t used) {
  if (used < buf_.size()) return;
  const uint64_t cap = header_.uncompressed_size + 1;
  const uint64_t want = std::min<uint64_t>(cap, std::max<uint64_t>(uint64_t{used} * 2, uint64_t{1} << 16));
  if (want > buf_.size()) buf_.resize(static_cast<size_t>(want));
}

void ChunkLoader::finish(size_t used) {
  if (used != header_.uncompressed_size) {
    bad_data("decompressed to " + std::to_string(used) + " bytes, uncompressed_size says " +
             std::to_string(header_.uncompressed_size));
  }
  size_ = used;
}

void ChunkLoader::decompress_lz4() {
  LZ4F_dctx* ctx = nullptr;
  if (LZ4F_isError(LZ4F_createDecompressionContext(&ctx, LZ4F_VERSION))) bad_data("liblz4 context creation failed");
  struct Free {
    LZ4F_dctx* c;
    ~Free() { LZ4F_freeDecompressionContext(c); }
  } guard{ctx};
  const uint64_t limit = header_.uncompressed_size;
  size_t in = 0, used = 0;
  for (;;) {
    grow(used);
    size_t out_n = buf_.size() - used;
    size_t in_n = comp_.size() - in;
    const size_t hint = LZ4F_decompress(ctx, buf_.data() + used, &out_n, comp_.data() + in, &in_n, nullptr);
    if (LZ4F_isError(hint)) {
      bad_data(std::string("liblz4: ") + LZ4F_getErrorName(hint) + " after " + std::to_string(used) + " output bytes");
    }
    in += in_n;
    used += out_n;
    if (used > limit) bad_data("decompresses to more than uncompressed_size=" + std::to_string(limit) + " bytes");
    if (hint == 0) {  // a frame ends here; another may follow
      if (in == comp_.size()) break;
      continue;
    }
    if (in == comp_.size() && used < buf_.size()) {
      bad_data("the lz4 frame ends early after " + std::to_string(used) + " of " + std::to_string(limit) + " bytes");
    }
    if (in_n == 0 && out_n == 0 && used < buf_.size()) bad_data("liblz4 makes no progress");
  }
  finish(used);
}

void ChunkLoader::decompress_zstd() {
  ZSTD_DCtx* ctx = ZSTD_createDCtx();
  if (ctx == nullptr) bad_data("libzstd context creation failed");
  struct Free {
    ZSTD_DCtx* c;
    ~Free() { ZSTD_freeDCtx(c); }
  } guard{ctx};
  const uint64_t limit = header_.uncompressed_size;
  // libzstd allocates the window a frame header asks for before producing anything: bound it by the
  // chunk's size (from 8 MiB, the largest window of the standard levels up to 19, to zstd's default
  // limit of 128 MiB), so a small chunk cannot claim a large window.
  int window_log = 23;
  while (window_log < 27 && (uint64_t{1} << window_log) < limit) ++window_log;
  if (ZSTD_isError(ZSTD_DCtx_setParameter(ctx, ZSTD_d_windowLogMax, window_log))) {
    bad_data("libzstd rejects windowLogMax " + std::to_string(window_log));
  }
  ZSTD_inBuffer in{comp_.data(), comp_.size(), 0};
  size_t used = 0;
  for (;;) {
    grow(used);
    ZSTD_outBuffer out{buf_.data(), buf_.size(), used};
    const size_t in_before = in.pos;
    const size_t hint = ZSTD_decompressStream(ctx, &out, &in);
    if (ZSTD_isError(hint)) {
      bad_data(std::string("libzstd: ") + ZSTD_getErrorName(hint) + " after " + std::to_string(used) + " output bytes");
    }
    const bool progress = in.pos != in_before || out.pos != used;
    used = out.pos;
    if (used > limit) bad_data("decompresses to more than uncompressed_size=" + std::to_string(limit) + " bytes");
    if (hint == 0) {  // a frame is decoded and flushed; another may follow
      if (in.pos == in.size) break;
      continue;
    }
    if (in.pos == in.size && used < buf_.size()) {
      bad_data("the zstd frame ends early after " + std::to_string(used) + " of " + std::to_string(limit) + " bytes");
    }
    if (!progress && used < buf_.size()) bad_data("libzstd makes no progress");
  }
  finish(used);
}

// ---------------------------------------------------------------------------------------------
// Opening: header, footer, summary.

File::File(const std::string& path) : file_(path, kMcapForm) {
  read_header();
  const std::optional<Footer> footer = read_footer();
  std::string why;
  if (footer && footer->summary_start != 0) {
    try {
      read_summary(*footer);
      has_summary_ = true;
    } catch (const InputError& e) {
      reset_contents();
      why = "its summary section is unusable (" + e.problem() + ")";
    }
  } else if (footer) {
    why = "it has no summary section (Footer summary_start is 0)";
  } else {
    why = "it does not end with a Footer record and the magic (a truncated or unfinished recording)";
  }
  if (has_summary_) return;
  scan_linearly(footer ? footer->pos : file_.size(), footer.has_value());
  log_warning(path + ": MCAP file read by a linear scan of its data section because " + why + "; found " +
              std::to_string(chunks_.size()) + " chunk(s) and " + std::to_string(stats_.message_count) + " message(s)" +
              (damage_ ? "; the data stops at damage: " + damage_->problem() : ""));
}

void File::read_header() {
  const std::string& path = file_.path();
  char magic[kMagicSize] = {};
  const size_t n = static_cast<size_t>(std::min<uint64_t>(file_.size(), kMagicSize));
  file_.read(0, magic, n, "magic");
  if (n < kMagicSize || std::memcmp(magic, kMagic, kMagicSize) != 0) {
    const std::string got(magic, n);
    if (n >= 6 && std::memcmp(magic, kMagic, 5) == 0) {
      throw InputError(path, 0, "unsupported MCAP major version '" + printable(got.substr(5, 1)) + "' at byte offset 5",
                       "MCAP major version 0 (magic \"\\x89MCAP0\\r\\n\")");
    }
    throw InputError(path, 0, "not an MCAP file: magic \"" + printable(got) + "\" at byte offset 0", kMcapForm);
  }
  const RecordHead h = read_head(file_, kMagicSize, file_.size(), "the end of the file");
  if (h.op != kOpHeader) {
    throw InputError(
        path, 0,
        "expected the Header (op=0x01) record at " + kFile.at(kMagicSize) + ", found a " + op_name(h.op) + " record",
        kMcapForm);
  }
  std::vector<uint8_t> content;
  read_content(file_, kMagicSize, h, &content);
  Fields f(path, content.data(), content.size(), kOpHeader, kFile, kMagicSize);
  profile_ = f.str("profile");
  library_ = f.str("library");
  data_start_ = kMagicSize + kRecordPrefix + h.length;
}

// The Footer record (29 bytes) and the closing magic at the end of the file, if both are there.
std::optional<File::Footer> File::read_footer() const {
  constexpr uint64_t kTail = kRecordPrefix + kFooterContent + kMagicSize;
  if (file_.size() < data_start_ + kTail) return std::nullopt;
  uint8_t b[kTail];
  const uint64_t pos = file_.size() - kTail;
  file_.read(pos, b, kTail, "Footer record and magic");
  if (b[0] != kOpFooter || load_le<uint64_t>(b + 1) != kFooterContent ||
      std::memcmp(b + kRecordPrefix + kFooterContent, kMagic, kMagicSize) != 0) {
    return std::nullopt;
  }
  Footer f;
  f.pos = pos;
  f.summary_start = load_le<uint64_t>(b + 9);
  f.summary_offset_start = load_le<uint64_t>(b + 17);
  f.summary_crc = load_le<uint32_t>(b + 25);
  return f;
}

// Summary section: [summary_start, footer) holds Schema, Channel, Statistics and Chunk Index
// records (and others, skipped), then the Summary Offset records. summary_crc covers it and the
// Footer up to summary_crc.
void File::read_summary(const Footer& footer) {
  const std::string& path = file_.path();
  if (footer.summary_start < data_start_ || footer.summary_start > footer.pos) {
    throw InputError(path, 0,
                     "Footer summary_start " + std::to_string(footer.summary_start) +
                         " lies outside the file's records [" + std::to_string(data_start_) + ", " +
                         std::to_string(footer.pos) + "]",
                     record_form(kOpFooter));
  }
  if (footer.summary_crc != 0) {
    const uint32_t crc = crc_of_range(file_, footer.summary_start, footer.pos + kRecordPrefix + 16);
    if (crc != footer.summary_crc) {
      throw InputError(path, 0,
                       "the summary section's CRC-32 is " + hex(crc, 8) + ", the Footer at " + kFile.at(footer.pos) +
                           " says summary_crc=" + hex(footer.summary_crc, 8),
                       "a summary section matching the Footer's summary_crc");
    }
  }
  std::vector<std::pair<uint16_t, uint64_t>> counts;
  std::vector<uint8_t> content;
  for (uint64_t pos = footer.summary_start; pos < footer.pos;) {
    const RecordHead h = read_head(file_, pos, footer.pos, "the Footer");
    if (h.op == kOpSchema || h.op == kOpChannel || h.op == kOpStatistics || h.op == kOpChunkIndex) {
      read_content(file_, pos, h, &content);
      read_summary_record(h.op, content, pos, &counts);
    }
    pos += kRecordPrefix + h.length;
  }
  finish_summary(counts);
  plan_from_chunk_index(footer);
}

void File::read_summary_record(uint8_t op, const std::vector<uint8_t>& content, uint64_t pos,
                               std::vector<std::pair<uint16_t, uint64_t>>* counts) {
  Fields f(file_.path(), content.data(), content.size(), op, kFile, pos);
  if (op == kOpSchema) {
    add_schema(parse_schema(f));
  } else if (op == kOpChannel) {
    add_channel(parse_channel(f), false, kFile, pos);
  } else if (op == kOpStatistics) {
    stats_.known = true;
    stats_.message_count = f.u64("message_count");
    f.u16("schema_count");
    f.u32("channel_count");
    f.u32("attachment_count");
    f.u32("metadata_count");
    f.u32("chunk_count");
    stats_.message_start_ns = f.u64("message_start_time");
    stats_.message_end_ns = f.u64("message_end_time");
    *counts = parse_u16_u64_map(f, "channel_message_counts");
  } else {
    uint64_t index_length = 0;
    chunks_.push_back(parse_chunk_index(f, &index_length));
    chunks_.back().message_index_length = index_length;
  }
}

// Schema names of the channels and the Statistics' message counts, now that all are read.
void File::finish_summary(const std::vector<std::pair<uint16_t, uint64_t>>& counts) {
  for (Channel& c : channels_) {
    if (c.schema_id == 0) continue;
    const Schema* s = find_schema(c.schema_id);
    if (s == nullptr) {
      throw InputError(file_.path(), 0,
                       "summary Channel record for topic '" + printable(c.topic) + "' names schema " +
                           std::to_string(c.schema_id) + ", which has no Schema record in the summary",
                       "a summary holding a Schema record for every channel's schema_id");
    }
    c.schema_name = s->name;
  }
  if (counts.empty()) return;  // "an empty map indicates this statistic is not available"
  for (Channel& c : channels_) c.messages = 0;
  for (const auto& kv : counts) {
    const auto it = channel_by_id_.find(kv.first);
    if (it == channel_by_id_.end()) {
      throw InputError(file_.path(), 0,
                       "Statistics channel_message_counts names channel " + std::to_string(kv.first) +
                           ", which has no Channel record in the summary",
                       "a summary holding a Channel record for every channel it counts");
    }
    channels_[it->second].messages = static_cast<int64_t>(kv.second);
  }
}

// The reading plan from the Chunk Index records: the chunks in file order, checked to lie in the
// data section without overlapping, and the runs between them that hold unchunked messages.
void File::plan_from_chunk_index(const Footer& footer) {
  const std::string& path = file_.path();
  const uint64_t data_end = footer.summary_start;
  std::sort(chunks_.begin(), chunks_.end(), [](const ChunkInfo& a, const ChunkInfo& b) { return a.pos < b.pos; });
  uint64_t cursor = data_start_;  // end of the previous chunk and its message indexes
  for (size_t i = 0; i < chunks_.size(); ++i) {
    const ChunkInfo& c = chunks_[i];
    if (c.pos < cursor || c.pos > data_end || c.length < kChunkFixed || c.length > data_end - c.pos) {
      throw InputError(path, 0,
                       "Chunk Index record points to a chunk of " + std::to_string(c.length) +
                           " bytes at byte offset " + std::to_string(c.pos) + ", outside the data section [" +
                           std::to_string(data_start_) + ", " + std::to_string(data_end) +
                           ") or overlapping the previous chunk",
                       "Chunk Index records pointing to distinct Chunk records of the data section");
    }
    if (gap_has_messages(cursor, c.pos)) segments_.push_back(Segment{false, 0, cursor, c.pos});
    segments_.push_back(Segment{true, i, c.pos, c.pos + c.length});
    cursor = c.pos + c.length;
    const uint64_t next = i + 1 < chunks_.size() ? chunks_[i + 1].pos : data_end;
    if (c.message_index_length <= (next > cursor ? next - cursor : 0)) cursor += c.message_index_length;
  }
  if (gap_has_messages(cursor, data_end)) segments_.push_back(Segment{false, 0, cursor, data_end});
}

// Whether the top-level records in [begin, end) between indexed chunks hold a Message record
// (reads only record heads, stops at the first message or at Data End).
bool File::gap_has_messages(uint64_t begin, uint64_t end) {
  for (uint64_t pos = begin; pos < end;) {
    const RecordHead h = read_head(file_, pos, end, "the next indexed chunk or the summary");
    if (h.op == kOpMessage) {
      has_unchunked_ = true;
      return true;
    }
    if (h.op == kOpDataEnd) return false;
    if (h.op == kOpChunk) {
      throw InputError(file_.path(), 0, "Chunk (op=0x06) record at " + kFile.at(pos) + " has no Chunk Index record",
                       "a summary with a Chunk Index record for every chunk");
    }
    pos += kRecordPrefix + h.length;
  }
  return false;
}

void File::reset_contents() {
  schemas_.clear();
  channels_.clear();
  schema_by_id_.clear();
  channel_by_id_.clear();
  chunks_.clear();
  segments_.clear();
  stats_ = Statistics{};
  has_unchunked_ = false;
  damage_.reset();
}

void File::add_schema(Schema s) {
  if (s.id == 0 || schema_by_id_.count(s.id) != 0) return;  // id 0 is invalid; repeats are identical
  schema_by_id_.emplace(s.id, schemas_.size());
  schemas_.push_back(std::move(s));
}

void File::add_channel(Channel c, bool require_schema, const Where& where, uint64_t pos) {
  if (channel_by_id_.count(c.id) != 0) return;  // repeated in the summary and chunks, identical
  if (c.schema_id != 0) {
    const Schema* s = find_schema(c.schema_id);
    if (s != nullptr) {
      c.schema_name = s->name;
    } else if (require_schema) {
      throw InputError(file_.path(), 0,
                       "Channel (op=0x04) record at " + where.at(pos) + " for topic '" + printable(c.topic) +
                           "' names schema " + std::to_string(c.schema_id) + ", which has no earlier Schema record",
                       "a Schema record before the first Channel record using it");
    }
  }
  channel_by_id_.emplace(c.id, channels_.size());
  channels_.push_back(std::move(c));
}

const Channel* File::find_channel(uint16_t id) const {
  const auto it = channel_by_id_.find(id);
  return it == channel_by_id_.end() ? nullptr : &channels_[it->second];
}

const Schema* File::find_schema(uint16_t id) const {
  const auto it = schema_by_id_.find(id);
  return it == schema_by_id_.end() ? nullptr : &schemas_[it->second];
}

// ---------------------------------------------------------------------------------------------
// Linear scan of the data section (no usable summary): every record from the Header to Data End
// (or `end`), decompressing each chunk once. The first bad record stops the scan: it becomes the
// damage the cursor reports after the messages before it.

void File::scan_linearly(uint64_t end, bool footer_found) {
  ChunkLoader loader(file_);
  std::vector<uint8_t> content;
  uint64_t pos = data_start_;
  bool data_end = false;
  try {
    while (pos < end) {
      const RecordHead h = read_head(file_, pos, end, footer_found ? "the Footer" : "the end of the file");
      if (h.op == kOpDataEnd) {
        data_end = true;
        break;
      }
      scan_record(h.op, pos, h.length, &loader, &content);
      pos += kRecordPrefix + h.length;
    }
  } catch (const InputError& e) {
    damage_ = e;
  }
  close_range(pos);
  if (!damage_ && !data_end && !footer_found) {
    damage_ = InputError(file_.path(), 0,
                         "truncated file: the data section stops at " + kFile.at(pos) +
                             " (the end of the file) without a Data End (op=0x0f) record, Footer and closing magic",
                         "a complete MCAP file (the recording was not finished)");
  }
  stats_.known = true;
  for (Channel& c : channels_) {
    const auto it = scan_counts_.find(c.id);
    c.messages = it == scan_counts_.end() ? 0 : static_cast<int64_t>(it->second);
  }
  scan_counts_.clear();
}

void File::scan_record(uint8_t op, uint64_t pos, uint64_t length, ChunkLoader* loader, std::vector<uint8_t>* content) {
  const RecordHead h{op, length};
  switch (op) {
    case kOpSchema:
      read_content(file_, pos, h, content);
      add_schema(parse_schema(Fields(file_.path(), content->data(), content->size(), op, kFile, pos)));
      break;
    case kOpChannel:
      read_content(file_, pos, h, content);
      add_channel(parse_channel(Fields(file_.path(), content->data(), content->size(), op, kFile, pos)), true, kFile,
                  pos);
      break;
    case kOpMessage: {
      check_message_length(file_.path(), length, kFile, pos);
      uint8_t b[kMessagePrefix];
      file_.read(pos + kRecordPrefix, b, kMessagePrefix, "Message record fields");
      const MessageHead m = message_head(b);
      count_message(m.channel, m.log_time, kFile, pos);
      if (!range_begin_) range_begin_ = pos;
      has_unchunked_ = true;
      break;
    }
    case kOpChunk:
      close_range(pos);
      scan_chunk(pos, kRecordPrefix + length, loader);
      index_chain_end_ = pos + kRecordPrefix + length;
      break;
    case kOpMessageIndex:
      // Message Index records right after a chunk belong to it.
      if (!chunks_.empty() && pos == index_chain_end_ && length >= 2) {
        uint8_t b[2];
        file_.read(pos + kRecordPrefix, b, 2, "Message Index channel_id");
        chunks_.back().message_index_offsets.emplace_back(load_le<uint16_t>(b), pos);
        chunks_.back().message_index_length += kRecordPrefix + length;
        index_chain_end_ = pos + kRecordPrefix + length;
      }
      break;
    default:  // Attachment, Metadata, summary records, unknown opcodes: not needed
      break;
  }
}

// A chunk found by the scan: recorded as soon as its record fields are read (so the cursor reaches
// it even when its data is damaged), then decompressed for its schemas, channels and messages.
void File::scan_chunk(uint64_t pos, uint64_t length, ChunkLoader* loader) {
  const size_t index = chunks_.size();
  ChunkInfo c;
  c.pos = pos;
  c.length = length;
  chunks_.push_back(c);
  segments_.push_back(Segment{true, index, pos, pos + length});
  loader->read_fields(pos, length);
  const ChunkHeader& h = loader->header();
  ChunkInfo& info = chunks_[index];
  info.start_ns = h.start_ns;
  info.end_ns = h.end_ns;
  info.compression = h.compression;
  info.compressed_size = h.records_size;
  info.uncompressed_size = h.uncompressed_size;
  loader->decompress();
  std::vector<uint16_t> ids;
  const Where& w = loader->where();
  for (size_t off = 0; off < loader->size();) {
    const MemRecord r = parse_mem_record(file_.path(), loader->data(), loader->size(), off, w);
    if (r.op == kOpSchema) {
      add_schema(parse_schema(Fields(file_.path(), r.content, r.length, r.op, w, r.pos)));
    } else if (r.op == kOpChannel) {
      add_channel(parse_channel(Fields(file_.path(), r.content, r.length, r.op, w, r.pos)), true, w, r.pos);
    } else if (r.op == kOpMessage) {
      check_message_length(file_.path(), r.length, w, r.pos);
      const MessageHead m = message_head(r.content);
      count_message(m.channel, m.log_time, w, r.pos);
      ids.push_back(m.channel);
    }
    off = r.next;
  }
  std::sort(ids.begin(), ids.end());
  ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
  info.channel_ids = std::move(ids);
  info.channels_known = true;
}

void File::count_message(uint16_t channel, uint64_t log_time_ns, const Where& where, uint64_t pos) {
  if (find_channel(channel) == nullptr) {
    throw InputError(file_.path(), 0,
                     "Message (op=0x05) record at " + where.at(pos) + " on channel " + std::to_string(channel) +
                         ", which has no earlier Channel record",
                     "a Channel record before the first message on it");
  }
  ++scan_counts_[channel];
  if (stats_.message_count == 0 || log_time_ns < stats_.message_start_ns) stats_.message_start_ns = log_time_ns;
  if (stats_.message_count == 0 || log_time_ns > stats_.message_end_ns) stats_.message_end_ns = log_time_ns;
  ++stats_.message_count;
}

// Ends the run of top-level records holding unchunked messages (if one is open) at `end`.
void File::close_range(uint64_t end) {
  if (!range_begin_) return;
  segments_.push_back(Segment{false, 0, *range_begin_, end});
  range_begin_.reset();
}

// ---------------------------------------------------------------------------------------------
// Message iteration.

MessageCursor::MessageCursor(const File& file, std::vector<uint16_t> channel_ids, uint64_t start_log_time_ns)
    : file_(file), selected_(size_t{1} << 16, 0), start_ns_(start_log_time_ns), loader_(file.file_) {
  for (const uint16_t id : channel_ids) selected_[id] = 1;
  plan_bytes_.push_back(0);
  for (size_t i = 0; i < file.segments_.size(); ++i) {
    const File::Segment& s = file.segments_[i];
    if (!wanted(s)) continue;
    plan_.push_back(i);
    total_bytes_ += s.end - s.begin;
    plan_bytes_.push_back(total_bytes_);
  }
}

// A chunk is skipped when it ends before the start time, or when its channels are known and none
// is selected; runs of unchunked messages are always read.
bool MessageCursor::wanted(const File::Segment& s) const {
  if (!s.chunk) return true;
  const ChunkInfo& c = file_.chunks_[s.chunk_index];
  if (start_ns_ > 0 && c.end_ns < start_ns_) return false;
  if (!c.channels_known) return true;
  return std::any_of(c.channel_ids.begin(), c.channel_ids.end(), [this](uint16_t id) { return selected(id); });
}

bool MessageCursor::next(Message* m) {
  for (;;) {
    if (done_) return false;
    if (!in_segment_) {
      if (next_segment_ == plan_.size()) {
        if (file_.damage_) throw *file_.damage_;  // the messages before the damage were all delivered
        done_ = true;
        return false;
      }
      start_segment();
      continue;
    }
    const File::Segment& s = file_.segments_[plan_[next_segment_ - 1]];
    if (s.chunk ? next_in_chunk(m) : next_in_range(m, s.end)) return true;
    in_segment_ = false;
  }
}

void MessageCursor::start_segment() {
  const File::Segment& s = file_.segments_[plan_[next_segment_]];
  if (s.chunk) {
    const ChunkInfo& c = file_.chunks_[s.chunk_index];
    loader_.load(c.pos, c.length);
    check_chunk_index(c);
    ++chunks_loaded_;
    off_ = 0;
  } else {
    pos_ = s.begin;
  }
  ++next_segment_;
  in_segment_ = true;
}

// A Chunk Index record and the Chunk record it points to agree.
void MessageCursor::check_chunk_index(const ChunkInfo& c) const {
  const ChunkHeader& h = loader_.header();
  if (!file_.has_summary_) return;  // the scan took the fields from the chunk itself
  if (h.compression != c.compression || h.uncompressed_size != c.uncompressed_size ||
      h.records_size != c.compressed_size) {
    throw InputError(file_.path(), 0,
                     "Chunk (op=0x06) record at " + kFile.at(c.pos) + " has compression '" + printable(h.compression) +
                         "', " + std::to_string(h.records_size) + " compressed and " +
                         std::to_string(h.uncompressed_size) + " uncompressed bytes; its Chunk Index record says '" +
                         printable(c.compression) + "', " + std::to_string(c.compressed_size) + " and " +
                         std::to_string(c.uncompressed_size),
                     "a Chunk Index record matching its Chunk record");
  }
}

const Channel* MessageCursor::channel_of(uint16_t id, const Where& where, uint64_t pos) const {
  const Channel* c = file_.find_channel(id);
  if (c == nullptr) {
    throw InputError(file_.path(), 0,
                     "Message (op=0x05) record at " + where.at(pos) + " on channel " + std::to_string(id) +
                         ", which has no Channel record",
                     "a Channel record for every channel that has messages");
  }
  return c;
}

bool MessageCursor::next_in_chunk(Message* m) {
  const Where& w = loader_.where();
  while (off_ < loader_.size()) {
    const MemRecord r = parse_mem_record(file_.path(), loader_.data(), loader_.size(), off_, w);
    off_ = r.next;
    if (r.op != kOpMessage) continue;  // schemas and channels are known from the summary or the scan
    check_message_length(file_.path(), r.length, w, r.pos);
    const MessageHead h = message_head(r.content);
    if (!selected(h.channel) || h.log_time < start_ns_) continue;
    m->channel = channel_of(h.channel, w, r.pos);
    m->sequence = h.sequence;
    m->log_time_ns = h.log_time;
    m->publish_time_ns = h.publish_time;
    m->data = r.content + kMessagePrefix;
    m->size = r.length - kMessagePrefix;
    const uint64_t data_off = r.pos + kRecordPrefix + kMessagePrefix;
    m->chunk_compression = w.compression;
    m->chunk_pos = w.chunk_pos;
    m->data_pos = w.compression == nullptr ? w.base + data_off : data_off;
    return true;
  }
  return false;
}

bool MessageCursor::next_in_range(Message* m, uint64_t end) {
  const BinaryFile& file = file_.file_;
  while (pos_ < end) {
    const uint64_t pos = pos_;
    const RecordHead h = read_head(file, pos, end, "the end of the data section's run of messages");
    pos_ = pos + kRecordPrefix + h.length;
    if (h.op == kOpDataEnd) {
      pos_ = end;
      break;
    }
    if (h.op != kOpMessage) continue;
    check_message_length(file.path(), h.length, kFile, pos);
    uint8_t b[kMessagePrefix];
    file.read(pos + kRecordPrefix, b, kMessagePrefix, "Message record fields");
    const MessageHead mh = message_head(b);
    if (!selected(mh.channel) || mh.log_time < start_ns_) continue;
    const uint64_t data_pos = pos + kRecordPrefix + kMessagePrefix;
    record_.resize(h.length - kMessagePrefix);
    file.read(data_pos, record_.data(), record_.size(), "Message data");
    m->channel = channel_of(mh.channel, kFile, pos);
    m->sequence = mh.sequence;
    m->log_time_ns = mh.log_time;
    m->publish_time_ns = mh.publish_time;
    m->data = record_.data();
    m->size = record_.size();
    m->chunk_compression = nullptr;
    m->chunk_pos = 0;
    m->data_pos = data_pos;
    return true;
  }
  return false;
}

double MessageCursor::progress() const {
  if (done_ || total_bytes_ == 0) return done_ || plan_.empty() ? 1.0 : 0.0;
  double consumed = static_cast<double>(plan_bytes_[next_segment_]);
  if (in_segment_) {
    const File::Segment& s = file_.segments_[plan_[next_segment_ - 1]];
    const double len = static_cast<double>(s.end - s.begin);
    double within = 0.0;
    if (s.chunk) {
      within = loader_.size() > 0 ? len * static_cast<double>(off_) / static_cast<double>(loader_.size()) : len;
    } else {
      within = static_cast<double>(std::min(pos_, s.end) - s.begin);
    }
    consumed = static_cast<double>(plan_bytes_[next_segment_ - 1]) + within;
  }
  return std::min(1.0, consumed / static_cast<double>(total_bytes_));
}

}  // namespace evio::detail::mcap
