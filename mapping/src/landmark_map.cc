#include "evio/mapping/landmark_map.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <stdexcept>

#include <vector>

#include "evio/calib/error.h"
#include "evio/calib/plugin.h"

namespace evio::mapping {
namespace {

// The PCL plugin (pcl_io_plugin.cc), opened at the first map write or read (calib/plugin.h).
struct PclPlugin {
  int (*write)(const char*, const float*, size_t, int);
  int (*read)(const char*, int, void (*)(void*, const float*, size_t), void*);
};

const PclPlugin& pcl_plugin() {
  static const PclPlugin plugin = [] {
    const std::string file = "libevio_pcl_io.so";
    void* h = open_plugin(file);
    return PclPlugin{reinterpret_cast<decltype(PclPlugin::write)>(plugin_symbol(h, file, "evio_pcl_write")),
                     reinterpret_cast<decltype(PclPlugin::read)>(plugin_symbol(h, file, "evio_pcl_read"))};
  }();
  return plugin;
}

int format_code(MapFormat f) {
  switch (f) {
    case MapFormat::kPlyBinary:
      return 0;
    case MapFormat::kPlyAscii:
      return 1;
    case MapFormat::kPcdBinary:
      return 2;
    case MapFormat::kPcdAscii:
      return 3;
  }
  return 0;
}

}  // namespace

MapFormat map_format_for(const std::string& path) {
  const std::string ext = std::filesystem::path(path).extension().string();
  if (ext == ".ply") return MapFormat::kPlyBinary;
  if (ext == ".pcd") return MapFormat::kPcdBinary;
  throw std::invalid_argument("landmark map: unknown extension '" + ext + "' of " + path + " (expected .ply or .pcd)");
}

void write_landmark_map(const std::string& path, const std::vector<MapPoint>& points, MapFormat format) {
  std::vector<float> xyzi;
  xyzi.reserve(4 * points.size());
  for (const MapPoint& m : points) {
    if (!m.p_w.allFinite() || !std::isfinite(m.intensity)) throw std::invalid_argument("landmark map: non-finite point");
    xyzi.insert(xyzi.end(), {static_cast<float>(m.p_w.x()), static_cast<float>(m.p_w.y()),
                             static_cast<float>(m.p_w.z()), m.intensity});
  }
  if (points.empty()) {
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
  const int rc = pcl_plugin().write(path.c_str(), xyzi.data(), points.size(), format_code(format));
  if (rc != 0) throw InputError(path, 0, "cannot write the landmark map", "a writable output folder");
}

std::vector<MapPoint> read_landmark_map(const std::string& path) {
  const std::string ext = std::filesystem::path(path).extension().string();
  {
    // An empty map (written by hand above; PCL does not read zero-point files back).
    std::ifstream f(path);
    if (!f) throw InputError(path, 0, "cannot read the landmark map", "a PLY or PCD file written by evio");
    std::string head((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    if (head.find("element vertex 0\n") != std::string::npos || head.find("\nPOINTS 0\n") != std::string::npos) return {};
  }
  std::vector<MapPoint> out;
  auto sink = [](void* ctx, const float* xyzi, size_t n) {
    auto* v = static_cast<std::vector<MapPoint>*>(ctx);
    v->reserve(n);
    for (size_t i = 0; i < n; ++i) {
      v->push_back({Eigen::Vector3d(xyzi[4 * i], xyzi[4 * i + 1], xyzi[4 * i + 2]), xyzi[4 * i + 3]});
    }
  };
  const int rc = pcl_plugin().read(path.c_str(), ext == ".pcd" ? 1 : 0, sink, &out);
  if (rc != 0) throw InputError(path, 0, "cannot read the landmark map", "a PLY or PCD file written by evio");
  return out;
}

}  // namespace evio::mapping
