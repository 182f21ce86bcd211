// Calibration files: the Event Camera Dataset calib.txt (Mueggler et al. 2017) and Kalibr's
// camchain / IMU YAML (Furgale et al. 2013). Kalibr conventions are kept: T_c_b is Kalibr's
// T_cam_imu (p_c = T_c_b * p_b) and t_imu = t_cam + timeshift_cam_imu. Bad files throw
// evio::InputError naming the file, the 1-based line and the expected form.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "evio/calib/camera.h"
#include "evio/calib/geometry.h"

namespace evio::calib {

struct CameraCalibration {
  std::string name;  // "cam0", ... (Kalibr key) or "cam0" for ECD
  PinholeCamera camera;
  SE3 T_c_b;              // camera <- body (IMU): p_c = T_c_b * p_b; Kalibr T_cam_imu
  bool has_T_c_b = false;  // false when the file has no camera-IMU extrinsics
  int64_t time_shift_ns = 0;  // Kalibr timeshift_cam_imu: t_imu = t_cam + shift, ns
  std::string source;         // file it was loaded from
};

struct ImuNoise {
  double accelerometer_noise_density = 0;  // m/s^2/sqrt(Hz)
  double accelerometer_random_walk = 0;    // m/s^3/sqrt(Hz)
  double gyroscope_noise_density = 0;      // rad/s/sqrt(Hz)
  double gyroscope_random_walk = 0;        // rad/s^2/sqrt(Hz)
  double update_rate_hz = 0;               // Hz
  std::string source;                      // file it was loaded from

  // Noise densities and rate must be finite and > 0; random walks finite and >= 0.
  bool Validate(std::string* why) const;
};

// ECD calib.txt: one line "fx fy cx cy k1 k2 p1 p2 k3" (radtan). The file has no resolution, so
// the caller gives it (DAVIS240C: 240x180). Throws evio::InputError on a missing file, a wrong
// count of numbers, non-numeric tokens or invalid intrinsics (fx, fy <= 0).
CameraCalibration load_ecd_calib(const std::string& path, int width = 240, int height = 180);
// Writes the same one-line form with %.17g, so load_ecd_calib reads back the same doubles.
// Missing radtan coefficients are written as 0. Throws std::invalid_argument for an equidistant
// camera (not representable) and evio::InputError when the file cannot be written.
void write_ecd_calib(const std::string& path, const PinholeCamera& cam);

// Kalibr camchain YAML: cam0, cam1, ... (returned in index order), each with camera_model
// (pinhole only), intrinsics [fu fv pu pv], distortion_model, distortion_coeffs, resolution [w h],
// optional T_cam_imu (4x4, row by row) and optional timeshift_cam_imu (s, rounded to ns).
// Throws evio::InputError for missing keys, wrong sizes, unknown models, invalid intrinsics and
// non-rigid T_cam_imu (rotation not orthonormal to 1e-6, or bottom row not [0 0 0 1]).
std::vector<CameraCalibration> load_kalibr_camchain(const std::string& path);

// Writes a Kalibr-style YAML that both load_kalibr_camchain and load_kalibr_imu read back: the
// cameras as cam0, cam1, ... (camera_model pinhole, intrinsics, distortion_model,
// distortion_coeffs, resolution, T_cam_imu when has_T_c_b, timeshift_cam_imu in s, rostopic,
// cam_overlaps) and, when `imu` is given, imu0 with the Kalibr noise keys (accelerometer_noise_density,
// accelerometer_random_walk, gyroscope_noise_density, gyroscope_random_walk, update_rate), an
// identity T_i_b and rostopic. Doubles are written in the shortest form that reads back exactly
// (at most 17 digits) and the time shift as exact decimal seconds, so intrinsics, distortion,
// noise and the shift read back bit for bit and T_cam_imu to the last bit of its rotation matrix.
// Throws std::invalid_argument for an empty camera list and evio::InputError when the file
// cannot be written.
void write_kalibr_camchain(const std::string& path, const std::vector<CameraCalibration>& cameras,
                           const ImuNoise* imu = nullptr);

// Kalibr IMU YAML: the keys accelerometer_noise_density, accelerometer_random_walk,
// gyroscope_noise_density, gyroscope_random_walk and update_rate, under imu0 or at top level.
ImuNoise load_kalibr_imu(const std::string& path);

// One line stating the conventions applied, e.g. "cam0: pinhole radtan 346x260, T_c_b = Kalibr
// T_cam_imu (p_c = T_c_b * p_b), t_imu = t_cam + 0.000012 s (from camchain.yaml)". The loaders
// pass it to evio::log_info.
std::string describe(const CameraCalibration& calib);

}  // namespace evio::calib
