#include "evio/sensors/image_io.h"

#include "evio/calib/plugin.h"

namespace evio {
namespace {

constexpr const char* kPlugin = "libevio_image_io.so";

struct ImageCodecs {
  bool (*read)(const char*, int, cv::Mat*);
  bool (*write)(const char*, const cv::Mat*, const int*, size_t);
};

const ImageCodecs& codecs() {
  static const ImageCodecs c = [] {
    void* h = open_plugin(kPlugin);
    return ImageCodecs{reinterpret_cast<bool (*)(const char*, int, cv::Mat*)>(plugin_symbol(h, kPlugin, "evio_image_read")),
                       reinterpret_cast<bool (*)(const char*, const cv::Mat*, const int*, size_t)>(
                           plugin_symbol(h, kPlugin, "evio_image_write"))};
  }();
  return c;
}

}  // namespace

cv::Mat read_image(const std::string& path, int flags) {
  cv::Mat out;
  if (!codecs().read(path.c_str(), flags, &out)) return {};
  return out;
}

bool write_image(const std::string& path, const cv::Mat& image, const std::vector<int>& params) {
  return codecs().write(path.c_str(), &image, params.data(), params.size());
}

}  // namespace evio
