#include "evio/sensors/event_buffer.h"

#include <algorithm>

namespace evio {

const char* polarity_convention_name(PolarityConvention c) {
  switch (c) {
    case PolarityConvention::kUnknown: return "unknown";
    case PolarityConvention::kZeroOne: return "0/1";
    case PolarityConvention::kMinusPlusOne: return "-1/+1";
  }
  return "?";
}

EventSpan EventSpan::slice(int64_t t0_ns, int64_t t1_ns) const {
  if (t1_ns <= t0_ns || size_ == 0) return EventSpan(data_, 0);
  const auto by_time = [](const Event& e, int64_t t) { return e.t_ns < t; };
  const Event* first = std::lower_bound(begin(), end(), t0_ns, by_time);
  const Event* last = std::lower_bound(first, end(), t1_ns, by_time);
  return EventSpan(first, static_cast<size_t>(last - first));
}

EventSpan EventSpan::subspan(size_t first, size_t count) const {
  first = std::min(first, size_);
  count = std::min(count, size_ - first);
  return EventSpan(data_ + first, count);
}

bool EventBuffer::is_time_sorted() const {
  return std::is_sorted(events_.begin(), events_.end(),
                        [](const Event& a, const Event& b) { return a.t_ns < b.t_ns; });
}

void EventStatistics::add(EventSpan events) {
  if (events.empty()) return;
  if (count == 0) t_first_ns = events.front().t_ns;
  int64_t n_on = 0;
  int mx = max_x, my = max_y;
  for (const Event& e : events) {
    n_on += e.polarity > 0;
    mx = std::max(mx, static_cast<int>(e.x));
    my = std::max(my, static_cast<int>(e.y));
  }
  max_x = mx;
  max_y = my;
  on += n_on;
  off += static_cast<int64_t>(events.size()) - n_on;
  count += static_cast<int64_t>(events.size());
  t_last_ns = events.back().t_ns;
}

double EventStatistics::rate_hz() const {
  const int64_t d = duration_ns();
  return d > 0 ? static_cast<double>(count) / (static_cast<double>(d) * 1e-9) : 0.0;
}

}  // namespace evio
