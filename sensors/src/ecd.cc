#include "evio/sensors/ecd.h"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>


#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio/sensors/image_io.h"
#include "text_common.h"

namespace evio {
namespace fs = std::filesystem;
using detail::is_space;
using detail::quote_line;
using detail::skip_space;

namespace {

std::string event_form(const ReadReport& r) {
  return std::string("`t x y p`: time in ") + time_unit_name(r.time_unit) +
         ", integer pixel x and y, polarity 0/1 or -1/+1 (e.g. `0.003811000 96 133 0`)";
}

std::string subpixel_event_form(const ReadReport& r) {
  return std::string("`t x y p`: time in ") + time_unit_name(r.time_unit) +
         ", pixel x and y as finite integers or decimals (may be negative), polarity 0/1 or -1/+1 "
         "(e.g. `0.003811000 96.25 -1.5 0`)";
}

// The integer path's message for a fractional coordinate.
constexpr const char* kSubpixelHint =
    "fractional pixel coordinate (the file holds sub-pixel coordinates, e.g. undistorted events, which the "
    "integer event path does not take; they are read by the sub-pixel path, EcdEventReader::read_subpixel / "
    "DatasetReader::read_subpixel_events, as `evio flow` and `evio segment` do)";

// True when the token at p is a number with a decimal point, such as "-5.836659".
bool is_decimal_number(const char* p, const char* end) {
  const char* b = p;
  double v = 0;
  if (!detail::parse_double(p, end, &v) || (p < end && !is_space(*p))) return false;
  return std::find(b, p, '.') != p;
}

// Parses an unsigned integer pixel coordinate; returns false when there is no digit.
inline bool parse_coord(const char*& p, const char* end, uint32_t* v) {
  uint32_t x = 0;
  const char* b = p;
  while (p < end && static_cast<unsigned>(*p - '0') < 10u && p - b < 9) {
    x = x * 10 + static_cast<uint32_t>(*p - '0');
    ++p;
  }
  *v = x;
  return p != b;
}

constexpr int64_t kPow10[] = {1, 10, 100, 1000, 10000, 100000, 1000000, 10000000, 100000000, 1000000000};

#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
constexpr bool kLittleEndian = false;
#else
constexpr bool kLittleEndian = true;
#endif

// Eight ASCII digits in a little-endian 64-bit word (first character in the lowest byte).
inline bool all_digits8(uint64_t w) {
  return (w & 0xF0F0F0F0F0F0F0F0ull) == 0x3030303030303030ull &&
         ((w + 0x0606060606060606ull) & 0xF0F0F0F0F0F0F0F0ull) == 0x3030303030303030ull;
}
// Their value (first character most significant), by pairwise combination (SWAR).
inline uint64_t digits8_value(uint64_t w) {
  w -= 0x3030303030303030ull;
  w = (w * 10 + (w >> 8)) & 0x00FF00FF00FF00FFull;           // pairs
  w = (w * 100 + (w >> 16)) & 0x0000FFFF0000FFFFull;         // quads
  return (w * 10000 + (w >> 32)) & 0x00000000FFFFFFFFull;    // eight
}

// Fast path for the common record form `S[.F] X Y P` as written by the ECD and `evio simulate`:
// single spaces, an unsigned time of at most 9 integer digits and at most `exponent` fraction
// digits, pixel coordinates of 1..5 digits, polarity 0 or 1, nothing else on the line. Gives
// exactly what the general parser gives for such lines; false for anything else, which the general
// parser then handles (and reports).
inline bool parse_record_fast(const char* p, const char* end, int exponent, int64_t* t_ns, uint32_t* x, uint32_t* y,
                              int8_t* polarity, PolarityConvention* conv) {
  const char* b = p;
  uint64_t ip = 0;
  while (p < end && static_cast<unsigned>(*p - '0') < 10u) ip = ip * 10 + static_cast<unsigned>(*p++ - '0');
  if (p == b || p - b > 9) return false;
  uint64_t frac = 0;
  int kept = 0;
  if (p < end && *p == '.') {
    const char* fb = ++p;
    uint64_t chunk;
    if (kLittleEndian && end - p >= 8 && (std::memcpy(&chunk, p, 8), all_digits8(chunk))) {  // nanosecond fractions: 8 digits at once
      frac = digits8_value(chunk);
      p += 8;
    }
    while (p < end && static_cast<unsigned>(*p - '0') < 10u) frac = frac * 10 + static_cast<unsigned>(*p++ - '0');
    kept = static_cast<int>(p - fb);
    if (kept > exponent) return false;
  }
  if (end - p < 6 || *p != ' ') return false;  // " X Y P" at least
  const auto coord = [&](uint32_t* v) {
    const char* c = ++p;  // past the space
    uint32_t a = 0;
    while (p < end && static_cast<unsigned>(*p - '0') < 10u) a = a * 10 + static_cast<uint32_t>(*p++ - '0');
    *v = a;
    return p != c && p - c <= 5 && p < end && *p == ' ';
  };
  if (!coord(x) || !coord(y)) return false;
  ++p;
  if (end - p != 1 || (*p != '0' && *p != '1')) return false;
  *polarity = *p == '1' ? 1 : -1;
  *conv = *p == '1' ? PolarityConvention::kUnknown : PolarityConvention::kZeroOne;
  *t_ns = static_cast<int64_t>(ip) * kPow10[exponent] + static_cast<int64_t>(frac) * kPow10[exponent - kept];
  return true;
}

std::string existing(const fs::path& p) {
  std::error_code ec;
  return fs::is_regular_file(p, ec) ? p.string() : std::string();
}

}  // namespace

EcdFolder find_ecd_folder(const std::string& dir) {
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) {
    throw InputError(dir, 0, "not a directory", "an Event Camera Dataset folder with events.txt");
  }
  EcdFolder f;
  f.dir = dir;
  const fs::path d(dir);
  f.events = existing(d / "events.txt");
  if (f.events.empty()) f.events = existing(d / "events_undistorted.txt");  // sub-pixel events
  if (f.events.empty()) {
    throw InputError(dir, 0, "no events.txt (or events_undistorted.txt) in this folder",
                     "an Event Camera Dataset folder: events.txt or events_undistorted.txt "
                     "[imu.txt groundtruth.txt images.txt calib.txt]");
  }
  f.imu = existing(d / "imu.txt");
  f.groundtruth = existing(d / "groundtruth.txt");
  f.images = existing(d / "images.txt");
  f.calib = existing(d / "calib.txt");
  return f;
}

