// `evio info PATH`: what a recording holds (format, sensor, duration, events, rates, polarity
// balance, IMU, frames, ground truth, calibration), from one streaming pass.
#pragma once

#include <iosfwd>
#include <string>

#include "evio/sensors/dataset.h"

namespace evio::apps {

struct InfoArgs {
  std::string path;
  DatasetOptions dataset;
  bool json = false;      // print one JSON object instead of the text table
  bool progress = true;   // progress on stderr for files above 64 MiB
};

// Returns the process exit code; writes the report to out. Throws evio::InputError on bad input.
int run_info(const InfoArgs& args, std::ostream& out);

}  // namespace evio::apps
