// `evio convert IN OUT`: any readable dataset to an Event Camera Dataset text folder or an evio
// HDF5 file (DSEC layout), optionally sliced to [t_start, t_end), streaming in bounded memory.
#pragma once

#include <cstdint>
#include <iosfwd>
#include <optional>
#include <string>

#include "evio/sensors/dataset.h"

namespace evio::apps {

enum class ConvertTarget { kAuto, kEcd, kH5 };  // kAuto: ".h5"/".hdf5" OUT -> kH5, else kEcd

struct ConvertArgs {
  std::string in;
  std::string out;
  DatasetOptions dataset;
  ConvertTarget to = ConvertTarget::kAuto;
  std::optional<int64_t> t_start_ns;  // keep t >= t_start (absolute file time, ns)
  std::optional<int64_t> t_end_ns;    // keep t < t_end (absolute file time, ns)
  // ECD output: polarity written as 0/1 (ECD) or -1/+1; kUnknown = the input's convention.
  PolarityConvention polarity = PolarityConvention::kUnknown;
  TimeUnit h5_time_unit = TimeUnit::kNanoseconds;  // h5 output: ns (lossless) or us (DSEC, rounds)
  std::string h5_compression = "none";               // h5 output: none | gzip | blosc
  bool progress = true;                              // progress on stderr for long inputs
};

// Returns the exit code; prints a summary to out. Throws evio::InputError on bad input.
int run_convert(const ConvertArgs& args, std::ostream& out);

}  // namespace evio::apps
