// Tests of the `evio simulate` scene YAML parser: every section into its library object, seeds
// derived from one top-level seed, `--set`/`--seed`/`--duration` overrides, errors naming the
// file and line (or the command-line option) and the expected form, unknown keys as errors, the
// resolved YAML reproducing the configuration, and the .npy writer.
#include "evio/simulator/scene_config.h"

#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio/sensors/time.h"
#include "evio/sensors/yaml_config.h"
#include "evio_test/temp_dir.h"

namespace evio::simulator {
namespace {

class QuietLog {
 public:
  QuietLog() { set_log_sink([](LogLevel, const std::string&) {}); }
  ~QuietLog() { set_log_sink({}); }
};

// A small but complete panorama scene.
const char* kPanorama = R"(description: "test scene"
seed: 5
duration: 0.5
camera:
  preset: davis240c
scene:
  type: panorama
  texture: {procedural: checkerboard, size: [128, 64], cell_px: 8}
trajectory:
  type: sinusoid
  rpy_deg: [-90, 0, -90]
  angle_rate_dps: [0, 100, 0]
)";

// text with the first occurrence of `from` replaced by `to` (which must be there).
std::string sub(std::string text, const std::string& from, const std::string& to) {
  const size_t at = text.find(from);
  EXPECT_NE(at, std::string::npos) << from;
  if (at != std::string::npos) text.replace(at, from.size(), to);
  return text;
}

SimulationConfig parse(const std::string& text, const SimulateOverrides& o = {}, const std::string& path = "scene.yaml") {
  return parse_simulation_config(text, path, o);
}

// Expects an InputError whose message holds every fragment; returns it.
InputError expect_error(const std::string& text, const std::vector<std::string>& fragments,
                        const SimulateOverrides& o = {}) {
  try {
    parse(text, o);
  } catch (const InputError& e) {
    for (const std::string& f : fragments) EXPECT_NE(std::string(e.what()).find(f), std::string::npos) << f << "\n" << e.what();
    EXPECT_NE(std::string(e.what()).find("expected: "), std::string::npos) << e.what();
    return e;
  }
  ADD_FAILURE() << "no InputError for:\n" << text;
  return InputError("", 0, "none");
}

TEST(SimulateConfig, MinimalPanoramaSceneBuildsEveryObject) {
  const SimulationConfig c = parse(kPanorama);
  EXPECT_EQ(c.description, "test scene");
  EXPECT_EQ(c.seed, 5u);
  EXPECT_EQ(c.scene_type, "panorama");
  ASSERT_TRUE(c.scene);
  ASSERT_TRUE(c.panorama);
  EXPECT_EQ(c.panorama->width(), 128);
  EXPECT_EQ(c.panorama->height(), 64);
  EXPECT_EQ(c.panorama->wrap_u(), simulator::TextureWrap::kRepeat);  // panoramas wrap around in u
  EXPECT_EQ(c.trajectory_type, "sinusoid");
  ASSERT_TRUE(c.trajectory);
  EXPECT_EQ(c.simulator.t_begin_ns, 0);
  EXPECT_EQ(c.simulator.t_end_ns, 500'000'000);
  EXPECT_DOUBLE_EQ(c.duration_s, 0.5);
  // Camera preset: the ECD DAVIS240C calibration.
  EXPECT_EQ(c.camera_preset, "davis240c");
  const calib::CameraIntrinsics& k = c.simulator.camera.intrinsics();
  EXPECT_EQ(k.width, 240);
  EXPECT_EQ(k.height, 180);
  EXPECT_DOUBLE_EQ(k.fx, 199.092366542);
  EXPECT_EQ(k.model, calib::DistortionModel::kRadtan);
  EXPECT_EQ(k.distortion.size(), 5u);
  EXPECT_TRUE(c.camera.has_T_c_b);
  EXPECT_TRUE(c.imu_enabled);
  EXPECT_DOUBLE_EQ(c.imu.rate_hz, 1000.0);
  EXPECT_DOUBLE_EQ(c.imu.noise.update_rate_hz, 1000.0);
  EXPECT_FALSE(c.ground_truth.event_labels);
  EXPECT_TRUE(c.simulator.ground_truth_times_ns.empty());
  EXPECT_DOUBLE_EQ(c.simulator.frames.rate_hz, 0.0);
  // The initial body orientation: body z (optical axis) along world +x, body y (down) along -z.
  const simulator::TrajectoryState s = c.trajectory->evaluate(0);
  const Eigen::Matrix3d R = s.T_w_b.rotation.toRotationMatrix();
  EXPECT_NEAR((R.col(2) - Eigen::Vector3d::UnitX()).norm(), 0, 1e-12);
  EXPECT_NEAR((R.col(1) + Eigen::Vector3d::UnitZ()).norm(), 0, 1e-12);
  EXPECT_NEAR(s.omega_b.y(), 100.0 * M_PI / 180.0, 1e-9);
}

TEST(SimulateConfig, IlluminationImuGapsAndClockOffset) {
  const SimulationConfig plain = parse(kPanorama);
  EXPECT_TRUE(plain.simulator.illumination.empty());
  EXPECT_TRUE(plain.imu.gaps_ns.empty());
  EXPECT_EQ(plain.clock_offset_ns, 0);
  const std::string text = std::string(kPanorama) +
                           "illumination: [[0.1, 1], [0.15, 4]]\nimu: {gaps_s: [[0.2, 0.25]]}\n"
                           "output: {clock_offset_ns: 1700000000000000000}\n";
  const SimulationConfig c = parse(text);
  const int64_t t0 = c.simulator.t_begin_ns;
  ASSERT_EQ(c.simulator.illumination.size(), 2u);
  EXPECT_EQ(c.simulator.illumination[0], std::make_pair(t0 + 100000000, 1.0));
  EXPECT_EQ(c.simulator.illumination[1], std::make_pair(t0 + 150000000, 4.0));
  ASSERT_EQ(c.imu.gaps_ns.size(), 1u);
  EXPECT_EQ(c.imu.gaps_ns[0], std::make_pair(t0 + 200000000, t0 + 250000000));
  EXPECT_EQ(c.clock_offset_ns, 1700000000000000000LL);
  expect_error(std::string(kPanorama) + "illumination: [[0.1, 1], [0.1, 2]]\n", {"illumination.1", "not after the previous knot"});
  expect_error(std::string(kPanorama) + "illumination: [[0.1, 0]]\n", {"illumination.0.1", "out of range"});
  expect_error(std::string(kPanorama) + "imu: {gaps_s: [[0.3, 0.2]]}\n", {"imu.gaps_s", "does not end after it starts"});
  expect_error(std::string(kPanorama) + "output: {clock_offset_ns: -5}\n", {"output.clock_offset_ns", "[0, 4e18]"});
  expect_error(std::string(kPanorama) + "output: {clock_offset_ns: 1.5e9}\n", {"output.clock_offset_ns"});
}

TEST(SimulateConfig, SeedsDeriveFromTheTopLevelSeedUnlessPinned) {
  const SimulationConfig c = parse(kPanorama);
  EXPECT_EQ(c.simulator.events.seed, yaml_config::derive_seed(5, "events.seed"));
  EXPECT_EQ(c.imu.seed, yaml_config::derive_seed(5, "imu.seed"));
  EXPECT_EQ(c.simulator.frames.seed, yaml_config::derive_seed(5, "frames.seed"));
  EXPECT_NE(c.simulator.events.seed, c.imu.seed);
  EXPECT_EQ(yaml_config::derive_seed(5, "events.seed"), yaml_config::derive_seed(5, "events.seed"));
  EXPECT_NE(yaml_config::derive_seed(5, "events.seed"), yaml_config::derive_seed(6, "events.seed"));

  SimulateOverrides o;
  o.seed = 6;
  const SimulationConfig d = parse(kPanorama, o);
  EXPECT_EQ(d.seed, 6u);
  EXPECT_EQ(d.simulator.events.seed, yaml_config::derive_seed(6, "events.seed"));

  const SimulationConfig pinned = parse(std::string(kPanorama) + "events: {seed: 77}\n", o);
  EXPECT_EQ(pinned.simulator.events.seed, 77u);

  // No top-level seed means seed 1.
  std::string no_seed = kPanorama;
  no_seed = sub(no_seed, "seed: 5\n", "");
  EXPECT_EQ(parse(no_seed).seed, 1u);
}

TEST(SimulateConfig, ResolvedYamlReproducesTheConfiguration) {
  SimulateOverrides o;
  o.set = {"events.contrast_threshold_pos=0.31"};
  o.duration_s = 0.25;
  const SimulationConfig c = parse(kPanorama, o);
  EXPECT_NE(c.resolved_yaml.find("seed:"), std::string::npos);
  const SimulationConfig again = parse(c.resolved_yaml);
  EXPECT_EQ(again.seed, c.seed);
  EXPECT_EQ(again.simulator.t_end_ns, 250'000'000);
  EXPECT_EQ(again.simulator.events.seed, c.simulator.events.seed);
  EXPECT_EQ(again.imu.seed, c.imu.seed);
  EXPECT_DOUBLE_EQ(again.simulator.events.contrast_threshold_pos, 0.31);
  // One more round changes nothing (a fixed point; the first round may restyle empty maps).
  EXPECT_EQ(parse(again.resolved_yaml).resolved_yaml, again.resolved_yaml);
}

TEST(SimulateConfig, CameraPresetsScaleExplicitIntrinsicsAndExtrinsics) {
  for (const std::string& name : camera_preset_names()) {
    const calib::CameraIntrinsics k = camera_preset(name);
    EXPECT_TRUE(k.Validate(nullptr)) << name;
  }
  EXPECT_EQ(camera_preset("davis346").width, 346);
  EXPECT_EQ(camera_preset("davis346").height, 260);
  EXPECT_EQ(camera_preset("prophesee").width, 640);
  EXPECT_EQ(camera_preset("prophesee_hd").width, 1280);
  EXPECT_THROW(camera_preset("kinect"), std::invalid_argument);

  SimulateOverrides o;
  o.set = {"camera.scale=0.25"};
  const calib::CameraIntrinsics s = parse(kPanorama, o).simulator.camera.intrinsics();
  EXPECT_EQ(s.width, 60);
  EXPECT_EQ(s.height, 45);
  EXPECT_DOUBLE_EQ(s.fx, 199.092366542 * 0.25);
  EXPECT_DOUBLE_EQ(s.cx, (132.192071378 + 0.5) * 0.25 - 0.5);

  std::string text = kPanorama;
  text = sub(text, "  preset: davis240c\n", "  width: 64\n  height: 48\n  intrinsics: [50, 51, 31.5, 23.5]\n  distortion_model: none\n"
               "  time_shift_s: 0.000012\n  supersample: 2\n"
               "  T_c_b: {translation_m: [0.01, 0.02, 0.03], rpy_deg: [0, 0, 90]}\n");
  const SimulationConfig e = parse(text);
  EXPECT_EQ(e.camera_preset, "");
  EXPECT_EQ(e.simulator.camera.width(), 64);
  EXPECT_DOUBLE_EQ(e.simulator.camera.intrinsics().fy, 51);
  EXPECT_EQ(e.simulator.camera.intrinsics().model, calib::DistortionModel::kNone);
  EXPECT_EQ(e.simulator.time_shift_ns, 12'000);
  EXPECT_EQ(e.camera.time_shift_ns, 12'000);
  EXPECT_EQ(e.simulator.supersample, 2);
  EXPECT_NEAR(e.simulator.T_c_b.translation.y(), 0.02, 1e-15);
  EXPECT_NEAR((e.simulator.T_c_b.rotation.toRotationMatrix() * Eigen::Vector3d::UnitX() - Eigen::Vector3d::UnitY()).norm(),
              0, 1e-12);

  // The same extrinsics as a 4x4 matrix.
  std::string matrix = kPanorama;
  matrix = sub(matrix, "  preset: davis240c\n", "  preset: davis346\n  T_c_b:\n  - [0, -1, 0, 0.01]\n  - [1, 0, 0, 0.02]\n  - [0, 0, 1, 0.03]\n"
                 "  - [0, 0, 0, 1]\n");
  const SimulationConfig m = parse(matrix);
  EXPECT_EQ(m.simulator.camera.width(), 346);
  EXPECT_NEAR((m.simulator.T_c_b.rotation.toRotationMatrix() * Eigen::Vector3d::UnitX() - Eigen::Vector3d::UnitY()).norm(),
              0, 1e-12);
  EXPECT_NEAR(m.simulator.T_c_b.translation.z(), 0.03, 1e-15);
}

TEST(SimulateConfig, PlanesAndBoxes) {
  const std::string text = R"(duration: 0.2
scene:
  type: planes
  background_intensity: 0.2
  planes:
  - center_m: [2, 0, 0]
    axis_u: [0, -2, 0]
    axis_v: [0, 0, 3]
    size_m: [4, 3]
    gain: 2
    texture: {procedural: noise, size: [64, 48], seed: 3}
  boxes:
  - center_m: [1.5, 0.3, -0.5]
    size_m: [0.3, 0.4, 0.5]
    yaw_deg: 30
    texture: {procedural: shapes, size: [32, 32], num_shapes: 3}
trajectory: {type: sinusoid, rpy_deg: [-90, 0, -90], amplitude_m: [0, 0.1, 0], frequency_hz: [0, 1, 0]}
)";
  const SimulationConfig c = parse(text);
  EXPECT_EQ(c.scene_type, "planes");
  const auto* planes = dynamic_cast<const simulator::PlanarScene*>(c.scene.get());
  ASSERT_NE(planes, nullptr);
  ASSERT_EQ(planes->planes().size(), 7u);  // 1 plane + 6 box faces
  EXPECT_NEAR((planes->planes()[0].axis_u_w - Eigen::Vector3d(0, -1, 0)).norm(), 0, 1e-15);  // normalised
  EXPECT_DOUBLE_EQ(planes->planes()[0].gain, 2);
  EXPECT_EQ(planes->planes()[0].texture->width(), 64);
  EXPECT_FALSE(c.panorama);
  // Box faces: each centre at half the box size from the box centre, orthonormal axes.
  for (size_t i = 1; i < 7; ++i) {
    const simulator::TexturedPlane& f = planes->planes()[i];
    EXPECT_NEAR(f.axis_u_w.dot(f.axis_v_w), 0, 1e-12);
    EXPECT_NEAR(f.axis_u_w.norm(), 1, 1e-12);
  }
  EXPECT_NEAR((planes->planes()[5].center_w - Eigen::Vector3d(1.5, 0.3, -0.25)).norm(), 0, 1e-12);  // top face
  EXPECT_EQ(c.resolved_yaml.find("seed: 3") != std::string::npos, true);

  std::string skew = text;
  skew = sub(skew, "axis_v: [0, 0, 3]", "axis_v: [0, 1, 1]");
  expect_error(skew, {"scene.yaml:8:", "scene.planes.0", "orthogonal"});
}

TEST(SimulateConfig, CheckerboardPlanesGiveTheirGridNodesAsTrueCorners) {
  // A 3 x 2 board of 64-texel cells on a 0.6 x 0.4 m plane (0.2 m squares) facing +x at x = 1:
  // 4 x 3 grid nodes, the 2 inner ones X-junctions; the noise plane gives none.
  const std::string text = R"(duration: 0.2
scene:
  type: planes
  planes:
  - center_m: [1, 0, 0]
    axis_u: [0, -1, 0]
    axis_v: [0, 0, 1]
    size_m: [0.6, 0.4]
    texture: {procedural: checkerboard, size: [192, 128], cell_px: 64}
  - center_m: [3, 0, 0]
    axis_u: [0, -1, 0]
    axis_v: [0, 0, 1]
    size_m: [4, 3]
    texture: {procedural: noise, size: [64, 48], seed: 3}
trajectory: {type: sinusoid, rpy_deg: [-90, 0, -90], amplitude_m: [0, 0.1, 0], frequency_hz: [0, 1, 0]}
)";
  const SimulationConfig c = parse(text);
  ASSERT_EQ(c.corners.size(), 12u);
  // Row by row from the texture's top-left (texel u along axis_u = -y, rows down along -z).
  EXPECT_NEAR((c.corners[0].p_w - Eigen::Vector3d(1, 0.3, 0.2)).norm(), 0, 1e-12);
  EXPECT_NEAR((c.corners[1].p_w - Eigen::Vector3d(1, 0.1, 0.2)).norm(), 0, 1e-12);
  EXPECT_NEAR((c.corners[5].p_w - Eigen::Vector3d(1, 0.1, 0.0)).norm(), 0, 1e-12);
  EXPECT_NEAR((c.corners[11].p_w - Eigen::Vector3d(1, -0.3, -0.2)).norm(), 0, 1e-12);
  int inner = 0;
  for (const simulator::SceneCorner& k : c.corners) inner += k.inner;
  EXPECT_EQ(inner, 2);
  EXPECT_TRUE(c.corners[5].inner);
  EXPECT_TRUE(c.corners[6].inner);
  EXPECT_TRUE(parse(sub(text, "procedural: checkerboard", "procedural: shapes")).corners.empty());
}

TEST(SimulateConfig, SpritesOverABackgroundWithLabels) {
  const std::string text = R"(duration: 0.2
scene:
  type: sprites
  background:
    type: panorama
    texture: {procedural: noise, size: [128, 64]}
  sprites:
  - texture: {procedural: checkerboard, size: [32, 32], cell_px: 4}
    shape: ellipse
    size_px: [20, 10]
    motion: {centre_px: [30, 20], velocity_pxps: [10, 0], angular_rate_dps: 90, scale_rate_per_s: 0.1}
  - texture: {procedural: constant, size: [8, 8]}
trajectory: {type: sinusoid}
ground_truth: {period_s: 0.1, times_s: [0.05, 0.1], depth: false}
)";
  const SimulationConfig c = parse(text);
  EXPECT_EQ(c.scene_type, "sprites");
  EXPECT_NE(dynamic_cast<const simulator::SpriteScene*>(c.scene.get()), nullptr);
  ASSERT_TRUE(c.panorama);  // the background panorama is still written out
  EXPECT_TRUE(c.ground_truth.event_labels);
  EXPECT_TRUE(c.simulator.event_labels);
  EXPECT_FALSE(c.ground_truth.depth);
  // period 0.1 s over [0, 0.2] plus 0.05 and a duplicate 0.1: sorted and unique.
  const std::vector<int64_t> times = {0, 50'000'000, 100'000'000, 200'000'000};
  EXPECT_EQ(c.ground_truth.times_ns, times);
  EXPECT_EQ(c.simulator.ground_truth_times_ns, times);

