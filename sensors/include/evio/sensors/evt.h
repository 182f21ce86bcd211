// Prophesee RAW event formats: streaming decoders for EVT 2.0 (32-bit words) and EVT 3.0 (16-bit
// words) and a DatasetReader for RAW files ('%' ASCII header, then little-endian words). Follows
// Prophesee's public "EVT 2.0 / EVT 3.0 format" documentation (same word layouts as openeb).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "evio/sensors/dataset.h"
#include "evio/sensors/measurements.h"

namespace evio {

// Counters of one decoder since its last reset().
struct EvtDecodeStats {
  int64_t words = 0;        // complete words decoded
  int64_t cd_events = 0;    // CD events emitted (including those outside the sensor, see below)
  int64_t triggers = 0;     // external trigger events emitted
  int64_t other_words = 0;  // OTHERS / CONTINUED / IMU / unassigned word types (counted, otherwise ignored)
  int64_t time_wraps = 0;   // wrap-arounds of the sensor's time counter that were unwrapped
  // CD or trigger words before the first complete time base (EVT 2.0: TIME_HIGH; EVT 3.0: TIME_HIGH
  // and TIME_LOW): they are dropped, since their time is unknown, and counted here.
  int64_t events_before_time = 0;
  int64_t first_word_before_time = -1;  // index (in words since reset) of the first such word; -1 if none
};

// Stateful EVT 3.0 decoder. State (time high/low, current y, vector base x, polarity) carries
// across calls, so a stream may be fed in pieces of any size (a partial trailing byte is kept).
// Time: 24-bit us counter (time_high 12 bits << 12 | time_low 12 bits), unwrapped to 64 bits: a
// decrease of time_high by more than half its range (> 2048) counts as a wrap (+2^24 us); a smaller
// decrease is passed through (time goes back; readers treat that as bad data). A time high that
// changes the value sets time low to 0 until the next time low word, so time never runs ahead
// (openeb does the same). The time base is complete at the first time low after a time high; CD and
// trigger words before that are dropped and counted (stats().events_before_time).
// Vectors: VECT_12 / VECT_8 emit one event per set bit i at base_x + i, then advance base_x by 12 / 8.
// Output is appended in stream order; the decoder itself neither sorts nor filters coordinates.
// Time offset: kept by reset().
class Evt3Decoder {
 public:
  void reset();
  // Appends CD events (t_ns = unwrapped sensor time in us * 1000 + time_offset_ns) and external
  // triggers (channel = trigger id, polarity +1 rising / -1 falling edge). `triggers` may be null
  // (triggers are then counted but not stored).
  void decode(const uint8_t* data, size_t size, std::vector<Event>* events, std::vector<Trigger>* triggers);
  void set_time_offset_ns(int64_t offset_ns) { time_offset_ns_ = offset_ns; }
  int64_t time_offset_ns() const { return time_offset_ns_; }
  const EvtDecodeStats& stats() const { return stats_; }
  bool has_time() const { return has_time_high_ && has_time_low_; }  // a time high + time low word has been seen
  int64_t current_time_us() const;  // unwrapped 64-bit sensor time, us (0 before has_time())
  // Bytes held back from the last call (0 or 1: an incomplete trailing 16-bit word).
  size_t pending_bytes() const { return pending_size_; }

 private:
  void run(const uint8_t* p, size_t n_words, std::vector<Event>* events, std::vector<Trigger>* triggers);
  void prelude_word(uint32_t w);

