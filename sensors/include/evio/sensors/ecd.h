// Event Camera Dataset text layout (Mueggler et al., "The Event-Camera Dataset and Simulator",
// IJRR 2017): events.txt `t x y p`, imu.txt `t ax ay az gx gy gz`, groundtruth.txt
// `t px py pz qx qy qz qw` (TUM layout, see trajectory.h), images.txt `t path`, calib.txt.
// Events are streamed in bounded memory; every line is validated (see text_read_options.h).
// Integer pixel events go to EventBuffer (read); sub-pixel ones, e.g. the ECD's
// events_undistorted.txt, to SubpixelEvent (read_subpixel).
#pragma once

#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "evio/sensors/event_buffer.h"
#include "evio/sensors/line_reader.h"
#include "evio/sensors/measurements.h"
#include "evio/sensors/text_read_options.h"

namespace evio {

// Files of an ECD folder; optional ones are empty when absent.
struct EcdFolder {
  std::string dir;
  std::string events;       // events.txt, or events_undistorted.txt when there is no events.txt
  std::string imu;          // imu.txt
  std::string groundtruth;  // groundtruth.txt
  std::string images;       // images.txt
  std::string calib;        // calib.txt
};
// Throws InputError when dir is not a folder or has neither events.txt nor events_undistorted.txt.
// events.txt wins when both exist. events_undistorted.txt holds sub-pixel coordinates: read it
// with EcdEventReader::read_subpixel (read() rejects it, naming that path).
EcdFolder find_ecd_folder(const std::string& dir);

// Streaming reader of events.txt. The constructor opens the file, resolves the time unit
// (TextReadOptions::time_unit) and checks it against the first 10,000 records, so a wrong unit
// fails before any event is returned.
class EcdEventReader {
 public:
  explicit EcdEventReader(const std::string& path, const TextReadOptions& options = {});

  // Appends up to max_events events to *out and returns how many; 0 means end of file (the
  // report is final then, and skipped-line counts have been logged). Pixel coordinates must be
  // non-negative integers (inside TextReadOptions::sensor when it is known); a fractional one is a
  // bad line whose message points to read_subpixel.
  size_t read(EventBuffer* out, size_t max_events);

  // As read(), for sub-pixel events: x and y may be integers or decimals, negative or beyond the
  // sensor (TextReadOptions::sensor is not applied), any finite float value; nan, inf and
  // non-numbers are bad lines. Time unit, time-order and polarity handling as in read(). Use one
  // of read() and read_subpixel() per reader.
  size_t read_subpixel(std::vector<SubpixelEvent>* out, size_t max_events);

  const ReadReport& report() const { return report_; }
  TimeUnit time_unit() const { return report_.time_unit; }
  // Fraction of the file consumed, in [0, 1] (for progress reports).
  double progress() const;

 private:
  void bad(const char* kind, std::string_view line, const std::string& problem);
  bool parse_general(std::string_view line, Event* e, uint32_t* x, uint32_t* y, PolarityConvention* conv);
  bool parse_subpixel(std::string_view line, SubpixelEvent* e, PolarityConvention* conv);
  // Shared tail of a record: polarity token, then the end of the line.
  bool parse_polarity(std::string_view line, const char* p, int8_t* polarity, PolarityConvention* conv);
  // Slow paths shared by read() and read_subpixel(), called when a record's polarity convention
  // differs from the report's (records it, or reports a mix: false) or its time goes back.
  bool accept_polarity_convention(std::string_view line, PolarityConvention conv);
  void bad_time_order(std::string_view line, int64_t t_ns);
  void end_chunk(size_t n);

  TextReadOptions options_;
  LineReader lines_;
  ReadReport report_;
  int exponent_ = 9;
  int64_t last_t_ns_ = INT64_MIN;
  bool finished_ = false;
  bool subpixel_ = false;  // the last call was read_subpixel (for the expected form in messages)
};

// Streaming reader of imu.txt (`t ax ay az gx gy gz`: accelerometer m/s^2, gyroscope rad/s). The
// constructor resolves the time unit (TextReadOptions::time_unit, checked against the first
// records); malformed, non-finite and out-of-order lines are bad lines (TextReadOptions::on_bad_line).
class EcdImuReader {
 public:
  explicit EcdImuReader(const std::string& path, const TextReadOptions& options = {});

  // Appends up to max_samples samples in time order to *out and returns how many; 0 means end of
  // file (the report is final then, and skipped-line counts have been logged).
  size_t read(std::vector<ImuSample>* out, size_t max_samples);
  const ReadReport& report() const { return report_; }

 private:
  TextReadOptions options_;
  LineReader lines_;
  ReadReport report_;
  int exponent_ = 9;
  int64_t last_t_ns_ = INT64_MIN;
  bool finished_ = false;
};

// Whole-file convenience wrappers.
EventBuffer read_ecd_events(const std::string& path, const TextReadOptions& options = {},
                            ReadReport* report = nullptr);
// Sub-pixel events of a whole file (e.g. events_undistorted.txt), see read_subpixel.
std::vector<SubpixelEvent> read_ecd_subpixel_events(const std::string& path, const TextReadOptions& options = {},
                                                    ReadReport* report = nullptr);
std::vector<ImuSample> read_ecd_imu(const std::string& path, const TextReadOptions& options = {},
                                    ReadReport* report = nullptr);
// Frames with t_ns and absolute path; images are not decoded (see load_frame_image). A listed
// image file that does not exist is a bad line.
std::vector<Frame> read_ecd_image_list(const std::string& path, const TextReadOptions& options = {},
                                       ReadReport* report = nullptr);
// Decodes frame->path into frame->image (as stored: mono8 stays mono8). Throws InputError.
void load_frame_image(Frame* frame);

// Streaming writer of events.txt: `t[s, 9 decimals] x y p`, polarity written as 0/1 (ECD) or
// -1/+1. Times round-trip exactly with EcdEventReader. Throws InputError on I/O failure.
class EcdEventWriter {
 public:
  explicit EcdEventWriter(const std::string& path,
                          PolarityConvention polarity = PolarityConvention::kZeroOne);
  ~EcdEventWriter();
  EcdEventWriter(const EcdEventWriter&) = delete;
  EcdEventWriter& operator=(const EcdEventWriter&) = delete;

  void write(EventSpan events);
  // Flushes and closes; throws on a write error (the destructor closes silently).
  void close();

 private:
  void flush();

  std::string path_;
  std::FILE* file_ = nullptr;
  std::vector<char> buf_;
  size_t used_ = 0;
  bool zero_one_ = true;
};

void write_ecd_imu(const std::string& path, const std::vector<ImuSample>& imu);
// Writes each frame's image as <dir>/images/frame_%08d.png and <dir>/images.txt. Frames without
// an image but with a path are copied by decoding and re-encoding.
void write_ecd_images(const std::string& dir, const std::vector<Frame>& frames);

}  // namespace evio
