#include "evio/sensors/rosbag.h"

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
#include "rosbag_container.h"
#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio/sensors/evt.h"
#include "binary_file.h"
#include "text_common.h"

#if !defined(__BYTE_ORDER__) || __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "the ROS bag reader assumes a little-endian host (ROS1 serialisation is little-endian)"
#endif

namespace evio {
namespace {
constexpr char kTypeEventArray[] = "dvs_msgs/EventArray";
constexpr char kTypeEventPacket[] = "event_camera_msgs/EventPacket";
constexpr char kTypeImu[] = "sensor_msgs/Imu";
constexpr char kTypeImage[] = "sensor_msgs/Image";

constexpr char kFormEventArray[] =
    "dvs_msgs/EventArray: std_msgs/Header header, uint32 height, uint32 width, Event[] events with "
    "Event = uint16 x, uint16 y, time ts (uint32 sec, uint32 nsec), bool polarity";
constexpr char kFormEventPacket[] =
    "event_camera_msgs/EventPacket: std_msgs/Header header, uint32 height, uint32 width, uint64 seq, "
    "uint64 time_base, string encoding, bool is_bigendian, uint8[] events";
constexpr char kFormImu[] =
    "sensor_msgs/Imu: std_msgs/Header header, orientation (4 float64) + covariance (9 float64), "
    "angular_velocity (3 float64) + covariance (9), linear_acceleration (3 float64) + covariance (9)";
constexpr char kFormImage[] =
    "sensor_msgs/Image: std_msgs/Header header, uint32 height, uint32 width, string encoding, "
    "uint8 is_bigendian, uint32 step, uint8[] data";

using detail::load_le;
using namespace detail::rosbag;  // NOLINT: the bag container

// ---------------------------------------------------------------------------------------------
// ROS1 message deserialisation with bounds checks.

class MsgReader {
 public:
  MsgReader(const std::string& path, const Message& m, const char* form)
      : path_(path), m_(m), form_(form), p_(m.data), end_(m.data + m.size) {}

  [[noreturn]] void fail(const std::string& problem, const uint8_t* at) const {
    throw InputError(path_, 0,
                     m_.conn->type + " message on " + m_.conn->topic + ": " + problem + " at " +
                         m_.where->at(m_.off + static_cast<uint64_t>(at - m_.data)),
                     form_);
  }
  void need(uint64_t n, const char* what) const {
    if (n > static_cast<uint64_t>(end_ - p_)) {
      fail(std::string(what) + " of " + std::to_string(n) + " bytes runs past the end of the " +
               std::to_string(m_.size) + "-byte message (" + std::to_string(end_ - p_) + " bytes left)",
           p_);
    }
  }
  uint8_t u8(const char* what) {
    need(1, what);
    return *p_++;
  }
  uint32_t u32(const char* what) {
    need(4, what);
    const uint32_t v = load_le<uint32_t>(p_);
    p_ += 4;
    return v;
  }
  uint64_t u64(const char* what) {
    need(8, what);
    const uint64_t v = load_le<uint64_t>(p_);
    p_ += 8;
    return v;
  }
  double f64(const char* what) {
    need(8, what);
    double v;
    std::memcpy(&v, p_, 8);
    p_ += 8;
    return v;
  }
  void skip(size_t n, const char* what) {
    need(n, what);
    p_ += n;
  }
  std::string_view string(const char* what) {
    const uint8_t* at = p_;
    const uint32_t n = u32(what);
    if (n > static_cast<uint64_t>(end_ - p_)) {
      fail(std::string(what) + " string of " + std::to_string(n) + " bytes runs past the end of the message (" +
               std::to_string(end_ - p_) + " bytes left)",
           at);
    }
    const std::string_view s(reinterpret_cast<const char*>(p_), n);
    p_ += n;
    return s;
  }
  // uint32 count + count elements of elem_size bytes; returns the first element, checked to fit.
  const uint8_t* array(size_t elem_size, const char* what, uint32_t* count) {
    const uint8_t* at = p_;
    *count = u32(what);
    const uint64_t bytes = uint64_t{*count} * elem_size;
    if (bytes > static_cast<uint64_t>(end_ - p_)) {
      fail(std::string(what) + " array of " + std::to_string(*count) + " x " + std::to_string(elem_size) +
               " bytes runs past the end of the " + std::to_string(m_.size) + "-byte message (" +
               std::to_string(end_ - p_) + " bytes left)",
           at);
    }
    const uint8_t* first = p_;
    p_ += bytes;
    return first;
  }
  // std_msgs/Header: uint32 seq, time stamp, string frame_id. Returns the stamp in ns.
  int64_t header() {
    u32("header.seq");
    const uint32_t sec = u32("header.stamp.sec");
    const uint32_t nsec = u32("header.stamp.nsec");
    string("header.frame_id");
    return ros_time_ns(sec, nsec);
  }
  void expect_end() const {
    if (p_ != end_) fail(std::to_string(end_ - p_) + " unexpected bytes after the last field", p_);
  }
  const uint8_t* pos() const { return p_; }
  uint64_t offset_of(const uint8_t* at) const { return m_.off + static_cast<uint64_t>(at - m_.data); }

