// An MP4 video of 8-bit grey images through OpenCV's VideoWriter (fourcc mp4v), loaded from the
// plugin libevio_video_io.so at the first use. Whether this machine's OpenCV can encode MP4 is
// known only when opening: open() says so instead of failing.
#pragma once

#include <string>

#include <opencv2/core.hpp>

namespace evio::apps {

class VideoOut {
 public:
  VideoOut() = default;
  ~VideoOut();
  VideoOut(const VideoOut&) = delete;
  VideoOut& operator=(const VideoOut&) = delete;

  // True when the file is open for writing; false (with *why) when the plugin is missing or no
  // encoder takes mp4v.
  bool open(const std::string& path, double fps, int width, int height, std::string* why);
  bool is_open() const { return writer_ != nullptr; }
  // Appends a CV_8UC1 frame of the opened size; throws evio::InputError when the write fails.
  void write(const cv::Mat& grey);
  void close();

 private:
  std::string path_;
  void* writer_ = nullptr;
};

}  // namespace evio::apps
