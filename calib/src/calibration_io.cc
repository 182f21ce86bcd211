// Readers and writer for ECD calib.txt and Kalibr camchain / IMU YAML. Every problem with the
// file becomes an evio::InputError with the file, the 1-based line (yaml-cpp marks are 0-based)
// and the expected form; the conventions applied are logged once per load.
#include "evio/calib/calibration_io.h"

#include <algorithm>
#include <cerrno>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <utility>

#include <yaml-cpp/yaml.h>

#include "evio/calib/error.h"
#include "evio/calib/log.h"

namespace evio::calib {
namespace {

constexpr const char* kEcdExpected =
    "one line of 9 numbers 'fx fy cx cy k1 k2 p1 p2 k3' (pinhole radtan, px)";
constexpr const char* kCamchainExpected =
    "Kalibr camchain YAML with entries cam0, cam1, ... each holding camera_model, intrinsics, "
    "distortion_model, distortion_coeffs, resolution";
constexpr const char* kImuExpected =
    "Kalibr IMU YAML with accelerometer_noise_density, accelerometer_random_walk, "
    "gyroscope_noise_density, gyroscope_random_walk, update_rate (top level or under imu0)";

// ---- text helpers -------------------------------------------------------------------------------

std::vector<std::string> split_whitespace(const std::string& line) {
  std::istringstream in(line);
  std::vector<std::string> tokens;
  for (std::string t; in >> t;) tokens.push_back(t);
  return tokens;
}

// Parses the whole token as a finite double.
bool parse_double(const std::string& token, double* value) {
  if (token.empty()) return false;
  errno = 0;
  char* end = nullptr;
  const double v = std::strtod(token.c_str(), &end);
  if (end != token.c_str() + token.size() || errno == ERANGE || !std::isfinite(v)) return false;
  *value = v;
  return true;
}

// "0.000012", "-1.5", "0": int64 ns printed exactly as seconds, trailing zeros removed.
std::string format_ns_as_seconds(int64_t ns) {
  const bool negative = ns < 0;
  const uint64_t mag = negative ? static_cast<uint64_t>(-(ns + 1)) + 1 : static_cast<uint64_t>(ns);
  const uint64_t ns_per_s = 1000000000;
  char buf[48];
  std::snprintf(buf, sizeof(buf), "%s%" PRIu64 ".%09" PRIu64, negative ? "-" : "", mag / ns_per_s, mag % ns_per_s);
  std::string s(buf);
  while (s.back() == '0') s.pop_back();
  if (s.back() == '.') s.pop_back();
  return s;
}

// ---- YAML helpers ---------------------------------------------------------------------------------

// Reads values out of one YAML file and turns every problem into an InputError at the node's line.
class YamlReader {
 public:
  explicit YamlReader(std::string path) : path_(std::move(path)) {}

  const std::string& path() const { return path_; }

  static int64_t line_of(const YAML::Node& n) { return static_cast<int64_t>(n.Mark().line) + 1; }

  [[noreturn]] void fail(const YAML::Node& at, const std::string& problem, const std::string& expected) const {
    throw InputError(path_, line_of(at), problem, expected);
  }

  YAML::Node require(const YAML::Node& map, const std::string& context, const std::string& key,
                     const std::string& expected) const {
    const YAML::Node n = map[key];
    if (!n || n.IsNull()) fail(map, context + ": missing key '" + key + "'", expected);
    return n;
  }

  double number(const YAML::Node& n, const std::string& what, const std::string& expected) const {
    double v = 0.0;
    if (!n.IsScalar() || !parse_double(n.Scalar(), &v)) {
      fail(n, what + " is not a finite number" + (n.IsScalar() ? " ('" + n.Scalar() + "')" : ""), expected);
    }
    return v;
  }

  int integer(const YAML::Node& n, const std::string& what, const std::string& expected) const {
    const double v = number(n, what, expected);
    if (v != std::floor(v) || std::abs(v) > 1e9) fail(n, what + " is not an integer", expected);
    return static_cast<int>(v);
  }

  std::string string(const YAML::Node& n, const std::string& what, const std::string& expected) const {
    if (!n.IsScalar()) fail(n, what + " is not a string", expected);
    return n.Scalar();
  }

  // A sequence of numbers whose size is one of `sizes` (any size when `sizes` is empty).
  std::vector<double> numbers(const YAML::Node& n, const std::string& what, const std::vector<size_t>& sizes,
                              const std::string& expected) const {
    if (!n.IsSequence()) fail(n, what + " is not a list", expected);
    if (!sizes.empty() && std::find(sizes.begin(), sizes.end(), n.size()) == sizes.end()) {
      fail(n, what + " has " + std::to_string(n.size()) + " entries", expected);
    }
    std::vector<double> out;
    for (size_t i = 0; i < n.size(); ++i) {
      out.push_back(number(n[i], what + "[" + std::to_string(i) + "]", expected));
    }
    return out;
  }