// ---------------------------------------------------------------------------------------------
// events.txt

EcdEventReader::EcdEventReader(const std::string& path, const TextReadOptions& options)
    : options_(options), lines_(path) {
  std::string why;
  if (!options_.Validate(&why)) throw InputError(path, 0, "invalid read options: " + why);
  report_.path = path;
  exponent_ = detail::prepare_time_unit(path, options_, 0, "event", 10.0, 2e9, 1000, &report_);
}

double EcdEventReader::progress() const {
  return lines_.file_size() > 0 ? static_cast<double>(lines_.bytes_consumed()) / lines_.file_size() : 1.0;
}

void EcdEventReader::bad(const char* kind, std::string_view line, const std::string& problem) {
  detail::BadLineHandler(report_.path, options_.on_bad_line, &report_)
      .bad(kind, lines_.line_number(), problem + " in " + quote_line(line),
           subpixel_ ? subpixel_event_form(report_) : event_form(report_));
}

// The general record parser: any whitespace or commas, any time form, polarity 0/1 or -1/+1.
// False for comments, blank lines and bad lines (reported).
bool EcdEventReader::parse_general(std::string_view line, Event* e, uint32_t* x, uint32_t* y, PolarityConvention* conv) {
  const char* p = line.data();
  const char* end = p + line.size();
  p = skip_space(p, end);
  if (p == end || *p == '#' || *p == '%') return false;

  if (!detail::parse_time(p, end, exponent_, &e->t_ns) || (p < end && !is_space(*p))) {
    bad("malformed", line, "time is not a number");
    return false;
  }
  // x then y: a non-negative integer followed by a separator.
  for (const auto& [coord, name] : {std::pair<uint32_t*, const char*>{x, "x"}, {y, "y"}}) {
    p = skip_space(p, end);
    const char* token = p;
    const bool has = parse_coord(p, end, coord);
    if (!has || p == end || !is_space(*p)) {
      if (is_decimal_number(token, end)) {
        bad("malformed", line, kSubpixelHint);
        return false;
      }
      bad("malformed", line, "expected 4 columns, found " + std::to_string(detail::count_tokens(line)) +
                                 (has ? "" : std::string(" or ") + name + " is not a non-negative integer"));
      return false;
    }
  }
  return parse_polarity(line, p, &e->polarity, conv);
}

