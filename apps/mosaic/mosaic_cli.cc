// evio mosaic: the command line of `evio mosaic` (run as evio-mosaic by the `evio` dispatcher).
#include <cstdio>
#include <iostream>

#include "cli_common.h"
#include "mosaic_command.h"

int main(int argc, char** argv) try {
  evio::apps::CommandLine cli("mosaic");
  evio::apps::MosaicArgs mosaic;
  CLI::Option* dataset_opt = cli->add_option("DATASET", mosaic.dataset, "Dataset with events (IMU for --use-imu; any format evio reads)");
  CLI::Option* out_opt = cli->add_option("-o,--out", mosaic.out, "Output folder (created)");
  cli->add_option("--config", mosaic.config, "Mosaic config YAML (docs/commands/mosaic.md; --print-config lists every key)");
  cli->add_option("--calib", mosaic.calib,
                  "Calibration: Kalibr camchain .yaml or ECD calib.txt; default: the dataset folder's calib.yaml, "
                  "else the dataset's calibration");
  cli->add_flag("--use-imu", mosaic.use_imu, "Drive the particles and the bootstrap with the gyro");
  cli->add_option("--particles", mosaic.particles, "Particles (overrides tracker.particles)")
      ->check(CLI::PositiveNumber);
  cli->add_option("--batch", mosaic.batch, "Events per particle-filter update (overrides tracker.batch_size)")
      ->check(CLI::PositiveNumber);
  cli->add_option("--stride", mosaic.stride, "One event in this many weighs the particles (overrides tracker.event_stride)")
      ->check(CLI::PositiveNumber);
  cli->add_option("--width", mosaic.width, "Mosaic width in px; height = width / 2 (overrides mosaic.width)")
      ->check(CLI::Range(8, 32768));
  cli->add_option("--threads", mosaic.threads,
                  "1, or 2: the mapper (gradient EKF, Poisson solves) on a second thread; identical output "
                  "(overrides mosaic.threads)")
      ->check(CLI::Range(1, 2));
  cli->add_option("--snapshots-every", mosaic.snapshot_s, "Write snapshots/panorama_NNNNNN.png every this many s")
      ->check(CLI::NonNegativeNumber);
  cli->add_option("--gt", mosaic.gt,
                  "Ground truth (TUM or csv): rotation error after aligning the initial orientation into eval.json "
                  "(and PSNR/SSIM against the true panorama of a simulated dataset)");
  cli->add_flag("--gt-bootstrap", mosaic.gt_bootstrap,
                "Diagnostic: the bootstrap maps with the --gt rotations (no bootstrap error; needs --gt)");
  cli->add_flag("--gt-mapping", mosaic.gt_mapping,
                "Diagnostic: the --gt rotations map every event, the bootstrap's and the tracked ones, so the map "
                "carries no tracking error (implies --gt-bootstrap; needs --gt)");
  cli->add_flag("--oracle-map", mosaic.oracle_map,
                "Diagnostic: the tracker weighs its particles against the true panorama (a dataset written by evio "
                "simulate with a panorama scene, rendered in the mosaic frame by the --gt start pose) instead of the "
                "mosaic's reconstructions; no map error (needs --gt)");
  cli.add_set(&mosaic.set, "tracker.particles=200");
  evio::apps::add_dataset_options(&cli.app(), &mosaic.dataset_options);
  bool print_config = false;
  cli.add_print_config(&print_config, {dataset_opt, out_opt});
  return cli.run(argc, argv, [&] {
    if (print_config) {
      std::cout << evio::apps::mosaic_config_text(evio::apps::load_mosaic_config(mosaic.config, nullptr, mosaic.set));
      return 0;
    }
    mosaic.progress = !cli.quiet();
    return evio::apps::run_mosaic(mosaic, std::cout);
  });
} catch (const std::exception& e) {  // setting the options up failed (a programming error)
  std::fprintf(stderr, "evio: internal error: %s\n", e.what());
  return 3;
}
