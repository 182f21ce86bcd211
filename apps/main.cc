// The `evio` command-line tool. All flag parsing lives here (CLI11 is included in this file only);
// each subcommand's work is in its own <name>_command.cc. Exit codes: 0 success, 1 bad input
// (file, line and expected form on one line of stderr), 2 usage error, 3 internal error.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "convert_command.h"
#include "corners_command.h"
#include "eval_command.h"
#include "evio/sensors/time.h"
#include "info_command.h"
#include "simulate_command.h"
#include "mosaic_command.h"
#include "vio_command.h"

namespace {

// Levenshtein distance (insertions, deletions, substitutions), for subcommand suggestions.
size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<size_t> row(b.size() + 1);
  for (size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (size_t i = 1; i <= a.size(); ++i) {
    size_t diag = row[0];
    row[0] = i;
    for (size_t j = 1; j <= b.size(); ++j) {
      const size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diag = up;
    }
  }
  return row[b.size()];
}

// Parses "WxH" into a sensor size.
std::string parse_sensor(const std::string& s, evio::SensorSize* out) {
  int w = 0, h = 0;
  char x = 0, extra = 0;
  if (std::sscanf(s.c_str(), "%d%c%d%c", &w, &x, &h, &extra) != 3 || (x != 'x' && x != 'X') || w <= 0 || h <= 0) {
    return "expected WIDTHxHEIGHT in pixels, e.g. 240x180; got '" + s + "'";
  }
  out->width = w;
  out->height = h;
  return {};
}

// Flags shared by every command that reads a dataset.
void add_dataset_options(CLI::App* cmd, evio::DatasetOptions* opts, std::string* format, std::string* time_unit,
                         std::string* on_bad_line) {
  cmd->add_option("--format", *format, "Dataset format; auto detects it from the folder layout and extension")
      ->check(CLI::IsMember({"auto", "ecd", "ecd-events", "h5", "aedat4", "evt2", "evt3", "rosbag", "aedat2"}))
      ->capture_default_str();
  cmd->add_option("--time-unit", *time_unit,
                  "Unit of the time column of text files: s, ms, us, ns; auto = decimal point means s, "
                  "integers mean us (ns above 1e17 or when all are multiples of 1000)")
      ->check(CLI::IsMember({"auto", "s", "ms", "us", "ns"}))
      ->capture_default_str();
  cmd->add_option_function<std::string>(
      "--sensor",
      [opts](const std::string& s) {
        const std::string err = parse_sensor(s, &opts->text.sensor);
        if (!err.empty()) throw CLI::ValidationError("--sensor", err);
      },
      "Sensor size WIDTHxHEIGHT in pixels; events outside it are bad lines (default: unknown, not checked)");
  cmd->add_option("--on-bad-line", *on_bad_line,
                  "What to do with a malformed, out-of-order or out-of-sensor line: error = stop with file, "
                  "line and expected form; warn = skip it and report counts")
      ->check(CLI::IsMember({"error", "warn"}))
      ->capture_default_str();
  cmd->add_flag_callback(
      "--no-time-unit-check", [opts] { opts->text.check_time_unit = false; },
      "Accept a time unit even when the first records imply an implausible event rate (outside 10 Hz..2 GHz) "
      "or IMU/pose rate (outside 0.1 Hz..100 kHz)");
  cmd->add_option("--events-topic", opts->topics.events,
                  "ROS bag: topic of dvs_msgs/EventArray or event_camera_msgs/EventPacket (default: the only one)");
  cmd->add_option("--imu-topic", opts->topics.imu, "ROS bag: topic of sensor_msgs/Imu (default: the only one)");
  cmd->add_option("--image-topic", opts->topics.image, "ROS bag: topic of sensor_msgs/Image mono8 (default: the only one)");
}

// Seconds as text -> exact int64 ns (no detour through double).
int64_t parse_seconds_flag(const std::string& flag, const std::string& s) {
  const char* p = s.c_str();
  int64_t t = 0;
  if (!evio::parse_decimal_time_ns(p, s.c_str() + s.size(), 9, &t) || *p != '\0') {
    throw CLI::ValidationError(flag, "expected a time in seconds, e.g. 12.5; got '" + s + "'");
  }
  return t;
}

void apply_dataset_strings(const std::string& format, const std::string& time_unit, const std::string& on_bad_line,
                           evio::DatasetOptions* opts) {
  opts->format = *evio::dataset_format_from_name(format);
  opts->text.time_unit = *evio::time_unit_from_name(time_unit);
  opts->text.on_bad_line = on_bad_line == "warn" ? evio::BadLinePolicy::kWarnAndSkip : evio::BadLinePolicy::kError;
}

// "10,20,30,40,50%" or "5,10m" -> lengths and unit.
void parse_rpe_lengths(const std::string& s, evio::evaluation::RelativeErrorOptions* rpe) {
  const std::string form = "comma-separated lengths ending in % (of the ground-truth path length) or m, e.g. "
                           "10,20,30,40,50% or 5,10,20m; got '" + s + "'";
  if (s.empty() || (s.back() != '%' && s.back() != 'm')) throw CLI::ValidationError("--rpe-lengths", form);
  rpe->lengths_in_percent = s.back() == '%';
  rpe->lengths.clear();
  std::string body = s.substr(0, s.size() - 1);
  size_t start = 0;
  for (;;) {
    const size_t comma = body.find(',', start);
    const std::string item = body.substr(start, comma == std::string::npos ? std::string::npos : comma - start);
    char* end = nullptr;
    const double v = std::strtod(item.c_str(), &end);
    if (item.empty() || end == item.c_str() || *end != '\0' || !(v > 0)) {
      throw CLI::ValidationError("--rpe-lengths", form);
    }
    rpe->lengths.push_back(v);
    if (comma == std::string::npos) break;
    start = comma + 1;
  }
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"evio: event-camera odometry, mosaicing and mapping on recorded datasets (no ROS).\n"
               "Times are printed in seconds; pixel sizes in px."};
  app.set_version_flag("--version", "evio 0.1.0");
  app.require_subcommand(1);
  app.fallthrough();  // global flags (-q, -v) may also follow the subcommand
  bool quiet = false, verbose = false;
  app.add_flag("-q,--quiet", quiet, "Print only warnings and errors on stderr (no progress, no conventions)");
  app.add_flag("-v,--verbose", verbose, "Also print debug messages on stderr");

