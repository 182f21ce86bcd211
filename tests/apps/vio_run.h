// Tests of `evio vio` on simulated data: one run of the command with a config, printing its summary.
#pragma once

#include <cstdio>
#include <cstdlib>
#include <utility>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "vio_command.h"

namespace evio::apps {

// datasets/vio/simulator.yaml: tight bias priors for the simulated IMU, which starts at zero bias.
inline const std::string kSimulatorConfig = std::string(EVIO_SOURCE_DIR) + "/datasets/vio/simulator.yaml";

// `evio vio DATASET --out OUT --gt DATASET/groundtruth.txt` with `config` ("" = the library
// defaults); prints its summary, a non-zero exit is a test failure; returns the args.
inline VioArgs vio_on(const std::string& dataset, const std::string& out, const std::string& config = kSimulatorConfig) {
  VioArgs va;
  va.config = config;
  va.dataset = dataset;
  va.out = out;
  va.gt = dataset + "/groundtruth.txt";
  va.progress = false;
  std::ostringstream o;
  EXPECT_EQ(run_vio(va, o), 0) << dataset;
  std::printf("%s", o.str().c_str());
  return va;
}

// A sequence of the crosscheck simulator (scripts/crosscheck_generate.sh PRESET SEED [--set ...]
// in `args`, `duration_s` long, uncached) into `out`; returns the script's exit code (77: the
// simulator is not available; its log is out + ".log").
inline int crosscheck_generate(const std::string& out, const std::string& args, double duration_s) {
  const std::string script = std::string(EVIO_SOURCE_DIR) + "/scripts/crosscheck_generate.sh";
  const int rc = std::system(("EVIO_CROSSCHECK_CACHE= " + script + " " + out + " " + args + " --duration " +
                              std::to_string(duration_s) + " > " + out + ".log 2>&1").c_str());
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

}  // namespace evio::apps
