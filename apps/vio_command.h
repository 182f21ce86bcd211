// `evio vio DATASET --out DIR`: event-based visual-inertial odometry on a recording. Events are
// undistorted and filtered, turned into feature observations by a front-end (eFAST corner tracks
// sampled at a fixed rate, or motion-compensated event frames with FAST/KLT/RANSAC), initialised
// without ground truth (static start or visual-inertial alignment), and estimated by the
// sliding-window back-end. Writes trajectory.tum, keyframes.txt, map.ply, stats.json, the resolved
// config and, with --gt, eval.json in the `evio eval` schema.
#pragma once

#include <iosfwd>
#include <string>

#include "evio/backend/initialization.h"
#include "evio/backend/sliding_window_estimator.h"
#include "evio/frontend/corner_tracker.h"
#include "evio/frontend/efast.h"
#include "evio/frontend/event_frame.h"
#include "evio/frontend/feature_tracker.h"
#include "evio/frontend/event_filters.h"
#include "evio/sensors/dataset.h"

namespace evio::apps {

// Everything `--config FILE` sets (YAML schema in README.md and datasets/vio/*.yaml).
struct VioConfig {
  std::string frontend = "frames";               // frontend: frames (event frames + FAST/KLT/RANSAC) | corners (eFAST tracks)
  // frames front-end
  frontend::EventFrameOptions frames;            // frames.{events_per_frame, max_window_ms, min_events, motion_compensation, clip_percentile}
  frontend::FeatureTrackerOptions tracker;       // tracker.{grid_cols, grid_rows, max_features, max_per_cell, fast_threshold, ...}
  // corners front-end
  frontend::EfastOptions efast;                  // efast.{filter_sae, filter_window_ms}
  frontend::CornerTrackerOptions corner_tracker; // corner_tracker.{max_distance_px, max_gap_ms, position_gain, min_length, ...}
  int64_t observation_period_ns = 50'000'000;    // corner_tracker.observation_period_ms: frames of track positions
  int64_t min_track_age_ns = 20'000'000;         // corner_tracker.min_track_age_ms: tracks younger are not observed
  bool refractory_enabled = true;                // filters.refractory (period_ms)
  frontend::RefractoryFilterOptions refractory;
  bool background_activity_enabled = true;      // filters.background_activity (window_ms, radius, min_support)
  frontend::BackgroundActivityFilterOptions background_activity;
  // back-end
  backend::SlidingWindowOptions window;          // window.{size, max_iterations, pixel_sigma, ...}
  // IMU noise (Kalibr densities) when neither --calib nor the dataset's calib.yaml has imu0
  calib::ImuNoise imu_noise;                     // imu.{accelerometer_noise_density, ...}
  // initialisation
  // init.method: auto (static, else alignment) | static | alignment | groundtruth (diagnostic:
  // pose and velocity from --gt at the first frame, to judge front-end and back-end alone)
  std::string init = "auto";
  backend::StaticInitOptions static_init;
  backend::VisualInertialInitOptions vi_init;
  int64_t init_window_ns = 2'000'000'000;        // init.window_ms: frames used by the alignment
};

VioConfig default_vio_config();
// Reads a VIO config YAML over the defaults. Throws evio::InputError (file:line, key, expected form).
VioConfig load_vio_config(const std::string& path, std::string* resolved_yaml = nullptr);

struct VioArgs {
  std::string dataset;
  DatasetOptions dataset_options;
  std::string config;   // optional YAML
  std::string calib;    // optional Kalibr camchain (+ imu0) or ECD calib.txt
  std::string gt;       // optional ground truth (TUM or csv) -> eval.json
  std::string out;
  bool progress = true;
};

int run_vio(const VioArgs& args, std::ostream& out);

}  // namespace evio::apps