  evio::apps::InfoArgs info;
  std::string info_format = "auto", info_unit = "auto", info_bad = "error";
  CLI::App* info_cmd = app.add_subcommand(
      "info", "Summarise a recording: format, sensor size, duration, event count and rate, polarity balance, "
              "IMU rate, frames, ground-truth span, calibration");
  info_cmd->add_option("PATH", info.path, "Dataset folder (ECD layout) or events text file")->required();
  add_dataset_options(info_cmd, &info.dataset, &info_format, &info_unit, &info_bad);
  info_cmd->add_flag("--json", info.json, "Print one JSON object instead of the table");

  evio::apps::ConvertArgs conv;
  std::string conv_format = "auto", conv_unit = "auto", conv_bad = "error", conv_to = "auto";
  std::string conv_polarity = "input", conv_h5_unit = "ns";
  CLI::App* conv_cmd = app.add_subcommand(
      "convert", "Convert a recording (any readable format) to an Event Camera Dataset text folder or an evio "
                 "HDF5 file (DSEC layout), streaming, optionally sliced in time");
  conv_cmd->add_option("IN", conv.in, "Input dataset (folder or file)")->required();
  conv_cmd->add_option("OUT", conv.out, "Output: a folder (ECD layout) or a .h5 file")->required();
  add_dataset_options(conv_cmd, &conv.dataset, &conv_format, &conv_unit, &conv_bad);
  conv_cmd->add_option("--to", conv_to, "Output format: ecd, h5, or auto (h5 for a .h5/.hdf5 OUT, else ecd)")
      ->check(CLI::IsMember({"auto", "ecd", "h5"}))
      ->capture_default_str();
  conv_cmd->add_option_function<std::string>(
      "--t-start", [&conv](const std::string& s) { conv.t_start_ns = parse_seconds_flag("--t-start", s); },
      "Keep data with t >= T_START, in seconds of the input's time axis (as `evio info` prints it)");
  conv_cmd->add_option_function<std::string>(
      "--t-end", [&conv](const std::string& s) { conv.t_end_ns = parse_seconds_flag("--t-end", s); },
      "Keep data with t < T_END, in seconds of the input's time axis");
  conv_cmd->add_option("--polarity", conv_polarity,
                       "ECD output polarity: 01 (ECD), pm1 (-1/+1), or input (the input's convention; 0/1 for "
                       "binary formats)")
      ->check(CLI::IsMember({"input", "01", "pm1"}))
      ->capture_default_str();
  conv_cmd->add_option("--h5-time-unit", conv_h5_unit,
                       "HDF5 output time unit: ns (lossless) or us (DSEC, rounds to whole microseconds)")
      ->check(CLI::IsMember({"ns", "us"}))
      ->capture_default_str();
  conv_cmd->add_option("--h5-compression", conv.h5_compression, "HDF5 output compression: none, gzip or blosc")
      ->check(CLI::IsMember({"none", "gzip", "blosc"}))
      ->capture_default_str();

