// evio vio: the command line of `evio vio` (run as evio-vio by the `evio` dispatcher).
#include <cstdio>
#include <iostream>

#include "cli_common.h"
#include "vio_command.h"

int main(int argc, char** argv) try {
  evio::apps::CommandLine cli("vio");
  evio::apps::VioArgs vio;
  CLI::Option* dataset_opt = cli->add_option("DATASET", vio.dataset, "Dataset with events and IMU (any format evio reads)");
  CLI::Option* out_opt = cli->add_option("-o,--out", vio.out, "Output folder (created)");
  cli->add_option("--config", vio.config, "VIO config YAML (docs/commands/vio.md; examples in datasets/vio/*.yaml; --print-config lists every key)");
  cli->add_option("--calib", vio.calib,
                  "Calibration: Kalibr camchain .yaml (with imu0 noise) or ECD calib.txt; default: the dataset "
                  "folder's calib.yaml, else the dataset's calibration");
  cli->add_option("--gt", vio.gt,
                  "Ground truth (TUM or csv): evaluate at the end (SE3 alignment on the first 5 s) into eval.json");
  cli->add_flag("--gt-align-first-pose", vio.gt_align_first_pose,
                "With --gt: align the first pose instead (for a camera turning in place with a few cm of translation, "
                "where a fit to positions follows their errors)");
  cli->add_option("--oracle-tracks", vio.oracle_scene,
                  "Error budget on a simulated sequence: SCENE.yaml it was simulated from, or the meta.json of a "
                  "crosscheck-simulator room sequence (needs --gt). The estimator sees the true projections of the "
                  "front-end's tracks (same tracks, lifetimes and frames)");
  cli->add_option("--oracle-noise-px", vio.oracle_noise_px,
                  "With --oracle-tracks: white Gaussian noise added per axis (px on the ideal pinhole)")
      ->check(CLI::NonNegativeNumber);
  cli->add_option("--oracle-drift-px", vio.oracle_drift_px,
                  "With --oracle-tracks: random-walk drift per track, Gaussian step per axis and frame (px)")
      ->check(CLI::NonNegativeNumber);
  cli->add_option("--oracle-error", vio.oracle_error,
                  "With --oracle-tracks: what the estimator keeps of the front-end's own error (observed minus true "
                  "projection): none, real (all of it), independent (each frame's common mode, the per-axis median, "
                  "removed) or common_mode (that median alone)")
      ->check(CLI::IsMember({"none", "real", "independent", "common_mode"}));
  cli->add_flag("--oracle-frame-motion", vio.oracle_frame_motion,
                "With --oracle-tracks: the event frames' translation compensation (frames.use_depth) takes the true "
                "camera-centre velocity at each frame's stamp and the true median depth of the latest tracked frame's "
                "tracks instead of the estimate's");
  cli->add_flag("--oracle-frame-plane", vio.oracle_frame_plane,
                "With --oracle-frame-motion: each event's depth from the least-squares plane through the true scene "
                "points of the frame's tracks instead of their median depth");
  cli->add_option("--dump-tracking-images", vio.dump_tracking_images,
                  "Write every N-th image the frames front-end tracks (event frame or reconstruction, undistorted) to "
                  "OUT/tracking_images/ as PNG (0: none)")
      ->check(CLI::NonNegativeNumber);
  cli->add_flag("--oracle-observations", vio.oracle_observations,
                "With --oracle-error real, independent or common_mode: write every observation's own error, its frame's "
                "common mode and the truth it is measured against to OUT/oracle_observations.csv (one row per observation; "
                "columns in the file's header)");
  cli->add_option("--oracle-max-error-px", vio.oracle_max_error_px,
                  "With --oracle-error real or independent: drop observations whose own error is larger (px; 0 = keep "
                  "all)")
      ->check(CLI::NonNegativeNumber);
  cli.add_set(&vio.set, "frames.events_per_frame=20000");
  evio::apps::add_dataset_options(&cli.app(), &vio.dataset_options);
  bool print_config = false;
  cli.add_print_config(&print_config, {dataset_opt, out_opt});
  return cli.run(argc, argv, [&] {
    if (print_config) {
      std::cout << evio::apps::vio_config_text(evio::apps::load_vio_config(vio.config, nullptr, vio.set));
      return 0;
    }
    vio.progress = !cli.quiet();
    return evio::apps::run_vio(vio, std::cout);
  });
} catch (const std::exception& e) {  // setting the options up failed (a programming error)
  std::fprintf(stderr, "evio: internal error: %s\n", e.what());
  return 3;
}
