// Fuzzing helpers: the fuzzer's input as an in-memory file (memfd) with a path, so readers that
// open paths are fuzzed end to end without touching the disk.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "evio/calib/log.h"

#include <sys/mman.h>
#include <unistd.h>

namespace evio_fuzz {

// Readers log one line per file opened; drop the log to keep libFuzzer's output readable and fast.
inline void silence_log() {
  static const bool quiet = [] {
    evio::set_log_sink([](evio::LogLevel, const std::string&) {});
    return true;
  }();
  (void)quiet;
}

class MemFile {
 public:
  MemFile(const uint8_t* data, size_t size) {
    fd_ = memfd_create("evio_fuzz", 0);
    if (fd_ < 0) return;
    size_t off = 0;
    while (off < size) {
      const ssize_t n = ::write(fd_, data + off, size - off);
      if (n <= 0) break;
      off += static_cast<size_t>(n);
    }
    path_ = "/proc/self/fd/" + std::to_string(fd_);
  }
  ~MemFile() {
    if (fd_ >= 0) ::close(fd_);
  }
  MemFile(const MemFile&) = delete;
  MemFile& operator=(const MemFile&) = delete;

  bool ok() const { return fd_ >= 0; }
  const std::string& path() const { return path_; }

 private:
  int fd_ = -1;
  std::string path_;
};

}  // namespace evio_fuzz
