// make_ecd_sequence DIR [EVENTS] [RATE_HZ]: writes the synthetic ECD sequence of make_ecd_sequence.h.
#include <cstdio>
#include <cstdlib>
#include <exception>

#include "make_ecd_sequence.h"

int main(int argc, char** argv) {
  if (argc < 2 || argc > 4) {
    std::fprintf(stderr, "usage: %s DIR [EVENTS=100000] [RATE_HZ=1e6]\n", argv[0]);
    return 2;
  }
  evio::bench::SequenceSpec spec;
  if (argc > 2) spec.events = std::atoll(argv[2]);
  if (argc > 3) spec.event_rate_hz = std::atof(argv[3]);
  if (spec.events < 0 || !(spec.event_rate_hz > 0)) {
    std::fprintf(stderr, "EVENTS must be >= 0 and RATE_HZ > 0\n");
    return 2;
  }
  try {
    std::printf("%s\n", evio::bench::make_ecd_sequence(argv[1], spec).c_str());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "make_ecd_sequence: %s\n", e.what());
    return 1;
  }
  return 0;
}
