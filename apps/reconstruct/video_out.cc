#include "video_out.h"

#include <stdexcept>

#include "evio/calib/error.h"
#include "evio/calib/plugin.h"

namespace evio::apps {
namespace {

constexpr const char* kPlugin = "libevio_video_io.so";

struct VideoCalls {
  void* (*open)(const char*, const char*, double, int, int);
  bool (*write)(void*, const cv::Mat*);
  void (*close)(void*);
};

const VideoCalls& calls() {
  static const VideoCalls c = [] {
    void* h = open_plugin(kPlugin);
    return VideoCalls{reinterpret_cast<void* (*)(const char*, const char*, double, int, int)>(plugin_symbol(h, kPlugin, "evio_video_open")),
                      reinterpret_cast<bool (*)(void*, const cv::Mat*)>(plugin_symbol(h, kPlugin, "evio_video_write")),
                      reinterpret_cast<void (*)(void*)>(plugin_symbol(h, kPlugin, "evio_video_close"))};
  }();
  return c;
}

}  // namespace

VideoOut::~VideoOut() { close(); }

bool VideoOut::open(const std::string& path, double fps, int width, int height, std::string* why) {
  close();
  try {
    writer_ = calls().open(path.c_str(), "mp4v", fps, width, height);
  } catch (const std::runtime_error& e) {
    if (why) *why = std::string("the video plugin could not be loaded: ") + e.what();
    return false;
  }
  if (!writer_) {
    if (why) *why = "OpenCV's VideoWriter has no MP4 (mp4v) encoder on this machine";
    return false;
  }
  path_ = path;
  return true;
}

void VideoOut::write(const cv::Mat& grey) {
  if (writer_ && !calls().write(writer_, &grey)) throw InputError(path_, 0, "cannot write the video frame", "a writable output folder");
}

void VideoOut::close() {
  if (writer_) calls().close(writer_);
  writer_ = nullptr;
}

}  // namespace evio::apps
