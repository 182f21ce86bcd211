// Initialisation of the VIO state without ground truth.
//
// Static start: the mean specific
// force of a still IMU is -g in the body frame, which fixes roll and pitch (R_w_b maps it onto
// +z of the world, gravity along -z); the mean gyro reading is the gyro bias; position, velocity
// and yaw are zero (the unobservable gauge: R_w_b is the minimal tilt, no turn about the vertical). The accelerometer bias cannot be told apart from a
// tilt over a static window and is set to zero. Stillness is checked from the spread of the
// samples against the sensor's white noise.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

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
  // Also accept a body rotating in place (no linear acceleration): the specific force rotated with
  // the integrated gyro into the body frame at the window's end must be constant; the gyro bias is
  // then unknown (zero).
  bool allow_rotation = true;
  // The body must be still up to the window's end: the mean gyro and specific force of the last
  // still_tail_ns must agree with the window's within max_*_noise_ratio standard errors of the
  // white noise (a motion that starts inside the window passes the spread test but not this one),
  // ns, >= 0 (0: no check). Not applied to a rotation in place (an unknown gyro bias makes the
  // gyro-compensated specific force drift over the window).
  int64_t still_tail_ns = 100'000'000;
  bool Validate(std::string* why) const;
};

// What an initialiser measured well: sigmas for the estimator's first prior (<= 0: not measured,
// the estimator's options apply).
struct InitialSigmas {
  double bias_gyro_radps = -1.0;  // rad/s per axis
  double velocity_mps = -1.0;     // m/s per axis
};

// State at the end of the window [t_begin_ns, t_begin_ns + window_ns], or nullopt with *why
// (fewer than 10 samples or samples spanning less than 80% of the window, not still, gravity
// magnitude off).
// sigmas (optional out): when the body was still, the standard error of the gyro bias per axis
// (rad/s: the larger of the measured spread and the noise model's white-noise sigma, over
// sqrt(samples)) and of the zero velocity (m/s: max_accel_noise_ratio x the accelerometer noise
// density x sqrt(window), what the stillness test lets through); both -1 when it rotated in place
// (bias unknown, returned as zero; the velocity is only known from the accelerometer's tilt).
std::optional<VioState> static_initialization(const std::vector<ImuSample>& imu, int64_t t_begin_ns,
                                              const calib::ImuNoise& noise, const StaticInitOptions& options,
                                              std::string* why = nullptr, InitialSigmas* sigmas = nullptr);

// Moving start: a linear visual-inertial alignment in the spirit of Martinelli's closed form
// (IJCV 2014) and Kaiser et al. (RA-L 2017). Over the first frames of a window, the IMU gives the
// rotations R_0j (gyro integration, bias b_g) and the preintegrated position deltas dp_j of body j
// in the first body frame; every feature k seen from frame j along the world direction
// d_jk = R_0j R_b_c b_jk satisfies X_k = p_j + R_0j t_b_c + lambda_jk d_jk with
// p_j = v_0 t_j + g_0 t_j^2 / 2 + dp_j. Projecting out the unknown depth,
//   (I - d d^T) (X_k - v_0 t_j - g_0 t_j^2 / 2) = (I - d d^T) (dp_j + R_0j t_b_c)
// is linear in the initial velocity v_0, gravity g_0 (both in the first body frame) and the
// feature points X_k; it is solved by least squares (scale is metric, from the accelerometer),
// then once more with |g_0| fixed to the gravity magnitude (direction from the first solve).
// The state returned is at the first frame: R_w_b0 is the minimal tilt taking g_0 to -z, v_w =
// R_w_b0 v_0, p = 0; biases are those given (b_a is not estimated).
struct VisualInertialInitOptions {
  int min_frames = 6;               // frames in the window, >= 3
  int min_tracks = 15;              // tracks seen in >= min_track_frames frames
  int min_track_frames = 3;         // frames a track must be seen in to be used
  int max_tracks = 150;             // most-observed tracks used (bounds the solve), >= min_tracks
  double gravity_mps2 = 9.81;       // m/s^2
  double max_gravity_error = 1.5;   // the free solution's |g_0| must be within this of g, m/s^2
  double min_accel_excitation_mps2 = 0.05;  // std of the specific force over the window (else degenerate), m/s^2
  bool Validate(std::string* why) const;
};

// frames: the window's frames (time order, camera clock = body clock); imu covering them.
// Returns the state at frames.front().t_ns, or nullopt with *why (too few frames or tracks, too
// little excitation, rank-deficient system, gravity magnitude off).
std::optional<VioState> visual_inertial_initialization(const std::vector<FeatureObservations>& frames,
                                                       const std::vector<ImuSample>& imu,
                                                       const calib::CameraCalibration& camera,
                                                       const calib::ImuNoise& noise,
                                                       const Eigen::Vector3d& bias_gyro,
                                                       const Eigen::Vector3d& bias_accel,
                                                       const VisualInertialInitOptions& options,
                                                       std::string* why = nullptr);

}  // namespace evio::backend