  evio::apps::SimulateArgs simulate;
  CLI::App* sim_cmd = app.add_subcommand(
      "simulate", "Simulate an event camera (DAVIS/Prophesee-like, ESIM-style) with IMU, frames and ground truth on a "
                  "scene YAML (schema: datasets/README.md) and write an Event Camera Dataset folder, events.h5, a "
                  "Kalibr calib.yaml and ground-truth extras");
  sim_cmd->add_option("SCENE", simulate.scene, "Scene YAML (e.g. datasets/poster_6dof.yaml)")->required();
  sim_cmd->add_option("-o,--out", simulate.out, "Output folder (created; existing files are overwritten)")->required();
  sim_cmd->add_option_function<uint64_t>(
      "--seed", [&simulate](const uint64_t& s) { simulate.overrides.seed = s; },
      "Top-level seed (replaces the YAML's `seed`); every component seed not pinned in the YAML derives from it");
  sim_cmd->add_option_function<double>(
      "--duration", [&simulate](const double& d) { simulate.overrides.duration_s = d; },
      "Simulated span in seconds (replaces the YAML's `duration`; file trajectories: from trajectory.start_s)")
      ->check(CLI::PositiveNumber);
  sim_cmd->add_option("--set", simulate.overrides.set,
                      "Change one YAML value before parsing: key.sub=value, value in YAML syntax, list entries by "
                      "index (e.g. --set camera.scale=0.25 --set events.contrast_threshold_pos=0.3); repeatable")
      ->expected(1)
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
  sim_cmd->add_option("--threads", simulate.threads,
                      "Render threads (the image is split in row bands); the output is identical for any count")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();

