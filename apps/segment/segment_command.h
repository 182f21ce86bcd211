// `evio segment DATASET --out DIR`: motion segmentation by contrast maximisation
// (pipeline::SegmentationPipeline: event windows, each split into clusters of events that share a
// motion, warm-started from the previous window's clusters so labels persist). Writes
//   labels.txt     `t x y p label`, one line per input event in input order: t in s, x y as read,
//                  p 1 (ON) / 0 (OFF) as in ECD events.txt, label the cluster id or -1 (noise, or
//                  an event in no segmented window: a window too small, an event the undistortion
//                  dropped)
//   segments.json  per window: span, events, clusters (id, model, parameters with units, events,
//                  objective, gain over the best other motion, the models tried) and the count
//                  decisions
//   images/        per window (--png): window_NNNNNN.png, the clusters' IWEs in their colours, and
//                  window_NNNNNN_cluster_ID.png, each cluster's IWE (its own events, warped)
//   stats.json     events, windows, time per window and per event, alternations, evaluations,
//                  labels used, the undistortion choice
//   segment_config.yaml  the resolved config
//   eval.json      with true labels (--gt FILE, or DATASET/event_labels.txt of `evio simulate`):
//                  per-event label accuracy, per window (evaluation/windowed_label_evaluation.h)
#pragma once

#include <cstdint>
#include <iosfwd>
#include <optional>
#include <string>
#include <vector>

#include "evio/pipeline/segmentation_pipeline.h"
#include "evio/sensors/dataset.h"

namespace evio::apps {

// Everything `--config FILE` sets (sections window, segmentation, cmax; docs/commands/segment.md,
// `evio segment --print-config`). cmax width/height/fx/fy/cx/cy come from the camera.
struct SegmentConfig : pipeline::SegmentationPipelineOptions {};

SegmentConfig load_segment_config(const std::string& path, const std::vector<std::string>& sets = {});
std::string segment_config_text(const SegmentConfig& c);

struct SegmentArgs {
  std::string dataset;
  DatasetOptions dataset_options;
  std::string config;
  std::vector<std::string> set;
  std::string calib;
  std::string out;
  int64_t window_events = 0;     // --window-events (> 0 overrides window.events, clears window.duration_ms)
  int64_t window_ns = 0;         // --window-ms (> 0 overrides window.duration_ms)
  std::string clusters;          // --clusters auto|N (empty: the config's)
  std::string models;            // --models flow,similarity,... (empty: the config's)
  std::optional<int64_t> t_start_ns, t_end_ns;
  std::string gt;                // --gt FILE: true per-event labels (empty: DATASET/event_labels.txt when present)
  bool no_gt = false;            // --no-gt: no scoring even when DATASET/event_labels.txt exists
  bool png = true;               // --png / --no-png
  int png_every = 1;             // PNGs of every this many windows
  bool progress = true;
};

SegmentConfig resolve_segment_config(const SegmentArgs& args);
int run_segment(const SegmentArgs& args, std::ostream& out);

}  // namespace evio::apps
