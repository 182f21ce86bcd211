// Config tables of the front-end's options structs (option_tables.h).
#include "evio/frontend/option_tables.h"

namespace evio::frontend {

using yaml_config::Interval;
using yaml_config::Range;
using yaml_config::Table;

const Table<RefractoryFilterOptions>& refractory_table() {
  using O = RefractoryFilterOptions;
  static const Table<O> t = Table<O>("refractory settings")
                                .duration_ms("period_ms", &O::period_ns, Range::kNonNegative)
                                .boolean("per_polarity", &O::per_polarity)
                                .validate();
  return t;
}

const Table<BackgroundActivityFilterOptions>& background_activity_table() {
  using O = BackgroundActivityFilterOptions;
  static const Table<O> t = Table<O>("background-activity settings")
                                .duration_ms("window_ms", &O::window_ns, Range::kPositive)
                                .integer("radius", &O::radius, 1, 3)
                                .integer("min_support", &O::min_support, 1, 48)  // 48: every neighbour at radius 3
                                .validate();
  return t;
}

const Table<EfastOptions>& efast_table() {
  using O = EfastOptions;
  static const Table<O> t = Table<O>("eFAST settings")
                                .boolean("filter_sae", &O::filter_sae)
                                .duration_ms("filter_window_ms", &O::filter_window_ns, Range::kNonNegative)
                                .validate();
  return t;
}

const Table<CornerTrackerOptions>& corner_tracker_table() {
  using O = CornerTrackerOptions;
  static const Table<O> t =
      Table<O>("corner tracker settings")
          // At most 64: the tracker's grid cells are twice the gate.
          .number("max_distance_px", &O::max_distance_px, Interval::open_closed(0, 64), "px")
          .duration_ms("max_gap_ms", &O::max_gap_ns, Range::kPositive)
          .number("position_gain", &O::position_gain, Interval::open_closed(0, 1), "")
          .duration_ms("velocity_window_ms", &O::velocity_window_ns, Range::kPositive)
          .duration_ms("min_velocity_span_ms", &O::min_velocity_span_ns, Range::kPositive)
          .integer("min_length", &O::min_length, 1, 1000000)
          .number("descriptor_ratio", &O::descriptor_ratio, Interval::open_closed(0, 1), "")
          .number("max_descriptor_distance", &O::max_descriptor_distance, Range::kNonNegative,
                  "DART distance, 0..1.414", /*allow_infinity=*/true)
          .validate();
  return t;
}

const Table<DartOptions>& dart_table() {
  using O = DartOptions;
  static const Table<O> t =
      Table<O>("DART settings")
          .duration_ms("window_ms", &O::window_ns, Range::kNonNegative)
          .integer("rings", &O::rings, 1, kDartMaxRings)
          .integer("wedges", &O::wedges, 1, kDartMaxWedges)
          .number("inner_radius_px", &O::inner_radius_px, Range::kPositive, "px")
          .number("outer_radius_px", &O::outer_radius_px, Interval::open_closed(0, 64), "px")
          .choice("polarity", &O::polarity, {{"both", DartPolarity::kBoth}, {"same", DartPolarity::kSame}})
          .choice("normalisation", &O::normalisation,
                  {{"none", DartNormalisation::kNone}, {"l1", DartNormalisation::kL1}, {"l2", DartNormalisation::kL2}})
          .choice("weighting", &O::weighting, {{"count", DartWeighting::kCount}, {"density", DartWeighting::kDensity}})
          .choice("binning", &O::binning, {{"hard", DartBinning::kHard}, {"soft", DartBinning::kSoft}})
          .integer("max_ring_shift", &O::max_ring_shift, 0, kDartMaxRings - 1)
          .boolean("half_wedge_shifts", &O::half_wedge_shifts)
          .validate();
  return t;
}

const Table<EventFrameOptions>& event_frame_table() {
  using O = EventFrameOptions;
  static const Table<O> t =
      Table<O>("frame settings")
          .integer("events_per_frame", &O::events_per_frame, 1, 100000000)
          .duration_ms("min_window_ms", &O::min_window_ns, Range::kNonNegative)
          .duration_ms("max_window_ms", &O::max_window_ns, Range::kPositive)
          .duration_ms("sparse_max_window_ms", &O::sparse_max_window_ns, Range::kNonNegative)
          .duration_ms("sparse_after_ms", &O::sparse_after_ns, Range::kNonNegative)
          .integer("min_events", &O::min_events, 1, 100000000)
          .number("overlap", &O::overlap, Interval::closed(0, 0.9), "fraction of a frame's events")
          .boolean("motion_compensation", &O::motion_compensation)
          .boolean("use_depth", &O::use_depth)
          .boolean("use_polarity", &O::use_polarity)
          .boolean("normalize", &O::normalize)
          .number("clip_percentile", &O::clip_percentile, Interval::open_closed(0, 1), "")
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

const Table<FeatureTrackerOptions>& feature_tracker_table() {
  using O = FeatureTrackerOptions;
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
          .choice("klt_warp", &O::klt_warp, {{"none", KltWarp::kNone}, {"rotation", KltWarp::kRotation}, {"rotation_scale", KltWarp::kRotationScale}})
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

const Table<RotationParticleFilterOptions>& rotation_probe_table() {
  using O = RotationParticleFilterOptions;
  // No validate(): the filter's own table (which includes this one) runs Validate.
  static const Table<O> t = Table<O>("tracker settings")
                                .integer("probe_every_batches", &O::probe_every_batches, 0, 1000000)
                                .number("probe_offset_rad", &O::probe_offset_rad, Range::kPositive, "rad");
  return t;
}

const Table<RotationParticleFilterOptions>& rotation_particle_filter_table() {
  using O = RotationParticleFilterOptions;
  static const Table<O> t =
      Table<O>("tracker settings")
          .integer("particles", &O::num_particles, 1, 1000000)
          .integer("min_particles", &O::min_particles, 0, 1000000)
          .number("kld_bin_rad", &O::kld_bin_rad, Range::kPositive, "rad")
          .number("kld_epsilon", &O::kld_epsilon, Range::kPositive, "")
          .number("kld_z", &O::kld_z, Range::kPositive, "")
          .integer("batch_size", &O::batch_size, 1, 1000000)
          .integer("event_stride", &O::event_stride, 1, 1000000)
          .duration_ms("max_batch_ms", &O::max_batch_duration_ns, Range::kPositive)
          .number("linearize_max_spread_rad", &O::linearize_max_spread_rad, Range::kNonNegative, "rad")
          .choice("motion_model", &O::motion_model,
                  {{"random_walk", RotationMotionModel::kRandomWalk},
                   {"constant_velocity", RotationMotionModel::kConstantVelocity},
                   {"particle_velocity", RotationMotionModel::kParticleVelocity}})
          .choice("measurement_model", &O::measurement_model,
                  {{"previous_mean", RotationMeasurementModel::kPreviousMean},
                   {"relative_motion", RotationMeasurementModel::kRelativeMotion},
                   {"auto", RotationMeasurementModel::kAuto}})
          .number("motion_noise_rad_per_sqrt_s", &O::motion_noise_rad_per_sqrt_s, Range::kPositive, "rad/sqrt(s)")
          .number("gyro_noise_rad_per_sqrt_s", &O::gyro_noise_rad_per_sqrt_s, Range::kPositive, "rad/sqrt(s)")
          .duration_ms("gyro_max_age_ms", &O::gyro_max_age_ns, Range::kPositive)
          .number("contrast_threshold", &O::contrast_threshold, Range::kPositive, "log units")
          .number("likelihood_std", &O::likelihood_std, Range::kPositive, "log units")
          .number("outlier_probability", &O::outlier_probability, Interval::open(0, 1), "")
          .number("outlier_range", &O::outlier_range, Range::kPositive, "log units")
          .number("resample_ess_fraction", &O::resample_ess_fraction, Range::kUnit, "")
          .number("initial_spread_rad", &O::initial_spread_rad, Range::kNonNegative, "rad")
          .duration_ms("velocity_window_ms", &O::velocity_window_ns, Range::kPositive)
          .number("velocity_smoothing", &O::velocity_smoothing, Interval::open_closed(0, 1), "")
          .number("velocity_noise_rad_s_per_sqrt_s", &O::velocity_noise_rad_s_per_sqrt_s, Range::kPositive,
                  "rad/s/sqrt(s)")
          .number("velocity_rotation_noise_rad_per_sqrt_s", &O::velocity_rotation_noise_rad_per_sqrt_s,
                  Range::kPositive, "rad/sqrt(s)")
          .number("initial_velocity_spread_rad_s", &O::initial_velocity_spread_rad_s, Range::kNonNegative, "rad/s")
          .duration_ms("relative_max_interval_ms", &O::relative_max_interval_ns, Range::kPositive)
          .number("relative_max_path_rad", &O::relative_max_path_rad, Range::kPositive, "rad")
          .seed("seed", &O::seed)
          .include(rotation_probe_table(), [](O& o) -> O& { return o; })
          .validate();
  return t;
}

}  // namespace evio::frontend
