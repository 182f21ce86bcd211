// evio eval: the command line of `evio eval` (run as evio-eval by the `evio` dispatcher).
#include <cstdlib>
#include <cstdio>
#include <iostream>

#include "cli_common.h"
#include "eval_command.h"

namespace {

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

int main(int argc, char** argv) try {
  evio::apps::CommandLine cli("eval");
  evio::apps::EvalArgs eval;
  cli->add_option("GT", eval.groundtruth,
                  "Ground truth: TUM `t x y z qx qy qz qw` (t in s) or csv with a header (EuRoC/mocap, t in ns)")
      ->required();
  cli->add_option("EST", eval.estimates, "Estimated trajectories (same formats), one or more")->required();
  cli->add_option_function<std::string>(
         "--align",
         [&eval](const std::string& s) { eval.options.alignment.method = *evio::evaluation::alignment_from_name(s); },
         "Alignment of each estimate to the ground truth: none, se3 (Umeyama), sim3 (Umeyama with scale), posyaw "
         "(translation + yaw, the 4 unobservable DoF of VIO), first_pose (the first pair's poses: for a camera turning "
         "in place, where a fit to positions follows their errors)")
      ->check(CLI::IsMember({"none", "se3", "sim3", "posyaw", "first_pose"}))
      ->default_str("se3");
  cli->add_option("--align-first-s", eval.options.alignment.first_s,
                  "Fit the alignment on the pairs of the first S seconds only (0: all pairs), s")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cli->add_option("--align-first-n", eval.options.alignment.first_poses,
                  "Fit the alignment on the first N pairs only (0: all pairs)")
      ->capture_default_str();
  cli->add_option("--max-dt", eval.options.association.max_dt_s,
                  "Largest time difference of an estimate/ground-truth pair, s")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  cli->add_option("--time-offset", eval.options.association.time_offset_s,
                  "Added to the estimate's stamps before matching, s")
      ->capture_default_str();
  cli->add_flag("--interpolate", eval.options.association.interpolate_groundtruth,
                "Interpolate the ground truth at each estimate stamp instead of taking the nearest pose");
  cli->add_option_function<std::string>(
      "--rpe-lengths", [&eval](const std::string& s) { parse_rpe_lengths(s, &eval.options.rpe); },
      "Sub-trajectory lengths of the relative error: 10,20,30,40,50% (of the ground-truth path length, the "
      "default) or metres, e.g. 5,10,20m");
  cli->add_option("--rre-interval", eval.rre_interval_s,
                  "Relative rotation error over this interval (from every 5th estimate pose), s; 0: off")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  cli->add_option("--imu", eval.imu,
                  "IMU of the recording (any dataset evio reads, e.g. the ECD folder or its imu.txt): the RRE of the "
                  "measured gyro integrated alone over the same intervals, the reference for the estimate's RRE");
  cli->add_option("-o,--out", eval.out,
                  "Output folder: results.json, summary.{csv,yaml,json,tex}, per-estimate aligned TUM and error csv");
  cli->add_option("--plot", eval.plot,
                  "Plot folder: runs scripts/plot_trajectory.py (/usr/bin/python3 with numpy and matplotlib) on the "
                  "outputs (written to --out, or here without --out); PNG and PDF");
  cli->add_option("--label", eval.labels,
                  "Method label per estimate, in order (runs of one method share a label); summaries group by label "
                  "(default: each file is its own method)")
      ->expected(1)
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
  cli->add_option_function<std::string>(
         "--on-bad-line",
         [&eval](const std::string& s) {
           eval.read.on_bad_line = s == "warn" ? evio::BadLinePolicy::kWarnAndSkip : evio::BadLinePolicy::kError;
         },
         "What to do with a malformed, non-finite, out-of-order or non-unit-quaternion line: error = stop with "
         "file, line and expected form; warn = skip it and report counts")
      ->check(CLI::IsMember({"error", "warn"}))
      ->default_str("error");
  cli->add_option_function<std::string>(
         "--time-unit", [&eval](const std::string& s) { eval.read.time_unit = *evio::time_unit_from_name(s); },
         "Unit of the estimates' time column: s, ms, us, ns; auto = a unit tag in a header comment, else a decimal "
         "point means s, integers mean us (ns above 1e17 or when all are multiples of 1000)")
      ->check(evio::apps::time_unit_check())
      ->default_str("auto");
  cli->add_option_function<std::string>(
         "--gt-time-unit",
         [&eval](const std::string& s) { eval.groundtruth_time_unit = *evio::time_unit_from_name(s); },
         "Unit of the ground truth's time column (as --time-unit)")
      ->check(evio::apps::time_unit_check())
      ->default_str("auto");
  cli->add_flag_callback(
      "--no-time-unit-check", [&eval] { eval.read.check_time_unit = false; },
      "Accept a time unit even when the first poses imply a rate outside 0.1 Hz..100 kHz");
  cli->add_option("--python", eval.python, "Python interpreter for --plot")->capture_default_str();
  return cli.run(argc, argv, [&] { return evio::apps::run_eval(eval, std::cout); });
} catch (const std::exception& e) {  // setting the options up failed (a programming error)
  std::fprintf(stderr, "evio: internal error: %s\n", e.what());
  return 3;
}