bool EcdEventReader::parse_polarity(std::string_view line, const char* p, int8_t* polarity, PolarityConvention* conv) {
  const char* end = line.data() + line.size();
  p = skip_space(p, end);
  // Polarity: 0/1 or -1/+1 (also "+1"); the two conventions may not mix within one file.
  bool polarity_ok = true;
  if (p < end && *p == '1') {
    *polarity = 1;
    ++p;
  } else if (p < end && *p == '0') {
    *polarity = -1;
    *conv = PolarityConvention::kZeroOne;
    ++p;
  } else if (end - p >= 2 && p[0] == '-' && p[1] == '1') {
    *polarity = -1;
    *conv = PolarityConvention::kMinusPlusOne;
    p += 2;
  } else if (end - p >= 2 && p[0] == '+' && p[1] == '1') {
    *polarity = 1;
    *conv = PolarityConvention::kMinusPlusOne;
    p += 2;
  } else {
    polarity_ok = false;
  }
  p = skip_space(p, end);
  if (!polarity_ok || p != end) {
    if (detail::count_tokens(line) != 4) {
      bad("malformed", line, "expected 4 columns, found " + std::to_string(detail::count_tokens(line)));
    } else {
      bad("polarity", line, "polarity is not 0, 1, -1 or +1");
    }
    return false;
  }
  return true;
}

// Like parse_general, with x and y parsed as finite floats.
bool EcdEventReader::parse_subpixel(std::string_view line, SubpixelEvent* e, PolarityConvention* conv) {
  const char* p = line.data();
  const char* end = p + line.size();
  p = skip_space(p, end);
  if (p == end || *p == '#' || *p == '%') return false;

  if (!detail::parse_time(p, end, exponent_, &e->t_ns) || (p < end && !is_space(*p))) {
    bad("malformed", line, "time is not a number");
    return false;
  }
  for (const auto& [coord, name] : {std::pair<float*, const char*>{&e->x, "x"}, {&e->y, "y"}}) {
    p = skip_space(p, end);
    double v = 0;
    const bool has = detail::parse_double(p, end, &v);
    if (!has || p == end || !is_space(*p)) {
      const int n = detail::count_tokens(line);
      bad("malformed", line,
          n != 4 ? "expected 4 columns, found " + std::to_string(n) : std::string(name) + " is not a number");
      return false;
    }
    *coord = static_cast<float>(v);
    if (!std::isfinite(*coord)) {
      bad("non-finite", line, std::string(name) + " is not a finite float (nan, inf or beyond the float range)");
      return false;
    }
  }
  return parse_polarity(line, p, &e->polarity, conv);
}

bool EcdEventReader::accept_polarity_convention(std::string_view line, PolarityConvention conv) {
  if (report_.polarity != PolarityConvention::kUnknown) {
    bad("polarity", line,
        std::string("polarity convention ") + polarity_convention_name(conv) + " mixed with " +
            polarity_convention_name(report_.polarity) + " used earlier in the file");
    return false;
  }
  report_.polarity = conv;
  return true;
}

void EcdEventReader::bad_time_order(std::string_view line, int64_t t_ns) {
  bad("time order", line,
      "timestamp " + format_seconds(t_ns) + " s is earlier than the previous event's " + format_seconds(last_t_ns_) +
          " s");
}

void EcdEventReader::end_chunk(size_t n) {
  report_.records += static_cast<int64_t>(n);
  report_.lines = lines_.line_number();
  if (n == 0 && !finished_) {
    finished_ = true;
    detail::BadLineHandler(report_.path, options_.on_bad_line, &report_).finish();
  }
}

