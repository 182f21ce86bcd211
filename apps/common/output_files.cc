#include "output_files.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <opencv2/core.hpp>

#include "evio/calib/error.h"
#include "evio/sensors/image_io.h"

namespace evio::apps {

TextOut::TextOut(const std::string& path) : path_(path), f_(std::fopen(path.c_str(), "wb")) {
  if (!f_) throw InputError(path, 0, "cannot create the file", "a writable output folder");
}

TextOut::~TextOut() {
  if (f_) std::fclose(f_);
}

void TextOut::close() {
  const bool ok = std::ferror(f_) == 0;
  const bool closed = std::fclose(f_) == 0;
  f_ = nullptr;
  if (!ok || !closed) throw InputError(path_, 0, "write failed (disk full?)", "a writable output folder");
}

void write_text_file(const std::string& path, const std::string& text) {
  TextOut f(path);
  std::fputs(text.c_str(), f.get());
  f.close();
}

double robust_scale(const mapping::ImageF& img) {
  std::vector<float> v;
  v.reserve(static_cast<size_t>(img.size()));
  for (Eigen::Index i = 0; i < img.size(); ++i)
    if (img.data()[i] != 0.0f) v.push_back(std::fabs(img.data()[i]));
  if (v.empty()) return 1.0;
  const size_t k = std::min(v.size() - 1, static_cast<size_t>(0.99 * static_cast<double>(v.size())));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return std::max(1.0, static_cast<double>(v[k]));
}

// 8-bit grey PNG: counts 0 .. scale -> 0 .. 255 (clipped); signed (polarity) IWEs around 128.
void write_iwe_png(const std::string& path, const mapping::ImageF& img, double scale, bool is_signed) {
  cv::Mat m(static_cast<int>(img.rows()), static_cast<int>(img.cols()), CV_8UC1);
  for (int j = 0; j < m.rows; ++j) {
    for (int i = 0; i < m.cols; ++i) {
      const double v = img(j, i) / scale;
      const double g = is_signed ? 127.5 + 127.5 * v : 255.0 * v;
      m.at<uint8_t>(j, i) = static_cast<uint8_t>(std::clamp(std::lround(g), 0L, 255L));
    }
  }
  if (!write_image(path, m)) throw InputError(path, 0, "cannot write the PNG", "a writable output folder");
}

}  // namespace evio::apps
