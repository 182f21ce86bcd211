// Corner events against true corners: per-event corner decisions (eFAST, event Harris, ...) scored
// against known corner points whose image positions are known at every time (e.g. the grid nodes
// of a simulated checkerboard projected through the true camera pose). As in Mueggler et al.
// (BMVC 2017) and tests/frontend: a corner event is a true positive when a true corner lies within
// match_radius_px of its pixel at its time. Reported: precision; chance level (share of all events
// within that radius of a true corner: the precision of flagging events at random); event recall
// (share of those near events flagged); (corner, bin) recall (share of the bins in which a visible,
// moving corner, at least border_px inside the image, gets a corner event within the radius);
// reduction (events per corner event).
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "evio/sensors/measurements.h"

namespace evio::evaluation {

struct CornerScoringOptions {
  double match_radius_px = 2.0;   // a corner event within this distance of a true corner is right, px (> 0)
  int64_t bin_ns = 50'000'000;    // recall bins, ns (> 0)
  double min_speed_pxps = 20.0;   // a corner "moves" in a bin at this mean image speed, px/s (>= 0)
  double border_px = 4.0;         // recall counts corners at least this far inside the image, px (>= 0)
  bool Validate(std::string* why) const;
};

struct CornerMetrics {
  int64_t events = 0;
  int64_t corner_events = 0;
  int64_t true_positives = 0;
  int64_t near_events = 0;          // events within the radius of a true corner
  int64_t near_events_flagged = 0;  // of those, flagged as corners
  int64_t pairs = 0, pairs_hit = 0;              // (corner, bin) pairs: visible and moving; with a hit
  int64_t inner_pairs = 0, inner_pairs_hit = 0;  // the same for inner corners only (e.g. X-junctions)
  double precision() const { return corner_events ? double(true_positives) / double(corner_events) : 0.0; }
  double chance() const { return events ? double(near_events) / double(events) : 0.0; }
  double event_recall() const { return near_events ? double(near_events_flagged) / double(near_events) : 0.0; }
  double pair_recall() const { return pairs ? double(pairs_hit) / double(pairs) : 0.0; }
  double inner_pair_recall() const { return inner_pairs ? double(inner_pairs_hit) / double(inner_pairs) : 0.0; }
  double reduction() const { return corner_events ? double(events) / double(corner_events) : 0.0; }
  // Harmonic mean of precision and (corner, bin) recall (0 when both are 0).
  double f_score() const {
    const double p = precision(), r = pair_recall();
    return p + r > 0 ? 2 * p * r / (p + r) : 0.0;
  }
};

// The image positions of all true corners at a time (event clock), px (pixel (0, 0) the top-left
// pixel centre, as event coordinates): px->at(i) for corner i, NaN when it is not visible (behind
// the camera). px is resized to the corner count by the callee.
using CornerProjector = std::function<void(int64_t t_ns, std::vector<Eigen::Vector2d>* px)>;

// Streams the events (time order) with their corner decisions; finish() gives the metrics.
class CornerEventScorer {
 public:
  // inner[i]: corner i counts in the inner-corner recall (empty: none is inner). Events before
  // t_begin_ns are scored but in no recall bin; bins are the whole bin_ns spans in [t_begin, t_end).
  // Throws std::invalid_argument on invalid options or sizes.
  CornerEventScorer(int width, int height, int num_corners, std::vector<bool> inner, CornerProjector project,
                    int64_t t_begin_ns, int64_t t_end_ns, const CornerScoringOptions& options = {});
  // Whether a true corner lies within the radius of the event's pixel at its time.
  bool near_true_corner(const Event& e);
  // One event; `near` when the caller already knows near_true_corner(e) (e.g. cached across runs).
  void add(const Event& e, bool is_corner);
  void add(const Event& e, bool is_corner, bool near);
  // The metrics so far (the (corner, bin) pairs over the whole span).
  CornerMetrics finish() const;

 private:
  const std::vector<Eigen::Vector2d>& corners_at(int64_t t_ns);
  int width_, height_, num_corners_;
  std::vector<bool> inner_;
  CornerProjector project_;
  int64_t t_begin_ns_, t_end_ns_;
  CornerScoringOptions o_;
  int num_bins_ = 0;
  std::vector<uint8_t> hit_;  // bin x corner
  CornerMetrics m_;
  int64_t cached_t_ = INT64_MIN;
  std::vector<Eigen::Vector2d> cached_;
};

}  // namespace evio::evaluation
