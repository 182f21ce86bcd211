// Image reconstruction from events (and APS frames): per-pixel, per-event continuous-time filters
// of log intensity, each solved in closed form between events (no time steps).
//   ComplementaryFilter  Scheerlinck, Barnes, Mahony, "Continuous-time Intensity Estimation Using
//                        Event Cameras", ACCV 2018 (dvs_image_reconstruction); without frames
//                        (reference 0) it is the paper's high-pass filter.
//   AsyncKalmanFilter    Wang, Ng, Scheerlinck, Mahony, "An Asynchronous Kalman Filter for Hybrid
//                        Event Cameras", ICCV 2021: a per-pixel Kalman gain from event and frame
//                        noise models instead of a hand-set cut-off.
//
// Conventions: t in int64 ns; event polarity +1 (ON) / -1 (OFF); log intensity in the units of the
// events (an ON event adds contrast_on); an 8-bit APS value v maps to L = gamma log(v/255 + offset)
// (FrameResponse). Images are H x W (image.h), pixel (x, y) = element (y, x).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "evio/mapping/image.h"
#include "evio/mapping/scaled_decay.h"
#include "evio/sensors/measurements.h"

namespace evio::mapping {

// An 8-bit grey image in memory (an APS frame): row y starts at data + y * stride.
struct GreyView {
  const uint8_t* data = nullptr;
  int width = 0, height = 0;
  std::ptrdiff_t stride = 0;  // bytes per row, >= width
};

// The log intensity of an APS value v in [0, 255]: L = gamma * log(v / 255 + offset). The defaults
// are dvs_image_reconstruction's (L in [0, log 2]); a gamma-encoded frame of linear intensity I
// (v = 255 I^(1/gamma)) with a small offset gives L ~ log I, the events' own scale.
struct FrameResponse {
  double gamma = 1.0;           // > 0, <= 10
  double offset = 1.0;          // normalised intensity added before the log, > 0
  double initial_grey = 127.5;  // grey level in [0, 255] assumed before the first frame (the
                                // complementary filter's reference until then; log 1.5 by default)
  bool Validate(std::string* why) const;
  double log_of(double v) const;  // gamma * log(v / 255 + offset)
};

// Complementary filter (ACCV 2018). Per pixel, with L_F the latest frame's log intensity (held
// until the next frame; the reference log(initial_grey) before it, or 0 for the high-pass filter)
// and E the events (Dirac impulses of +contrast_on / -contrast_off):
//   dL/dt = E(t) - alpha (L - L_F),   alpha = 2 pi cutoff_hz  [rad/s]
// solved exactly: between events L(t) = L_F + exp(-alpha dt) (L(t0) - L_F); at an event L += c.
// A frame at t_k changes L_F for t > t_k (events at t <= t_k come before it). This is the
// published per-event update L <- b L + (1 - b) L_F + c, b = exp(-alpha dt), and its per-frame
// global update.
struct ComplementaryFilterOptions {
  double cutoff_hz = 0.5;       // crossover frequency f, Hz, in [0, 1e6]; alpha = 2 pi f rad/s;
                                // 0 = direct integration (no decay)
  double contrast_on = 0.1;     // log-intensity step of an ON event, > 0
  double contrast_off = 0.1;    // log-intensity step of an OFF event (subtracted), > 0
  bool use_frames = true;       // false: add_frame is ignored
  bool high_pass = false;       // reference 0 instead of log(initial_grey): the high-pass filter
  double initial_log_intensity = 0.0;  // state at t_start, log units (published: 0)
  bool init_from_first_frame = true;   // the first frame sets the state (published: false)
  FrameResponse frame;
  bool Validate(std::string* why) const;
};

// What the filters count.
struct ReconstructionStats {
  int64_t events = 0;          // events processed
  int64_t events_outside = 0;  // events outside the sensor, dropped
  int64_t frames = 0;          // frames fused
  int64_t rebases = 0;         // complementary filter: full-image rescalings (see below)
};

// The common interface of the filters (one virtual call per batch, not per event).
class LogIntensityFilter {
 public:
  virtual ~LogIntensityFilter() = default;
  // Events in time order (not checked per event; see each filter). Events outside the sensor are
  // counted and dropped.
  virtual void process(const Event* events, size_t n) = 0;
  void process(const std::vector<Event>& events) { process(events.data(), events.size()); }
  // An APS frame at t_ns (after every event with t <= t_ns, before any later one; frames in time
  // order). Throws std::invalid_argument when its size is not the sensor's.
  virtual void add_frame(int64_t t_ns, const GreyView& frame) = 0;
  // The log-intensity image at t_ns (>= the last event and frame processed): H x W.
  virtual void log_intensity(int64_t t_ns, ImageF* out) const = 0;
  ImageF log_intensity(int64_t t_ns) const {
    ImageF out;
    log_intensity(t_ns, &out);
    return out;
  }
  virtual const ReconstructionStats& stats() const = 0;
  virtual int width() const = 0;
  virtual int height() const = 0;
};

// The complementary (or high-pass) filter. Implementation: the state is held scaled,
// S = L exp(alpha (t - t_ref)), so that an event adds c exp(alpha (t_e - t_ref)) and nothing else
// (no per-pixel timestamp, no per-pixel decay), and a frame adds L_F (exp(alpha (t_k - t_ref)) -
// exp(alpha (t_{k-1} - t_ref))) to every pixel (one multiply-add per pixel, no exp). Reading the
// image divides by exp(alpha (t - t_ref)). The same equations, reordered; float state, the
// exponentials in double (per event from three tables, see process()). When alpha (t - t_ref)
// would exceed 20, or t - t_ref 8.6 s, the whole state is rescaled to a new t_ref (a "rebase":
// every 6.4 s at 0.5 Hz; also after a gap of any length, where it decays the state exactly, to 0
// after hours). Since the update is a sum, events need not be in order between two frames.
class ComplementaryFilter : public LogIntensityFilter {
 public:
  // t_start_ns: the time of the initial state. Throws std::invalid_argument for invalid options or
  // a size outside 1..65536.
  ComplementaryFilter(int width, int height, int64_t t_start_ns, const ComplementaryFilterOptions& options = {});

