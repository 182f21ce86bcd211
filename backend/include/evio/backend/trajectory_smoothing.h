// The trajectory at every frame from the optimised keyframes: each frame's state is re-propagated
// from the final (last optimised) state of the keyframe it was predicted from, with the same IMU
// motion, and the mismatch with the next keyframe's final state is spread linearly in time over
// the interval, so the trajectory passes through every keyframe and has no jump larger than the
// IMU motion between two frames explains.
//
// The IMU motion of a frame predicted from keyframe state a (world frame, gravity g_w) is
// recovered from the prediction x without the IMU samples, as the preintegrated deltas
//   dR = R_a^T R_x,  dv = R_a^T (v_x - v_a - g dt),  dp = R_a^T (p_x - p_a - v_a dt - g dt^2 / 2),
// and re-applied to the final keyframe state k:
//   R = R_k dR,  v = v_k + g dt + R_k dv,  p = p_k + v_k dt + g dt^2 / 2 + R_k dp.
// (The bias change between the prediction and the final keyframe state is neglected: its effect
// over one keyframe interval is second order.)
#pragma once

#include <cstdint>
#include <map>
#include <vector>

#include <Eigen/Core>

#include "evio/sensors/vio_types.h"

namespace evio::backend {

struct FramePrediction {
  VioState state;               // the state at the frame as estimated then (causal)
  bool predicted = false;       // anchor and prediction are valid
  VioState anchor;              // the keyframe state the frame was predicted from, at that time
  VioState prediction;          // the IMU prediction from anchor to the frame's time
};

// frames: in time order; final_keyframes: by time (ns), the last optimised state of every
// keyframe. A frame at a keyframe's time gets that keyframe's final state; a frame whose anchor
// has no final state keeps its causal state.
std::vector<VioState> repropagate_trajectory(const std::vector<FramePrediction>& frames,
                                             const std::map<int64_t, VioState>& final_keyframes,
                                             const Eigen::Vector3d& gravity_w);

}  // namespace evio::backend
