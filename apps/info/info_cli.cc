// evio info: the command line of `evio info` (run as evio-info by the `evio` dispatcher).
#include <cstdio>
#include <iostream>

#include "cli_common.h"
#include "info_command.h"

int main(int argc, char** argv) try {
  evio::apps::CommandLine cli("info");
  evio::apps::InfoArgs info;
  cli->add_option("PATH", info.path, "Dataset folder (ECD layout) or events text file")->required();
  evio::apps::add_dataset_options(&cli.app(), &info.dataset);
  cli->add_flag("--json", info.json, "Print one JSON object instead of the table");
  return cli.run(argc, argv, [&] {
    info.progress = !cli.quiet();
    return evio::apps::run_info(info, std::cout);
  });
} catch (const std::exception& e) {  // setting the options up failed (a programming error)
  std::fprintf(stderr, "evio: internal error: %s\n", e.what());
  return 3;
}