 private:
  const std::string& path_;
  const Message& m_;
  const char* form_;
  const uint8_t* p_;
  const uint8_t* end_;
};

bool is_event_type(const std::string& t) { return t == kTypeEventArray || t == kTypeEventPacket; }

std::string list_topics(const Bag& bag, bool (*pred)(const std::string&)) {
  std::vector<std::pair<std::string, std::string>> seen;
  for (const Connection& c : bag.connections) {
    if (pred != nullptr && !pred(c.type)) continue;
    const std::pair<std::string, std::string> tt(c.topic, c.type);
    if (std::find(seen.begin(), seen.end(), tt) == seen.end()) seen.push_back(tt);
  }
  std::string s;
  for (const auto& tt : seen) s += (s.empty() ? "" : ", ") + tt.first + " (" + tt.second + ")";
  return s.empty() ? "none" : s;
}

struct Selection {
  std::string topic, type;
  std::vector<uint32_t> conns;
  bool empty() const { return conns.empty(); }
};

Selection select_topic(const Bag& bag, const std::string& requested, bool (*accepts)(const std::string&),
                       const char* kind, const char* types_text, const char* option) {
  Selection s;
  if (!requested.empty()) {
    for (const Connection& c : bag.connections) {
      if (c.topic != requested) continue;
      if (!accepts(c.type)) {
        throw InputError(bag.path, 0,
                         std::string("topic '") + requested + "' chosen for " + kind + " has type " + c.type,
                         std::string("a topic of type ") + types_text + "; " + kind +
                             " topics in this bag: " + list_topics(bag, accepts));
      }
      if (!s.type.empty() && s.type != c.type) {
        throw InputError(bag.path, 0,
                         "topic '" + requested + "' carries two message types, " + s.type + " and " + c.type,
                         "one message type per topic");
      }
      s.topic = requested;
      s.type = c.type;
      s.conns.push_back(c.id);
    }
    if (s.conns.empty()) {
      throw InputError(bag.path, 0, std::string("topic '") + requested + "' chosen for " + kind + " is not in the bag",
                       std::string("one of the bag's topics: ") + list_topics(bag, nullptr));
    }
    return s;
  }
  std::vector<std::string> topics;
  for (const Connection& c : bag.connections) {
    if (accepts(c.type) && std::find(topics.begin(), topics.end(), c.topic) == topics.end()) topics.push_back(c.topic);
  }
  if (topics.size() > 1) {
    throw InputError(bag.path, 0, std::string("several ") + kind + " topics: " + list_topics(bag, accepts),
                     std::string("name the one to read (") + option + ")");
  }
  if (topics.empty()) return s;
  return select_topic(bag, topics[0], accepts, kind, types_text, option);
}

bool accepts_events(const std::string& t) { return is_event_type(t); }
bool accepts_imu(const std::string& t) { return t == kTypeImu; }
bool accepts_image(const std::string& t) { return t == kTypeImage; }

// ---------------------------------------------------------------------------------------------
// The event stream of the selected topic.

class EventStream {
 public:
  EventStream(const Bag& bag, const Selection& sel, SensorSize sensor, const DatasetOptions& options, bool log_end)
      : bag_(bag),
        sel_(sel),
        packets_(sel.type == kTypeEventPacket),
        width_(static_cast<uint32_t>(sensor.width)),
        height_(static_cast<uint32_t>(sensor.height)),
        bounded_(sensor.known()),
        options_(options),
        log_end_(log_end),
        cursor_(bag, sel.conns) {
    report_.path = bag.path;
    report_.time_unit = TimeUnit::kNanoseconds;
    report_.polarity = PolarityConvention::kZeroOne;
    if (packets_) {
      report_.time_unit_reason =
          "evt3 sensor time in us, put on the ROS clock by the header.stamp of the first packet with a sensor time "
          "(event_camera_msgs/EventPacket on " + sel.topic + ")";
    } else {
      report_.time_unit_reason = "ROS time (uint32 sec, uint32 nsec) of each event (dvs_msgs/EventArray on " +
                                 sel.topic + ")";
    }
  }

