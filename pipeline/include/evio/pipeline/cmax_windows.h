// Event windows for contrast maximisation: a time-ordered stream of (sub-pixel) events is cut into
// windows of N events, of a fixed duration, or of N events capped in duration; each window's events
// are brought to the undistorted pinhole (as they are, or through the undistortion lookup table),
// integer pixels are dithered within their pixel, and the window is handed out as
// mapping::CmaxEvents referenced to its middle time, with the stream index of every event, so
// per-event results (labels) can be written in input order. Shared by the CMax pipelines.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "evio/calib/camera.h"
#include "evio/mapping/cmax.h"
#include "evio/sensors/measurements.h"

namespace evio::frontend {
class EventUndistorter;
}

namespace evio::pipeline {

// Where the window's pixel coordinates come from. The warps work on the undistorted pinhole of the
// camera's fx, fy, cx, cy.
enum class CmaxUndistortion {
  // As is when the input is sub-pixel (undistorted files such as ECD's events_undistorted.txt: a
  // fractional or out-of-sensor coordinate among the first window's events) or the camera has no
  // distortion; through the lookup table otherwise (integer pixels of a distorted camera).
  kAuto,
  kNone,  // "none": the coordinates are already undistorted pinhole pixels; used as they are
  kLut,   // "lut": integer pixels of the distorted camera (sub-pixel ones rounded), undistorted
          // through calib::UndistortionLut; pixels outside the sensor or not undistortable dropped
};
const char* cmax_undistortion_name(CmaxUndistortion u);  // "auto", "none", "lut"
std::optional<CmaxUndistortion> cmax_undistortion_from_name(const std::string& name);

struct CmaxWindowOptions {
  int64_t window_events = 120000;  // events per window (> 0), used when window_ns is 0
  int64_t window_ns = 0;           // window duration, ns (>= 0; > 0: windows of this duration instead)
  // Event windows also close when they span this long, ns (0: no limit): slow motion then does not
  // stretch a window over a change of velocity the constant-velocity warps cannot follow.
  int64_t max_window_ns = 25'000'000;
  int64_t min_window_events = 50;  // windows with fewer events are not handed out (>= 1)
  CmaxUndistortion undistortion = CmaxUndistortion::kAuto;
  // Integer-pixel input only: each event is moved by an offset uniform in [-dither_px/2,
  // dither_px/2]^2 (px, >= 0, <= 4; 0: off), from a hash of its stamp and pixel (deterministic,
  // whatever the windows; mapping::pixel_dither). Without it the events of one pixel stack exactly
  // at zero motion, which pulls small motions to zero.
  double dither_px = 1.0;
  bool Validate(std::string* why) const;
};

struct CmaxWindow {
  int64_t index = 0;       // 0, 1, ... over the windows handed out
  int64_t t_start_ns = 0;  // first event (event windows) or window start (time windows), ns
  int64_t t_end_ns = 0;    // last event (event windows) or window end (time windows), ns
  int64_t t_ref_ns = 0;    // warp reference: the middle of [t_start, t_end], ns
  mapping::CmaxEvents events;          // undistorted, dithered; referenced to t_ref_ns
  std::vector<int64_t> input_index;    // stream index (0-based, order of process()) of each event
  int64_t input_begin = 0, input_end = 0;  // the stream indices the window covered (dropped included)
};

struct CmaxWindowStats {
  int64_t events = 0;           // given to process()
  int64_t events_used = 0;      // in windows handed out
  int64_t events_dropped = 0;   // lut: outside the sensor or not undistortable; non-finite coordinates
  int64_t windows = 0;          // handed out
  int64_t windows_skipped = 0;  // with fewer than min_window_events (time windows: empty ones too)
};

class CmaxWindower {
 public:
  // camera: the pinhole (geometry) and the undistortion table; without it, coordinates are used as
  // they are, with base.fx/fy and the principal point at the sensor centre. Throws
  // std::invalid_argument for invalid options, a non-positive size, or "lut" without a camera.
  CmaxWindower(const CmaxWindowOptions& options, int width, int height,
               const std::optional<calib::PinholeCamera>& camera, const mapping::WarpGeometry& base = {});
  ~CmaxWindower();

  // One event, in time order. Returns true when a window closed (take it with take()).
  bool process(const SubpixelEvent& e);
  // Ends the stream: hands out the last, partial window when it holds min_window_events and at
  // least half a window (half of window_events, or half of window_ns / max_window_ns in time) or
  // no window was handed out before; otherwise it is counted as skipped (a short tail has little
  // motion: measured on poster_rotation, a 4.5 ms tail was the worst window of 220, 48 deg/s off).
  void finish();
  // Windows closed since the last call, in time order.
  std::vector<CmaxWindow> take();

  int width() const { return width_; }
  int height() const { return height_; }
  const mapping::WarpGeometry& geometry() const { return geometry_; }
  // The undistortion in use: kNone or kLut once the first window decided it (kAuto before), and why.
  CmaxUndistortion undistortion() const { return undistortion_; }
  const std::string& undistortion_reason() const { return undistortion_reason_; }
  bool dithered() const { return integer_input_ && options_.dither_px > 0; }
  const CmaxWindowStats& stats() const { return stats_; }
  const CmaxWindowOptions& options() const { return options_; }

 private:
  void close_window(int64_t t_start_ns, int64_t t_end_ns);
  void decide_undistortion();

  CmaxWindowOptions options_;
  int width_ = 0, height_ = 0;
  mapping::WarpGeometry geometry_;
  std::unique_ptr<frontend::EventUndistorter> undistorter_;
  bool distorted_ = false;
  std::string distortion_name_;
  CmaxUndistortion undistortion_ = CmaxUndistortion::kAuto;
  std::string undistortion_reason_;
  bool input_checked_ = false, integer_input_ = false;
  std::vector<SubpixelEvent> buf_;
  int64_t buf_first_index_ = 0;  // stream index of buf_[0]
  bool started_ = false;
  int64_t window_start_ns_ = 0;
  CmaxWindowStats stats_;
  std::vector<CmaxWindow> done_;
};

}  // namespace evio::pipeline
