// What every evio subcommand program (<name>_cli.cc, run as evio-<name> by the `evio` dispatcher)
// shares: the CLI11 app with the global flags, the dataset-reading flags, time flags, and the run
// wrapper that maps errors to exit codes (0 success, 1 bad input with file, line and expected form
// on one line of stderr, 2 usage error, 3 internal error). CLI11 is included only by the *_cli.cc
// programs and this file.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "evio/sensors/dataset.h"

namespace evio::apps {

class CommandLine {
 public:
  // name: the subcommand, e.g. "vio"; the help shows "evio vio" and its summary from subcommands.h.
  explicit CommandLine(const char* name);

  CLI::App& app() { return app_; }
  CLI::App* operator->() { return &app_; }
  bool quiet() const { return quiet_; }

  // --print-config: print the resolved config (the defaults with --config and --set applied, every
  // key with its unit and range) and exit; the options in `needed` are required only without it.
  void add_print_config(bool* flag, const std::vector<CLI::Option*>& needed);
  // --set key.sub=value (repeatable, applied after --config, in order) into *sets; example: a
  // key=value of this command's config for the help.
  void add_set(std::vector<std::string>* sets, const std::string& example);

  // Parses argv (the dispatcher passes everything after `evio` except the subcommand's name) and
  // runs body; returns the process exit code.
  int run(int argc, char** argv, const std::function<int()>& body);

 private:
  CLI::App app_;
  bool quiet_ = false;
  bool verbose_ = false;
};

// Flags shared by every command that reads a dataset: --format, --time-unit, --sensor,
// --on-bad-line, --no-time-unit-check and the ROS bag topics; they fill *opts as they are parsed.
void add_dataset_options(CLI::App* cmd, DatasetOptions* opts);

// "12.5" (seconds as text) -> exact int64 ns (no detour through double); a CLI11 ValidationError
// naming the flag otherwise.
int64_t parse_seconds_flag(const std::string& flag, const std::string& s);

// A time unit flag's value ("auto", "s", "ms", "us", "ns").
CLI::Validator time_unit_check();

}  // namespace evio::apps