  size_t read(EventBuffer* out, size_t max_events) {
    std::vector<Event>& v = out->events();
    const size_t n0 = v.size();
    if (pending_pos_ < pending_.size()) {
      const size_t k = std::min(max_events, pending_.size() - pending_pos_);
      v.insert(v.end(), pending_.begin() + static_cast<std::ptrdiff_t>(pending_pos_),
               pending_.begin() + static_cast<std::ptrdiff_t>(pending_pos_ + k));
      pending_pos_ += k;
      if (pending_pos_ == pending_.size()) {
        pending_.clear();
        pending_pos_ = 0;
      }
    }
    Message m;
    while (v.size() - n0 < max_events && cursor_.next(&m)) {
      ++report_.lines;
      if (packets_) {
        decode_packet(m, &v);
      } else {
        decode_event_array(m, &v);
      }
    }
    if (v.size() - n0 > max_events) {
      pending_.assign(v.begin() + static_cast<std::ptrdiff_t>(n0 + max_events), v.end());
      pending_pos_ = 0;
      v.resize(n0 + max_events);
    }
    const size_t n = v.size() - n0;
    report_.records += static_cast<int64_t>(n);
    if (n == 0 && !finished_) finish();
    return n;
  }

  bool finished() const { return finished_; }
  double progress() const { return cursor_.progress(); }
  const ReadReport& report() const { return report_; }
  const std::vector<Trigger>& triggers() const { return triggers_; }

 private:
  void finish() {
    finished_ = true;
    detail::BadLineHandler(bag_.path, options_.text.on_bad_line, &report_).finish();
    if (!log_end_) return;
    std::string s = bag_.path + ": " + std::to_string(report_.records) + " events from " + sel_.topic + " (" +
                    sel_.type + ", " + std::to_string(report_.lines) + " messages)";
    if (packets_) {
      const EvtDecodeStats& st = decoder_.stats();
      s += ", " + std::to_string(st.triggers) + " trigger events";
      if (st.events_before_time > 0) {
        s += ", " + std::to_string(st.events_before_time) + " events before the first evt3 time base dropped";
      }
      if (!offset_set_) s += ", no evt3 time base found";
    }
    log_info(s);
  }

  void bad(const char* kind, uint64_t off, const Where& where, const std::string& problem) {
    detail::BadLineHandler(bag_.path, options_.text.on_bad_line, &report_)
        .bad(kind, 0, problem + " at " + where.at(off),
             packets_ ? std::string(kFormEventPacket) + "; events inside the sensor, in time order"
                      : std::string(kFormEventArray) + "; events inside the sensor, in time order");
  }

