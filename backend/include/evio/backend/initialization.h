// Initialisation of the VIO state without ground truth from a static start: the mean specific
// force of a still IMU is -g in the body frame, which fixes roll and pitch (R_w_b maps it onto
// +z of the world, gravity along -z); the mean gyro reading is the gyro bias; position, velocity
// and yaw are zero (the unobservable gauge: R_w_b is the minimal tilt, no turn about the vertical). The accelerometer bias cannot be told apart from a
// tilt over a static window and is set to zero. Stillness is checked from the spread of the
// samples against the sensor's white noise.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "evio/calib/calibration_io.h"
#include "evio/sensors/measurements.h"
#include "evio/sensors/vio_types.h"

namespace evio::backend {

struct StaticInitOptions {
  int64_t window_ns = 1'000'000'000;  // span of IMU samples averaged, ns (default 1 s)
  // The body counts as still when the standard deviation of every gyro / accelerometer axis is
  // below these multiples of the white-noise sigma at the IMU rate (density * sqrt(rate)).
  double max_gyro_noise_ratio = 3.0;
  double max_accel_noise_ratio = 3.0;
  double gravity_mps2 = 9.81;         // m/s^2
  double max_gravity_error = 0.5;     // |mean specific force| must be within this of g, m/s^2
  bool Validate(std::string* why) const;
};

// State at the end of the window [t_begin_ns, t_begin_ns + window_ns], or nullopt with *why
// (not enough samples, not still, gravity magnitude off).
std::optional<VioState> static_initialization(const std::vector<ImuSample>& imu, int64_t t_begin_ns,
                                              const calib::ImuNoise& noise, const StaticInitOptions& options,
                                              std::string* why = nullptr);

}  // namespace evio::backend
