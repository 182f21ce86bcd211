// OpenCV's imgcodecs behind plain C entry points, built as the plugin libevio_image_io.so that
// image_io.cc loads at the first image read or write (see evio/sensors/image_io.h). cv::Mat passes
// by pointer: the plugin and its users share libopencv_core. No exception crosses the boundary.
#include <cstddef>
#include <exception>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#define EVIO_PLUGIN_EXPORT extern "C" __attribute__((visibility("default")))

EVIO_PLUGIN_EXPORT bool evio_image_read(const char* path, int flags, cv::Mat* out) {
  try {
    *out = cv::imread(path, flags);
    return !out->empty();
  } catch (const std::exception&) {
    return false;
  }
}

EVIO_PLUGIN_EXPORT bool evio_image_write(const char* path, const cv::Mat* image, const int* params, size_t n) {
  try {
    return cv::imwrite(path, *image, std::vector<int>(params, params + n));
  } catch (const std::exception&) {
    return false;
  }
}
