// evio corners: the command line of `evio corners` (run as evio-corners by the `evio` dispatcher).
#include <cmath>
#include <cstdio>
#include <iostream>

#include "cli_common.h"
#include "corners_command.h"

int main(int argc, char** argv) try {
  evio::apps::CommandLine cli("corners");
  evio::apps::CornersArgs corners;
  CLI::Option* dataset_opt = cli->add_option("DATASET", corners.dataset, "Dataset (any format evio reads)");
  CLI::Option* out_opt = cli->add_option("-o,--out", corners.out, "Output folder (created)");
  cli->add_option("--config", corners.config,
                  "YAML with refractory, background_activity, efast, tracker and frames sections (docs/commands/corners.md)");
  cli->add_option("--calib", corners.calib,
                  "Calibration (Kalibr camchain .yaml or ECD calib.txt); default: the dataset folder's calib.yaml, else the dataset's own. Gives the sensor "
                  "size and the undistortion of track positions");
  cli->add_flag("--filter-sae", corners.filter_sae,
                "Filtered SAE: an event updates the SAE (and is tested) only when the pixel's latest event of its "
                "polarity is older than 50 ms (efast.filter_window_ms) or had the other polarity");
  cli->add_option_function<double>(
         "--frames-every-ms",
         [&corners](const double& ms) { corners.frames_every_ns = static_cast<int64_t>(std::llround(ms * 1e6)); },
         "Write a PNG overlay (events, corners, tracks) every N ms of sensor time to DIR/frames/; 0: none "
         "(default: the config's frames.every_ms, else none), ms")
      ->check(CLI::NonNegativeNumber);
  CLI::Option* gt_opt = cli->add_option(
      "--gt", corners.gt,
      "Scene YAML the dataset was simulated from (evio simulate's scene_resolved.yaml; default: DATASET/"
      "scene_resolved.yaml when it exists). When its planes carry checkerboard textures, eval.json scores the corner "
      "events against the grid nodes projected through the true pose: precision (within 2 px), (corner, 50 ms bin) "
      "recall, F = harmonic mean of the two, f_error = 1 - F");
  cli->add_flag("--no-gt", corners.no_gt, "Do not score against DATASET/scene_resolved.yaml")->excludes(gt_opt);
  cli.add_set(&corners.set, "efast.filter_sae=true");
  evio::apps::add_dataset_options(&cli.app(), &corners.dataset_options);
  bool print_config = false;
  cli.add_print_config(&print_config, {dataset_opt, out_opt});
  return cli.run(argc, argv, [&] {
    if (print_config) {
      std::cout << evio::apps::corners_config_text(evio::apps::load_corners_config(corners.config, corners.set));
      return 0;
    }
    corners.progress = !cli.quiet();
    return evio::apps::run_corners(corners, std::cout);
  });
} catch (const std::exception& e) {  // setting the options up failed (a programming error)
  std::fprintf(stderr, "evio: internal error: %s\n", e.what());
  return 3;
}
