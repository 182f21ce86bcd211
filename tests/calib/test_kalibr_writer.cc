// Tests of write_kalibr_camchain: the file it writes is read back by load_kalibr_camchain and
// load_kalibr_imu to the same doubles (intrinsics, distortion, noise, time shift bit for bit;
// T_cam_imu to the last bit of its rotation matrix), for radtan, equidistant and no distortion,
// with and without extrinsics and IMU block.
#include <cmath>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "evio/calib/calibration_io.h"
#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio_test/temp_dir.h"

namespace evio::calib {
namespace {

class QuietLog {
 public:
  QuietLog() { set_log_sink([](LogLevel, const std::string&) {}); }
  ~QuietLog() { set_log_sink({}); }
};

CameraCalibration ecd_like_camera() {
  CameraIntrinsics intr;
  intr.width = 240;
  intr.height = 180;
  intr.fx = 199.092366542;
  intr.fy = 198.82882047;
  intr.cx = 132.192071378;
  intr.cy = 110.712660011;
  intr.model = DistortionModel::kRadtan;
  intr.distortion = {-0.368436311798, 0.150947243557, -0.000296130534385, -0.000759431726241, 0.0};
  CameraCalibration c;
  c.name = "cam0";
  c.camera = PinholeCamera(intr);
  // An awkward rotation (not axis-aligned) and translation so that rounding would show.
  c.T_c_b = SE3(so3_exp(Vec3(0.1234567890123, -2.0987654321, 0.31415926535)), Vec3(0.01234, -0.0567, 1.0 / 3.0));
  c.has_T_c_b = true;
  c.time_shift_ns = -1'234'567;  // -1.234567 ms
  return c;
}

ImuNoise davis_like_noise() {
  ImuNoise n;
  n.accelerometer_noise_density = 0.0039;
  n.accelerometer_random_walk = 4.0e-4 / 3.0;
  n.gyroscope_noise_density = 1.7e-4;
  n.gyroscope_random_walk = 2.0e-5;
  n.update_rate_hz = 1000.0;
  return n;
}

void expect_same_intrinsics(const CameraIntrinsics& a, const CameraIntrinsics& b) {
  EXPECT_EQ(a.width, b.width);
  EXPECT_EQ(a.height, b.height);
  EXPECT_EQ(a.fx, b.fx);  // exact: %.17g round trip
  EXPECT_EQ(a.fy, b.fy);
  EXPECT_EQ(a.cx, b.cx);
  EXPECT_EQ(a.cy, b.cy);
  EXPECT_EQ(a.model, b.model);
  EXPECT_EQ(a.distortion, b.distortion);
}

TEST(KalibrWriter, CamchainAndImuReadBackExactly) {
  QuietLog quiet;
  evio_test::TempDir dir;
  const std::string path = dir.file("calib.yaml");
  const CameraCalibration cam = ecd_like_camera();
  const ImuNoise noise = davis_like_noise();
  write_kalibr_camchain(path, {cam}, &noise);

  const std::vector<CameraCalibration> back = load_kalibr_camchain(path);
  ASSERT_EQ(back.size(), 1u);
  EXPECT_EQ(back[0].name, "cam0");
  expect_same_intrinsics(back[0].camera.intrinsics(), cam.camera.intrinsics());
  ASSERT_TRUE(back[0].has_T_c_b);
  EXPECT_EQ(back[0].time_shift_ns, cam.time_shift_ns);
  const Mat3 R_in = cam.T_c_b.rotation.toRotationMatrix();
  const Mat3 R_back = back[0].T_c_b.rotation.toRotationMatrix();
  EXPECT_LT((R_in - R_back).cwiseAbs().maxCoeff(), 1e-15);
  EXPECT_EQ(back[0].T_c_b.translation, cam.T_c_b.translation);  // exact

  const ImuNoise imu = load_kalibr_imu(path);
  EXPECT_EQ(imu.accelerometer_noise_density, noise.accelerometer_noise_density);
  EXPECT_EQ(imu.accelerometer_random_walk, noise.accelerometer_random_walk);
  EXPECT_EQ(imu.gyroscope_noise_density, noise.gyroscope_noise_density);
  EXPECT_EQ(imu.gyroscope_random_walk, noise.gyroscope_random_walk);
  EXPECT_EQ(imu.update_rate_hz, noise.update_rate_hz);
  EXPECT_EQ(imu.source, path);
}

TEST(KalibrWriter, EquidistantNoneAndSeveralCameras) {
  QuietLog quiet;
  evio_test::TempDir dir;
  CameraIntrinsics fish;
  fish.width = 346;
  fish.height = 260;
  fish.fx = 226.38018519795807;
  fish.fy = 226.15002947047415;
  fish.cx = 173.6470807871759;
  fish.cy = 133.73271487507847;
  fish.model = DistortionModel::kEquidistant;
  fish.distortion = {-0.048031442223833355, 0.011330957517194437, -0.055378166304281135, 0.021500973881459395};
  CameraIntrinsics plain;
  plain.width = 640;
  plain.height = 480;
  plain.fx = plain.fy = 530.0;
  plain.cx = 319.5;
  plain.cy = 239.5;
  CameraCalibration a, b;
  a.camera = PinholeCamera(fish);
  a.time_shift_ns = 2'500;  // 2.5 us
  b.camera = PinholeCamera(plain);
  const std::string path = dir.file("two.yaml");
  write_kalibr_camchain(path, {a, b});

  const std::vector<CameraCalibration> back = load_kalibr_camchain(path);
  ASSERT_EQ(back.size(), 2u);
  EXPECT_EQ(back[0].name, "cam0");
  EXPECT_EQ(back[1].name, "cam1");
  expect_same_intrinsics(back[0].camera.intrinsics(), fish);
  expect_same_intrinsics(back[1].camera.intrinsics(), plain);
  EXPECT_FALSE(back[0].has_T_c_b);  // no extrinsics written when there are none
  EXPECT_FALSE(back[1].has_T_c_b);
  EXPECT_EQ(back[0].time_shift_ns, 2'500);
  EXPECT_EQ(back[1].time_shift_ns, 0);
  // Without an IMU block the IMU loader finds no noise keys.
  EXPECT_THROW(load_kalibr_imu(path), InputError);
}

TEST(KalibrWriter, TimeShiftsAreExactOverAWideRange) {
  QuietLog quiet;
  evio_test::TempDir dir;
  CameraCalibration cam = ecd_like_camera();
  for (int64_t ns : {int64_t{0}, int64_t{1}, int64_t{-1}, int64_t{999'999'999}, int64_t{-3'000'000'007},
                     int64_t{123'456'789'012}}) {
    cam.time_shift_ns = ns;
    const std::string path = dir.file("shift.yaml");
    write_kalibr_camchain(path, {cam});
    EXPECT_EQ(load_kalibr_camchain(path).at(0).time_shift_ns, ns);
  }
}

TEST(KalibrWriter, FileHoldsTheKalibrKeys) {
  QuietLog quiet;
  evio_test::TempDir dir;
  const std::string path = dir.file("calib.yaml");
  const ImuNoise noise = davis_like_noise();
  write_kalibr_camchain(path, {ecd_like_camera()}, &noise);
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  for (const char* key : {"cam0:", "camera_model: pinhole", "intrinsics: [199.092366542, ", "distortion_model: radtan",
                          "distortion_coeffs: [", "resolution: [240, 180]", "T_cam_imu:", "timeshift_cam_imu: -0.001234567",
                          "imu0:", "accelerometer_noise_density: 0.0039", "update_rate: 1000"}) {
    EXPECT_NE(text.str().find(key), std::string::npos) << key << "\n" << text.str();
  }
}

TEST(KalibrWriter, Errors) {
  evio_test::TempDir dir;
  EXPECT_THROW(write_kalibr_camchain(dir.file("x.yaml"), {}), std::invalid_argument);
  EXPECT_THROW(write_kalibr_camchain(dir.file("no/such/folder/x.yaml"), {ecd_like_camera()}), InputError);
}

}  // namespace
}  // namespace evio::calib
