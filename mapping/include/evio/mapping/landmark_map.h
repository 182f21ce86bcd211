// Landmark map export: 3D points (world frame, m) with optional per-point values, written as PLY
// (binary little-endian or ASCII) or PCD through PCL. PCL stays inside the plugin libevio_pcl_io.so
// (src/pcl_io_plugin.cc), which landmark_map.cc opens at the first map write or read (PCL is slow to
// compile and its I/O loads VTK); callers pass plain Eigen points.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

namespace evio::mapping {

struct MapPoint {
  Eigen::Vector3d p_w = Eigen::Vector3d::Zero();  // m, world frame
  float intensity = 0.0f;                         // free value per point (e.g. observation count)
};

enum class MapFormat { kPlyBinary, kPlyAscii, kPcdBinary, kPcdAscii };

// Format from the file extension (.ply -> binary PLY, .pcd -> binary PCD); throws
// std::invalid_argument for other extensions.
MapFormat map_format_for(const std::string& path);

// Writes the points; throws evio::InputError when the file cannot be written and
// std::invalid_argument for non-finite points.
void write_landmark_map(const std::string& path, const std::vector<MapPoint>& points, MapFormat format);
inline void write_landmark_map(const std::string& path, const std::vector<MapPoint>& points) {
  write_landmark_map(path, points, map_format_for(path));
}

// Reads a map written by write_landmark_map (PLY or PCD by extension); throws evio::InputError.
std::vector<MapPoint> read_landmark_map(const std::string& path);

}  // namespace evio::mapping
