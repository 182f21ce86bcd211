#include "evio_test/mcap_writer.h"

#include <lz4frame.h>
#include <zstd.h>

#include <stdexcept>

namespace evio_test {
namespace {

constexpr char kMagic[] = "\x89MCAP0\r\n";
enum : uint8_t {
  kHeader = 0x01,
  kFooter = 0x02,
  kSchema = 0x03,
  kChannel = 0x04,
  kMessage = 0x05,
  kChunk = 0x06,
  kMessageIndex = 0x07,
  kChunkIndex = 0x08,
  kStatistics = 0x0b,
  kSummaryOffset = 0x0e,
  kDataEnd = 0x0f,
};

// Little-endian serialization (spec "Serialization").
template <typename T>
void put(std::string* s, T v) {
  for (size_t i = 0; i < sizeof(T); ++i) s->push_back(static_cast<char>((static_cast<uint64_t>(v) >> (8 * i)) & 0xff));
}
void put_str(std::string* s, const std::string& v) {
  put<uint32_t>(s, static_cast<uint32_t>(v.size()));
  *s += v;
}
std::string record(uint8_t op, const std::string& content) {
  std::string r(1, static_cast<char>(op));
  put<uint64_t>(&r, content.size());
  return r + content;
}

// CRC-32 (IEEE, reflected 0xEDB88320), bit by bit: independent of the reader's table version.
uint32_t crc32_bitwise(const std::string& s, uint32_t crc = 0) {
  crc = ~crc;
  for (const char ch : s) {
    crc ^= static_cast<uint8_t>(ch);
    for (int k = 0; k < 8; ++k) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
  }
  return ~crc;
}

}  // namespace

McapWriter::McapWriter(const std::string& path, McapWriterOptions o) : o_(std::move(o)), path_(path) {
  if (!o_.compression.empty() && o_.compression != "lz4" && o_.compression != "zstd") {
    throw std::runtime_error("McapWriter: unknown compression '" + o_.compression + "'");
  }
  f_ = std::fopen(path.c_str(), "wb");
  if (f_ == nullptr) throw std::runtime_error("McapWriter: cannot write " + path);
  emit(std::string(kMagic, 8));
  std::string header;
  put_str(&header, o_.profile);
  put_str(&header, "evio_test McapWriter");
  emit_record(kHeader, header);
}

McapWriter::~McapWriter() {
  try {
    close();
  } catch (const std::exception&) {
  }
  if (f_ != nullptr) std::fclose(f_);
}

void McapWriter::emit(const std::string& bytes) {
  if (std::fwrite(bytes.data(), 1, bytes.size(), f_) != bytes.size()) {
    throw std::runtime_error("McapWriter: write error on " + path_);
  }
  pos_ += bytes.size();
}

void McapWriter::emit_record(uint8_t op, const std::string& content) { emit(record(op, content)); }

// Into the open chunk when chunking, else straight into the data section.
void McapWriter::add_to_chunk(uint8_t op, const std::string& content) {
  if (o_.chunk_size == 0) {
    emit_record(op, content);
  } else {
    chunk_ += record(op, content);
  }
}

uint16_t McapWriter::add_schema(const std::string& name, const std::string& encoding, const std::string& data) {
  const auto id = static_cast<uint16_t>(schema_records_.size() + 1);
  std::string c;
  put<uint16_t>(&c, id);
  put_str(&c, name);
  put_str(&c, encoding);
  put_str(&c, data);
  schema_records_.push_back(c);
  add_to_chunk(kSchema, c);
  return id;
}

uint16_t McapWriter::add_channel(uint16_t schema_id, const std::string& topic, const std::string& message_encoding,
                                 const std::vector<std::pair<std::string, std::string>>& metadata) {
  const auto id = static_cast<uint16_t>(channel_records_.size() + 1);
  std::string c;
  put<uint16_t>(&c, id);
  put<uint16_t>(&c, schema_id);
  put_str(&c, topic);
  put_str(&c, message_encoding);
  std::string map;
  for (const auto& kv : metadata) {
    put_str(&map, kv.first);
    put_str(&map, kv.second);
  }
  put_str(&c, map);
  channel_records_.push_back(c);
  channel_counts_[id];  // listed in the statistics even without messages
  add_to_chunk(kChannel, c);
  return id;
}

void McapWriter::write(uint16_t channel, uint64_t log_time_ns, const std::string& data, uint64_t publish_time_ns,
                       uint32_t sequence) {
  std::string c;
  put<uint16_t>(&c, channel);
  put<uint32_t>(&c, sequence);
  put<uint64_t>(&c, log_time_ns);
  put<uint64_t>(&c, publish_time_ns);
  c += data;
  start_ = messages_ == 0 ? log_time_ns : std::min(start_, log_time_ns);
  end_ = messages_ == 0 ? log_time_ns : std::max(end_, log_time_ns);
  ++messages_;
  ++channel_counts_[channel];
  if (o_.chunk_size == 0) {
    emit_record(kMessage, c);
    return;
  }
  chunk_start_ = chunk_has_messages_ ? std::min(chunk_start_, log_time_ns) : log_time_ns;
  chunk_end_ = chunk_has_messages_ ? std::max(chunk_end_, log_time_ns) : log_time_ns;
  chunk_has_messages_ = true;
  chunk_index_[channel].emplace_back(log_time_ns, chunk_.size());
  chunk_ += record(kMessage, c);
  if (chunk_.size() >= o_.chunk_size) flush_chunk();
}

void McapWriter::write_record(uint8_t opcode, const std::string& content, bool in_chunk) {
  if (in_chunk && o_.chunk_size != 0) {
    chunk_ += record(opcode, content);
    return;
  }
  flush_chunk();
  emit_record(opcode, content);
}

std::string McapWriter::compress(const std::string& records) const {
  if (o_.compression.empty()) return records;
  std::string out;
  if (o_.compression == "lz4") {
    out.resize(LZ4F_compressFrameBound(records.size(), nullptr));
    const size_t n = LZ4F_compressFrame(out.data(), out.size(), records.data(), records.size(), nullptr);
    if (LZ4F_isError(n)) throw std::runtime_error(std::string("McapWriter: lz4: ") + LZ4F_getErrorName(n));
    out.resize(n);
  } else {
    out.resize(ZSTD_compressBound(records.size()));
    const size_t n = ZSTD_compress(out.data(), out.size(), records.data(), records.size(), 3);
    if (ZSTD_isError(n)) throw std::runtime_error(std::string("McapWriter: zstd: ") + ZSTD_getErrorName(n));
    out.resize(n);
  }
  return out;
}

// Chunk record, then one Message Index record per channel; remembered for the Chunk Index.
void McapWriter::flush_chunk() {
  if (chunk_.empty()) return;
  const std::string compressed = compress(chunk_);
  ChunkIndex ci;
  ci.start = chunk_has_messages_ ? chunk_start_ : 0;
  ci.end = chunk_has_messages_ ? chunk_end_ : 0;
  ci.pos = pos_;
  ci.compressed = compressed.size();
  ci.uncompressed = chunk_.size();
  std::string c;
  put<uint64_t>(&c, ci.start);
  put<uint64_t>(&c, ci.end);
  put<uint64_t>(&c, chunk_.size());
  put<uint32_t>(&c, crc32_bitwise(chunk_));
  put_str(&c, o_.compression);
  put<uint64_t>(&c, compressed.size());
  c += compressed;
  emit_record(kChunk, c);
  ci.length = pos_ - ci.pos;
  if (o_.message_index) {
    const uint64_t index_start = pos_;
    for (const auto& kv : chunk_index_) {
      std::string m;
      put<uint16_t>(&m, kv.first);
      put<uint32_t>(&m, static_cast<uint32_t>(kv.second.size() * 16));
      for (const auto& e : kv.second) {
        put<uint64_t>(&m, e.first);
        put<uint64_t>(&m, e.second);
      }
      ci.index_offsets.emplace_back(kv.first, pos_);
      emit_record(kMessageIndex, m);
    }
    ci.index_length = pos_ - index_start;
  }
  chunk_indexes_.push_back(ci);
  chunk_.clear();
  chunk_index_.clear();
  chunk_has_messages_ = false;
}

// Summary records grouped by opcode; *offsets receives the Summary Offset records.
std::string McapWriter::summary_section(uint64_t summary_start, std::string* offsets) const {
  std::string s;
  auto group = [&](uint8_t op, const std::vector<std::string>& contents) {
    if (contents.empty()) return;
    const uint64_t start = summary_start + s.size();
    for (const std::string& c : contents) s += record(op, c);
    std::string o;
    put<uint8_t>(&o, op);
    put<uint64_t>(&o, start);
    put<uint64_t>(&o, summary_start + s.size() - start);
    *offsets += record(kSummaryOffset, o);
  };
  group(kSchema, schema_records_);
  group(kChannel, channel_records_);
  std::string st;
  put<uint64_t>(&st, messages_);
  put<uint16_t>(&st, static_cast<uint16_t>(schema_records_.size()));
  put<uint32_t>(&st, static_cast<uint32_t>(channel_records_.size()));
  put<uint32_t>(&st, 0);  // attachments
  put<uint32_t>(&st, 0);  // metadata
  put<uint32_t>(&st, static_cast<uint32_t>(chunk_indexes_.size()));
  put<uint64_t>(&st, start_);
  put<uint64_t>(&st, end_);
  std::string counts;
  for (const auto& kv : channel_counts_) {
    put<uint16_t>(&counts, kv.first);
    put<uint64_t>(&counts, kv.second);
  }
  put_str(&st, counts);
  group(kStatistics, {st});
  std::vector<std::string> indexes;
  for (const ChunkIndex& ci : chunk_indexes_) {
    std::string c;
    put<uint64_t>(&c, ci.start);
    put<uint64_t>(&c, ci.end);
    put<uint64_t>(&c, ci.pos);
    put<uint64_t>(&c, ci.length);
    std::string map;
    for (const auto& e : ci.index_offsets) {
      put<uint16_t>(&map, e.first);
      put<uint64_t>(&map, e.second);
    }
    put_str(&c, map);
    put<uint64_t>(&c, ci.index_length);
    put_str(&c, o_.compression);
    put<uint64_t>(&c, ci.compressed);
    put<uint64_t>(&c, ci.uncompressed);
    indexes.push_back(c);
  }
  group(kChunkIndex, indexes);
  return s;
}

void McapWriter::close() {
  if (closed_ || f_ == nullptr) return;
  closed_ = true;
  flush_chunk();
  std::string data_end;
  put<uint32_t>(&data_end, 0);  // data_section_crc: not available
  emit_record(kDataEnd, data_end);
  uint64_t summary_start = 0, offsets_start = 0;
  std::string tail;  // summary, summary offsets, and the Footer fields the CRC covers
  if (o_.summary) {
    summary_start = pos_;
    std::string offsets;
    tail = summary_section(summary_start, &offsets);
    offsets_start = summary_start + tail.size();
    tail += offsets;
  }
  std::string footer(1, static_cast<char>(kFooter));
  put<uint64_t>(&footer, 20);
  put<uint64_t>(&footer, summary_start);
  put<uint64_t>(&footer, offsets_start);
  const uint32_t crc = o_.summary ? crc32_bitwise(tail + footer) : 0;
  put<uint32_t>(&footer, crc);
  emit(tail + footer + std::string(kMagic, 8));
  if (std::fflush(f_) != 0) throw std::runtime_error("McapWriter: write error on " + path_);
}

}  // namespace evio_test
