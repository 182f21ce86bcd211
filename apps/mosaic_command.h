// `evio mosaic DATASET --out DIR`: simultaneous rotational tracking and panorama mosaicing (Kim et
// al., BMVC 2014). A particle filter on SO(3) (frontend::RotationParticleFilter) tracks the camera
// against the log-intensity mosaic, which a pixel-wise EKF on its gradient
// (mapping::GradientMosaic) builds from the tracked rotation, reconstructed by Poisson
// integration every `reconstruct_ms`. Bootstrap over the first `bootstrap.duration_ms`: the gyro
// (--use-imu) or the angular velocity of rotational contrast maximisation per window.
// Writes rotation.tum, panorama.png (8-bit, gamma), panorama_log.tiff (float log intensity, NaN
// unseen), stats.json, the resolved config, optional snapshots and, with --gt, eval.json (rotation
// error after aligning the initial orientation; with a simulated panorama dataset also PSNR/SSIM
// of the mosaic against the true panorama over the seen region).
#pragma once

#include <cstdint>
#include <iosfwd>
#include <string>

#include "evio/frontend/rotation_particle_filter.h"
#include "evio/mapping/contrast_maximization.h"
#include "evio/mapping/gradient_mosaic.h"
#include "evio/mapping/mosaic_image.h"
#include "evio/sensors/dataset.h"

namespace evio::apps {

// Everything `--config FILE` sets (YAML sections mosaic, tracker, bootstrap, output; README.md).
struct MosaicConfig {
  mapping::GradientMosaicOptions mosaic;              // mosaic.{width, height, contrast_threshold, ...}
  frontend::RotationParticleFilterOptions tracker;    // tracker.{particles, batch_size, motion_model, ...}
  // tracker.event_stride when the YAML and --stride leave it unset (0): 4 with --use-imu (as
  // accurate as 1 on poster_rotation and 2x faster), 1 without (the stride costs accuracy there).
  int event_stride = 0;
  int64_t reconstruct_period_ns = 20'000'000;         // mosaic.reconstruct_ms: Poisson solve period (tracker's map)
  int64_t bootstrap_ns = 300'000'000;                 // bootstrap.duration_ms: mapping from gyro / CMax rates only
  // bootstrap.window_ms / window_events: a CMax window (events only) closes after this time or
  // this many events, whichever comes first (defaults 50 ms, 40000 events: about 11 ms at
  // 3.5 M events/s, 50 ms below 0.8 M events/s). Fixed 10 ms windows gave 3.7 deg of error in the
  // first 0.2 s at 66 deg/s (too little motion per window); fixed 30 ms ones diverged at 270 deg/s.
  // With the gyro the bootstrap uses 1 ms windows.
  int64_t bootstrap_window_ns = 50'000'000;
  int bootstrap_window_events = 40000;
  // bootstrap.calibrate_contrast: the tracker's C = the bootstrap mosaic's mean log-intensity change
  // per event along the bootstrap's paths (capped at tracker.contrast_threshold); false: use
  // tracker.contrast_threshold (default: mosaic.contrast_threshold) as given.
  bool calibrate_contrast = true;
  // bootstrap.min_contrast_ratio: the calibrated C is at least this times tracker.contrast_threshold
  // (in [0, 1], default 0.8). A slow bootstrap sees little texture: on a 66 deg/s scene it measured
  // 0.128 for C = 0.2 and tracking with that diverged (45 deg RMS over 3 s; 5.7 deg at 0.16).
  double min_contrast_ratio = 0.8;
  mapping::RotationalCmaxOptions cmax;                // bootstrap.{blur_px, ...} (IWE size/focal from the camera)
  int64_t trajectory_period_ns = 5'000'000;           // output.trajectory_ms: rotation.tum sampling
  int64_t snapshot_period_ns = 0;                     // output.snapshot_ms: panorama snapshots (0 = none)
  mapping::LogImageDisplayOptions display;            // output.{gamma, low_percentile, high_percentile}
};

MosaicConfig default_mosaic_config();
// Reads a mosaic config YAML over the defaults. Throws evio::InputError (file:line, key, expected form).
MosaicConfig load_mosaic_config(const std::string& path, std::string* resolved_yaml = nullptr);

struct MosaicArgs {
  std::string dataset;
  DatasetOptions dataset_options;
  std::string config;      // optional YAML
  std::string calib;       // optional Kalibr camchain or ECD calib.txt
  std::string gt;          // optional ground truth (TUM or csv) -> eval.json
  std::string out;
  bool use_imu = false;    // drive the particles (and bootstrap) with the gyro
  int particles = 0;       // > 0 overrides tracker.particles
  int batch = 0;           // > 0 overrides tracker.batch_size
  int stride = 0;          // > 0 overrides tracker.event_stride
  int width = 0;           // > 0 overrides mosaic.width (height = width / 2)
  double snapshot_s = 0;   // > 0 overrides output.snapshot_ms
  bool progress = true;
};

int run_mosaic(const MosaicArgs& args, std::ostream& out);

}  // namespace evio::apps
