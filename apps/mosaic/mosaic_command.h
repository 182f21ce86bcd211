// `evio mosaic DATASET --out DIR`: simultaneous rotational tracking and panorama mosaicing (Kim et
// al., BMVC 2014). A particle filter on SO(3) (frontend::RotationParticleFilter) tracks the camera
// against the log-intensity mosaic, which a pixel-wise EKF on its gradient
// (mapping::GradientMosaic) builds from the tracked rotation, reconstructed by Poisson
// integration every `reconstruct_events` events (at the latest every `reconstruct_ms`). Bootstrap over the first `bootstrap.duration_ms`: the gyro
// (--use-imu) or the angular velocity of rotational contrast maximisation per window.
// Writes rotation.tum, panorama.png (8-bit grey + alpha: unseen texels transparent; percentile
// range over the seen texels, gamma), panorama_seen.png (seen coverage), panorama_log.tiff (float
// log intensity, NaN unseen), stats.json, the resolved config, optional snapshots and, with --gt,
// eval.json (rotation error after aligning the initial orientation, overall and of the bootstrap's
// poses alone; with a simulated panorama dataset also PSNR/SSIM of the mosaic against the true
// panorama over the seen region). The algorithm is pipeline::MosaicPipeline; events are streamed.
#pragma once

#include <cstdint>
#include <iosfwd>
#include <string>
#include <vector>

#include "evio/mapping/mosaic_image.h"
#include "evio/pipeline/mosaic_pipeline.h"
#include "evio/sensors/dataset.h"

namespace evio::apps {

// Everything `--config FILE` sets (YAML sections mosaic, tracker, bootstrap, output; docs/commands/mosaic.md):
// the pipeline's options (mosaic.*, tracker.*, bootstrap.*, output.trajectory_ms/snapshot_ms)
// plus what only the command uses.
struct MosaicConfig : pipeline::MosaicPipelineOptions {
  // tracker.event_stride when the YAML and --stride leave it unset (0): 4 with --use-imu (as
  // accurate as 1 on poster_rotation and 2x faster), 1 without (the stride costs accuracy there).
  int event_stride = 0;
  // tracker.min_particles when the YAML leaves it unset or -1: the adaptive particle count
  // (KLD-sampling) down to 20 particles with --use-imu and 40 without (frontend/rotation_particle_filter.h).
  int min_particles = -1;
  // Why tracker_method is what it is once resolved by the input: "set", or "auto: events only" /
  // "auto: with the gyro" (pipeline::resolve_mosaic_tracker).
  std::string tracker_reason = "set";
  mapping::LogImageDisplayOptions display;            // output.{gamma, low_percentile, high_percentile, transparent_unseen}
};

MosaicConfig default_mosaic_config();
// Reads a mosaic config YAML (path empty: none) with `--set key.sub=value` overrides over the
// defaults. Throws evio::InputError (file:line or the --set option, key, expected form).
MosaicConfig load_mosaic_config(const std::string& path, std::string* resolved_yaml = nullptr,
                                const std::vector<std::string>& sets = {});
// The resolved config (every key, value, unit and range), readable by load_mosaic_config.
std::string mosaic_config_text(const MosaicConfig& c);

struct MosaicArgs {
  std::string dataset;
  DatasetOptions dataset_options;
  std::string config;      // optional YAML
  std::vector<std::string> set;  // --set key.sub=value overrides of the config, in order
  std::string calib;       // optional Kalibr camchain or ECD calib.txt
  std::string gt;          // optional ground truth (TUM or csv) -> eval.json
  std::string out;
  bool use_imu = false;    // drive the particles (and bootstrap) with the gyro
  bool gt_bootstrap = false;  // diagnostic: the bootstrap maps with the --gt rotations
  bool gt_mapping = false;    // diagnostic: --gt rotations map every event (bootstrap and tracking)
  bool oracle_map = false;    // diagnostic: the tracker tracks against the true panorama (simulated dataset)
  int particles = 0;       // > 0 overrides tracker.particles
  int batch = 0;           // > 0 overrides tracker.batch_size
  int stride = 0;          // > 0 overrides tracker.event_stride
  int width = 0;           // > 0 overrides mosaic.width (height = width / 2)
  double snapshot_s = 0;   // > 0 overrides output.snapshot_ms
  int threads = 0;         // > 0 overrides mosaic.threads (1, or 2: the mapper on a second thread)
  bool progress = true;
};

int run_mosaic(const MosaicArgs& args, std::ostream& out);

}  // namespace evio::apps
