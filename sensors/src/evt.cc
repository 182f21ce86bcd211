#include "evio/sensors/evt.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <type_traits>
#include <sys/stat.h>

#include "byte_order.h"
#include "evio/calib/error.h"
#include "evio/calib/log.h"

namespace evio {
namespace {

// Unwrapping stops adding wrap periods beyond this (2^52 us, ~143 years of sensor time): a stream of
// alternating time-high words cannot push t_ns towards int64 overflow. A wrap refused here makes time
// go back, which readers report as bad data.
constexpr int64_t kMaxEpochUs = int64_t{1} << 52;
constexpr uint32_t kMaxBaseX = 4096;  // vector base x saturates here: beyond any 11-bit address

constexpr size_t kEvt3BlockWords = 256;   // words per block: at most 12 events each
constexpr size_t kEvt2BlockWords = 4096;  // at most 1 event each
constexpr size_t kScratchEvents = 4096;
static_assert(kEvt3BlockWords * 12 + 1 <= kScratchEvents && kEvt2BlockWords <= kScratchEvents, "scratch too small");

using detail::load_le;

// us * 1000 + offset, in wrapping unsigned arithmetic (no signed overflow for any offset).
inline uint64_t to_ns_bits(int64_t us, int64_t offset_ns) {
  return static_cast<uint64_t>(us) * 1000u + static_cast<uint64_t>(offset_ns);
}

// Events of one block are written here first, then appended to the caller's vector in one insert:
// no capacity check per event and no zero-initialisation of vector slots that are written anyway.
Event* scratch_events() {
  static thread_local std::unique_ptr<Event[]> scratch(new Event[kScratchEvents]);
  return scratch.get();
}

inline Event make_event(uint64_t t_bits, uint32_t x, uint32_t y, int32_t polarity) {
  Event e;
  e.t_ns = static_cast<int64_t>(t_bits);
  e.x = static_cast<uint16_t>(x);
  e.y = static_cast<uint16_t>(y);
  e.polarity = static_cast<int8_t>(polarity);
  return e;
}

inline Trigger make_trigger(uint64_t t_bits, uint32_t channel, uint32_t value) {
  Trigger tr;
  tr.t_ns = static_cast<int64_t>(t_bits);
  tr.channel = static_cast<int32_t>(channel);
  tr.polarity = value != 0 ? 1 : -1;
  return tr;
}

}  // namespace

// ------------------------------------------------------------------------------------------------
// EVT 3.0: 16-bit words, type in bits 15..12.
//   0x0 EVT_ADDR_Y   y = bits 10..0 (bit 11: system type, ignored)
//   0x2 EVT_ADDR_X   x = bits 10..0, polarity bit 11: one event at (x, y)
//   0x3 VECT_BASE_X  base x = bits 10..0, polarity bit 11
//   0x4 VECT_12      bit i of bits 11..0 set: event at base x + i; then base x += 12
//   0x5 VECT_8       bit i of bits 7..0 set: event at base x + i; then base x += 8
//   0x6 EVT_TIME_LOW time bits 11..0;  0x8 EVT_TIME_HIGH time bits 23..12
//   0xA EXT_TRIGGER  value bit 0, channel id bits 11..8
//   0x7 CONTINUED_4, 0xE OTHERS, 0xF CONTINUED_12 and unassigned types: counted, ignored.

void Evt3Decoder::reset() {
  const int64_t offset = time_offset_ns_;
  *this = Evt3Decoder();
  time_offset_ns_ = offset;
}

int64_t Evt3Decoder::current_time_us() const {
  if (!has_time()) return 0;
  return epoch_us_ + static_cast<int64_t>((time_high_ << 12) | time_low_);
}

// One word before the time base is complete: address state is tracked, events are dropped.
void Evt3Decoder::prelude_word(uint32_t w) {
  auto drop = [this](int64_t n) {
    if (n <= 0) return;
    if (stats_.first_word_before_time < 0) stats_.first_word_before_time = stats_.words;
    stats_.events_before_time += n;
  };
  switch (w >> 12) {
    case 0x0: y_ = w & 0x7FF; break;
    case 0x2: drop(1); break;
    case 0x3:
      base_x_ = w & 0x7FF;
      polarity_ = static_cast<int32_t>((w >> 10) & 2) - 1;
      break;
    case 0x4:
      drop(__builtin_popcount(w & 0xFFF));
      base_x_ = std::min(base_x_ + 12, kMaxBaseX);
      break;
    case 0x5:
      drop(__builtin_popcount(w & 0xFF));
      base_x_ = std::min(base_x_ + 8, kMaxBaseX);
      break;
    case 0x6:
      time_low_ = w & 0xFFF;
      has_time_low_ = has_time_high_;  // a time low counts once a time high gave its upper bits
      break;
    case 0x8: {
      const uint32_t h = w & 0xFFF;
      if (has_time_high_ && time_high_ > h + 2048) {
        ++stats_.time_wraps;
        if (epoch_us_ < kMaxEpochUs) epoch_us_ += int64_t{1} << 24;
      }
      if (!has_time_high_ || h != time_high_) time_low_ = 0;
      time_high_ = h;
      has_time_high_ = true;
      break;
    }
    case 0xA: drop(1); break;
    default: ++stats_.other_words; break;
  }
  ++stats_.words;
}

void Evt3Decoder::run(const uint8_t* p, size_t n, std::vector<Event>* events, std::vector<Trigger>* triggers) {
  size_t i = 0;
  while (i < n && !has_time()) prelude_word(load_le<uint16_t>(p + 2 * i++));
  if (i == n) return;

  uint32_t y = y_, base_x = base_x_, high = time_high_, low = time_low_;
  int32_t pol = polarity_;
  int64_t epoch = epoch_us_;
  int64_t other = 0, wraps = 0, n_trig = 0, n_cd = 0;
  const int64_t offset = time_offset_ns_;
  uint64_t t = to_ns_bits(epoch + static_cast<int64_t>((high << 12) | low), offset);
  Event* const scratch = scratch_events();
  const size_t first = i;

  while (i < n) {
    const size_t end = std::min(n, i + kEvt3BlockWords);
    Event* o = scratch;
    for (; i < end; ++i) {
      const uint32_t w = load_le<uint16_t>(p + 2 * i);
      const uint32_t type = w >> 12;
      // EVT_ADDR_X and EVT_ADDR_Y are ~80% of the words in real streams and come in data-dependent
      // order: they are handled without a branch (the event slot is written for every word and kept
      // only for EVT_ADDR_X; the scratch has room for one slot beyond the block's maximum).
      *o = make_event(t, w & 0x7FF, y, static_cast<int32_t>((w >> 10) & 2) - 1);
      o += type == 0x2;
      y = type == 0x0 ? (w & 0x7FF) : y;
      if (((1u << type) & 0x5u) != 0) continue;
      switch (type) {
        case 0x3:
          base_x = w & 0x7FF;
          pol = static_cast<int32_t>((w >> 10) & 2) - 1;
          break;
        case 0x4: {
          uint32_t m = w & 0xFFF;
          while (m != 0) {
            *o++ = make_event(t, base_x + static_cast<uint32_t>(__builtin_ctz(m)), y, pol);
            m &= m - 1;
          }
          base_x = std::min(base_x + 12, kMaxBaseX);
          break;
        }
        case 0x5: {
          uint32_t m = w & 0xFF;
          while (m != 0) {
            *o++ = make_event(t, base_x + static_cast<uint32_t>(__builtin_ctz(m)), y, pol);
            m &= m - 1;
          }
          base_x = std::min(base_x + 8, kMaxBaseX);
          break;
        }
        case 0x6:
          low = w & 0xFFF;
          t = to_ns_bits(epoch + static_cast<int64_t>((high << 12) | low), offset);
          break;
        case 0x8: {
          const uint32_t h = w & 0xFFF;
          if (h != high) {
            if (high > h + 2048) {  // fell by more than half the 12-bit range: the 24-bit counter wrapped
              ++wraps;
              if (epoch < kMaxEpochUs) epoch += int64_t{1} << 24;
            }
            high = h;
            low = 0;  // until the next time low: keeps time from running ahead of the true value
          }
          t = to_ns_bits(epoch + static_cast<int64_t>((high << 12) | low), offset);
          break;
        }
        case 0xA:
          ++n_trig;
          if (triggers != nullptr) triggers->push_back(make_trigger(t, (w >> 8) & 0xF, w & 1));
          break;
        default: ++other; break;
      }
    }
    n_cd += o - scratch;
    if (events != nullptr) events->insert(events->end(), scratch, o);
  }

  y_ = y;
  base_x_ = base_x;
  time_high_ = high;
  time_low_ = low;
  polarity_ = pol;
  epoch_us_ = epoch;
  stats_.words += static_cast<int64_t>(n - first);
  stats_.cd_events += n_cd;
  stats_.triggers += n_trig;
  stats_.other_words += other;
  stats_.time_wraps += wraps;
}

void Evt3Decoder::decode(const uint8_t* data, size_t size, std::vector<Event>* events,
                         std::vector<Trigger>* triggers) {
  if (size == 0) return;
  if (pending_size_ == 1) {
    const uint8_t w[2] = {pending_[0], data[0]};
    pending_size_ = 0;
    run(w, 1, events, triggers);
    ++data;
    --size;
  }
  run(data, size / 2, events, triggers);
  if (size % 2 != 0) {
    pending_[0] = data[size - 1];
    pending_size_ = 1;
  }
}

// ------------------------------------------------------------------------------------------------
// EVT 2.0: 32-bit words, type in bits 31..28.
//   0x0 CD_OFF / 0x1 CD_ON  y = bits 10..0, x = bits 21..11, time bits 5..0 = bits 27..22
//   0x8 EVT_TIME_HIGH       time bits 33..6 = bits 27..0
//   0xA EXT_TRIGGER         value bit 0, channel id bits 12..8, time bits 5..0 = bits 27..22
//   0xE OTHERS, 0xF CONTINUED and other types: counted, ignored.

void Evt2Decoder::reset() {
  const int64_t offset = time_offset_ns_;
  *this = Evt2Decoder();
  time_offset_ns_ = offset;
}

int64_t Evt2Decoder::current_time_us() const {
  if (!has_time_high_) return 0;
  return epoch_us_ + (static_cast<int64_t>(time_high_) << 6);
}

void Evt2Decoder::run(const uint8_t* p, size_t n, std::vector<Event>* events, std::vector<Trigger>* triggers) {
  size_t i = 0;
  for (; i < n && !has_time_high_; ++i) {
    const uint32_t w = load_le<uint32_t>(p + 4 * i);
    const uint32_t type = w >> 28;
    if (type == 0x8) {
      time_high_ = w & 0x0FFFFFFF;
      has_time_high_ = true;
    } else if (type <= 0x1 || type == 0xA) {
      if (stats_.first_word_before_time < 0) stats_.first_word_before_time = stats_.words;
      ++stats_.events_before_time;
    } else {
      ++stats_.other_words;
    }
    ++stats_.words;
  }
  if (i == n) return;

  uint32_t high = time_high_;
  int64_t epoch = epoch_us_;
  int64_t other = 0, wraps = 0, n_trig = 0, n_cd = 0;
  const int64_t offset = time_offset_ns_;
  uint64_t base = to_ns_bits(epoch + (static_cast<int64_t>(high) << 6), offset);
  Event* const scratch = scratch_events();
  const size_t first = i;

  while (i < n) {
    const size_t end = std::min(n, i + kEvt2BlockWords);
    Event* o = scratch;
    for (; i < end; ++i) {
      const uint32_t w = load_le<uint32_t>(p + 4 * i);
      switch (w >> 28) {
        case 0x0:
        case 0x1:
          *o++ = make_event(base + ((w >> 22) & 63) * 1000u, (w >> 11) & 0x7FF, w & 0x7FF,
                            static_cast<int32_t>((w >> 27) & 2) - 1);
          break;
        case 0x8: {
          const uint32_t h = w & 0x0FFFFFFF;
          if (high > h + (uint32_t{1} << 27)) {  // fell by more than half the 28-bit range: wrapped
            ++wraps;
            if (epoch < kMaxEpochUs) epoch += int64_t{1} << 34;
          }
          high = h;
          base = to_ns_bits(epoch + (static_cast<int64_t>(high) << 6), offset);
          break;
        }
        case 0xA:
          ++n_trig;
          if (triggers != nullptr) triggers->push_back(make_trigger(base + ((w >> 22) & 63) * 1000u, (w >> 8) & 0x1F, w & 1));
          break;
        default: ++other; break;
      }
    }
    n_cd += o - scratch;
    if (events != nullptr) events->insert(events->end(), scratch, o);
  }

  time_high_ = high;
  epoch_us_ = epoch;
  stats_.words += static_cast<int64_t>(n - first);
  stats_.cd_events += n_cd;
  stats_.triggers += n_trig;
  stats_.other_words += other;
  stats_.time_wraps += wraps;
}

void Evt2Decoder::decode(const uint8_t* data, size_t size, std::vector<Event>* events,
                         std::vector<Trigger>* triggers) {
  if (size == 0) return;
  if (pending_size_ > 0) {
    const size_t take = std::min(size, 4 - pending_size_);
    std::memcpy(pending_ + pending_size_, data, take);
    pending_size_ += take;
    data += take;
    size -= take;
    if (pending_size_ < 4) return;
    pending_size_ = 0;
    run(pending_, 1, events, triggers);
  }
  run(data, size / 4, events, triggers);
  const size_t rest = size % 4;
  if (rest != 0) {
    std::memcpy(pending_, data + size - rest, rest);
    pending_size_ = rest;
  }
}

// ------------------------------------------------------------------------------------------------
// RAW file header and reader.

namespace {

constexpr size_t kMaxHeaderBytes = size_t{1} << 20;
constexpr size_t kChunkBytes = size_t{1} << 20;  // file read size
constexpr size_t kPieceBytes = size_t{64} << 10;  // decoded per step: bounds the events held back
constexpr int kMaxEvtSide = 2048;                 // 11-bit addresses

const char* kHeaderForm =
    "'%' header lines each ending in a newline (e.g. '% evt 3.0', '% format EVT3;height=720;width=1280', "
    "'% geometry 640x480', optional '% end'), then little-endian binary words";
const char* kVersionForm = "a header line '% evt 2.0' / '% evt 3.0' or '% format EVT2' / '% format EVT3'";

struct FileCloser {
  void operator()(std::FILE* f) const {
    if (f != nullptr) std::fclose(f);
  }
};
using FilePtr = std::unique_ptr<std::FILE, FileCloser>;

FilePtr open_file(const std::string& path) {
  FilePtr f(std::fopen(path.c_str(), "rb"));
  if (!f) throw InputError(path, 0, std::string("cannot open: ") + std::strerror(errno), "a readable Prophesee RAW file");
  return f;
}

uint64_t file_size(std::FILE* f) {
  struct stat st {};
  if (fstat(fileno(f), &st) != 0 || st.st_size < 0) return 0;
  return static_cast<uint64_t>(st.st_size);
}

std::string trim(const std::string& s) {
  size_t a = 0, b = s.size();
  while (a < b && (s[a] == ' ' || s[a] == '\t' || s[a] == '\r')) ++a;
  while (b > a && (s[b - 1] == ' ' || s[b - 1] == '\t' || s[b - 1] == '\r')) --b;
  return s.substr(a, b - a);
}

std::string quoted(const std::string& s) {
  std::string q = "'";
  for (char c : s.substr(0, 80)) q += (static_cast<unsigned char>(c) < 0x20 || static_cast<unsigned char>(c) > 0x7E) ? '?' : c;
  if (s.size() > 80) q += "...";
  return q + "'";
}

std::string at_offset(uint64_t offset) { return " at byte offset " + std::to_string(offset); }

// A positive pixel count 1..2048, digits only.
bool parse_side(const std::string& s, int* v) {
  if (s.empty() || s.size() > 5) return false;
  int x = 0;
  for (char c : s) {
    if (c < '0' || c > '9') return false;
    x = x * 10 + (c - '0');
  }
  if (x < 1 || x > kMaxEvtSide) return false;
  *v = x;
  return true;
}

// "2.0", "2", "EVT2" -> 2; "3.0", "3", "EVT3" -> 3; anything else -> 0.
int version_from_text(std::string s) {
  for (char& c : s) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  if (s.rfind("EVT", 0) == 0) s = trim(s.substr(3));
  if (s == "2.0" || s == "2") return 2;
  if (s == "3.0" || s == "3") return 3;
  return 0;
}

EvtRawHeader parse_header(std::FILE* f, const std::string& path) {
  // The header is read in growing steps (headers are usually < 1 KiB) up to kMaxHeaderBytes.
  std::string buf;
  bool more = true;
  auto read_more = [&]() {
    const size_t old = buf.size();
    const size_t want = std::min(kMaxHeaderBytes, std::max<size_t>(4096, 2 * old)) - old;
    buf.resize(old + want);
    const size_t got = std::fread(&buf[old], 1, want, f);
    if (std::ferror(f)) throw InputError(path, 0, "read error in the header", kHeaderForm);
    buf.resize(old + got);
    more = got == want && buf.size() < kMaxHeaderBytes;
    return got > 0;
  };
  read_more();

  EvtRawHeader h;
  std::string version_line;
  bool side_given[2] = {false, false};
  size_t pos = 0;
  auto set_version = [&](const std::string& text, const std::string& line, size_t line_off) {
    if (!h.version_text.empty() && version_from_text(text) != version_from_text(h.version_text)) {
      throw InputError(path, 0,
                       "header names two formats: " + quoted(version_line) + " and " + quoted(line) + at_offset(line_off),
                       kVersionForm);
    }
    h.version_text = text;
    h.version = version_from_text(text);
    version_line = line;
  };
  auto set_side = [&](int which, const std::string& value, const std::string& line, size_t line_off) {
    int v = 0;
    if (!parse_side(value, &v)) {
      throw InputError(path, 0, "malformed sensor size in header line " + quoted(line) + at_offset(line_off),
                       "a width and height in 1..2048 px, e.g. '% geometry 640x480' or '% format EVT3;height=720;width=1280'");
    }
    (which == 0 ? h.sensor.width : h.sensor.height) = v;
    side_given[which] = true;
  };

  while ((pos < buf.size() || (more && read_more())) && buf[pos] == '%') {
    const size_t line_off = pos;
    size_t nl = buf.find('\n', pos);
    while (nl == std::string::npos && more && read_more()) nl = buf.find('\n', pos);
    if (nl == std::string::npos) {
      if (buf.size() >= kMaxHeaderBytes) throw InputError(path, 0, "header longer than 1 MiB (no line ends it)", kHeaderForm);
      throw InputError(path, 0, "file ends inside the header: header line" + at_offset(line_off) + " has no end of line",
                       kHeaderForm);
    }
    const std::string line = trim(buf.substr(pos + 1, nl - pos - 1));
    pos = nl + 1;
    ++h.lines;
    if (line == "end") {
      h.has_end = true;
      break;
    }
    const size_t sp = line.find_first_of(" \t");
    const std::string key = line.substr(0, sp);
    const std::string value = sp == std::string::npos ? std::string() : trim(line.substr(sp + 1));
    const std::string full = "% " + line;
    if (key == "evt") {
      set_version(value, full, line_off);
    } else if (key == "format") {
      // "EVT3;height=720;width=1280"
      const size_t semi = value.find(';');
      set_version(trim(value.substr(0, semi)), full, line_off);
      size_t at = semi;
      while (at != std::string::npos) {
        const size_t next = value.find(';', at + 1);
        const std::string kv = trim(value.substr(at + 1, next == std::string::npos ? std::string::npos : next - at - 1));
        const size_t eq = kv.find('=');
        if (eq != std::string::npos) {
          const std::string k = trim(kv.substr(0, eq)), v = trim(kv.substr(eq + 1));
          if (k == "width") set_side(0, v, full, line_off);
          if (k == "height") set_side(1, v, full, line_off);
        }
        at = next;
      }
    } else if (key == "geometry") {
      const size_t x = value.find('x');
      if (x == std::string::npos) set_side(0, "", full, line_off);
      set_side(0, trim(value.substr(0, x)), full, line_off);
      set_side(1, trim(value.substr(x + 1)), full, line_off);
    } else if (key == "width") {
      set_side(0, value, full, line_off);
    } else if (key == "height") {
      set_side(1, value, full, line_off);
    } else if (key == "plugin_name") {
      h.plugin_name = value;
    }
  }
  if (side_given[0] != side_given[1]) {
    throw InputError(path, 0, std::string("header gives the sensor ") + (side_given[0] ? "width" : "height") + " only",
                     "both width and height, e.g. '% geometry 640x480'");
  }
  h.data_offset = pos;
  return h;
}

enum class BadKind { kOutside, kTimeOrder };

// The reader for both versions; Decoder is Evt2Decoder or Evt3Decoder.
template <class Decoder>
class EvtReader final : public DatasetReader {
 public:
  static constexpr int kWordBytes = std::is_same<Decoder, Evt3Decoder>::value ? 2 : 4;

