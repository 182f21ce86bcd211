#include "ros_messages.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <exception>
#include <string_view>
#include <utility>
#include <vector>

#include "byte_order.h"
#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio/sensors/evt.h"
#include "text_common.h"

#if !defined(__BYTE_ORDER__) || __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "the ROS message decoders assume a little-endian host"
#endif

namespace evio::detail::ros {

std::string canonical_type(std::string_view type) {
  const size_t slash = type.find('/');
  if (slash != std::string_view::npos && type.substr(slash, 5) == "/msg/") {
    return std::string(type.substr(0, slash)) + "/" + std::string(type.substr(slash + 5));
  }
  return std::string(type);
}

namespace {

constexpr char kTypeDvsArray[] = "dvs_msgs/EventArray";
constexpr char kTypePropheseeArray[] = "prophesee_event_msgs/EventArray";
constexpr char kTypeEventPacket[] = "event_camera_msgs/EventPacket";
constexpr char kTypeImu[] = "sensor_msgs/Imu";
constexpr char kTypeImage[] = "sensor_msgs/Image";

constexpr char kFormEventArray[] =
    "dvs_msgs/EventArray or prophesee_event_msgs/EventArray: std_msgs/Header header, uint32 height, uint32 width, "
    "Event[] events with Event = uint16 x, uint16 y, time ts, bool polarity";
constexpr char kFormEventPacket[] =
    "event_camera_msgs/EventPacket: std_msgs/Header header, uint32 height, uint32 width, uint64 seq, "
    "uint64 time_base, string encoding (evt3, evt2 or mono), bool is_bigendian, uint8[] events";
constexpr char kFormImu[] =
    "sensor_msgs/Imu: std_msgs/Header header, orientation (4 float64) + covariance (9 float64), "
    "angular_velocity (3 float64) + covariance (9), linear_acceleration (3 float64) + covariance (9)";
constexpr char kFormImage[] =
    "sensor_msgs/Image: std_msgs/Header header, uint32 height, uint32 width, string encoding, "
    "uint8 is_bigendian, uint32 step, uint8[] data";


bool is_event_array(const std::string& t) { return t == kTypeDvsArray || t == kTypePropheseeArray; }
bool accepts_events(const std::string& t) { return is_event_array(t) || t == kTypeEventPacket; }
bool accepts_imu(const std::string& t) { return t == kTypeImu; }
bool accepts_image(const std::string& t) { return t == kTypeImage; }

// ---------------------------------------------------------------------------------------------
// Deserialisation of one message (ROS1 or CDR) with bounds checks.

class MsgReader {
 public:
  MsgReader(const std::string& path, const Topic& topic, const MessageView& m, const MessageCursor& where,
            const char* form)
      : path_(path), topic_(topic), m_(m), where_(where), form_(form), p_(m.data), end_(m.data + m.size) {
    cdr_ = topic.encoding == "cdr";
    origin_ = m.data;
    if (!cdr_) return;
    if (m.size < 4) fail("CDR message of " + std::to_string(m.size) + " bytes has no 4-byte encapsulation header", p_);
    if (m.data[0] != 0 || m.data[1] > 1) {
      fail("CDR encapsulation 0x" + hex2(m.data[0]) + hex2(m.data[1]) +
               " is not plain CDR (0x0000 big-endian or 0x0001 little-endian)",
           p_);
    }
    swap_ = m.data[1] == 0;
    origin_ = p_ = m.data + 4;
  }