size_t EcdEventReader::read(EventBuffer* out, size_t max_events) {
  subpixel_ = false;
  std::vector<Event>& v = out->events();
  const size_t n0 = v.size();
  const uint32_t width = static_cast<uint32_t>(options_.sensor.width);
  const uint32_t height = static_cast<uint32_t>(options_.sensor.height);
  const bool bounded = options_.sensor.known();
  std::string_view line;
  size_t n = 0;
  while (n < max_events && lines_.next(&line)) {
    const char* p = line.data();
    const char* end = p + line.size();
    Event e;
    uint32_t x = 0, y = 0;
    PolarityConvention conv = PolarityConvention::kUnknown;
    if (exponent_ >= 0 && exponent_ <= 9 && parse_record_fast(p, end, exponent_, &e.t_ns, &x, &y, &e.polarity, &conv)) {
      // the common form
    } else if (!parse_general(line, &e, &x, &y, &conv)) {
      continue;  // comment, blank or bad line (reported)
    }
    if (conv != PolarityConvention::kUnknown && conv != report_.polarity && !accept_polarity_convention(line, conv)) {
      continue;
    }
    if (x > 65535 || y > 65535 || (bounded && (x >= width || y >= height))) {
      bad("outside sensor", line,
          "pixel (" + std::to_string(x) + ", " + std::to_string(y) + ") outside the " +
              (bounded ? std::to_string(width) + "x" + std::to_string(height) + " sensor" : std::string("uint16 range")));
      continue;
    }
    if (e.t_ns < last_t_ns_) {
      bad_time_order(line, e.t_ns);
      continue;
    }
    last_t_ns_ = e.t_ns;
    // Written field by field into the buffer: a copy of the stack-assembled Event stalled on store
    // forwarding (its fields are stored in pieces and read back as one 16-byte load).
    Event& out_e = v.emplace_back();
    out_e.t_ns = e.t_ns;
    out_e.x = static_cast<uint16_t>(x);
    out_e.y = static_cast<uint16_t>(y);
    out_e.polarity = e.polarity;
    ++n;
  }
  end_chunk(v.size() - n0);
  return n;
}

size_t EcdEventReader::read_subpixel(std::vector<SubpixelEvent>* out, size_t max_events) {
  subpixel_ = true;
  std::string_view line;
  size_t n = 0;
  while (n < max_events && lines_.next(&line)) {
    SubpixelEvent e;
    PolarityConvention conv = PolarityConvention::kUnknown;
    if (!parse_subpixel(line, &e, &conv)) continue;  // comment, blank or bad line (reported)
    if (conv != PolarityConvention::kUnknown && conv != report_.polarity && !accept_polarity_convention(line, conv)) {
      continue;
    }
    if (e.t_ns < last_t_ns_) {
      bad_time_order(line, e.t_ns);
      continue;
    }
    last_t_ns_ = e.t_ns;
    out->push_back(e);
    ++n;
  }
  end_chunk(n);
  return n;
}

EventBuffer read_ecd_events(const std::string& path, const TextReadOptions& options, ReadReport* report) {
  EcdEventReader reader(path, options);
  EventBuffer events;
  while (reader.read(&events, size_t{1} << 20) > 0) {
  }
  if (report != nullptr) *report = reader.report();
  return events;
}

std::vector<SubpixelEvent> read_ecd_subpixel_events(const std::string& path, const TextReadOptions& options,
                                                    ReadReport* report) {
  EcdEventReader reader(path, options);
  std::vector<SubpixelEvent> events;
  while (reader.read_subpixel(&events, size_t{1} << 20) > 0) {
  }
  if (report != nullptr) *report = reader.report();
  return events;
}

// ---------------------------------------------------------------------------------------------
// imu.txt

EcdImuReader::EcdImuReader(const std::string& path, const TextReadOptions& options) : options_(options), lines_(path) {
  report_.path = path;
  exponent_ = detail::prepare_time_unit(path, options_, 0, "IMU", 0.1, 1e5, 10, &report_);
}

