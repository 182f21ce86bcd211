// The config tables of the back-end's options structs (option_tables.h).
#include "evio/backend/option_tables.h"

namespace evio::backend {

using yaml_config::Interval;
using yaml_config::Range;
using yaml_config::Table;

const Table<SlidingWindowOptions>& sliding_window_table() {
  using O = SlidingWindowOptions;
  static const Table<O> t =
      Table<O>("window settings")
          .integer("size", &O::window_size, 2, 200)
          .integer("max_iterations", &O::max_iterations, 1, 1000)
          .number("function_tolerance", &O::function_tolerance, Interval::open(0, 1), "relative cost change")
          .seconds_as_ms("max_solver_time_ms", &O::max_solver_time_s, Range::kNonNegative)
          .choice("loss", &O::loss, {{"huber", RobustLoss::kHuber}, {"cauchy", RobustLoss::kCauchy}, {"none", RobustLoss::kNone}})
          .number("loss_scale", &O::loss_scale, Range::kPositive, "pixel sigmas")
          .number("pixel_sigma", &O::pixel_sigma, Range::kPositive, "px")
          .number("keyframe_min_parallax_px", &O::keyframe_min_parallax_px, Range::kPositive, "px")
          .number("keyframe_min_tracked_ratio", &O::keyframe_min_tracked_ratio, Range::kUnit, "")
          .seconds_as_ms("keyframe_max_interval_ms", &O::keyframe_max_interval_s, Range::kPositive)
          .integer("keyframe_min_tracks", &O::keyframe_min_tracks, 0, 100000)
          .seconds_as_ms("keyframe_max_interval_without_tracks_ms", &O::keyframe_max_interval_without_tracks_s, Range::kPositive)
          .number("min_triangulation_angle_deg", &O::min_triangulation_angle_deg, Interval::closed_open(0, 90), "deg")
          .number("max_reprojection_px", &O::max_reprojection_px, Range::kPositive, "px")
          .number("min_depth_m", &O::min_depth_m, Range::kPositive, "m")
          .choice("tracked_landmark_marginalisation", &O::tracked_landmark_marginalisation,
                  {{"drop", TrackedLandmarkMarginalisation::kDrop},
                   {"double_count", TrackedLandmarkMarginalisation::kDoubleCount},
                   {"restart", TrackedLandmarkMarginalisation::kRestart},
                   {"split", TrackedLandmarkMarginalisation::kSplit}})
          .boolean("rotation_only_model", &O::rotation_only_model)
          .boolean("rotation_only_static_centre", &O::rotation_only_static_centre)
          .boolean("rotation_only_imu_centre", &O::rotation_only_imu_centre)
          .number("rotation_only_gric_margin", &O::rotation_only_gric_margin, Range::kNonNegative, "GRIC units")
          .integer("rotation_only_min_keyframes", &O::rotation_only_min_keyframes, 1, 1000)
          .seconds_as_ms("rotation_only_min_duration_ms", &O::rotation_only_min_duration_s, Range::kNonNegative)
          .number("rotation_only_parallax_px", &O::rotation_only_parallax_px, Range::kNonNegative, "px")
          .number("rotation_only_translation_px", &O::rotation_only_translation_px, Range::kNonNegative, "px")
          .integer("model_selection_min_tracks", &O::model_selection_min_tracks, 6, 100000)
          .seconds_as_ms("model_selection_min_interval_ms", &O::model_selection_min_interval_s, Range::kNonNegative)
          .boolean("model_selection_longest_baseline", &O::model_selection_longest_baseline)
          .number("model_selection_imu_veto_p", &O::model_selection_imu_veto_p, Interval::closed_open(0, 1), "probability (0: no veto)")
          .number("model_selection_accel_sigma_mps2", &O::model_selection_accel_sigma_mps2, Range::kNonNegative, "m/s^2 (0: off)")
          .number("model_selection_velocity_sigma_mps", &O::model_selection_velocity_sigma_mps, Range::kNonNegative, "m/s (0: off)")
          .number("model_selection_velocity_drift_mps2", &O::model_selection_velocity_drift_mps2, Range::kNonNegative, "m/s^2")
          .vector3("gravity_w", &O::gravity_w, "m/s^2, world frame")
          .boolean("compute_covariance", &O::compute_covariance)
          .boolean("estimate_time_offset", &O::estimate_time_offset)
          .seconds_as_ms("time_offset_sigma_ms", &O::time_offset_sigma_s, Range::kPositive)
          .number("init_sigma_roll_pitch_rad", &O::init_sigma_roll_pitch_rad, Range::kPositive, "rad")
          .number("init_sigma_yaw_rad", &O::init_sigma_yaw_rad, Range::kPositive, "rad")
          .number("init_sigma_position_m", &O::init_sigma_position_m, Range::kPositive, "m")
          .number("init_sigma_velocity_mps", &O::init_sigma_velocity_mps, Range::kPositive, "m/s")
          .number("init_bias_gyro_turn_on_radps", &O::init_bias_gyro_turn_on_radps, Range::kPositive, "rad/s")
          .number("init_bias_accel_turn_on_mps2", &O::init_bias_accel_turn_on_mps2, Range::kPositive, "m/s^2")
          .number("init_bias_horizon_s", &O::init_bias_horizon_s, Range::kNonNegative, "s")
          .seconds_as_ms("tracker_max_gap_ms", &O::tracker_max_gap_s, Range::kPositive)
          .number("tracker_min_sigma_deg", &O::tracker_min_sigma_deg, Range::kPositive, "deg")
          .number("tracker_loss_scale", &O::tracker_loss_scale, Range::kPositive, "sigmas (Huber)")
          .number("tracker_reject_p", &O::tracker_reject_p, Interval::open(0, 1), "probability")
          .number("tracker_centre_px", &O::tracker_centre_px, Range::kNonNegative, "px (0: off)")
          .validate();
  return t;
}

const Table<StaticInitOptions>& static_init_table() {
  using O = StaticInitOptions;
  static const Table<O> t = Table<O>("static initialisation settings")
                                .duration_ms("window_ms", &O::window_ns, Range::kPositive)
                                .number("max_gyro_noise_ratio", &O::max_gyro_noise_ratio, Range::kPositive, "")
                                .number("max_accel_noise_ratio", &O::max_accel_noise_ratio, Range::kPositive, "")
                                .number("gravity_mps2", &O::gravity_mps2, Range::kPositive, "m/s^2")
                                .number("max_gravity_error", &O::max_gravity_error, Range::kPositive, "m/s^2")
                                .boolean("allow_rotation", &O::allow_rotation)
                                .duration_ms("still_tail_ms", &O::still_tail_ns, Range::kNonNegative)
                                .validate();
  return t;
}

const Table<VisualInertialInitOptions>& visual_inertial_init_table() {
  using O = VisualInertialInitOptions;
  static const Table<O> t =
      Table<O>("visual-inertial initialisation settings")
          .integer("min_frames", &O::min_frames, 3, 100000)
          .integer("min_tracks", &O::min_tracks, 3, 100000)
          .integer("min_track_frames", &O::min_track_frames, 2, 100000)
          .integer("max_tracks", &O::max_tracks, 1, 100000)
          .number("gravity_mps2", &O::gravity_mps2, Range::kPositive, "m/s^2")
          .number("max_gravity_error", &O::max_gravity_error, Range::kPositive, "m/s^2")
          .number("min_accel_excitation_mps2", &O::min_accel_excitation_mps2, Range::kNonNegative, "m/s^2")
          .validate();
  return t;
}

const Table<CmaxSlamOptions>& cmax_slam_table() {
  using O = CmaxSlamOptions;
  static const Table<O> t = Table<O>("CMax-SLAM back-end settings")
                                .choice("spline", &O::spline, {{"linear", CmaxSlamSpline::kLinear}, {"cubic", CmaxSlamSpline::kCubic}})
                                .duration_ms("knot_spacing_ms", &O::knot_spacing_ns, Range::kPositive)
                                .integer("window_knots", &O::window_knots, 2, 10000)
                                .integer("step_knots", &O::step_knots, 1, 10000)
                                .integer("panorama_width", &O::panorama_width, 16, 1 << 15)
                                .integer("panorama_height", &O::panorama_height, 8, 1 << 15)
                                .number("blur_px", &O::blur_sigma_px, Interval::closed(0, 10), "px")
                                .number("coarse_blur_px", &O::coarse_blur_sigma_px, Interval::closed(0, 10), "px")
                                .integer("max_window_events", &O::max_window_events, 0, 1000000000)
                                .integer("max_iterations", &O::max_iterations, 1, 100000)
                                .number("map_weight", &O::map_weight, Range::kNonNegative, "")
                                .number("box_margin_px", &O::box_margin_px, Range::kNonNegative, "px")
                                .number("prior_weight", &O::prior_weight, Range::kNonNegative, "per rad^2")
                                .number("rate_prior_weight", &O::rate_prior_weight, Range::kNonNegative, "per rad^2")
                                .number("min_segment_events", &O::min_segment_events, Range::kNonNegative, "events")
                                .note("min_segment_events", "0: off; a sparser knot segment's rate prior weighs this / its events")
                                .boolean("keep_first_window", &O::keep_first_window)
                                .integer("global_iterations", &O::global_iterations, 0, 100000)
                                .number("global_rate_weight", &O::global_rate_weight, Range::kNonNegative, "")
                                .integer("global_max_events", &O::global_max_events, 1000, 1000000000)
                                .note("global_iterations", "0: no global pass")
                                .note("global_rate_weight", "per (rad of a segment's change / rad turned in all)")
                                .note("max_window_events", "0: all of the window's events")
                                .note("coarse_blur_px", "0 or <= blur_px: no coarse pass")
                                .validate();
  return t;
}

}  // namespace evio::backend
