// The evio subcommands: names and one-line summaries, shared by the `evio` dispatcher (main.cc,
// which lists them and execs the chosen one) and by each subcommand program (<name>_cli.cc, whose
// --help shows the same summary). Header-only, no dependencies, so the dispatcher links nothing.
#pragma once

#include <cstring>

namespace evio::apps {

inline constexpr const char* kVersion = "evio 0.1.0";

inline constexpr const char* kDescription =
    "evio: event-camera odometry, mosaicing and mapping on recorded datasets (no ROS).\n"
    "Times are printed in seconds; pixel sizes in px.";

struct SubcommandInfo {
  const char* name;
  const char* summary;
};

// In the order `evio --help` lists them. Each runs as the program evio-<name> (same folder as
// `evio`, or <prefix>/libexec/evio when installed), linked only with what it uses.
inline constexpr SubcommandInfo kSubcommands[] = {
    {"info",
     "Summarise a recording: format, sensor size, duration, event count and rate, polarity balance, IMU rate, "
     "frames, ground-truth span, calibration"},
    {"convert",
     "Convert a recording (any readable format) to an Event Camera Dataset text folder or an evio HDF5 file "
     "(DSEC layout), streaming, optionally sliced in time"},
    {"simulate",
     "Simulate an event camera (DAVIS/Prophesee-like, ESIM-style) with IMU, frames and ground truth on a scene YAML "
     "(schema: datasets/README.md) and write an Event Camera Dataset folder, events.h5, a Kalibr calib.yaml and "
     "ground-truth extras"},
    {"eval",
     "Evaluate estimated trajectories against ground truth (rpg_trajectory_evaluation protocol): association by "
     "time, alignment, ATE, RPE, mean position error %, yaw drift; results.json, summaries over runs (csv, yaml, "
     "json, LaTeX) and plots"},
    {"corners",
     "eFAST corner events and corner tracks of a recording (Mueggler et al. BMVC 2017): corners.txt, tracks.txt, "
     "stats.json (events, corners, reduction rate, ns per event) and optional PNG overlays"},
    {"vio",
     "Event-based visual-inertial odometry: events + IMU -> trajectory.tum, keyframes.txt, map.ply, stats.json "
     "(and eval.json with --gt)"},
    {"mosaic",
     "Rotational tracking and panorama mosaicing (particle filter on SO(3), gradient EKF, Poisson): events -> "
     "rotation.tum, panorama.png, stats.json (and eval.json with --gt)"},
    {"flow",
     "Motion per event window by contrast maximisation (optical flow, rotation, similarity or 6-DoF; Gallego et al. "
     "CVPR 2018): motion.csv, stats.json, optional IWE PNGs, and with --gt for rotation the angular-velocity error "
     "(motion_eval.csv)"},
    {"segment",
     "Motion segmentation by contrast maximisation (Stoffregen et al. ICCV 2019): clusters of events that share a "
     "motion, their number and warp models chosen per window, labels that persist across windows: labels.txt, "
     "segments.json, coloured IWE PNGs, stats.json"},
    {"reconstruct",
     "Image reconstruction from events and APS frames, per pixel and per event (high-pass, complementary filter "
     "Scheerlinck et al. ACCV 2018, asynchronous Kalman filter Wang et al. ICCV 2021): images/ (PNG + float TIFF log "
     "intensity), images.txt, stats.json, optional MP4"},
    {"sweep",
     "Speed-accuracy sweep: datasets x algorithms x parameter grids from a spec YAML, one `evio <algorithm>` process "
     "per cell (local process pool, --resume), results.jsonl (exit code, wall/CPU time, peak RSS, error metrics) and a "
     "report (Pareto fronts as Markdown, CSV, LaTeX, plots, one HTML page)"},
};

// The summary of a subcommand, or nullptr for an unknown name.
inline const char* subcommand_summary(const char* name) {
  for (const SubcommandInfo& s : kSubcommands) {
    if (std::strcmp(s.name, name) == 0) return s.summary;
  }
  return nullptr;
}

}  // namespace evio::apps
