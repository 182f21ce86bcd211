// Event generation for the simulator: the ESIM model (Rebecq et al., CoRL 2018) with the sensor
// non-idealities of v2e (Hu et al., CVPRW 2021), written for exactness first, then speed.
//
// Model, per pixel i (thresholds and levels in natural-log units, time in int64 ns):
//  * L = log(I + eps), I the rendered linear intensity (CV_32F or CV_64F; NaN and negative values
//    are read as 0, +inf and values above FLT_MAX as FLT_MAX). Computed once per pixel per step in
//    double (OpenCV's vectorised cv::log, |error| < 2e-15).
//  * Thresholds C+_i, C-_i drawn once at construction from N(mean, threshold_mismatch_std),
//    clamped below at threshold_min and rounded to float values (own Box-Muller on
//    std::mt19937_64 seeded from `seed`).
//  * Between two samples L0 (t_prev) and L1 (t_ns) L is linear in time. The reference r_i moves
//    by exactly one threshold per event: every time L - r reaches +C+ (ON) or -C- (OFF) one event
//    is emitted at the linearly interpolated crossing time, t_prev + round(f * (t_ns - t_prev)),
//    f in (0, 1] the crossing's fraction of the interval, clamped into (t_prev, t_ns]. Only
//    differences of int64 times are ever converted to double, so stamps at 1.7e18 ns are as exact
//    as at 0. At the end of each step -C- < L - r < C+ holds for every pixel not in reset, so the
//    signed sum of thresholds over a pixel's signal events tracks its log change within one
//    threshold.
//  * Leak: the reference drifts down at C+_i * leak_rate_hz per second while the pixel is not in
//    reset, so a static pixel emits ON events at exactly leak_rate_hz. reset() starts every pixel
//    at a uniformly random phase (r = L - u * C+_i, u ~ U[0, 1)) so leaks are not synchronised.
//    The drift is solved exactly inside a step (L - r is still linear in time).
//  * Refractory period (the DVS reset switch): after any event at t_e the pixel is held in reset
//    until t_e + refractory_ns. While held, the reference follows the photoreceptor (r = L), so a
//    change during the reset is lost (as in a real pixel, and like v2e's choice of updating the
//    reference); when the reset is released, r = L(t_e + refractory_ns) and the pixel detects
//    changes from that level, with no drift during the reset. Hence two events of one pixel are
//    never closer than refractory_ns (before jitter), and noise events falling in a reset are not
//    emitted.
//  * Shot noise and hot pixels: each pixel carries a Poisson process of rate
//    shot_noise_rate_hz (+ hot_pixel_rate_hz for the round(hot_pixel_fraction * N) hot pixels,
//    a seeded random subset), realised as per-pixel exponential waiting times (next event time
//    stored per pixel, so a step costs one comparison per pixel). A shot-noise event is ON or OFF
//    with probability 1/2; a hot-pixel event is ON (the sign of excess dark current). A noise
//    event is a real pixel event: it resets the pixel (r = current L, so L - r = 0; v2e also
//    resets the reference on noise) and starts a refractory period. Effective noise rates with a
//    refractory period R are therefore rate / (1 + rate * R).
//  * Timestamp jitter: each emitted stamp gets round(N(0, timestamp_jitter_ns)) added, then is
//    clamped into (t_prev, t_ns] so a step's events stay inside its interval (the clamp piles a
//    little probability on the interval ends when the jitter is comparable to the step). Jitter is
//    a readout error and does not move the pixel's internal state.
//  * Output of a step is sorted by (time, pixel index y * width + x, ON before OFF). Labels: the
//    label image's value at the pixel at t_ns for signal events; 0xFFFF for shot and hot-pixel
//    events and for ON events of a step where the pixel's L did not rise (then only the leak
//    drift can have caused them).
//  * Randomness: std::mt19937_64 with own uniform/normal/exponential mappings (no std
//    distributions, whose algorithms differ between standard libraries). Thresholds and hot
//    pixels come from streams derived from `seed` at construction; noise, leak phases and jitter
//    from a stream reseeded by every reset(), drawn in pixel order, so a given seed, first image
//    and step sequence always give the same events.
//
// Speed: pass 1 runs over chunks of rows that stay in cache: vectorised convertTo + log (OpenCV),
// then a branch-free band test per pixel (no pending noise or reset, and the drift-compensated end
// level inside (-C-, C+): nothing to emit, only the leak drift is applied), with thresholds read
// as floats. Pending noise comes from a min-heap of next noise times, pixels in reset from a list,
// so pass 2 visits only the flagged pixels (in pixel order, keeping the random draws
// deterministic). The step's events are radix-sorted on a 64-bit (time offset, pixel, polarity)
// key. Allocations happen only when the output or an internal scratch vector has to grow.
#include "evio/simulator/events.h"