  [[noreturn]] void fail(const std::string& problem, const uint8_t* at) const {
    throw InputError(path_, 0,
                     topic_.type + " message on " + topic_.name + ": " + problem + " at " +
                         where_.at(static_cast<uint64_t>(at - m_.data)),
                     form_);
  }
  void need(uint64_t n, const char* what) const {
    if (n > static_cast<uint64_t>(end_ - p_)) {
      fail(std::string(what) + " of " + std::to_string(n) + " bytes runs past the end of the " +
               std::to_string(m_.size) + "-byte message (" + std::to_string(end_ - p_) + " bytes left)",
           p_);
    }
  }
  // CDR: the next field of `size` bytes starts at a multiple of its size (at most 8) from the origin.
  void align(size_t size, const char* what) {
    if (!cdr_ || size <= 1) return;
    const size_t off = static_cast<size_t>(p_ - origin_);
    const size_t pad = (size - off % size) % size;
    need(pad, what);
    p_ += pad;
  }
  template <typename T>
  T load(const uint8_t* p) const {
    const T v = load_le<T>(p);
    return swap_ ? byte_swap(v) : v;
  }
  template <typename T>
  T get(const char* what) {
    align(sizeof(T), what);
    need(sizeof(T), what);
    const T v = load<T>(p_);
    p_ += sizeof(T);
    return v;
  }
  uint8_t u8(const char* what) { return get<uint8_t>(what); }
  uint32_t u32(const char* what) { return get<uint32_t>(what); }
  uint64_t u64(const char* what) { return get<uint64_t>(what); }
  double f64(const char* what) {
    const uint64_t bits = get<uint64_t>(what);
    double v;
    std::memcpy(&v, &bits, 8);
    return v;
  }
  void skip_f64(size_t n, const char* what) {
    align(8, what);
    need(n * 8, what);
    p_ += n * 8;
  }
  std::string_view string(const char* what) {
    align(4, what);
    const uint8_t* at = p_;
    const uint32_t n = u32(what);
    if (n > static_cast<uint64_t>(end_ - p_)) {
      fail(std::string(what) + " string of " + std::to_string(n) + " bytes runs past the end of the message (" +
               std::to_string(end_ - p_) + " bytes left)",
           at);
    }
    std::string_view s(reinterpret_cast<const char*>(p_), n);
    p_ += n;
    if (cdr_ && !s.empty() && s.back() == '\0') s.remove_suffix(1);  // CDR counts the terminating NUL
    return s;
  }
  // uint32 count + count elements of elem_size bytes (a primitive type); returns the first element.
  const uint8_t* array(size_t elem_size, const char* what, uint32_t* count) {
    const uint8_t* at = p_;
    *count = u32(what);
    if (*count > 0) align(std::min<size_t>(elem_size, 8), what);
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
  // std_msgs/Header. Returns the stamp in ns.
  int64_t header() {
    if (!cdr_) {
      u32("header.seq");
      const uint32_t sec = u32("header.stamp.sec");
      const uint32_t nsec = u32("header.stamp.nsec");
      string("header.frame_id");
      return int64_t{sec} * 1000000000 + int64_t{nsec};
    }
    const auto sec = static_cast<int32_t>(u32("header.stamp.sec"));
    const uint32_t nsec = u32("header.stamp.nanosec");
    string("header.frame_id");
    return int64_t{sec} * 1000000000 + int64_t{nsec};
  }
  void expect_end() const {
    const auto left = static_cast<size_t>(end_ - p_);
    if (left == 0 || (cdr_ && left < 8)) return;  // CDR writers may pad the payload
    fail(std::to_string(left) + " unexpected bytes after the last field", p_);
  }

  bool cdr() const { return cdr_; }
  bool swapped() const { return swap_; }
  const uint8_t* pos() const { return p_; }
  void set_pos(const uint8_t* p) { p_ = p; }
  const uint8_t* origin() const { return origin_; }
  const uint8_t* end() const { return end_; }
  uint64_t offset_of(const uint8_t* at) const { return static_cast<uint64_t>(at - m_.data); }
  const MessageCursor& where() const { return where_; }

 private:
  static std::string hex2(uint8_t b) {
    static const char* d = "0123456789abcdef";
    return std::string{d[b >> 4], d[b & 15]};
  }

  const std::string& path_;
  const Topic& topic_;
  const MessageView& m_;
  const MessageCursor& where_;
  const char* form_;
  const uint8_t* p_;
  const uint8_t* end_;
  const uint8_t* origin_ = nullptr;
  bool cdr_ = false;
  bool swap_ = false;
};

// ---------------------------------------------------------------------------------------------
// Topic selection.

std::string list_topics(const MessageSource& src, bool (*pred)(const std::string&)) {
  std::vector<std::pair<std::string, std::string>> seen;
  for (const Topic& t : src.topics()) {
    if (pred != nullptr && !pred(canonical_type(t.type))) continue;
    const std::pair<std::string, std::string> tt(t.name, t.type);
    if (std::find(seen.begin(), seen.end(), tt) == seen.end()) seen.push_back(tt);
  }
  std::string s;
  for (const auto& tt : seen) s += (s.empty() ? "" : ", ") + tt.first + " (" + tt.second + ")";
  return s.empty() ? "none" : s;
}

struct Selection {
  std::string topic, type;  // type canonical
  std::vector<size_t> ids;  // indices into MessageSource::topics()
  bool empty() const { return ids.empty(); }
};

Selection select_topic(const MessageSource& src, const std::string& requested, bool (*accepts)(const std::string&),
                       const char* kind, const char* types_text, const char* option) {
  Selection s;
  const std::vector<Topic>& topics = src.topics();
  if (!requested.empty()) {
    for (size_t i = 0; i < topics.size(); ++i) {
      const Topic& t = topics[i];
      if (t.name != requested) continue;
      const std::string type = canonical_type(t.type);
      if (!accepts(type)) {
        throw InputError(src.path(), 0, std::string("topic '") + requested + "' chosen for " + kind + " has type " + t.type,
                         std::string("a topic of type ") + types_text + "; " + kind +
                             " topics in this bag: " + list_topics(src, accepts));
      }
      if (!s.type.empty() && s.type != type) {
        throw InputError(src.path(), 0,
                         "topic '" + requested + "' carries two message types, " + s.type + " and " + type,
                         "one message type per topic");
      }
      if (t.encoding != "ros1" && t.encoding != "cdr") {
        throw InputError(src.path(), 0,
                         "topic '" + requested + "' is serialised as '" + printable(t.encoding) + "'",
                         "ROS1 or CDR serialisation (rosbag2's serialization_format: cdr)");
      }
      s.topic = requested;
      s.type = type;
      s.ids.push_back(i);
    }
    if (s.ids.empty()) {
      throw InputError(src.path(), 0, std::string("topic '") + requested + "' chosen for " + kind + " is not in the bag",
                       std::string("one of the bag's topics: ") + list_topics(src, nullptr));
    }
    return s;
  }
  std::vector<std::string> names;
  for (const Topic& t : topics) {
    if (accepts(canonical_type(t.type)) && std::find(names.begin(), names.end(), t.name) == names.end()) {
      names.push_back(t.name);
    }
  }
  if (names.size() > 1) {
    throw InputError(src.path(), 0, std::string("several ") + kind + " topics: " + list_topics(src, accepts),
                     std::string("name the one to read (") + option + ")");
  }
  if (names.empty()) return s;
  return select_topic(src, names[0], accepts, kind, types_text, option);
}

// ---------------------------------------------------------------------------------------------
// The event stream of the selected topic.

// A seek starts at the messages received up to this long before the target: an event is assumed
// to reach the recorder within 1 s.
constexpr int64_t kSeekMarginNs = 1000000000;

class EventStream {
 public:
  // start_ns > INT64_MIN: only events at or after it, from the messages the index places after
  // start_ns - kSeekMarginNs.
  EventStream(const MessageSource& src, const Selection& sel, SensorSize sensor, const DatasetOptions& options,
              bool log_end, int64_t start_ns = INT64_MIN)
      : src_(src),
        path_(src.path()),
        sel_(sel),
        packets_(sel.type == kTypeEventPacket),
        width_(static_cast<uint32_t>(sensor.width)),
        height_(static_cast<uint32_t>(sensor.height)),
        bounded_(sensor.known()),
        options_(options),
        log_end_(log_end),
        start_ns_(start_ns),
        cursor_(src.cursor(sel.ids, start_ns == INT64_MIN ? INT64_MIN : start_ns - kSeekMarginNs)) {
    report_.path = path_;
    report_.time_unit = TimeUnit::kNanoseconds;
    report_.polarity = PolarityConvention::kZeroOne;
    if (packets_) {
      report_.time_unit_reason = "the payload's encoding (evt3, evt2: sensor time put on the ROS clock by the first "
                                 "packet's header.stamp; mono: header.stamp + dt) of event_camera_msgs/EventPacket on " +
                                 sel.topic + ", " + src.container_name();
    } else {
      report_.time_unit_reason = "ROS time (sec, nsec) of each event (" + sel.type + " on " + sel.topic + ", " +
                                 src.container_name() + ")";
    }
  }

