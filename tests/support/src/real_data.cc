#include "evio_test/real_data.h"

#include <cstdlib>
#include <filesystem>

namespace evio_test {

std::optional<std::string> real_data_dir(const std::string& sub) {
  namespace fs = std::filesystem;
  fs::path root;
  if (const char* env = std::getenv("EVIO_REAL_DATA"); env != nullptr && *env != '\0') {
    root = env;
  } else {
    root = fs::path(EVIO_SOURCE_DIR) / ".." / "shared" / "data" / "real";
  }
  const fs::path p = root / sub;
  std::error_code ec;
  if (!fs::exists(p, ec)) return std::nullopt;
  return fs::weakly_canonical(p, ec).string();
}

}  // namespace evio_test