size_t EcdImuReader::read(std::vector<ImuSample>* out, size_t max_samples) {
  if (finished_) return 0;
  detail::BadLineHandler handler(report_.path, options_.on_bad_line, &report_);
  const std::string form = std::string("`t ax ay az gx gy gz`: time in ") + time_unit_name(report_.time_unit) +
                           ", accelerometer in m/s^2, gyroscope in rad/s";
  size_t n = 0;
  std::string_view line;
  while (n < max_samples) {
    if (!lines_.next(&line)) {
      finished_ = true;
      report_.lines = lines_.line_number();
      handler.finish();
      break;
    }
    if (detail::is_comment_or_blank(line)) continue;
    const char* p = skip_space(line.data(), line.data() + line.size());
    const char* end = line.data() + line.size();
    ImuSample s;
    double v[6];
    bool ok = detail::parse_time(p, end, exponent_, &s.t_ns) && (p == end || is_space(*p));
    for (int i = 0; ok && i < 6; ++i) {
      p = skip_space(p, end);
      ok = detail::parse_double(p, end, &v[i]) && (p == end || is_space(*p));
    }
    if (ok) p = skip_space(p, end);
    if (!ok || p != end) {
      const int k = detail::count_tokens(line);
      handler.bad("malformed", lines_.line_number(),
                  (k != 7 ? "expected 7 columns, found " + std::to_string(k) : std::string("a value is not a number")) +
                      " in " + quote_line(line),
                  form);
      continue;
    }
    bool finite = true;
    for (double x : v) finite = finite && std::isfinite(x);
    if (!finite) {
      handler.bad("non-finite", lines_.line_number(), "NaN or infinite IMU value in " + quote_line(line), form);
      continue;
    }
    if (s.t_ns <= last_t_ns_) {
      handler.bad("time order", lines_.line_number(),
                  "timestamp " + format_seconds(s.t_ns) + " s is not after the previous sample's " +
                      format_seconds(last_t_ns_) + " s",
                  form + ", strictly increasing time");
      continue;
    }
    last_t_ns_ = s.t_ns;
    s.accel = Eigen::Vector3d(v[0], v[1], v[2]);
    s.gyro = Eigen::Vector3d(v[3], v[4], v[5]);
    out->push_back(s);
    ++n;
  }
  report_.records += static_cast<int64_t>(n);
  return n;
}

std::vector<ImuSample> read_ecd_imu(const std::string& path, const TextReadOptions& options, ReadReport* report) {
  EcdImuReader reader(path, options);
  std::vector<ImuSample> out;
  while (reader.read(&out, size_t{1} << 16) > 0) {
  }
  if (report != nullptr) *report = reader.report();
  return out;
}

// ---------------------------------------------------------------------------------------------
// images.txt

std::vector<Frame> read_ecd_image_list(const std::string& path, const TextReadOptions& options, ReadReport* report) {
  ReadReport local;
  ReadReport& r = report != nullptr ? *report : local;
  r = ReadReport();
  r.path = path;
  LineReader lines(path);
  const int e = detail::prepare_time_unit(path, options, 0, "frame", 0.01, 1e5, 10, &r);
  detail::BadLineHandler handler(path, options.on_bad_line, &r);
  const std::string form = std::string("`t path`: time in ") + time_unit_name(r.time_unit) +
                           ", image path relative to the folder of images.txt";
  const fs::path base = fs::path(path).parent_path();
  std::vector<Frame> out;
  std::string_view line;
  int64_t last = INT64_MIN;
  while (lines.next(&line)) {
    if (detail::is_comment_or_blank(line)) continue;
    const char* end = line.data() + line.size();
    const char* p = skip_space(line.data(), end);
    Frame f;
    if (!detail::parse_time(p, end, e, &f.t_ns) || p == end || !is_space(*p)) {
      handler.bad("malformed", lines.line_number(), "expected a time and a path in " + quote_line(line), form);
      continue;
    }
    p = skip_space(p, end);
    const char* q = end;
    while (q > p && (q[-1] == ' ' || q[-1] == '\t')) --q;
    const fs::path rel(std::string(p, static_cast<size_t>(q - p)));
    const fs::path full = rel.is_absolute() ? rel : base / rel;
    std::error_code ec;
    if (!fs::is_regular_file(full, ec)) {
      handler.bad("missing image", lines.line_number(), "image file " + full.string() + " does not exist", form);
      continue;
    }
    if (f.t_ns <= last) {
      handler.bad("time order", lines.line_number(),
                  "timestamp " + format_seconds(f.t_ns) + " s is not after the previous frame's " +
                      format_seconds(last) + " s",
                  form + ", strictly increasing time");
      continue;
    }
    last = f.t_ns;
    f.path = full.string();
    out.push_back(std::move(f));
  }
  r.records = static_cast<int64_t>(out.size());
  r.lines = lines.line_number();
  handler.finish();
  return out;
}

