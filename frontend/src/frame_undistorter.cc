#include "evio/frontend/frame_undistorter.h"

#include <algorithm>
#include <sstream>
#include <stdexcept>

#include <opencv2/imgproc.hpp>

namespace evio::frontend {

FrameUndistorter::FrameUndistorter(const calib::PinholeCamera& camera) {
  const calib::CameraIntrinsics& K = camera.intrinsics();
  map_x_.create(K.height, K.width, CV_32F);
  map_y_.create(K.height, K.width, CV_32F);
  mask_.create(K.height, K.width, CV_8UC1);
  const float max_x = static_cast<float>(K.width - 1), max_y = static_cast<float>(K.height - 1);
  for (int v = 0; v < K.height; ++v) {
    for (int u = 0; u < K.width; ++u) {
      const Eigen::Vector3d ray((u - K.cx) / K.fx, (v - K.cy) / K.fy, 1.0);
      Eigen::Vector2d px;
      const bool ok = camera.project(ray, &px) && px.allFinite();
      const bool on = ok && px.x() >= 0 && px.y() >= 0 && px.x() <= max_x && px.y() <= max_y;
      map_x_.at<float>(v, u) = ok ? std::clamp(static_cast<float>(px.x()), 0.0f, max_x) : static_cast<float>(u);
      map_y_.at<float>(v, u) = ok ? std::clamp(static_cast<float>(px.y()), 0.0f, max_y) : static_cast<float>(v);
      mask_.at<uint8_t>(v, u) = on ? 255 : 0;
    }
  }
}

cv::Mat FrameUndistorter::undistort(const cv::Mat& image) const {
  if (image.cols != width() || image.rows != height() || image.depth() != CV_8U ||
      (image.channels() != 1 && image.channels() != 3)) {
    std::ostringstream os;
    os << "FrameUndistorter: expected an 8-bit grey or BGR " << width() << "x" << height() << " image, got "
       << image.cols << "x" << image.rows << " with " << image.channels() << " channel(s) of depth " << image.depth();
    throw std::invalid_argument(os.str());
  }
  cv::Mat grey = image;
  if (image.channels() == 3) cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  cv::Mat out;
  cv::remap(grey, out, map_x_, map_y_, cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  return out;
}

}  // namespace evio::frontend
