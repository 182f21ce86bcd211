// libFuzzer target: the CDR message decoders of the ROS 2 bag reader. The first input byte picks
// the message type; the rest is one CDR message (encapsulation header included), written into a
// minimal uncompressed MCAP file (Header, Schema, Channel, two copies of the Message, Footer with
// no summary) that is read through open_rosbag2_dataset with both bad-data policies.
#include <cstdint>
#include <string>

#include "evio/calib/error.h"
#include "evio/sensors/rosbag2.h"
#include "fuzz_support.h"

namespace {

void put(std::string* s, uint64_t v, int bytes) {
  for (int i = 0; i < bytes; ++i) s->push_back(static_cast<char>((v >> (8 * i)) & 0xFF));
}
void put_str(std::string* s, const std::string& v) {
  put(s, v.size(), 4);
  *s += v;
}
void record(std::string* file, uint8_t op, const std::string& content) {
  file->push_back(static_cast<char>(op));
  put(file, content.size(), 8);
  *file += content;
}

// The MCAP records per the specification (mcap.dev/spec); no chunks, no summary.
std::string mcap_with(const std::string& type, const std::string& message) {
  std::string f("\x89MCAP0\r\n", 8), c;
  put_str(&c, "ros2");
  put_str(&c, "fuzz");
  record(&f, 0x01, c);  // Header
  c.clear();
  put(&c, 1, 2);
  put_str(&c, type);
  put_str(&c, "ros2msg");
  put(&c, 0, 4);
  record(&f, 0x03, c);  // Schema
  c.clear();
  put(&c, 1, 2);
  put(&c, 1, 2);
  put_str(&c, "/topic");
  put_str(&c, "cdr");
  put(&c, 0, 4);
  record(&f, 0x04, c);  // Channel
  for (uint64_t t : {1000, 2000}) {
    c.clear();
    put(&c, 1, 2);
    put(&c, 0, 4);
    put(&c, t, 8);
    put(&c, t, 8);
    c += message;
    record(&f, 0x05, c);  // Message
  }
  record(&f, 0x0F, std::string(4, '\0'));  // Data End
  c.clear();
  put(&c, 0, 8);
  put(&c, 0, 8);
  put(&c, 0, 4);
  record(&f, 0x02, c);  // Footer
  f += std::string("\x89MCAP0\r\n", 8);
  return f;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  evio_fuzz::silence_log();
  if (size < 1) return 0;
  static const char* kTypes[] = {"dvs_msgs/msg/EventArray", "prophesee_event_msgs/msg/EventArray",
                                 "event_camera_msgs/msg/EventPacket", "sensor_msgs/msg/Imu", "sensor_msgs/msg/Image"};
  const std::string type = kTypes[data[0] % 5];
  const std::string file = mcap_with(type, std::string(reinterpret_cast<const char*>(data + 1), size - 1));
  evio_fuzz::MemFile mem(reinterpret_cast<const uint8_t*>(file.data()), file.size());
  if (!mem.ok()) return 0;
  for (const auto policy : {evio::BadLinePolicy::kError, evio::BadLinePolicy::kWarnAndSkip}) {
    try {
      evio::DatasetOptions options;
      options.text.on_bad_line = policy;
      auto reader = evio::open_rosbag2_dataset(mem.path(), options);
      reader->streams();
      evio::EventBuffer events;
      while (reader->read_events(&events, 4096) > 0) events.clear();
      reader->read_triggers();
      reader->read_imu();
      reader->read_frames();
    } catch (const evio::InputError&) {
    }
  }
  return 0;
}
