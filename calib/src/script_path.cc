#include "evio/calib/script_path.h"

#include <filesystem>
#include <vector>

#ifndef EVIO_SCRIPTS_DIR
#define EVIO_SCRIPTS_DIR ""
#endif

namespace evio {
namespace fs = std::filesystem;

std::string find_evio_script(const std::string& name, const std::string& given) {
  if (!given.empty()) return given;
  std::vector<fs::path> candidates;
  if (std::string(EVIO_SCRIPTS_DIR).size() > 0) candidates.push_back(fs::path(EVIO_SCRIPTS_DIR) / name);
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  // Installed: <prefix>/libexec/evio/evio-<name> (or a program in <prefix>/bin) -> <prefix>/share/evio/scripts.
  if (!ec) {
    for (const fs::path& prefix : {exe.parent_path().parent_path().parent_path(), exe.parent_path().parent_path()}) {
      candidates.push_back(prefix / "share" / "evio" / "scripts" / name);
    }
  }
  for (const fs::path& c : candidates) {
    if (fs::exists(c, ec)) return c.string();
  }
  return {};
}

}  // namespace evio
