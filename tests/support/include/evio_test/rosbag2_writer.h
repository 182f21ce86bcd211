// ROS 2 bags for tests: a CDR serialiser, the event/IMU/image messages evio reads, and a rosbag2
// writer (SQLite3 or MCAP storage, split files, metadata.yaml, zstd per message or per file).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "evio/sensors/measurements.h"

namespace evio_test {

// Plain CDR (XCDR1): 4-byte encapsulation header, then primitives aligned to their size from the
// byte after it.
class CdrWriter {
 public:
  explicit CdrWriter(bool big_endian = false);
  void u8(uint8_t v);
  void u16(uint16_t v);
  void u32(uint32_t v);
  void i32(int32_t v);
  void u64(uint64_t v);
  void f64(double v);
  void string(const std::string& s);  // uint32 length with the NUL, bytes, NUL
  void bytes(const std::string& b);   // uint8[]: uint32 count + bytes
  void header(int64_t stamp_ns, const std::string& frame_id = "cam0");  // builtin_interfaces/Time + frame_id
  const std::string& data() const { return out_; }

 private:
  void align(size_t n);
  void put(const void* p, size_t n);
  bool big_;
  std::string out_;
};

// dvs_msgs/msg/EventArray (and prophesee_event_msgs/msg/EventArray, the same layout).
std::string cdr_event_array(int64_t stamp_ns, uint32_t width, uint32_t height, const std::vector<evio::Event>& events,
                            bool big_endian = false);
// event_camera_msgs/msg/EventPacket with a raw payload in `encoding` ("evt3", "evt2", "mono").
std::string cdr_event_packet(int64_t stamp_ns, uint32_t width, uint32_t height, const std::string& encoding,
                             const std::string& payload, bool big_endian = false, uint64_t time_base = 0);
// The "mono" payload of events at stamp_ns + dt (dt < 2^32 ns).
std::string mono_payload(int64_t stamp_ns, const std::vector<evio::Event>& events);
std::string cdr_imu(const evio::ImuSample& s, bool big_endian = false);
std::string cdr_image(int64_t stamp_ns, uint32_t width, uint32_t height, const std::string& encoding, uint32_t step,
                      const std::string& data, bool big_endian = false);

struct Rosbag2WriterOptions {
  std::string storage = "sqlite3";      // "sqlite3" or "mcap"
  std::string mcap_compression;         // MCAP chunks: "", "lz4", "zstd"
  size_t mcap_chunk_size = 64 * 1024;   // bytes; 0 = no chunks
  bool mcap_summary = true;
  std::string compression_mode;         // "", "message" or "file" (zstd)
  size_t split_messages = 0;            // > 0: a new storage file after this many messages
  bool metadata = true;                 // write metadata.yaml
};

// Writes a bag folder: <folder>/<name>_<i>.db3|.mcap[.zstd] and metadata.yaml.
class Rosbag2Writer {
 public:
  Rosbag2Writer(const std::string& folder, Rosbag2WriterOptions options = {});
  ~Rosbag2Writer();
  size_t add_topic(const std::string& name, const std::string& type);
  void write(size_t topic, int64_t timestamp_ns, const std::string& cdr);
  void close();
  const std::vector<std::string>& files() const { return files_; }

 private:
  struct Impl;
  void open_next();
  void close_current();
  std::string folder_;
  Rosbag2WriterOptions o_;
  std::unique_ptr<Impl> impl_;
  std::vector<std::string> files_;
  std::vector<std::string> topic_names_, topic_types_;
  std::vector<int64_t> counts_;
  size_t in_file_ = 0;
  int64_t t_min_ = INT64_MAX, t_max_ = INT64_MIN;
  bool closed_ = false;
};

}  // namespace evio_test