  EvtReader(const std::string& path, FilePtr file, const EvtRawHeader& header, const DatasetOptions& options,
            SensorSize sensor, const std::string& sensor_source)
      : path_(path), file_(std::move(file)), header_(header), policy_(options.text.on_bad_line), sensor_(sensor) {
    const uint64_t size = file_size(file_.get());
    data_bytes_ = size > header_.data_offset ? size - header_.data_offset : 0;
    seek_data(file_.get());
    chunk_.reset(new uint8_t[kChunkBytes]);  // not zero-filled: fread writes what is read
    max_x_ = sensor_.known() ? static_cast<uint32_t>(sensor_.width) : 0x10000u;
    max_y_ = sensor_.known() ? static_cast<uint32_t>(sensor_.height) : 0x10000u;
    report_.path = path_;
    report_.time_unit = TimeUnit::kMicroseconds;
    report_.time_unit_reason = std::string(version_name()) + " sensor clock";
    if (options.text.time_unit != TimeUnit::kAuto && options.text.time_unit != TimeUnit::kMicroseconds) {
      report_.time_unit_reason += "; the time_unit option does not apply";
    }
    report_.polarity = PolarityConvention::kZeroOne;
    report_.lines = header_.lines;
    std::string msg = path_ + ": Prophesee " + version_name() + ", sensor ";
    msg += sensor_.known() ? std::to_string(sensor_.width) + "x" + std::to_string(sensor_.height) + " (" + sensor_source + ")"
                           : std::string("size unknown (no geometry in the header or options; coordinates unchecked)");
    log_info(msg);
  }

