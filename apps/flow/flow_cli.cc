// evio flow: the command line of `evio flow` (run as evio-flow by the `evio` dispatcher).
#include <cmath>
#include <cstdio>
#include <iostream>

#include "cli_common.h"
#include "flow_command.h"

int main(int argc, char** argv) try {
  evio::apps::CommandLine cli("flow");
  evio::apps::FlowArgs flow;
  cli->footer(
      "motion.csv: t_start_s,t_end_s,model,p0,...,contrast_zero,contrast_final,iterations,time_ms, one row per window.\n"
      "p0.. per model: flow vx vy (px/s, undistorted pixels); similarity vx vy (px/s), dilation (1/s), in-plane\n"
      "rotation (rad/s); rotation wx wy wz (rad/s, the camera's angular velocity in the camera frame); 6dof vx vy vz\n"
      "(m/s, camera frame, at cmax.depth_m or the plane) then wx wy wz (rad/s); flow_accel and similarity_accel: those of\n"
      "flow and similarity (velocities at the window's mid-time) then ax ay (px/s^2). contrast_*: the objective at zero\n"
      "motion and at the estimate. With the rotation model and a ground truth (--gt or the dataset's) or IMU:\n"
      "motion_eval.csv (reference angular velocities per window, errors in deg/s).\n"
      "--model auto: per window, every candidate (flow, similarity, and rotation when the camera is calibrated; or the\n"
      "config's candidates) is fitted with one objective (normalized_gradient_magnitude unless --objective) and the\n"
      "simplest wins unless a richer one raises the objective by more than model_gain_per_parameter (default 0.01,\n"
      "relative) per extra parameter, the rule evio segment applies per cluster. motion.csv then has the richest\n"
      "candidate's columns (a window's own parameters first); model_selection.csv: per window the chosen model and\n"
      "each candidate's objective, gain over the simplest and score; stats.json \"model\": windows won per candidate.");
  CLI::Option* dataset_opt = cli->add_option("DATASET", flow.dataset, "Dataset (any format evio reads; sub-pixel ECD text too)");
  CLI::Option* out_opt = cli->add_option("-o,--out", flow.out, "Output folder (created)");
  cli->add_option("--model", flow.model, "Warp model, or auto: choose per window (overrides cmax.model and model_selection; default flow)")
      ->check(CLI::IsMember([] {
        std::vector<std::string> names = {"auto"};
        for (evio::mapping::WarpModel m : evio::mapping::warp_models()) names.push_back(evio::mapping::warp_model_name(m));
        return names;
      }()));
  cli->add_option("--objective", flow.objective,
                  "Objective (overrides cmax.objective): auto = variance for flow and flow_accel, gradient_magnitude for "
                  "rotation, normalized_gradient_magnitude for similarity, similarity_accel and 6dof")
      ->check(CLI::IsMember({"auto", "variance", "mean_square", "gradient_magnitude", "normalized_gradient_magnitude"}));
  cli->add_option_function<std::string>(
      "--t-start", [&flow](const std::string& s) { flow.t_start_ns = evio::apps::parse_seconds_flag("--t-start", s); },
      "First event time, s (absolute file time)");
  cli->add_option_function<std::string>(
      "--t-end", [&flow](const std::string& s) { flow.t_end_ns = evio::apps::parse_seconds_flag("--t-end", s); },
      "Events before this time, s (absolute file time)");
  CLI::Option* we = cli->add_option("--window-events", flow.window_events, "Events per window (overrides window.events)")
                        ->check(CLI::PositiveNumber);
  CLI::Option* wm = cli->add_option_function<double>(
                           "--window-ms",
                           [&flow](const double& ms) { flow.window_ns = static_cast<int64_t>(std::llround(ms * 1e6)); },
                           "Windows of this duration, ms, instead of a number of events (overrides window.duration_ms)")
                        ->check(CLI::PositiveNumber);
  we->excludes(wm);
  cli->add_option("--pyramid-levels", flow.pyramid_levels, "Coarse-to-fine levels (overrides cmax.pyramid_levels)")
      ->check(CLI::Range(1, 8));
  cli->add_option("--config", flow.config, "Flow config YAML: window, undistortion and cmax sections (--print-config lists every key)");
  cli->add_option("--calib", flow.calib,
                  "Calibration: Kalibr camchain .yaml or ECD calib.txt; default: the dataset folder's calib.yaml, else "
                  "the dataset's calibration (the IWE size, the pinhole, the undistortion)");
  cli->add_option("--gt", flow.gt,
                  "Ground truth (TUM or csv) for the rotation model: angular-velocity error per window in "
                  "motion_eval.csv and its RMS in stats.json (default: the dataset's ground truth)");
  cli->add_flag("--png", flow.png, "Write each window's IWE before and after warping to DIR/iwe/ (8-bit, robust scale)");
  cli->add_option("--png-every", flow.png_every, "With --png: every this many windows")->check(CLI::PositiveNumber);
  cli.add_set(&flow.set, "cmax.blur_sigma_px=0.7");
  evio::apps::add_dataset_options(&cli.app(), &flow.dataset_options);
  bool print_config = false;
  cli.add_print_config(&print_config, {dataset_opt, out_opt});
  return cli.run(argc, argv, [&] {
    if (print_config) {
      std::cout << evio::apps::flow_config_text(evio::apps::resolve_flow_config(flow));
      return 0;
    }
    flow.progress = !cli.quiet();
    return evio::apps::run_flow(flow, std::cout);
  });
} catch (const std::exception& e) {  // setting the options up failed (a programming error)
  std::fprintf(stderr, "evio: internal error: %s\n", e.what());
  return 3;
}
