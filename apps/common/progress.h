// Throttled progress line on stderr for long runs: at most one line per interval (none for runs
// shorter than that), with the fraction done, a count, the elapsed time and an ETA.
#pragma once

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <string>

namespace evio::apps {

class Progress {
 public:
  // command: e.g. "evio convert"; unit: what `count` counts, e.g. "events written".
  Progress(std::string command, bool enabled, std::string unit = "events", double interval_s = 1.0)
      : command_(std::move(command)), unit_(std::move(unit)), enabled_(enabled), interval_(interval_s),
        start_(clock::now()), last_(start_) {}

  // fraction in [0, 1] of the input consumed; extra: appended text (e.g. a rate), may be empty.
  void update(double fraction, int64_t count, const std::string& extra = {}) {
    if (!enabled_) return;
    const auto now = clock::now();
    if (std::chrono::duration<double>(now - last_).count() < interval_) return;
    last_ = now;
    const double s = std::chrono::duration<double>(now - start_).count();
    const double eta = fraction > 1e-6 ? s * (1.0 - fraction) / fraction : 0.0;
    std::fprintf(stderr, "%s: %5.1f%%, %lld %s, %.0f s elapsed, ETA %.0f s%s%s\n", command_.c_str(), 100.0 * fraction,
                 static_cast<long long>(count), unit_.c_str(), s, eta, extra.empty() ? "" : ", ", extra.c_str());
  }

 private:
  using clock = std::chrono::steady_clock;
  std::string command_, unit_;
  bool enabled_;
  double interval_;
  clock::time_point start_, last_;
};

}  // namespace evio::apps