  DatasetFormat format() const override {
    return kWordBytes == 2 ? DatasetFormat::kEvt3 : DatasetFormat::kEvt2;
  }
  const std::string& path() const override { return path_; }
  SensorSize sensor_size() const override { return sensor_; }
  double progress() const override {
    if (data_bytes_ == 0) return eof_ ? 1.0 : 0.0;
    return std::min(1.0, static_cast<double>(consumed_) / static_cast<double>(data_bytes_));
  }
  const ReadReport& event_report() const override { return report_; }

  size_t read_events(EventBuffer* out, size_t max_events) override {
    std::vector<Event>& v = out->events();
    size_t n_out = 0;
    if (pending_pos_ < pending_.size()) {
      const size_t take = std::min(max_events, pending_.size() - pending_pos_);
      v.insert(v.end(), pending_.begin() + static_cast<std::ptrdiff_t>(pending_pos_),
               pending_.begin() + static_cast<std::ptrdiff_t>(pending_pos_ + take));
      pending_pos_ += take;
      n_out += take;
      if (pending_pos_ == pending_.size()) {
        pending_.clear();
        pending_pos_ = 0;
      }
    }
    while (n_out < max_events && !eof_) {
      if (chunk_pos_ == chunk_len_ && !refill()) {
        finish();
        break;
      }
      const size_t len = std::min(kPieceBytes, chunk_len_ - chunk_pos_);
      const uint8_t* piece = chunk_.get() + chunk_pos_;
      const Decoder saved = decoder_;
      const size_t before = v.size();
      decoder_.decode(piece, len, &v, nullptr);
      validate(&v, before, saved, piece, len, header_.data_offset + consumed_);
      chunk_pos_ += len;
      consumed_ += len;
      n_out += v.size() - before;
      if (n_out > max_events) {
        const size_t excess = n_out - max_events;
        pending_.assign(v.end() - static_cast<std::ptrdiff_t>(excess), v.end());
        pending_pos_ = 0;
        v.resize(v.size() - excess);
        n_out = max_events;
      }
    }
    update_before_time_report(decoder_.stats());
    report_.records += static_cast<int64_t>(n_out);
    return n_out;
  }

