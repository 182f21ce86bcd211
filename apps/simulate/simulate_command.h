// `evio simulate SCENE.yaml --out DIR`: runs the event camera simulator (simulator/simulator.h) on a
// scene YAML (simulator/scene_config.h; schema in datasets/README.md) and writes an Event Camera
// Dataset folder (events.txt, imu.txt, groundtruth.txt, calib.txt, images.txt + images/), events.h5,
// a Kalibr calib.yaml and ground-truth extras (velocities, IMU biases, depth/flow/intensity/label
// maps, per-event labels, the panorama), plus scene_resolved.yaml and simulation.json.
#pragma once

#include <cstdint>
#include <iosfwd>
#include <string>

#include <opencv2/core.hpp>

#include "evio/simulator/scene_config.h"

namespace evio::apps {

struct SimulateArgs {
  std::string scene;             // scene YAML
  std::string out;               // output folder (created)
  simulator::SimulateOverrides overrides;   // --seed, --duration, --set
  bool progress = true;          // progress lines on stderr (fraction, events, ETA)
  int threads = 1;               // render threads, 1..64 (outputs do not depend on it)
};

// Returns the exit code (0); prints a short summary to out. Throws evio::InputError on bad input
// (the scene file, its textures or trajectory file, an unwritable output folder).
int run_simulate(const SimulateArgs& args, std::ostream& out);

// Writes a 2-D (channels == 1) or 3-D (H x W x C) NumPy .npy file (format 1.0, little-endian
// float32) from a CV_32F image with any number of channels. Throws InputError on I/O failure.
void write_npy_float32(const std::string& path, const cv::Mat& image);

}  // namespace evio::apps
