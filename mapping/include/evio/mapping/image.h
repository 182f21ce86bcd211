// Plain image types of the mapping module: row-major Eigen matrices, H rows (v) x W columns (u),
// element (j, i) = row j, column i. OpenCV stays inside the .cc files.
#pragma once

#include <cstdint>

#include <Eigen/Core>

namespace evio::mapping {

using ImageF = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;     // H x W
using ImageD = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;    // H x W
using MaskU8 = Eigen::Matrix<uint8_t, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;   // H x W, 0 / 1

}  // namespace evio::mapping
