// `evio flow DATASET --out DIR --model flow|rotation|similarity|6dof`: one motion per event window
// by contrast maximisation (pipeline::CmaxMotionPipeline: windows of N events or of a duration,
// each warped to its middle time, warm-started from the previous window). Writes motion.csv (one
// row per window), stats.json, flow_config.yaml (the resolved config), optional IWE PNGs before
// and after warping, and for the rotation model with a ground truth (--gt or the dataset's own)
// motion_eval.csv: the ground truth's angular velocity per window in the camera frame, the error,
// and the gyro's when the dataset has IMU (evaluation/angular_velocity_windows.h).
//
// motion.csv: `t_start_s,t_end_s,model,p0,...,p{n-1},contrast_zero,contrast_final,iterations,time_ms`
// with p0.. the model's parameters (mapping::warp_parameter_names):
//   flow        p0 p1 = vx vy, px/s (undistorted pixels; an event at t moves to x - (t - t_ref) v)
//   similarity  p0 p1 = vx vy px/s, p2 = dilation 1/s, p3 = in-plane rotation rad/s (about cx, cy)
//   rotation    p0 p1 p2 = wx wy wz, rad/s: the camera's angular velocity in the camera frame
//   6dof        p0 p1 p2 = vx vy vz m/s (camera velocity, camera frame, at cmax.depth_m or the
//               plane), p3 p4 p5 = wx wy wz rad/s
// contrast_* are the objective (cmax.objective resolved) at zero motion and at the estimate.
// With --model auto (model_selection): the model is chosen per window (mapping::choose_warp_model,
// as `evio segment` per cluster); motion.csv has the richest candidate's columns (a window's own
// parameters first, the rest empty) and model_selection.csv each candidate's objective, gain and
// score per window; stats.json's "model" block counts the windows each candidate won.
#pragma once

#include <cstdint>
#include <iosfwd>
#include <optional>
#include <string>
#include <vector>

#include "evio/pipeline/cmax_motion_pipeline.h"
#include "evio/sensors/dataset.h"

namespace evio::apps {

// Everything `--config FILE` sets (YAML sections window, cmax and the key undistortion; docs/commands/flow.md,
// `evio flow --print-config`): the pipeline's options. cmax.width/height/fx/fy/cx/cy come from
// the camera calibration and are not config keys.
struct FlowConfig : pipeline::CmaxMotionPipelineOptions {
  // Model selection per window (`--model auto`): the pipeline's `models` are these candidates,
  // without the 3-D warps (rotation, 6dof) when the camera is not calibrated. Off: cmax.model.
  bool model_selection = false;
  std::vector<mapping::WarpModel> candidates = {mapping::WarpModel::kFlow, mapping::WarpModel::kSimilarity,
                                                mapping::WarpModel::kRotation};
};

// Reads a flow config YAML (path empty: none) with `--set key.sub=value` overrides over the
// defaults. Throws evio::InputError (file:line or the --set option, key, expected form).
FlowConfig load_flow_config(const std::string& path, const std::vector<std::string>& sets = {});
// The resolved config (every key, value, unit and range), readable by load_flow_config.
std::string flow_config_text(const FlowConfig& c);

struct FlowArgs {
  std::string dataset;
  DatasetOptions dataset_options;
  std::string config;              // optional YAML
  std::vector<std::string> set;    // --set key.sub=value overrides, in order
  std::string calib;               // optional Kalibr camchain or ECD calib.txt
  std::string gt;                  // optional ground truth (TUM or csv); default: the dataset's own
  std::string out;                 // output folder (created)
  std::string model;               // --model: overrides cmax.model (model_selection off) when not empty; "auto": model_selection on
  std::string objective;           // --objective: overrides cmax.objective when not empty
  int64_t window_events = 0;       // --window-events (> 0 overrides window.events and clears window.ms)
  int64_t window_ns = 0;           // --window-ms (> 0 overrides window.ms)
  int pyramid_levels = 0;          // --pyramid-levels (> 0 overrides cmax.pyramid_levels)
  std::optional<int64_t> t_start_ns, t_end_ns;  // events with t_start <= t < t_end (absolute file time)
  bool png = false;                // IWE PNGs before/after warping into DIR/iwe/
  int png_every = 1;               // every this many windows
  bool progress = true;
};

// The config file and --set overrides with the flags (--model, --objective, --window-events,
// --window-ms, --pyramid-levels) applied, validated. Throws evio::InputError.
FlowConfig resolve_flow_config(const FlowArgs& args);

// Returns the exit code. Throws evio::InputError on bad input.
int run_flow(const FlowArgs& args, std::ostream& out);

}  // namespace evio::apps