#include <algorithm>
#include <array>
#include <cfloat>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <utility>

namespace evio::simulator {
namespace {

constexpr int64_t kNever = std::numeric_limits<int64_t>::min();
constexpr int64_t kNoNoise = std::numeric_limits<int64_t>::max();
constexpr uint16_t kNoiseLabel = 0xFFFF;

uint64_t splitmix64(uint64_t x) {
  x += 0x9E3779B97F4A7C15ULL;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
  return x ^ (x >> 31);
}

// Independent streams from one user seed.
enum Stream : uint64_t { kThresholdStream = 1, kHotPixelStream = 2, kNoiseStream = 3 };
uint64_t stream_seed(uint64_t seed, Stream s) { return splitmix64(seed ^ splitmix64(s)); }

double uniform01(std::mt19937_64& g) { return static_cast<double>(g() >> 11) * 0x1.0p-53; }

// Box-Muller, one value per call (used at construction only).
double normal_once(std::mt19937_64& g) {
  const double u1 = 1.0 - uniform01(g);  // (0, 1]
  const double u2 = uniform01(g);
  return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * M_PI * u2);
}

// Uniform integer in [0, n), n > 0, without bias (rejection of the incomplete last block).
uint64_t uniform_below(std::mt19937_64& g, uint64_t n) {
  const uint64_t limit = std::numeric_limits<uint64_t>::max() - std::numeric_limits<uint64_t>::max() % n;
  uint64_t v = g();
  while (v >= limit) v = g();
  return v % n;
}

// max(v, lo) rounded to a float value >= lo: thresholds are float numbers (exactly the same in
// the double accessors and in the float copies the fast path reads, halving its memory traffic).
double to_float_at_least(double v, double lo) {
  float f = static_cast<float>(std::max(v, lo));
  while (static_cast<double>(f) < lo) f = std::nextafter(f, std::numeric_limits<float>::infinity());
  return f;
}

int64_t saturating_add(int64_t t, int64_t d) { return t > kNoNoise - d ? kNoNoise : t + d; }  // d >= 0

bool finite_nonneg(double v) { return std::isfinite(v) && v >= 0; }

}  // namespace

bool EventSimOptions::Validate(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  // threshold_min >= 1e-6 keeps every reference step far above the double spacing of log levels
  // (|L| < 1e3), so each crossing moves the reference and a step always terminates.
  if (!(std::isfinite(contrast_threshold_pos) && contrast_threshold_pos > 0))
    return fail("contrast_threshold_pos must be > 0 (log units)");
  if (!(std::isfinite(contrast_threshold_neg) && contrast_threshold_neg > 0))
    return fail("contrast_threshold_neg must be > 0 (log units)");
  if (!finite_nonneg(threshold_mismatch_std)) return fail("threshold_mismatch_std must be >= 0 (log units)");
  if (!(std::isfinite(threshold_min) && threshold_min >= 1e-6))
    return fail("threshold_min must be >= 1e-6 (log units)");
  if (!(std::isfinite(log_eps) && log_eps > 0 && log_eps <= 1e30)) return fail("log_eps must be in (0, 1e30]");
  if (refractory_ns < 0) return fail("refractory_ns must be >= 0 (ns)");
  if (!finite_nonneg(shot_noise_rate_hz)) return fail("shot_noise_rate_hz must be >= 0 (Hz)");
  if (!finite_nonneg(leak_rate_hz)) return fail("leak_rate_hz must be >= 0 (Hz)");
  if (!(finite_nonneg(hot_pixel_fraction) && hot_pixel_fraction <= 1))
    return fail("hot_pixel_fraction must be in [0, 1]");
  if (!finite_nonneg(hot_pixel_rate_hz)) return fail("hot_pixel_rate_hz must be >= 0 (Hz)");
  if (!finite_nonneg(timestamp_jitter_ns)) return fail("timestamp_jitter_ns must be >= 0 (ns)");
  return true;
}