  std::string event_name(size_t i) const {
    return "event " + std::to_string(i) + (packets_ ? " of the evt3 payload of a message on " : " of a message on ") +
           sel_.topic + ": ";
  }
  std::string outside(uint32_t x, uint32_t y) const {
    return "pixel (" + std::to_string(x) + ", " + std::to_string(y) + ") outside the " + std::to_string(width_) + "x" +
           std::to_string(height_) + " sensor";
  }
  std::string earlier(int64_t t) const {
    return "timestamp " + format_seconds(t) + " s is earlier than the previous event's " + format_seconds(last_t_ns_) +
           " s";
  }

  void decode_event_array(const Message& m, std::vector<Event>* v) {
    MsgReader r(bag_.path, m, kFormEventArray);
    r.header();
    r.u32("height");
    r.u32("width");
    uint32_t count = 0;
    const uint8_t* p = r.array(13, "events", &count);
    r.expect_end();
    const size_t n0 = v->size();
    v->resize(n0 + count);
    Event* out = v->data() + n0;
    size_t k = 0;
    int64_t last = last_t_ns_;
    const uint32_t w = bounded_ ? width_ : 65536u, h = bounded_ ? height_ : 65536u;
    for (uint32_t i = 0; i < count; ++i, p += 13) {
      const uint32_t x = load_le<uint16_t>(p), y = load_le<uint16_t>(p + 2);
      const int64_t t = ros_time_ns(load_le<uint32_t>(p + 4), load_le<uint32_t>(p + 8));
      if (x >= w || y >= h || t < last) {
        last_t_ns_ = last;
        if (x >= w || y >= h) {
          bad("outside sensor", r.offset_of(p), *m.where, event_name(i) + outside(x, y));
        } else {
          bad("time order", r.offset_of(p), *m.where, event_name(i) + earlier(t));
        }
        continue;
      }
      last = t;
      Event& e = out[k++];
      e.t_ns = t;
      e.x = static_cast<uint16_t>(x);
      e.y = static_cast<uint16_t>(y);
      e.polarity = p[12] != 0 ? 1 : -1;
    }
    last_t_ns_ = last;
    v->resize(n0 + k);
  }

  void decode_packet(const Message& m, std::vector<Event>* v) {
    MsgReader r(bag_.path, m, kFormEventPacket);
    const int64_t stamp = r.header();
    r.u32("height");
    r.u32("width");
    r.u64("seq");
    r.u64("time_base");
    const uint8_t* enc_at = r.pos();
    const std::string_view encoding = r.string("encoding");
    const uint8_t big_endian = r.u8("is_bigendian");
    uint32_t size = 0;
    const uint8_t* payload_at = r.pos();
    const uint8_t* payload = r.array(1, "events", &size);
    r.expect_end();
    if (encoding != "evt3") {
      r.fail("encoding '" + printable(encoding) + "' is not supported (only evt3 is)", enc_at);
    }
    if (big_endian != 0) r.fail("big-endian evt3 payload (is_bigendian=1) is not supported", payload_at);
    if (size % 2 != 0) r.fail("evt3 payload of " + std::to_string(size) + " bytes is not a whole number of 16-bit words", payload_at);
    const size_t n0 = v->size();
    const size_t t0 = triggers_.size();
    decoder_.decode(payload, size, v, &triggers_);
    if (!offset_set_ && decoder_.has_time()) {
      // First packet with a sensor time: relate its first decoded time to the packet's header stamp.
      int64_t first = decoder_.current_time_us() * 1000;
      if (v->size() > n0) first = (*v)[n0].t_ns;
      if (triggers_.size() > t0) first = std::min(first, triggers_[t0].t_ns);
      const int64_t offset = stamp - first;
      for (size_t i = n0; i < v->size(); ++i) (*v)[i].t_ns += offset;
      for (size_t i = t0; i < triggers_.size(); ++i) triggers_[i].t_ns += offset;
      decoder_.set_time_offset_ns(offset);
      offset_set_ = true;
    }
    // Validate in place: inside the sensor and in time order.
    Event* e = v->data();
    const size_t end = v->size();
    size_t k = n0;
    int64_t last = last_t_ns_;
    const uint32_t w = bounded_ ? width_ : 65536u, h = bounded_ ? height_ : 65536u;
    for (size_t i = n0; i < end; ++i) {
      const Event ev = e[i];
      if (ev.x >= w || ev.y >= h || ev.t_ns < last) {
        last_t_ns_ = last;
        const std::string what = event_name(i - n0);
        if (ev.x >= w || ev.y >= h) {
          bad("outside sensor", r.offset_of(payload), *m.where, what + outside(ev.x, ev.y));
        } else {
          bad("time order", r.offset_of(payload), *m.where, what + earlier(ev.t_ns));
        }
        continue;
      }
      last = ev.t_ns;
      e[k++] = ev;
    }
    last_t_ns_ = last;
    v->resize(k);
  }

