#include "evio/calib/plugin.h"

#include <dlfcn.h>
#include <unistd.h>

#include <cstdlib>
#include <map>
#include <mutex>
#include <stdexcept>
#include <vector>

namespace evio {
std::string executable_dir() {
  std::vector<char> buf(4096);
  const ssize_t n = readlink("/proc/self/exe", buf.data(), buf.size() - 1);
  if (n <= 0) return {};
  std::string path(buf.data(), static_cast<size_t>(n));
  const size_t slash = path.rfind('/');
  return slash == std::string::npos ? std::string() : path.substr(0, slash);
}


void* open_plugin(const std::string& file) {
  static std::mutex mutex;
  static std::map<std::string, void*> opened;
  const std::lock_guard<std::mutex> lock(mutex);
  if (auto it = opened.find(file); it != opened.end()) return it->second;
  std::vector<std::string> dirs;
  if (const char* env = std::getenv("EVIO_PLUGIN_DIR"); env != nullptr && *env != '\0') {
    dirs.emplace_back(env);  // the only place looked at when set
  } else {
    const std::string exe = executable_dir();
    if (!exe.empty()) {
      dirs.push_back(exe + "/../lib/evio");
      dirs.push_back(exe + "/../../lib/evio");
    }
    dirs.emplace_back(EVIO_PLUGIN_INSTALL_DIR);
    dirs.emplace_back(EVIO_PLUGIN_BUILD_DIR);
  }
  std::string tried;
  for (const std::string& dir : dirs) {
    std::string path = dir;
    path += '/';
    path += file;
    if (!tried.empty()) tried += ", ";
    tried += path;
    if (access(path.c_str(), R_OK) != 0) continue;
    void* h = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (h == nullptr) {
      const char* e = dlerror();
      throw std::runtime_error("cannot load the plugin " + path + ": " + (e != nullptr ? e : "unknown error"));
    }
    opened[file] = h;
    return h;
  }
  throw std::runtime_error("the plugin " + file + " is missing (looked for " + tried +
                           "); set EVIO_PLUGIN_DIR to the folder that holds it");
}

void* plugin_symbol(void* handle, const std::string& file, const char* name) {
  void* s = dlsym(handle, name);
  if (s == nullptr) throw std::runtime_error("the plugin " + file + " has no symbol " + name);
  return s;
}

}  // namespace evio
