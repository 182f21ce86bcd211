// Tests of the calibration readers: ECD calib.txt (load, write round trip, malformed files),
// Kalibr camchain and IMU YAML (conventions, errors naming file, line and expected form), and the
// real ECD calib.txt files when ../shared/data/real is present.
#include <cstdio>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "evio/calib/calibration_io.h"
#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio_test/real_data.h"
#include "evio_test/temp_dir.h"

namespace evio::calib {
namespace {

constexpr const char* kEcdLine =
    "199.092366542 198.82882047 132.192071378 110.712660011 -0.368436311798 0.150947243557 "
    "-0.000296130534385 -0.000759431726241 0.0\n";

// Captures log messages for the lifetime of the object.
class LogCapture {
 public:
  LogCapture() {
    set_log_sink([this](LogLevel, const std::string& m) { messages_.push_back(m); });
  }
  ~LogCapture() { set_log_sink({}); }
  const std::vector<std::string>& messages() const { return messages_; }

 private:
  std::vector<std::string> messages_;
};

// Runs f, expects an InputError and checks that it names the file, the line and the expected form.
template <typename F>
InputError expect_input_error(F f, const std::string& path, int64_t line, const std::string& problem,
                              const std::string& expected) {
  try {
    f();
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_EQ(e.file(), path);
    EXPECT_NE(what.find(path), std::string::npos) << what;
    EXPECT_EQ(e.line(), line) << what;
    if (line > 0) {
      EXPECT_NE(what.find(path + ":" + std::to_string(line) + ":"), std::string::npos) << what;
    }
    EXPECT_NE(what.find(problem), std::string::npos) << what;
    EXPECT_NE(what.find("expected: "), std::string::npos) << what;
    EXPECT_NE(what.find(expected), std::string::npos) << what;
    return e;
  } catch (const std::exception& e) {
    ADD_FAILURE() << "expected evio::InputError, got: " << e.what();
    return InputError(path, 0, "wrong exception");
  }
  ADD_FAILURE() << "no exception for " << path << " (" << problem << ")";
  return InputError(path, 0, "no exception");
}

// 1-based number of the first line of text containing needle.
int64_t line_of(const std::string& text, const std::string& needle) {
  const size_t pos = text.find(needle);
  EXPECT_NE(pos, std::string::npos) << needle;
  int64_t line = 1;
  for (size_t i = 0; i < pos; ++i) line += text[i] == '\n' ? 1 : 0;
  return line;
}

TEST(CalibrationIo, EcdLoadAndWriteRoundTrip) {
  evio_test::TempDir dir;
  const std::string path = dir.write("calib.txt", kEcdLine);
  LogCapture log;
  const CameraCalibration c = load_ecd_calib(path);
  const CameraIntrinsics& k = c.camera.intrinsics();
  EXPECT_EQ(k.width, 240);
  EXPECT_EQ(k.height, 180);
  EXPECT_EQ(k.fx, 199.092366542);
  EXPECT_EQ(k.fy, 198.82882047);
  EXPECT_EQ(k.cx, 132.192071378);
  EXPECT_EQ(k.cy, 110.712660011);
  EXPECT_EQ(k.model, DistortionModel::kRadtan);
  ASSERT_EQ(k.distortion.size(), 5u);
  EXPECT_EQ(k.distortion[0], -0.368436311798);
  EXPECT_EQ(k.distortion[3], -0.000759431726241);
  EXPECT_FALSE(c.has_T_c_b);
  EXPECT_EQ(c.time_shift_ns, 0);
  EXPECT_EQ(c.source, path);
  ASSERT_EQ(log.messages().size(), 1u);
  EXPECT_NE(log.messages()[0].find("cam0: pinhole radtan 240x180"), std::string::npos) << log.messages()[0];

  // Write and read back: every double survives exactly (%.17g).
  CameraIntrinsics odd = k;
  odd.fx = 0.1 + 0.2 + 199.0;
  odd.distortion = {1.0 / 3.0, -2.0 / 7.0, 1e-300, -4.9e-5, 0.125};
  const std::string out = dir.file("written.txt");
  write_ecd_calib(out, PinholeCamera(odd));
  const CameraCalibration back = load_ecd_calib(out, 240, 180);
  EXPECT_EQ(back.camera.intrinsics().fx, odd.fx);
  EXPECT_EQ(back.camera.intrinsics().cy, odd.cy);
  EXPECT_EQ(back.camera.intrinsics().distortion, odd.distortion);

  // A DAVIS346 resolution given by the caller; a 4-coefficient radtan camera is written with k3 = 0.
  CameraIntrinsics four = k;
  four.width = 346;
  four.height = 260;
  four.distortion.resize(4);
  write_ecd_calib(out, PinholeCamera(four));
  const CameraCalibration back4 = load_ecd_calib(out, 346, 260);
  EXPECT_EQ(back4.camera.width(), 346);
  ASSERT_EQ(back4.camera.intrinsics().distortion.size(), 5u);
  EXPECT_EQ(back4.camera.intrinsics().distortion[4], 0.0);

  CameraIntrinsics fisheye = k;
  fisheye.model = DistortionModel::kEquidistant;
  fisheye.distortion = {0.01, 0.0, 0.0, 0.0};
  EXPECT_THROW(write_ecd_calib(out, PinholeCamera(fisheye)), std::invalid_argument);
}

TEST(CalibrationIo, EcdCommentsAndBlankLinesAreSkipped) {
  evio_test::TempDir dir;
  const std::string path = dir.write("calib.txt", std::string("# DAVIS240C\n\n") + kEcdLine + "\n   \n");
  EXPECT_EQ(load_ecd_calib(path).camera.intrinsics().fx, 199.092366542);
}

TEST(CalibrationIo, EcdMalformedFilesNameFileLineAndForm) {
  evio_test::TempDir dir;
  const std::string form = "fx fy cx cy k1 k2 p1 p2 k3";
  struct Case {
    std::string text;
    int64_t line;
    std::string problem;
  };
  const std::vector<Case> cases = {
      {"199.0 198.8 132.1 110.7 -0.36 0.15 -0.0003 -0.0007\n", 1, "found 8 numbers"},
      {"199.0 198.8 132.1 110.7 -0.36 0.15 -0.0003 -0.0007 0.0 1.0\n", 1, "found 10 numbers"},
      {"# header\n199.0 198.8 abc 110.7 -0.36 0.15 -0.0003 -0.0007 0.0\n", 2, "value 3 'abc' is not a finite number"},
      {"199.0 198.8 132.1 110.7x -0.36 0.15 -0.0003 -0.0007 0.0\n", 1, "value 4 '110.7x'"},
      {"199.0 nan 132.1 110.7 -0.36 0.15 -0.0003 -0.0007 0.0\n", 1, "value 2 'nan'"},
      {"0 198.8 132.1 110.7 -0.36 0.15 -0.0003 -0.0007 0.0\n", 1, "focal lengths must be finite and positive"},
      {"\n199.0 -198.8 132.1 110.7 -0.36 0.15 -0.0003 -0.0007 0.0\n", 2, "focal lengths must be finite and positive"},
      {"", 1, "no calibration line"},
      {std::string(kEcdLine) + kEcdLine, 2, "unexpected second line"},
  };
  int i = 0;
  for (const Case& c : cases) {
    const std::string path = dir.write("bad" + std::to_string(i++) + ".txt", c.text);
    expect_input_error([&] { load_ecd_calib(path); }, path, c.line, c.problem, form);
  }
  const std::string missing = dir.file("does_not_exist.txt");
  expect_input_error([&] { load_ecd_calib(missing); }, missing, 0, "cannot open file", form);
  const std::string good = dir.write("good.txt", kEcdLine);
  expect_input_error([&] { load_ecd_calib(good, 0, 180); }, good, 1, "resolution must be positive", form);
}

TEST(CalibrationIo, RealEcdCalibFiles) {
  const auto slider = evio_test::real_data_dir("ecd_slider_depth_head");
  if (!slider) GTEST_SKIP() << "../shared/data/real/ecd_slider_depth_head not present";
  const CameraCalibration c = load_ecd_calib(*slider + "/calib.txt", 240, 180);
  EXPECT_NEAR(c.camera.intrinsics().fx, 335.419462958, 1e-9);
  EXPECT_NEAR(c.camera.intrinsics().cy, 99.1864303447, 1e-9);
  EXPECT_EQ(c.camera.intrinsics().model, DistortionModel::kRadtan);
  // Every pixel of the DAVIS240C unprojects and reprojects.
  const UndistortionLut lut(c.camera);
  for (int y = 0; y < 180; ++y) {
    for (int x = 0; x < 240; ++x) ASSERT_TRUE(lut.valid(x, y)) << x << "," << y;
  }
  if (const auto dynamic = evio_test::real_data_dir("ecd_dynamic_10ms")) {
    const CameraCalibration d = load_ecd_calib(*dynamic + "/calib.txt");
    EXPECT_NEAR(d.camera.intrinsics().fx, 199.092366542, 1e-12);
    EXPECT_NEAR(d.camera.intrinsics().distortion[0], -0.368436311798, 1e-15);
  }
}

// Kalibr camchain with a known T_cam_imu; cam1 is listed before cam0 on purpose.
struct Camchain {
  std::string text;
  SE3 T_c_b;
};

std::string matrix_yaml(const Eigen::Matrix4d& T) {
  std::string s;
  char buf[256];
  for (int i = 0; i < 4; ++i) {
    std::snprintf(buf, sizeof(buf), "  - [%.17g, %.17g, %.17g, %.17g]\n", T(i, 0), T(i, 1), T(i, 2), T(i, 3));
    s += buf;
  }
  return s;
}

Camchain make_camchain() {
  Camchain c;
  c.T_c_b = SE3(so3_exp(Vec3(0.02, -1.55, 0.01)), Vec3(0.0021, -0.0452, -0.0178));
  c.text =
      "cam1:\n"
      "  camera_model: pinhole\n"
      "  distortion_model: equidistant\n"
      "  distortion_coeffs: [0.0034823894022493434, 0.0007150348452162257, -0.0020532361418706202,\n"
      "    0.00020293673591811182]\n"
      "  intrinsics: [190.97847715128717, 190.9733070521226, 254.93170605935475, 256.8974428996504]\n"
      "  resolution: [512, 512]\n"
      "  rostopic: /cam1/image_raw\n"
      "cam0:\n"
      "  T_cam_imu:\n" +
      matrix_yaml(c.T_c_b.matrix()) +
      "  cam_overlaps: []\n"
      "  camera_model: pinhole\n"
      "  distortion_coeffs: [-0.38, 0.16, 0.0003, -0.0007]\n"
      "  distortion_model: radtan\n"
      "  intrinsics: [259.36, 258.96, 171.93, 131.05]\n"
      "  resolution: [346, 260]\n"
      "  rostopic: /dvs/events\n"
      "  timeshift_cam_imu: 1.2345e-05\n";
  return c;
}

TEST(CalibrationIo, KalibrCamchainConventions) {
  evio_test::TempDir dir;
  const Camchain chain = make_camchain();
  const std::string path = dir.write("camchain.yaml", chain.text);
  LogCapture log;
  const std::vector<CameraCalibration> cams = load_kalibr_camchain(path);
  ASSERT_EQ(cams.size(), 2u);

  const CameraCalibration& cam0 = cams[0];
  EXPECT_EQ(cam0.name, "cam0");
  EXPECT_EQ(cam0.source, path);
  EXPECT_EQ(cam0.camera.width(), 346);
  EXPECT_EQ(cam0.camera.height(), 260);
  EXPECT_EQ(cam0.camera.intrinsics().fx, 259.36);
  EXPECT_EQ(cam0.camera.intrinsics().cy, 131.05);
  EXPECT_EQ(cam0.camera.intrinsics().model, DistortionModel::kRadtan);
  EXPECT_EQ(cam0.camera.intrinsics().distortion, (std::vector<double>{-0.38, 0.16, 0.0003, -0.0007}));
  ASSERT_TRUE(cam0.has_T_c_b);
  EXPECT_EQ(cam0.time_shift_ns, 12345);  // t_imu = t_cam + 12.345 us

  // p_c = T_c_b * p_b with T_c_b the matrix written in the file (Kalibr T_cam_imu).
  const Eigen::Matrix4d T_file = chain.T_c_b.matrix();
  for (const Vec3& p_b : {Vec3(1, 0, 0), Vec3(0.3, -2.0, 5.0), Vec3(-1, 4, 0.5)}) {
    const Vec3 p_c = cam0.T_c_b * p_b;
    const Eigen::Vector4d ref = T_file * p_b.homogeneous();
    EXPECT_LT((p_c - ref.head<3>()).norm(), 1e-14);
  }
  EXPECT_LT((cam0.T_c_b.matrix() - T_file).cwiseAbs().maxCoeff(), 1e-15);

  const CameraCalibration& cam1 = cams[1];
  EXPECT_EQ(cam1.name, "cam1");
  EXPECT_EQ(cam1.camera.intrinsics().model, DistortionModel::kEquidistant);
  EXPECT_EQ(cam1.camera.intrinsics().distortion.size(), 4u);
  EXPECT_EQ(cam1.camera.width(), 512);
  EXPECT_FALSE(cam1.has_T_c_b);
  EXPECT_EQ(cam1.time_shift_ns, 0);

  ASSERT_EQ(log.messages().size(), 2u);
  const std::string& line0 = log.messages()[0];
  EXPECT_NE(line0.find("cam0: pinhole radtan 346x260, T_c_b = Kalibr T_cam_imu (p_c = T_c_b * p_b), "
                       "t_imu = t_cam + 0.000012345 s"),
            std::string::npos)
      << line0;
  EXPECT_NE(line0.find(path), std::string::npos) << line0;
  EXPECT_NE(log.messages()[1].find("cam1: pinhole equidistant 512x512, no camera-IMU extrinsics"),
            std::string::npos)
      << log.messages()[1];
}

TEST(CalibrationIo, DescribeFormatsTimeShift) {
  CameraCalibration c;
  c.name = "cam0";
  CameraIntrinsics k;
  k.width = 240;
  k.height = 180;
  k.fx = k.fy = 200;
  c.camera = PinholeCamera(k);
  c.time_shift_ns = -2500000;
  EXPECT_NE(describe(c).find("t_imu = t_cam + -0.0025 s"), std::string::npos) << describe(c);
  c.time_shift_ns = 3000000000;
  EXPECT_NE(describe(c).find("t_imu = t_cam + 3 s"), std::string::npos) << describe(c);
  c.time_shift_ns = 0;
  EXPECT_NE(describe(c).find("cam0: pinhole none 240x180"), std::string::npos) << describe(c);
  EXPECT_NE(describe(c).find("t_imu = t_cam + 0 s"), std::string::npos) << describe(c);
}

TEST(CalibrationIo, KalibrNegativeAndRoundedTimeShift) {
  evio_test::TempDir dir;
  std::string text = make_camchain().text;
  const size_t pos = text.find("1.2345e-05");
  text.replace(pos, 10, "-0.0025000004");
  const std::string path = dir.write("camchain.yaml", text);
  EXPECT_EQ(load_kalibr_camchain(path)[0].time_shift_ns, -2500000);
}

// Replaces the first occurrence of `from` in the camchain text.
std::string edited(std::string text, const std::string& from, const std::string& to) {
  const size_t pos = text.find(from);
  EXPECT_NE(pos, std::string::npos) << from;
  return text.replace(pos, from.size(), to);
}

TEST(CalibrationIo, KalibrCamchainErrorsNameFileLineAndForm) {
  evio_test::TempDir dir;
  const std::string base = make_camchain().text;
  struct Case {
    std::string text;
    std::string line_needle;  // the error points at the first line containing this
    std::string problem;
    std::string expected;
  };
  const std::vector<Case> cases = {
      {edited(base, "  intrinsics: [259.36, 258.96, 171.93, 131.05]\n", ""), "  T_cam_imu:",
       "cam0: missing key 'intrinsics'", "intrinsics: [fu, fv, pu, pv]"},
      {edited(base, "[259.36, 258.96, 171.93, 131.05]", "[259.36, 258.96, 171.93]"), "[259.36, 258.96",
       "cam0.intrinsics has 3 entries", "intrinsics: [fu, fv, pu, pv]"},
      {edited(base, "[259.36, 258.96, 171.93, 131.05]", "[259.36, 258.96, abc, 131.05]"), "[259.36, 258.96",
       "cam0.intrinsics[2] is not a finite number ('abc')", "intrinsics: [fu, fv, pu, pv]"},
      {edited(base, "[-0.38, 0.16, 0.0003, -0.0007]", "[-0.38, 0.16, 0.0003]"), "[-0.38, 0.16",
       "cam0.distortion_coeffs has 3 entries", "[k1, k2, p1, p2]"},
      {edited(base, "radtan", "fov"), "distortion_model: fov", "unknown distortion_model 'fov'",
       "radtan, equidistant or none"},
      {edited(base, "  camera_model: pinhole\n  distortion_coeffs", "  camera_model: omni\n  distortion_coeffs"),
       "camera_model: omni", "camera_model 'omni' is not supported", "camera_model: pinhole"},
      {edited(base, "[346, 260]", "[346]"), "[346]", "cam0.resolution has 1 entries", "resolution: [width, height]"},
      {edited(base, "[346, 260]", "[346.5, 260]"), "[346.5", "cam0.resolution[0] is not an integer",
       "resolution: [width, height]"},
      {edited(base, "[259.36, 258.96", "[-259.36, 258.96"), "  T_cam_imu:", "focal lengths must be finite",
       "Kalibr camchain YAML"},
      {edited(base, "  timeshift_cam_imu: 1.2345e-05", "  timeshift_cam_imu: soon"), "timeshift_cam_imu: soon",
       "cam0.timeshift_cam_imu is not a finite number", "timeshift_cam_imu: seconds"},
      {edited(base, "  - [0, 0, 0, 1]\n", ""), "  - [", "cam0.T_cam_imu is not a list of 4 rows",
       "4 rows of 4 numbers"},
      {edited(base, "  - [0, 0, 0, 1]\n", "  - [0, 0, 0.5, 1]\n"), "  - [", "last row is not [0, 0, 0, 1]",
       "rigid transform"},
      {"cam0:\n  camera_model: pinhole\n  intrinsics: [1, 1, 0, 0]: 3\n  resolution: [240, 180]\n",
       "  intrinsics: [1, 1, 0, 0]: 3", "YAML syntax error", "Kalibr camchain YAML"},
      {"imu0:\n  update_rate: 200\n", "imu0", "no camera entries", "cam0, cam1"},
      {"- cam0\n- cam1\n", "- cam0", "top level is not a map", "Kalibr camchain YAML"},
  };
  int i = 0;
  for (const Case& c : cases) {
    const std::string path = dir.write("camchain" + std::to_string(i++) + ".yaml", c.text);
    SCOPED_TRACE(c.problem);
    expect_input_error([&] { load_kalibr_camchain(path); }, path, line_of(c.text, c.line_needle), c.problem,
                       c.expected);
  }

  // A scaled rotation block is not rigid.
  Camchain scaled = make_camchain();
  Eigen::Matrix4d T = scaled.T_c_b.matrix();
  T.topLeftCorner<3, 3>() *= 1.001;
  const std::string text =
      edited(scaled.text, matrix_yaml(scaled.T_c_b.matrix()), matrix_yaml(T));
  const std::string path = dir.write("scaled.yaml", text);
  expect_input_error([&] { load_kalibr_camchain(path); }, path, line_of(text, "  - ["),
                     "cam0.T_cam_imu is not rigid", "orthonormal rotation");

  const std::string missing = dir.file("missing.yaml");
  expect_input_error([&] { load_kalibr_camchain(missing); }, missing, 0, "cannot open file", "Kalibr camchain YAML");
}

TEST(CalibrationIo, KalibrImuTopLevelAndNested) {
  evio_test::TempDir dir;
  const std::string top =
      "#Accelerometers\n"
      "accelerometer_noise_density: 1.86e-03   #Noise density (continuous-time)\n"
      "accelerometer_random_walk:   4.33e-04   #Bias random walk\n"
      "\n"
      "#Gyroscopes\n"
      "gyroscope_noise_density:     1.87e-04   #Noise density (continuous-time)\n"
      "gyroscope_random_walk:       2.66e-05   #Bias random walk\n"
      "\n"
      "rostopic:                    /imu0      #the IMU ROS topic\n"
      "update_rate:                 200.0      #Hz (for discretization of the values above)\n";
  const std::string p1 = dir.write("imu.yaml", top);
  LogCapture log;
  const ImuNoise a = load_kalibr_imu(p1);
  EXPECT_EQ(a.accelerometer_noise_density, 1.86e-03);
  EXPECT_EQ(a.accelerometer_random_walk, 4.33e-04);
  EXPECT_EQ(a.gyroscope_noise_density, 1.87e-04);
  EXPECT_EQ(a.gyroscope_random_walk, 2.66e-05);
  EXPECT_EQ(a.update_rate_hz, 200.0);
  EXPECT_EQ(a.source, p1);
  EXPECT_TRUE(a.Validate(nullptr));
  ASSERT_EQ(log.messages().size(), 1u);
  EXPECT_NE(log.messages()[0].find("200 Hz"), std::string::npos) << log.messages()[0];

  const std::string nested =
      "imu0:\n"
      "  T_i_b:\n"
      "  - [1.0, 0.0, 0.0, 0.0]\n"
      "  - [0.0, 1.0, 0.0, 0.0]\n"
      "  - [0.0, 0.0, 1.0, 0.0]\n"
      "  - [0.0, 0.0, 0.0, 1.0]\n"
      "  accelerometer_noise_density: 0.0028\n"
      "  accelerometer_random_walk: 0.00086\n"
      "  gyroscope_noise_density: 0.00016\n"
      "  gyroscope_random_walk: 2.2e-05\n"
      "  model: calibrated\n"
      "  rostopic: /imu0\n"
      "  time_offset: 0.0\n"
      "  update_rate: 1000.0\n";
  const ImuNoise b = load_kalibr_imu(dir.write("imu_nested.yaml", nested));
  EXPECT_EQ(b.accelerometer_noise_density, 0.0028);
  EXPECT_EQ(b.gyroscope_random_walk, 2.2e-05);
  EXPECT_EQ(b.update_rate_hz, 1000.0);
}

TEST(CalibrationIo, KalibrImuErrors) {
  evio_test::TempDir dir;
  const std::string good =
      "accelerometer_noise_density: 1.86e-03\n"
      "accelerometer_random_walk: 4.33e-04\n"
      "gyroscope_noise_density: 1.87e-04\n"
      "gyroscope_random_walk: 2.66e-05\n"
      "update_rate: 200.0\n";
  {
    const std::string text = edited(good, "update_rate: 200.0\n", "");
    const std::string path = dir.write("no_rate.yaml", text);
    expect_input_error([&] { load_kalibr_imu(path); }, path, 1, "IMU file: missing key 'update_rate'",
                       "update_rate: number in Hz");
  }
  {
    const std::string text = edited(good, "1.87e-04", "-1.87e-04");
    const std::string path = dir.write("negative.yaml", text);
    expect_input_error([&] { load_kalibr_imu(path); }, path, 1, "gyroscope_noise_density must be finite and > 0",
                       "Kalibr IMU YAML");
  }
  {
    const std::string text = edited(good, "4.33e-04", "[1, 2]");
    const std::string path = dir.write("list.yaml", text);
    expect_input_error([&] { load_kalibr_imu(path); }, path, 2, "accelerometer_random_walk is not a finite number",
                       "m/s^3/sqrt(Hz)");
  }
  const std::string missing = dir.file("missing.yaml");
  expect_input_error([&] { load_kalibr_imu(missing); }, missing, 0, "cannot open file", "Kalibr IMU YAML");
}

TEST(CalibrationIo, ImuNoiseValidate) {
  ImuNoise n;
  std::string why;
  EXPECT_FALSE(n.Validate(&why));
  EXPECT_NE(why.find("accelerometer_noise_density"), std::string::npos);
  n.accelerometer_noise_density = 1e-3;
  n.gyroscope_noise_density = 1e-4;
  n.update_rate_hz = 200;
  EXPECT_TRUE(n.Validate(&why)) << why;  // zero random walks are allowed (e.g. simulation)
  n.gyroscope_random_walk = -1e-5;
  EXPECT_FALSE(n.Validate(&why));
  EXPECT_NE(why.find("gyroscope_random_walk"), std::string::npos);
}

}  // namespace
}  // namespace evio::calib
