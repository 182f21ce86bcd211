// Trajectory evaluation: association of an estimate with ground truth by timestamp, alignment
// (none, SE3 and Sim3 by Umeyama's closed form, position + yaw for VIO), absolute trajectory error,
// relative error over sub-trajectories of given lengths (the protocol of rpg_trajectory_evaluation,
// Zhang and Scaramuzza, IROS 2018), mean position error as % of distance travelled, yaw drift, and
// statistics over several runs. Poses are body (IMU) poses T_w_b; times int64 ns.
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "evio/calib/geometry.h"
#include "evio/sensors/trajectory.h"

namespace evio::evaluation {

enum class Alignment {
  kNone,    // estimate used as it is
  kSE3,     // rotation + translation (Umeyama without scale)
  kSim3,    // rotation + translation + scale (Umeyama with scale)
  kPosYaw,  // translation + rotation about gravity (world z) only: the 4 unobservable DoF of VIO
  // The first pair's poses: rotation R_gt0 R_est0^T, translation from its positions, scale 1.
  // For motion with little translation (a camera turning in place), where a fit to positions
  // follows their errors: the orientation error then grows from zero at the start.
  kFirstPose,
};
// "none", "se3", "sim3", "posyaw", "first_pose".
const char* alignment_name(Alignment a);
std::optional<Alignment> alignment_from_name(const std::string& name);

struct AssociationOptions {
  double max_dt_s = 0.02;                 // largest |t_est + time_offset - t_gt| of a match, s, > 0
  double time_offset_s = 0.0;             // added to estimate stamps before matching, s
  bool interpolate_groundtruth = false;   // true: ground truth interpolated at each estimate stamp
                                          // (between neighbours at most 2 * max_dt_s apart)
  bool Validate(std::string* why) const;
};

// Pairs of poses at the same instant (the estimate's stamp, after the offset).
struct AssociatedPoses {
  std::vector<int64_t> t_ns;                 // estimate stamps + offset
  std::vector<calib::SE3> groundtruth;       // T_w_b of the ground truth
  std::vector<calib::SE3> estimate;          // T_w_b of the estimate (unaligned)
  std::vector<size_t> estimate_index;        // index into the estimate trajectory
  size_t size() const { return t_ns.size(); }
};

// Nearest ground-truth pose within max_dt (each ground-truth pose used at most once, in time
// order), or interpolation. Throws std::invalid_argument when a trajectory is empty or nothing
// associates; the message gives both time ranges and, when they differ by a factor near 1e3,
// 1e6 or 1e9, says that one file is probably in another time unit.
AssociatedPoses associate(const Trajectory& groundtruth, const Trajectory& estimate, const AssociationOptions& options);

struct AlignmentOptions {
  Alignment method = Alignment::kSE3;
  double first_s = 0;     // > 0: fit on the pairs within the first first_s seconds only, s
  size_t first_poses = 0; // > 0: fit on the first first_poses pairs only (both set: the fewer pairs)
  bool Validate(std::string* why) const;
};

// p_gt ~= scale * rotation * p_est + translation; the estimate's orientations are rotated too.
struct AlignmentResult {
  Alignment method = Alignment::kNone;
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  double scale = 1.0;
  size_t pairs_used = 0;
};

// Closed-form alignment of corresponding positions (Umeyama 1991; posyaw: the same restricted
// to rotations about z). Throws std::invalid_argument for fewer than the method needs (se3/sim3:
// 3 non-collinear points; posyaw: 2 points, or 1 with the translation only) or mismatched sizes.
AlignmentResult align_positions(const std::vector<Eigen::Vector3d>& p_groundtruth,
                                const std::vector<Eigen::Vector3d>& p_estimate, Alignment method);
// Chooses the pairs by AlignmentOptions and aligns.
AlignmentResult align(const AssociatedPoses& pairs, const AlignmentOptions& options);
// T_w_b' = S * T_w_b with S = (scale * rotation, translation): position s R p + t, rotation R R_est.
calib::SE3 apply_alignment(const AlignmentResult& alignment, const calib::SE3& T_w_b);

// Summary of a set of values (empty: count 0 and zeros).
struct Stats {
  size_t count = 0;
  double rmse = 0, mean = 0, median = 0, std = 0, min = 0, max = 0;  // std: population (divides by n)
};
Stats compute_stats(std::vector<double> values);

struct AbsoluteError {
  Stats trans_m;                        // |p_gt - p_est_aligned|, m
  Stats rot_deg;                        // angle of R_gt^T R_est_aligned, deg
  std::vector<double> trans_errors_m;   // per pair
  std::vector<double> rot_errors_deg;   // per pair
};

struct RelativeErrorOptions {
  std::vector<double> lengths = {10, 20, 30, 40, 50};  // sub-trajectory lengths
  bool lengths_in_percent = true;  // true: % of the ground truth's total path length; false: m
  bool Validate(std::string* why) const;
};

// Errors of all sub-trajectories of one length (pairs i -> j where the ground truth has travelled
// the length from i), as in rpg_trajectory_evaluation: E = (T_gt_i^-1 T_gt_j)^-1 (T_est_i^-1 T_est_j).
struct RelativeError {
  double length_m = 0;
  size_t count = 0;
  Stats trans_m;          // |translation of E|, m
  Stats trans_percent;    // 100 |translation of E| / length
  Stats rot_deg;          // angle of E, deg
  Stats yaw_deg;          // |yaw of E|, deg
  Stats yaw_deg_per_m;    // |yaw of E| / length, deg/m
};

struct EvaluationOptions {
  AssociationOptions association;
  AlignmentOptions alignment;
  RelativeErrorOptions rpe;
  bool Validate(std::string* why) const;
};

struct EvaluationResult {
  size_t matched_poses = 0;
  double groundtruth_length_m = 0;            // path length of the matched ground truth, m
  AlignmentResult alignment;
  AbsoluteError ate;
  // Mean translation error (after alignment) as % of the distance travelled (matched ground
  // truth path length), the figure event-VIO papers report.
  // NaN when the matched ground truth travels less than 1 um (pure rotation).
  double mean_position_error_percent = std::numeric_limits<double>::quiet_NaN();
  double final_yaw_error_deg = 0;             // signed yaw error at the last pair, deg
  double yaw_drift_deg_per_m = std::numeric_limits<double>::quiet_NaN();  // final |yaw error| / path length, deg/m; NaN as above
  std::vector<RelativeError> rpe;
  AssociatedPoses pairs;                      // the matched pairs
  std::vector<calib::SE3> aligned_estimate;   // estimate poses of the pairs after alignment
};

// Associates, aligns and computes every metric. Throws std::invalid_argument on invalid options
// or when nothing associates / too few pairs for the alignment.
EvaluationResult evaluate(const Trajectory& groundtruth, const Trajectory& estimate, const EvaluationOptions& options);

// Yaw (rotation about world z) of a rotation, rad, from the ZYX Euler decomposition.
double yaw_of(const Eigen::Matrix3d& R);

}  // namespace evio::evaluation