EventGenerator::EventGenerator(int width, int height, const EventSimOptions& options)
    : width_(width), height_(height), o_(options) {
  std::string why;
  if (!o_.Validate(&why)) throw std::invalid_argument("EventSimOptions: " + why);
  if (width <= 0 || height <= 0 || width > 65536 || height > 65536) {
    std::ostringstream m;
    m << "EventGenerator: image size " << width << "x" << height << " must be in [1, 65536] per side";
    throw std::invalid_argument(m.str());
  }
  const int n = width * height;
  c_pos_.create(height, width, CV_64F);
  cpf_.resize(n);
  cnf_.resize(n);
  c_neg_.create(height, width, CV_64F);
  {
    std::mt19937_64 g(stream_seed(o_.seed, kThresholdStream));
    double* cp = c_pos_.ptr<double>();
    double* cn = c_neg_.ptr<double>();
    for (int i = 0; i < n; ++i) {
      double p = o_.contrast_threshold_pos, q = o_.contrast_threshold_neg;
      if (o_.threshold_mismatch_std > 0) {
        p += o_.threshold_mismatch_std * normal_once(g);
        q += o_.threshold_mismatch_std * normal_once(g);
      }
      cp[i] = to_float_at_least(p, o_.threshold_min);
      cn[i] = to_float_at_least(q, o_.threshold_min);
      cpf_[i] = static_cast<float>(cp[i]);
      cnf_[i] = static_cast<float>(cn[i]);
    }
  }
  hot_.assign(n, 0);
  const int64_t n_hot = std::llround(o_.hot_pixel_fraction * n);
  if (n_hot > 0) {
    // Partial Fisher-Yates: the first n_hot entries of a seeded permutation.
    std::mt19937_64 g(stream_seed(o_.seed, kHotPixelStream));
    std::vector<int> idx(n);
    for (int i = 0; i < n; ++i) idx[i] = i;
    for (int64_t k = 0; k < n_hot; ++k) {
      const int64_t j = k + static_cast<int64_t>(uniform_below(g, static_cast<uint64_t>(n - k)));
      std::swap(idx[k], idx[j]);
      hot_[idx[k]] = 1;
    }
  }
  any_noise_ = o_.shot_noise_rate_hz > 0 || (n_hot > 0 && o_.hot_pixel_rate_hz > 0);
  {
    cv::Mat ends = (cv::Mat_<double>(1, 2) << o_.log_eps, static_cast<double>(FLT_MAX) + o_.log_eps);
    cv::log(ends, ends);  // the same function as the per-pixel logs
    log_lo_ = ends.at<double>(0, 0);
    log_hi_ = ends.at<double>(0, 1);
  }
  log_.create(height, width, CV_64F);
  log_next_.create(height, width, CV_64F);
  ref_.create(height, width, CV_64F);
  log_.setTo(0.0);
  ref_.setTo(0.0);
  refractory_end_.assign(n, kNever);
  next_noise_.assign(n, kNoNoise);
  visit_.assign(n, 0);
  if (any_noise_) noise_heap_.reserve(2 * static_cast<size_t>(n));
}

double EventGenerator::uniform() { return uniform01(rng_); }

double EventGenerator::normal() {
  if (has_spare_normal_) {
    has_spare_normal_ = false;
    return spare_normal_;
  }
  const double u1 = 1.0 - uniform01(rng_);
  const double u2 = uniform01(rng_);
  const double r = std::sqrt(-2.0 * std::log(u1));
  spare_normal_ = r * std::sin(2.0 * M_PI * u2);
  has_spare_normal_ = true;
  return r * std::cos(2.0 * M_PI * u2);
}

void EventGenerator::check_image(const cv::Mat& intensity, const char* what) const {
  if (intensity.rows != height_ || intensity.cols != width_ || intensity.channels() != 1 ||
      (intensity.depth() != CV_32F && intensity.depth() != CV_64F)) {
    std::ostringstream m;
    m << "EventGenerator::" << what << ": intensity must be a single-channel CV_32F or CV_64F image of "
      << width_ << "x" << height_ << ", got " << intensity.cols << "x" << intensity.rows << " type "
      << intensity.type();
    throw std::invalid_argument(m.str());
  }
}

