// Positional reads (pread) of a binary recording: no shared stream position, so the event stream
// and the side passes (IMU, frames, triggers, index) read one file independently; every error
// names the file, the byte offset and the expected form. Internal to evio::sensors.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

namespace evio::detail {

class BinaryFile {
 public:
  // `form` is the expected form quoted in errors, e.g. "a ROS1 bag v2.0 file". Throws InputError
  // when the path cannot be opened or is not a regular file.
  BinaryFile(const std::string& path, std::string form);
  ~BinaryFile();
  BinaryFile(const BinaryFile&) = delete;
  BinaryFile& operator=(const BinaryFile&) = delete;

  uint64_t size() const { return size_; }
  const std::string& path() const { return path_; }

  // Reads exactly n bytes at byte offset `off`; `what` names them in errors. Throws InputError
  // "truncated file: <what> of n bytes at byte offset off runs past the end of the file (size
  // bytes)" when the range is not inside the file, and a read error naming the offset otherwise.
  void read(uint64_t off, void* dst, size_t n, const char* what) const;

 private:
  std::string path_;
  std::string form_;
  int fd_ = -1;
  uint64_t size_ = 0;
};

}  // namespace evio::detail
