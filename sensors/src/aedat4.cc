#include "evio/sensors/aedat4.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <limits>
#include <map>
#include <sstream>
#include <string_view>
#include <utility>

#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "binary_file.h"
#include "aedat4_flatbuffer.h"
#include "aedat4_xml.h"
#include "byte_order.h"
#include "frame_decompress.h"

namespace evio {
namespace {

// ---------------------------------------------------------------------------------------------
// Constants and small helpers

constexpr char kMagic[] = "#!AER-DAT4.0\r\n";
constexpr size_t kMagicSize = sizeof(kMagic) - 1;  // 14 bytes
// Largest header, packet (compressed or decompressed) and data table accepted, bytes. A 4K BGRA
// frame is 33 MB; anything above this limit is treated as a corrupt size field.
constexpr int64_t kMaxBlockBytes = int64_t{256} << 20;
const detail::DecompressLimit kPacketLimit{static_cast<size_t>(kMaxBlockBytes), "packets of at most 256 MiB after decompression"};
constexpr int64_t kMaxUs = std::numeric_limits<int64_t>::max() / 1000;  // us that fit in int64 ns
constexpr double kStandardGravity = 9.80665;                            // m/s^2 per g
constexpr double kDegToRad = 3.14159265358979323846 / 180.0;

enum Compression : int32_t { kNone = 0, kLz4 = 1, kLz4High = 2, kZstd = 3, kZstdHigh = 4 };

const char* compression_name(int32_t c) {
  switch (c) {
    case kNone:
      return "none";
    case kLz4:
      return "LZ4";
    case kLz4High:
      return "LZ4 high";
    case kZstd:
      return "Zstd";
    case kZstdHigh:
      return "Zstd high";
  }
  return "unknown";
}

const char kFileForm[] =
    "an AEDAT 4.0 file: \"#!AER-DAT4.0\\r\\n\", int32 header size, IOHeader flatbuffer (identifier IOHE), "
    "then packets of int32 stream id, int32 size and `size` bytes";
const char kPacketForm[] =
    "packets of int32 stream id (listed in the header's infoNode), int32 size > 0 and `size` bytes, "
    "ending at the end of the file or at the file data table";

using detail::load_le;
using namespace detail::aedat4;  // NOLINT: FbBuffer, XmlParser

std::string num(int64_t v) { return std::to_string(v); }

// Microseconds to nanoseconds; false when the result does not fit in int64.
inline bool us_to_ns(int64_t t_us, int64_t* t_ns) {
  if (t_us > kMaxUs || t_us < -kMaxUs) return false;
  *t_ns = t_us * 1000;
  return true;
}

// ---------------------------------------------------------------------------------------------
// The file, read with pread (no stream position shared between the event stream and side reads)

using File = detail::BinaryFile;

// A stream from the infoNode.
struct Stream {
  int32_t id = 0;
  std::string name;           // originalOutputName, else the id
  std::string type;           // typeIdentifier, e.g. "EVTS"
  int width = 0, height = 0;  // sizeX / sizeY of the info node, px (0 = not stated)
};

// One packet: header at `offset`, `size` bytes of body after the 8-byte header.
struct PacketRef {
  int64_t offset = 0;
  int32_t stream = 0;
  int32_t size = 0;
  // From the file data table (0 and has_time = false when scanned without the table).
  int64_t t_start_us = 0, t_end_us = 0;
  bool has_time = false;
};

// Iterates over the packets of one stream (or all, stream < 0), from the data table or by
// scanning the packet headers.
struct PacketCursor {
  int32_t stream = -1;
  size_t table_index = 0;             // with a data table
  int64_t offset = 0;                 // without: next packet header
  std::map<int32_t, int64_t> counts;  // packets seen per stream id while scanning without a table
};

// Side-stream samples whose time decreases (or repeats, for strictly increasing streams) are
// bad data: thrown under BadLinePolicy::kError, otherwise skipped and logged once.
class SideBadData {
 public:
  SideBadData(const std::string& path, BadLinePolicy policy, const char* what)
      : path_(path), policy_(policy), what_(what) {}
  void bad(const std::string& problem, const std::string& expected) {
    if (policy_ == BadLinePolicy::kError) {
      throw InputError(path_, 0, problem, expected + "; or skip such " + what_ + " with --on-bad-line warn");
    }
    if (count_++ == 0) first_ = problem;
  }
  void finish() const {
    if (count_ > 0) log_warning(path_ + ": skipped " + num(count_) + " bad " + what_ + " (first: " + first_ + ")");
  }

