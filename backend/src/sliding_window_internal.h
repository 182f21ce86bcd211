// SlidingWindowEstimator's keyframe and landmark records and the helpers its source files share
// (internal to evio::backend; the estimator is in sliding_window_estimator.h):
//   sliding_window_estimator.cc        options, keyframe selection, triangulation, add_frame, the solve
//   sliding_window_motion_model.cc     the per-keyframe rotation-only decision (GRIC + IMU datum, hysteresis)
//   sliding_window_marginalization.cc  what marginalising the oldest keyframe takes with it
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <memory>
#include <unordered_map>
#include <vector>

#include <ceres/ceres.h>
#include <Eigen/Core>
#include <Eigen/Geometry>

#include "evio/backend/imu_error.h"
#include "evio/backend/imu_preintegration.h"
#include "evio/backend/reprojection_error.h"
#include "evio/backend/sliding_window_estimator.h"

namespace evio::backend {

struct SlidingWindowEstimator::Keyframe {
  int64_t t_ns = 0;
  int64_t frame_id = 0;
  std::array<double, 7> pose{};  // [qx qy qz qw px py pz] of T_w_b
  std::array<double, 9> sb{};    // [v_w, b_g, b_a]
  std::unique_ptr<ImuPreintegration> pre;  // from the previous keyframe
  std::unique_ptr<ImuError> imu_error;
  std::unordered_map<int64_t, Eigen::Vector3d> obs;                          // track -> bearing
  std::unordered_map<int64_t, std::unique_ptr<ReprojectionError>> reproj;   // track -> residual
  // With estimate_time_offset: the same residuals with the time offset, by track.
  std::unordered_map<int64_t, std::unique_ptr<TimeOffsetReprojectionError>> reproj_td;
  bool rotation_only = false;                                                // no parallax to the previous keyframe
  std::unordered_map<int64_t, std::unique_ptr<RotationOnlyError>> rot;      // track -> residual to the previous keyframe
  std::unique_ptr<StaticCentreError> static_centre;  // rotation-only: the camera centre stays (to the previous keyframe)
  // Rotation tracker (add_tracked_rotation): the bearings alone do not call for a translation
  // (the model test's image_best is not G), so the tracker's orientation may constrain it.
  bool tracker_eligible = false;
  // Its orientation here, once attached.
  bool tracked = false;               // attached (or found unbracketed: tracker_tried)
  bool tracker_tried = false;         // the samples passed its time without bracketing it
  int64_t tracker_anchor_id = 0;      // its segment's anchor (tracker_anchors_)
  Eigen::Quaterniond tracker_q_m_c = Eigen::Quaterniond::Identity();
  Eigen::Matrix3d tracker_cov_c = Eigen::Matrix3d::Zero();
  std::unique_ptr<RelativeRotationError> tracker_factor;  // to the segment's anchor (none for the anchor)
  int tracker_stat = -1;              // its entry in stats().tracker_factors
};

struct SlidingWindowEstimator::Landmark {
  std::array<double, 3> p{};
  bool triangulated = false;
};

namespace internal {

// A keyframe pose block [qx qy qz qw px py pz] as its rotation and position.
inline Eigen::Quaterniond quat_of(const std::array<double, 7>& pose) {
  return Eigen::Quaterniond(pose[3], pose[0], pose[1], pose[2]).normalized();
}
inline Eigen::Vector3d pos_of(const std::array<double, 7>& pose) { return Eigen::Vector3d(pose[4], pose[5], pose[6]); }

// The upper median (0 for none).
inline double median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const size_t n = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<long>(n), v.end());
  return v[n];
}

// The window keeps its residuals, losses and manifolds: Ceres problems only borrow them.
inline ceres::Problem::Options problem_options() {
  ceres::Problem::Options o;
  o.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  o.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  o.manifold_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  o.enable_fast_removal = false;
  return o;
}

inline std::unique_ptr<ceres::LossFunction> make_loss(RobustLoss l, double scale) {
  switch (l) {
    case RobustLoss::kHuber:
      return std::make_unique<ceres::HuberLoss>(scale);
    case RobustLoss::kCauchy:
      return std::make_unique<ceres::CauchyLoss>(scale);
    default:
      return nullptr;
  }
}

}  // namespace internal
}  // namespace evio::backend
