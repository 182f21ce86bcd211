// evio reconstruct: the command line of `evio reconstruct` (run as evio-reconstruct by the `evio` dispatcher).
#include <cstdio>
#include <iostream>
#include <string>

#include "cli_common.h"
#include "reconstruct_command.h"

int main(int argc, char** argv) try {
  evio::apps::CommandLine cli("reconstruct");
  evio::apps::ReconstructArgs rec;
  cli->footer(
      "images/frame_NNNNNNNN.png (8-bit, 1st..99th percentile of the log intensity) and .tiff (float32 log intensity)\n"
      "at each requested time, listed in images.txt (`t[s] path`, as in the Event Camera Dataset, so the folder opens\n"
      "as a dataset); stats.json (events, frames fused, images, ns per event and events/s of the filter);\n"
      "reconstruct_config.yaml; video.mp4 with --video when OpenCV has an MP4 encoder; corners.txt with --corners;\n"
      "eval.json for a simulated dataset (--gt): psnr_db, ssim (means over the images), ssim_error, minima, per image.");
  CLI::Option* dataset_opt = cli->add_option("DATASET", rec.dataset, "Dataset (any format evio reads)");
  CLI::Option* out_opt = cli->add_option("-o,--out", rec.out, "Output folder (created)");
  cli->add_option("--method", rec.method,
                  "hf: high-pass filter (events only); cf: complementary filter (ACCV 2018); akf: asynchronous Kalman "
                  "filter (ICCV 2021); gradient: Poisson image of the asynchronous-convolution gradient state (RAL 2019; "
                  "cutoff, contrasts and frames as cf). Default: the config's method (cf)");
  CLI::Option* rate = cli->add_option_function<double>(
                             "--rate", [&rec](const double& hz) { rec.rate_hz = hz; },
                             "Images per second of sensor time from the first event, Hz (default 30; rate_hz)")
                          ->check(CLI::PositiveNumber);
  CLI::Option* at = cli->add_option_function<std::string>(
      "--at",
      [&rec](const std::string& list) {
        std::string word;
        for (char c : list + ",") {
          if (c != ',') {
            word += c;
          } else if (!word.empty()) {
            rec.at_ns.push_back(evio::apps::parse_seconds_flag("--at", word));
            word.clear();
          }
        }
      },
      "Images at these times instead, s (absolute file time), comma-separated: T1,T2,...");
  rate->excludes(at);
  cli->add_flag("--use-frames", rec.use_frames, "Fuse the recording's APS frames (cf, akf)");
  cli->add_option_function<double>(
         "--cutoff-hz", [&rec](const double& f) { rec.cutoff_hz = f; },
         "Complementary / high-pass filter crossover frequency f, Hz (alpha = 2 pi f rad/s; 0: direct integration; "
         "default 0.5)")
      ->check(CLI::NonNegativeNumber);
  cli->add_option_function<double>(
         "--contrast-on", [&rec](const double& c) { rec.contrast_on = c; },
         "Log-intensity step of an ON event (default 0.1)")
      ->check(CLI::PositiveNumber);
  cli->add_option_function<double>(
         "--contrast-off", [&rec](const double& c) { rec.contrast_off = c; },
         "Log-intensity step of an OFF event, positive, subtracted (default 0.1)")
      ->check(CLI::PositiveNumber);
  cli->add_flag("--corners", rec.corners,
                "Also write corners.txt: event Harris corner events (RAL 2019; config section harris), `t[s] x y p` as "
                "`evio corners` writes them");
  CLI::Option* gt_opt = cli->add_option(
      "--gt", rec.gt,
      "Scene YAML the dataset was simulated from (evio simulate's scene_resolved.yaml; default: DATASET/"
      "scene_resolved.yaml when it exists): eval.json scores every image against the clean view rendered at its time "
      "(log(I + log_eps), PSNR in dB and SSIM after a global affine fit; ssim_error = 1 - mean SSIM)");
  cli->add_flag("--no-gt", rec.no_gt, "Do not score against DATASET/scene_resolved.yaml")->excludes(gt_opt);
  cli->add_flag("--video", rec.video, "Also write video.mp4 (OpenCV VideoWriter, mp4v; reported when unavailable)");
  cli->add_option("--config", rec.config, "Reconstruct config YAML: method, cf, akf, frames, display (--print-config lists every key)");
  cli->add_option("--calib", rec.calib, "Calibration (Kalibr camchain .yaml or ECD calib.txt) for the sensor size; default: the dataset's");
  cli.add_set(&rec.set, "frames.gamma=2.2");
  evio::apps::add_dataset_options(&cli.app(), &rec.dataset_options);
  bool print_config = false;
  cli.add_print_config(&print_config, {dataset_opt, out_opt});
  return cli.run(argc, argv, [&] {
    if (print_config) {
      std::cout << evio::apps::reconstruct_config_text(evio::apps::resolve_reconstruct_config(rec));
      return 0;
    }
    rec.progress = !cli.quiet();
    return evio::apps::run_reconstruct(rec, std::cout);
  });
} catch (const std::exception& e) {  // setting the options up failed (a programming error)
  std::fprintf(stderr, "evio: internal error: %s\n", e.what());
  return 3;
}
