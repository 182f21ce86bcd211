// Corner tracker: links corner events over time into feature tracks by nearest neighbour in
// space-time. Each active track keeps a smoothed position and a velocity; a corner event joins
// the active track whose predicted position (position + velocity x elapsed time) is nearest,
// within `max_distance_px`; otherwise it starts a track. With descriptors, tracks whose
// descriptor is farther than `max_descriptor_distance` are no candidates, and when several remain
// the descriptor distance decides if it passes the ratio test (else the nearest wins), so
// crossing or nearby corners keep their identity. Tracks idle for longer than `max_gap_ns` end.
//
// Positions are in sensor pixels (distorted); the VIO front-end undistorts them through
// EventUndistorter / the camera model. Events must come in non-decreasing time.
#pragma once

#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "evio/frontend/dart.h"
#include "evio/sensors/measurements.h"

namespace evio::frontend {

// Defaults chosen on the simulated checkerboard sequence (tests/frontend/corner_ground_truth.h,
// test_corner_tracks_simulated) by a grid over the position gain, the gate and the velocity
// window: the setting with the lowest error and the longest tracks; a narrower gate fragments the
// tracks (docs/results/corners.md).
struct CornerTrackerOptions {
  double max_distance_px = 4.0;        // association gate around the predicted position, px
  int64_t max_gap_ns = 30'000'000;     // a track with no corner event for this long ends, ns
  double position_gain = 0.1;          // weight of a new corner event in the smoothed position
  int64_t velocity_window_ns = 20'000'000;  // velocity from the smoothed positions over this span, ns
  int64_t min_velocity_span_ns = 3'000'000;  // no velocity (zero) until a track spans this long, ns (<= velocity_window_ns)
  size_t min_length = 10;              // tracks with fewer corner events are not reported
  double descriptor_ratio = 0.8;       // ratio test between the two best tracks' descriptor distances
  // With descriptors: tracks whose descriptor is farther than this are not candidates (a corner
  // that looks different starts its own track). dart_distance_aligned units (distances lie in
  // [0, sqrt(2)]); infinity: off.
  double max_descriptor_distance = std::numeric_limits<double>::infinity();
  bool Validate(std::string* why) const;
};

struct TrackPoint {
  int64_t t_ns = 0;
  float x = 0, y = 0;          // smoothed position after this corner event, px
  uint16_t raw_x = 0, raw_y = 0;  // the corner event's pixel
};

struct CornerTrack {
  int64_t id = 0;
  std::vector<TrackPoint> points;
  int64_t t_begin_ns() const { return points.front().t_ns; }
  int64_t t_end_ns() const { return points.back().t_ns; }
};

struct CornerTrackerStats {
  int64_t corners = 0;          // corner events given
  int64_t tracks_started = 0;
  int64_t tracks_reported = 0;  // ended tracks with at least min_length corner events
  int64_t descriptor_decisions = 0;  // associations decided by descriptors among several candidates
};

class CornerTracker {
 public:

  CornerTracker(int width, int height, const CornerTrackerOptions& options = {});

  // Adds a corner event; returns the id of the track it joined or started. `descriptor` (may be
  // null) is the corner event's DART; a track keeps the latest one it was given, and descriptor
  // decisions compare them with dart_distance_aligned (patterns do not turn or scale between
  // consecutive corner events).
  int64_t add(const Event& corner, const DartDescriptor* descriptor = nullptr);

  // Ends every track idle for longer than max_gap_ns at time t_ns (add() does this lazily).
  void expire(int64_t t_ns);
  // Tracks ended so far with at least min_length points (moved out; call repeatedly to stream).
  std::vector<CornerTrack> take_finished();
  // Ends all tracks and returns the remaining reported ones.
  std::vector<CornerTrack> finish();

  size_t active_tracks() const { return active_.size(); }
  // Calls f(track id, position predicted at t_ns) for every active track updated within max_age_ns
  // of t_ns (position + velocity x elapsed time, px): samples asynchronous tracks at a frame time.
  // Tracks that began less than min_span_ns before t_ns are skipped (too young to trust).
  void predict_active(int64_t t_ns, int64_t max_age_ns, int64_t min_span_ns,
                      const std::function<void(int64_t, const Eigen::Vector2d&)>& f) const {
    for (const Active& a : active_) {
      if (t_ns - a.track.points.back().t_ns > max_age_ns) continue;
      if (t_ns - a.track.points.front().t_ns < min_span_ns) continue;
      f(a.track.id, predict(a, t_ns));
    }
  }
  // Calls f on every active (not yet ended) track, e.g. to draw them.
  void visit_active(const std::function<void(const CornerTrack&)>& f) const {
    for (const Active& a : active_) f(a.track);
  }
  const CornerTrackerStats& stats() const { return stats_; }

 private:
  struct Active {
    CornerTrack track;
    Eigen::Vector2d position;
    Eigen::Vector2d velocity = Eigen::Vector2d::Zero();
    DartDescriptor descriptor;
    bool has_descriptor = false;
    int cell = -1;
  };
  Eigen::Vector2d predict(const Active& a, int64_t t_ns) const;
  int cell_of(const Eigen::Vector2d& p) const;
  void move_to_cell(size_t slot, int cell);
  void end_track(size_t slot);
  void update_velocity(Active* a) const;

  CornerTrackerOptions options_;
  int width_, height_;
  int cell_size_, cells_x_, cells_y_;
  std::vector<std::vector<size_t>> cells_;  // slot indices of active tracks per grid cell
  std::vector<Active> active_;              // slots; swap-removed
  std::vector<CornerTrack> finished_;
  int64_t next_id_ = 0;
  int64_t last_expire_ns_;
  CornerTrackerStats stats_;
};

}  // namespace evio::frontend