  std::vector<Trigger> read_triggers() override {
    FilePtr f = open_file(path_);
    seek_data(f.get());
    Decoder dec;
    std::vector<Trigger> triggers;
    std::unique_ptr<uint8_t[]> buf(new uint8_t[kChunkBytes]);
    uint64_t offset = header_.data_offset;
    int64_t skipped = 0;
    size_t checked = 0;
    int64_t last = INT64_MIN;
    for (;;) {
      const size_t n = std::fread(buf.get(), 1, kChunkBytes, f.get());
      if (std::ferror(f.get())) throw InputError(path_, 0, "read error" + at_offset(offset));
      if (n == 0) break;
      dec.decode(buf.get(), n, nullptr, &triggers);
      offset += n;
      // Triggers going back in time are bad data like events (their word offset is not kept).
      size_t keep = checked;
      for (size_t i = checked; i < triggers.size(); ++i) {
        if (triggers[i].t_ns < last) {
          if (policy_ == BadLinePolicy::kError) {
            throw InputError(path_, 0,
                             "trigger time goes back from " + std::to_string(last) + " ns to " +
                                 std::to_string(triggers[i].t_ns) + " ns in the data between byte offsets " +
                                 std::to_string(offset - n) + " and " + std::to_string(offset),
                             "non-decreasing trigger time");
          }
          ++skipped;
          continue;
        }
        last = triggers[i].t_ns;
        triggers[keep++] = triggers[i];
      }
      triggers.resize(keep);
      checked = keep;
    }
    if (dec.pending_bytes() != 0 && policy_ == BadLinePolicy::kError) throw truncated_error(dec.pending_bytes(), offset);
    if (skipped > 0) log_warning(path_ + ": skipped " + std::to_string(skipped) + " trigger(s) going back in time");
    return triggers;
  }

