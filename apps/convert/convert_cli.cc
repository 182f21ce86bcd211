// evio convert: the command line of `evio convert` (run as evio-convert by the `evio` dispatcher).
#include <cstdio>
#include <iostream>

#include "cli_common.h"
#include "convert_command.h"

int main(int argc, char** argv) try {
  using evio::apps::ConvertTarget;
  evio::apps::CommandLine cli("convert");
  evio::apps::ConvertArgs conv;
  cli->add_option("IN", conv.in, "Input dataset (folder or file)")->required();
  cli->add_option("OUT", conv.out, "Output: a folder (ECD layout) or a .h5 file")->required();
  evio::apps::add_dataset_options(&cli.app(), &conv.dataset);
  cli->add_option_function<std::string>(
         "--to",
         [&conv](const std::string& s) {
           conv.to = s == "h5" ? ConvertTarget::kH5 : s == "ecd" ? ConvertTarget::kEcd : ConvertTarget::kAuto;
         },
         "Output format: ecd, h5, or auto (h5 for a .h5/.hdf5 OUT, else ecd)")
      ->check(CLI::IsMember({"auto", "ecd", "h5"}))
      ->default_str("auto");
  cli->add_option_function<std::string>(
      "--t-start",
      [&conv](const std::string& s) { conv.t_start_ns = evio::apps::parse_seconds_flag("--t-start", s); },
      "Keep data with t >= T_START, in seconds of the input's time axis (as `evio info` prints it)");
  cli->add_option_function<std::string>(
      "--t-end", [&conv](const std::string& s) { conv.t_end_ns = evio::apps::parse_seconds_flag("--t-end", s); },
      "Keep data with t < T_END, in seconds of the input's time axis");
  cli->add_option_function<std::string>(
         "--polarity",
         [&conv](const std::string& s) {
           conv.polarity = s == "01"    ? evio::PolarityConvention::kZeroOne
                           : s == "pm1" ? evio::PolarityConvention::kMinusPlusOne
                                        : evio::PolarityConvention::kUnknown;
         },
         "ECD output polarity: 01 (ECD), pm1 (-1/+1), or input (the input's convention; 0/1 for binary formats)")
      ->check(CLI::IsMember({"input", "01", "pm1"}))
      ->default_str("input");
  cli->add_option_function<std::string>(
         "--h5-time-unit",
         [&conv](const std::string& s) {
           conv.h5_time_unit = s == "us" ? evio::TimeUnit::kMicroseconds : evio::TimeUnit::kNanoseconds;
         },
         "HDF5 output time unit: ns (lossless) or us (DSEC, rounds to whole microseconds)")
      ->check(CLI::IsMember({"ns", "us"}))
      ->default_str("ns");
  cli->add_option("--h5-compression", conv.h5_compression, "HDF5 output compression: none, gzip or blosc")
      ->check(CLI::IsMember({"none", "gzip", "blosc"}))
      ->capture_default_str();
  return cli.run(argc, argv, [&] {
    conv.progress = !cli.quiet();
    return evio::apps::run_convert(conv, std::cout);
  });
} catch (const std::exception& e) {  // setting the options up failed (a programming error)
  std::fprintf(stderr, "evio: internal error: %s\n", e.what());
  return 3;
}
