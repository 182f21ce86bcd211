// Output helpers shared by the commands: a checked text file (a full disk is an error naming the
// file, not a short file), a whole text file written at once, and 8-bit PNGs of images of warped
// events with a robust display range.
#pragma once

#include <cstdio>
#include <string>

#include "evio/mapping/image.h"

namespace evio::apps {

// Writes with a check at close. Throws evio::InputError when the file cannot be created or the
// write fails.
class TextOut {
 public:
  explicit TextOut(const std::string& path);
  ~TextOut();
  TextOut(const TextOut&) = delete;
  TextOut& operator=(const TextOut&) = delete;
  std::FILE* get() { return f_; }
  void close();

 private:
  std::string path_;
  std::FILE* f_;
};

// Writes the text as the whole file (through TextOut: the same errors).
void write_text_file(const std::string& path, const std::string& text);

// The display scale of an IWE: the 99th percentile of its non-zero magnitudes (a few hot pixels
// do not set the range), at least 1 event.
double robust_scale(const mapping::ImageF& img);

// 8-bit grey PNG: 0 .. scale -> 0 .. 255 (clipped); signed (polarity) IWEs around 128. Throws
// evio::InputError when the file cannot be written.
void write_iwe_png(const std::string& path, const mapping::ImageF& img, double scale, bool is_signed);

}  // namespace evio::apps
