// evio simulate: the command line of `evio simulate` (run as evio-simulate by the `evio` dispatcher).
#include <cstdio>
#include <iostream>

#include "cli_common.h"
#include "simulate_command.h"

int main(int argc, char** argv) try {
  evio::apps::CommandLine cli("simulate");
  evio::apps::SimulateArgs simulate;
  cli->add_option("SCENE", simulate.scene, "Scene YAML (e.g. datasets/poster_6dof.yaml)")->required();
  cli->add_option("-o,--out", simulate.out, "Output folder (created; existing files are overwritten)")->required();
  cli->add_option_function<uint64_t>(
      "--seed", [&simulate](const uint64_t& s) { simulate.overrides.seed = s; },
      "Top-level seed (replaces the YAML's `seed`); every component seed not pinned in the YAML derives from it");
  cli->add_option_function<double>(
         "--duration", [&simulate](const double& d) { simulate.overrides.duration_s = d; },
         "Simulated span in seconds (replaces the YAML's `duration`; file trajectories: from trajectory.start_s)")
      ->check(CLI::PositiveNumber);
  cli->add_option("--set", simulate.overrides.set,
                  "Change one YAML value before parsing: key.sub=value, value in YAML syntax, list entries by "
                  "index (e.g. --set camera.scale=0.25 --set events.contrast_threshold_pos=0.3); repeatable")
      ->expected(1)
      ->multi_option_policy(CLI::MultiOptionPolicy::TakeAll);
  cli->add_option("--threads", simulate.threads,
                  "Render threads (the image is split in row bands); the output is identical for any count")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  return cli.run(argc, argv, [&] {
    simulate.progress = !cli.quiet();
    return evio::apps::run_simulate(simulate, std::cout);
  });
} catch (const std::exception& e) {  // setting the options up failed (a programming error)
  std::fprintf(stderr, "evio: internal error: %s\n", e.what());
  return 3;
}