// L = log(max(0, min(I, FLT_MAX)) + eps) for rows [y0, y1), computed as
// clamp(log(max(I + eps, eps)), log(eps), log(FLT_MAX + eps)) (log is monotone; NaN goes to the
// lower end),
// which lets OpenCV's vectorised convertTo and log do the work. With clamp = false the clamp is
// left to the caller (step() fuses it into its band test).
void EventGenerator::compute_log(const cv::Mat& intensity, cv::Mat* out, int y0, int y1, bool clamp) const {
  cv::Mat rows = out->rowRange(y0, y1);
  intensity.rowRange(y0, y1).convertTo(rows, CV_64F, 1.0, o_.log_eps);
  cv::max(rows, o_.log_eps, rows);  // I < 0 reads as 0 (cv::log would take |I + eps|)
  cv::log(rows, rows);
  if (!clamp) return;
  for (int y = y0; y < y1; ++y) {
    double* o = out->ptr<double>(y);
    for (int x = 0; x < width_; ++x) o[x] = std::min(std::max(log_lo_, o[x]), log_hi_);
  }
}

cv::Mat EventGenerator::to_log(const cv::Mat& intensity) const {
  check_image(intensity, "to_log");
  cv::Mat out(height_, width_, CV_64F);
  compute_log(intensity, &out, 0, height_, true);
  return out;
}

int64_t EventGenerator::draw_next_noise(int i, int64_t t_from) {
  const double rate = o_.shot_noise_rate_hz + (hot_[i] ? o_.hot_pixel_rate_hz : 0.0);
  if (rate <= 0) return kNoNoise;
  const double u = 1.0 - uniform();  // (0, 1]
  const double wait_ns = -std::log(u) * (1e9 / rate);
  // Saturate instead of overflowing for tiny rates (a wait beyond the int64 range never comes).
  const double room = t_from >= 0 ? static_cast<double>(kNoNoise - t_from) : 9e18;
  if (!(wait_ns < room - 4096.0)) return kNoNoise;
  return t_from + std::max<int64_t>(1, std::llround(wait_ns));
}

void EventGenerator::reset(const cv::Mat& intensity, int64_t t_ns) {
  check_image(intensity, "reset");
  compute_log(intensity, &log_, 0, height_, true);
  rng_.seed(stream_seed(o_.seed, kNoiseStream));
  has_spare_normal_ = false;
  const int n = width_ * height_;
  const double* L = log_.ptr<double>();
  double* r = ref_.ptr<double>();
  const double* cp = c_pos_.ptr<double>();
  for (int i = 0; i < n; ++i) r[i] = o_.leak_rate_hz > 0 ? L[i] - uniform() * cp[i] : L[i];
  std::fill(refractory_end_.begin(), refractory_end_.end(), kNever);
  noise_heap_.clear();
  for (int i = 0; i < n; ++i) {
    next_noise_[i] = any_noise_ ? draw_next_noise(i, t_ns) : kNoNoise;
    if (next_noise_[i] != kNoNoise) noise_heap_.push_back({next_noise_[i], static_cast<uint32_t>(i)});
  }
  std::make_heap(noise_heap_.begin(), noise_heap_.end(), std::greater<>());
  in_reset_.clear();
  t_ns_ = t_ns;
  last_max_change_ = 0;
  initialised_ = true;
}

void EventGenerator::emit(int64_t t, int64_t t0, int64_t t1, int i, bool on, bool noise) {
  if (o_.timestamp_jitter_ns > 0) {
    const double j = std::round(o_.timestamp_jitter_ns * normal());
    const double room_hi = static_cast<double>(t1 - t), room_lo = static_cast<double>(t0 + 1 - t);
    t += static_cast<int64_t>(std::clamp(j, room_lo, room_hi));
  }
  pending_.push_back(Pending{t, 0, static_cast<uint32_t>(i), static_cast<uint8_t>(on ? 0 : 1),
                             static_cast<uint8_t>(noise ? 1 : 0)});
}