  evio::apps::EvalArgs eval;
  std::string eval_align = "se3";
  CLI::App* eval_cmd = app.add_subcommand(
      "eval", "Evaluate estimated trajectories against ground truth (rpg_trajectory_evaluation protocol): "
              "association by time, alignment, ATE, RPE, mean position error %, yaw drift; results.json, "
              "summaries over runs (csv, yaml, json, LaTeX) and plots");
  eval_cmd->add_option("GT", eval.groundtruth,
                       "Ground truth: TUM `t x y z qx qy qz qw` (t in s) or csv with a header (EuRoC/mocap, t in ns)")
      ->required();
  eval_cmd->add_option("EST", eval.estimates, "Estimated trajectories (same formats), one or more")->required();
  eval_cmd->add_option("--align", eval_align,
                       "Alignment of each estimate to the ground truth: none, se3 (Umeyama), sim3 (Umeyama with "
                       "scale), posyaw (translation + yaw, the 4 unobservable DoF of VIO)")
      ->check(CLI::IsMember({"none", "se3", "sim3", "posyaw"}))
      ->capture_default_str();
  eval_cmd->add_option("--align-first-s", eval.options.alignment.first_s,
                       "Fit the alignment on the pairs of the first S seconds only (0: all pairs), s")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  eval_cmd->add_option("--align-first-n", eval.options.alignment.first_poses,
                       "Fit the alignment on the first N pairs only (0: all pairs)")
      ->capture_default_str();
  eval_cmd->add_option("--max-dt", eval.options.association.max_dt_s,
                       "Largest time difference of an estimate/ground-truth pair, s")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  eval_cmd->add_option("--time-offset", eval.options.association.time_offset_s,
                       "Added to the estimate's stamps before matching, s")
      ->capture_default_str();
  eval_cmd->add_flag("--interpolate", eval.options.association.interpolate_groundtruth,
                     "Interpolate the ground truth at each estimate stamp instead of taking the nearest pose");
  eval_cmd->add_option_function<std::string>(
      "--rpe-lengths", [&eval](const std::string& s) { parse_rpe_lengths(s, &eval.options.rpe); },
      "Sub-trajectory lengths of the relative error: 10,20,30,40,50% (of the ground-truth path length, the "
      "default) or metres, e.g. 5,10,20m");
  eval_cmd->add_option("-o,--out", eval.out,
                       "Output folder: results.json, summary.{csv,yaml,json,tex}, per-estimate aligned TUM and "
                       "error csv");
  eval_cmd->add_option("--plot", eval.plot,
                       "Plot folder: runs scripts/plot_trajectory.py (/usr/bin/python3 with numpy and matplotlib) "
                       "on the outputs (written to --out, or here without --out); PNG and PDF");
  eval_cmd->add_option("--label", eval.labels,
                       "Method label per estimate, in order (runs of one method share a label); summaries group by "
                       "label (default: each file is its own method)")
      ->expected(1)
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
  std::string eval_bad = "error";
  eval_cmd->add_option("--on-bad-line", eval_bad,
                       "What to do with a malformed, non-finite, out-of-order or non-unit-quaternion line: error = stop "
                       "with file, line and expected form; warn = skip it and report counts")
      ->check(CLI::IsMember({"error", "warn"}))
      ->capture_default_str();
  std::string eval_unit = "auto", eval_gt_unit = "auto";
  eval_cmd->add_option("--time-unit", eval_unit,
                       "Unit of the estimates' time column: s, ms, us, ns; auto = a unit tag in a header comment, "
                       "else a decimal point means s, integers "
                       "mean us (ns above 1e17 or when all are multiples of 1000)")
      ->check(CLI::IsMember({"auto", "s", "ms", "us", "ns"}))
      ->capture_default_str();
  eval_cmd->add_option("--gt-time-unit", eval_gt_unit, "Unit of the ground truth's time column (as --time-unit)")
      ->check(CLI::IsMember({"auto", "s", "ms", "us", "ns"}))
      ->capture_default_str();
  eval_cmd->add_flag_callback(
      "--no-time-unit-check", [&eval] { eval.read.check_time_unit = false; },
      "Accept a time unit even when the first poses imply a rate outside 0.1 Hz..100 kHz");
  eval_cmd->add_option("--python", eval.python, "Python interpreter for --plot")->capture_default_str();

