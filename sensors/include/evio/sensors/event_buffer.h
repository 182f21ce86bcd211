// Contiguous, time-ordered event storage with O(log n) slicing by time. Events are kept as an
// array of 16-byte structs: per-event algorithms touch all fields, so AoS is the cache-friendly
// layout here. Slices are non-owning views valid while the buffer is not modified.
#pragma once

#include <cstddef>
#include <vector>

#include "evio/sensors/measurements.h"

namespace evio {

class EventSpan {
 public:
  EventSpan() = default;
  EventSpan(const Event* data, size_t size) : data_(data), size_(size) {}

  const Event* begin() const { return data_; }
  const Event* end() const { return data_ + size_; }
  const Event* data() const { return data_; }
  size_t size() const { return size_; }
  bool empty() const { return size_ == 0; }
  const Event& operator[](size_t i) const { return data_[i]; }
  const Event& front() const { return data_[0]; }
  const Event& back() const { return data_[size_ - 1]; }

  // Events with t0_ns <= t_ns < t1_ns, by binary search (requires time order).
  EventSpan slice(int64_t t0_ns, int64_t t1_ns) const;
  // Index range [first, first + count) clamped to the span.
  EventSpan subspan(size_t first, size_t count) const;

 private:
  const Event* data_ = nullptr;
  size_t size_ = 0;
};

class EventBuffer {
 public:
  EventBuffer() = default;
  explicit EventBuffer(std::vector<Event> events) : events_(std::move(events)) {}

  void push_back(const Event& e) { events_.push_back(e); }
  void append(EventSpan s) { events_.insert(events_.end(), s.begin(), s.end()); }
  void reserve(size_t n) { events_.reserve(n); }
  void clear() { events_.clear(); }
  size_t size() const { return events_.size(); }
  bool empty() const { return events_.empty(); }
  const Event& operator[](size_t i) const { return events_[i]; }
  const Event& front() const { return events_.front(); }
  const Event& back() const { return events_.back(); }
  const Event* data() const { return events_.data(); }
  auto begin() const { return events_.begin(); }
  auto end() const { return events_.end(); }

  EventSpan span() const { return EventSpan(events_.data(), events_.size()); }
  EventSpan slice(int64_t t0_ns, int64_t t1_ns) const { return span().slice(t0_ns, t1_ns); }

  // True if timestamps never decrease (equal timestamps are allowed: sensors emit them).
  bool is_time_sorted() const;

  std::vector<Event>& events() { return events_; }
  const std::vector<Event>& events() const { return events_; }

 private:
  std::vector<Event> events_;
};

// Streaming summary of an event stream: counts, time span, polarity balance, coordinate range.
struct EventStatistics {
  int64_t count = 0;
  int64_t on = 0;
  int64_t off = 0;
  int64_t t_first_ns = 0;
  int64_t t_last_ns = 0;
  int max_x = -1;
  int max_y = -1;

  void add(EventSpan events);
  int64_t duration_ns() const { return count > 0 ? t_last_ns - t_first_ns : 0; }
  // Mean rate in events/s over [t_first, t_last]; 0 when the span is empty.
  double rate_hz() const;
  // Fraction of ON events in [0, 1]; 0 when there are no events.
  double on_fraction() const { return count > 0 ? static_cast<double>(on) / count : 0.0; }
};

}  // namespace evio