  // Events are returned up to the first bad container data; its error is raised on the next call,
  // so nothing decoded before the damage is lost.
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
    if (v.size() == n0 && error_) std::rethrow_exception(std::exchange(error_, nullptr));
    MessageView m;
    size_t before = v.size(), triggers_before = triggers_.size();
    try {
      while (v.size() - n0 < max_events && !error_) {
        before = v.size();
        triggers_before = triggers_.size();
        if (!cursor_->next(&m)) break;
        ++report_.lines;
        const Topic& topic = src_.topics()[m.topic];
        if (packets_) {
          decode_packet(topic, m, &v);
        } else {
          decode_event_array(topic, m, &v);
        }
      }
    } catch (const InputError&) {
      v.resize(before);  // nothing of the message that failed
      triggers_.resize(triggers_before);
      if (v.size() == n0) throw;
      error_ = std::current_exception();
    }
    if (v.size() - n0 > max_events) {
      pending_.insert(pending_.end(), v.begin() + static_cast<std::ptrdiff_t>(n0 + max_events), v.end());
      v.resize(n0 + max_events);
    }
    const size_t n = v.size() - n0;
    report_.records += static_cast<int64_t>(n);
    if (n == 0 && !finished_) finish();
    return n;
  }

  bool finished() const { return finished_; }
  double progress() const { return cursor_->progress(); }
  const ReadReport& report() const { return report_; }
  const std::vector<Trigger>& triggers() const { return triggers_; }