  void process(const Event* events, size_t n) override;
  using LogIntensityFilter::process;
  void add_frame(int64_t t_ns, const GreyView& frame) override;
  void log_intensity(int64_t t_ns, ImageF* out) const override;
  using LogIntensityFilter::log_intensity;
  const ReconstructionStats& stats() const override { return stats_; }
  int width() const override { return width_; }
  int height() const override { return height_; }
  const ComplementaryFilterOptions& options() const { return o_; }

 private:
  void rebase(int64_t t_ns);
  void fold_frame(int64_t t_ns);  // adds L_F's contribution over (t_fold, t_ns]

  int width_, height_;
  ComplementaryFilterOptions o_;
  float c_on_, c_off_;            // +contrast_on, -contrast_off
  std::vector<float> s_;          // scaled state, H x W row-major
  std::vector<uint8_t> frame_;    // the latest frame (empty before the first)
  std::array<float, 256> lut_{};  // frame value -> log intensity
  float reference_;               // L_F before the first frame (0 for the high-pass filter)
  ScaledDecayClock clock_;        // t_ref, t_fold, exp(alpha d) per event (scaled_decay.h)
  ReconstructionStats stats_;
};

// Asynchronous Kalman filter (ICCV 2021). Per pixel, state L (log intensity) and variance P (log^2).
// Events drive the state, frames are measurements of it at their times:
//   at an event      L += c,  P += Q
//   at a frame t_k   P += process_noise (t_k - t_update),  K = P / (P + R(v)),
//                    L += K (L_F - L),  P = (1 - K) P
// with (times in s; t_update: the pixel's last event or frame)
//   Q = event_noise                                        [the step's own error: threshold mismatch]
//     + process_noise * (t - t_update)
//     + isolated_noise * (t - the latest event among the 8 neighbours)
//     + refractory_noise if t - the pixel's previous event <= refractory_period
// so the state is the previous estimate carried forward by the events, corrected at each frame by a
// per-pixel gain: an event after a long quiet, without neighbours or in a burst raises P and the
// next frame's weight; a well-exposed frame counts more than an under/over-exposed one. Frame noise
// model (per pixel, from its value v): R = (frame_noise_std / 255)^2 gamma^2 / ((v/255 + offset)^2
// w(v)), grey-level noise carried into log units by dL/dv, with w(v) = 1 in [exposure_low,
// exposure_high] falling linearly to min_exposure_weight at 0 and 255. The first frame sets L and
// P = R; before it the events are integrated from initial_log_intensity with P from
// initial_variance. Between updates nothing changes (reading the image costs a copy).
// Differences from the paper: it fuses a frame as a continuous-time measurement (Riccati gain) of
// a frame deblurred and interpolated between its neighbours with events, which needs the next frame.
// Here a frame is one measurement at its own time, the exact Kalman update of the model above,
// which is causal and costs nothing per event. Held as a continuous measurement instead, the latest
// frame pulls the state towards a frame up to a frame period old after every event; held and
// augmented by the events since it, it still lets P collapse within one frame interval, counting
// one frame as many measurements (the error budget of bench/reconstruct_budget:
// docs/results/reconstruct.md). Not done: deblurring frames over their exposure.
struct AsyncKalmanFilterOptions {
  double contrast_on = 0.1;           // log-intensity step of an ON event, > 0
  double contrast_off = 0.1;          // step of an OFF event (subtracted), > 0
  double initial_variance = 0.09;     // P at the start (before the first frame), log^2, > 0
  double event_noise = 0.01;          // log^2 per event, >= 0
  double process_noise = 0.0005;      // log^2 per s since the pixel's last update, >= 0
  double isolated_noise = 0.03;       // log^2 per s since the neighbourhood's latest event, >= 0
  double refractory_noise = 0.05;     // log^2 per event within the refractory period, >= 0
  int64_t refractory_period_ns = 1'000'000;  // ns, >= 0
  double frame_noise_std = 2.0;       // grey levels (read noise and quantisation) of a well-exposed pixel, in (0, 255]
  double exposure_low = 25.0;         // grey levels: below, w falls linearly to min_exposure_weight at 0
  double exposure_high = 230.0;       // grey levels: above, w falls to min_exposure_weight at 255
  double min_exposure_weight = 0.05;  // w at 0 and 255, in (0, 1]
  bool use_frames = true;
  double initial_log_intensity = 0.0;  // state at t_start (replaced by the first frame)
  FrameResponse frame;
  bool Validate(std::string* why) const;
};

class AsyncKalmanFilter : public LogIntensityFilter {
 public:
  // Throws std::invalid_argument for invalid options or a size outside 1..65536.
  AsyncKalmanFilter(int width, int height, int64_t t_start_ns, const AsyncKalmanFilterOptions& options = {});

