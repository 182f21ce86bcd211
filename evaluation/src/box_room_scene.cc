#include "evio/evaluation/box_room_scene.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <yaml-cpp/yaml.h>

#include "evio/calib/error.h"

namespace evio::evaluation {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// Slab test: the entry and exit parameters of the line through a box (entry > exit: no hit).
void slabs(const AxisAlignedBox& b, const Eigen::Vector3d& o, const Eigen::Vector3d& d, double* enter, double* exit) {
  *enter = -kInf;
  *exit = kInf;
  for (int i = 0; i < 3; ++i) {
    if (d(i) == 0) {
      if (o(i) < b.lo(i) || o(i) > b.hi(i)) {
        *enter = kInf;
        *exit = -kInf;
        return;
      }
      continue;
    }
    double s0 = (b.lo(i) - o(i)) / d(i), s1 = (b.hi(i) - o(i)) / d(i);
    if (s0 > s1) std::swap(s0, s1);
    *enter = std::max(*enter, s0);
    *exit = std::min(*exit, s1);
  }
}

Eigen::Vector3d vec3(const YAML::Node& n, const std::string& file, const char* what) {
  if (!n || !n.IsSequence() || n.size() != 3) throw InputError(file, 0, std::string("scene.room: ") + what + " is not a 3-vector", "[x, y, z] in m");
  return Eigen::Vector3d(n[0].as<double>(), n[1].as<double>(), n[2].as<double>());
}

}  // namespace

std::optional<double> BoxRoomScene::intersect(const Eigen::Vector3d& o, const Eigen::Vector3d& d) const {
  if (!o.allFinite() || !d.allFinite() || d.squaredNorm() == 0) return std::nullopt;
  double best = kInf;
  double enter = 0, exit = 0;
  slabs(room, o, d, &enter, &exit);
  if (enter <= 0 && exit > 0) best = exit;  // inside: the wall where the ray leaves
  for (const AxisAlignedBox& b : boxes) {
    slabs(b, o, d, &enter, &exit);
    if (enter <= exit && enter > 0) best = std::min(best, enter);
  }
  if (!std::isfinite(best)) return std::nullopt;
  return best;
}

RayCaster BoxRoomScene::caster() const {
  return [scene = *this](const Eigen::Vector3d& o, const Eigen::Vector3d& d) { return scene.intersect(o, d); };
}

BoxRoomScene load_crosscheck_room(const std::string& path) {
  YAML::Node root;
  try {
    root = YAML::LoadFile(path);
  } catch (const YAML::Exception& e) {
    throw InputError(path, e.mark.line + 1, std::string("cannot read: ") + e.what(), "the meta.json of a crosscheck-simulator room sequence");
  }
  const YAML::Node room = root["scene"]["room"];
  if (!room || !room.IsMap())
    throw InputError(path, 0, "no scene.room (a panorama sequence has no room geometry)", "the meta.json of a crosscheck-simulator room sequence");
  BoxRoomScene s;
  try {
    s.room = {vec3(room["lo"], path, "lo"), vec3(room["hi"], path, "hi")};
    if (const YAML::Node boxes = room["boxes"]) {
      for (const YAML::Node& b : boxes) s.boxes.push_back({vec3(b["lo"], path, "boxes[].lo"), vec3(b["hi"], path, "boxes[].hi")});
    }
  } catch (const YAML::Exception& e) {
    throw InputError(path, e.mark.line + 1, std::string("scene.room: ") + e.what(), "numbers in lo, hi and boxes[].lo/hi");
  }
  if (!((s.room.hi - s.room.lo).array() > 0).all()) throw InputError(path, 0, "scene.room: hi must exceed lo on every axis");
  return s;
}

}  // namespace evio::evaluation