 private:
  void finish() {
    finished_ = true;
    BadLineHandler(path_, options_.text.on_bad_line, &report_).finish();
    if (!log_end_) return;
    std::string s = path_ + ": " + std::to_string(report_.records) + " events from " + sel_.topic + " (" + sel_.type +
                    ", " + std::to_string(report_.lines) + " messages)";
    if (packets_ && decoding_ != Encoding::kMono && decoding_ != Encoding::kNone) {
      const EvtDecodeStats& st = decoding_ == Encoding::kEvt3 ? evt3_.stats() : evt2_.stats();
      s += ", " + std::to_string(st.triggers) + " trigger events";
      if (st.events_before_time > 0) {
        s += ", " + std::to_string(st.events_before_time) + " events before the first time base dropped";
      }
      if (!offset_set_) s += ", no time base found";
    }
    log_info(s);
  }

  void bad(const char* kind, const std::string& where, const std::string& problem) {
    BadLineHandler(path_, options_.text.on_bad_line, &report_)
        .bad(kind, 0, problem + " at " + where,
             std::string(packets_ ? kFormEventPacket : kFormEventArray) + "; events inside the sensor, in time order");
  }

  std::string event_name(size_t i) const {
    return "event " + std::to_string(i) + (packets_ ? " of the payload of a message on " : " of a message on ") +
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

  // Keeps the events of v[n0..] inside the sensor and in time order (the others follow the policy);
  // where(i) names the place of the message's event i.
  template <typename Where>
  void validate(std::vector<Event>* v, size_t n0, const Where& where) {
    Event* e = v->data();
    const size_t end = v->size();
    size_t k = n0;
    int64_t last = last_t_ns_;
    const uint32_t w = bounded_ ? width_ : 65536u, h = bounded_ ? height_ : 65536u;
    for (size_t i = n0; i < end; ++i) {
      const Event ev = e[i];
      if (ev.t_ns < start_ns_) continue;  // before the seek target
      if (ev.x >= w || ev.y >= h || ev.t_ns < last) {
        last_t_ns_ = last;
        if (ev.x >= w || ev.y >= h) {
          bad("outside sensor", where(i - n0), event_name(i - n0) + outside(ev.x, ev.y));
        } else {
          bad("time order", where(i - n0), event_name(i - n0) + earlier(ev.t_ns));
        }
        continue;
      }
      last = ev.t_ns;
      e[k++] = ev;
    }
    last_t_ns_ = last;
    v->resize(k);
  }

  void decode_event_array(const Topic& topic, const MessageView& m, std::vector<Event>* v) {
    MsgReader r(path_, topic, m, *cursor_, kFormEventArray);
    r.header();
    r.u32("height");
    r.u32("width");
    const size_t n0 = v->size();
    size_t first_off = 0;  // offset of event 0 from the CDR origin, or in the ROS1 message
    if (!r.cdr()) {
      // ROS1: packed 13-byte events (uint16 x, uint16 y, uint32 sec, uint32 nsec, uint8 polarity).
      uint32_t count = 0;
      const uint8_t* p = r.array(13, "events", &count);
      first_off = r.offset_of(p);
      r.expect_end();
      v->resize(n0 + count);
      Event* out = v->data() + n0;
      for (uint32_t i = 0; i < count; ++i, p += 13) {
        Event& e = out[i];
        e.x = load_le<uint16_t>(p);
        e.y = load_le<uint16_t>(p + 2);
        e.t_ns = int64_t{load_le<uint32_t>(p + 4)} * 1000000000 + int64_t{load_le<uint32_t>(p + 8)};
        e.polarity = p[12] != 0 ? 1 : -1;
      }
    } else {
      // CDR: each event aligned field by field (x, y at 2; sec, nanosec at 4; polarity 1 byte).
      const uint8_t* count_at = r.pos();
      const uint32_t count = r.u32("events");
      const uint8_t* o = r.origin();
      size_t off = static_cast<size_t>(r.pos() - o);
      const size_t size = static_cast<size_t>(r.end() - o);
      if (uint64_t{count} * 13 > size - off) {
        r.fail("events array of " + std::to_string(count) + " events (at least 13 bytes each) runs past the end of the "
               "message (" + std::to_string(size - off) + " bytes left)", count_at);
      }
      v->resize(n0 + count);
      Event* out = v->data() + n0;
      first_off = off;
      for (uint32_t i = 0; i < count; ++i) {
        off = (off + 1) & ~size_t{1};
        const size_t t_off = (off + 4 + 3) & ~size_t{3};
        if (t_off + 9 > size) r.fail("event " + std::to_string(i) + " runs past the end of the message", o + off);
        Event& e = out[i];
        e.x = r.load<uint16_t>(o + off);
        e.y = r.load<uint16_t>(o + off + 2);
        e.t_ns = int64_t{static_cast<int32_t>(r.load<uint32_t>(o + t_off))} * 1000000000 +
                 int64_t{r.load<uint32_t>(o + t_off + 4)};
        e.polarity = o[t_off + 8] != 0 ? 1 : -1;
        off = t_off + 9;
      }
      r.set_pos(o + off);
      r.expect_end();
    }
    const bool cdr = r.cdr();
    const uint64_t origin = r.offset_of(r.origin());
    validate(v, n0, [&](size_t i) {
      if (!cdr) return cursor_->at(first_off + 13 * i);
      size_t off = first_off;  // replays the CDR alignment up to event i
      for (size_t k = 0; k < i; ++k) off = (((((off + 1) & ~size_t{1}) + 4 + 3) & ~size_t{3}) + 9);
      return cursor_->at(origin + ((off + 1) & ~size_t{1}));
    });
  }

  enum class Encoding { kNone, kEvt3, kEvt2, kMono };

  template <typename Decoder>
  void decode_evt(Decoder* d, int64_t stamp, const uint8_t* payload, uint32_t size, std::vector<Event>* v) {
    const size_t n0 = v->size();
    const size_t t0 = triggers_.size();
    d->decode(payload, size, v, &triggers_);
    if (!offset_set_ && d->has_time()) {
      // First packet with a sensor time: relate its first decoded time to the packet's header stamp.
      int64_t first = d->current_time_us() * 1000;
      if (v->size() > n0) first = (*v)[n0].t_ns;
      if (triggers_.size() > t0) first = std::min(first, triggers_[t0].t_ns);
      const int64_t offset = stamp - first;
      for (size_t i = n0; i < v->size(); ++i) (*v)[i].t_ns += offset;
      for (size_t i = t0; i < triggers_.size(); ++i) triggers_[i].t_ns += offset;
      d->set_time_offset_ns(offset);
      offset_set_ = true;
    }
  }

  void decode_packet(const Topic& topic, const MessageView& m, std::vector<Event>* v) {
    MsgReader r(path_, topic, m, *cursor_, kFormEventPacket);
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
    Encoding enc = Encoding::kNone;
    size_t word = 0;
    if (encoding == "evt3") {
      enc = Encoding::kEvt3;
      word = 2;
    } else if (encoding == "evt2") {
      enc = Encoding::kEvt2;
      word = 4;
    } else if (encoding == "mono") {
      enc = Encoding::kMono;
      word = 8;
    } else {
      r.fail("encoding '" + printable(encoding) + "' is not supported (evt3, evt2 and mono are)", enc_at);
    }
    if (decoding_ != Encoding::kNone && enc != decoding_) {
      r.fail("encoding '" + printable(encoding) + "' differs from the topic's earlier packets", enc_at);
    }
    if (decoding_ == Encoding::kNone) {
      report_.time_unit_reason =
          enc == Encoding::kMono
              ? "mono payload: header.stamp + dt in ns (event_camera_msgs/EventPacket on " + sel_.topic + ", " +
                    src_.container_name() + ")"
              : std::string(encoding) + " sensor time in us, put on the ROS clock by the header.stamp of the first "
                "packet with a sensor time (event_camera_msgs/EventPacket on " + sel_.topic + ", " +
                    src_.container_name() + ")";
    }
    decoding_ = enc;
    if (big_endian != 0 && enc != Encoding::kMono) {
      r.fail("big-endian " + std::string(encoding) + " payload (is_bigendian=1) is not supported", payload_at);
    }
    if (size % word != 0) {
      r.fail(std::string(encoding) + " payload of " + std::to_string(size) + " bytes is not a whole number of " +
                 std::to_string(word * 8) + "-bit words",
             payload_at);
    }
    const size_t n0 = v->size();
    if (enc == Encoding::kEvt3) {
      decode_evt(&evt3_, stamp, payload, size, v);
    } else if (enc == Encoding::kEvt2) {
      decode_evt(&evt2_, stamp, payload, size, v);
    } else {
      // mono: 64-bit words, bit 63 polarity, bits 48-62 y, 32-47 x, 0-31 dt (ns after header.stamp).
      const size_t n = size / 8;
      v->resize(n0 + n);
      Event* out = v->data() + n0;
      for (size_t i = 0; i < n; ++i) {
        uint64_t w = load_le<uint64_t>(payload + 8 * i);
        if (big_endian != 0) w = byte_swap(w);
        Event& e = out[i];
        e.t_ns = stamp + static_cast<int64_t>(w & 0xFFFFFFFFu);
        e.x = static_cast<uint16_t>((w >> 32) & 0xFFFFu);
        e.y = static_cast<uint16_t>((w >> 48) & 0x7FFFu);
        e.polarity = (w >> 63) != 0 ? 1 : -1;
      }
      offset_set_ = true;
    }
    const std::string where = cursor_->at(r.offset_of(payload));
    validate(v, n0, [&](size_t) { return where; });
  }

  const MessageSource& src_;
  const std::string& path_;
  Selection sel_;
  bool packets_;
  uint32_t width_, height_;
  bool bounded_;
  const DatasetOptions& options_;
  bool log_end_;
  int64_t start_ns_;
  std::unique_ptr<MessageCursor> cursor_;
  ReadReport report_;
  std::vector<Event> pending_;
  size_t pending_pos_ = 0;
  int64_t last_t_ns_ = INT64_MIN;
  bool finished_ = false;
  std::exception_ptr error_;
  Encoding decoding_ = Encoding::kNone;
  Evt3Decoder evt3_;
  Evt2Decoder evt2_;
  bool offset_set_ = false;
  std::vector<Trigger> triggers_;
};

// OpenCV's fixed-point BT.601 weights for RGB -> grey (0.299, 0.587, 0.114 scaled by 2^14).
inline uint8_t grey(uint32_t r, uint32_t g, uint32_t b) {
  return static_cast<uint8_t>((r * 4899u + g * 9617u + b * 1868u + (1u << 13)) >> 14);
}

// Image encodings read: bytes per pixel, and where R, G, B (or the 16-bit value) lie.
struct PixelLayout {
  int bytes = 0;
  int r = 0, g = 0, b = 0;  // byte index of each colour in a pixel (colour encodings)
  bool mono16 = false;
};

bool pixel_layout(std::string_view enc, PixelLayout* l) {
  if (enc == "mono8" || enc == "8UC1") *l = PixelLayout{1, 0, 0, 0, false};
  else if (enc == "mono16" || enc == "16UC1") *l = PixelLayout{2, 0, 0, 0, true};
  else if (enc == "rgb8") *l = PixelLayout{3, 0, 1, 2, false};
  else if (enc == "bgr8") *l = PixelLayout{3, 2, 1, 0, false};
  else if (enc == "rgba8") *l = PixelLayout{4, 0, 1, 2, false};
  else if (enc == "bgra8") *l = PixelLayout{4, 2, 1, 0, false};
  else return false;
  return true;
}

class RosDatasetReader final : public DatasetReader {
 public:
  RosDatasetReader(std::unique_ptr<MessageSource> source, const DatasetOptions& options)
      : src_(std::move(source)), path_(src_->path()), options_(options) {
    std::string why;
    if (!options_.Validate(&why)) throw InputError(path_, 0, "invalid dataset options: " + why);
    events_ = select_topic(*src_, options_.topics.events, accepts_events, "events",
                           "dvs_msgs/EventArray, prophesee_event_msgs/EventArray or event_camera_msgs/EventPacket",
                           "BagTopics::events, --events-topic");
    imu_ = select_topic(*src_, options_.topics.imu, accepts_imu, "IMU", "sensor_msgs/Imu", "BagTopics::imu, --imu-topic");
    image_ = select_topic(*src_, options_.topics.image, accepts_image, "image", "sensor_msgs/Image",
                          "BagTopics::image, --image-topic");
    if (!events_.empty()) sensor_ = first_event_sensor();
    if (!sensor_.known()) sensor_ = options_.text.sensor;
    stream_ = make_stream(true);
    std::string s = path_ + ": " + src_->describe();
    if (!events_.empty()) {
      s += "; events " + events_.topic + " (" + events_.type + "), " + std::to_string(sensor_.width) + "x" +
           std::to_string(sensor_.height);
    }
    if (!imu_.empty()) s += "; IMU " + imu_.topic;
    if (!image_.empty()) s += "; images " + image_.topic;
    log_info(s);
  }

