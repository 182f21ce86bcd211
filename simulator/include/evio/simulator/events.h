// Event generation for the simulator (the ESIM model, Rebecq et al., CoRL 2018, with the sensor
// non-idealities of v2e, Hu et al., CVPRW 2021): each pixel keeps a reference log intensity
// L = log(I + eps); when L crosses reference +- C the pixel fires, once per crossing, at the time
// interpolated linearly between the two rendered samples. Per-pixel thresholds with Gaussian
// mismatch, refractory period, shot noise, leak events, hot pixels and timestamp jitter, seeded.
// The full model (reference rules for refractory, noise and leak) is stated in src/events.cc.
#pragma once

#include <cstdint>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "evio/sensors/measurements.h"

namespace evio::simulator {

struct EventSimOptions {
  double contrast_threshold_pos = 0.2;   // mean ON threshold C+, log-intensity units, > 0
  double contrast_threshold_neg = 0.2;   // mean OFF threshold C-, log-intensity units, > 0
  double threshold_mismatch_std = 0.0;   // per-pixel Gaussian sigma around each mean, log units
  double threshold_min = 0.01;           // lower clamp of per-pixel thresholds, log units, >= 1e-6
  double log_eps = 1e-3;                 // eps in log(I + eps), intensity units, in (0, 1e30]
  // After any event the pixel is held in reset for this long (its reference follows L, so the
  // change during the reset is lost; crossings and noise in it are not emitted), ns, >= 0.
  int64_t refractory_ns = 0;
  double shot_noise_rate_hz = 0.0;       // background activity per pixel, Hz (half ON, half OFF)
  double leak_rate_hz = 0.0;             // leak (ON) events per pixel at a static scene, Hz
  double hot_pixel_fraction = 0.0;       // fraction of pixels that are hot (round(f * N) pixels), [0, 1]
  double hot_pixel_rate_hz = 0.0;        // extra Poisson rate of ON events of each hot pixel, Hz
  double timestamp_jitter_ns = 0.0;      // std of Gaussian timestamp jitter (clamped into the step), ns
  uint64_t seed = 1;                     // thresholds, hot pixels, noise, leak phases, jitter

  bool Validate(std::string* why) const;
};

class EventGenerator {
 public:
  // Throws std::invalid_argument for invalid options or size.
  EventGenerator(int width, int height, const EventSimOptions& options);

  // Sets the references from the first rendered intensity (CV_32F or CV_64F, width x height) at
  // t_ns (with a leak, at a random phase per pixel) and restarts the noise random stream, so the
  // same images after a reset give the same events. Emits nothing. Intensities are read as
  // clamp(I, 0, FLT_MAX), NaN as 0.
  void reset(const cv::Mat& intensity, int64_t t_ns);

  // Advances to the next rendered intensity at t_ns (> previous). Appends the events with
  // timestamps in (t_prev, t_ns], sorted by time (ties: by pixel index, then ON before OFF), to
  // *events. When `labels` (CV_16U) and `event_labels` are given, appends each event's label
  // (label of its pixel at t_ns; shot/hot-pixel noise events, and ON events of a pixel whose L
  // did not rise in the step (leak), get 0xFFFF). Throws std::logic_error before reset() and
  // std::invalid_argument for a wrong image, label image or time.
  void step(const cv::Mat& intensity, int64_t t_ns, std::vector<Event>* events,
            const cv::Mat* labels = nullptr, std::vector<uint16_t>* event_labels = nullptr);

  int width() const { return width_; }
  int height() const { return height_; }
  // Per-pixel thresholds (CV_64F holding float-representable values, >= threshold_min), fixed at
  // construction from the seed.
  const cv::Mat& threshold_pos() const { return c_pos_; }
  const cv::Mat& threshold_neg() const { return c_neg_; }
  // Current per-pixel log intensity (CV_64F) and reference level (CV_64F; during a refractory
  // reset the reference equals the log intensity).
  const cv::Mat& log_intensity() const { return log_; }
  const cv::Mat& reference() const { return ref_; }
  // Largest |L_new - L_old| over pixels in the last step, log units (for adaptive stepping).
  double last_max_log_change() const { return last_max_change_; }
  // Log intensity of an intensity image with this generator's eps (CV_64F).
  cv::Mat to_log(const cv::Mat& intensity) const;

 private:
  // One emitted event before sorting: time, sort key, pixel index, 0 = ON / 1 = OFF, noise flag.
  struct Pending {
    int64_t t_ns;
    uint64_t key;
    uint32_t pixel;
    uint8_t off;
    uint8_t noise;
  };
  void compute_log(const cv::Mat& intensity, cv::Mat* out, int y0, int y1, bool clamp) const;
  void check_image(const cv::Mat& intensity, const char* what) const;
  void process_pixel(int i, int64_t t0, int64_t t1, double leak_per_cp);
  void sort_pending(int64_t dt);
  void emit(int64_t t, int64_t t0, int64_t t1, int i, bool on, bool noise);
  int64_t draw_next_noise(int i, int64_t t_from);
  double uniform();  // [0, 1), 53 bits
  double normal();   // N(0, 1), Box-Muller

  int width_, height_;
  EventSimOptions o_;
  cv::Mat c_pos_, c_neg_, log_, ref_;
  cv::Mat log_next_;                      // scratch: log intensity of the sample being stepped to
  std::vector<int64_t> refractory_end_;   // per pixel: end of the current reset (refractory), ns
  std::vector<int64_t> next_noise_;       // per pixel: next shot/hot noise event time, ns
  std::vector<float> cpf_, cnf_;          // the thresholds (float values) for the fast path
  std::vector<uint8_t> hot_;              // per pixel: 1 for hot pixels
  std::vector<uint8_t> visit_;            // scratch: pixels needing the general path this step
  // Min-heap of (next noise time, pixel); entries whose time differs from next_noise_ are stale.
  std::vector<std::pair<int64_t, uint32_t>> noise_heap_;
  std::vector<uint32_t> in_reset_, in_reset_next_;  // pixels whose reset outlasts the last step
  std::vector<Pending> pending_;          // scratch: this step's events before sorting
  std::vector<Pending> sort_scratch_;     // scratch for the radix sort
  double log_lo_ = 0, log_hi_ = 0;        // log(eps), log(FLT_MAX + eps): range of L
  bool any_noise_ = false;                // some pixel has a noise rate > 0
  int64_t t_ns_ = 0;
  bool initialised_ = false;
  double last_max_change_ = 0;
  std::mt19937_64 rng_;                   // noise, leak phase and jitter; reseeded by reset()
  bool has_spare_normal_ = false;
  double spare_normal_ = 0;
};

}  // namespace evio::simulator
