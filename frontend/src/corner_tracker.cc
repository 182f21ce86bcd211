#include "evio/frontend/corner_tracker.h"
#include "evio/frontend/option_tables.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace evio::frontend {

bool CornerTrackerOptions::Validate(std::string* why) const {
  if (!corner_tracker_table().check(*this, why)) return false;
  if (min_velocity_span_ns > velocity_window_ns) {
    return validation_failed(why, "min_velocity_span_ms " + yaml_config::yaml_number(min_velocity_span_ns * 1e-6) +
                                      " is longer than velocity_window_ms " + yaml_config::yaml_number(velocity_window_ns * 1e-6));
  }
  return true;
}

CornerTracker::CornerTracker(int width, int height, const CornerTrackerOptions& options)
    : options_(options), width_(width), height_(height), last_expire_ns_(std::numeric_limits<int64_t>::min()) {
  std::string why;
  if (!options.Validate(&why)) throw std::invalid_argument("corner tracker options: " + why);
  if (width <= 0 || height <= 0) {
    throw std::invalid_argument("corner tracker: sensor size " + std::to_string(width) + "x" + std::to_string(height) +
                                " (expected positive pixels)");
  }
  // Cells at least twice the gate, so the 3x3 cells around a corner hold every track whose
  // stored position is within gate + one cell of it (tracks move less than a cell between updates
  // at the speeds the gate allows).
  cell_size_ = std::max(16, static_cast<int>(std::ceil(2 * options.max_distance_px)));
  cells_x_ = (width + cell_size_ - 1) / cell_size_;
  cells_y_ = (height + cell_size_ - 1) / cell_size_;
  cells_.resize(static_cast<size_t>(cells_x_) * cells_y_);
}

int CornerTracker::cell_of(const Eigen::Vector2d& p) const {
  const int cx = std::clamp(static_cast<int>(std::floor(p.x() / cell_size_)), 0, cells_x_ - 1);
  const int cy = std::clamp(static_cast<int>(std::floor(p.y() / cell_size_)), 0, cells_y_ - 1);
  return cy * cells_x_ + cx;
}

void CornerTracker::move_to_cell(size_t slot, int cell) {
  Active& a = active_[slot];
  if (a.cell == cell) return;
  if (a.cell >= 0) {
    auto& v = cells_[a.cell];
    v.erase(std::find(v.begin(), v.end(), slot));
  }
  cells_[cell].push_back(slot);
  a.cell = cell;
}

Eigen::Vector2d CornerTracker::predict(const Active& a, int64_t t_ns) const {
  const double dt = static_cast<double>(t_ns - a.track.points.back().t_ns) * 1e-9;
  return a.position + a.velocity * dt;
}

void CornerTracker::update_velocity(Active* a) const {
  const auto& pts = a->track.points;
  const int64_t t = pts.back().t_ns;
  // First point inside the window (points are few per window; scan back from the end).
  size_t k = pts.size() - 1;
  while (k > 0 && t - pts[k - 1].t_ns <= options_.velocity_window_ns) --k;
  const int64_t span = t - pts[k].t_ns;
  if (span < options_.min_velocity_span_ns) {
    a->velocity.setZero();
    return;
  }
  const double s = static_cast<double>(span) * 1e-9;
  a->velocity = Eigen::Vector2d(pts.back().x - pts[k].x, pts.back().y - pts[k].y) / s;
}

void CornerTracker::end_track(size_t slot) {
  Active& a = active_[slot];
  if (a.track.points.size() >= options_.min_length) {
    ++stats_.tracks_reported;
    finished_.push_back(std::move(a.track));
  }
  auto& v = cells_[a.cell];
  v.erase(std::find(v.begin(), v.end(), slot));
  const size_t last = active_.size() - 1;
  if (slot != last) {
    // Move the last slot into this one and fix its cell entry.
    active_[slot] = std::move(active_[last]);
    auto& w = cells_[active_[slot].cell];
    *std::find(w.begin(), w.end(), last) = slot;
  }
  active_.pop_back();
}

void CornerTracker::expire(int64_t t_ns) {
  for (size_t s = active_.size(); s-- > 0;) {
    if (t_ns - active_[s].track.points.back().t_ns > options_.max_gap_ns) end_track(s);
  }
  last_expire_ns_ = t_ns;
}