  void process(const Event* events, size_t n) override;
  using LogIntensityFilter::process;
  void add_frame(int64_t t_ns, const GreyView& frame) override;
  void log_intensity(int64_t t_ns, ImageF* out) const override;
  using LogIntensityFilter::log_intensity;
  const ReconstructionStats& stats() const override { return stats_; }
  int width() const override { return width_; }
  int height() const override { return height_; }
  // The variance P at t_ns, log^2 (H x W).
  void variance(int64_t t_ns, ImageF* out) const;
  const AsyncKalmanFilterOptions& options() const { return o_; }

 private:
  int width_, height_;
  AsyncKalmanFilterOptions o_;
  std::vector<float> l_, p_;            // state and variance
  std::vector<int64_t> t_update_;       // the pixel's last event or frame (t_start before any), ns
  std::vector<int64_t> t_event_;        // the pixel's latest event (t_start before any), ns
  std::array<float, 256> lut_log_{}, lut_var_{};  // frame value -> L_F, R (log^2)
  ReconstructionStats stats_;
};

// "hf", "cf", "akf", "gradient" (the Poisson image of the gradient state, async_convolution.h).
enum class ReconstructionMethod { kHighPass, kComplementary, kKalman, kGradient };
const char* reconstruction_method_name(ReconstructionMethod m);

}  // namespace evio::mapping