// The general path for one pixel over (t0, t1]: a sequence of free segments separated by events
// that reset the pixel (refractory) and by noise events. Within a free segment starting at
// fraction fa with reference `ref` (the reference's value at fa; it drifts down by D per unit
// fraction), L(f) - r(f) = L(f) - ref + D (f - fa) is linear in f and each crossing of +C+ / -C-
// is solved in closed form.
void EventGenerator::process_pixel(int i, int64_t t0, int64_t t1, double leak_per_cp) {
  const double L0 = log_.ptr<double>()[i];
  const double L1 = log_next_.ptr<double>()[i];
  const double dL = L1 - L0;
  const double cp = c_pos_.ptr<double>()[i];
  const double cn = c_neg_.ptr<double>()[i];
  const double D = cp * leak_per_cp;
  const double s = dL + D;  // slope of L - r per unit fraction while free
  const double dtd = static_cast<double>(t1 - t0);
  const int64_t R = o_.refractory_ns;
  double* ref_out = ref_.ptr<double>() + i;
  auto level = [&](double f) { return f >= 1.0 ? L1 : L0 + dL * f; };
  auto frac = [&](int64_t t) { return static_cast<double>(t - t0) / dtd; };

  int64_t reset_end = refractory_end_[i];
  double fa = 0.0;
  double ref = *ref_out;
  int64_t t_min = t0 + 1;  // earliest stamp allowed in the current free segment
  bool in_reset = reset_end > t0;
  for (;;) {
    if (in_reset) {
      // Held in reset until reset_end: the reference follows L; noise in the reset is lost
      // (by memorylessness the next noise event is drawn afresh from the release).
      in_reset = false;
      if (next_noise_[i] < reset_end) next_noise_[i] = draw_next_noise(i, reset_end);
      if (reset_end > t1) {
        *ref_out = L1;
        refractory_end_[i] = reset_end;
        return;
      }
      fa = frac(reset_end);
      ref = level(fa);
      t_min = reset_end;
    }
    const int64_t tn = next_noise_[i];
    const bool noise_here = tn <= t1;
    const double fend = noise_here ? frac(tn) : 1.0;
    const double level_end = level(fend) + D * (fend - fa);  // L - ref at fend is level_end - ref
    bool reset_now = false;
    while (s != 0) {
      const bool on = s > 0;
      const double target = on ? ref + cp : ref - cn;
      if (on ? level_end < target : level_end > target) break;  // not reached in this segment
      double f = (target - L0 + D * fa) / s;
      f = std::clamp(f, fa, fend);
      int64_t t = t0 + std::clamp<int64_t>(std::llround(f * dtd), 1, t1 - t0);
      t = std::max(t, t_min);
      if (noise_here) t = std::min(t, tn);
      // An ON event while L did not rise can only come from the leak drift: labelled noise.
      emit(t, t0, t1, i, on, on && dL <= 0);
      ref = target;
      if (R > 0) {
        reset_end = saturating_add(t, R);
        in_reset = true;
        reset_now = true;
        break;
      }
    }
    if (reset_now) continue;
    if (!noise_here) break;
    // Noise event at tn: a pixel event (reset to the current level, then refractory).
    const double rate_hot = hot_[i] ? o_.hot_pixel_rate_hz : 0.0;
    const double x = uniform() * (o_.shot_noise_rate_hz + rate_hot);
    const bool on = x < rate_hot || x - rate_hot < 0.5 * o_.shot_noise_rate_hz;
    emit(tn, t0, t1, i, on, true);
    fa = fend;
    ref = level(fa);
    t_min = tn;
    next_noise_[i] = draw_next_noise(i, tn);
    if (R > 0) {
      reset_end = saturating_add(tn, R);
      in_reset = true;
    }
  }
  *ref_out = ref - D * (1.0 - fa);
  refractory_end_[i] = reset_end;
}

