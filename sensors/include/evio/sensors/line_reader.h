// Buffered line reader for large text files: reads fixed-size chunks, hands out lines as
// string_views into its buffer (no copy, no iostream), tracks 1-based line numbers and bytes
// consumed. Memory stays bounded by the chunk size whatever the file size.
#pragma once

#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <string_view>
#include <vector>

namespace evio {

class LineReader {
 public:
  // Throws evio::InputError when the file cannot be opened. Lines longer than max_line_bytes
  // raise an InputError naming the line (a binary file given as text ends up there).
  explicit LineReader(std::string path, size_t chunk_bytes = size_t{4} << 20,
                      size_t max_line_bytes = size_t{1} << 16);
  ~LineReader();
  LineReader(const LineReader&) = delete;
  LineReader& operator=(const LineReader&) = delete;

  // Next line without its "\n" or "\r\n"; false at end of file. The view is valid until the
  // next call. A final line without a newline is returned too.
  bool next(std::string_view* line) {
    for (;;) {
      const char* nl = static_cast<const char*>(std::memchr(pos_, '\n', static_cast<size_t>(end_ - pos_)));
      if (nl != nullptr) {
        const char* b = pos_;
        const char* e = nl;
        if (e > b && e[-1] == '\r') --e;
        pos_ = nl + 1;
        ++line_;
        *line = std::string_view(b, static_cast<size_t>(e - b));
        return true;
      }
      if (!refill()) return take_last(line);
    }
  }

  int64_t line_number() const { return line_; }  // of the line last returned
  const std::string& path() const { return path_; }
  uint64_t file_size() const { return file_size_; }
  // Bytes of the file handed out as lines so far (for progress reports).
  uint64_t bytes_consumed() const { return file_offset_ - static_cast<uint64_t>(end_ - pos_); }

 private:
  bool refill();  // moves the partial line to the front and reads more; false at EOF
  bool take_last(std::string_view* line);

  std::string path_;
  std::FILE* file_ = nullptr;
  std::vector<char> buf_;
  size_t max_line_bytes_;
  const char* pos_ = nullptr;
  const char* end_ = nullptr;
  int64_t line_ = 0;
  uint64_t file_offset_ = 0;  // bytes read from the file so far
  uint64_t file_size_ = 0;
  bool eof_ = false;
};

}  // namespace evio
