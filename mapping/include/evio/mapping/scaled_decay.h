// The time base shared by the scaled-state filters of image reconstruction: the complementary
// filter (reconstruction.h) and the asynchronous convolutions (async_convolution.h). Both solve
//   dX/dt = E(t) - alpha (X - X_F)
// per pixel (X_F held between frames) exactly, by holding the state scaled, S = X w(t) with
// w(t) = exp(alpha (t - t_ref)): an event at t_e adds c w(t_e) and nothing else, a reference X_F
// held over (t_a, t_b] adds X_F (w(t_b) - w(t_a)), and a readout is X = S / w(t) + X_F (1 -
// w(t_fold) / w(t)). This class owns t_ref, the frame-fold time t_fold, w per event from three
// tables, and the factors of rebases (rescaling to a new t_ref) and readouts; the filters apply
// them to their own planes. Times int64 ns; exponentials in double, w per event in float.
#pragma once

#include <cstdint>
#include <cstring>
#include <vector>

namespace evio::mapping {

// exp(a) rounded to float, for a <= ~80: e^a = 2^k e^r with k = round(a / ln 2), |r| <= ln(2)/2,
// e^r by its Taylor polynomial of degree 7 in double (truncation below 5e-9 relative, under the
// float rounding of 6e-8). Cheaper per event than glibc's exp(), and branch-free but for the
// underflow test.
inline float exp_to_float(double a) {
  if (a < -87.0) return 0.0f;
  constexpr double kLog2e = 1.4426950408889634, kLn2 = 0.6931471805599453;
  constexpr double kRound = 6755399441055744.0;  // 1.5 * 2^52: adding it rounds to an integer
  const double kd = (a * kLog2e + kRound) - kRound;
  const double r = a - kd * kLn2;
  const double p =
      1.0 + r * (1.0 + r * (0.5 + r * (1.0 / 6 + r * (1.0 / 24 + r * (1.0 / 120 + r * (1.0 / 720 + r * (1.0 / 5040)))))));
  const int64_t bits = (static_cast<int64_t>(kd) + 1023) << 52;
  double scale;
  std::memcpy(&scale, &bits, sizeof(scale));
  return static_cast<float>(p * scale);
}

class ScaledDecayClock {
 public:
  // The filters rescale their state before exp(alpha (t - t_ref)) exceeds e^20.
  static constexpr double kMaxExponent = 20.0;

  // alpha_per_ns = 2 pi f * 1e-9 (>= 0; 0: no decay, w = 1); t_start_ns: t_ref = t_fold at start.
  ScaledDecayClock(double alpha_per_ns, int64_t t_start_ns);

  double alpha_per_ns() const { return alpha_per_ns_; }
  int64_t t_ref_ns() const { return t_ref_ns_; }
  int64_t t_fold_ns() const { return t_fold_ns_; }
  // alpha (t - t_ref), the log of w(t).
  double exponent(int64_t t_ns) const { return alpha_per_ns_ * static_cast<double>(t_ns - t_ref_ns_); }
  // True when t_ns is later than the tables reach: the filter rebases to t_ns first.
  bool needs_rebase(int64_t t_ns) const { return t_ns - t_ref_ns_ > static_cast<int64_t>(span_ns_); }

  // w(t_e) of an event, in float: from three tables over the 11-bit digits of t_e - t_ref (about
  // 4 float ulps), or exp_to_float before t_ref (out of order; w < 1). False when t_e is beyond
  // the tables' span: rebase(t_e), then ask again (the event is then at or before t_ref).
  bool event_weight(int64_t t_ns, float* w) const {
    const uint64_t d = static_cast<uint64_t>(t_ns - t_ref_ns_);  // wraps when negative
    if (d <= span_ns_) {
      *w = exp_hi_[d >> (2 * kDigitBits)] * exp_mid_[(d >> kDigitBits) & kDigitMask] * exp_lo_[d & kDigitMask];
      return true;
    }
    if (static_cast<int64_t>(d) > 0) return false;
    *w = exp_to_float(exponent(t_ns));
    return true;
  }

  // Moves t_fold to t_ns (> t_fold) and returns the weight a held reference X_F gains over
  // (t_fold, t_ns]: w(t_ns) - w(t_fold) = w(t_fold) expm1(alpha (t_ns - t_fold)), in double
  // (0 when t_ns <= t_fold: nothing moves).
  double fold(int64_t t_ns);

  // Rescales to t_ref = t_fold = max(t_ns, t_fold): the filter sets S' = S scale + X_F gain (the
  // state in plain units at the new t_ref; scale 0 after gaps so long that e^-a underflows).
  struct Rebase {
    double scale;
    double gain;
  };
  Rebase rebase(int64_t t_ns);

  // X(t) = S inv + X_F gain for a readout at t_ns (>= t_fold).
  struct Readout {
    double inv;
    double gain;
  };
  Readout readout(int64_t t_ns) const;

 private:
  static constexpr int kDigitBits = 11;
  static constexpr uint64_t kDigitMask = (uint64_t{1} << kDigitBits) - 1;
  static constexpr uint64_t kTableSpanNs = (uint64_t{1} << (3 * kDigitBits)) - 1;  // 8.6 s

  double alpha_per_ns_;
  int64_t t_ref_ns_, t_fold_ns_;
  uint64_t span_ns_;  // rebase when t - t_ref exceeds this (e^20, or the tables' 33 bits)
  std::vector<float> exp_lo_, exp_mid_, exp_hi_;
};

}  // namespace evio::mapping