// Sorts pending_ by (time, pixel, ON before OFF). When the key (time offset in the step, pixel
// index, polarity bit) fits 64 bits, an LSD radix sort over 11-bit digits (skipping digits
// that are equal for all events); otherwise std::sort.
void EventGenerator::sort_pending(int64_t dt) {
  const size_t m = pending_.size();
  if (m < 2) return;
  int pixel_bits = 1;
  while ((uint64_t{1} << pixel_bits) < static_cast<uint64_t>(width_) * static_cast<uint64_t>(height_)) ++pixel_bits;
  int time_bits = 1;
  while (time_bits < 63 && (uint64_t{1} << time_bits) <= static_cast<uint64_t>(dt)) ++time_bits;
  if (m < 64 || m >= (size_t{1} << 31) || time_bits + pixel_bits + 1 > 64) {
    std::sort(pending_.begin(), pending_.end(), [](const Pending& a, const Pending& b) {
      if (a.t_ns != b.t_ns) return a.t_ns < b.t_ns;
      if (a.pixel != b.pixel) return a.pixel < b.pixel;
      return a.off < b.off;
    });
    return;
  }
  const int64_t t_first = t_ns_ - dt;  // stamps are in (t_first, t_ns_]
  for (Pending& p : pending_)
    p.key = (static_cast<uint64_t>(p.t_ns - t_first) << (pixel_bits + 1)) | (uint64_t{p.pixel} << 1) | p.off;
  const int total_bits = time_bits + pixel_bits + 1;
  constexpr int kDigit = 11;
  sort_scratch_.resize(m);
  std::array<uint32_t, size_t{1} << kDigit> count;
  Pending* src = pending_.data();
  Pending* dst = sort_scratch_.data();
  for (int shift = 0; shift < total_bits; shift += kDigit) {
    std::fill(count.begin(), count.end(), 0u);
    const uint64_t mask = (uint64_t{1} << kDigit) - 1;
    for (size_t k = 0; k < m; ++k) ++count[(src[k].key >> shift) & mask];
    if (count[(src[0].key >> shift) & mask] == m) continue;  // digit equal everywhere
    uint32_t sum = 0;
    for (uint32_t& c : count) {
      const uint32_t c0 = c;
      c = sum;
      sum += c0;
    }
    for (size_t k = 0; k < m; ++k) dst[count[(src[k].key >> shift) & mask]++] = src[k];
    std::swap(src, dst);
  }
  if (src != pending_.data()) std::copy(src, src + m, pending_.data());
}

