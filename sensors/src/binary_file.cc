#include "binary_file.h"

#include <cerrno>
#include <cstring>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include "evio/calib/error.h"

namespace evio::detail {

BinaryFile::BinaryFile(const std::string& path, std::string form) : path_(path), form_(std::move(form)) {
  fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd_ < 0) throw InputError(path, 0, std::string("cannot open: ") + std::strerror(errno), form_);
  struct stat st {};
  if (::fstat(fd_, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd_);
    fd_ = -1;
    throw InputError(path, 0, "not a regular file", form_);
  }
  size_ = static_cast<uint64_t>(st.st_size);
}

BinaryFile::~BinaryFile() {
  if (fd_ >= 0) ::close(fd_);
}

void BinaryFile::read(uint64_t off, void* dst, size_t n, const char* what) const {
  if (off > size_ || n > size_ - off) {
    throw InputError(path_, 0,
                     std::string("truncated file: ") + what + " of " + std::to_string(n) + " bytes at byte offset " +
                         std::to_string(off) + " runs past the end of the file (" + std::to_string(size_) + " bytes)",
                     form_);
  }
  auto* d = static_cast<uint8_t*>(dst);
  size_t done = 0;
  while (done < n) {
    const ssize_t got = ::pread(fd_, d + done, n - done, static_cast<off_t>(off + done));
    if (got < 0 && errno == EINTR) continue;
    if (got <= 0) {
      throw InputError(path_, 0,
                       std::string("read error (") + (got < 0 ? std::strerror(errno) : "unexpected end of file") +
                           ") reading " + what + " at byte offset " + std::to_string(off + done),
                       form_);
    }
    done += static_cast<size_t>(got);
  }
}

}  // namespace evio::detail
