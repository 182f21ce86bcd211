// Relative rotation error over a fixed time interval (RRE): how far an estimate's orientation
// change over dt seconds departs from the ground truth's, the figure that tells whether a VIO's
// orientation is as good as its gyro. An interval runs between two poses of the estimate, t0 and
// the pose t1 nearest to t0 + dt (the estimate must reach t0 + dt, and t1 must lie within
// end_tolerance of it, otherwise the interval is skipped):
// the estimate is never interpolated, so a gap in its output (a span without frames) does not
// show up as the slerp's error across it. The ground truth is interpolated (slerp) at t0 and t1,
// and the error is the angle of (R_gt(t0)^T R_gt(t1))^T (R_est(t0)^T R_est(t1)).
// The reference is the measured gyro integrated alone over the same intervals (GyroIntegrator):
// an estimator whose RRE is near the gyro's adds no orientation error of its own.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "evio/evaluation/trajectory_evaluation.h"
#include "evio/sensors/measurements.h"
#include "evio/sensors/trajectory.h"

namespace evio::evaluation {

struct RelativeRotationOptions {
  double interval_s = 1.0;  // dt, s, > 0
  size_t stride = 5;        // every stride-th estimate pose starts an interval (count, >= 1)
  // The interval's end pose must lie within this fraction of dt from t0 + dt, [0, 1).
  double end_tolerance = 0.1;
  bool Validate(std::string* why) const;
};

struct RelativeRotationError {
  double interval_s = 0;
  Stats deg;                        // over the intervals, deg
  std::vector<int64_t> start_ns;    // the intervals' start times
  std::vector<int64_t> end_ns;      // and end times (estimate stamps)
  std::vector<double> errors_deg;   // per interval
};

// Intervals start at every stride-th estimate stamp that has an end pose (see above) and whose
// interval the ground truth covers. No interval: count 0. Throws std::invalid_argument on invalid
// options.
RelativeRotationError relative_rotation_error(const Trajectory& groundtruth, const Trajectory& estimate,
                                              const RelativeRotationOptions& options);
// The same over given intervals [start_ns[k], end_ns[k]] (e.g. another estimate's, for a
// like-for-like comparison), with both trajectories interpolated there (meant for dense ones such
// as GyroIntegrator's); intervals either trajectory does not cover are skipped. interval_s is the
// nominal dt reported. Throws std::invalid_argument when the two lists differ in length.
RelativeRotationError relative_rotation_error_at(const Trajectory& groundtruth, const Trajectory& estimate,
                                                 const std::vector<int64_t>& start_ns, const std::vector<int64_t>& end_ns,
                                                 double interval_s);

// Absolute error of an orientation-only estimate (a rotational tracker's, in its own frame m)
// after aligning the initial orientation: R_w_m maps the estimate's frame to the ground truth's
// world at the first estimate pose the ground truth covers; each covered pose's error is the angle
// of R_gt^T R_w_m R_est, deg. Empty (no poses) when the ground truth covers none.
struct InitialAlignedRotationError {
  Eigen::Matrix3d R_w_m = Eigen::Matrix3d::Identity();
  std::vector<int64_t> t_ns;       // the matched estimate stamps
  std::vector<double> errors_deg;  // per matched pose
};
InitialAlignedRotationError rotation_error_initial_aligned(const Trajectory& groundtruth, const Trajectory& estimate);

// The orientation obtained by integrating the measured angular rate alone (body frame, no bias
// removed, trapezoid on consecutive samples: R <- R Exp((w_k + w_k+1) / 2 dt)), kept every
// period_ns as an orientation-only trajectory (positions zero). Memory is one pose per period
// (200 Hz: 14 MB per hour), so it can run beside a streaming reader.
class GyroIntegrator {
 public:
  explicit GyroIntegrator(int64_t period_ns = 5'000'000);
  // Samples in time order (IMU clock); others are ignored.
  void add(const ImuSample& sample);
  // The orientation samples so far (the last sample is always included).
  Trajectory trajectory() const;
  size_t samples() const { return samples_; }

 private:
  int64_t period_ns_;
  std::vector<StampedPose> poses_;
  calib::Quat q_ = calib::Quat::Identity();
  ImuSample last_{};
  bool have_last_ = false;
  bool tentative_ = false;  // poses_.back() is the newest sample, less than a period after the last kept
  int64_t kept_t_ns_ = 0;
  size_t samples_ = 0;
};

}  // namespace evio::evaluation