  std::vector<ImuSample> read_imu() override { return {}; }
  std::vector<Frame> read_frames() override { return {}; }
  std::optional<Trajectory> read_groundtruth() override { return std::nullopt; }
  std::optional<calib::CameraCalibration> read_calibration() override { return std::nullopt; }

 private:
  static const char* version_name() { return kWordBytes == 2 ? "EVT 3.0" : "EVT 2.0"; }

  void seek_data(std::FILE* f) const {
    if (std::fseek(f, static_cast<long>(header_.data_offset), SEEK_SET) != 0) {
      throw InputError(path_, 0, "cannot seek to the event data" + at_offset(header_.data_offset));
    }
  }

  bool refill() {
    chunk_pos_ = 0;
    chunk_len_ = std::fread(chunk_.get(), 1, kChunkBytes, file_.get());
    if (std::ferror(file_.get())) throw InputError(path_, 0, "read error" + at_offset(header_.data_offset + consumed_));
    return chunk_len_ > 0;
  }

  // The data ends `pending` bytes into a word; end_offset is the file offset of the data's end.
  InputError truncated_error(size_t pending, uint64_t end_offset) const {
    const uint64_t word_off = end_offset - pending;
    return InputError(path_, 0,
                       "truncated final word: the file ends " + std::to_string(pending) + " byte(s) into a " +
                           std::to_string(kWordBytes * 8) + "-bit " + version_name() + " word" + at_offset(word_off),
                       std::string("whole ") + std::to_string(kWordBytes * 8) +
                           "-bit little-endian words after the header (data size a multiple of " +
                           std::to_string(kWordBytes) + " bytes)");
  }

