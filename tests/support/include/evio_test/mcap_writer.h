// A small MCAP writer for tests (https://mcap.dev/spec): Header, Schema and Channel records,
// messages in chunks ("" / "lz4" frame / "zstd", with CRC-32 and a Message Index record per
// channel after each chunk) or directly in the data section, Data End, and a summary (Schema,
// Channel, Statistics, Chunk Index records, Summary Offset records) with a CRC-checked Footer.
#pragma once

#include <cstdint>
#include <cstdio>
#include <map>
#include <string>
#include <utility>
#include <vector>

namespace evio_test {

struct McapWriterOptions {
  std::string compression = "";   // "", "lz4", "zstd"
  size_t chunk_size = 64 * 1024;  // uncompressed bytes per chunk; 0 = no chunks (messages in the data section)
  bool summary = true;            // Statistics, Schema, Channel, Chunk Index records + Summary Offset
  bool message_index = true;      // Message Index records after each chunk (and in the Chunk Index)
  std::string profile = "ros2";
};

class McapWriter {
 public:
  // Throws std::runtime_error when the file cannot be written or the compression is unknown.
  McapWriter(const std::string& path, McapWriterOptions o = {});
  ~McapWriter();
  McapWriter(const McapWriter&) = delete;
  McapWriter& operator=(const McapWriter&) = delete;

  // Ids count from 1. Schema and Channel records go into the open chunk when chunking (as a
  // recorder writes them before the first message on them), else into the data section.
  uint16_t add_schema(const std::string& name, const std::string& encoding, const std::string& data);
  uint16_t add_channel(uint16_t schema_id, const std::string& topic, const std::string& message_encoding = "cdr",
                       const std::vector<std::pair<std::string, std::string>>& metadata = {});
  void write(uint16_t channel, uint64_t log_time_ns, const std::string& data, uint64_t publish_time_ns = 0,
             uint32_t sequence = 0);
  // A raw record (any opcode, e.g. an unknown one) in the data section, after the open chunk is
  // written; or inside the open chunk when in_chunk (and chunking).
  void write_record(uint8_t opcode, const std::string& content, bool in_chunk = false);
  // Writes the open chunk, Data End, the summary, the Footer and the magic. Also called by the
  // destructor; later calls do nothing.
  void close();

  // Bytes written so far (the next record's file offset).
  uint64_t position() const { return pos_; }

 private:
  struct ChunkIndex {
    uint64_t start = 0, end = 0, pos = 0, length = 0;
    std::vector<std::pair<uint16_t, uint64_t>> index_offsets;
    uint64_t index_length = 0;
    uint64_t compressed = 0, uncompressed = 0;
  };

  void emit(const std::string& bytes);
  void emit_record(uint8_t op, const std::string& content);
  void add_to_chunk(uint8_t op, const std::string& content);
  void flush_chunk();
  std::string compress(const std::string& records) const;
  std::string summary_section(uint64_t summary_start, std::string* offsets) const;

  McapWriterOptions o_;
  std::FILE* f_ = nullptr;
  std::string path_;
  uint64_t pos_ = 0;
  bool closed_ = false;
  std::vector<std::string> schema_records_, channel_records_;  // record contents, for the summary
  // Open chunk: its uncompressed records, time range and per-channel (log_time, offset) entries.
  std::string chunk_;
  bool chunk_has_messages_ = false;
  uint64_t chunk_start_ = 0, chunk_end_ = 0;
  std::map<uint16_t, std::vector<std::pair<uint64_t, uint64_t>>> chunk_index_;
  std::vector<ChunkIndex> chunk_indexes_;
  // Statistics.
  uint64_t messages_ = 0, start_ = 0, end_ = 0;
  std::map<uint16_t, uint64_t> channel_counts_;
};

}  // namespace evio_test
