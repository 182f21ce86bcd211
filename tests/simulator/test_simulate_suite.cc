// Keeps the scene suite in datasets/ from rotting: every datasets/*.yaml parses, builds its
// textures, scene and trajectory, and is accepted by the simulator (constructed, not run); the
// situations the suite promises are all there. The motion-capture replay needs
// ../shared/data/real/trajectories and is checked only when that folder is present.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio/simulator/simulator.h"
#include "evio_test/real_data.h"
#include "evio/simulator/scene_config.h"

namespace evio::simulator {
namespace {
namespace fs = std::filesystem;

std::vector<fs::path> suite_files() {
  std::vector<fs::path> files;
  for (const auto& entry : fs::directory_iterator(fs::path(EVIO_SOURCE_DIR) / "datasets")) {
    if (entry.path().extension() == ".yaml") files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  return files;
}

TEST(SimulateSuite, HoldsEverySituationOfTheIssue) {
  std::set<std::string> names;
  for (const fs::path& p : suite_files()) names.insert(p.stem().string());
  for (const char* expected :
       {"shapes_rotation", "shapes_translation", "shapes_6dof", "poster_rotation", "poster_translation", "poster_6dof",
        "boxes_rotation", "boxes_translation", "boxes_6dof", "poster_6dof_mocap", "dynamic_3objects", "spin_1000dps",
        "static_noise", "hdr_1e4"}) {
    EXPECT_EQ(names.count(expected), 1u) << "datasets/" << expected << ".yaml is missing";
  }
}

TEST(SimulateSuite, EveryConfigParsesAndBuildsItsObjects) {
  set_log_sink([](LogLevel, const std::string&) {});
  const bool have_mocap = evio_test::real_data_dir("trajectories").has_value();
  int built = 0;
  for (const fs::path& p : suite_files()) {
    SCOPED_TRACE(p.string());
    SimulateOverrides o;
    // The replays of ../shared/data/real/trajectories/poster_6dof_mocap.csv (poster_6dof_mocap,
    // poster_rotation_mocap).
    const std::string stem = p.stem().string();
    const bool mocap = stem.size() > 6 && stem.compare(stem.size() - 6, 6, "_mocap") == 0;
    if (mocap) {
      if (!have_mocap) {
        std::printf("skipping %s: ../shared/data/real/trajectories not present\n", p.string().c_str());
        continue;
      }
      // The real data may live elsewhere ($EVIO_REAL_DATA); fit only 2 s to stay fast.
      o.set = {"trajectory.path=" + *evio_test::real_data_dir("trajectories") + "/poster_6dof_mocap.csv"};
      o.duration_s = 2.0;
    }
    try {
      const SimulationConfig c = load_simulation_config(p.string(), o);
      EXPECT_FALSE(c.description.empty());
      ASSERT_TRUE(c.scene);
      ASSERT_TRUE(c.trajectory);
      EXPECT_GT(c.duration_s, 0);
      // The suite is at DAVIS resolution: DAVIS240C, or DAVIS346 (room_6dof).
      const int w = c.simulator.camera.width(), h = c.simulator.camera.height();
      EXPECT_TRUE((w == 240 && h == 180) || (w == 346 && h == 260)) << w << "x" << h;
      if (mocap) {
        ASSERT_TRUE(c.fit_report.has_value());
        // Sanity bounds for the replay config (the fit's accuracy itself is tested in
        // tests/sensors): the rms stays sub-millimetre / sub-0.2 degree.
        EXPECT_LT(c.fit_report->position_rms_m, 1e-3);
        EXPECT_LT(c.fit_report->rotation_rms_deg, 0.2);
      }
      const Simulator simulator(c.scene, c.trajectory, c.simulator);
      // The first view renders: finite, positive intensities.
      const simulator::RenderedView view = simulator.render(c.simulator.t_begin_ns, false);
      double lo = 0, hi = 0;
      cv::minMaxLoc(view.intensity, &lo, &hi);
      EXPECT_GE(lo, 0.0);
      EXPECT_GT(hi, 0.0);
      ++built;
    } catch (const std::exception& e) {
      ADD_FAILURE() << e.what();
    }
  }
  EXPECT_GE(built, 13);
  set_log_sink({});
}

}  // namespace
}  // namespace evio::simulator