  void finish() {
    eof_ = true;
    const size_t pending = decoder_.pending_bytes();
    if (pending != 0) {
      if (policy_ == BadLinePolicy::kError) throw truncated_error(pending, header_.data_offset + consumed_);
      ReadReport::Skipped& s = report_.skipped["truncated word"];
      s.count = 1;
      s.first_line = static_cast<int64_t>(header_.data_offset + consumed_ - pending);
      s.first_message = "file ends inside a word" + at_offset(s.first_line);
    }
    update_before_time_report(decoder_.stats());
    if (report_.skipped_total() > 0) {
      std::string m = path_ + ": skipped";
      for (const auto& kv : report_.skipped) {
        m += " " + std::to_string(kv.second.count) + " " + kv.first + " (first: " + kv.second.first_message + ");";
      }
      log_warning(m);
    }
    log_info(path_ + ": " + std::to_string(decoder_.stats().triggers) + " external trigger event(s), " +
             std::to_string(decoder_.stats().time_wraps) + " time counter wrap(s)");
  }

  void update_before_time_report(const EvtDecodeStats& st) {
    if (st.events_before_time == 0) return;
    ReadReport::Skipped& s = report_.skipped["before time base"];
    s.count = st.events_before_time;
    s.first_line = static_cast<int64_t>(header_.data_offset + static_cast<uint64_t>(st.first_word_before_time) * kWordBytes);
    s.first_message = "event before the first time word" + at_offset(s.first_line);
  }

