// Parser of the `evio simulate` scene YAML (schema: datasets/README.md). Each map is read
// through a Section that knows its dotted key path and its YAML node, checks its keys against
// the allowed set (typos are errors) and turns every problem into an evio::InputError at the
// node's line; values that came from `--set`/`--seed`/`--duration` are reported against that
// command-line option instead of a line of the file.
#include "evio/simulator/scene_config.h"

#include "evio/sensors/yaml_config.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <utility>

#include <yaml-cpp/yaml.h>

#include "evio/calib/error.h"
#include "evio/calib/geometry.h"
#include "evio/sensors/time.h"
#include "evio/sensors/trajectory.h"

namespace evio::simulator {
namespace {
using namespace yaml_config;  // NOLINT: Section, Parser, Range, ...
namespace fs = std::filesystem;
using Eigen::Quaterniond;
using Eigen::Vector2d;
using Eigen::Vector3d;

constexpr double kDegToRad = M_PI / 180.0;

// Orientation from `rpy_deg: [roll, pitch, yaw]` (R = Rz(yaw) Ry(pitch) Rx(roll)) or
// `quaternion: [qx, qy, qz, qw]`; identity when neither is given.
Quaterniond read_rotation(const Section& s) {
  if (s.has("rpy_deg") && s.has("quaternion")) {
    s.fail_at("quaternion", "both rpy_deg and quaternion are given", "one of rpy_deg or quaternion");
  }
  if (s.has("rpy_deg")) {
    const std::vector<double> r = s.numbers("rpy_deg", 3, Range::kAny, "deg");
    return Quaterniond(Eigen::AngleAxisd(r[2] * kDegToRad, Vector3d::UnitZ()) *
                       Eigen::AngleAxisd(r[1] * kDegToRad, Vector3d::UnitY()) *
                       Eigen::AngleAxisd(r[0] * kDegToRad, Vector3d::UnitX()));
  }
  if (s.has("quaternion")) {
    const std::vector<double> q = s.numbers("quaternion", 4, Range::kAny, "qx, qy, qz, qw");
    const Quaterniond quat(q[3], q[0], q[1], q[2]);
    if (std::abs(quat.norm() - 1.0) > 1e-3) {
      s.fail_at("quaternion", "is not a unit quaternion", "[qx, qy, qz, qw] with norm 1 (within 1e-3)");
    }
    return quat.normalized();
  }
  return Quaterniond::Identity();
}

// A rigid transform: a 4x4 matrix (4 rows of 4 numbers) or {translation_m, rpy_deg | quaternion}.
calib::SE3 read_transform(const Section& parent, const std::string& key) {
  const std::string expected =
      "a map {translation_m: [x, y, z], rpy_deg: [r, p, y] or quaternion: [qx, qy, qz, qw]} or 4 rows of 4 numbers "
      "(rigid, last row [0, 0, 0, 1])";
  const YAML::Node n = parent.get(key);
  const Parser& p = parent.parser();
  if (n.IsSequence()) {
    if (n.size() != 4) p.fail(n, parent.key_path(key), "is not 4 rows", expected);
    Eigen::Matrix4d T;
    for (int i = 0; i < 4; ++i) {
      if (!n[i].IsSequence() || n[i].size() != 4) p.fail(n[i], parent.key_path(key), "row is not 4 numbers", expected);
      for (int j = 0; j < 4; ++j) {
        T(i, j) = parent.number_of(n[i][j], parent.key_path(key), Range::kAny, "");
      }
    }
    const Eigen::Matrix3d R = T.topLeftCorner<3, 3>();
    if ((R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() > 1e-6 || R.determinant() <= 0 ||
        (T.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() > 1e-9) {
      p.fail(n, parent.key_path(key), "is not a rigid transform", expected);
    }
    return calib::SE3::from_matrix(T);
  }
  if (!n.IsMap()) p.fail(n, parent.key_path(key), "is neither a map nor a matrix", expected);
  Section s(&p, n, parent.key_path(key));
  s.allow({"translation_m", "rpy_deg", "quaternion"});
  return calib::SE3(read_rotation(s), s.vec3("translation_m", Vector3d::Zero(), Range::kAny, "m"));
}

// ---- the whole config --------------------------------------------------------------------------------

class ConfigBuilder {
 public:
  ConfigBuilder(const Parser* parser, YAML::Node root, SimulationConfig* out) : p_(parser), root_(parser, root, ""), c_(out) {}

  void build() {
    root_.allow({"description", "seed", "duration", "camera", "scene", "trajectory", "imu", "events", "stepping",
                 "frames", "ground_truth", "illumination", "output"});
    if (root_.has("description")) c_->description = root_.string("description", "", {});
    c_->seed = root_.has("seed") ? root_.seed("seed", 0) : 1;  // a missing top-level seed means 1
    root_.set("seed", YAML::Node(c_->seed));

    read_camera(root_.child("camera", false, "camera: {preset: davis240c} or explicit intrinsics"));
    read_trajectory(root_.child("trajectory", true, "trajectory: {type: sinusoid | random_spline | file, ...}"));
    c_->scene = read_scene(root_.child("scene", true, "scene: {type: panorama | planes | sprites, ...}"), true);
    read_imu(root_.child("imu", false, "imu: {rate_hz, noise densities, ...}"));
    read_events(root_.child("events", false, "events: {contrast_threshold_pos, ...}"));
    read_stepping(root_.child("stepping", false, "stepping: {max_flow_px, max_log_change, min_step_s, max_step_s}"));
    read_frames(root_.child("frames", false, "frames: {rate_hz, exposure_s, ...}"));
    read_ground_truth(root_.child("ground_truth", false, "ground_truth: {pose_rate_hz, period_s, times_s, ...}"));
    read_illumination();
    Section output = root_.child("output", false, "output: {events_h5, panorama, clock_offset_ns}");
    output.allow({"events_h5", "panorama", "clock_offset_ns"});
    c_->write_h5 = output.boolean("events_h5", true);
    c_->write_panorama = output.boolean("panorama", true);
    if (output.has("clock_offset_ns")) {
      const YAML::Node n = output.get("clock_offset_ns");
      const std::string expected = "an integer number of ns in [0, 4e18], e.g. 1700000000000000000";
      long long v = -1;
      size_t used = 0;
      try {
        v = std::stoll(n.IsScalar() ? n.Scalar() : std::string(), &used);
      } catch (const std::exception&) {
      }
      if (!n.IsScalar() || used != n.Scalar().size() || v < 0 || v > 4'000'000'000'000'000'000LL) {
        p_->fail(n, output.key_path("clock_offset_ns"), "is not an integer in range", expected);
      }
      c_->clock_offset_ns = v;
    }

    SimulatorOptions& o = c_->simulator;
    o.camera = c_->camera.camera;
    o.T_c_b = c_->camera.T_c_b;
    o.time_shift_ns = c_->camera.time_shift_ns;
    o.event_labels = c_->ground_truth.event_labels;
    o.ground_truth_flow = c_->ground_truth.flow;
    std::string why;
    if (!o.Validate(&why)) root_.fail("invalid simulator options: " + why, "see datasets/README.md");
  }

 private:
  uint64_t seed_for(Section& s, const std::string& key = "seed") { return s.seed(key, c_->seed); }

  // ---- camera ----
  void read_camera(Section s) {
    s.allow({"preset", "scale", "width", "height", "intrinsics", "distortion_model", "distortion_coeffs", "T_c_b",
             "time_shift_s", "supersample"});
    std::string presets;
    for (const std::string& n : camera_preset_names()) presets += (presets.empty() ? "" : " | ") + n;
    calib::CameraIntrinsics intr;
    const bool explicit_intr = s.has("intrinsics");
    if (s.has("preset")) {
      c_->camera_preset = s.string("preset", "", camera_preset_names());
      intr = camera_preset(c_->camera_preset);
    } else if (!explicit_intr) {
      c_->camera_preset = "davis240c";
      intr = camera_preset(c_->camera_preset);
    }
    if (explicit_intr) {
      const std::vector<double> k = s.numbers("intrinsics", 4, Range::kAny, "fx, fy, cx, cy in px");
      intr.fx = k[0];
      intr.fy = k[1];
      intr.cx = k[2];
      intr.cy = k[3];
      if (!s.has("width") || !s.has("height")) {
        s.fail("explicit intrinsics need width and height", "width: px, height: px next to intrinsics");
      }
    }
    if ((s.has("width") || s.has("height")) && !explicit_intr) {
      s.fail_at(s.has("width") ? "width" : "height", "a preset's resolution cannot be changed alone",
                "scale: factor (scales resolution and intrinsics), or intrinsics with width and height");
    }
    intr.width = s.integer("width", intr.width, 1, 65535);
    intr.height = s.integer("height", intr.height, 1, 65535);
    if (s.has("distortion_model")) {
      const std::string name = s.string("distortion_model", "", {"none", "radtan", "equidistant"});
      intr.model = *calib::distortion_model_from_name(name);
      intr.distortion.clear();
      if (intr.model != calib::DistortionModel::kNone && !s.has("distortion_coeffs")) {
        s.fail_at("distortion_model", "needs distortion_coeffs", "distortion_coeffs: [k1, k2, p1, p2(, k3)] or [k1..k4]");
      }
    }
    if (s.has("distortion_coeffs")) intr.distortion = s.any_numbers("distortion_coeffs", Range::kAny, "");
    if (s.has("scale")) {
      const double f = s.number("scale", 1.0, Range::kPositive, "factor on resolution and intrinsics");
      intr.width = std::max(1, static_cast<int>(std::lround(intr.width * f)));
      intr.height = std::max(1, static_cast<int>(std::lround(intr.height * f)));
      intr.fx *= f;
      intr.fy *= f;
      intr.cx = (intr.cx + 0.5) * f - 0.5;  // pixel centres at integers
      intr.cy = (intr.cy + 0.5) * f - 0.5;
    }
    std::string why;
    if (!intr.Validate(&why)) {
      s.fail("invalid camera: " + why,
             "preset: " + presets + ", or width, height, intrinsics [fx, fy, cx, cy], distortion_model, distortion_coeffs");
    }
    c_->camera.name = "cam0";
    c_->camera.camera = calib::PinholeCamera(intr);
    c_->camera.T_c_b = s.has("T_c_b") ? read_transform(s, "T_c_b") : calib::SE3();
    c_->camera.has_T_c_b = true;
    c_->camera.time_shift_ns = s.time_ns("time_shift_s", 0, Range::kAny);
    c_->camera.source = p_->file();
    c_->simulator.supersample = s.integer("supersample", 1, 1, 8);
  }

  // ---- trajectory ----
  void read_trajectory(Section s) {
    c_->trajectory_type = s.string("type", "", {"sinusoid", "random_spline", "file"});
    const std::string& type = c_->trajectory_type;
    const bool has_duration = root_.has("duration");
    const double duration = root_.number("duration", 2.0, Range::kPositive, "s");
    if (type == "sinusoid") {
      s.allow({"type", "position_m", "rpy_deg", "quaternion", "velocity_mps", "amplitude_m", "frequency_hz",
               "phase_deg", "angle_rate_dps", "angle_amplitude_deg", "angle_frequency_hz", "angle_phase_deg"});
      SinusoidTrajectoryOptions o;
      o.t_begin_ns = 0;
      o.duration_s = duration;
      o.position_m = s.vec3("position_m", o.position_m, Range::kAny, "m");
      o.q_w_b0 = read_rotation(s);
      o.velocity_mps = s.vec3("velocity_mps", o.velocity_mps, Range::kAny, "m/s");
      o.amplitude_m = s.vec3("amplitude_m", o.amplitude_m, Range::kAny, "m");
      o.frequency_hz = s.vec3("frequency_hz", o.frequency_hz, Range::kNonNegative, "Hz");
      o.phase_rad = s.vec3("phase_deg", Vector3d::Zero(), Range::kAny, "deg") * kDegToRad;
      o.angle_rate_radps = s.vec3("angle_rate_dps", Vector3d::Zero(), Range::kAny, "deg/s (roll, pitch, yaw)") * kDegToRad;
      o.angle_amplitude_rad =
          s.vec3("angle_amplitude_deg", Vector3d::Zero(), Range::kAny, "deg (roll, pitch, yaw)") * kDegToRad;
      o.angle_frequency_hz = s.vec3("angle_frequency_hz", o.angle_frequency_hz, Range::kNonNegative, "Hz");
      o.angle_phase_rad = s.vec3("angle_phase_deg", Vector3d::Zero(), Range::kAny, "deg") * kDegToRad;
      std::string why;
      if (!o.Validate(&why)) s.fail("invalid sinusoid: " + why, "see datasets/README.md, trajectory");
      c_->trajectory = std::make_shared<SinusoidTrajectory>(o);
      set_span(0, duration);
    } else if (type == "random_spline") {
      s.allow({"type", "order", "knot_spacing_s", "position_m", "rpy_deg", "quaternion", "position_std_m",
               "rotation_std_deg", "seed"});
      RandomSplineOptions o;
      o.t_begin_ns = 0;
      o.duration_s = duration;
      o.order = s.integer("order", o.order, 4, 6);
      o.knot_spacing_s = s.number("knot_spacing_s", o.knot_spacing_s, Range::kPositive, "s");
      o.position_m = s.vec3("position_m", o.position_m, Range::kAny, "m");
      o.q_w_b0 = read_rotation(s);
      o.position_std_m = s.vec3("position_std_m", o.position_std_m, Range::kNonNegative, "m");
      o.rotation_std_rad = s.number("rotation_std_deg", o.rotation_std_rad / kDegToRad, Range::kNonNegative, "deg") *
                           kDegToRad;
      o.seed = seed_for(s);
      std::string why;
      if (!o.Validate(&why)) s.fail("invalid random spline: " + why, "see datasets/README.md, trajectory");
      try {
        c_->trajectory = std::make_shared<SplineTrajectory>(SplineTrajectory::random(o));
      } catch (const std::invalid_argument& e) {
        s.fail(std::string("random spline rejected: ") + e.what(), "see datasets/README.md, trajectory");
      }
      set_span(0, duration);
    } else {
      read_file_trajectory(s, has_duration, duration);
    }
    c_->duration_s = ns_to_seconds(c_->simulator.t_end_ns - c_->simulator.t_begin_ns);
    root_.set("duration", YAML::Node(format_seconds(c_->simulator.t_end_ns - c_->simulator.t_begin_ns)));
  }

  void set_span(int64_t t_begin_ns, double duration_s) {
    c_->simulator.t_begin_ns = t_begin_ns;
    c_->simulator.t_end_ns = std::min<int64_t>(t_begin_ns + std::llround(duration_s * 1e9), c_->trajectory->t_end_ns());
  }

  void read_file_trajectory(Section& s, bool has_duration, double duration) {
    s.allow({"type", "path", "format", "start_s", "fit", "transform"});
    const std::string rel = s.string("path", "", {});
    const fs::path file = fs::path(rel).is_absolute() ? fs::path(rel) : fs::path(c_->base_dir) / rel;
    std::error_code ec;
    if (!fs::is_regular_file(file, ec)) {
      s.fail_at("path", "trajectory file '" + file.string() + "' does not exist",
                "path to a motion-capture csv (timestamp[ns], x, y, z, qx, qy, qz, qw) or a TUM file, relative to the "
                "YAML file");
    }
    c_->trajectory_file = fs::absolute(file).lexically_normal().string();
    std::string format = s.string("format", "auto", {"auto", "csv", "tum"});
    if (format == "auto") format = file.extension() == ".csv" ? "csv" : "tum";
    const Trajectory samples = format == "csv" ? read_euroc_csv(file.string()) : read_tum(file.string());
    if (samples.size() < 2) s.fail_at("path", "trajectory file has fewer than 2 poses", "a trajectory file");

    Section fit = s.child("fit", false, "fit: {order, knot_spacing_s, max_iterations, smoothing}");
    fit.allow({"order", "knot_spacing_s", "max_iterations", "smoothing"});
    SplineFitOptions fo;
    fo.order = fit.integer("order", fo.order, 4, 6);
    fo.knot_spacing_s = fit.number("knot_spacing_s", fo.knot_spacing_s, Range::kPositive, "s");
    fo.max_iterations = fit.integer("max_iterations", fo.max_iterations, 1, 1000);
    fo.smoothing = fit.number("smoothing", fo.smoothing, Range::kNonNegative, "");
    std::string why;
    if (!fo.Validate(&why)) fit.fail("invalid fit options: " + why, "see datasets/README.md, trajectory.fit");

    const int64_t start_ns = s.time_ns("start_s", 0, Range::kNonNegative);
    const int64_t t0 = samples.t_begin_ns() + start_ns;
    if (t0 >= samples.t_end_ns()) {
      s.fail_at("start_s", "starts after the file ends (" + format_seconds(samples.duration_ns()) + " s of poses)",
                "start_s: seconds after the first pose, before the last");
    }
    int64_t t1 = samples.t_end_ns();
    if (has_duration) {
      t1 = t0 + std::llround(duration * 1e9);
      if (t1 > samples.t_end_ns()) {
        root_.fail_at("duration",
                      "start_s + duration runs past the end of the trajectory file (" +
                          format_seconds(samples.t_end_ns() - t0) + " s available)",
                      "duration: s, at most the file's span after start_s");
      }
    }
    // Fit only the window plus a margin of a few knots on each side (exact derivatives inside).
    const calib::SE3 T_w_f = s.has("transform") ? read_transform(s, "transform") : calib::SE3();
    const int64_t margin = std::llround((fo.order + 2) * fo.knot_spacing_s * 1e9);
    std::vector<StampedPose> window;
    for (const StampedPose& sp : samples) {
      if (sp.t_ns < t0 - margin || sp.t_ns > t1 + margin) continue;
      window.push_back({sp.t_ns, T_w_f * sp.T_w_b});
    }
    // The span must lie inside the fitted range: clip to the samples kept.
    if (window.size() < 2 || window.front().t_ns > t0 || window.back().t_ns < t1) {
      s.fail("the trajectory file does not cover the simulated span", "poses covering [start_s, start_s + duration]");
    }
    SplineFitReport report;
    try {
      c_->trajectory = std::make_shared<SplineTrajectory>(
          SplineTrajectory::fit(Trajectory(std::move(window)), fo, &report));
    } catch (const std::invalid_argument& e) {
      s.fail(std::string("spline fit failed: ") + e.what(),
             "a denser trajectory file or a larger fit.knot_spacing_s");
    }
    c_->fit_report = report;
    s.set("path", YAML::Node(c_->trajectory_file));  // the resolved YAML names the file absolutely
    c_->simulator.t_begin_ns = t0;
    c_->simulator.t_end_ns = t1;
  }

  // ---- textures and scenes ----
  std::shared_ptr<const Texture> read_texture(const Section& parent, const std::string& key,
                                                   TextureWrap default_wrap_u) {
    const std::string expected =
        "texture: {procedural: checkerboard | shapes | noise | constant, size: [w, h], seed, ...} or {file: path}";
    Section s = parent.child(key, true, expected);
    last_procedural_.reset();
    const bool is_file = s.has("file");
    if (is_file == s.has("procedural")) s.fail("give exactly one of 'procedural' and 'file'", expected);
    TextureWrap wu = default_wrap_u, wv = TextureWrap::kClamp;
    if (s.has("wrap")) {
      const YAML::Node w = s.get("wrap");
      const std::string wexp = "wrap: [clamp | repeat, clamp | repeat] (u, v)";
      if (!w.IsSequence() || w.size() != 2 || !w[0].IsScalar() || !w[1].IsScalar()) {
        p_->fail(w, s.key_path("wrap"), "is not a list of 2 names", wexp);
      }
      auto mode = [&](const YAML::Node& n) {
        if (n.Scalar() == "clamp") return TextureWrap::kClamp;
        if (n.Scalar() == "repeat") return TextureWrap::kRepeat;
        p_->fail(n, s.key_path("wrap"), "unknown wrap mode '" + n.Scalar() + "'", wexp);
      };
      wu = mode(w[0]);
      wv = mode(w[1]);
    }
    if (is_file) {
      s.allow({"file", "min_intensity", "max_intensity", "wrap"});
      const std::string rel = s.string("file", "", {});
      const fs::path file = fs::path(rel).is_absolute() ? fs::path(rel) : fs::path(c_->base_dir) / rel;
      const double lo = s.number("min_intensity", 0.05, Range::kNonNegative, "intensity units");
      const double hi = s.number("max_intensity", 1.0, Range::kPositive, "intensity units");
      if (hi <= lo) s.fail_at("max_intensity", "must exceed min_intensity", "max_intensity > min_intensity");
      const std::string abs = fs::absolute(file).lexically_normal().string();
      try {
        auto texture = std::make_shared<Texture>(Texture::load(abs, lo, hi, wu, wv));
        s.set("file", YAML::Node(abs));  // the resolved YAML names the file absolutely
        return texture;
      } catch (const InputError& e) {
        s.fail_at("file", "cannot load texture '" + abs + "': " + e.problem(),
                  "an image file OpenCV reads (PNG, JPEG, ...), path relative to the YAML file; "
                  "scripts/fetch_textures.sh installs sample images into datasets/textures/");
      } catch (const std::exception& e) {
        s.fail_at("file", std::string("cannot load texture: ") + e.what(), "an image file OpenCV reads");
      }
    }
    s.allow({"procedural", "size", "cell_px", "num_shapes", "noise_scale_px", "octaves", "min_intensity",
             "max_intensity", "seed", "wrap"});
    ProceduralTextureOptions o;
    const std::string kind = s.string("procedural", "", {"checkerboard", "shapes", "noise", "constant"});
    procedural_kind_from_name(kind, &o.kind);
    if (s.has("size")) {
      const std::vector<double> sz = s.numbers("size", 2, Range::kPositive, "texels");
      if (sz[0] != std::floor(sz[0]) || sz[1] != std::floor(sz[1]) || sz[0] > 16384 || sz[1] > 16384) {
        s.fail_at("size", "is not two whole numbers up to 16384", "size: [width, height] in texels");
      }
      o.width = static_cast<int>(sz[0]);
      o.height = static_cast<int>(sz[1]);
    }
    o.cell_px = s.number("cell_px", o.cell_px, Range::kPositive, "texels");
    o.num_shapes = s.integer("num_shapes", o.num_shapes, 0, 100000);
    o.noise_scale_px = s.number("noise_scale_px", o.noise_scale_px, Range::kPositive, "texels");
    o.octaves = s.integer("octaves", o.octaves, 1, 16);
    o.min_intensity = s.number("min_intensity", o.min_intensity, Range::kNonNegative, "intensity units");
    o.max_intensity = s.number("max_intensity", o.max_intensity, Range::kPositive, "intensity units");
    o.seed = seed_for(s);
    std::string why;
    if (!o.Validate(&why)) s.fail("invalid procedural texture: " + why, expected);
    last_procedural_ = o;
    try {
      return std::make_shared<Texture>(make_procedural_texture(o, wu, wv));
    } catch (const std::invalid_argument& e) {
      s.fail(std::string("procedural texture rejected: ") + e.what(), expected);
    }
  }

  std::shared_ptr<const Scene> read_scene(Section s, bool top) {
    const std::vector<std::string> types =
        top ? std::vector<std::string>{"panorama", "planes", "sprites"} : std::vector<std::string>{"panorama", "planes"};
    const std::string type = s.string("type", "", types);
    if (top) c_->scene_type = type;
    try {
      if (type == "panorama") {
        s.allow({"type", "texture", "gain"});
        auto tex = read_texture(s, "texture", TextureWrap::kRepeat);
        c_->panorama = tex;
        return std::make_shared<PanoramaScene>(tex, s.number("gain", 1.0, Range::kPositive, "intensity factor"));
      }
      if (type == "planes") return read_planes(s);
      return read_sprites(s);
    } catch (const std::invalid_argument& e) {
      s.fail(std::string("scene rejected: ") + e.what(), "see datasets/README.md, scene");
    }
  }

  std::shared_ptr<const Scene> read_planes(Section& s) {
    s.allow({"type", "background_intensity", "planes", "boxes"});
    std::vector<TexturedPlane> planes;
    const std::string plane_expected = "planes: a list of {center_m, axis_u, axis_v, size_m, texture, gain}";
    for (Section& ps : list_of_maps(s, "planes", plane_expected)) {
      ps.allow({"center_m", "axis_u", "axis_v", "size_m", "texture", "gain"});
      TexturedPlane pl;
      pl.center_w = ps.vec3("center_m", pl.center_w, Range::kAny, "m, world frame");
      const Vector3d u = ps.vec3("axis_u", pl.axis_u_w, Range::kAny, "direction in the world frame");
      const Vector3d v = ps.vec3("axis_v", pl.axis_v_w, Range::kAny, "direction in the world frame");
      if (u.norm() < 1e-9 || v.norm() < 1e-9 || std::abs(u.normalized().dot(v.normalized())) > 1e-6) {
        ps.fail_at("axis_v", "axis_u and axis_v must be non-zero and orthogonal",
                   "two orthogonal directions (normalised on use)");
      }
      pl.axis_u_w = u.normalized();
      pl.axis_v_w = v.normalized();
      if (!ps.has("size_m")) ps.fail("missing key 'size_m'", "size_m: [width, height] in m");
      const Vector2d size = ps.vec2("size_m", Vector2d::Ones(), Range::kPositive, "m");
      pl.width_m = size.x();
      pl.height_m = size.y();
      pl.texture = read_texture(ps, "texture", TextureWrap::kClamp);
      pl.gain = ps.number("gain", 1.0, Range::kPositive, "intensity factor");
      if (last_procedural_ && last_procedural_->kind == ProceduralKind::kCheckerboard) add_board_corners(pl, *last_procedural_);
      planes.push_back(pl);
    }
    const std::string box_expected = "boxes: a list of {center_m, size_m: [sx, sy, sz], yaw_deg, texture, gain}";
    for (Section& bs : list_of_maps(s, "boxes", box_expected)) {
      bs.allow({"center_m", "size_m", "yaw_deg", "texture", "gain"});
      const Vector3d c = bs.vec3("center_m", Vector3d::Zero(), Range::kAny, "m, world frame");
      if (!bs.has("size_m")) bs.fail("missing key 'size_m'", "size_m: [sx, sy, sz] in m");
      const Vector3d sz = bs.vec3("size_m", Vector3d::Ones(), Range::kPositive, "m");
      const double yaw = bs.number("yaw_deg", 0.0, Range::kAny, "deg about world z") * kDegToRad;
      const auto tex = read_texture(bs, "texture", TextureWrap::kClamp);
      const double gain = bs.number("gain", 1.0, Range::kPositive, "intensity factor");
      const Eigen::Matrix3d R = Eigen::AngleAxisd(yaw, Vector3d::UnitZ()).toRotationMatrix();
      const Vector3d ex = R.col(0), ey = R.col(1), ez = R.col(2);
      // Six faces: (centre offset, axis_u, axis_v, width, height).
      const struct {
        Vector3d offset, u, v;
        double w, h;
      } faces[] = {
          {ex * sz.x() / 2, ey, ez, sz.y(), sz.z()},   {-ex * sz.x() / 2, -ey, ez, sz.y(), sz.z()},
          {ey * sz.y() / 2, -ex, ez, sz.x(), sz.z()},  {-ey * sz.y() / 2, ex, ez, sz.x(), sz.z()},
          {ez * sz.z() / 2, ex, ey, sz.x(), sz.y()},   {-ez * sz.z() / 2, ex, -ey, sz.x(), sz.y()},
      };
      for (const auto& f : faces) {
        TexturedPlane pl;
        pl.center_w = c + f.offset;
        pl.axis_u_w = f.u;
        pl.axis_v_w = f.v;
        pl.width_m = f.w;
        pl.height_m = f.h;
        pl.texture = tex;
        pl.gain = gain;
        planes.push_back(pl);
      }
    }
    if (planes.empty()) s.fail("a planes scene needs at least one entry in planes or boxes", plane_expected);
    const double bg = s.number("background_intensity", 0.1, Range::kNonNegative, "intensity units");
    return std::make_shared<PlanarScene>(std::move(planes), bg);
  }

  std::shared_ptr<const Scene> read_sprites(Section& s) {
    s.allow({"type", "background", "sprites"});
    auto background =
        read_scene(s.child("background", true, "background: a panorama or planes scene"), false);
    std::vector<Sprite> sprites;
    const std::string expected = "sprites: a list of {texture, shape, size_px, gain, motion}";
    for (Section& ss : list_of_maps(s, "sprites", expected)) {
      ss.allow({"texture", "shape", "size_px", "gain", "motion"});
      Sprite sp;
      sp.texture = read_texture(ss, "texture", TextureWrap::kClamp);
      sp.shape = ss.string("shape", "rectangle", {"rectangle", "ellipse"}) == "ellipse" ? SpriteShape::kEllipse
                                                                                        : SpriteShape::kRectangle;
      const Vector2d size = ss.vec2("size_px", Vector2d(sp.width_px, sp.height_px), Range::kPositive, "px");
      sp.width_px = size.x();
      sp.height_px = size.y();
      sp.gain = ss.number("gain", 1.0, Range::kPositive, "intensity factor");
      Section m = ss.child("motion", false, "motion: {centre_px, velocity_pxps, ...}");
      m.allow({"centre_px", "velocity_pxps", "amplitude_px", "frequency_hz", "phase_deg", "angle_deg",
               "angular_rate_dps", "scale", "scale_rate_per_s"});
      SpriteMotion& mo = sp.motion;
      mo.centre_px = m.vec2("centre_px", mo.centre_px, Range::kAny, "px");
      mo.velocity_pxps = m.vec2("velocity_pxps", mo.velocity_pxps, Range::kAny, "px/s");
      mo.amplitude_px = m.vec2("amplitude_px", mo.amplitude_px, Range::kAny, "px");
      mo.frequency_hz = m.vec2("frequency_hz", mo.frequency_hz, Range::kNonNegative, "Hz");
      mo.phase_rad = m.vec2("phase_deg", Vector2d::Zero(), Range::kAny, "deg") * kDegToRad;
      mo.angle_rad = m.number("angle_deg", 0.0, Range::kAny, "deg") * kDegToRad;
      mo.angular_rate_radps = m.number("angular_rate_dps", 0.0, Range::kAny, "deg/s") * kDegToRad;
      mo.scale = m.number("scale", 1.0, Range::kPositive, "");
      mo.scale_rate_per_s = m.number("scale_rate_per_s", 0.0, Range::kAny, "1/s");
      sprites.push_back(sp);
    }
    if (sprites.empty()) s.fail("a sprites scene needs at least one sprite", expected);
    return std::make_shared<SpriteScene>(background, std::move(sprites), c_->simulator.t_begin_ns);
  }

  // [[t_s, v], ...] pairs, t_s seconds since the start (sorted, increasing); v checked by range r.
  std::vector<std::pair<int64_t, double>> timed_pairs(const Section& s, const std::string& key, Range r, const std::string& expected) {
    std::vector<std::pair<int64_t, double>> out;
    const YAML::Node n = s.get(key);
    if (!n.IsSequence()) p_->fail(n, s.key_path(key), "is not a list", expected);
    for (size_t i = 0; i < n.size(); ++i) {
      const std::string kp = s.key_path(key) + "." + std::to_string(i);
      if (!n[i].IsSequence() || n[i].size() != 2) p_->fail(n[i], kp, "is not a pair", expected);
      out.emplace_back(c_->simulator.t_begin_ns + s.time_ns_of(n[i][0], kp + ".0", Range::kNonNegative), s.number_of(n[i][1], kp + ".1", r, ""));
    }
    return out;
  }

  void read_illumination() {
    if (!root_.has("illumination")) return;
    const std::string expected = "illumination: [[t_s, gain], ...] with t_s seconds since the start, increasing, gain > 0";
    c_->simulator.illumination = timed_pairs(root_, "illumination", Range::kPositive, expected);
    for (size_t i = 1; i < c_->simulator.illumination.size(); ++i) {
      if (c_->simulator.illumination[i].first <= c_->simulator.illumination[i - 1].first) {
        p_->fail(root_.get("illumination")[i], "illumination." + std::to_string(i), "is not after the previous knot", expected);
      }
    }
  }

  // ---- sensors ----
  void read_imu(Section s) {
    s.allow({"enable", "rate_hz", "accelerometer_noise_density", "accelerometer_random_walk",
             "gyroscope_noise_density", "gyroscope_random_walk", "enable_noise", "gravity_mps2",
             "initial_bias_gyro_radps", "initial_bias_accel_mps2", "gaps_s", "seed"});
    ImuSimOptions& o = c_->imu;
    c_->imu_enabled = s.boolean("enable", true);
    o.rate_hz = s.number("rate_hz", 1000.0, Range::kPositive, "Hz");
    // Defaults: a MEMS IMU like the DAVIS's InvenSense MPU-6150 (datasheet densities, inflated 2x
    // for the gyro, random walks as typically used with Kalibr for such parts).
    o.noise.accelerometer_noise_density = s.number("accelerometer_noise_density", 4.0e-3, Range::kPositive, "m/s^2/sqrt(Hz)");
    o.noise.accelerometer_random_walk = s.number("accelerometer_random_walk", 4.0e-4, Range::kNonNegative, "m/s^3/sqrt(Hz)");
    o.noise.gyroscope_noise_density = s.number("gyroscope_noise_density", 1.7e-4, Range::kPositive, "rad/s/sqrt(Hz)");
    o.noise.gyroscope_random_walk = s.number("gyroscope_random_walk", 2.0e-5, Range::kNonNegative, "rad/s^2/sqrt(Hz)");
    o.noise.update_rate_hz = o.rate_hz;
    o.noise.source = p_->file();
    o.enable_noise = s.boolean("enable_noise", true);
    o.gravity_w = s.vec3("gravity_mps2", o.gravity_w, Range::kAny, "m/s^2, world frame");
    o.initial_bias_gyro_radps = s.vec3("initial_bias_gyro_radps", o.initial_bias_gyro_radps, Range::kAny, "rad/s");
    o.initial_bias_accel_mps2 = s.vec3("initial_bias_accel_mps2", o.initial_bias_accel_mps2, Range::kAny, "m/s^2");
    o.seed = seed_for(s);
    if (s.has("gaps_s")) {
      const std::string expected = "gaps_s: [[start_s, end_s], ...] seconds since the start, end after start";
      for (const auto& [b, e] : timed_pairs(s, "gaps_s", Range::kNonNegative, expected)) {
        const int64_t end = c_->simulator.t_begin_ns + std::llround(e * 1e9);
        if (end <= b) s.fail_at("gaps_s", "has a gap that does not end after it starts", expected);
        o.gaps_ns.emplace_back(b, end);
      }
    }
    std::string why;
    if (!o.Validate(&why)) s.fail("invalid IMU options: " + why, "see datasets/README.md, imu");
  }

  void read_events(Section s) {
    s.allow({"contrast_threshold_pos", "contrast_threshold_neg", "threshold_mismatch_std", "threshold_min", "log_eps",
             "refractory_s", "shot_noise_rate_hz", "leak_rate_hz", "hot_pixel_fraction", "hot_pixel_rate_hz",
             "timestamp_jitter_s", "seed"});
    EventSimOptions& o = c_->simulator.events;
    o.contrast_threshold_pos = s.number("contrast_threshold_pos", o.contrast_threshold_pos, Range::kPositive, "log intensity");
    o.contrast_threshold_neg = s.number("contrast_threshold_neg", o.contrast_threshold_neg, Range::kPositive, "log intensity");
    o.threshold_mismatch_std = s.number("threshold_mismatch_std", o.threshold_mismatch_std, Range::kNonNegative, "log intensity");
    o.threshold_min = s.number("threshold_min", o.threshold_min, Range::kPositive, "log intensity");
    o.log_eps = s.number("log_eps", o.log_eps, Range::kPositive, "intensity units");
    o.refractory_ns = s.time_ns("refractory_s", o.refractory_ns, Range::kNonNegative);
    o.shot_noise_rate_hz = s.number("shot_noise_rate_hz", o.shot_noise_rate_hz, Range::kNonNegative, "Hz per pixel");
    o.leak_rate_hz = s.number("leak_rate_hz", o.leak_rate_hz, Range::kNonNegative, "Hz per pixel");
    o.hot_pixel_fraction = s.number("hot_pixel_fraction", o.hot_pixel_fraction, Range::kUnit, "fraction of pixels");
    o.hot_pixel_rate_hz = s.number("hot_pixel_rate_hz", o.hot_pixel_rate_hz, Range::kNonNegative, "Hz");
    o.timestamp_jitter_ns = s.number("timestamp_jitter_s", o.timestamp_jitter_ns * 1e-9, Range::kNonNegative, "s") * 1e9;
    o.seed = seed_for(s);
    std::string why;
    if (!o.Validate(&why)) s.fail("invalid event options: " + why, "see datasets/README.md, events");
  }

  void read_stepping(Section s) {
    s.allow({"max_flow_px", "max_log_change", "min_step_s", "max_step_s"});
    SteppingOptions& o = c_->simulator.stepping;
    o.max_flow_px = s.number("max_flow_px", o.max_flow_px, Range::kNonNegative, "px per step");
    o.max_log_change = s.number("max_log_change", o.max_log_change, Range::kNonNegative, "log intensity per step");
    o.min_step_ns = s.time_ns("min_step_s", o.min_step_ns, Range::kPositive);
    o.max_step_ns = s.time_ns("max_step_s", o.max_step_ns, Range::kPositive);
    std::string why;
    if (!o.Validate(&why)) s.fail("invalid stepping options: " + why, "see datasets/README.md, stepping");
  }

  void read_frames(Section s) {
    s.allow({"rate_hz", "exposure_s", "exposure_samples", "gain", "gamma", "read_noise_std", "seed"});
    ApsOptions& o = c_->simulator.frames;
    o.rate_hz = s.number("rate_hz", 0.0, Range::kNonNegative, "Hz, 0 = no frames");
    o.exposure_s = s.number("exposure_s", o.exposure_s, Range::kPositive, "s");
    o.exposure_samples = s.integer("exposure_samples", o.exposure_samples, 1, 1000);
    o.gain = s.number("gain", o.gain, Range::kPositive, "intensity -> [0, 1]");
    o.gamma = s.number("gamma", o.gamma, Range::kPositive, "");
    o.read_noise_std = s.number("read_noise_std", o.read_noise_std, Range::kNonNegative, "grey levels");
    o.seed = seed_for(s);
    std::string why;
    if (!o.Validate(&why)) s.fail("invalid frame options: " + why, "see datasets/README.md, frames");
  }

  void read_ground_truth(Section s) {
    s.allow({"pose_rate_hz", "period_s", "times_s", "depth", "flow", "intensity", "labels", "event_labels"});
    GroundTruthConfig& g = c_->ground_truth;
    g.pose_rate_hz = s.number("pose_rate_hz", g.pose_rate_hz, Range::kPositive, "Hz");
    g.depth = s.boolean("depth", true);
    g.flow = s.boolean("flow", true);
    g.intensity = s.boolean("intensity", true);
    g.labels = s.boolean("labels", true);
    g.event_labels = s.boolean("event_labels", c_->scene_type == "sprites");
    const int64_t t0 = c_->simulator.t_begin_ns, t1 = c_->simulator.t_end_ns;
    std::vector<int64_t> times;
    const int64_t period = s.time_ns("period_s", 0, Range::kNonNegative);
    if (period > 0) {
      if ((t1 - t0) / period > 100000) s.fail_at("period_s", "gives more than 100000 maps", "a longer period_s");
      for (int64_t t = t0; t <= t1; t += period) times.push_back(t);
    }
    if (s.has("times_s")) {
      const YAML::Node n = s.get("times_s");
      if (!n.IsSequence()) p_->fail(n, s.key_path("times_s"), "is not a list", "times_s: [s, ...] since the start");
      for (size_t i = 0; i < n.size(); ++i) {
        const std::string kp = s.key_path("times_s") + "." + std::to_string(i);
        const int64_t t = t0 + s.time_ns_of(n[i], kp, Range::kNonNegative);
        if (t > t1) p_->fail(n[i], kp, "is after the end of the simulation", "seconds in [0, duration]");
        times.push_back(t);
      }
    }
    std::sort(times.begin(), times.end());
    times.erase(std::unique(times.begin(), times.end()), times.end());
    g.times_ns = times;
    if (g.depth || g.flow || g.intensity || g.labels) c_->simulator.ground_truth_times_ns = times;
  }

  // The grid nodes of a checkerboard texture on a plane (SimulationConfig::corners): texel
  // coordinates u = i cell_px (and the texture's edge) map to a = u / W width_m - width_m / 2 along
  // axis_u, b = height_m / 2 - v / H height_m along axis_v (scene.h).
  void add_board_corners(const TexturedPlane& pl, const ProceduralTextureOptions& o) {
    auto nodes = [&o](int size) {
      std::vector<double> n;
      for (int k = 0; k * o.cell_px < size; ++k) n.push_back(k * o.cell_px);
      n.push_back(size);
      return n;
    };
    for (double v : nodes(o.height))
      for (double u : nodes(o.width)) {
        SceneCorner c;
        const double a = u / o.width * pl.width_m - 0.5 * pl.width_m, b = 0.5 * pl.height_m - v / o.height * pl.height_m;
        c.p_w = pl.center_w + a * pl.axis_u_w + b * pl.axis_v_w;
        c.inner = u > 0 && u < o.width && v > 0 && v < o.height;
        c_->corners.push_back(c);
      }
  }

  const Parser* p_;
  Section root_;
  SimulationConfig* c_;
  std::optional<ProceduralTextureOptions> last_procedural_;  // of the last texture read_texture read
};

}  // namespace


std::vector<std::string> camera_preset_names() { return {"davis240c", "davis346", "prophesee", "prophesee_hd"}; }

calib::CameraIntrinsics camera_preset(const std::string& name) {
  calib::CameraIntrinsics k;
  if (name == "davis240c") {
    // The Event Camera Dataset's DAVIS240C calibration (calib.txt of shapes_*, poster_*, boxes_*,
    // dynamic_*): pinhole radtan.
    k.width = 240;
    k.height = 180;
    k.fx = 199.092366542;
    k.fy = 198.82882047;
    k.cx = 132.192071378;
    k.cy = 110.712660011;
    k.model = calib::DistortionModel::kRadtan;
    k.distortion = {-0.368436311798, 0.150947243557, -0.000296130534385, -0.000759431726241, 0.0};
  } else if (name == "davis346") {
    // DAVIS346 (18.5 um pixels) with a ~4.2 mm lens, no distortion.
    k.width = 346;
    k.height = 260;
    k.fx = k.fy = 226.0;
    k.cx = 172.5;
    k.cy = 129.5;
  } else if (name == "prophesee") {
    // Prophesee Gen3 VGA (640x480, 15 um pixels) with an 8 mm lens, no distortion.
    k.width = 640;
    k.height = 480;
    k.fx = k.fy = 533.0;
    k.cx = 319.5;
    k.cy = 239.5;
  } else if (name == "prophesee_hd") {
    // Prophesee Gen4 / Sony IMX636 (1280x720, 4.86 um pixels) with a 5 mm lens, no distortion.
    k.width = 1280;
    k.height = 720;
    k.fx = k.fy = 1029.0;
    k.cx = 639.5;
    k.cy = 359.5;
  } else {
    throw std::invalid_argument("unknown camera preset '" + name + "'");
  }
  return k;
}

SimulationConfig parse_simulation_config(const std::string& yaml_text, const std::string& path,
                                         const SimulateOverrides& overrides) {
  const std::string expected = "a scene YAML (see datasets/README.md)";
  YAML::Node root;
  try {
    root = YAML::Load(yaml_text);
  } catch (const YAML::Exception& e) {
    throw InputError(path, static_cast<int64_t>(e.mark.line) + 1, "YAML syntax error: " + e.msg, expected);
  }
  if (root.IsNull()) root = YAML::Node(YAML::NodeType::Map);
  if (!root.IsMap()) throw InputError(path, 1, "top level is not a map", expected);

  std::vector<Override> applied = apply_set_overrides(root, overrides.set);
  if (overrides.seed) {
    root["seed"] = YAML::Node(*overrides.seed);  // a new node: no file mark (errors name --seed)
    applied.push_back({"seed", "--seed " + std::to_string(*overrides.seed)});
  }
  if (overrides.duration_s) {
    std::ostringstream d;
    d.precision(17);
    d << *overrides.duration_s;
    root["duration"] = YAML::Node(d.str());
    applied.push_back({"duration", "--duration " + d.str()});
  }

  SimulationConfig config;
  config.path = path;
  config.base_dir = fs::absolute(fs::path(path)).parent_path().string();
  const Parser parser(path, applied);
  try {
    ConfigBuilder(&parser, root, &config).build();
  } catch (const YAML::Exception& e) {
    throw InputError(path, static_cast<int64_t>(e.mark.line) + 1, "YAML error: " + e.msg, expected);
  }
  YAML::Emitter emitter;
  emitter << root;
  config.resolved_yaml = std::string(emitter.c_str()) + "\n";
  return config;
}

SimulationConfig load_simulation_config(const std::string& path, const SimulateOverrides& overrides) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, 0, "cannot open the scene file", "a readable scene YAML (see datasets/README.md)");
  std::stringstream text;
  text << in.rdbuf();
  return parse_simulation_config(text.str(), path, overrides);
}

}  // namespace evio::simulator
