// Config tables of event frames and the feature tracker (option_tables.h).
#include "option_tables.h"

namespace evio::apps {

using yaml_config::Range;
using yaml_config::Table;

const Table<frontend::EventFrameOptions>& event_frame_table() {
  using O = frontend::EventFrameOptions;
  static const Table<O> t =
      Table<O>("frame settings")
          .integer("events_per_frame", &O::events_per_frame, 1, 100000000)
          .duration_ms("min_window_ms", &O::min_window_ns, Range::kNonNegative)
          .duration_ms("max_window_ms", &O::max_window_ns, Range::kPositive)
          .duration_ms("sparse_max_window_ms", &O::sparse_max_window_ns, Range::kNonNegative)
          .duration_ms("sparse_after_ms", &O::sparse_after_ns, Range::kNonNegative)
          .integer("min_events", &O::min_events, 1, 100000000)
          .number("overlap", &O::overlap, Range::kNonNegative, "fraction of a frame's events")
          .boolean("motion_compensation", &O::motion_compensation)
          .boolean("use_depth", &O::use_depth)
          .boolean("use_polarity", &O::use_polarity)
          .boolean("normalize", &O::normalize)
          .number("clip_percentile", &O::clip_percentile, Range::kUnit, "")
          .number("clip_count", &O::clip_count, Range::kNonNegative, "events per pixel")
          .duration_ms("knot_spacing_ms", &O::knot_spacing_ns, Range::kPositive)
          .duration_ms("max_imu_extrapolation_ms", &O::max_imu_extrapolation_ns, Range::kNonNegative)
          .duration_ms("max_imu_gap_ms", &O::max_imu_gap_ns, Range::kPositive)
          .number("event_lag_px", &O::event_lag_px, Range::kNonNegative, "px")
          .boolean("keep_accumulator", &O::keep_accumulator)
          .number("time_surface_tau_fraction", &O::time_surface_tau_fraction, Range::kNonNegative, "fraction of the frame's span; 0: counts")
          .validate();
  return t;
}

const Table<frontend::FeatureTrackerOptions>& feature_tracker_table() {
  using O = frontend::FeatureTrackerOptions;
  using frontend::RansacModel;
  static const Table<O> t =
      Table<O>("tracker settings")
          .integer("grid_cols", &O::grid_cols, 1, 100)
          .integer("grid_rows", &O::grid_rows, 1, 100)
          .integer("max_features", &O::max_features, 1, 100000)
          .integer("max_per_cell", &O::max_per_cell, 1, 100000)
          .integer("fast_threshold", &O::fast_threshold, 1, 255)
          .integer("min_distance_px", &O::min_distance_px, 0, 1000)
          .integer("border_px", &O::border_px, 0, 1000)
          .integer("klt_window_px", &O::klt_window_px, 3, 255)
          .integer("klt_pyramid_levels", &O::klt_pyramid_levels, 0, 8)
          .integer("klt_max_iterations", &O::klt_max_iterations, 1, 1000)
          .number("klt_epsilon_px", &O::klt_epsilon_px, Range::kPositive, "px")
          .number("forward_backward_max_px", &O::forward_backward_max_px, Range::kPositive, "px")
          .integer("template_max_age_frames", &O::template_max_age_frames, 1, 100000)
          .boolean("template_fallback", &O::template_fallback)
          .number("template_max_rotation_deg", &O::template_max_rotation_deg, Range::kNonNegative, "deg")
          .integer("anchor_frames", &O::anchor_frames, 0, 100000)
          .number("anchor_ransac_threshold_px", &O::anchor_ransac_threshold_px, Range::kPositive, "px")
          .number("reacquire_max_age_s", &O::reacquire_max_age_s, Range::kNonNegative, "s")
          .number("reacquire_max_px", &O::reacquire_max_px, Range::kPositive, "px")
          .choice("ransac", &O::ransac,
                  {{"two_point", RansacModel::kTwoPoint}, {"two_point_triangulating", RansacModel::kTwoPointTriangulating}, {"five_point", RansacModel::kFivePoint}, {"none", RansacModel::kNone}})
          .number("ransac_threshold_px", &O::ransac_threshold_px, Range::kPositive, "px")
          .integer("ransac_max_iterations", &O::ransac_max_iterations, 1, 1000000)
          .integer("min_tracks_before_detection", &O::min_tracks_before_detection, 0, 100000)
          .seed("seed", &O::seed)
          .validate();
  return t;
}

}  // namespace evio::apps