int64_t CornerTracker::add(const Event& corner, const DartDescriptor* descriptor) {
  ++stats_.corners;
  const int64_t t = corner.t_ns;
  if (last_expire_ns_ == std::numeric_limits<int64_t>::min() || t - last_expire_ns_ > options_.max_gap_ns / 4) expire(t);
  const Eigen::Vector2d z(corner.x, corner.y);
  const int c = cell_of(z);
  const int cx = c % cells_x_, cy = c / cells_x_;
  // Candidates within the gate, nearest first.
  struct Candidate {
    size_t slot;
    double d2;
  };
  Candidate cand[8];
  int n = 0;
  const double gate2 = options_.max_distance_px * options_.max_distance_px;
  for (int y = std::max(0, cy - 1); y <= std::min(cells_y_ - 1, cy + 1); ++y) {
    for (int x = std::max(0, cx - 1); x <= std::min(cells_x_ - 1, cx + 1); ++x) {
      for (size_t slot : cells_[static_cast<size_t>(y) * cells_x_ + x]) {
        const Active& a = active_[slot];
        if (t - a.track.points.back().t_ns > options_.max_gap_ns) continue;
        const double d2 = (predict(a, t) - z).squaredNorm();
        if (d2 > gate2) continue;
        // Keep the 8 nearest (sorted insertion).
        int i = std::min(n, 7);
        if (n == 8 && d2 >= cand[7].d2) continue;
        while (i > 0 && cand[i - 1].d2 > d2) {
          cand[i] = cand[i - 1];
          --i;
        }
        cand[i] = {slot, d2};
        n = std::min(n + 1, 8);
      }
    }
  }
  if (descriptor != nullptr && n > 0) {
    // Descriptor gate, then the ratio test among what remains (nearest first otherwise).
    float dist[8];
    int m = 0;
    for (int i = 0; i < n; ++i) {
      const Active& a = active_[cand[i].slot];
      const float d = a.has_descriptor ? dart_distance_aligned(*descriptor, a.descriptor)
                                       : std::numeric_limits<float>::infinity();
      if (a.has_descriptor && !(d <= options_.max_descriptor_distance)) continue;
      cand[m] = cand[i];
      dist[m++] = d;
    }
    n = m;
    if (n > 1) {
      int best = 0;
      for (int i = 1; i < n; ++i) best = dist[i] < dist[best] ? i : best;
      float second = std::numeric_limits<float>::infinity();
      for (int i = 0; i < n; ++i) second = i != best ? std::min(second, dist[i]) : second;
      if (std::isfinite(dist[best]) && dist[best] < options_.descriptor_ratio * second) {
        std::swap(cand[0], cand[best]);
        ++stats_.descriptor_decisions;
      }
    }
  }
  const size_t chosen = n > 0 ? cand[0].slot : active_.size();
  TrackPoint p;
  p.t_ns = t;
  p.raw_x = corner.x;
  p.raw_y = corner.y;
  if (chosen == active_.size()) {
    Active a;
    a.track.id = next_id_++;
    a.position = z;
    if (descriptor != nullptr) {
      a.descriptor = *descriptor;
      a.has_descriptor = true;
    }
    p.x = static_cast<float>(z.x());
    p.y = static_cast<float>(z.y());
    a.track.points.push_back(p);
    active_.push_back(std::move(a));
    move_to_cell(active_.size() - 1, c);
    ++stats_.tracks_started;
    return active_.back().track.id;
  }
  Active& a = active_[chosen];
  const Eigen::Vector2d pred = predict(a, t);
  a.position = pred + options_.position_gain * (z - pred);
  if (descriptor != nullptr) {
    a.descriptor = *descriptor;
    a.has_descriptor = true;
  }
  p.x = static_cast<float>(a.position.x());
  p.y = static_cast<float>(a.position.y());
  a.track.points.push_back(p);
  update_velocity(&a);
  move_to_cell(chosen, cell_of(a.position));
  return a.track.id;
}

std::vector<CornerTrack> CornerTracker::take_finished() {
  std::vector<CornerTrack> out;
  out.swap(finished_);
  return out;
}

std::vector<CornerTrack> CornerTracker::finish() {
  while (!active_.empty()) end_track(active_.size() - 1);
  return take_finished();
}

}  // namespace evio::frontend
