// evio segment: the command line of `evio segment` (run as evio-segment by the `evio` dispatcher).
#include <cmath>
#include <cstdio>
#include <iostream>

#include "cli_common.h"
#include "segment_command.h"

int main(int argc, char** argv) try {
  evio::apps::CommandLine cli("segment");
  evio::apps::SegmentArgs seg;
  cli->footer(
      "labels.txt: `t x y p label`, one line per input event in input order (t in s, p 1 = ON / 0 = OFF, label the\n"
      "cluster id or -1: noise, or an event in no segmented window). segments.json: per window the clusters (id,\n"
      "model, parameters with units, events, objective, gain over the best other motion, models tried) and the\n"
      "cluster-count decisions. images/: per window the clusters' IWEs in their colours, and each cluster's IWE.\n"
      "eval.json (with true labels): events_scored, accuracy, label_error = 1 - accuracy, accuracy_in_windows, per_label.");
  CLI::Option* dataset_opt = cli->add_option("DATASET", seg.dataset, "Dataset (any format evio reads; sub-pixel ECD text too)");
  CLI::Option* out_opt = cli->add_option("-o,--out", seg.out, "Output folder (created)");
  cli->add_option_function<std::string>(
      "--t-start", [&seg](const std::string& s) { seg.t_start_ns = evio::apps::parse_seconds_flag("--t-start", s); },
      "First event time, s (absolute file time)");
  cli->add_option_function<std::string>(
      "--t-end", [&seg](const std::string& s) { seg.t_end_ns = evio::apps::parse_seconds_flag("--t-end", s); },
      "Events before this time, s (absolute file time)");
  CLI::Option* we = cli->add_option("--window-events", seg.window_events, "Events per window (overrides window.events)")
                        ->check(CLI::PositiveNumber);
  CLI::Option* wm = cli->add_option_function<double>(
                           "--window-ms",
                           [&seg](const double& ms) { seg.window_ns = static_cast<int64_t>(std::llround(ms * 1e6)); },
                           "Windows of this duration, ms, instead of a number of events (overrides window.duration_ms)")
                        ->check(CLI::PositiveNumber);
  we->excludes(wm);
  cli->add_option("--clusters", seg.clusters,
                  "auto (the count the scene needs, up to segmentation.max_clusters) or a fixed number of clusters");
  cli->add_option("--models", seg.models,
                  "Candidate warp models, comma-separated (flow, similarity, rotation, 6dof, flow_accel, similarity_accel): each cluster takes the "
                  "simplest that is good enough (overrides segmentation.models; default flow,similarity)");
  cli->add_option("--config", seg.config, "Segment config YAML: window, segmentation and cmax sections (--print-config lists every key)");
  cli->add_option("--calib", seg.calib,
                  "Calibration: Kalibr camchain .yaml or ECD calib.txt; default: the dataset's (the IWE size, the pinhole, "
                  "the undistortion)");
  CLI::Option* gt_opt = cli->add_option(
      "--gt", seg.gt,
      "True per-event labels, one integer per line in the dataset's event order (0 background, 1..N objects, 65535 "
      "noise), e.g. event_labels.txt of `evio simulate`; default: DATASET/event_labels.txt when it exists. Writes "
      "eval.json: accuracy (share of true-labelled events whose cluster maps, per window by majority, to their label)");
  cli->add_flag("--no-gt", seg.no_gt, "Do not score against DATASET/event_labels.txt")->excludes(gt_opt);
  cli->add_flag("--png,!--no-png", seg.png, "Coloured IWE PNGs per window to DIR/images/ (default on)");
  cli->add_option("--png-every", seg.png_every, "PNGs of every this many windows")->check(CLI::PositiveNumber);
  cli.add_set(&seg.set, "segmentation.max_clusters=6");
  evio::apps::add_dataset_options(&cli.app(), &seg.dataset_options);
  bool print_config = false;
  cli.add_print_config(&print_config, {dataset_opt, out_opt});
  return cli.run(argc, argv, [&] {
    if (print_config) {
      std::cout << evio::apps::segment_config_text(evio::apps::resolve_segment_config(seg));
      return 0;
    }
    seg.progress = !cli.quiet();
    return evio::apps::run_segment(seg, std::cout);
  });
} catch (const std::exception& e) {  // setting the options up failed (a programming error)
  std::fprintf(stderr, "evio: internal error: %s\n", e.what());
  return 3;
}
