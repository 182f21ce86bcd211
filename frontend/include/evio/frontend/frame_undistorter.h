// Undistortion of intensity (APS) frames into the ideal pinhole of the same fx, fy, cx, cy, the
// geometry the feature tracker and the event frames work in: a per-pixel map from each ideal
// pixel to the distorted sensor pixel (calib::PinholeCamera::project of its ray), applied with
// bilinear interpolation (cv::remap). Pixels whose ray misses the sensor repeat the nearest
// sensor pixel (no artificial black border for the corner detector) and are flagged in mask().
#pragma once

#include <opencv2/core.hpp>

#include "evio/calib/camera.h"

namespace evio::frontend {

class FrameUndistorter {
 public:
  explicit FrameUndistorter(const calib::PinholeCamera& camera);

  // 8-bit single-channel image of the camera's size (3-channel BGR is converted to grey); throws
  // std::invalid_argument for another size or type. Returns the undistorted CV_8UC1 image.
  cv::Mat undistort(const cv::Mat& image) const;
  // CV_8UC1, 255 where the ideal pixel's ray lands on the sensor, 0 elsewhere.
  const cv::Mat& mask() const { return mask_; }
  int width() const { return map_x_.cols; }
  int height() const { return map_x_.rows; }

 private:
  cv::Mat map_x_, map_y_;  // CV_32F, sensor pixel of each ideal pixel
  cv::Mat mask_;
};

}  // namespace evio::frontend
