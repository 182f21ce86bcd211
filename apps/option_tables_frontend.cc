// Config tables of the front-end's options structs and the IMU noise (option_tables.h).
#include "option_tables.h"

namespace evio::apps {

using yaml_config::Range;
using yaml_config::Table;

const Table<frontend::RefractoryFilterOptions>& refractory_table() {
  using O = frontend::RefractoryFilterOptions;
  static const Table<O> t = Table<O>("refractory settings")
                                .duration_ms("period_ms", &O::period_ns, Range::kNonNegative)
                                .boolean("per_polarity", &O::per_polarity)
                                .validate();
  return t;
}

const Table<frontend::BackgroundActivityFilterOptions>& background_activity_table() {
  using O = frontend::BackgroundActivityFilterOptions;
  static const Table<O> t = Table<O>("background-activity settings")
                                .duration_ms("window_ms", &O::window_ns, Range::kPositive)
                                .integer("radius", &O::radius, 1, 3)
                                .integer("min_support", &O::min_support, 1, 48)
                                .validate();
  return t;
}

const Table<frontend::EfastOptions>& efast_table() {
  using O = frontend::EfastOptions;
  static const Table<O> t = Table<O>("eFAST settings")
                                .boolean("filter_sae", &O::filter_sae)
                                .duration_ms("filter_window_ms", &O::filter_window_ns, Range::kNonNegative)
                                .validate();
  return t;
}

const Table<frontend::CornerTrackerOptions>& corner_tracker_table() {
  using O = frontend::CornerTrackerOptions;
  static const Table<O> t =
      Table<O>("corner tracker settings")
          .number("max_distance_px", &O::max_distance_px, Range::kPositive, "px")
          .duration_ms("max_gap_ms", &O::max_gap_ns, Range::kPositive)
          .number("position_gain", &O::position_gain, Range::kUnit, "")
          .duration_ms("velocity_window_ms", &O::velocity_window_ns, Range::kPositive)
          .duration_ms("min_velocity_span_ms", &O::min_velocity_span_ns, Range::kPositive)
          .integer("min_length", &O::min_length, 1, 1000000)
          .number("descriptor_ratio", &O::descriptor_ratio, Range::kUnit, "")
          .number("max_descriptor_distance", &O::max_descriptor_distance, Range::kNonNegative,
                  "DART distance, 0..1.414", /*allow_infinity=*/true)
          .validate();
  return t;
}

const Table<frontend::DartOptions>& dart_table() {
  using O = frontend::DartOptions;
  using frontend::DartBinning;
  using frontend::DartNormalisation;
  using frontend::DartPolarity;
  using frontend::DartWeighting;
  static const Table<O> t =
      Table<O>("DART settings")
          .duration_ms("window_ms", &O::window_ns, Range::kNonNegative)
          .integer("rings", &O::rings, 1, frontend::kDartMaxRings)
          .integer("wedges", &O::wedges, 1, frontend::kDartMaxWedges)
          .number("inner_radius_px", &O::inner_radius_px, Range::kPositive, "px")
          .number("outer_radius_px", &O::outer_radius_px, Range::kPositive, "px")
          .choice("polarity", &O::polarity, {{"both", DartPolarity::kBoth}, {"same", DartPolarity::kSame}})
          .choice("normalisation", &O::normalisation,
                  {{"none", DartNormalisation::kNone}, {"l1", DartNormalisation::kL1}, {"l2", DartNormalisation::kL2}})
          .choice("weighting", &O::weighting, {{"count", DartWeighting::kCount}, {"density", DartWeighting::kDensity}})
          .choice("binning", &O::binning, {{"hard", DartBinning::kHard}, {"soft", DartBinning::kSoft}})
          .integer("max_ring_shift", &O::max_ring_shift, 0, frontend::kDartMaxRings - 1)
          .boolean("half_wedge_shifts", &O::half_wedge_shifts)
          .validate();
  return t;
}

const Table<frontend::EventFrameOptions>& event_frame_table() {
  using O = frontend::EventFrameOptions;
  static const Table<O> t =
      Table<O>("frame settings")
          .integer("events_per_frame", &O::events_per_frame, 1, 100000000)
          .duration_ms("min_window_ms", &O::min_window_ns, Range::kNonNegative)
          .duration_ms("max_window_ms", &O::max_window_ns, Range::kPositive)
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
          .choice("ransac", &O::ransac,
                  {{"two_point", RansacModel::kTwoPoint}, {"five_point", RansacModel::kFivePoint}, {"none", RansacModel::kNone}})
          .number("ransac_threshold_px", &O::ransac_threshold_px, Range::kPositive, "px")
          .integer("ransac_max_iterations", &O::ransac_max_iterations, 1, 1000000)
          .integer("min_tracks_before_detection", &O::min_tracks_before_detection, 0, 100000)
          .seed("seed", &O::seed)
          .validate();
  return t;
}

const Table<frontend::RotationParticleFilterOptions>& rotation_particle_filter_table() {
  using O = frontend::RotationParticleFilterOptions;
  using frontend::RotationMeasurementModel;
  using frontend::RotationMotionModel;
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
          .number("outlier_probability", &O::outlier_probability, Range::kUnit, "")
          .number("outlier_range", &O::outlier_range, Range::kPositive, "log units")
          .number("resample_ess_fraction", &O::resample_ess_fraction, Range::kUnit, "")
          .number("initial_spread_rad", &O::initial_spread_rad, Range::kNonNegative, "rad")
          .duration_ms("velocity_window_ms", &O::velocity_window_ns, Range::kPositive)
          .number("velocity_smoothing", &O::velocity_smoothing, Range::kUnit, "")
          .number("velocity_noise_rad_s_per_sqrt_s", &O::velocity_noise_rad_s_per_sqrt_s, Range::kPositive,
                  "rad/s/sqrt(s)")
          .number("velocity_rotation_noise_rad_per_sqrt_s", &O::velocity_rotation_noise_rad_per_sqrt_s,
                  Range::kPositive, "rad/sqrt(s)")
          .number("initial_velocity_spread_rad_s", &O::initial_velocity_spread_rad_s, Range::kNonNegative, "rad/s")
          .duration_ms("relative_max_interval_ms", &O::relative_max_interval_ns, Range::kPositive)
          .number("relative_max_path_rad", &O::relative_max_path_rad, Range::kPositive, "rad")
          .seed("seed", &O::seed)
          .validate();
  return t;
}

const Table<calib::ImuNoise>& imu_noise_table() {
  using O = calib::ImuNoise;
  static const Table<O> t =
      Table<O>("IMU noise")
          .number("accelerometer_noise_density", &O::accelerometer_noise_density, Range::kPositive, "m/s^2/sqrt(Hz)")
          .number("accelerometer_random_walk", &O::accelerometer_random_walk, Range::kNonNegative, "m/s^3/sqrt(Hz)")
          .number("gyroscope_noise_density", &O::gyroscope_noise_density, Range::kPositive, "rad/s/sqrt(Hz)")
          .number("gyroscope_random_walk", &O::gyroscope_random_walk, Range::kNonNegative, "rad/s^2/sqrt(Hz)")
          .number("update_rate_hz", &O::update_rate_hz, Range::kPositive, "Hz")
          .validate();
  return t;
}

}  // namespace evio::apps
