// The true geometry of a room scene made of axis-aligned boxes (the camera inside the room, solid
// boxes standing in it), as the second simulator of ../shared/crosscheck_sim writes it in its
// meta.json (scene.room: lo, hi, boxes[].lo/hi, world frame, m). Its ray caster gives the oracle
// tools (TrackOracle, true_frame_motion, evaluate_tracks) the same error budget on that simulator's
// sequences as on evio's own planar scenes.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "evio/evaluation/track_evaluation.h"

namespace evio::evaluation {

struct AxisAlignedBox {
  Eigen::Vector3d lo = Eigen::Vector3d::Zero();
  Eigen::Vector3d hi = Eigen::Vector3d::Zero();
};

struct BoxRoomScene {
  AxisAlignedBox room;               // seen from inside
  std::vector<AxisAlignedBox> boxes; // seen from outside

  // Parameter s > 0 of the nearest surface along origin_w + s dir_w, or nullopt (origin outside the
  // room and no box hit, or a degenerate direction).
  std::optional<double> intersect(const Eigen::Vector3d& origin_w, const Eigen::Vector3d& dir_w) const;
  RayCaster caster() const;
};

// Reads scene.room of a crosscheck-simulator meta.json. Throws evio::InputError naming the file
// when it cannot be read or has no room scene (a panorama sequence has none).
BoxRoomScene load_crosscheck_room(const std::string& meta_json);

}  // namespace evio::evaluation
