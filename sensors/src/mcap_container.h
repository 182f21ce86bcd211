// MCAP container (https://mcap.dev/spec, major version 0) for the ROS 2 bag reader: the file's
// records, its summary (Schema, Channel, Statistics, ChunkIndex) or a linear scan of the data
// section when there is none, chunk decompression (lz4 frame, zstd) and message iteration.
// Message payloads stay opaque here (CDR decoding is the caller's). Internal to evio::sensors.
//
// The model (all integers little-endian):
//   file    = magic "\x89MCAP0\r\n", Header record, data section (Schema, Channel, Message, Chunk,
//             MessageIndex, Attachment, Metadata records, ending with DataEnd), optional summary
//             section (Schema, Channel, Statistics, ChunkIndex, AttachmentIndex, MetadataIndex
//             records grouped by opcode), optional SummaryOffset records, Footer record, magic.
//   record  = uint8 opcode, uint64 content length, content. Unknown opcodes are skipped, and fields
//             past the known ones (records grow at their end) are ignored.
//   String  = uint32 byte length + UTF-8 bytes; Bytes in a record's tail run to its end;
//             Map / Array = uint32 byte length + entries.
//   Chunk   = a batch of Schema, Channel and Message records, compressed with "" (none), "lz4"
//             (LZ4 frame format) or "zstd"; a MessageIndex record per channel follows it.
// Times are uint64 nanoseconds (log_time: when recorded; publish_time: when published).
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "binary_file.h"
#include "evio/calib/error.h"

namespace evio::detail::mcap {

// Record opcodes (spec section "Records").
enum Op : uint8_t {
  kOpHeader = 0x01,
  kOpFooter = 0x02,
  kOpSchema = 0x03,
  kOpChannel = 0x04,
  kOpMessage = 0x05,
  kOpChunk = 0x06,
  kOpMessageIndex = 0x07,
  kOpChunkIndex = 0x08,
  kOpAttachment = 0x09,
  kOpAttachmentIndex = 0x0a,
  kOpStatistics = 0x0b,
  kOpMetadata = 0x0c,
  kOpMetadataIndex = 0x0d,
  kOpSummaryOffset = 0x0e,
  kOpDataEnd = 0x0f,
};

constexpr char kMagic[] = "\x89MCAP0\r\n";
constexpr size_t kMagicSize = 8;
constexpr size_t kRecordPrefix = 9;    // opcode + uint64 content length
constexpr size_t kFooterContent = 20;  // uint64 summary_start, uint64 summary_offset_start, uint32 summary_crc
constexpr size_t kMessagePrefix = 22;  // uint16 channel_id, uint32 sequence, uint64 log_time, uint64 publish_time

constexpr uint64_t kMaxRecordBytes = uint64_t{256} << 20;  // a record read whole (Header, Schema, Channel, ...)
constexpr uint64_t kMaxDataBytes = uint64_t{1} << 30;      // a Message record, or a chunk compressed or not

// The expected form quoted in errors about the file's structure.
extern const char kMcapForm[];

// "Schema (op=0x03)"; unknown opcodes read "op=0x80".
std::string op_name(uint8_t op);
// CRC-32 (IEEE 802.3, reflected polynomial 0xEDB88320) as MCAP uses it; `crc` continues a previous
// value (0 to start).
uint32_t crc32(const uint8_t* p, size_t n, uint32_t crc = 0);

// Where a byte buffer lies, for error messages: the file itself (and uncompressed chunks, whose
// records are file bytes), or a decompressed chunk.
struct Where {
  uint64_t base = 0;                  // file offset of buffer byte 0, when not in a decompressed chunk
  const char* compression = nullptr;  // "lz4" / "zstd" when the buffer is a decompressed chunk
  uint64_t chunk_pos = 0;             // file offset of that Chunk record
  // "byte offset 1234 of the file" or "byte offset 56 of the decompressed zstd chunk at byte offset 789".
  std::string at(uint64_t off) const;
};

struct Schema {
  uint16_t id = 0;
  std::string name, encoding;
  std::string data;
};

struct Channel {
  uint16_t id = 0;
  uint16_t schema_id = 0;
  std::string topic, message_encoding;
  std::string schema_name;  // of its schema, "" if schema_id is 0
  std::vector<std::pair<std::string, std::string>> metadata;
  // From the Statistics record's channel_message_counts, or counted by the linear scan; -1 unknown.
  int64_t messages = -1;
};

struct ChunkInfo {
  uint64_t pos = 0;                   // file offset of the Chunk record (its opcode byte)
  uint64_t length = 0;                // whole record, opcode and length prefix included
  uint64_t start_ns = 0, end_ns = 0;  // message_start_time, message_end_time (0 when no messages)
  std::string compression;
  uint64_t compressed_size = 0, uncompressed_size = 0;
  // Channel id -> file offset of its MessageIndex record after the chunk; may be empty.
  std::vector<std::pair<uint16_t, uint64_t>> message_index_offsets;
  uint64_t message_index_length = 0;  // bytes of the Message Index records right after the chunk
  // Channels with messages in the chunk (sorted): the keys of message_index_offsets, or found by
  // decompressing the chunk in the linear scan. Unknown (false) when neither was available.
  bool channels_known = false;
  std::vector<uint16_t> channel_ids;
};

// File-wide message statistics: the summary's Statistics record, or counted by the linear scan
// (up to the damage, if any).
struct Statistics {
  bool known = false;
  uint64_t message_count = 0;
  uint64_t message_start_ns = 0, message_end_ns = 0;  // 0 when no messages
};

// A Chunk record's fields, read from the file.
struct ChunkHeader {
  uint64_t pos = 0, length = 0;  // record offset and whole length
  uint64_t start_ns = 0, end_ns = 0;
  uint64_t uncompressed_size = 0;
  uint32_t uncompressed_crc = 0;
  std::string compression;
  uint64_t records_pos = 0, records_size = 0;  // the (compressed) records field in the file
};

// Reads and decompresses one Chunk record at a time into a buffer that grows with the data
// actually produced (a false uncompressed_size allocates nothing up front); checks the size and
// the CRC-32 when the chunk has one.
class ChunkLoader {
 public:
  explicit ChunkLoader(const BinaryFile& file) : file_(file) {}

