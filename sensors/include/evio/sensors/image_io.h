// Image files (PNG, TIFF, JPEG, ...) through OpenCV's imgcodecs, which evio loads at the first
// image read or write from its plugin libevio_image_io.so (calib/plugin.h): imgcodecs pulls in
// GDAL and about 140 shared libraries, and programs that never touch an image file do not load
// them. Same semantics as cv::imread / cv::imwrite.
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>  // the flag constants (cv::IMREAD_*, cv::IMWRITE_*) only

namespace evio {

// cv::imread(path, flags): an empty Mat when the file is missing or unreadable.
cv::Mat read_image(const std::string& path, int flags);
// cv::imwrite(path, image, params): false when it cannot be written.
bool write_image(const std::string& path, const cv::Mat& image, const std::vector<int>& params = {});

}  // namespace evio
