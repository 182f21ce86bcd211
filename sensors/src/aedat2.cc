#include "evio/sensors/aedat2.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <vector>

#include "byte_order.h"
#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "text_common.h"

namespace evio {
namespace {

constexpr int kSize = 128;  // DVS128
constexpr char kForm[] =
    "jAER AEDAT 2.0: '#' header lines starting with \"#!AER-DAT2.0\", then big-endian int32 address + int32 "
    "timestamp [us] pairs";

using detail::load_be;

class Aedat2Reader final : public DatasetReader {
 public:
  Aedat2Reader(const std::string& path, const DatasetOptions& options) : path_(path), options_(options) {
    file_ = std::fopen(path.c_str(), "rb");
    if (file_ == nullptr) throw InputError(path, 0, std::string("cannot open: ") + std::strerror(errno), kForm);
    parse_header();
    report_.path = path;
    report_.time_unit = TimeUnit::kMicroseconds;
    report_.time_unit_reason = "AEDAT 2.0 timestamps tick in us";
    report_.polarity = PolarityConvention::kZeroOne;
    buf_.resize(size_t{1} << 20);
  }
  ~Aedat2Reader() override {
    if (file_ != nullptr) std::fclose(file_);
  }

  DatasetFormat format() const override { return DatasetFormat::kAedat2; }
  const std::string& path() const override { return path_; }
  SensorSize sensor_size() const override { return SensorSize{kSize, kSize}; }
  const ReadReport& event_report() const override { return report_; }
  double progress() const override {
    return file_size_ > 0 ? static_cast<double>(offset_) / static_cast<double>(file_size_) : 1.0;
  }

  size_t read_events(EventBuffer* out, size_t max_events) override {
    std::vector<Event>& v = out->events();
    size_t n = 0;
    while (n < max_events) {
      if (pos_ == end_ && !refill()) break;
      const uint8_t* p = buf_.data() + pos_;
      const size_t records = std::min((end_ - pos_) / 8, max_events - n);
      for (size_t i = 0; i < records; ++i, p += 8) {
        const uint32_t addr = load_be<uint32_t>(p);
        const int64_t t_ns = unwrap(load_be<uint32_t>(p + 4)) * 1000;
        const auto at = [&] { return offset_ - (end_ - pos_) + i * 8; };  // byte offset, for errors only
        if (addr & 0xffff0000u) {
          bad("malformed", at(), "address 0x" + hex(addr) + " has bits above 15 set (not a DVS128 address)");
          continue;
        }
        if (t_ns < last_t_ns_) {
          bad("time order", at(), "timestamp " + format_seconds(t_ns) + " s is earlier than the previous " +
                                    format_seconds(last_t_ns_) + " s");
          continue;
        }
        last_t_ns_ = t_ns;
        if (addr & 0x8000u) {
          triggers_.push_back(Trigger{t_ns, 0, static_cast<int8_t>(addr & 1u ? 1 : -1)});
          continue;
        }
        Event e;
        e.t_ns = t_ns;
        e.x = static_cast<uint16_t>(kSize - 1 - ((addr >> 1) & 0x7fu));
        e.y = static_cast<uint16_t>(kSize - 1 - ((addr >> 8) & 0x7fu));
        e.polarity = static_cast<int8_t>(addr & 1u ? 1 : -1);
        v.push_back(e);
        ++n;
      }
      pos_ += records * 8;
    }
    report_.records += static_cast<int64_t>(n);
    if (n == 0 && !finished_) {
      finished_ = true;
      detail::BadLineHandler(path_, options_.text.on_bad_line, &report_).finish();
    }
    return n;
  }

  std::vector<ImuSample> read_imu() override { return {}; }
  std::vector<Frame> read_frames() override { return {}; }
  // External events seen so far by the event stream (the whole file once it has been read).
  std::vector<Trigger> read_triggers() override {
    if (!finished_) {
      Aedat2Reader all(path_, options_);
      EventBuffer sink;
      while (all.read_events(&sink, size_t{1} << 20) > 0) sink.clear();
      return all.triggers_;
    }
    return triggers_;
  }
  std::optional<Trajectory> read_groundtruth() override { return std::nullopt; }
  std::optional<calib::CameraCalibration> read_calibration() override { return std::nullopt; }

 private:
  static std::string hex(uint32_t v) {
    char b[16];
    std::snprintf(b, sizeof(b), "%08x", v);
    return b;
  }

