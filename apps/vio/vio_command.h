// `evio vio DATASET --out DIR`: event-based visual-inertial odometry on a recording through
// pipeline::VioPipeline (events undistorted and filtered, turned into feature observations by a
// front-end: eFAST corner tracks sampled at a fixed rate, or motion-compensated event frames with
// FAST/KLT/RANSAC; initialised without ground truth by a static start or visual-inertial
// alignment; estimated by the sliding-window back-end). This command parses the config, reads the
// dataset into the pipeline and writes trajectory.tum, keyframes.txt, map.ply, observations.txt,
// stats.json, the resolved config and, with --gt, eval.json in the `evio eval` schema.
#pragma once

#include <iosfwd>
#include <string>
#include <vector>

#include "evio/calib/calibration_io.h"
#include "evio/pipeline/vio_pipeline.h"
#include "evio/sensors/dataset.h"

namespace evio::apps {

// Everything `--config FILE` sets (docs/commands/vio.md and datasets/vio/*.yaml): the
// pipeline's options (sections frontend, filters, frames, tracker, efast, corner_tracker, window,
// init) plus the IMU noise used when neither --calib nor the dataset's calib.yaml has imu0.
// init.method `groundtruth` is the pipeline's `given` method with the state from --gt (a
// diagnostic: pose and velocity at the first frame, to judge front-end and back-end alone).
struct VioConfig : pipeline::VioPipelineOptions {
  // imu.{...}: Kalibr densities of the simulator's default (an MPU-6150-class DAVIS IMU).
  calib::ImuNoise imu_noise = [] {
    calib::ImuNoise n;
    n.accelerometer_noise_density = 0.004;  // m/s^2/sqrt(Hz)
    n.accelerometer_random_walk = 0.0004;   // m/s^3/sqrt(Hz)
    n.gyroscope_noise_density = 0.00017;    // rad/s/sqrt(Hz)
    n.gyroscope_random_walk = 2e-5;         // rad/s^2/sqrt(Hz)
    n.update_rate_hz = 1000;                // Hz
    return n;
  }();
};

VioConfig default_vio_config();
// Reads a VIO config YAML (path empty: none) with `--set key.sub=value` overrides over the
// defaults; resolved_yaml receives vio_config_text of the result. Throws evio::InputError
// (file:line or the --set option, key, expected form).
VioConfig load_vio_config(const std::string& path, std::string* resolved_yaml = nullptr,
                          const std::vector<std::string>& sets = {});
// The resolved config: every key with its value and a comment giving its unit and range;
// load_vio_config reads it back to the same config.
std::string vio_config_text(const VioConfig& c);

struct VioArgs {
  std::string dataset;
  DatasetOptions dataset_options;
  std::string config;   // optional YAML
  std::vector<std::string> set;  // --set key.sub=value overrides of the config, in order
  std::string calib;    // optional Kalibr camchain (+ imu0) or ECD calib.txt
  std::string gt;       // optional ground truth (TUM or csv) -> eval.json
  // The evaluation's alignment: true, the first pose's (a camera turning in place); false, SE3
  // fitted on the first 5 s.
  bool gt_align_first_pose = false;
  std::string out;
  bool progress = true;
  // Error budget (evaluation::TrackOracle): the estimator sees the true projections of the
  // front-end's tracks (landmarks from the simulator scene YAML of the sequence and --gt), with
  // optional white noise (px) and random-walk drift (px per frame).
  std::string oracle_scene;
  double oracle_noise_px = 0;
  double oracle_drift_px = 0;
  double oracle_max_error_px = 0;       // drop observations whose own error is larger (0: keep all)
  std::string oracle_error = "none";    // none | real | independent | common_mode (evaluation::OracleError)
  bool oracle_frame_motion = false;     // the frames' translation compensation from the ground truth
  bool oracle_frame_plane = false;      // with oracle_frame_motion: per-event depth from the plane through the tracks' true points
  bool oracle_observations = false;     // with oracle_error != none: OUT/oracle_observations.csv
  // Diagnostics: every n-th tracking image of the frames front-end as PNG into out/tracking_images/
  // (0: none), with the frame's tracks drawn.
  int dump_tracking_images = 0;
};

int run_vio(const VioArgs& args, std::ostream& out);

}  // namespace evio::apps