  std::string nested = text;
  nested = sub(nested, "    type: panorama", "    type: sprites ");
  expect_error(nested, {"scene.yaml:5:", "scene.background.type", "'sprites' is not allowed", "panorama | planes"});
}

TEST(SimulateConfig, RandomSplineAndSinusoidOptions) {
  const std::string text = R"(seed: 3
duration: 1.5
scene: {type: panorama, texture: {procedural: noise, size: [64, 32]}}
trajectory:
  type: random_spline
  order: 5
  knot_spacing_s: 0.25
  position_m: [1, 2, 3]
  position_std_m: [0.1, 0.1, 0]
  rotation_std_deg: 5
)";
  const SimulationConfig c = parse(text);
  EXPECT_EQ(c.trajectory_type, "random_spline");
  const auto* spline = dynamic_cast<const simulator::SplineTrajectory*>(c.trajectory.get());
  ASSERT_NE(spline, nullptr);
  EXPECT_EQ(spline->order(), 5);
  EXPECT_EQ(spline->knot_spacing_ns(), 250'000'000);
  EXPECT_EQ(c.simulator.t_end_ns, 1'500'000'000);
  EXPECT_LE(c.simulator.t_end_ns, c.trajectory->t_end_ns());
  // Seeded: the same seed gives the same motion, another seed another one.
  const Eigen::Vector3d p = c.trajectory->evaluate(700'000'000).T_w_b.translation;
  EXPECT_EQ(parse(text).trajectory->evaluate(700'000'000).T_w_b.translation, p);
  SimulateOverrides o;
  o.seed = 4;
  EXPECT_NE(parse(text, o).trajectory->evaluate(700'000'000).T_w_b.translation, p);

  std::string bad = text;
  bad = sub(bad, "order: 5", "order: 9");
  expect_error(bad, {"scene.yaml:6:", "trajectory.order", "an integer in [4, 6]"});
}

