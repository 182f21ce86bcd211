// Whole-simulation benchmark: runs the simulator on a scene config of datasets/ (default: the
// poster_6dof motion-capture replay at DAVIS240C) without writing files, and reports generated
// events per second of wall time and the real-time factor (simulated s / wall s, > 1 = faster
// than real time) on one core, with the share of rendering and event generation.
//
//   bench_simulate [--config datasets/poster_6dof_mocap.yaml] [--duration S] [--max-flow-px P] [--threads N]
//
// --threads N renders in N row bands (default 1: the one-core figure).
//
// Prints a human summary and one JSON line.
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

#include "evio/simulator/simulator.h"
#include "evio/simulator/scene_config.h"

int main(int argc, char** argv) {
  std::string config = std::string(EVIO_SOURCE_DIR) + "/datasets/poster_6dof_mocap.yaml";
  evio::simulator::SimulateOverrides overrides;
  double max_flow_px = -1;
  int threads = 1;
  for (int i = 1; i + 1 < argc; i += 2) {
    if (!std::strcmp(argv[i], "--config")) {
      config = argv[i + 1];
    } else if (!std::strcmp(argv[i], "--duration")) {
      overrides.duration_s = std::atof(argv[i + 1]);
    } else if (!std::strcmp(argv[i], "--threads")) {
      threads = std::atoi(argv[i + 1]);
    } else if (!std::strcmp(argv[i], "--max-flow-px")) {
      max_flow_px = std::atof(argv[i + 1]);
    } else {
      std::fprintf(stderr, "usage: %s [--config FILE] [--duration S] [--max-flow-px P] [--threads N]\n", argv[0]);
      return 2;
    }
  }
  try {
    evio::simulator::SimulationConfig cfg = evio::simulator::load_simulation_config(config, overrides);
    if (max_flow_px >= 0) cfg.simulator.stepping.max_flow_px = max_flow_px;
    cfg.simulator.threads = threads;
    evio::simulator::Simulator sim(cfg.scene, cfg.trajectory, cfg.simulator);
    const evio::simulator::SimulationStats s = sim.run(nullptr);
    const double sim_s = s.simulated_ns * 1e-9;
    std::printf("%s: %.2f s simulated at %dx%d, %llu events (%.2f Mev/s of sequence), %llu steps, wall %.2f s "
                "(render %.2f s, events %.2f s)\n  generated %.2f Mev/s of wall time, real-time factor %.2f\n",
                config.c_str(), sim_s, cfg.simulator.camera.width(), cfg.simulator.camera.height(),
                static_cast<unsigned long long>(s.events), s.events / sim_s * 1e-6,
                static_cast<unsigned long long>(s.steps), s.wall_s, s.render_s, s.events_s, s.events / s.wall_s * 1e-6,
                sim_s / s.wall_s);
    std::printf("{\"benchmark\": \"simulate\", \"config\": \"%s\", \"simulated_s\": %.3f, \"events\": %llu, "
                "\"steps\": %llu, \"wall_s\": %.3f, \"render_s\": %.3f, \"events_s\": %.3f, "
                "\"events_per_wall_s\": %.0f, \"real_time_factor\": %.3f, \"max_flow_px\": %.3f, \"threads\": %d}\n",
                config.c_str(), sim_s, static_cast<unsigned long long>(s.events),
                static_cast<unsigned long long>(s.steps), s.wall_s, s.render_s, s.events_s, s.events / s.wall_s,
                sim_s / s.wall_s, cfg.simulator.stepping.max_flow_px, threads);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_simulate: %s\n", e.what());
    return 1;
  }
  return 0;
}
