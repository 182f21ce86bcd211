#include "evio/mapping/scaled_decay.h"

#include <algorithm>
#include <cmath>

namespace evio::mapping {

ScaledDecayClock::ScaledDecayClock(double alpha_per_ns, int64_t t_start_ns)
    : alpha_per_ns_(alpha_per_ns), t_ref_ns_(t_start_ns), t_fold_ns_(t_start_ns) {
  // Rebase before exp(alpha d) exceeds e^20 or d leaves the tables' 33 bits.
  const double span = alpha_per_ns_ > 0 ? kMaxExponent / alpha_per_ns_ : 1e300;
  span_ns_ = static_cast<uint64_t>(std::min(span, static_cast<double>(kTableSpanNs)));
  const size_t digits = size_t{1} << kDigitBits;
  exp_lo_.resize(digits);
  exp_mid_.resize(digits);
  exp_hi_.resize(digits);
  auto e = [this](double d_ns) { return static_cast<float>(std::min(std::exp(alpha_per_ns_ * d_ns), 3e38)); };
  for (size_t j = 0; j < digits; ++j) {
    exp_lo_[j] = e(static_cast<double>(j));
    exp_mid_[j] = e(static_cast<double>(j << kDigitBits));
    exp_hi_[j] = e(static_cast<double>(j << (2 * kDigitBits)));
  }
}

double ScaledDecayClock::fold(int64_t t_ns) {
  if (t_ns <= t_fold_ns_) return 0.0;
  const double dw = std::exp(exponent(t_fold_ns_)) * std::expm1(alpha_per_ns_ * static_cast<double>(t_ns - t_fold_ns_));
  t_fold_ns_ = t_ns;
  return dw;
}

ScaledDecayClock::Rebase ScaledDecayClock::rebase(int64_t t_ns) {
  // S' = S exp(-alpha (t_ns - t_ref)) + X_F (1 - exp(-alpha (t_ns - t_fold))), in double (no
  // overflow whatever the gap).
  t_ns = std::max(t_ns, t_fold_ns_);  // a frame later than the event that asked: rebase there
  const double a = exponent(t_ns);
  Rebase r;
  r.scale = a > 700 ? 0.0 : std::exp(-a);
  r.gain = t_ns > t_fold_ns_ ? -std::expm1(-alpha_per_ns_ * static_cast<double>(t_ns - t_fold_ns_)) : 0.0;
  t_ref_ns_ = t_fold_ns_ = t_ns;
  return r;
}

ScaledDecayClock::Readout ScaledDecayClock::readout(int64_t t_ns) const {
  Readout r;
  r.inv = std::exp(-exponent(t_ns));
  r.gain = t_ns > t_fold_ns_ ? -std::expm1(-alpha_per_ns_ * static_cast<double>(t_ns - t_fold_ns_)) : 0.0;
  return r;
}

}  // namespace evio::mapping