  const Bag& bag_;
  Selection sel_;
  bool packets_;
  uint32_t width_, height_;
  bool bounded_;
  const DatasetOptions& options_;
  bool log_end_;
  MessageCursor cursor_;
  ReadReport report_;
  std::vector<Event> pending_;
  size_t pending_pos_ = 0;
  int64_t last_t_ns_ = INT64_MIN;
  bool finished_ = false;
  Evt3Decoder decoder_;
  bool offset_set_ = false;
  std::vector<Trigger> triggers_;
};

// OpenCV's fixed-point BT.601 weights for RGB -> grey (0.299, 0.587, 0.114 scaled by 2^14).
inline uint8_t grey(uint32_t r, uint32_t g, uint32_t b) {
  return static_cast<uint8_t>((r * 4899u + g * 9617u + b * 1868u + (1u << 13)) >> 14);
}

class RosbagReader final : public DatasetReader {
 public:
  RosbagReader(const std::string& path, const DatasetOptions& options) : path_(path), options_(options) {
    std::string why;
    if (!options_.Validate(&why)) throw InputError(path, 0, "invalid dataset options: " + why);
    bag_ = open_bag(path);
    events_ = select_topic(*bag_, options_.topics.events, accepts_events, "events",
                           "dvs_msgs/EventArray or event_camera_msgs/EventPacket", "BagTopics::events");
    imu_ = select_topic(*bag_, options_.topics.imu, accepts_imu, "IMU", "sensor_msgs/Imu", "BagTopics::imu");
    image_ = select_topic(*bag_, options_.topics.image, accepts_image, "image", "sensor_msgs/Image",
                          "BagTopics::image");
    if (!events_.empty()) sensor_ = first_event_sensor();
    if (!sensor_.known()) sensor_ = options_.text.sensor;
    stream_ = make_stream(true);
    std::string s = path + ": ROS bag 2.0, " + std::to_string(bag_->connections.size()) + " connection(s), " +
                    std::to_string(bag_->chunks.size()) + " chunk(s)";
    if (!events_.empty()) {
      s += "; events " + events_.topic + " (" + events_.type + "), " + std::to_string(sensor_.width) + "x" +
           std::to_string(sensor_.height);
    }
    if (!imu_.empty()) s += "; IMU " + imu_.topic;
    if (!image_.empty()) s += "; images " + image_.topic;
    log_info(s);
  }

  DatasetFormat format() const override { return DatasetFormat::kRosbag; }
  const std::string& path() const override { return path_; }
  SensorSize sensor_size() const override { return sensor_; }

