// Locating the optional real recordings used by tests (see shared/data/README.md). Tests that
// need them call real_data_dir() and GTEST_SKIP() with a message when it returns nothing.
#pragma once

#include <optional>
#include <string>

namespace evio_test {

// Path of <root>/<sub> where root is $EVIO_REAL_DATA if set, else <repo>/../shared/data/real.
// Empty when that path does not exist.
std::optional<std::string> real_data_dir(const std::string& sub);

}  // namespace evio_test