void load_frame_image(Frame* frame) {
  if (frame->path.empty()) {
    throw InputError("", 0, "frame at " + format_seconds(frame->t_ns) + " s has neither an image nor a path",
                     "a frame read from a dataset");
  }
  frame->image = read_image(frame->path, cv::IMREAD_UNCHANGED);
  if (frame->image.empty()) {
    throw InputError(frame->path, 0, "cannot decode image", "an image file OpenCV can read (PNG, JPEG, ...)");
  }
}

// ---------------------------------------------------------------------------------------------
// writers

namespace {
std::FILE* open_for_writing(const std::string& path) {
  std::error_code ec;
  const fs::path parent = fs::path(path).parent_path();
  if (!parent.empty()) fs::create_directories(parent, ec);
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) throw InputError(path, 0, std::string("cannot create: ") + std::strerror(errno), "a writable path");
  return f;
}
}  // namespace

EcdEventWriter::EcdEventWriter(const std::string& path, PolarityConvention polarity)
    : path_(path), file_(open_for_writing(path)), buf_(size_t{1} << 20),
      zero_one_(polarity != PolarityConvention::kMinusPlusOne) {}

EcdEventWriter::~EcdEventWriter() {
  if (file_ != nullptr) {
    std::fwrite(buf_.data(), 1, used_, file_);
    std::fclose(file_);
  }
}

void EcdEventWriter::flush() {
  if (used_ > 0 && std::fwrite(buf_.data(), 1, used_, file_) != used_) {
    throw InputError(path_, 0, std::string("write failed: ") + std::strerror(errno), "a writable path with free space");
  }
  used_ = 0;
}

void EcdEventWriter::write(EventSpan events) {
  if (file_ == nullptr) throw InputError(path_, 0, "write after close");
  constexpr size_t kMaxLine = 64;
  for (const Event& e : events) {
    if (buf_.size() - used_ < kMaxLine) flush();
    char* w = buf_.data() + used_;
    w = format_seconds(e.t_ns, w);
    *w++ = ' ';
    w = std::to_chars(w, w + 8, e.x).ptr;
    *w++ = ' ';
    w = std::to_chars(w, w + 8, e.y).ptr;
    *w++ = ' ';
    if (zero_one_) {
      *w++ = e.polarity > 0 ? '1' : '0';
    } else {
      if (e.polarity < 0) *w++ = '-';
      *w++ = '1';
    }
    *w++ = '\n';
    used_ = static_cast<size_t>(w - buf_.data());
  }
}

void EcdEventWriter::close() {
  if (file_ == nullptr) return;
  flush();
  const bool failed = std::fclose(file_) != 0;
  file_ = nullptr;
  if (failed) throw InputError(path_, 0, "closing failed", "a writable path with free space");
}

void write_ecd_imu(const std::string& path, const std::vector<ImuSample>& imu) {
  std::FILE* f = open_for_writing(path);
  bool ok = true;
  for (const ImuSample& s : imu) {
    const std::string t = format_seconds(s.t_ns);
    ok = ok && std::fprintf(f, "%s %.17g %.17g %.17g %.17g %.17g %.17g\n", t.c_str(), s.accel.x(), s.accel.y(),
                            s.accel.z(), s.gyro.x(), s.gyro.y(), s.gyro.z()) > 0;
  }
  ok = (std::fclose(f) == 0) && ok;
  if (!ok) throw InputError(path, 0, "write failed", "a writable path with free space");
}

void write_ecd_images(const std::string& dir, const std::vector<Frame>& frames) {
  const fs::path images_dir = fs::path(dir) / "images";
  std::error_code ec;
  fs::create_directories(images_dir, ec);
  const std::string list_path = (fs::path(dir) / "images.txt").string();
  std::FILE* f = open_for_writing(list_path);
  bool ok = true;
  for (size_t i = 0; i < frames.size(); ++i) {
    Frame fr = frames[i];
    if (fr.image.empty()) load_frame_image(&fr);
    char name[64];
    std::snprintf(name, sizeof(name), "images/frame_%08zu.png", i);
    const std::string out = (fs::path(dir) / name).string();
    if (!write_image(out, fr.image)) {
      std::fclose(f);
      throw InputError(out, 0, "cannot write image", "a writable path");
    }
    ok = ok && std::fprintf(f, "%s %s\n", format_seconds(fr.t_ns).c_str(), name) > 0;
  }
  ok = (std::fclose(f) == 0) && ok;
  if (!ok) throw InputError(list_path, 0, "write failed", "a writable path with free space");
}

}  // namespace evio