 private:
  const std::string& path_;
  BadLinePolicy policy_;
  std::string what_;
  int64_t count_ = 0;
  std::string first_;
};

// ---------------------------------------------------------------------------------------------

class Aedat4Reader final : public DatasetReader {
 public:
  Aedat4Reader(const std::string& path, const DatasetOptions& options) : path_(path), options_(options), file_(path, "a readable AEDAT 4.0 file") {
    std::string why;
    if (!options_.Validate(&why)) throw InputError(path, 0, "invalid dataset options: " + why);
    report_.path = path;
    report_.time_unit = TimeUnit::kMicroseconds;
    report_.time_unit_reason = "AEDAT 4.0 timestamps are int64 microseconds";
    report_.polarity = PolarityConvention::kZeroOne;
    read_header();
    if (has_table_) read_data_table();
    events_.stream = event_stream_ >= 0 ? streams_[static_cast<size_t>(event_stream_)].id : -1;
    events_.offset = header_end_;
    event_bytes_done_ = header_end_;
    std::ostringstream s;
    s << path_ << ": AEDAT 4.0, " << compression_name(compression_) << " compression, " << streams_.size()
      << " stream(s)";
    if (sensor_.known()) s << ", events " << sensor_.width << "x" << sensor_.height;
    s << ", time unit us, polarity bool -> +1/-1" << (has_table_ ? ", with file data table" : ", no file data table");
    log_info(s.str());
  }

  DatasetFormat format() const override { return DatasetFormat::kAedat4; }
  const std::string& path() const override { return path_; }
  SensorSize sensor_size() const override { return sensor_; }
  double progress() const override {
    const int64_t span = data_end_ - header_end_;
    if (span <= 0 || events_done_) return 1.0;
    return std::clamp(static_cast<double>(event_bytes_done_ - header_end_) / static_cast<double>(span), 0.0, 1.0);
  }
  const ReadReport& event_report() const override { return report_; }

  size_t read_events(EventBuffer* out, size_t max_events) override;
  bool seek_events(int64_t t_ns) override;
  std::vector<ImuSample> read_imu() override;
  std::vector<Frame> read_frames() override;
  std::vector<Trigger> read_triggers() override;
  std::optional<Trajectory> read_groundtruth() override { return std::nullopt; }
  std::optional<calib::CameraCalibration> read_calibration() override { return std::nullopt; }
  std::vector<StreamInfo> streams() const override;

 private:
  void read_header();
  void parse_info_node(std::string_view xml, int64_t file_offset);
  void read_data_table();
  const Stream* find_stream(int32_t id) const {
    const auto it = stream_index_.find(id);
    return it == stream_index_.end() ? nullptr : &streams_[it->second];
  }
  std::string stream_list() const;
  // Next packet of cursor->stream; false at the end.
  bool next_packet(PacketCursor* cursor, PacketRef* ref);
  // Reads and decompresses a packet body into *buf; returns the flatbuffer without its size prefix.
  FbBuffer load_packet(const PacketRef& ref, const char* table_name, std::vector<uint8_t>* raw,
                       std::vector<uint8_t>* buf);
  // Decompresses src according to compression_ into *out (resized to the decompressed size).
  void decompress(const uint8_t* src, size_t n, std::vector<uint8_t>* out, const std::string& where);
  bool load_next_event_packet();
  void bad_event(const char* kind, size_t index, const std::string& problem);
  std::string event_form() const;

  std::string path_;
  DatasetOptions options_;
  File file_;
  int32_t compression_ = kNone;
  int64_t header_end_ = 0;  // first packet header
  int64_t data_end_ = 0;    // end of the packets: data table position, or the file size
  bool has_table_ = false;
  std::vector<Stream> streams_;
  std::map<int32_t, size_t> stream_index_;
  std::vector<PacketRef> table_;  // file data table, sorted by offset
  // Packet counts per stream id: from the data table, or filled by the first complete header scan.
  std::map<int32_t, int64_t> packet_counts_;
  bool counts_known_ = false;
  int event_stream_ = -1, imu_stream_ = -1, frame_stream_ = -1, trigger_stream_ = -1;  // index into streams_
  SensorSize sensor_;
  detail::Lz4FrameDecoder lz4_;
  detail::ZstdFrameDecoder zstd_;

