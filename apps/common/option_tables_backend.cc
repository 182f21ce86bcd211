// Config tables of the back-end's options structs and the IMU noise (option_tables.h).
#include "option_tables.h"

namespace evio::apps {

using yaml_config::Range;
using yaml_config::Table;

const Table<backend::StaticInitOptions>& static_init_table() {
  using O = backend::StaticInitOptions;
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

const Table<backend::VisualInertialInitOptions>& visual_inertial_init_table() {
  using O = backend::VisualInertialInitOptions;
  static const Table<O> t =
      Table<O>("visual-inertial initialisation settings")
          .integer("min_frames", &O::min_frames, 3, 100000)
          .integer("min_tracks", &O::min_tracks, 1, 100000)
          .integer("min_track_frames", &O::min_track_frames, 2, 100000)
          .integer("max_tracks", &O::max_tracks, 1, 100000)
          .number("gravity_mps2", &O::gravity_mps2, Range::kPositive, "m/s^2")
          .number("max_gravity_error", &O::max_gravity_error, Range::kPositive, "m/s^2")
          .number("min_accel_excitation_mps2", &O::min_accel_excitation_mps2, Range::kNonNegative, "m/s^2")
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
