// Stamped poses and trajectories: T_w_b over time (p_w = T_w_b * p_b), strictly increasing
// int64 ns stamps, interpolation between neighbours (slerp + linear translation). File formats:
// TUM (`t tx ty tz qx qy qz qw`, seconds; the ECD groundtruth.txt layout) read and write,
// EuRoC-style csv (`timestamp[ns], ...` with a header naming the columns) read.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "evio/calib/geometry.h"
#include "evio/sensors/text_read_options.h"

namespace evio {

struct StampedPose {
  int64_t t_ns = 0;
  calib::SE3 T_w_b;
};

class Trajectory {
 public:
  Trajectory() = default;
  // Throws std::invalid_argument when stamps are not strictly increasing.
  explicit Trajectory(std::vector<StampedPose> poses);

  // Appends a pose; throws std::invalid_argument unless t_ns is after the last stamp.
  void push_back(const StampedPose& pose);

  size_t size() const { return poses_.size(); }
  bool empty() const { return poses_.empty(); }
  const StampedPose& operator[](size_t i) const { return poses_[i]; }
  auto begin() const { return poses_.begin(); }
  auto end() const { return poses_.end(); }
  const std::vector<StampedPose>& poses() const { return poses_; }

  int64_t t_begin_ns() const { return poses_.empty() ? 0 : poses_.front().t_ns; }
  int64_t t_end_ns() const { return poses_.empty() ? 0 : poses_.back().t_ns; }
  int64_t duration_ns() const { return t_end_ns() - t_begin_ns(); }

  // Pose at t_ns, interpolated between the two neighbouring poses (exact at stamps);
  // nullopt outside [t_begin, t_end] (no extrapolation).
  std::optional<calib::SE3> interpolate(int64_t t_ns) const;
  // Sum of distances between consecutive positions, m.
  double path_length_m() const;

 private:
  std::vector<StampedPose> poses_;
};

// TUM trajectory. Time unit from options (auto: a decimal point means seconds). Each line must
// have 8 finite numbers; quaternions within 1e-2 of unit norm are normalised, others are bad lines.
Trajectory read_tum(const std::string& path, const TextReadOptions& options = {}, ReadReport* report = nullptr);
// Writes seconds with 9 decimals and the shortest round-trip form of each double (lossless).
void write_tum(const std::string& path, const Trajectory& trajectory);

// Csv with a header line naming the columns, e.g. EuRoC's `#timestamp [ns], p_RS_R_x [m], ...,
// q_RS_w [], q_RS_x [], ...` or `# timestamp, x, y, z, qx, qy, qz, qw`. The first column is
// time in ns unless options.time_unit says otherwise (or the header names [s]/[us]); position
// and quaternion columns are found by name, so either quaternion order is read correctly.
Trajectory read_euroc_csv(const std::string& path, const TextReadOptions& options = {},
                          ReadReport* report = nullptr);

// A trajectory file of either form: csv (read_euroc_csv) when the extension is .csv or the first
// line that is not a `#` comment starts with a letter (a header) or holds a comma, else TUM.
// Throws evio::InputError for a missing file, bad lines, and fewer than 2 poses.
Trajectory read_trajectory(const std::string& path, const TextReadOptions& options = {});

}  // namespace evio