  // Checks the events decoded from one piece (v[begin..]): coordinates inside the sensor and time
  // not going back. The common case is one branch-free pass; bad events take the slow path.
  void validate(std::vector<Event>* v, size_t begin, const Decoder& saved, const uint8_t* piece, size_t len,
                uint64_t piece_offset) {
    Event* e = v->data() + begin;
    const size_t n = v->size() - begin;
    int64_t last = last_t_ns_;
    bool bad = false;
    for (size_t i = 0; i < n; ++i) {
      bad |= (e[i].t_ns < last) | (e[i].x >= max_x_) | (e[i].y >= max_y_);
      last = e[i].t_ns;
    }
    if (!bad) {
      if (n > 0) last_t_ns_ = last;
      return;
    }
    last = last_t_ns_;
    size_t keep = 0;
    for (size_t i = 0; i < n; ++i) {
      const Event ev = e[i];
      if (ev.x >= max_x_ || ev.y >= max_y_) {
        bad_event(BadKind::kOutside, ev, i, last, saved, piece, len, piece_offset);
        continue;
      }
      if (ev.t_ns < last) {
        bad_event(BadKind::kTimeOrder, ev, i, last, saved, piece, len, piece_offset);
        continue;
      }
      last = ev.t_ns;
      e[keep++] = ev;
    }
    v->resize(begin + keep);
    last_t_ns_ = last;
  }

  void bad_event(BadKind kind, const Event& ev, size_t index, int64_t last, const Decoder& saved, const uint8_t* piece,
                 size_t len, uint64_t piece_offset) {
    const char* name = kind == BadKind::kOutside ? "outside sensor" : "time order";
    ReadReport::Skipped& s = report_.skipped[name];
    ++s.count;
    if (s.count > 1 && policy_ != BadLinePolicy::kError) return;
    const uint64_t off = word_offset(saved, piece, len, piece_offset, index);
    std::string problem, expected;
    if (kind == BadKind::kOutside) {
      problem = "event at x=" + std::to_string(ev.x) + " y=" + std::to_string(ev.y) + " outside the " +
                std::to_string(sensor_.width) + "x" + std::to_string(sensor_.height) + " sensor" + at_offset(off);
      expected = "x < " + std::to_string(sensor_.width) + " and y < " + std::to_string(sensor_.height) +
                 " (sensor size from the header or options)";
    } else {
      problem = "event time goes back from " + std::to_string(last / 1000) + " us to " + std::to_string(ev.t_ns / 1000) +
                " us" + at_offset(off);
      expected = "non-decreasing event time (time-high words increase except at 24-bit/34-bit counter wrap)";
    }
    if (policy_ == BadLinePolicy::kError) throw InputError(path_, 0, problem, expected);
    s.first_line = static_cast<int64_t>(off);
    s.first_message = problem;
  }