  // Event stream state.
  PacketCursor events_;
  std::vector<uint8_t> event_raw_, event_buf_;
  const uint8_t* cur_elems_ = nullptr;  // 16-byte dv::Event structs of the current packet
  size_t cur_count_ = 0, cur_index_ = 0;
  int64_t cur_packet_offset_ = 0;
  int64_t event_bytes_done_ = 0;
  bool events_done_ = false;
  bool finished_logged_ = false;
  int64_t last_t_ns_ = std::numeric_limits<int64_t>::min();
  int64_t seek_t_ns_ = std::numeric_limits<int64_t>::min();  // events before this are dropped (after seek_events)
  ReadReport report_;
};

// ---------------------------------------------------------------------------------------------
// Header, infoNode and data table

void Aedat4Reader::read_header() {
  const int64_t fsize = static_cast<int64_t>(file_.size());
  uint8_t magic[kMagicSize];
  if (fsize < static_cast<int64_t>(kMagicSize)) {
    throw InputError(path_, 0, "file of " + num(fsize) + " bytes is too short for the AEDAT 4.0 magic at byte offset 0",
                     kFileForm);
  }
  file_.read(0, magic, kMagicSize, "magic");
  if (std::memcmp(magic, kMagic, kMagicSize) != 0) {
    throw InputError(path_, 0, "wrong magic \"" + FbBuffer::printable(magic, kMagicSize) + "\" at byte offset 0",
                     kFileForm);
  }
  const int64_t size_at = static_cast<int64_t>(kMagicSize);
  if (fsize < size_at + 4) {
    throw InputError(path_, 0, "truncated header: no int32 header size at byte offset " + num(size_at), kFileForm);
  }
  uint8_t b4[4];
  file_.read(size_at, b4, 4, "header size");
  const int64_t hsize = load_le<int32_t>(b4);
  const int64_t hstart = size_at + 4;
  if (hsize < 8 || hsize > kMaxBlockBytes) {
    throw InputError(
        path_, 0,
        "header size " + num(hsize) + " at byte offset " + num(size_at) + " is not in [8, " + num(kMaxBlockBytes) + "]",
        kFileForm);
  }
  if (hsize > fsize - hstart) {
    throw InputError(path_, 0,
                     "truncated header: the " + num(hsize) + "-byte IOHeader at byte offset " + num(hstart) +
                         " extends beyond the end of the file (" + num(fsize) + " bytes)",
                     kFileForm);
  }
  std::vector<uint8_t> h(static_cast<size_t>(hsize));
  file_.read(hstart, h.data(), h.size(), "IOHeader");
  header_end_ = hstart + hsize;

  const FbBuffer fb(
      h.data(), h.size(), path_, "IOHeader flatbuffer at byte offset " + num(hstart),
      "an IOHeader flatbuffer (dv IOHeader.fbs: compression int32, dataTablePosition int64, infoNode string; "
      "identifier IOHE)");
  const FbTable root = fb.root("IOHE");
  compression_ = fb.scalar<int32_t>(root, 0, kNone);
  if (compression_ < kNone || compression_ > kZstdHigh) {
    fb.bad("unknown compression type " + num(compression_));
  }
  const int64_t table_pos = fb.scalar<int64_t>(root, 1, -1);
  const FbVector info = fb.vector(root, 2, 1, "infoNode string");
  if (table_pos >= 0) {
    if (table_pos < header_end_ || table_pos >= fsize) {
      fb.bad("dataTablePosition " + num(table_pos) + " is outside the packet area [" + num(header_end_) + ", " +
             num(fsize) + ") of the file");
    }
    has_table_ = true;
    data_end_ = table_pos;
  } else {
    data_end_ = fsize;
  }
  parse_info_node(std::string_view(reinterpret_cast<const char*>(h.data() + info.start), info.size),
                  hstart + static_cast<int64_t>(info.start));
}

void Aedat4Reader::parse_info_node(std::string_view xml, int64_t file_offset) {
  const std::vector<XmlNode> nodes = XmlParser(xml, path_, file_offset).parse();
  std::vector<std::vector<size_t>> info_children(nodes.size());  // "info" child nodes per node
  for (size_t k = 0; k < nodes.size(); ++k) {
    if (nodes[k].parent >= 0 && nodes[k].name == "info")
      info_children[static_cast<size_t>(nodes[k].parent)].push_back(k);
  }
  const std::string where = "infoNode at byte offset " + num(file_offset);
  const char* form =
      "one <node name=\"<stream id>\"> per output with <attr key=\"typeIdentifier\"> (EVTS, IMUS, FRME, TRIG, ...) "
      "and sizeX/sizeY between 1 and 65535";
  for (size_t i = 0; i < nodes.size(); ++i) {
    const XmlNode& n = nodes[i];
    const auto type = n.attrs.find("typeIdentifier");
    if (type == n.attrs.end()) continue;
    int64_t id = 0;
    if (!parse_int(n.name, 0, std::numeric_limits<int32_t>::max(), &id)) {
      throw InputError(path_, 0, where + ": stream node name \"" + n.name + "\" is not a stream id", form);
    }
    Stream s;
    s.id = static_cast<int32_t>(id);
    s.type = type->second;
    const auto out_name = n.attrs.find("originalOutputName");
    s.name = out_name != n.attrs.end() && !out_name->second.empty() ? out_name->second : n.name;
    // sizeX / sizeY: in the stream node's "info" child, or on the stream node itself.
    std::vector<const XmlNode*> holders = {&n};
    for (size_t k : info_children[i]) holders.push_back(&nodes[k]);
    for (const XmlNode* h : holders) {
      for (const char* key : {"sizeX", "sizeY"}) {
        const auto it = h->attrs.find(key);
        if (it == h->attrs.end()) continue;
        int64_t v = 0;
        if (!parse_int(it->second, 1, 65535, &v)) {
          throw InputError(path_, 0,
                           where + ": " + key + " \"" + it->second + "\" of stream " + n.name + " is not a size in px",
                           form);
        }
        (key[4] == 'X' ? s.width : s.height) = static_cast<int>(v);
      }
    }
    if (stream_index_.count(s.id) != 0) {
      throw InputError(path_, 0, where + ": stream id " + num(s.id) + " is listed twice", form);
    }
    stream_index_[s.id] = streams_.size();
    streams_.push_back(std::move(s));
  }
  if (streams_.empty()) {
    throw InputError(path_, 0, where + ": no stream (no node with a typeIdentifier attribute)", form);
  }
  // The first stream of each decoded type, by id.
  auto pick = [&](const char* type) {
    int best = -1;
    for (size_t k = 0; k < streams_.size(); ++k) {
      if (streams_[k].type == type && (best < 0 || streams_[k].id < streams_[static_cast<size_t>(best)].id)) {
        best = static_cast<int>(k);
      }
    }
    return best;
  };
  event_stream_ = pick("EVTS");
  imu_stream_ = pick("IMUS");
  frame_stream_ = pick("FRME");
  trigger_stream_ = pick("TRIG");
  if (event_stream_ >= 0) {
    const Stream& e = streams_[static_cast<size_t>(event_stream_)];
    if (e.width > 0 && e.height > 0) sensor_ = SensorSize{e.width, e.height};
  }
  if (!sensor_.known()) sensor_ = options_.text.sensor;
}

std::string Aedat4Reader::stream_list() const {
  std::string s;
  for (const Stream& st : streams_) s += (s.empty() ? "" : ", ") + num(st.id);
  return s;
}

void Aedat4Reader::read_data_table() {
  const int64_t pos = data_end_;
  const int64_t n = static_cast<int64_t>(file_.size()) - pos;
  if (n > kMaxBlockBytes) {
    throw InputError(path_, 0,
                     "file data table at byte offset " + num(pos) + " is " + num(n) + " bytes, above the " +
                         num(kMaxBlockBytes) + "-byte limit",
                     kFileForm);
  }
  std::vector<uint8_t> raw(static_cast<size_t>(n)), buf;
  file_.read(pos, raw.data(), raw.size(), "file data table");
  const std::string where = "file data table at byte offset " + num(pos);
  decompress(raw.data(), raw.size(), &buf, where);
  const std::string expected =
      "a size-prefixed FileDataTable flatbuffer (dv FileDataTable.fbs, identifier FTAB) at dataTablePosition";
  if (buf.size() < 4 || load_le<uint32_t>(buf.data()) != buf.size() - 4) {
    throw InputError(path_, 0,
                     where + ": size prefix " +
                         (buf.size() < 4 ? std::string("missing") : num(load_le<uint32_t>(buf.data()))) +
                         " does not match the " + num(static_cast<int64_t>(buf.size()) - 4) + " bytes that follow",
                     expected);
  }
  const FbBuffer fb(buf.data() + 4, buf.size() - 4, path_, where, expected);
  const FbTable root = fb.root("FTAB");
  const FbVector v = fb.vector(root, 0, 4, "Table vector");
  table_.reserve(v.size);
  for (uint32_t j = 0; j < v.size; ++j) {
    const FbTable e = fb.vector_table(v, j, "FileDataDefinition");
    PacketRef r;
    const int64_t body = fb.scalar<int64_t>(e, 0, 0);
    const size_t info = fb.field(e, 1, 8);
    if (info == 0) fb.bad("entry " + num(j) + " has no PacketInfo");
    r.stream = load_le<int32_t>(fb.data() + info);
    r.size = load_le<int32_t>(fb.data() + info + 4);
    r.t_start_us = fb.scalar<int64_t>(e, 3, 0);
    r.t_end_us = fb.scalar<int64_t>(e, 4, 0);
    r.has_time = fb.has(e, 3, 8) && fb.has(e, 4, 8);
    if (find_stream(r.stream) == nullptr) {
      fb.bad("entry " + num(j) + " names stream id " + num(r.stream) + ", which the infoNode does not list (" +
             stream_list() + ")");
    }
    if (r.size <= 0 || r.size > kMaxBlockBytes || body < header_end_ + 8 || body > data_end_ ||
        r.size > data_end_ - body) {
      fb.bad("entry " + num(j) + " places a " + num(r.size) + "-byte packet at byte offset " + num(body) +
             ", outside the packet area [" + num(header_end_ + 8) + ", " + num(data_end_) + ")");
    }
    r.offset = body - 8;
    table_.push_back(r);
    ++packet_counts_[r.stream];
  }
  std::stable_sort(table_.begin(), table_.end(),
                   [](const PacketRef& a, const PacketRef& b) { return a.offset < b.offset; });
  for (size_t j = 1; j < table_.size(); ++j) {
    if (table_[j].offset < table_[j - 1].offset + 8 + table_[j - 1].size) {
      fb.bad("packets at byte offsets " + num(table_[j - 1].offset) + " and " + num(table_[j].offset) + " overlap");
    }
  }
  counts_known_ = true;
}

// ---------------------------------------------------------------------------------------------
// Packets

bool Aedat4Reader::next_packet(PacketCursor* c, PacketRef* ref) {
  if (has_table_) {
    while (c->table_index < table_.size()) {
      const PacketRef& r = table_[c->table_index++];
      if (c->stream >= 0 && r.stream != c->stream) continue;
      uint8_t h[8];
      file_.read(r.offset, h, 8, "packet header");
      const int32_t sid = load_le<int32_t>(h);
      const int32_t size = load_le<int32_t>(h + 4);
      if (sid != r.stream || size != r.size) {
        throw InputError(path_, 0,
                         "packet header at byte offset " + num(r.offset) + " (stream " + num(sid) + ", " + num(size) +
                             " bytes) does not match the file data table (stream " + num(r.stream) + ", " +
                             num(r.size) + " bytes)",
                         kPacketForm);
      }
      *ref = r;
      c->offset = r.offset + 8 + r.size;
      return true;
    }
    c->offset = data_end_;
    return false;
  }
  while (c->offset < data_end_) {
    const int64_t at = c->offset;
    if (data_end_ - at < 8) {
      throw InputError(path_, 0,
                       "truncated packet header at byte offset " + num(at) + ": " + num(data_end_ - at) +
                           " bytes left of the 8-byte header",
                       kPacketForm);
    }
    uint8_t h[8];
    file_.read(at, h, 8, "packet header");
    PacketRef r;
    r.offset = at;
    r.stream = load_le<int32_t>(h);
    r.size = load_le<int32_t>(h + 4);
    if (find_stream(r.stream) == nullptr) {
      throw InputError(path_, 0,
                       "packet at byte offset " + num(at) + " has unknown stream id " + num(r.stream) +
                           " (the infoNode lists " + stream_list() + ")",
                       kPacketForm);
    }
    if (r.size <= 0 || r.size > kMaxBlockBytes) {
      throw InputError(
          path_, 0,
          "packet at byte offset " + num(at) + " has size " + num(r.size) + ", not in [1, " + num(kMaxBlockBytes) + "]",
          kPacketForm);
    }
    if (r.size > data_end_ - at - 8) {
      throw InputError(path_, 0,
                       "truncated packet at byte offset " + num(at) + ": size " + num(r.size) +
                           " extends beyond the end of " + (has_table_ ? "the packet area" : "the file") + " (" +
                           num(data_end_ - at - 8) + " bytes left)",
                       kPacketForm);
    }
    c->offset = at + 8 + r.size;
    ++c->counts[r.stream];
    if (c->stream >= 0 && r.stream != c->stream) continue;
    *ref = r;
    return true;
  }
  if (!counts_known_) {  // a complete scan: every stream's packet count is now known
    packet_counts_ = c->counts;
    counts_known_ = true;
  }
  return false;
}

void Aedat4Reader::decompress(const uint8_t* src, size_t n, std::vector<uint8_t>* out, const std::string& where) {
  switch (compression_) {
    case kNone:
      out->assign(src, src + n);
      return;
    case kLz4:
    case kLz4High:
      lz4_.decode(src, n, out, kPacketLimit, path_, where,
                  "LZ4 frame(s) (lz4 frame format, magic 04 22 4d 18) holding the packet's flatbuffer");
      return;
    case kZstd:
    case kZstdHigh:
      zstd_.decode(src, n, out, kPacketLimit, path_, where, "Zstd frame(s) (magic 28 b5 2f fd) holding the packet's flatbuffer");
      return;
  }
  throw InputError(path_, 0, where + ": unknown compression " + num(compression_), kFileForm);
}

FbBuffer Aedat4Reader::load_packet(const PacketRef& ref, const char* table_name, std::vector<uint8_t>* raw,
                                   std::vector<uint8_t>* buf) {
  const Stream* s = find_stream(ref.stream);
  const std::string where =
      "packet at byte offset " + num(ref.offset) + " (stream " + num(ref.stream) + ", " + table_name + ")";
  const std::string expected =
      std::string("a size-prefixed ") + table_name + " flatbuffer (dv schema, identifier " +
      (s != nullptr ? s->type : std::string("?")) + ")" +
      (compression_ != kNone ? std::string(", ") + compression_name(compression_) + "-compressed" : "");
  if (compression_ == kNone) {
    buf->resize(static_cast<size_t>(ref.size));
    file_.read(ref.offset + 8, buf->data(), buf->size(), "packet");
  } else {
    raw->resize(static_cast<size_t>(ref.size));
    file_.read(ref.offset + 8, raw->data(), raw->size(), "packet");
    decompress(raw->data(), raw->size(), buf, where);
  }
  if (buf->size() < 4 || load_le<uint32_t>(buf->data()) != buf->size() - 4) {
    throw InputError(path_, 0,
                     where + ": flatbuffer size prefix " +
                         (buf->size() < 4 ? std::string("missing") : num(load_le<uint32_t>(buf->data()))) +
                         " does not match the " + num(std::max<int64_t>(0, static_cast<int64_t>(buf->size()) - 4)) +
                         " bytes that follow it",
                     expected);
  }
  return FbBuffer(buf->data() + 4, buf->size() - 4, path_, where, expected);
}

// ---------------------------------------------------------------------------------------------
// Events

std::string Aedat4Reader::event_form() const {
  std::string s = "dv::Event {int64 timestamp us, int16 x, int16 y, bool polarity} in non-decreasing time";
  if (sensor_.known()) s += ", inside the " + num(sensor_.width) + "x" + num(sensor_.height) + " sensor";
  return s;
}

void Aedat4Reader::bad_event(const char* kind, size_t index, const std::string& problem) {
  const std::string msg = "event " + num(static_cast<int64_t>(index)) + " of the packet at byte offset " +
                          num(cur_packet_offset_) + ": " + problem;
  if (options_.text.on_bad_line == BadLinePolicy::kError) {
    throw InputError(path_, 0, msg, event_form() + "; or skip such events with --on-bad-line warn");
  }
  ReadReport::Skipped& s = report_.skipped[kind];
  if (s.count == 0) {
    s.first_line = cur_packet_offset_;  // byte offset of the packet (binary format)
    s.first_message = msg;
  }
  ++s.count;
}

bool Aedat4Reader::load_next_event_packet() {
  if (events_.stream < 0) return false;
  PacketRef ref;
  if (!next_packet(&events_, &ref)) return false;
  event_bytes_done_ = events_.offset;
  cur_packet_offset_ = ref.offset;
  const FbBuffer fb = load_packet(ref, "EventPacket", &event_raw_, &event_buf_);
  const FbTable root = fb.root("EVTS");
  const FbVector v = fb.vector(root, 0, 16, "elements vector");
  cur_elems_ = fb.data() + v.start;
  cur_count_ = v.size;
  cur_index_ = 0;
  return true;
}

size_t Aedat4Reader::read_events(EventBuffer* out, size_t max_events) {
  std::vector<Event>& v = out->events();
  const size_t n0 = v.size();
  // Coordinates must lie in the sensor; without a known size, in the non-negative int16 range.
  const uint32_t w = sensor_.known() ? static_cast<uint32_t>(sensor_.width) : 32768u;
  const uint32_t h = sensor_.known() ? static_cast<uint32_t>(sensor_.height) : 32768u;
  size_t produced = 0;
  while (produced < max_events && !events_done_) {
    if (cur_index_ == cur_count_) {
      if (!load_next_event_packet()) {
        events_done_ = true;
        event_bytes_done_ = data_end_;
        break;
      }
      continue;
    }
    const size_t take = std::min(max_events - produced, cur_count_ - cur_index_);
    const size_t base = v.size();
    v.resize(base + take);
    Event* dst = v.data() + base;
    size_t written = 0;
    int64_t last = last_t_ns_;
    const int64_t seek = seek_t_ns_;  // locals: stores through dst cannot alias them
    const uint8_t* p = cur_elems_ + 16 * cur_index_;
    for (size_t k = 0; k < take; ++k, p += 16) {
      const int64_t t_us = load_le<int64_t>(p);
      const uint16_t x = static_cast<uint16_t>(load_le<int16_t>(p + 8));
      const uint16_t y = static_cast<uint16_t>(load_le<int16_t>(p + 10));
      const bool in_range = t_us <= kMaxUs && t_us >= -kMaxUs;
      const int64_t t_ns = in_range ? t_us * 1000 : 0;
      if (in_range && x < w && y < h && t_ns >= last && t_ns >= seek) {
        Event& e = dst[written++];
        e.t_ns = t_ns;
        e.x = x;
        e.y = y;
        e.polarity = p[12] != 0 ? int8_t{1} : int8_t{-1};
        last = t_ns;
        continue;
      }
      const size_t index = cur_index_ + k;
      const char* kind = nullptr;
      std::string problem;
      if (!in_range) {
        kind = "timestamp range";
        problem = "timestamp " + num(t_us) + " us does not fit in int64 nanoseconds";
      } else if (x >= w || y >= h) {
        kind = "outside sensor";
        problem = "pixel (" + num(static_cast<int16_t>(x)) + ", " + num(static_cast<int16_t>(y)) + ") outside the " +
                  (sensor_.known() ? num(sensor_.width) + "x" + num(sensor_.height) + " sensor"
                                   : std::string("non-negative int16 range"));
      } else if (t_ns < last) {
        kind = "time order";
        problem = "timestamp " + format_seconds(t_ns) + " s is earlier than the previous event's " +
                  format_seconds(last) + " s";
      } else {
        continue;  // before the seek target: dropped
      }
      if (options_.text.on_bad_line == BadLinePolicy::kError) v.resize(base + written);  // bad_event throws
      bad_event(kind, index, problem);
    }
    last_t_ns_ = last;
    if (last != std::numeric_limits<int64_t>::min() && last >= seek_t_ns_)
      seek_t_ns_ = std::numeric_limits<int64_t>::min();
    v.resize(base + written);
    cur_index_ += take;
    produced += written;
  }
  report_.records += static_cast<int64_t>(v.size() - n0);
  if (events_done_ && produced == 0 && !finished_logged_) {
    finished_logged_ = true;
    if (report_.skipped_total() > 0) {
      std::ostringstream s;
      s << path_ << ": skipped " << report_.skipped_total() << " bad event(s):";
      for (const auto& kv : report_.skipped) {
        s << " " << kv.second.count << " " << kv.first << " (first: " << kv.second.first_message << ");";
      }
      log_warning(s.str());
    }
  }
  return produced;
}

bool Aedat4Reader::seek_events(int64_t t_ns) {
  if (!has_table_ || events_.stream < 0) return false;
  // The first event packet whose last timestamp is at or after t_ns (the table states packet spans).
  size_t target = table_.size();
  for (size_t j = 0; j < table_.size(); ++j) {
    const PacketRef& r = table_[j];
    if (r.stream != events_.stream) continue;
    int64_t end_ns = 0;
    if (!r.has_time || !us_to_ns(r.t_end_us, &end_ns)) return false;
    if (end_ns >= t_ns) {
      target = j;
      break;
    }
  }
  events_.table_index = target;
  events_.offset = target < table_.size() ? table_[target].offset : data_end_;
  event_bytes_done_ = events_.offset;
  cur_elems_ = nullptr;
  cur_count_ = cur_index_ = 0;
  events_done_ = false;
  finished_logged_ = false;
  last_t_ns_ = std::numeric_limits<int64_t>::min();
  seek_t_ns_ = t_ns;
  return true;
}

// ---------------------------------------------------------------------------------------------
// Side streams

std::vector<ImuSample> Aedat4Reader::read_imu() {
  std::vector<ImuSample> out;
  if (imu_stream_ < 0) return out;
  PacketCursor c;
  c.stream = streams_[static_cast<size_t>(imu_stream_)].id;
  c.offset = header_end_;
  std::vector<uint8_t> raw, buf;
  SideBadData bad(path_, options_.text.on_bad_line, "IMU samples");
  const char* form =
      "dv::IMU {int64 timestamp us, accelerometer in g, gyroscope in deg/s} with strictly increasing, "
      "finite values";
  int64_t last = std::numeric_limits<int64_t>::min();
  PacketRef ref;
  while (next_packet(&c, &ref)) {
    const FbBuffer fb = load_packet(ref, "IMUPacket", &raw, &buf);
    const FbTable root = fb.root("IMUS");
    const FbVector v = fb.vector(root, 0, 4, "elements vector");
    out.reserve(out.size() + v.size);
    for (uint32_t j = 0; j < v.size; ++j) {
      const FbTable t = fb.vector_table(v, j, "IMU table");
      const int64_t t_us = fb.scalar<int64_t>(t, 0, 0);
      float f[6];
      for (int k = 0; k < 6; ++k) f[k] = fb.scalar<float>(t, 2 + k, 0.0f);
      // Where, for error messages only (built on the bad path, not per sample).
      const auto at = [&] { return "IMU sample " + num(j) + " of the packet at byte offset " + num(ref.offset); };
      ImuSample s;
      if (!us_to_ns(t_us, &s.t_ns)) {
        bad.bad(at() + ": timestamp " + num(t_us) + " us does not fit in int64 nanoseconds", form);
        continue;
      }
      bool finite = true;
      for (float x : f) finite = finite && std::isfinite(x);
      if (!finite) {
        bad.bad(at() + ": NaN or infinite accelerometer/gyroscope value", form);
        continue;
      }
      if (s.t_ns <= last) {
        bad.bad(at() + ": timestamp " + format_seconds(s.t_ns) + " s is not after the previous sample's " +
                    format_seconds(last) + " s",
                form);
        continue;
      }
      last = s.t_ns;
      s.accel = Eigen::Vector3d(f[0], f[1], f[2]) * kStandardGravity;
      s.gyro = Eigen::Vector3d(f[3], f[4], f[5]) * kDegToRad;
      out.push_back(s);
    }
  }
  bad.finish();
  return out;
}

std::vector<Frame> Aedat4Reader::read_frames() {
  std::vector<Frame> out;
  if (frame_stream_ < 0) return out;
  PacketCursor c;
  c.stream = streams_[static_cast<size_t>(frame_stream_)].id;
  c.offset = header_end_;
  std::vector<uint8_t> raw, buf;
  SideBadData bad(path_, options_.text.on_bad_line, "frames");
  const char* form = "dv::Frame with timestamps in us, strictly increasing in time";
  int64_t last = std::numeric_limits<int64_t>::min();
  bool warned_position = false;
  PacketRef ref;
  while (next_packet(&c, &ref)) {
    const FbBuffer fb = load_packet(ref, "Frame", &raw, &buf);
    const FbTable t = fb.root("FRME");
    const std::string at = "frame in the packet at byte offset " + num(ref.offset);
    // Time: exposure midpoint when both exposure stamps are present and ordered, else `timestamp`.
    const int64_t ts = fb.scalar<int64_t>(t, 0, 0);
    const int64_t soe = fb.scalar<int64_t>(t, 3, 0);
    const int64_t eoe = fb.scalar<int64_t>(t, 4, 0);
    Frame f;
    bool time_ok = false;
    if (fb.has(t, 3, 8) && fb.has(t, 4, 8) && eoe >= soe && soe >= -kMaxUs && eoe <= kMaxUs) {
      f.t_ns = (soe + eoe) * 500;  // |soe + eoe| <= 2 * kMaxUs, so the product fits in int64
      time_ok = true;
    } else {
      time_ok = us_to_ns(ts, &f.t_ns);
    }
    if (!time_ok) {
      bad.bad(at + ": timestamp " + num(ts) + " us does not fit in int64 nanoseconds", form);
      continue;
    }
    const int8_t format = fb.scalar<int8_t>(t, 5, 0);
    const int16_t sx = fb.scalar<int16_t>(t, 6, 0);
    const int16_t sy = fb.scalar<int16_t>(t, 7, 0);
    const int16_t px = fb.scalar<int16_t>(t, 8, 0);
    const int16_t py = fb.scalar<int16_t>(t, 9, 0);
    int channels = 0;
    if (format == 0)
      channels = 1;  // GRAY
    else if (format == 16)
      channels = 3;  // BGR
    else if (format == 24)
      channels = 4;  // BGRA
    else
      fb.bad("unsupported frame format " + num(format));
    if (sx <= 0 || sy <= 0) fb.bad("frame size " + num(sx) + "x" + num(sy) + " is not positive");
    const FbVector pix = fb.vector(t, 10, 1, "pixels vector");
    const int64_t need = int64_t{sx} * sy * channels;
    if (static_cast<int64_t>(pix.size) != need) {
      fb.bad("pixels vector has " + num(pix.size) + " bytes, expected sizeX * sizeY * channels = " + num(sx) + " * " +
             num(sy) + " * " + num(channels) + " = " + num(need));
    }
    if (f.t_ns <= last) {
      bad.bad(at + ": time " + format_seconds(f.t_ns) + " s is not after the previous frame's " + format_seconds(last) +
                  " s",
              form);
      continue;
    }
    last = f.t_ns;
    if ((px != 0 || py != 0) && !warned_position) {
      warned_position = true;
      log_warning(path_ + ": " + at + " is a region at position (" + num(px) + ", " + num(py) +
                  "); frames are returned as stored, without that offset");
    }
    f.image.create(sy, sx, CV_8UC1);
    const uint8_t* src = fb.data() + pix.start;
    if (channels == 1) {
      for (int r = 0; r < sy; ++r)
        std::memcpy(f.image.ptr<uint8_t>(r), src + static_cast<size_t>(r) * sx, static_cast<size_t>(sx));
    } else {
      // BT.601 luma from B, G, R (OpenCV channel order), weights 0.114, 0.587, 0.299 in 1/256.
      for (int r = 0; r < sy; ++r) {
        uint8_t* d = f.image.ptr<uint8_t>(r);
        const uint8_t* s = src + static_cast<size_t>(r) * sx * channels;
        for (int col = 0; col < sx; ++col, s += channels) {
          d[col] = static_cast<uint8_t>((29u * s[0] + 150u * s[1] + 77u * s[2] + 128u) >> 8);
        }
      }
    }
    out.push_back(std::move(f));
  }
  bad.finish();
  return out;
}

std::vector<Trigger> Aedat4Reader::read_triggers() {
  std::vector<Trigger> out;
  if (trigger_stream_ < 0) return out;
  PacketCursor c;
  c.stream = streams_[static_cast<size_t>(trigger_stream_)].id;
  c.offset = header_end_;
  std::vector<uint8_t> raw, buf;
  SideBadData bad(path_, options_.text.on_bad_line, "triggers");
  const char* form = "dv::Trigger {int64 timestamp us, int8 type} in non-decreasing time";
  int64_t last = std::numeric_limits<int64_t>::min();
  PacketRef ref;
  while (next_packet(&c, &ref)) {
    const FbBuffer fb = load_packet(ref, "TriggerPacket", &raw, &buf);
    const FbTable root = fb.root("TRIG");
    const FbVector v = fb.vector(root, 0, 4, "elements vector");
    out.reserve(out.size() + v.size);
    for (uint32_t j = 0; j < v.size; ++j) {
      const FbTable t = fb.vector_table(v, j, "Trigger table");
      const int64_t t_us = fb.scalar<int64_t>(t, 0, 0);
      const int8_t type = fb.scalar<int8_t>(t, 1, 0);
      // Where, for error messages only (built on the bad path, not per trigger).
      const auto at = [&] { return "trigger " + num(j) + " of the packet at byte offset " + num(ref.offset); };
      Trigger tr;
      if (!us_to_ns(t_us, &tr.t_ns)) {
        bad.bad(at() + ": timestamp " + num(t_us) + " us does not fit in int64 nanoseconds", form);
        continue;
      }
      if (tr.t_ns < last) {
        bad.bad(at() + ": timestamp " + format_seconds(tr.t_ns) + " s is earlier than the previous trigger's " +
                    format_seconds(last) + " s",
                form);
        continue;
      }
      last = tr.t_ns;
      tr.channel = type;
      tr.polarity = (type == 2 || type == 5) ? int8_t{-1} : int8_t{1};  // falling edges
      out.push_back(tr);
    }
  }
  bad.finish();
  return out;
}

std::vector<StreamInfo> Aedat4Reader::streams() const {
  std::vector<StreamInfo> out;
  for (size_t k = 0; k < streams_.size(); ++k) {
    const Stream& s = streams_[k];
    StreamInfo i;
    i.count_unit = "packets";
    i.name = s.name + " (id " + num(s.id) + ")";
    i.type = s.type;
    if (counts_known_) {
      const auto it = packet_counts_.find(s.id);
      i.messages = it == packet_counts_.end() ? 0 : it->second;
    } else {
      i.messages = -1;
    }
    const int ki = static_cast<int>(k);
    i.selected = ki == event_stream_ || ki == imu_stream_ || ki == frame_stream_ || ki == trigger_stream_;
    out.push_back(std::move(i));
  }
  return out;
}

}  // namespace

std::unique_ptr<DatasetReader> open_aedat4_dataset(const std::string& path, const DatasetOptions& options) {
  return std::make_unique<Aedat4Reader>(path, options);
}

}  // namespace evio