// A smooth synthetic motion-capture file: a 0.5 m circle in 4 s at 200 Hz, slowly yawing.
std::string write_mocap(const evio_test::TempDir& dir) {
  std::ostringstream csv;
  csv << "# timestamp, x, y, z, qx, qy, qz, qw\n";
  csv.precision(17);
  for (int i = 0; i <= 800; ++i) {
    const double t = i * 0.005;
    const double a = 0.5 * t;
    const Eigen::Quaterniond q(Eigen::AngleAxisd(0.3 * t, Eigen::Vector3d::UnitZ()));
    csv << int64_t{1'000'000'000} + int64_t{i} * 5'000'000 << "," << 0.5 * std::cos(a) << "," << 0.5 * std::sin(a)
        << "," << 1.0 << "," << q.x() << "," << q.y() << "," << q.z() << "," << q.w() << "\n";
  }
  return dir.write("traj/mocap.csv", csv.str());
}

TEST(SimulateConfig, FileTrajectoryWindowTransformAndFit) {
  QuietLog quiet;
  evio_test::TempDir dir;
  write_mocap(dir);
  const std::string text = R"(duration: 1.0
scene: {type: panorama, texture: {procedural: noise, size: [64, 32]}}
trajectory:
  type: file
  path: traj/mocap.csv
  start_s: 1.5
  transform: {translation_m: [10, 0, 0]}
  fit: {order: 6, knot_spacing_s: 0.05}
)";
  const std::string path = dir.write("scene.yaml", text);
  const SimulationConfig c = load_simulation_config(path);
  EXPECT_EQ(c.trajectory_type, "file");
  EXPECT_NE(c.trajectory_file.find("traj/mocap.csv"), std::string::npos);
  EXPECT_EQ(c.simulator.t_begin_ns, 2'500'000'000);  // file starts at 1 s, + start_s
  EXPECT_EQ(c.simulator.t_end_ns, 3'500'000'000);
  ASSERT_TRUE(c.fit_report.has_value());
  EXPECT_GT(c.fit_report->samples, 200u);
  EXPECT_LT(c.fit_report->position_max_m, 1e-3);
  // At t = 3 s (2 s into the file) the body is on the circle, shifted by the transform.
  const double a = 0.5 * 2.0;
  const Eigen::Vector3d expected(10 + 0.5 * std::cos(a), 0.5 * std::sin(a), 1.0);
  EXPECT_LT((c.trajectory->evaluate(3'000'000'000).T_w_b.translation - expected).norm(), 1e-3);
  // The resolved YAML names the file by its absolute path.
  EXPECT_NE(c.resolved_yaml.find(dir.path()), std::string::npos) << c.resolved_yaml;

  // Without duration: the rest of the file.
  SimulateOverrides o;
  o.set = {"trajectory.start_s=3"};
  std::string no_duration = text;
  no_duration.replace(0, 14, "");
  const SimulationConfig rest = parse_simulation_config(no_duration, path, o);
  EXPECT_EQ(rest.simulator.t_begin_ns, 4'000'000'000);
  EXPECT_EQ(rest.simulator.t_end_ns, 5'000'000'000);

  // Too long a window, a missing file.
  SimulateOverrides longer;
  longer.duration_s = 5;
  try {
    load_simulation_config(path, longer);
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("--duration 5"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("runs past the end"), std::string::npos) << e.what();
  }
  std::string missing = text;
  missing = sub(missing, "traj/mocap.csv", "traj/nothing.csv");
  try {
    parse_simulation_config(missing, path);
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(path + ":5:"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("nothing.csv"), std::string::npos) << e.what();
  }
}

TEST(SimulateConfig, ImuEventsSteppingFramesSections) {
  const std::string text = std::string(kPanorama) + R"(imu:
  rate_hz: 200
  accelerometer_noise_density: 0.01
  accelerometer_random_walk: 0.001
  gyroscope_noise_density: 0.002
  gyroscope_random_walk: 0.0001
  enable_noise: false
  initial_bias_gyro_radps: [0.01, 0, 0]
  gravity_mps2: [0, 0, -9.8]
events:
  contrast_threshold_pos: 0.15
  contrast_threshold_neg: 0.25
  threshold_mismatch_std: 0.02
  log_eps: 0.0001
  refractory_s: 0.0005
  shot_noise_rate_hz: 0.1
  leak_rate_hz: 0.05
  hot_pixel_fraction: 0.001
  hot_pixel_rate_hz: 30
  timestamp_jitter_s: 0.00001
stepping: {max_flow_px: 0.25, max_log_change: 0.02, min_step_s: 0.000001, max_step_s: 0.002}
frames: {rate_hz: 20, exposure_s: 0.01, exposure_samples: 4, gain: 2, gamma: 1, read_noise_std: 0}
output: {events_h5: false, panorama: false}
)";
  const SimulationConfig c = parse(text);
  EXPECT_DOUBLE_EQ(c.imu.rate_hz, 200);
  EXPECT_DOUBLE_EQ(c.imu.noise.update_rate_hz, 200);
  EXPECT_DOUBLE_EQ(c.imu.noise.accelerometer_noise_density, 0.01);
  EXPECT_DOUBLE_EQ(c.imu.noise.gyroscope_random_walk, 0.0001);
  EXPECT_FALSE(c.imu.enable_noise);
  EXPECT_DOUBLE_EQ(c.imu.initial_bias_gyro_radps.x(), 0.01);
  EXPECT_DOUBLE_EQ(c.imu.gravity_w.z(), -9.8);
  const simulator::EventSimOptions& e = c.simulator.events;
  EXPECT_DOUBLE_EQ(e.contrast_threshold_pos, 0.15);
  EXPECT_DOUBLE_EQ(e.contrast_threshold_neg, 0.25);
  EXPECT_DOUBLE_EQ(e.threshold_mismatch_std, 0.02);
  EXPECT_DOUBLE_EQ(e.log_eps, 1e-4);
  EXPECT_EQ(e.refractory_ns, 500'000);
  EXPECT_DOUBLE_EQ(e.shot_noise_rate_hz, 0.1);
  EXPECT_DOUBLE_EQ(e.leak_rate_hz, 0.05);
  EXPECT_DOUBLE_EQ(e.hot_pixel_fraction, 0.001);
  EXPECT_DOUBLE_EQ(e.hot_pixel_rate_hz, 30);
  EXPECT_NEAR(e.timestamp_jitter_ns, 10'000, 1e-6);
  EXPECT_DOUBLE_EQ(c.simulator.stepping.max_flow_px, 0.25);
  EXPECT_EQ(c.simulator.stepping.min_step_ns, 1'000);
  EXPECT_EQ(c.simulator.stepping.max_step_ns, 2'000'000);
  EXPECT_DOUBLE_EQ(c.simulator.frames.rate_hz, 20);
  EXPECT_EQ(c.simulator.frames.exposure_samples, 4);
  EXPECT_FALSE(c.write_h5);
  EXPECT_FALSE(c.write_panorama);

  std::string bad = text;
  bad = sub(bad, "hot_pixel_fraction: 0.001", "hot_pixel_fraction: 1.5  ");
  expect_error(bad, {"scene.yaml:30:", "events.hot_pixel_fraction", "out of range", "[0, 1]"});
  std::string zero = text;
  zero = sub(zero, "gyroscope_noise_density: 0.002", "gyroscope_noise_density: 0    ");
  expect_error(zero, {"scene.yaml:17:", "imu.gyroscope_noise_density", "> 0"});
}

TEST(SimulateConfig, OverridesEditTheTreeBeforeParsing) {
  std::string text = std::string(kPanorama) + "events: {contrast_threshold_pos: 0.2}\n";
  SimulateOverrides o;
  o.set = {"events.contrast_threshold_pos=0.3", "frames.rate_hz=10", "scene.texture.size=[64, 32]",
           "trajectory.angle_rate_dps.1=200"};
  o.duration_s = 0.125;
  const SimulationConfig c = parse(text, o);
  EXPECT_DOUBLE_EQ(c.simulator.events.contrast_threshold_pos, 0.3);
  EXPECT_DOUBLE_EQ(c.simulator.frames.rate_hz, 10);
  EXPECT_EQ(c.panorama->width(), 64);
  EXPECT_EQ(c.simulator.t_end_ns, 125'000'000);
  EXPECT_NEAR(c.trajectory->evaluate(0).omega_b.y(), 200 * M_PI / 180, 1e-9);

  // Errors about overridden values name the option, not a line of the file.
  SimulateOverrides typo;
  typo.set = {"events.contrast_treshold_pos=0.3"};
  const InputError e = expect_error(text, {"--set events.contrast_treshold_pos=0.3", "unknown key 'contrast_treshold_pos'",
                                           "contrast_threshold_pos"},
                                    typo);
  EXPECT_EQ(e.line(), 0);
  SimulateOverrides bad_value;
  bad_value.set = {"events.leak_rate_hz=-1"};
  expect_error(text, {"--set events.leak_rate_hz=-1", "events.leak_rate_hz", ">= 0"}, bad_value);
  SimulateOverrides no_eq;
  no_eq.set = {"events.leak_rate_hz"};
  expect_error(text, {"--set events.leak_rate_hz", "no '='"}, no_eq);
  SimulateOverrides bad_index;
  bad_index.set = {"trajectory.rpy_deg.7=1"};
  expect_error(text, {"--set trajectory.rpy_deg.7=1", "not an index"}, bad_index);
}

TEST(SimulateConfig, ErrorsNameFileLineAndExpectedForm) {
  // Unknown keys anywhere (typos) with the allowed keys listed.
  std::string typo = kPanorama;
  typo = sub(typo, "  angle_rate_dps", "  angle_rate_dpz");
  expect_error(typo, {"scene.yaml:12:", "trajectory.angle_rate_dpz", "unknown key", "angle_rate_dps"});
  expect_error(std::string(kPanorama) + "framez: {}\n", {"scene.yaml:13:", "unknown key 'framez'", "frames"});
  // Wrong types and sizes.
  std::string type = kPanorama;
  type = sub(type, "duration: 0.5", "duration: abc");
  expect_error(type, {"scene.yaml:3:", "duration", "not a finite number", "> 0 (s)"});
  std::string size = kPanorama;
  size = sub(size, "[-90, 0, -90]", "[-90, 0]");
  expect_error(size, {"scene.yaml:11:", "trajectory.rpy_deg", "has 2 entries", "3 numbers"});
  // Missing sections and values.
  std::string no_traj = kPanorama;
  no_traj.erase(no_traj.find("trajectory:"));
  expect_error(no_traj, {"scene.yaml:1:", "missing key 'trajectory'"});
  std::string no_kind = kPanorama;
  no_kind = sub(no_kind, "procedural: checkerboard, ", "");
  expect_error(no_kind, {"scene.yaml:8:", "scene.texture", "exactly one of 'procedural' and 'file'"});
  std::string bad_kind = kPanorama;
  bad_kind = sub(bad_kind, "checkerboard", "stripes");
  expect_error(bad_kind, {"scene.yaml:8:", "'stripes' is not allowed", "checkerboard | shapes | noise | constant"});
  // A preset's resolution cannot change alone.
  std::string res = kPanorama;
  res = sub(res, "  preset: davis240c\n", "  preset: davis240c\n  width: 100\n");
  expect_error(res, {"scene.yaml:6:", "camera.width", "scale"});
  // YAML syntax errors carry the line too.
  expect_error("seed: 1\nscene: [\n", {"scene.yaml:", "YAML syntax error"});
  // Missing texture file: relative to the YAML file, named with the YAML line.
  std::string file = kPanorama;
  file = sub(file, "{procedural: checkerboard, size: [128, 64], cell_px: 8}", "{file: no_such_image.png}");
  expect_error(file, {"scene.yaml:8:", "no_such_image.png", "cannot load texture"});
  // A missing scene file.
  EXPECT_THROW(load_simulation_config("/nonexistent/scene.yaml"), InputError);
}

TEST(SimulateConfig, TextureFromAnImageFile) {
  evio_test::TempDir dir;
  cv::Mat img(16, 32, CV_8U);
  for (int y = 0; y < img.rows; ++y) {
    for (int x = 0; x < img.cols; ++x) img.at<uint8_t>(y, x) = static_cast<uint8_t>(x * 8);
  }
  // Written as a .npy is not an image; write a PGM by hand (OpenCV reads it).
  std::string pgm = "P5\n32 16\n255\n";
  pgm.append(reinterpret_cast<const char*>(img.data), img.total());
  dir.write("tex.pgm", pgm);
  std::string text = kPanorama;
  text = sub(text, "{procedural: checkerboard, size: [128, 64], cell_px: 8}", "{file: tex.pgm, min_intensity: 0.1, max_intensity: 0.9}");
  const SimulationConfig c = parse_simulation_config(text, dir.file("scene.yaml"));
  ASSERT_TRUE(c.panorama);
  EXPECT_EQ(c.panorama->width(), 32);
  EXPECT_EQ(c.panorama->height(), 16);
  EXPECT_NEAR(c.panorama->level(0).at<float>(0, 0), 0.1, 1e-6);
}

}  // namespace
}  // namespace evio::simulator