  EvtDecodeStats stats_;
  int64_t time_offset_ns_ = 0;
  int64_t epoch_us_ = 0;    // wraps << 24, us
  uint32_t time_high_ = 0;  // last 12-bit time high
  uint32_t time_low_ = 0;   // last 12-bit time low
  bool has_time_high_ = false;
  bool has_time_low_ = false;
  uint32_t y_ = 0;
  uint32_t base_x_ = 0;  // vector base x; saturates at 4096, beyond any 11-bit address
  int32_t polarity_ = -1;
  uint8_t pending_[1] = {0};
  size_t pending_size_ = 0;
};

// Stateful EVT 2.0 decoder, same contract with 32-bit words. Time: 34-bit us counter
// (time_high 28 bits << 6 | 6-bit event timestamp), unwrapped to 64 bits: a decrease of time_high
// by more than 2^27 counts as a wrap (+2^34 us). CD events and triggers before the first TIME_HIGH
// word are dropped and counted (stats().events_before_time). Partial trailing words (1..3 bytes)
// are kept for the next call.
class Evt2Decoder {
 public:
  void reset();
  void decode(const uint8_t* data, size_t size, std::vector<Event>* events, std::vector<Trigger>* triggers);
  void set_time_offset_ns(int64_t offset_ns) { time_offset_ns_ = offset_ns; }
  int64_t time_offset_ns() const { return time_offset_ns_; }
  const EvtDecodeStats& stats() const { return stats_; }
  bool has_time() const { return has_time_high_; }  // a TIME_HIGH word has been seen (EVT 2.0 has no time low word)
  int64_t current_time_us() const;  // unwrapped time of the last TIME_HIGH (time_high << 6), us; 0 before has_time()
  size_t pending_bytes() const { return pending_size_; }

 private:
  void run(const uint8_t* p, size_t n_words, std::vector<Event>* events, std::vector<Trigger>* triggers);

  EvtDecodeStats stats_;
  int64_t time_offset_ns_ = 0;
  int64_t epoch_us_ = 0;     // wraps << 34, us
  uint32_t time_high_ = 0;   // last 28-bit time high
  bool has_time_high_ = false;
  uint8_t pending_[4] = {0, 0, 0, 0};
  size_t pending_size_ = 0;
};

// Header of a Prophesee RAW file: the '%' lines up to and including "% end", or up to the first
// line that does not start with '%' (older files have no "% end"; as in openeb, binary data that
// happens to start with the byte '%' cannot be told apart from a header line in such files).
struct EvtRawHeader {
  int version = 0;             // 2 or 3; 0 when the header names none (or an unsupported one, see below)
  std::string version_text;    // the format as written ("3.0", "EVT3", "EVT21"); empty when absent
  SensorSize sensor;           // from "% format EVTn;width=W;height=H", "% geometry WxH" or "% width"/"% height"
  std::string plugin_name;     // "% plugin_name" (older files state their geometry only through it)
  size_t data_offset = 0;      // byte offset of the first binary word
  int64_t lines = 0;           // header lines
  bool has_end = false;        // "% end" was present
};
// Parses the header at the start of a file. Throws InputError when a header line is unterminated,
// the header is longer than 1 MiB, geometry values are malformed or outside 1..2048 px, or two lines
// name different formats. Does not check that the version is supported.
EvtRawHeader parse_evt_raw_header(const std::string& path);

// Sensor geometry of the Prophesee camera plugins that wrote RAW files without geometry lines
// (openeb's table of legacy plugins: Gen3/Gen3.1 640x480, Gen4/Gen4.1 1280x720); {0,0} if unknown.
SensorSize evt_plugin_sensor_size(const std::string& plugin_name);

// Opens a Prophesee RAW file, EVT 2.0 or 3.0 as its header states. A header without a version is
// accepted only when options.format is kEvt2 or kEvt3 (raw dumps); an unknown version, or one that
// contradicts options.format, is an InputError. Sensor size: the header's geometry, else
// options.text.sensor, else the plugin table above; unknown sizes disable the coordinate check.
// Bad data, handled by options.text.on_bad_line (kError: InputError naming the byte offset of the
// word; kWarnAndSkip: dropped and counted in event_report().skipped with the first byte offset):
// "outside sensor" (x >= width or y >= height), "time order" (t below the last event returned),
// "truncated word" (the file ends inside a word). Events before the first complete time base are
// always dropped and counted as "before time base". Time unit: the sensor clock, us (t_ns = us * 1000).
// Triggers come from read_triggers(), a separate pass over the file, in stream order (a trigger
// going back in time is bad data, as for events).
std::unique_ptr<DatasetReader> open_evt_dataset(const std::string& path, const DatasetOptions& options);

}  // namespace evio
