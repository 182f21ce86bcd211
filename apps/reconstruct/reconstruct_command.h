// `evio reconstruct DATASET --out DIR --method hf|cf|akf|gradient [--corners]`: image reconstruction
// from events (and APS frames with --use-frames) by the per-pixel filters of
// mapping/reconstruction.h, or the Poisson image of the asynchronous-convolution gradient state
// (mapping/async_convolution.h), streamed in bounded memory (events in chunks, one frame decoded at
// a time). At each requested time writes
//   images/frame_NNNNNNNN.png   8-bit, the log intensity's 1st..99th percentile range (display section)
//   images/frame_NNNNNNNN.tiff  float32 log intensity (the filter's state)
//   images.txt                  `t[s] images/frame_NNNNNNNN.png`, as in the Event Camera Dataset
//   video.mp4                   with --video, when OpenCV's VideoWriter has an MP4 codec
//   stats.json                  events, frames fused, images, events/s, ns per event (filter only)
//   reconstruct_config.yaml     the resolved config
//   corners.txt                 with --corners: event Harris corner events (mapping/event_harris.h),
//                               `t[s] x y p` as `evio corners` writes them
//   eval.json                   for a simulated dataset (--gt SCENE.yaml, or DATASET/scene_resolved.yaml):
//                               PSNR and SSIM of every image against the clean view rendered at its time
//                               (Simulator::true_log_view, mapping::compare_images), their means and minima
//                               (evaluation/image_quality_summary.h)
#pragma once

#include <cstdint>
#include <iosfwd>
#include <optional>
#include <string>
#include <vector>

#include "evio/mapping/async_convolution.h"
#include "evio/mapping/event_harris.h"
#include "evio/mapping/mosaic_image.h"
#include "evio/mapping/reconstruction.h"
#include "evio/sensors/dataset.h"

namespace evio::apps {

// Everything `--config FILE` sets (docs/commands/reconstruct.md, `evio reconstruct --print-config`).
struct ReconstructConfig {
  mapping::ReconstructionMethod method = mapping::ReconstructionMethod::kComplementary;
  bool use_frames = false;
  double rate_hz = 30.0;  // images per second of sensor time when no --at list
  mapping::ComplementaryFilterOptions cf;  // hf and cf (hf: high_pass, no frames)
  mapping::AsyncKalmanFilterOptions akf;
  bool gradient_sobel = false;             // gradient: Sobel 3x3 instead of forward differences
  mapping::EventHarrisOptions harris;      // --corners (contrasts: cf's)
  mapping::FrameResponse frames;           // copied into cf and akf
  mapping::LogImageDisplayOptions display;
  double video_fps = 30.0;
  bool Validate(std::string* why) const;
};

ReconstructConfig load_reconstruct_config(const std::string& path, const std::vector<std::string>& sets = {});
std::string reconstruct_config_text(const ReconstructConfig& c);

struct ReconstructArgs {
  std::string dataset;
  DatasetOptions dataset_options;
  std::string config;
  std::vector<std::string> set;
  std::string calib;
  std::string out;
  std::string method;                 // hf | cf | akf | gradient (empty: the config's)
  std::optional<double> rate_hz;      // --rate
  std::vector<int64_t> at_ns;         // --at (absolute file times)
  bool use_frames = false;            // --use-frames
  std::optional<double> cutoff_hz;    // --cutoff-hz
  std::optional<double> contrast_on;  // --contrast-on
  std::optional<double> contrast_off; // --contrast-off
  bool video = false;                 // --video
  bool corners = false;               // --corners
  std::string gt;                     // --gt SCENE.yaml (empty: DATASET/scene_resolved.yaml when present)
  bool no_gt = false;                 // --no-gt
  bool progress = true;
};

ReconstructConfig resolve_reconstruct_config(const ReconstructArgs& args);
// Returns the exit code. Throws evio::InputError on bad input.
int run_reconstruct(const ReconstructArgs& args, std::ostream& out);

}  // namespace evio::apps