  DatasetFormat format() const override { return src_->format(); }
  const std::string& path() const override { return path_; }
  SensorSize sensor_size() const override { return sensor_; }

  size_t read_events(EventBuffer* out, size_t max_events) override {
    if (!stream_) return 0;
    return stream_->read(out, max_events);
  }
  double progress() const override { return stream_ ? stream_->progress() : 1.0; }
  const ReadReport& event_report() const override { return stream_ ? stream_->report() : empty_report_; }

  // With a time index, EventArray topics (each event stamped) start at the first message received
  // after t_ns - 1 s; EventPacket payloads need the decoder's time state from the first packet,
  // so they are not seeked (false: the caller reads through).
  bool seek_events(int64_t t_ns) override {
    if (!stream_) return true;
    if (!src_->seekable() || events_.type == kTypeEventPacket) return false;
    stream_ = std::make_unique<EventStream>(*src_, events_, sensor_, options_, true, t_ns);
    return true;
  }

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
    BadLineHandler handler(path_, options_.text.on_bad_line, &rep);
    std::unique_ptr<MessageCursor> cursor = src_->cursor(imu_.ids);
    MessageView m;
    int64_t last = INT64_MIN;
    while (cursor->next(&m)) {
      MsgReader r(path_, src_->topics()[m.topic], m, *cursor, kFormImu);
      ImuSample s;
      s.t_ns = r.header();
      r.skip_f64(13, "orientation and its covariance");
      const uint8_t* at = r.pos();
      double v[6];
      for (int i = 0; i < 3; ++i) v[i] = r.f64("angular_velocity");
      r.skip_f64(9, "angular_velocity_covariance");
      for (int i = 3; i < 6; ++i) v[i] = r.f64("linear_acceleration");
      r.skip_f64(9, "linear_acceleration_covariance");
      r.expect_end();
      bool finite = true;
      for (double x : v) finite = finite && std::isfinite(x);
      if (!finite) {
        handler.bad("non-finite", 0, "NaN or infinite IMU value on " + imu_.topic + " at " + cursor->at(r.offset_of(at)),
                    kFormImu);
        continue;
      }
      if (s.t_ns <= last) {
        handler.bad("time order", 0,
                    "IMU stamp " + format_seconds(s.t_ns) + " s on " + imu_.topic + " is not after the previous " +
                        format_seconds(last) + " s at " + cursor->at(0),
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
    BadLineHandler handler(path_, options_.text.on_bad_line, &rep);
    std::unique_ptr<MessageCursor> cursor = src_->cursor(image_.ids);
    MessageView m;
    int64_t last = INT64_MIN;
    while (cursor->next(&m)) {
      MsgReader r(path_, src_->topics()[m.topic], m, *cursor, kFormImage);
      Frame f;
      f.t_ns = r.header();
      const uint8_t* dims_at = r.pos();
      const uint32_t height = r.u32("height");
      const uint32_t width = r.u32("width");
      const uint8_t* enc_at = r.pos();
      const std::string_view encoding = r.string("encoding");
      const bool big_endian = r.u8("is_bigendian") != 0;
      const uint32_t step = r.u32("step");
      uint32_t size = 0;
      const uint8_t* data_at = r.pos();
      const uint8_t* data = r.array(1, "data", &size);
      r.expect_end();
      PixelLayout px;
      if (!pixel_layout(encoding, &px)) {
        r.fail("image encoding '" + printable(encoding) +
                   "' is not supported (mono8, mono16, rgb8, bgr8, rgba8, bgra8, 8UC1 and 16UC1 are)",
               enc_at);
      }
      if (width == 0 || height == 0 || width > 65535 || height > 65535) {
        r.fail("image size " + std::to_string(width) + "x" + std::to_string(height) + " outside 1..65535", dims_at);
      }
      if (uint64_t{step} < uint64_t{width} * static_cast<uint64_t>(px.bytes)) {
        r.fail("step " + std::to_string(step) + " is smaller than width x " + std::to_string(px.bytes) + " bytes",
               dims_at);
      }
      if (uint64_t{step} * height > size) {
        r.fail("data of " + std::to_string(size) + " bytes is shorter than step x height = " +
                   std::to_string(uint64_t{step} * height),
               data_at);
      }
      if (f.t_ns < last) {
        handler.bad("time order", 0,
                    "image stamp " + format_seconds(f.t_ns) + " s on " + image_.topic + " is earlier than the previous " +
                        format_seconds(last) + " s at " + cursor->at(0),
                    std::string(kFormImage) + "; non-decreasing header stamps");
        continue;
      }
      last = f.t_ns;
      f.image.create(static_cast<int>(height), static_cast<int>(width), CV_8UC1);
      // mono16: the high byte (the first of each pair when big-endian).
      const int hi = big_endian ? 0 : 1;
      for (uint32_t y = 0; y < height; ++y) {
        const uint8_t* src = data + uint64_t{step} * y;
        uint8_t* dst = f.image.ptr<uint8_t>(static_cast<int>(y));
        if (px.bytes == 1) {
          std::memcpy(dst, src, width);
        } else if (px.mono16) {
          for (uint32_t x = 0; x < width; ++x, src += 2) dst[x] = src[hi];
        } else {
          for (uint32_t x = 0; x < width; ++x, src += px.bytes) dst[x] = grey(src[px.r], src[px.g], src[px.b]);
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
    for (const Topic& t : src_->topics()) {
      auto it = std::find_if(out.begin(), out.end(), [&](const StreamInfo& s) { return s.name == t.name && s.type == t.type; });
      if (it == out.end()) {
        StreamInfo s;
        s.name = t.name;
        s.type = t.type;
        const std::string type = canonical_type(t.type);
        s.selected = (t.name == events_.topic && type == events_.type) || (t.name == imu_.topic && type == imu_.type) ||
                     (t.name == image_.topic && type == image_.type);
        s.messages = 0;
        out.push_back(s);
        it = out.end() - 1;
      }
      if (t.messages < 0 || it->messages < 0) {
        it->messages = -1;
      } else {
        it->messages += t.messages;
      }
    }
    return out;
  }

 private:
  std::unique_ptr<EventStream> make_stream(bool log_end) const {
    if (events_.empty()) return nullptr;
    return std::make_unique<EventStream>(*src_, events_, sensor_, options_, log_end);
  }

  // width x height of the first event message (every event type starts with Header, height, width).
  SensorSize first_event_sensor() const {
    std::unique_ptr<MessageCursor> cursor = src_->cursor(events_.ids);
    MessageView m;
    if (!cursor->next(&m)) return SensorSize{};
    MsgReader r(path_, src_->topics()[m.topic], m, *cursor,
                events_.type == kTypeEventPacket ? kFormEventPacket : kFormEventArray);
    r.header();
    const uint8_t* at = r.pos();
    const uint32_t height = r.u32("height");
    const uint32_t width = r.u32("width");
    if (width > 65536 || height > 65536) {
      r.fail("sensor size " + std::to_string(width) + "x" + std::to_string(height) + " exceeds 65536x65536", at);
    }
    return SensorSize{static_cast<int>(width), static_cast<int>(height)};
  }

  std::unique_ptr<MessageSource> src_;
  std::string path_;
  DatasetOptions options_;
  Selection events_, imu_, image_;
  SensorSize sensor_;
  std::unique_ptr<EventStream> stream_;
  ReadReport empty_report_;
};

}  // namespace

std::unique_ptr<DatasetReader> open_ros_dataset(std::unique_ptr<MessageSource> source, const DatasetOptions& options) {
  return std::make_unique<RosDatasetReader>(std::move(source), options);
}

}  // namespace evio::detail::ros
