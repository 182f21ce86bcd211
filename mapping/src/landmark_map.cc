#include "evio/mapping/landmark_map.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <stdexcept>

#include <pcl/io/pcd_io.h>
#include <pcl/io/ply_io.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#include "evio/calib/error.h"

namespace evio::mapping {

MapFormat map_format_for(const std::string& path) {
  const std::string ext = std::filesystem::path(path).extension().string();
  if (ext == ".ply") return MapFormat::kPlyBinary;
  if (ext == ".pcd") return MapFormat::kPcdBinary;
  throw std::invalid_argument("landmark map: unknown extension '" + ext + "' of " + path + " (expected .ply or .pcd)");
}

void write_landmark_map(const std::string& path, const std::vector<MapPoint>& points, MapFormat format) {
  pcl::PointCloud<pcl::PointXYZI> cloud;
  cloud.reserve(points.size());
  for (const MapPoint& m : points) {
    if (!m.p_w.allFinite() || !std::isfinite(m.intensity)) throw std::invalid_argument("landmark map: non-finite point");
    pcl::PointXYZI q;
    q.x = static_cast<float>(m.p_w.x());
    q.y = static_cast<float>(m.p_w.y());
    q.z = static_cast<float>(m.p_w.z());
    q.intensity = m.intensity;
    cloud.push_back(q);
  }
  cloud.width = static_cast<uint32_t>(cloud.size());
  cloud.height = 1;
  cloud.is_dense = true;
  if (cloud.empty()) {
    // PCL refuses to write empty clouds: a valid empty file by hand (same fields).
    std::ofstream f(path);
    if (format == MapFormat::kPlyBinary || format == MapFormat::kPlyAscii) {
      f << "ply\nformat " << (format == MapFormat::kPlyBinary ? "binary_little_endian" : "ascii")
        << " 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nproperty float intensity\nend_header\n";
    } else {
      f << "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z intensity\nSIZE 4 4 4 4\nTYPE F F F F\n"
           "COUNT 1 1 1 1\nWIDTH 0\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 0\nDATA "
        << (format == MapFormat::kPcdBinary ? "binary" : "ascii") << "\n";
    }
    if (!f) throw InputError(path, 0, "cannot write the landmark map", "a writable output folder");
    return;
  }
  int rc = -1;
  switch (format) {
    case MapFormat::kPlyBinary:
      rc = pcl::io::savePLYFileBinary(path, cloud);
      break;
    case MapFormat::kPlyAscii:
      rc = pcl::io::savePLYFileASCII(path, cloud);
      break;
    case MapFormat::kPcdBinary:
      rc = pcl::io::savePCDFileBinary(path, cloud);
      break;
    case MapFormat::kPcdAscii:
      rc = pcl::io::savePCDFileASCII(path, cloud);
      break;
  }
  if (rc != 0) throw InputError(path, 0, "cannot write the landmark map", "a writable output folder");
}

std::vector<MapPoint> read_landmark_map(const std::string& path) {
  pcl::PointCloud<pcl::PointXYZI> cloud;
  const std::string ext = std::filesystem::path(path).extension().string();
  {
    // An empty map (written by hand above; PCL does not read zero-point files back).
    std::ifstream f(path);
    if (!f) throw InputError(path, 0, "cannot read the landmark map", "a PLY or PCD file written by evio");
    std::string head((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    if (head.find("element vertex 0\n") != std::string::npos || head.find("\nPOINTS 0\n") != std::string::npos) return {};
  }
  const int rc = ext == ".pcd" ? pcl::io::loadPCDFile(path, cloud) : pcl::io::loadPLYFile(path, cloud);
  if (rc != 0) throw InputError(path, 0, "cannot read the landmark map", "a PLY or PCD file written by evio");
  std::vector<MapPoint> out;
  out.reserve(cloud.size());
  for (const auto& q : cloud) out.push_back({Eigen::Vector3d(q.x, q.y, q.z), q.intensity});
  return out;
}

}  // namespace evio::mapping