  size_t read_events(EventBuffer* out, size_t max_events) override {
    if (!stream_) return 0;
    return stream_->read(out, max_events);
  }
  double progress() const override { return stream_ ? stream_->progress() : 1.0; }
  const ReadReport& event_report() const override { return stream_ ? stream_->report() : empty_report_; }

  std::vector<Trigger> read_triggers() override {
    if (!stream_ || events_.type != kTypeEventPacket) return {};
    if (stream_->finished()) return stream_->triggers();
    std::unique_ptr<EventStream> all = make_stream(false);
    EventBuffer sink;
    while (all->read(&sink, size_t{1} << 20) > 0) sink.clear();
    return all->triggers();
  }

  std::vector<ImuSample> read_imu() override {
    std::vector<ImuSample> out;
    if (imu_.empty()) return out;
    ReadReport rep;
    rep.path = path_;
    detail::BadLineHandler handler(path_, options_.text.on_bad_line, &rep);
    MessageCursor cursor(*bag_, imu_.conns);
    Message m;
    int64_t last = INT64_MIN;
    while (cursor.next(&m)) {
      MsgReader r(path_, m, kFormImu);
      ImuSample s;
      s.t_ns = r.header();
      r.skip(13 * 8, "orientation and its covariance");
      const uint8_t* at = r.pos();
      double v[6];
      for (int i = 0; i < 3; ++i) v[i] = r.f64("angular_velocity");
      r.skip(9 * 8, "angular_velocity_covariance");
      for (int i = 3; i < 6; ++i) v[i] = r.f64("linear_acceleration");
      r.skip(9 * 8, "linear_acceleration_covariance");
      r.expect_end();
      bool finite = true;
      for (double x : v) finite = finite && std::isfinite(x);
      if (!finite) {
        handler.bad("non-finite", 0, "NaN or infinite IMU value on " + imu_.topic + " at " + m.where->at(r.offset_of(at)),
                    kFormImu);
        continue;
      }
      if (s.t_ns <= last) {
        handler.bad("time order", 0,
                    "IMU stamp " + format_seconds(s.t_ns) + " s on " + imu_.topic + " is not after the previous " +
                        format_seconds(last) + " s at " + m.where->at(m.off),
                    std::string(kFormImu) + "; strictly increasing header stamps");
        continue;
      }
      last = s.t_ns;
      s.gyro = Eigen::Vector3d(v[0], v[1], v[2]);
      s.accel = Eigen::Vector3d(v[3], v[4], v[5]);
      out.push_back(s);
    }
    handler.finish();
    return out;
  }

