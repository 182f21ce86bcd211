// evio corners: the command line of `evio corners` (run as evio-corners by the `evio` dispatcher).
#include <cmath>
#include <iostream>

#include "cli_common.h"
#include "corners_command.h"

int main(int argc, char** argv) {
  evio::apps::CommandLine cli("corners");
  evio::apps::CornersArgs corners;
  cli->add_option("DATASET", corners.dataset, "Dataset (any format evio reads)")->required();
  cli->add_option("-o,--out", corners.out, "Output folder (created)")->required();
  cli->add_option("--config", corners.config,
                  "YAML with refractory, background_activity, efast, tracker and frames sections (README.md)");
  cli->add_option("--calib", corners.calib,
                  "Calibration (Kalibr camchain .yaml or ECD calib.txt); default: the dataset's own. Gives the sensor "
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
  evio::apps::add_dataset_options(&cli.app(), &corners.dataset_options);
  return cli.run(argc, argv, [&] {
    corners.progress = !cli.quiet();
    return evio::apps::run_corners(corners, std::cout);
  });
}
