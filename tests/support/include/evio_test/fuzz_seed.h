// Fuzz seeds from the tests: when $EVIO_FUZZ_SEED_DIR is set, small files the tests write are
// copied to $EVIO_FUZZ_SEED_DIR/<fuzz target>/ so scripts/fuzz.sh starts from valid inputs of
// every kind (a cut of a real recording is a poor seed: its index points past the cut).
#pragma once

#include <string>

namespace evio_test {

// Copies `path` into $EVIO_FUZZ_SEED_DIR/<target>/ when the variable is set and the file is at
// most 256 KiB; does nothing otherwise.
void export_fuzz_seed(const std::string& path, const std::string& target);

}  // namespace evio_test
