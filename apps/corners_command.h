// `evio corners DATASET --out DIR`: the event-feature front-end on a recording: undistortion
// lookup, optional refractory and background-activity filters, eFAST corner events (optionally
// on the filtered SAE), corner tracks; writes corners.txt, tracks.txt, stats.json, optional PNG
// overlays, and prints a summary (reduction rate, corners per second, tracks and their lengths).
#pragma once

#include <iosfwd>
#include <string>

#include "evio/frontend/corner_tracker.h"
#include "evio/frontend/dart.h"
#include "evio/frontend/efast.h"
#include "evio/frontend/event_filters.h"
#include "evio/sensors/dataset.h"

namespace evio::apps {

// Everything `--config FILE` can set (YAML schema in README.md, keys in parentheses).
struct CornersConfig {
  bool refractory_enabled = false;                // refractory.enabled
  frontend::RefractoryFilterOptions refractory;   // refractory.{period_ms, per_polarity}
  bool background_activity_enabled = false;       // background_activity.enabled
  frontend::BackgroundActivityFilterOptions background_activity;  // background_activity.{window_ms, radius, min_support}
  frontend::EfastOptions efast;                   // efast.{filter_sae, filter_window_ms}
  bool tracks = true;                             // tracker.enabled
  frontend::CornerTrackerOptions tracker;         // tracker.{max_distance_px, max_gap_ms, position_gain, velocity_window_ms, min_velocity_span_ms, min_length, descriptor_ratio, max_descriptor_distance}
  bool descriptors = true;                        // tracker.descriptors: DART per corner event for the tracker
  frontend::DartOptions dart;                     // dart.{window_ms, rings, wedges, inner_radius_px, outer_radius_px, polarity}
  int64_t frames_every_ns = 0;                    // frames.every_ms: overlay period (0: none)
  int64_t frame_window_ns = 10'000'000;           // frames.window_ms: events shown per overlay
  int frame_scale = 2;                            // frames.scale: pixel magnification of overlays
  int64_t frame_track_history_ns = 100'000'000;   // frames.track_history_ms: track tail drawn
};

// Reads a corners config YAML (unknown keys are errors, with file:line). Throws evio::InputError.
CornersConfig load_corners_config(const std::string& path);

struct CornersArgs {
  std::string dataset;
  DatasetOptions dataset_options;
  std::string calib;          // optional calibration (Kalibr camchain YAML or ECD calib.txt)
  std::string config;         // optional YAML; flags below override it
  std::string out;            // output folder (created)
  bool filter_sae = false;    // --filter-sae
  int64_t frames_every_ns = -1;  // --frames-every-ms (>= 0 overrides the config)
  bool progress = true;
};

// Returns the exit code. Throws evio::InputError on bad input.
int run_corners(const CornersArgs& args, std::ostream& out);

}  // namespace evio::apps
