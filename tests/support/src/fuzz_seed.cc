#include "evio_test/fuzz_seed.h"

#include <atomic>
#include <cstdlib>
#include <filesystem>

#include <unistd.h>

namespace evio_test {

void export_fuzz_seed(const std::string& path, const std::string& target) {
  const char* root = std::getenv("EVIO_FUZZ_SEED_DIR");
  if (root == nullptr || *root == '\0') return;
  namespace fs = std::filesystem;
  std::error_code ec;
  if (!fs::is_regular_file(path, ec) || fs::file_size(path, ec) > (256u << 10)) return;
  static std::atomic<int> counter{0};
  const fs::path dir = fs::path(root) / target;
  fs::create_directories(dir, ec);
  const fs::path dst = dir / ("seed_" + std::to_string(::getpid()) + "_" + std::to_string(counter++) + "_" +
                              fs::path(path).filename().string());
  fs::copy_file(path, dst, fs::copy_options::overwrite_existing, ec);
}

}  // namespace evio_test