  std::vector<Frame> read_frames() override {
    std::vector<Frame> out;
    if (image_.empty()) return out;
    ReadReport rep;
    rep.path = path_;
    detail::BadLineHandler handler(path_, options_.text.on_bad_line, &rep);
    MessageCursor cursor(*bag_, image_.conns);
    Message m;
    int64_t last = INT64_MIN;
    while (cursor.next(&m)) {
      MsgReader r(path_, m, kFormImage);
      Frame f;
      f.t_ns = r.header();
      const uint8_t* dims_at = r.pos();
      const uint32_t height = r.u32("height");
      const uint32_t width = r.u32("width");
      const uint8_t* enc_at = r.pos();
      const std::string_view encoding = r.string("encoding");
      r.u8("is_bigendian");
      const uint32_t step = r.u32("step");
      uint32_t size = 0;
      const uint8_t* data_at = r.pos();
      const uint8_t* data = r.array(1, "data", &size);
      r.expect_end();
      int channels = 0;
      bool bgr = false;
      if (encoding == "mono8") {
        channels = 1;
      } else if (encoding == "rgb8" || encoding == "bgr8") {
        channels = 3;
        bgr = encoding == "bgr8";
      } else {
        r.fail("image encoding '" + printable(encoding) + "' is not supported", enc_at);
      }
      if (width == 0 || height == 0 || width > 65535 || height > 65535) {
        r.fail("image size " + std::to_string(width) + "x" + std::to_string(height) + " outside 1..65535", dims_at);
      }
      if (uint64_t{step} < uint64_t{width} * static_cast<uint64_t>(channels)) {
        r.fail("step " + std::to_string(step) + " is smaller than width x " + std::to_string(channels) + " bytes", dims_at);
      }
      if (uint64_t{step} * height > size) {
        r.fail("data of " + std::to_string(size) + " bytes is shorter than step x height = " +
                   std::to_string(uint64_t{step} * height),
               data_at);
      }
      if (f.t_ns < last) {
        handler.bad("time order", 0,
                    "image stamp " + format_seconds(f.t_ns) + " s on " + image_.topic + " is earlier than the previous " +
                        format_seconds(last) + " s at " + m.where->at(m.off),
                    std::string(kFormImage) + "; non-decreasing header stamps");
        continue;
      }
      last = f.t_ns;
      f.image.create(static_cast<int>(height), static_cast<int>(width), CV_8UC1);
      for (uint32_t y = 0; y < height; ++y) {
        const uint8_t* src = data + uint64_t{step} * y;
        uint8_t* dst = f.image.ptr<uint8_t>(static_cast<int>(y));
        if (channels == 1) {
          std::memcpy(dst, src, width);
        } else {
          for (uint32_t x = 0; x < width; ++x, src += 3) {
            dst[x] = bgr ? grey(src[2], src[1], src[0]) : grey(src[0], src[1], src[2]);
          }
        }
      }
      out.push_back(std::move(f));
    }
    handler.finish();
    return out;
  }

  std::optional<Trajectory> read_groundtruth() override { return std::nullopt; }
  std::optional<calib::CameraCalibration> read_calibration() override { return std::nullopt; }

  std::vector<StreamInfo> streams() const override {
    std::vector<StreamInfo> out;
    for (const Connection& c : bag_->connections) {
      auto it = std::find_if(out.begin(), out.end(),
                             [&](const StreamInfo& s) { return s.name == c.topic && s.type == c.type; });
      if (it == out.end()) {
        StreamInfo s;
        s.name = c.topic;
        s.type = c.type;
        s.selected = (c.topic == events_.topic && c.type == events_.type) ||
                     (c.topic == imu_.topic && c.type == imu_.type) || (c.topic == image_.topic && c.type == image_.type);
        out.push_back(s);
        it = out.end() - 1;
      }
      it->messages += c.messages;
    }
    return out;
  }

 private:
  std::unique_ptr<EventStream> make_stream(bool log_end) const {
    if (events_.empty()) return nullptr;
    return std::make_unique<EventStream>(*bag_, events_, sensor_, options_, log_end);
  }

  // width x height of the first event message (both event types start with Header, height, width).
  SensorSize first_event_sensor() const {
    MessageCursor cursor(*bag_, events_.conns);
    Message m;
    if (!cursor.next(&m)) return SensorSize{};
    MsgReader r(path_, m, events_.type == kTypeEventPacket ? kFormEventPacket : kFormEventArray);
    r.header();
    const uint8_t* at = r.pos();
    const uint32_t height = r.u32("height");
    const uint32_t width = r.u32("width");
    if (width > 65536 || height > 65536) {
      r.fail("sensor size " + std::to_string(width) + "x" + std::to_string(height) + " exceeds 65536x65536", at);
    }
    return SensorSize{static_cast<int>(width), static_cast<int>(height)};
  }

  std::string path_;
  DatasetOptions options_;
  std::shared_ptr<Bag> bag_;
  Selection events_, imu_, image_;
  SensorSize sensor_;
  std::unique_ptr<EventStream> stream_;
  ReadReport empty_report_;
};

}  // namespace

std::unique_ptr<DatasetReader> open_rosbag_dataset(const std::string& path, const DatasetOptions& options) {
  return std::make_unique<RosbagReader>(path, options);
}

}  // namespace evio