  evio::apps::CornersArgs corners;
  std::string corners_format = "auto", corners_unit = "auto", corners_bad = "error";
  double corners_frames_ms = -1;
  CLI::App* corners_cmd = app.add_subcommand(
      "corners", "eFAST corner events and corner tracks of a recording (Mueggler et al. BMVC 2017): corners.txt, "
                 "tracks.txt, stats.json (events, corners, reduction rate, ns per event) and optional PNG overlays");
  corners_cmd->add_option("DATASET", corners.dataset, "Dataset (any format evio reads)")->required();
  corners_cmd->add_option("-o,--out", corners.out, "Output folder (created)")->required();
  corners_cmd->add_option("--config", corners.config,
                          "YAML with refractory, background_activity, efast, tracker and frames sections (README.md)");
  corners_cmd->add_option("--calib", corners.calib,
                          "Calibration (Kalibr camchain .yaml or ECD calib.txt); default: the dataset's own. Gives the "
                          "sensor size and the undistortion of track positions");
  corners_cmd->add_flag("--filter-sae", corners.filter_sae,
                        "Filtered SAE: an event updates the SAE (and is tested) only when the pixel's latest event of "
                        "its polarity is older than 50 ms (efast.filter_window_ms) or had the other polarity");
  corners_cmd->add_option("--frames-every-ms", corners_frames_ms,
                          "Write a PNG overlay (events, corners, tracks) every N ms of sensor time to DIR/frames/; "
                          "0: none (default: the config's frames.every_ms, else none), ms")
      ->check(CLI::NonNegativeNumber);
  add_dataset_options(corners_cmd, &corners.dataset_options, &corners_format, &corners_unit, &corners_bad);

  evio::apps::VioArgs vio;
  std::string vio_format = "auto", vio_unit = "auto", vio_bad = "error";
  CLI::App* vio_cmd = app.add_subcommand(
      "vio", "Event-based visual-inertial odometry: events + IMU -> trajectory.tum, keyframes.txt, map.ply, "
             "stats.json (and eval.json with --gt)");
  vio_cmd->add_option("DATASET", vio.dataset, "Dataset with events and IMU (any format evio reads)")->required();
  vio_cmd->add_option("-o,--out", vio.out, "Output folder (created)")->required();
  vio_cmd->add_option("--config", vio.config, "VIO config YAML (README.md; examples in datasets/vio/*.yaml)");
  vio_cmd->add_option("--calib", vio.calib,
                      "Calibration: Kalibr camchain .yaml (with imu0 noise) or ECD calib.txt; default: the dataset "
                      "folder's calib.yaml, else the dataset's calibration");
  vio_cmd->add_option("--gt", vio.gt,
                      "Ground truth (TUM or csv): evaluate at the end (SE3 alignment on the first 5 s) into eval.json");
  vio_cmd->add_option("--oracle-tracks", vio.oracle_scene,
                      "Error budget on a simulated sequence: SCENE.yaml it was simulated from (needs --gt). The estimator "
                      "sees the true projections of the front-end's tracks (same tracks, lifetimes and frames)");
  vio_cmd->add_option("--oracle-noise-px", vio.oracle_noise_px,
                      "With --oracle-tracks: white Gaussian noise added per axis (px on the ideal pinhole)")
      ->check(CLI::NonNegativeNumber);
  vio_cmd->add_option("--oracle-drift-px", vio.oracle_drift_px,
                      "With --oracle-tracks: random-walk drift per track, Gaussian step per axis and frame (px)")
      ->check(CLI::NonNegativeNumber);
  vio_cmd->add_option("--oracle-error", vio.oracle_error,
                      "With --oracle-tracks: what the estimator keeps of the front-end's own error (observed minus true "
                      "projection): none, real (all of it), independent (each frame's common mode, the per-axis median, "
                      "removed) or common_mode (that median alone)")
      ->check(CLI::IsMember({"none", "real", "independent", "common_mode"}));
  vio_cmd->add_flag("--oracle-frame-motion", vio.oracle_frame_motion,
                    "With --oracle-tracks: the event frames' translation compensation (frames.use_depth) takes the true "
                    "camera-centre velocity at each frame's stamp and the true median depth of the latest tracked frame's "
                    "tracks instead of the estimate's");
  vio_cmd->add_flag("--oracle-frame-plane", vio.oracle_frame_plane,
                    "With --oracle-frame-motion: each event's depth from the least-squares plane through the true scene points "
                    "of the frame's tracks instead of their median depth");
  vio_cmd->add_option("--oracle-max-error-px", vio.oracle_max_error_px,
                      "With --oracle-error real or independent: drop observations whose own error is larger (px; 0 = keep all)")
      ->check(CLI::NonNegativeNumber);
  add_dataset_options(vio_cmd, &vio.dataset_options, &vio_format, &vio_unit, &vio_bad);

