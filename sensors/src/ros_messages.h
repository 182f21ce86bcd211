// ROS messages without ROS, shared by the ROS1 bag reader (rosbag.cc) and the ROS 2 bag reader
// (rosbag2.cc): the two wire formats, a container-neutral message source, and the DatasetReader
// that selects topics and decodes events, IMU and images from any source. Internal to
// evio::sensors.
//
// Wire formats:
//  - ROS1 serialisation: little-endian, packed (no alignment); std_msgs/Header is uint32 seq,
//    time stamp (uint32 sec, uint32 nsec), string frame_id; strings are uint32 length + bytes.
//  - CDR (OMG CDR / XCDR1, as rmw serialises ROS 2 messages): a 4-byte encapsulation header
//    (0x00 0x00 big-endian, 0x00 0x01 little-endian, 2 option bytes), then every primitive aligned
//    to its own size (at most 8) counted from the byte after that header; std_msgs/Header is
//    builtin_interfaces/Time stamp (int32 sec, uint32 nanosec), string frame_id; strings are uint32
//    length including a terminating NUL, then the bytes; sequences are uint32 count + elements,
//    fixed arrays have no count. Up to 7 bytes of padding after the last field are accepted.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "evio/sensors/dataset.h"

namespace evio::detail::ros {

enum class Serialization { kRos1, kCdr };

// A topic (ROS1: a connection; a topic recorded by several publishers appears once per
// connection) of a container.
struct Topic {
  std::string name;
  std::string type;      // as recorded, e.g. "dvs_msgs/EventArray" or "dvs_msgs/msg/EventArray"
  std::string encoding;  // "ros1" or "cdr" (rosbag2: the topic's serialization_format)
  int64_t messages = -1;  // -1 when unknown without a pass over the data
};

// "pkg/msg/Type" -> "pkg/Type" (ROS 2 names the message subfolder); ROS1 names pass unchanged.
std::string canonical_type(std::string_view type);

struct MessageView {
  size_t topic = 0;  // index into MessageSource::topics()
  const uint8_t* data = nullptr;
  size_t size = 0;  // valid until the next call of next()
};

// Messages of some topics in the container's order.
class MessageCursor {
 public:
  virtual ~MessageCursor() = default;
  virtual bool next(MessageView* m) = 0;  // false at the end; InputError on bad data
  // Where byte k of the current message's data lies, e.g. "byte offset 12 of the decompressed
  // zstd chunk at byte offset 4096" (for error messages).
  virtual std::string at(uint64_t k) const = 0;
  virtual double progress() const = 0;  // fraction in [0, 1] of the selected data consumed
};

class MessageSource {
 public:
  virtual ~MessageSource() = default;
  virtual const std::string& path() const = 0;
  virtual const std::vector<Topic>& topics() const = 0;
  // Messages of `topics`; with start_ns > INT64_MIN (only when seekable()), from the first message
  // whose container time (rosbag2: receive time) is at or after start_ns, found by the index.
  virtual std::unique_ptr<MessageCursor> cursor(const std::vector<size_t>& topics,
                                                int64_t start_ns = INT64_MIN) const = 0;
  // The container has a time index (SQLite3 timestamp index, MCAP summary with chunk indexes).
  virtual bool seekable() const { return false; }
  virtual DatasetFormat format() const = 0;
  // One line for the open log, e.g. "ROS bag 2.0, 3 connection(s), 12 chunk(s)".
  virtual std::string describe() const = 0;
  // How message times are stated, for ReadReport (e.g. "rosbag2 (sqlite3)").
  virtual std::string container_name() const = 0;
};

// The DatasetReader over a source (see rosbag.h and rosbag2.h for the behaviour).
std::unique_ptr<DatasetReader> open_ros_dataset(std::unique_ptr<MessageSource> source, const DatasetOptions& options);

}  // namespace evio::detail::ros
