// The PCL half of landmark-map export, built as a plugin (libevio_pcl_io.so) that
// landmark_map.cc loads with dlopen at the first map write or read. PCL's I/O pulls in VTK and
// about 67 shared libraries; a program that never exports a map (every evio subcommand but vio,
// and vio until its end) does not load them. Plain C entry points: no C++ types or
// exceptions cross the boundary.
#include <cstddef>
#include <exception>

#include <pcl/io/pcd_io.h>
#include <pcl/io/ply_io.h>
#include <pcl/point_cloud.h>
#include <pcl/point_types.h>

#define EVIO_PLUGIN_EXPORT extern "C" __attribute__((visibility("default")))

// Writes n points (x, y, z, intensity: 4 floats each); format 0 binary PLY, 1 ASCII PLY, 2 binary
// PCD, 3 ASCII PCD. Returns 0 on success (PCL's code otherwise; -100 for an exception).
EVIO_PLUGIN_EXPORT int evio_pcl_write(const char* path, const float* xyzi, size_t n, int format) {
  try {
    pcl::PointCloud<pcl::PointXYZI> cloud;
    cloud.reserve(n);
    for (size_t i = 0; i < n; ++i) {
      pcl::PointXYZI q;
      q.x = xyzi[4 * i];
      q.y = xyzi[4 * i + 1];
      q.z = xyzi[4 * i + 2];
      q.intensity = xyzi[4 * i + 3];
      cloud.push_back(q);
    }
    cloud.width = static_cast<uint32_t>(cloud.size());
    cloud.height = 1;
    cloud.is_dense = true;
    switch (format) {
      case 0:
        return pcl::io::savePLYFileBinary(path, cloud);
      case 1:
        return pcl::io::savePLYFileASCII(path, cloud);
      case 2:
        return pcl::io::savePCDFileBinary(path, cloud);
      case 3:
        return pcl::io::savePCDFileASCII(path, cloud);
      default:
        return -101;
    }
  } catch (const std::exception&) {
    return -100;
  }
}

// Reads a PLY (is_pcd 0) or PCD file and hands its points to sink(ctx, xyzi, n) once. Returns 0
// on success.
EVIO_PLUGIN_EXPORT int evio_pcl_read(const char* path, int is_pcd, void (*sink)(void*, const float*, size_t),
                                     void* ctx) {
  try {
    pcl::PointCloud<pcl::PointXYZI> cloud;
    const int rc = is_pcd ? pcl::io::loadPCDFile(path, cloud) : pcl::io::loadPLYFile(path, cloud);
    if (rc != 0) return rc;
    std::vector<float> xyzi;
    xyzi.reserve(4 * cloud.size());
    for (const auto& q : cloud) xyzi.insert(xyzi.end(), {q.x, q.y, q.z, q.intensity});
    sink(ctx, xyzi.data(), cloud.size());
    return 0;
  } catch (const std::exception&) {
    return -100;
  }
}