  void bad(const char* kind, uint64_t offset, const std::string& problem) {
    detail::BadLineHandler(path_, options_.text.on_bad_line, &report_)
        .bad(kind, 0, problem + " at byte offset " + std::to_string(offset), kForm);
  }

  // jAER timestamps are int32 us and wrap after 2^32 us when read unsigned: a drop of more than
  // half the range is a wrap, a smaller drop is out-of-order data.
  int64_t unwrap(uint32_t t) {
    if (have_t_ && t < last_raw_ && last_raw_ - t > 0x80000000u) wraps_ += int64_t{1} << 32;
    have_t_ = true;
    last_raw_ = t;
    return wraps_ + t;
  }

  void parse_header() {
    std::fseek(file_, 0, SEEK_END);
    file_size_ = static_cast<uint64_t>(std::ftell(file_));
    std::fseek(file_, 0, SEEK_SET);
    std::string line;
    uint64_t off = 0;
    bool first = true;
    std::string chip;
    for (;;) {
      const int c = std::fgetc(file_);
      if (c == EOF) break;
      if (c != '#') {
        std::ungetc(c, file_);
        break;
      }
      line.assign(1, '#');
      int d;
      while ((d = std::fgetc(file_)) != EOF && d != '\n') {
        if (line.size() > 65536) throw InputError(path_, 0, "header line longer than 64 KiB at byte offset " + std::to_string(off), kForm);
        line.push_back(static_cast<char>(d));
      }
      if (!line.empty() && line.back() == '\r') line.pop_back();
      if (first) {
        if (line.rfind("#!AER-DAT", 0) != 0) {
          throw InputError(path_, 0, "first line is not an AER-DAT version line at byte offset 0", kForm);
        }
        if (line != "#!AER-DAT2.0") {
          throw InputError(path_, 0, "unsupported version '" + line.substr(9) + "' at byte offset 0",
                           "AEDAT 2.0 (\"#!AER-DAT2.0\"); AEDAT 4.0 files are read with --format aedat4");
        }
        first = false;
      }
      if (line.rfind("# AEChip:", 0) == 0) chip = line.substr(line.find_first_not_of(" ", 9) == std::string::npos ? line.size() : line.find_first_not_of(" ", 9));
      off = static_cast<uint64_t>(std::ftell(file_));
    }
    if (first) throw InputError(path_, 0, "no \"#!AER-DAT2.0\" line at byte offset 0", kForm);
    data_offset_ = off;
    offset_ = off;
    if (!chip.empty() && chip.find("DVS128") == std::string::npos && chip.find("Tmpdiff128") == std::string::npos) {
      throw InputError(path_, 0, "AEDAT 2.0 from chip '" + chip + "' is not supported", "a DVS128 (Tmpdiff128) recording");
    }
    const uint64_t data = file_size_ - data_offset_;
    if (data % 8 != 0) {
      throw InputError(path_, 0,
                       "data section of " + std::to_string(data) + " bytes is not a whole number of 8-byte records (truncated at byte offset " +
                           std::to_string(file_size_ - data % 8) + ")",
                       kForm);
    }
    log_info(path_ + ": AEDAT 2.0" + (chip.empty() ? std::string() : ", chip " + chip) + ", " + std::to_string(data / 8) +
             " records, 128x128, coordinates flipped to origin top left");
  }

  bool refill() {
    const size_t got = std::fread(buf_.data(), 1, buf_.size(), file_);
    if (got == 0) {
      if (std::ferror(file_)) throw InputError(path_, 0, "read error at byte offset " + std::to_string(offset_), kForm);
      return false;
    }
    if (got % 8 != 0 && !std::feof(file_)) {
      throw InputError(path_, 0, "short read at byte offset " + std::to_string(offset_), kForm);
    }
    offset_ += got;
    pos_ = 0;
    end_ = got - got % 8;
    return end_ > 0;
  }

  std::string path_;
  DatasetOptions options_;
  std::FILE* file_ = nullptr;
  uint64_t file_size_ = 0, data_offset_ = 0, offset_ = 0;
  std::vector<uint8_t> buf_;
  size_t pos_ = 0, end_ = 0;
  ReadReport report_;
  std::vector<Trigger> triggers_;
  int64_t last_t_ns_ = INT64_MIN;
  int64_t wraps_ = 0;
  uint32_t last_raw_ = 0;
  bool have_t_ = false;
  bool finished_ = false;
};

}  // namespace

std::unique_ptr<DatasetReader> open_aedat2_dataset(const std::string& path, const DatasetOptions& options) {
  return std::make_unique<Aedat2Reader>(path, options);
}

}  // namespace evio
