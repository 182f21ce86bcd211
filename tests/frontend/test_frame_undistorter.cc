// FrameUndistorter: identity without distortion; with radtan distortion a bright dot drawn at the
// distorted projection of a ray lands at the ray's ideal pinhole pixel; bad sizes are rejected.
#include "evio/frontend/frame_undistorter.h"

#include <cmath>
#include <stdexcept>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

namespace evio::frontend {
namespace {

calib::CameraIntrinsics intrinsics(bool distorted) {
  calib::CameraIntrinsics K;
  K.width = 240;
  K.height = 180;
  K.fx = 199.1;
  K.fy = 198.7;
  K.cx = 121.3;
  K.cy = 88.9;
  if (distorted) {
    K.model = calib::DistortionModel::kRadtan;
    K.distortion = {-0.33, 0.12, 0.001, -0.0005};
  }
  return K;
}

TEST(FrameUndistorter, IdentityWithoutDistortion) {
  const FrameUndistorter u{calib::PinholeCamera(intrinsics(false))};
  cv::Mat img(180, 240, CV_8UC1);
  cv::randu(img, 0, 256);
  const cv::Mat out = u.undistort(img);
  EXPECT_EQ(cv::norm(out, img, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::countNonZero(u.mask()), 240 * 180);
}

TEST(FrameUndistorter, DistortedDotLandsAtTheIdealPixel) {
  const calib::PinholeCamera cam(intrinsics(true));
  const FrameUndistorter u(cam);
  const calib::CameraIntrinsics ideal = intrinsics(false);
  for (const Eigen::Vector2d& target : {Eigen::Vector2d(30, 25), Eigen::Vector2d(200, 150), Eigen::Vector2d(121, 90)}) {
    const Eigen::Vector3d ray((target.x() - ideal.cx) / ideal.fx, (target.y() - ideal.cy) / ideal.fy, 1.0);
    Eigen::Vector2d px;
    ASSERT_TRUE(cam.project(ray, &px));
    cv::Mat img(180, 240, CV_32F);
    for (int y = 0; y < 180; ++y)
      for (int x = 0; x < 240; ++x) img.at<float>(y, x) = 255.0f * std::exp(-((x - px.x()) * (x - px.x()) + (y - px.y()) * (y - px.y())) / 4.5);
    cv::Mat img8;
    img.convertTo(img8, CV_8U);
    const cv::Mat out = u.undistort(img8);
    const cv::Moments m = cv::moments(out);
    ASSERT_GT(m.m00, 0);
    // Centroid within a tenth of a pixel of the ideal position (the dot is small: distortion is
    // locally affine over it).
    EXPECT_NEAR(m.m10 / m.m00, target.x(), 0.1) << target.transpose();
    EXPECT_NEAR(m.m01 / m.m00, target.y(), 0.1) << target.transpose();
  }
  // Pincushion distortion: the ideal image's corners see beyond the sensor, flagged in the mask.
  calib::CameraIntrinsics pin = intrinsics(true);
  pin.distortion = {0.3, 0.0, 0.0, 0.0};
  const FrameUndistorter p{calib::PinholeCamera(pin)};
  EXPECT_EQ(p.mask().at<uint8_t>(0, 0), 0);
  EXPECT_EQ(p.mask().at<uint8_t>(90, 120), 255);
}

TEST(FrameUndistorter, RejectsOtherSizesAndConvertsColour) {
  const FrameUndistorter u{calib::PinholeCamera(intrinsics(false))};
  EXPECT_THROW(u.undistort(cv::Mat(100, 100, CV_8UC1)), std::invalid_argument);
  EXPECT_THROW(u.undistort(cv::Mat(180, 240, CV_16UC1)), std::invalid_argument);
  const cv::Mat bgr(180, 240, CV_8UC3, cv::Scalar(10, 20, 30));
  const cv::Mat out = u.undistort(bgr);
  EXPECT_EQ(out.type(), CV_8UC1);
  EXPECT_NEAR(out.at<uint8_t>(90, 120), 0.114 * 10 + 0.587 * 20 + 0.299 * 30, 1.0);
}

}  // namespace
}  // namespace evio::frontend