 private:
  std::string path_;
};

YAML::Node load_yaml(const std::string& path, const std::string& expected) {
  std::ifstream probe(path);
  if (!probe) throw InputError(path, 0, "cannot open file", expected);
  try {
    return YAML::LoadFile(path);
  } catch (const YAML::Exception& e) {
    throw InputError(path, static_cast<int64_t>(e.mark.line) + 1, "YAML syntax error: " + e.msg, expected);
  }
}

// 4x4 rigid transform given row by row; the rotation block must be orthonormal with det +1.
SE3 read_rigid_transform(const YamlReader& r, const YAML::Node& n, const std::string& what) {
  const std::string expected = what + ": 4 rows of 4 numbers, a rigid transform (orthonormal rotation, "
                               "translation in m, last row [0, 0, 0, 1])";
  if (!n.IsSequence() || n.size() != 4) {
    r.fail(n, what + " is not a list of 4 rows", expected);
  }
  Eigen::Matrix4d T;
  for (int i = 0; i < 4; ++i) {
    const std::vector<double> row = r.numbers(n[i], what + " row " + std::to_string(i), {4}, expected);
    for (int j = 0; j < 4; ++j) T(i, j) = row[j];
  }
  const Eigen::RowVector4d bottom(0.0, 0.0, 0.0, 1.0);
  if ((T.row(3) - bottom).cwiseAbs().maxCoeff() > 1e-6) {
    r.fail(n, what + " last row is not [0, 0, 0, 1]", expected);
  }
  const Mat3 R = T.topLeftCorner<3, 3>();
  const double ortho_err = (R.transpose() * R - Mat3::Identity()).cwiseAbs().maxCoeff();
  if (!(ortho_err <= 1e-6) || !(R.determinant() > 0.0)) {
    std::ostringstream msg;
    msg << what << " is not rigid: max |R^T R - I| = " << ortho_err << ", det R = " << R.determinant();
    r.fail(n, msg.str(), expected);
  }
  return SE3::from_matrix(T);
}

CameraCalibration read_kalibr_camera(const YamlReader& r, const std::string& name, const YAML::Node& cam) {
  if (!cam.IsMap()) r.fail(cam, name + " is not a map", kCamchainExpected);

  const std::string model_expected = "camera_model: pinhole";
  const std::string camera_model =
      r.string(r.require(cam, name, "camera_model", model_expected), name + ".camera_model", model_expected);
  if (camera_model != "pinhole") {
    r.fail(cam["camera_model"], name + ": camera_model '" + camera_model + "' is not supported", model_expected);
  }

  const std::string intr_expected = "intrinsics: [fu, fv, pu, pv] (px)";
  const std::vector<double> k =
      r.numbers(r.require(cam, name, "intrinsics", intr_expected), name + ".intrinsics", {4}, intr_expected);

  const std::string res_expected = "resolution: [width, height] (px)";
  const YAML::Node res = r.require(cam, name, "resolution", res_expected);
  r.numbers(res, name + ".resolution", {2}, res_expected);

  const std::string dist_model_expected =
      "distortion_model: radtan, equidistant or none (aliases plumb_bob, fisheye, equi)";
  const YAML::Node dm = r.require(cam, name, "distortion_model", dist_model_expected);
  const std::string dist_name = r.string(dm, name + ".distortion_model", dist_model_expected);
  const std::optional<DistortionModel> model = distortion_model_from_name(dist_name);
  if (!model) r.fail(dm, name + ": unknown distortion_model '" + dist_name + "'", dist_model_expected);

  std::vector<size_t> dist_sizes;
  std::string dist_expected;
  switch (*model) {
    case DistortionModel::kNone:
      dist_sizes = {0};
      dist_expected = "distortion_coeffs: [] for distortion_model none";
      break;
    case DistortionModel::kRadtan:
      dist_sizes = {4, 5};
      dist_expected = "distortion_coeffs: [k1, k2, p1, p2] or [k1, k2, p1, p2, k3] for radtan";
      break;
    case DistortionModel::kEquidistant:
      dist_sizes = {4};
      dist_expected = "distortion_coeffs: [k1, k2, k3, k4] for equidistant";
      break;
  }
  const std::vector<double> dist = r.numbers(r.require(cam, name, "distortion_coeffs", dist_expected),
                                             name + ".distortion_coeffs", dist_sizes, dist_expected);

  CameraIntrinsics intr;
  intr.width = r.integer(res[0], name + ".resolution[0]", res_expected);
  intr.height = r.integer(res[1], name + ".resolution[1]", res_expected);
  intr.fx = k[0];
  intr.fy = k[1];
  intr.cx = k[2];
  intr.cy = k[3];
  intr.model = *model;
  intr.distortion = dist;
  std::string why;
  if (!intr.Validate(&why)) r.fail(cam, name + ": " + why, kCamchainExpected);

  CameraCalibration c;
  c.name = name;
  c.camera = PinholeCamera(intr);
  c.source = r.path();
  if (const YAML::Node T = cam["T_cam_imu"]; T && !T.IsNull()) {
    c.T_c_b = read_rigid_transform(r, T, name + ".T_cam_imu");
    c.has_T_c_b = true;
  }
  if (const YAML::Node ts = cam["timeshift_cam_imu"]; ts && !ts.IsNull()) {
    const std::string ts_expected = "timeshift_cam_imu: seconds, t_imu = t_cam + shift";
    const double s = r.number(ts, name + ".timeshift_cam_imu", ts_expected);
    if (std::abs(s) > 1e6) r.fail(ts, name + ".timeshift_cam_imu is implausibly large", ts_expected);
    c.time_shift_ns = std::llround(s * 1e9);
  }
  return c;
}

}  // namespace

bool ImuNoise::Validate(std::string* why) const {
  std::ostringstream msg;
  auto positive = [](double v) { return std::isfinite(v) && v > 0.0; };
  auto non_negative = [](double v) { return std::isfinite(v) && v >= 0.0; };
  if (!positive(accelerometer_noise_density)) {
    msg << "accelerometer_noise_density must be finite and > 0, got " << accelerometer_noise_density;
  } else if (!positive(gyroscope_noise_density)) {
    msg << "gyroscope_noise_density must be finite and > 0, got " << gyroscope_noise_density;
  } else if (!non_negative(accelerometer_random_walk)) {
    msg << "accelerometer_random_walk must be finite and >= 0, got " << accelerometer_random_walk;
  } else if (!non_negative(gyroscope_random_walk)) {
    msg << "gyroscope_random_walk must be finite and >= 0, got " << gyroscope_random_walk;
  } else if (!positive(update_rate_hz)) {
    msg << "update_rate must be finite and > 0 Hz, got " << update_rate_hz;
  } else {
    return true;
  }
  if (why != nullptr) *why = msg.str();
  return false;
}

CameraCalibration load_ecd_calib(const std::string& path, int width, int height) {
  std::ifstream in(path);
  if (!in) throw InputError(path, 0, "cannot open file", kEcdExpected);

  std::vector<double> values;
  int64_t value_line = 0;
  int64_t line_no = 0;
  for (std::string line; std::getline(in, line);) {
    ++line_no;
    const std::vector<std::string> tokens = split_whitespace(line);
    if (tokens.empty() || tokens[0][0] == '#') continue;
    if (value_line != 0) {
      throw InputError(path, line_no, "unexpected second line of numbers", kEcdExpected);
    }
    value_line = line_no;
    for (size_t i = 0; i < tokens.size(); ++i) {
      double v = 0.0;
      if (!parse_double(tokens[i], &v)) {
        throw InputError(path, line_no,
                         "value " + std::to_string(i + 1) + " '" + tokens[i] + "' is not a finite number",
                         kEcdExpected);
      }
      values.push_back(v);
    }
    if (values.size() != 9) {
      throw InputError(path, line_no, "found " + std::to_string(values.size()) + " numbers", kEcdExpected);
    }
  }
  if (value_line == 0) throw InputError(path, 1, "no calibration line in file", kEcdExpected);

  CameraIntrinsics intr;
  intr.width = width;
  intr.height = height;
  intr.fx = values[0];
  intr.fy = values[1];
  intr.cx = values[2];
  intr.cy = values[3];
  intr.model = DistortionModel::kRadtan;
  intr.distortion.assign(values.begin() + 4, values.end());
  std::string why;
  if (!intr.Validate(&why)) throw InputError(path, value_line, "invalid intrinsics: " + why, kEcdExpected);

  CameraCalibration c;
  c.name = "cam0";
  c.camera = PinholeCamera(intr);
  c.source = path;
  log_info(describe(c) + "; resolution given by the caller (calib.txt has none)");
  return c;
}

void write_ecd_calib(const std::string& path, const PinholeCamera& cam) {
  const CameraIntrinsics& intr = cam.intrinsics();
  if (intr.model == DistortionModel::kEquidistant) {
    throw std::invalid_argument("write_ecd_calib: ECD calib.txt holds radtan only, camera is equidistant");
  }
  double d[5] = {0.0, 0.0, 0.0, 0.0, 0.0};
  for (size_t i = 0; i < intr.distortion.size() && i < 5; ++i) d[i] = intr.distortion[i];

  std::FILE* f = std::fopen(path.c_str(), "w");
  if (f == nullptr) throw InputError(path, 0, "cannot open file for writing", "a writable path");
  std::fprintf(f, "%.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g\n", intr.fx, intr.fy, intr.cx, intr.cy,
               d[0], d[1], d[2], d[3], d[4]);
  const bool write_failed = std::ferror(f) != 0;
  if (std::fclose(f) != 0 || write_failed) throw InputError(path, 0, "write failed", "a writable path");
}

std::vector<CameraCalibration> load_kalibr_camchain(const std::string& path) {
  const YAML::Node root = load_yaml(path, kCamchainExpected);
  const YamlReader r(path);
  if (!root.IsMap()) throw InputError(path, 1, "top level is not a map", kCamchainExpected);

  // Collect camN keys and order them by N.
  std::vector<std::pair<int, std::string>> keys;
  for (const auto& kv : root) {
    const std::string key = kv.first.IsScalar() ? kv.first.Scalar() : std::string();
    if (key.size() < 4 || key.compare(0, 3, "cam") != 0) continue;
    const std::string digits = key.substr(3);
    if (!std::all_of(digits.begin(), digits.end(), [](char ch) { return ch >= '0' && ch <= '9'; }) ||
        digits.size() > 6) {
      continue;
    }
    keys.emplace_back(std::stoi(digits), key);
  }
  if (keys.empty()) throw InputError(path, 1, "no camera entries (cam0, cam1, ...)", kCamchainExpected);
  std::sort(keys.begin(), keys.end());

  std::vector<CameraCalibration> cams;
  try {
    for (const auto& [index, key] : keys) cams.push_back(read_kalibr_camera(r, key, root[key]));
  } catch (const YAML::Exception& e) {
    throw InputError(path, static_cast<int64_t>(e.mark.line) + 1, "YAML error: " + e.msg, kCamchainExpected);
  }
  for (const CameraCalibration& c : cams) log_info(describe(c));
  return cams;
}

ImuNoise load_kalibr_imu(const std::string& path) {
  const YAML::Node root = load_yaml(path, kImuExpected);
  const YamlReader r(path);
  if (!root.IsMap()) throw InputError(path, 1, "top level is not a map", kImuExpected);

  ImuNoise noise;
  try {
    const YAML::Node imu0 = root["imu0"];
    const bool nested = imu0 && imu0.IsMap();
    const YAML::Node node = nested ? imu0 : root;
    const std::string context = nested ? "imu0" : "IMU file";
    auto read = [&](const char* key, const char* unit) {
      const std::string expected = std::string(key) + ": number in " + unit;
      return r.number(r.require(node, context, key, expected), key, expected);
    };
    noise.accelerometer_noise_density = read("accelerometer_noise_density", "m/s^2/sqrt(Hz)");
    noise.accelerometer_random_walk = read("accelerometer_random_walk", "m/s^3/sqrt(Hz)");
    noise.gyroscope_noise_density = read("gyroscope_noise_density", "rad/s/sqrt(Hz)");
    noise.gyroscope_random_walk = read("gyroscope_random_walk", "rad/s^2/sqrt(Hz)");
    noise.update_rate_hz = read("update_rate", "Hz");
    noise.source = path;
    std::string why;
    if (!noise.Validate(&why)) r.fail(node, why, kImuExpected);
  } catch (const YAML::Exception& e) {
    throw InputError(path, static_cast<int64_t>(e.mark.line) + 1, "YAML error: " + e.msg, kImuExpected);
  }

  std::ostringstream msg;
  msg << "imu: noise densities accel " << noise.accelerometer_noise_density << " m/s^2/sqrt(Hz), gyro "
      << noise.gyroscope_noise_density << " rad/s/sqrt(Hz); random walks accel " << noise.accelerometer_random_walk
      << " m/s^3/sqrt(Hz), gyro " << noise.gyroscope_random_walk << " rad/s^2/sqrt(Hz); " << noise.update_rate_hz
      << " Hz (continuous-time Kalibr values, from " << path << ")";
  log_info(msg.str());
  return noise;
}

void write_kalibr_camchain(const std::string& path, const std::vector<CameraCalibration>& cameras,
                           const ImuNoise* imu) {
  if (cameras.empty()) throw std::invalid_argument("write_kalibr_camchain: no cameras");
  // Shortest of %.15g, %.16g, %.17g that reads back to the same double (readable and exact).
  auto num = [](double v) {
    char buf[40];
    for (int precision = 15; precision <= 17; ++precision) {
      std::snprintf(buf, sizeof(buf), "%.*g", precision, v);
      if (std::strtod(buf, nullptr) == v) break;
    }
    return std::string(buf);
  };
  auto list = [&](const std::vector<double>& v) {
    std::string s = "[";
    for (size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + num(v[i]);
    return s + "]";
  };
  std::ostringstream out;
  out << "# Kalibr camchain (cam0, ...) and IMU noise (imu0), written by evio. Conventions: T_cam_imu maps\n"
         "# IMU-frame points into the camera frame (p_c = T_cam_imu * p_imu); t_imu = t_cam + timeshift_cam_imu (s).\n";
  for (size_t i = 0; i < cameras.size(); ++i) {
    const CameraIntrinsics& intr = cameras[i].camera.intrinsics();
    out << "cam" << i << ":\n";
    out << "  camera_model: pinhole\n";
    out << "  intrinsics: " << list({intr.fx, intr.fy, intr.cx, intr.cy}) << "\n";
    out << "  distortion_model: " << distortion_model_name(intr.model) << "\n";
    out << "  distortion_coeffs: " << list(intr.distortion) << "\n";
    out << "  resolution: [" << intr.width << ", " << intr.height << "]\n";
    if (cameras[i].has_T_c_b) {
      const Mat3 R = cameras[i].T_c_b.rotation.toRotationMatrix();
      const Vec3& t = cameras[i].T_c_b.translation;
      out << "  T_cam_imu:\n";
      for (int r = 0; r < 3; ++r) out << "  - " << list({R(r, 0), R(r, 1), R(r, 2), t(r)}) << "\n";
      out << "  - [0.0, 0.0, 0.0, 1.0]\n";
    }
    out << "  timeshift_cam_imu: " << format_ns_as_seconds(cameras[i].time_shift_ns) << "\n";
    out << "  cam_overlaps: []\n";
    out << "  rostopic: /cam" << i << "/events\n";
  }
  if (imu != nullptr) {
    out << "imu0:\n";
    out << "  accelerometer_noise_density: " << num(imu->accelerometer_noise_density) << "  # m/s^2/sqrt(Hz)\n";
    out << "  accelerometer_random_walk: " << num(imu->accelerometer_random_walk) << "  # m/s^3/sqrt(Hz)\n";
    out << "  gyroscope_noise_density: " << num(imu->gyroscope_noise_density) << "  # rad/s/sqrt(Hz)\n";
    out << "  gyroscope_random_walk: " << num(imu->gyroscope_random_walk) << "  # rad/s^2/sqrt(Hz)\n";
    out << "  update_rate: " << num(imu->update_rate_hz) << "  # Hz\n";
    out << "  T_i_b:\n";
    out << "  - [1.0, 0.0, 0.0, 0.0]\n  - [0.0, 1.0, 0.0, 0.0]\n  - [0.0, 0.0, 1.0, 0.0]\n  - [0.0, 0.0, 0.0, 1.0]\n";
    out << "  time_offset: 0.0\n";
    out << "  rostopic: /imu0\n";
  }
  const std::string text = out.str();
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) throw InputError(path, 0, "cannot open file for writing", "a writable path");
  const bool write_failed = std::fwrite(text.data(), 1, text.size(), f) != text.size();
  if (std::fclose(f) != 0 || write_failed) throw InputError(path, 0, "write failed", "a writable path");
}

std::string describe(const CameraCalibration& calib) {
  const CameraIntrinsics& intr = calib.camera.intrinsics();
  std::ostringstream s;
  s << calib.name << ": pinhole " << distortion_model_name(intr.model) << " " << intr.width << "x" << intr.height;
  if (calib.has_T_c_b) {
    s << ", T_c_b = Kalibr T_cam_imu (p_c = T_c_b * p_b)";
  } else {
    s << ", no camera-IMU extrinsics (T_c_b = identity, unset)";
  }
  s << ", t_imu = t_cam + " << format_ns_as_seconds(calib.time_shift_ns) << " s";
  if (!calib.source.empty()) s << " (from " << calib.source << ")";
  return s.str();
}

}  // namespace evio::calib
