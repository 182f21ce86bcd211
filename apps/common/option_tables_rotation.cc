// Config table of the rotation particle filter (option_tables.h).
#include "option_tables.h"

namespace evio::apps {

using yaml_config::Range;
using yaml_config::Table;

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

}  // namespace evio::apps
