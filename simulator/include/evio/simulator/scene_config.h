// The scene YAML of `evio simulate` (schema in datasets/README.md): parsed into the simulator's
// library objects (scene with textures, continuous trajectory, camera, IMU,
// event, stepping, frame and ground-truth options). Every error is an evio::InputError naming the
// YAML file, the 1-based line and the expected form; unknown keys are errors. `--set key=value`
// overrides edit the YAML tree before parsing; one top-level seed derives every component seed.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "evio/calib/calibration_io.h"
#include "evio/calib/camera.h"
#include "evio/simulator/imu.h"
#include "evio/simulator/scene.h"
#include "evio/simulator/texture.h"
#include "evio/simulator/trajectory.h"
#include "evio/simulator/simulator.h"

namespace evio::simulator {

// Command-line changes applied to the YAML before parsing.
struct SimulateOverrides {
  std::optional<uint64_t> seed;        // replaces the top-level `seed`
  std::optional<double> duration_s;    // replaces the top-level `duration`, s
  std::vector<std::string> set;        // "dotted.key=value" (value in YAML syntax; list index: key.0)
};

// Ground-truth extras written next to the ECD files.
struct GroundTruthConfig {
  double pose_rate_hz = 200.0;      // groundtruth.txt and velocities.txt, Hz (> 0)
  std::vector<int64_t> times_ns;    // body-clock times of depth/flow/intensity/label maps, sorted
  bool depth = true;                // depth/depth_NNNNNN.npy (float32, m, inf = no hit)
  bool flow = true;                 // flow/flow_NNNNNN.npy (float32 H x W x 2, px/s)
  bool intensity = true;            // intensity/intensity_NNNNNN.npy (float32 linear)
  bool labels = true;               // labels/labels_NNNNNN.png (16-bit object ids)
  bool event_labels = false;        // event_labels.txt (default: on for sprite scenes)
};

// A true corner of the scene: a grid node of a checkerboard texture on a plane (scene type
// planes; boxes, sprites and image textures give none). Inner nodes are X-junctions; nodes on the
// texture's outline are T- or L-junctions against whatever lies behind. Occlusion by other planes
// is not modelled.
struct SceneCorner {
  Eigen::Vector3d p_w = Eigen::Vector3d::Zero();  // world frame, m
  bool inner = false;
};

struct SimulationConfig {
  std::string path;        // the YAML file
  std::string base_dir;    // its folder (relative paths in the YAML are relative to it)
  std::string description; // free text from the YAML (`description`)
  uint64_t seed = 1;       // top-level seed
  double duration_s = 0;   // simulated span, s

  std::string scene_type;                         // "panorama", "planes" or "sprites"
  std::shared_ptr<const Scene> scene;
  std::shared_ptr<const Texture> panorama;   // panorama texture (also under a sprite scene)

  std::string trajectory_type;                    // "sinusoid", "random_spline" or "file"
  std::shared_ptr<const ContinuousTrajectory> trajectory;
  std::string trajectory_file;                    // file trajectories: absolute path
  std::optional<SplineFitReport> fit_report;  // file trajectories: residuals of the fit

  std::string camera_preset;                      // "" when given explicitly
  calib::CameraCalibration camera;                // cam0: intrinsics, T_c_b, time shift (for calib.yaml)
  SimulatorOptions simulator;                // camera, extrinsics, span, stepping, events, frames, GT times

  bool imu_enabled = true;
  ImuSimOptions imu;                         // imu.noise.update_rate_hz == imu.rate_hz

  std::vector<SceneCorner> corners;  // true corners (checkerboard planes), row by row per plane

  GroundTruthConfig ground_truth;
  bool write_h5 = true;                           // events.h5
  bool write_panorama = true;                     // panorama.npy/.png for panorama backgrounds
  int64_t clock_offset_ns = 0;  // output.clock_offset_ns: added to every written time stamp (events, frames,
                                // IMU, poses, maps), ns >= 0; 1.7e18 puts them at Unix time ~2023

  std::string resolved_yaml;  // the tree after overrides, with seeds, duration and paths resolved
};

// Loads and parses the scene YAML. Throws evio::InputError (file, line, expected form) on any
// problem: syntax, unknown keys, wrong types or sizes, invalid values, missing texture or
// trajectory files, or objects the library rejects.
SimulationConfig load_simulation_config(const std::string& path, const SimulateOverrides& overrides = {});

// The same from YAML text; `path` names the text in errors and anchors relative paths.
SimulationConfig parse_simulation_config(const std::string& yaml_text, const std::string& path,
                                         const SimulateOverrides& overrides = {});

// Component seeds: yaml_config::derive_seed (evio/sensors/yaml_config.h).

// Camera presets: "davis240c", "davis346", "prophesee" (Gen3 VGA) and "prophesee_hd" (Gen4 HD).
std::vector<std::string> camera_preset_names();
// Throws std::invalid_argument for an unknown name.
calib::CameraIntrinsics camera_preset(const std::string& name);

}  // namespace evio::simulator
