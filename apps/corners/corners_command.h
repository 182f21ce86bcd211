// `evio corners DATASET --out DIR`: the event-feature front-end (pipeline::CornerPipeline) on a
// recording: undistortion lookup, optional refractory and background-activity filters, eFAST
// corner events (optionally on the filtered SAE), corner tracks; writes corners.txt, tracks.txt, stats.json, optional PNG
// overlays, and prints a summary (reduction rate, corners per second, tracks and their lengths).
// On a simulated dataset whose scene has checkerboard planes (--gt SCENE.yaml, or
// DATASET/scene_resolved.yaml), also eval.json: corner events against the true corners
// (evaluation/corner_evaluation.h: precision, chance, event and (corner, bin) recall, F).
#pragma once

#include <iosfwd>
#include <string>
#include <vector>

#include "evio/pipeline/corner_pipeline.h"
#include "evio/sensors/dataset.h"

namespace evio::apps {

// Everything `--config FILE` can set (docs/commands/corners.md; `evio corners --print-config`):
// the front-end chain's options (pipeline::CornerPipelineOptions: refractory, background_activity,
// efast, tracker, dart) plus the PNG overlays.
struct CornersConfig : pipeline::CornerPipelineOptions {
  int64_t frames_every_ns = 0;                    // frames.every_ms: overlay period (0: none)
  int64_t frame_window_ns = 10'000'000;           // frames.window_ms: events shown per overlay
  int frame_scale = 2;                            // frames.scale: pixel magnification of overlays
  int64_t frame_track_history_ns = 100'000'000;   // frames.track_history_ms: track tail drawn
};

// Reads a corners config YAML (path empty: none) with `--set key.sub=value` overrides over the
// defaults (unknown keys are errors, with file:line or the --set option). Throws evio::InputError.
CornersConfig load_corners_config(const std::string& path, const std::vector<std::string>& sets = {});
// The resolved config (every key, value, unit and range), written to corners_config.yaml and
// readable by load_corners_config.
std::string corners_config_text(const CornersConfig& c);

struct CornersArgs {
  std::string dataset;
  DatasetOptions dataset_options;
  std::string calib;          // optional calibration (Kalibr camchain YAML or ECD calib.txt)
  std::string config;         // optional YAML; flags below override it
  std::vector<std::string> set;  // --set key.sub=value overrides of the config, in order
  std::string out;            // output folder (created)
  bool filter_sae = false;    // --filter-sae
  int64_t frames_every_ns = -1;  // --frames-every-ms (>= 0 overrides the config)
  std::string gt;             // --gt SCENE.yaml (empty: DATASET/scene_resolved.yaml when present)
  bool no_gt = false;         // --no-gt
  bool progress = true;
};

// Returns the exit code. Throws evio::InputError on bad input.
int run_corners(const CornersArgs& args, std::ostream& out);

}  // namespace evio::apps