  // Byte offset in the file of the word that produced event `index` of a piece, found by decoding
  // the piece again one byte at a time from the decoder state before it (cold path only).
  static uint64_t word_offset(Decoder dec, const uint8_t* piece, size_t len, uint64_t piece_offset, size_t index) {
    std::vector<Event> tmp;
    size_t b = 0;
    constexpr size_t kStep = 4096;  // coarse steps first, then byte by byte within the step that emits it
    while (b < len) {
      const size_t step = std::min(kStep, len - b);
      const Decoder before = dec;
      const size_t before_size = tmp.size();
      dec.decode(piece + b, step, &tmp, nullptr);
      if (tmp.size() > index) {
        dec = before;
        tmp.resize(before_size);
        break;
      }
      b += step;
    }
    for (; b < len; ++b) {
      dec.decode(piece + b, 1, &tmp, nullptr);
      if (tmp.size() > index) return piece_offset + b + 1 - kWordBytes;
    }
    return piece_offset;
  }

  std::string path_;
  FilePtr file_;
  EvtRawHeader header_;
  BadLinePolicy policy_;
  SensorSize sensor_;
  uint32_t max_x_ = 0, max_y_ = 0;
  uint64_t data_bytes_ = 0;
  uint64_t consumed_ = 0;  // data bytes handed to the decoder
  std::unique_ptr<uint8_t[]> chunk_;
  size_t chunk_pos_ = 0, chunk_len_ = 0;
  bool eof_ = false;
  Decoder decoder_;
  std::vector<Event> pending_;  // decoded beyond max_events in the last call
  size_t pending_pos_ = 0;
  int64_t last_t_ns_ = INT64_MIN;
  ReadReport report_;
};

}  // namespace

EvtRawHeader parse_evt_raw_header(const std::string& path) {
  FilePtr f = open_file(path);
  return parse_header(f.get(), path);
}

SensorSize evt_plugin_sensor_size(const std::string& plugin_name) {
  static const char* const k640[] = {"hal_plugin_gen3_fx3", "hal_plugin_gen31_fx3", "hal_plugin_gen31_evk2",
                                     "hal_plugin_gen31_evk3"};
  static const char* const k1280[] = {"hal_plugin_gen4_fx3", "hal_plugin_gen4_evk2", "hal_plugin_gen41_evk2",
                                      "hal_plugin_gen41_evk3"};
  for (const char* n : k640) {
    if (plugin_name == n) return SensorSize{640, 480};
  }
  for (const char* n : k1280) {
    if (plugin_name == n) return SensorSize{1280, 720};
  }
  return SensorSize{};
}

std::unique_ptr<DatasetReader> open_evt_dataset(const std::string& path, const DatasetOptions& options) {
  std::string why;
  if (!options.Validate(&why)) throw InputError(path, 0, "invalid dataset options: " + why);
  FilePtr f = open_file(path);
  const EvtRawHeader h = parse_header(f.get(), path);
  int version = h.version;
  if (version == 0 && !h.version_text.empty()) {
    throw InputError(path, 0, "unsupported event format " + quoted(h.version_text) + " in the header", kVersionForm);
  }
  const int wanted = options.format == DatasetFormat::kEvt2 ? 2 : options.format == DatasetFormat::kEvt3 ? 3 : 0;
  if (version == 0) {
    if (wanted == 0) throw InputError(path, 0, "no event format version in the header", kVersionForm);
    version = wanted;
  } else if (wanted != 0 && wanted != version) {
    throw InputError(path, 0,
                     "the header says EVT " + std::to_string(version) + ".0 but format evt" + std::to_string(wanted) +
                         " was requested",
                     "a RAW file of the requested version, or the format named in its header");
  }
  SensorSize sensor = h.sensor;
  std::string source = "header";
  if (!sensor.known() && options.text.sensor.known()) {
    sensor = options.text.sensor;
    source = "options";
  }
  if (!sensor.known()) {
    sensor = evt_plugin_sensor_size(h.plugin_name);
    source = "plugin " + h.plugin_name;
  }
  if (version == 3) return std::make_unique<EvtReader<Evt3Decoder>>(path, std::move(f), h, options, sensor, source);
  return std::make_unique<EvtReader<Evt2Decoder>>(path, std::move(f), h, options, sensor, source);
}

}  // namespace evio