  // Reads the fields of the Chunk record at `pos` (the whole record `record_length` bytes, as the
  // Chunk Index or the scan found it), then decompresses its records and checks their CRC.
  void load(uint64_t pos, uint64_t record_length) {
    read_fields(pos, record_length);
    decompress();
  }
  // The two steps of load(): header() is valid after the first.
  void read_fields(uint64_t pos, uint64_t record_length);
  void decompress();
  const ChunkHeader& header() const { return header_; }
  const uint8_t* data() const { return buf_.data(); }
  size_t size() const { return size_; }
  const Where& where() const { return where_; }

 private:
  [[noreturn]] void bad_data(const std::string& detail) const;
  void grow(size_t used);
  void finish(size_t used);
  void decompress_lz4();
  void decompress_zstd();

  const BinaryFile& file_;
  ChunkHeader header_;
  std::vector<uint8_t> buf_, comp_;
  size_t size_ = 0;
  Where where_;
};

class MessageCursor;

class File {
 public:
  // Reads the header and the summary, or scans the data section when there is no usable summary.
  // Throws InputError when the file cannot be opened or does not start with an MCAP header; damage
  // found by the linear scan is reported by the cursor when it gets there (see damage()).
  explicit File(const std::string& path);

  const std::string& path() const { return file_.path(); }
  uint64_t size() const { return file_.size(); }
  const std::string& profile() const { return profile_; }  // Header record's profile, e.g. "ros2"
  const std::string& library() const { return library_; }
  // The summary section was read (Footer.summary_start != 0 and it was consistent).
  bool has_summary() const { return has_summary_; }
  const std::vector<Schema>& schemas() const { return schemas_; }
  const std::vector<Channel>& channels() const { return channels_; }  // in order of appearance
  const Channel* find_channel(uint16_t id) const;
  const Schema* find_schema(uint16_t id) const;
  const std::vector<ChunkInfo>& chunks() const { return chunks_; }  // file order
  bool has_unchunked_messages() const { return has_unchunked_; }    // Message records directly in the data section
  const Statistics& statistics() const { return stats_; }
  // Where the linear scan stopped at a truncated or corrupt record (nullptr when the data section
  // is whole): the cursor delivers every message before it, then throws this error.
  const InputError* damage() const { return damage_ ? &*damage_ : nullptr; }
  const BinaryFile& binary() const { return file_; }

 private:
  friend class MessageCursor;

  // The reading plan: chunks and runs of top-level records holding unchunked messages, in file order.
  struct Segment {
    bool chunk = false;
    size_t chunk_index = 0;       // chunks_[chunk_index] when chunk
    uint64_t begin = 0, end = 0;  // file byte range
  };