void EventGenerator::step(const cv::Mat& intensity, int64_t t_ns, std::vector<Event>* events,
                          const cv::Mat* labels, std::vector<uint16_t>* event_labels) {
  if (!initialised_) throw std::logic_error("EventGenerator::step called before reset");
  check_image(intensity, "step");
  if (t_ns <= t_ns_) {
    std::ostringstream m;
    m << "EventGenerator::step: t_ns " << t_ns << " must be after the previous sample " << t_ns_;
    throw std::invalid_argument(m.str());
  }
  if (events == nullptr) throw std::invalid_argument("EventGenerator::step: events is null");
  const bool want_labels = labels != nullptr && event_labels != nullptr;
  if (want_labels && (labels->rows != height_ || labels->cols != width_ || labels->type() != CV_16UC1))
    throw std::invalid_argument("EventGenerator::step: labels must be a CV_16U image of the generator's size");

  const int64_t t0 = t_ns_, t1 = t_ns;
  pending_.clear();
  const int n = width_ * height_;
  const double leak_per_cp = o_.leak_rate_hz * (static_cast<double>(t1 - t0) * 1e-9);
  const bool leak = leak_per_cp > 0;
  double* L1 = log_next_.ptr<double>();
  const double* L0 = log_.ptr<double>();
  const float* cp = cpf_.data();
  const float* cn = cnf_.data();
  double* ref = ref_.ptr<double>();
  uint8_t* visit = visit_.data();
  // Pass 1, in chunks of rows that stay in cache: log intensity, largest change, and the
  // branch-free band test. A pixel needs the general path when L - r at the end of the step
  // (drift included) leaves (-C-, C+); L - r is linear over the step and started inside the
  // band, so otherwise nothing crosses. Pixels on the fast path only drift their reference.
  const int rows_per_chunk = std::max(1, 4096 / width_);
  double max_change = 0;
  for (int y0 = 0; y0 < height_; y0 += rows_per_chunk) {
    const int y1 = std::min(height_, y0 + rows_per_chunk);
    compute_log(intensity, &log_next_, y0, y1, false);
    const int i1 = y1 * width_;
    const double lo = log_lo_, hi = log_hi_;
    double mc0 = 0, mc1 = 0;  // largest |L1 - L0| (two chains, even and odd pixels)
    if (leak) {
      for (int i = y0 * width_; i < i1; ++i) {
        L1[i] = std::min(std::max(lo, L1[i]), hi);
        const double change = std::abs(L1[i] - L0[i]);
        if (i & 1) mc1 = std::max(mc1, change); else mc0 = std::max(mc0, change);
        const double c_pos = cp[i], c_neg = cn[i];
        const double D = c_pos * leak_per_cp;
        const double d_end = L1[i] + D - ref[i];
        const bool outside = (d_end >= c_pos) | (d_end <= -c_neg);
        visit[i] = static_cast<uint8_t>(outside);
        ref[i] -= outside ? 0.0 : D;
      }
    } else {
      for (int i = y0 * width_; i < i1; ++i) {
        L1[i] = std::min(std::max(lo, L1[i]), hi);
        const double change = std::abs(L1[i] - L0[i]);
        if (i & 1) mc1 = std::max(mc1, change); else mc0 = std::max(mc0, change);
        const double d_end = L1[i] - ref[i];
        const double c_pos = cp[i], c_neg = cn[i];
        visit[i] = static_cast<uint8_t>((d_end >= c_pos) | (d_end <= -c_neg));
      }
    }
    max_change = std::max(max_change, std::max(mc0, mc1));
  }
  // Pixels with a noise event due in (t0, t1] or still in reset also take the general path.
  while (!noise_heap_.empty() && noise_heap_.front().first <= t1) {
    const auto [tn, i] = noise_heap_.front();
    std::pop_heap(noise_heap_.begin(), noise_heap_.end(), std::greater<>());
    noise_heap_.pop_back();
    if (next_noise_[i] == tn) visit[i] = 1;  // else a stale entry of a redrawn time
  }
  for (uint32_t i : in_reset_) visit[i] = 1;
  in_reset_next_.clear();
  // Pass 2: the general path, in pixel order (the order of random draws is deterministic).
  for (int base = 0; base < n; base += 8) {
    uint64_t word = 0;
    if (base + 8 <= n) {
      std::memcpy(&word, visit + base, 8);
      if (word == 0) continue;
    }
    for (int i = base; i < std::min(n, base + 8); ++i) {
      if (!visit[i]) continue;
      const int64_t noise_before = next_noise_[i];
      process_pixel(i, t0, t1, leak_per_cp);
      if (next_noise_[i] != noise_before && next_noise_[i] != kNoNoise) {
        noise_heap_.push_back({next_noise_[i], static_cast<uint32_t>(i)});
        std::push_heap(noise_heap_.begin(), noise_heap_.end(), std::greater<>());
      }
      if (refractory_end_[i] > t1) in_reset_next_.push_back(static_cast<uint32_t>(i));
    }
  }
  in_reset_.swap(in_reset_next_);
  last_max_change_ = max_change;
  cv::swap(log_, log_next_);
  t_ns_ = t1;
  sort_pending(t1 - t0);

  const size_t base = events->size();
  events->resize(base + pending_.size());
  Event* out = events->data() + base;
  for (size_t k = 0; k < pending_.size(); ++k) {
    const Pending& p = pending_[k];
    out[k].t_ns = p.t_ns;
    out[k].x = static_cast<uint16_t>(p.pixel % static_cast<uint32_t>(width_));
    out[k].y = static_cast<uint16_t>(p.pixel / static_cast<uint32_t>(width_));
    out[k].polarity = p.off ? int8_t{-1} : int8_t{1};
  }
  if (want_labels) {
    const uint16_t* lab = labels->ptr<uint16_t>();
    const bool continuous = labels->isContinuous();
    event_labels->reserve(event_labels->size() + pending_.size());
    for (const Pending& p : pending_) {
      if (p.noise) {
        event_labels->push_back(kNoiseLabel);
      } else if (continuous) {
        event_labels->push_back(lab[p.pixel]);
      } else {
        event_labels->push_back(labels->at<uint16_t>(static_cast<int>(p.pixel) / width_,
                                                     static_cast<int>(p.pixel) % width_));
      }
    }
  }
}

}  // namespace evio::simulator
