// Tests of the commands on simulated data: `evio simulate` of a datasets/ scene into a temp folder.
#pragma once

#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "evio_test/temp_dir.h"
#include "simulate_command.h"

namespace evio::apps {

// Simulates `duration_s` of datasets/<scene> (with --set `sets`) into dir/<name>; returns the folder.
// A failed simulation is a test failure (the folder is returned anyway).
inline std::string simulate_scene(const evio_test::TempDir& dir, const std::string& scene, double duration_s,
                                  const std::vector<std::string>& sets = {}, const std::string& name = "seq") {
  SimulateArgs sa;
  sa.scene = std::string(EVIO_SOURCE_DIR) + "/datasets/" + scene;
  sa.out = dir.file(name);
  sa.overrides.duration_s = duration_s;
  sa.overrides.set = sets;
  sa.progress = false;
  std::ostringstream so;
  EXPECT_EQ(run_simulate(sa, so), 0) << so.str();
  return sa.out;
}

}  // namespace evio::apps