  evio::apps::MosaicArgs mosaic;
  std::string mosaic_format = "auto", mosaic_unit = "auto", mosaic_bad = "error";
  CLI::App* mosaic_cmd = app.add_subcommand(
      "mosaic", "Rotational tracking and panorama mosaicing (particle filter on SO(3), gradient EKF, Poisson): events "
                "-> rotation.tum, panorama.png, stats.json (and eval.json with --gt)");
  mosaic_cmd->add_option("DATASET", mosaic.dataset, "Dataset with events (IMU for --use-imu; any format evio reads)")->required();
  mosaic_cmd->add_option("-o,--out", mosaic.out, "Output folder (created)")->required();
  mosaic_cmd->add_option("--config", mosaic.config, "Mosaic config YAML (README.md; example datasets/mosaic/simulator.yaml)");
  mosaic_cmd->add_option("--calib", mosaic.calib,
                         "Calibration: Kalibr camchain .yaml or ECD calib.txt; default: the dataset folder's calib.yaml, "
                         "else the dataset's calibration");
  mosaic_cmd->add_flag("--use-imu", mosaic.use_imu, "Drive the particles and the bootstrap with the gyro");
  mosaic_cmd->add_option("--particles", mosaic.particles, "Particles (overrides tracker.particles)")->check(CLI::PositiveNumber);
  mosaic_cmd->add_option("--batch", mosaic.batch, "Events per particle-filter update (overrides tracker.batch_size)")
      ->check(CLI::PositiveNumber);
  mosaic_cmd->add_option("--stride", mosaic.stride,
                         "One event in this many weighs the particles (overrides tracker.event_stride)")
      ->check(CLI::PositiveNumber);
  mosaic_cmd->add_option("--width", mosaic.width, "Mosaic width in px; height = width / 2 (overrides mosaic.width)")
      ->check(CLI::Range(8, 32768));
  mosaic_cmd->add_option("--threads", mosaic.threads,
                         "1, or 2: the mapper (gradient EKF, Poisson solves) on a second thread; identical output "
                         "(overrides mosaic.threads)")
      ->check(CLI::Range(1, 2));
  mosaic_cmd->add_option("--snapshots-every", mosaic.snapshot_s, "Write snapshots/panorama_NNNNNN.png every this many s")
      ->check(CLI::NonNegativeNumber);
  mosaic_cmd->add_option("--gt", mosaic.gt,
                         "Ground truth (TUM or csv): rotation error after aligning the initial orientation into eval.json "
                         "(and PSNR/SSIM against the true panorama of a simulated dataset)");
  mosaic_cmd->add_flag("--gt-bootstrap", mosaic.gt_bootstrap,
                       "Diagnostic: the bootstrap maps with the --gt rotations (no bootstrap error; needs --gt)");
  mosaic_cmd->add_flag("--gt-mapping", mosaic.gt_mapping,
                       "Diagnostic: the --gt rotations map every event, the bootstrap's and the tracked ones, so the "
                       "map carries no tracking error (implies --gt-bootstrap; needs --gt)");
  mosaic_cmd->add_flag("--oracle-map", mosaic.oracle_map,
                       "Diagnostic: the tracker weighs its particles against the true panorama (a dataset written by "
                       "evio simulate with a panorama scene, rendered in the mosaic frame by the --gt start pose) "
                       "instead of the mosaic's reconstructions; no map error (needs --gt)");
  add_dataset_options(mosaic_cmd, &mosaic.dataset_options, &mosaic_format, &mosaic_unit, &mosaic_bad);