  void read_header();
  struct Footer {
    uint64_t pos = 0, summary_start = 0, summary_offset_start = 0;
    uint32_t summary_crc = 0;
  };
  std::optional<Footer> read_footer() const;
  void read_summary(const Footer& footer);
  void read_summary_record(uint8_t op, const std::vector<uint8_t>& content, uint64_t pos,
                           std::vector<std::pair<uint16_t, uint64_t>>* counts);
  void plan_from_chunk_index(const Footer& footer);
  bool gap_has_messages(uint64_t begin, uint64_t end);
  void finish_summary(const std::vector<std::pair<uint16_t, uint64_t>>& counts);
  void reset_contents();
  void scan_linearly(uint64_t end, bool footer_found);
  void scan_record(uint8_t op, uint64_t pos, uint64_t length, ChunkLoader* loader, std::vector<uint8_t>* content);
  void scan_chunk(uint64_t pos, uint64_t length, ChunkLoader* loader);
  void count_message(uint16_t channel, uint64_t log_time_ns, const Where& where, uint64_t pos);
  void close_range(uint64_t end);
  void add_schema(Schema s);
  void add_channel(Channel c, bool require_schema, const Where& where, uint64_t pos);

  BinaryFile file_;
  std::string profile_, library_;
  uint64_t data_start_ = 0;  // first record after the Header
  bool has_summary_ = false;
  bool has_unchunked_ = false;
  std::vector<Schema> schemas_;
  std::vector<Channel> channels_;
  std::unordered_map<uint16_t, size_t> schema_by_id_, channel_by_id_;
  std::vector<ChunkInfo> chunks_;
  std::vector<Segment> segments_;
  Statistics stats_;
  std::optional<InputError> damage_;
  // Linear scan state.
  std::unordered_map<uint16_t, uint64_t> scan_counts_;
  std::optional<uint64_t> range_begin_;  // first unchunked Message record of the open range
  uint64_t index_chain_end_ = 0;         // end of the last chunk and the Message Index records after it
};

struct Message {
  const Channel* channel = nullptr;
  uint32_t sequence = 0;
  uint64_t log_time_ns = 0, publish_time_ns = 0;
  const uint8_t* data = nullptr;  // valid until the next next() call
  size_t size = 0;
  // Where byte k of `data` lies, for error messages, e.g. "byte offset 1234 of the file" or
  // "byte offset 56 of the decompressed zstd chunk at byte offset 789".
  std::string at(size_t k) const;

  // What at() needs: the offset of data[0] in the file, or in the decompressed chunk when
  // chunk_compression is set ("lz4", "zstd"; nullptr for file offsets).
  uint64_t data_pos = 0;
  const char* chunk_compression = nullptr;
  uint64_t chunk_pos = 0;
};

class MessageCursor {
 public:
  // Messages of the given channels in file order (chunk by chunk, one decompressed chunk in memory
  // at a time), skipping chunks that hold none of them (by their channel ids, when known) and,
  // when start_log_time_ns > 0, chunks whose message_end_time < start_log_time_ns and every
  // message with log_time < start_log_time_ns.
  MessageCursor(const File& file, std::vector<uint16_t> channel_ids, uint64_t start_log_time_ns = 0);

  bool next(Message* m);                                   // false at the end; throws InputError on bad data
  double progress() const;                                 // fraction of the selected bytes consumed, in [0, 1]
  size_t chunks_loaded() const { return chunks_loaded_; }  // chunks decompressed so far

 private:
  bool wanted(const File::Segment& s) const;
  bool selected(uint16_t id) const { return selected_[id] != 0; }
  bool next_in_chunk(Message* m);
  bool next_in_range(Message* m, uint64_t end);
  void start_segment();
  void check_chunk_index(const ChunkInfo& c) const;
  const Channel* channel_of(uint16_t id, const Where& where, uint64_t pos) const;

  const File& file_;
  std::vector<uint8_t> selected_;  // 65536 flags, by channel id
  uint64_t start_ns_ = 0;
  std::vector<size_t> plan_;          // indices into file_.segments_
  std::vector<uint64_t> plan_bytes_;  // cumulative bytes before each planned segment
  uint64_t total_bytes_ = 0;
  size_t next_segment_ = 0;  // plan_ index of the segment after the current one
  bool in_segment_ = false;
  bool done_ = false;
  ChunkLoader loader_;
  size_t off_ = 0;               // next record in the decompressed chunk
  uint64_t pos_ = 0;             // next record in a range of the file
  std::vector<uint8_t> record_;  // an unchunked message's content
  size_t chunks_loaded_ = 0;
};

}  // namespace evio::detail::mcap
