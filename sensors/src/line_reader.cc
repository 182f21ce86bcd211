#include "evio/sensors/line_reader.h"

#include <cerrno>
#include <sys/stat.h>

#include "evio/calib/error.h"

namespace evio {

LineReader::LineReader(std::string path, size_t chunk_bytes, size_t max_line_bytes)
    : path_(std::move(path)), max_line_bytes_(max_line_bytes) {
  struct stat st {};
  if (::stat(path_.c_str(), &st) != 0) {
    throw InputError(path_, 0, std::string("cannot open: ") + std::strerror(errno), "a readable text file");
  }
  if (S_ISDIR(st.st_mode)) throw InputError(path_, 0, "is a directory", "a readable text file");
  file_ = std::fopen(path_.c_str(), "rb");
  if (file_ == nullptr) {
    throw InputError(path_, 0, std::string("cannot open: ") + std::strerror(errno), "a readable text file");
  }
  file_size_ = static_cast<uint64_t>(st.st_size);
  buf_.resize(std::max(chunk_bytes, max_line_bytes_ + 1));
  pos_ = end_ = buf_.data();
}

LineReader::~LineReader() {
  if (file_ != nullptr) std::fclose(file_);
}

bool LineReader::refill() {
  if (eof_) return false;
  const size_t rest = static_cast<size_t>(end_ - pos_);
  if (rest > max_line_bytes_) {
    throw InputError(path_, line_ + 1,
                     "line longer than " + std::to_string(max_line_bytes_) + " bytes (binary file read as text?)",
                     "a text file with one record per line");
  }
  std::memmove(buf_.data(), pos_, rest);
  const size_t got = std::fread(buf_.data() + rest, 1, buf_.size() - rest, file_);
  if (got == 0) {
    if (std::ferror(file_)) throw InputError(path_, line_ + 1, "read error", "a readable text file");
    eof_ = true;
  }
  file_offset_ += got;
  pos_ = buf_.data();
  end_ = buf_.data() + rest + got;
  return got > 0;
}

bool LineReader::take_last(std::string_view* line) {
  if (pos_ == end_) return false;
  const char* b = pos_;
  const char* e = end_;
  if (e > b && e[-1] == '\r') --e;
  pos_ = end_;
  ++line_;
  *line = std::string_view(b, static_cast<size_t>(e - b));
  return true;
}

}  // namespace evio
