// OpenCV's videoio behind plain C entry points, built as the plugin libevio_video_io.so that
// video_out.cc loads when a command writes a video (videoio pulls in FFmpeg and GStreamer: programs
// that never write one do not load them at start-up). No exception crosses the boundary.
#include <exception>

#include <opencv2/core.hpp>
#include <opencv2/videoio.hpp>

#define EVIO_PLUGIN_EXPORT extern "C" __attribute__((visibility("default")))

// An open writer, or nullptr when no encoder takes the fourcc for this file.
EVIO_PLUGIN_EXPORT void* evio_video_open(const char* path, const char* fourcc, double fps, int width, int height) {
  try {
    auto* w = new cv::VideoWriter(path, cv::VideoWriter::fourcc(fourcc[0], fourcc[1], fourcc[2], fourcc[3]), fps,
                                  cv::Size(width, height), false);
    if (w->isOpened()) return w;
    delete w;
  } catch (const std::exception&) {
  }
  return nullptr;
}

EVIO_PLUGIN_EXPORT bool evio_video_write(void* writer, const cv::Mat* grey) {
  try {
    static_cast<cv::VideoWriter*>(writer)->write(*grey);
    return true;
  } catch (const std::exception&) {
    return false;
  }
}

EVIO_PLUGIN_EXPORT void evio_video_close(void* writer) {
  try {
    delete static_cast<cv::VideoWriter*>(writer);
  } catch (const std::exception&) {
  }
}