  // A mistyped subcommand: name it and list the real ones (CLI11 alone says "A subcommand is
  // required", and with --help prints the main help and exits 0). The global options take no
  // values, so the first argument not starting with '-' is the subcommand.
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (!a.empty() && a[0] == '-') continue;
    std::vector<std::string> names;
    for (const CLI::App* sub : app.get_subcommands([](CLI::App*) { return true; })) names.push_back(sub->get_name());
    if (std::find(names.begin(), names.end(), a) != names.end()) break;
    std::string closest;
    size_t best = 3;  // suggest within 2 edits
    for (const std::string& n : names) {
      const size_t d = edit_distance(a, n);
      if (d < best) best = d, closest = n;
    }
    std::cerr << "evio: unknown subcommand '" << a << "'" << (closest.empty() ? "" : " (did you mean '" + closest + "'?)")
              << "; the subcommands are:";
    for (const std::string& n : names) std::cerr << " " << n;
    std::cerr << "\nRun 'evio --help' or 'evio SUBCOMMAND --help' for more information.\n";
    return 2;
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }
  if (quiet) evio::set_log_level(evio::LogLevel::kWarning);
  if (verbose) evio::set_log_level(evio::LogLevel::kDebug);

  try {
    if (info_cmd->parsed()) {
      apply_dataset_strings(info_format, info_unit, info_bad, &info.dataset);
      info.progress = !quiet;
      return evio::apps::run_info(info, std::cout);
    }
    if (conv_cmd->parsed()) {
      apply_dataset_strings(conv_format, conv_unit, conv_bad, &conv.dataset);
      conv.to = conv_to == "h5" ? evio::apps::ConvertTarget::kH5
                : conv_to == "ecd" ? evio::apps::ConvertTarget::kEcd
                                   : evio::apps::ConvertTarget::kAuto;
      conv.polarity = conv_polarity == "01"    ? evio::PolarityConvention::kZeroOne
                      : conv_polarity == "pm1" ? evio::PolarityConvention::kMinusPlusOne
                                               : evio::PolarityConvention::kUnknown;
      conv.h5_time_unit = conv_h5_unit == "us" ? evio::TimeUnit::kMicroseconds : evio::TimeUnit::kNanoseconds;
      conv.progress = !quiet;
      return evio::apps::run_convert(conv, std::cout);
    }
    if (vio_cmd->parsed()) {
      apply_dataset_strings(vio_format, vio_unit, vio_bad, &vio.dataset_options);
      vio.progress = !quiet;
      return evio::apps::run_vio(vio, std::cout);
    }
    if (mosaic_cmd->parsed()) {
      apply_dataset_strings(mosaic_format, mosaic_unit, mosaic_bad, &mosaic.dataset_options);
      mosaic.progress = !quiet;
      return evio::apps::run_mosaic(mosaic, std::cout);
    }
    if (corners_cmd->parsed()) {
      apply_dataset_strings(corners_format, corners_unit, corners_bad, &corners.dataset_options);
      if (corners_frames_ms >= 0) corners.frames_every_ns = static_cast<int64_t>(std::llround(corners_frames_ms * 1e6));
      corners.progress = !quiet;
      return evio::apps::run_corners(corners, std::cout);
    }
    if (eval_cmd->parsed()) {
      eval.options.alignment.method = *evio::evaluation::alignment_from_name(eval_align);
      eval.read.time_unit = *evio::time_unit_from_name(eval_unit);
      eval.groundtruth_time_unit = *evio::time_unit_from_name(eval_gt_unit);
      eval.read.on_bad_line = eval_bad == "warn" ? evio::BadLinePolicy::kWarnAndSkip : evio::BadLinePolicy::kError;
      return evio::apps::run_eval(eval, std::cout);
    }
    if (sim_cmd->parsed()) {
      simulate.progress = !quiet;
      return evio::apps::run_simulate(simulate, std::cout);
    }
  } catch (const evio::InputError& e) {
    std::fprintf(stderr, "evio: error: %s\n", e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "evio: internal error: %s\n", e.what());
    return 3;
  }
  return 2;
}
