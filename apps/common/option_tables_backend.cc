// Config table of the IMU noise densities (option_tables.h).
#include "option_tables.h"

namespace evio::apps {

using yaml_config::Range;
using yaml_config::Table;

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
