// Continuous-time body trajectories for the event simulator: T_w_b(t) with exact first and second
// derivatives (velocity, acceleration, angular velocity and acceleration), so IMU samples and
// optical flow follow from the same function. Analytic sinusoids and uniform cumulative B-splines
// on SO(3) x R^3 (Sommer et al., CVPR 2020, "Efficient Derivative Computation for Cumulative
// B-Splines on Lie Groups"): random smooth motion from a seed, or a least-squares fit to a
// recorded trajectory (e.g. motion capture).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "evio/calib/geometry.h"
#include "evio/sensors/trajectory.h"

namespace evio::simulator {

// The body (IMU) state at one instant. Conventions: p_w = T_w_b * p_b; R_w_b' = R_w_b * hat(omega_b).
struct TrajectoryState {
  int64_t t_ns = 0;
  calib::SE3 T_w_b;
  Eigen::Vector3d v_w = Eigen::Vector3d::Zero();      // velocity of the body origin in w, m/s
  Eigen::Vector3d a_w = Eigen::Vector3d::Zero();      // acceleration of the body origin in w (no gravity), m/s^2
  Eigen::Vector3d omega_b = Eigen::Vector3d::Zero();  // angular velocity in the body frame, rad/s
  Eigen::Vector3d alpha_b = Eigen::Vector3d::Zero();  // d/dt omega_b, rad/s^2
};

class ContinuousTrajectory {
 public:
  virtual ~ContinuousTrajectory() = default;
  // Valid time range [t_begin_ns, t_end_ns].
  virtual int64_t t_begin_ns() const = 0;
  virtual int64_t t_end_ns() const = 0;
  // Exact state at t_ns. Throws std::out_of_range outside [t_begin_ns, t_end_ns].
  virtual TrajectoryState evaluate(int64_t t_ns) const = 0;
  // One line for logs and the output README, e.g. "cubic B-spline, 600 knots at 20 ms".
  virtual std::string describe() const = 0;
};

// Sinusoids around a start pose: p_w(t) = p0 + v*t + A .* sin(2 pi f t + phi) (per axis), and
// R_w_b(t) = R0 * Rz(yaw(t)) * Ry(pitch(t)) * Rx(roll(t)) with each angle
// angle(t) = rate*t + amplitude*sin(2 pi f t + phase). t is seconds since t_begin.
// Zero amplitudes and rates give a static body (the "no motion" case).
struct SinusoidTrajectoryOptions {
  int64_t t_begin_ns = 0;
  double duration_s = 10.0;                                        // s, > 0
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();            // p0, m
  Eigen::Quaterniond q_w_b0 = Eigen::Quaterniond::Identity();      // R0 (normalised on use)
  Eigen::Vector3d velocity_mps = Eigen::Vector3d::Zero();          // constant drift v, m/s
  Eigen::Vector3d amplitude_m = Eigen::Vector3d::Zero();           // A, m
  Eigen::Vector3d frequency_hz = Eigen::Vector3d::Zero();          // f, Hz, >= 0
  Eigen::Vector3d phase_rad = Eigen::Vector3d::Zero();             // phi, rad
  Eigen::Vector3d angle_rate_radps = Eigen::Vector3d::Zero();      // (roll, pitch, yaw) constant rates, rad/s
  Eigen::Vector3d angle_amplitude_rad = Eigen::Vector3d::Zero();   // (roll, pitch, yaw), rad
  Eigen::Vector3d angle_frequency_hz = Eigen::Vector3d::Zero();    // Hz, >= 0
  Eigen::Vector3d angle_phase_rad = Eigen::Vector3d::Zero();       // rad

  bool Validate(std::string* why) const;
};

class SinusoidTrajectory final : public ContinuousTrajectory {
 public:
  // Throws std::invalid_argument when options are invalid.
  explicit SinusoidTrajectory(const SinusoidTrajectoryOptions& options);
  int64_t t_begin_ns() const override;
  int64_t t_end_ns() const override;
  TrajectoryState evaluate(int64_t t_ns) const override;
  std::string describe() const override;

 private:
  SinusoidTrajectoryOptions o_;
};

// Uniform cumulative B-spline of order k (k = 4 cubic: C2, continuous acceleration; k = 6
// quintic: C4, continuous jerk and snap) on SO(3) x R^3, knots at t0 + i*dt.
// Control point i influences [t0 + (i - k + 1) dt, t0 + (i + 1) dt); the valid range is
// [t0, t0 + (n - k + 1) dt] for n control points.
struct RandomSplineOptions {
  int64_t t_begin_ns = 0;
  double duration_s = 10.0;                                   // s, > 0
  int order = 6;                                              // 4..6
  double knot_spacing_s = 0.3;                                // s, > 0; smaller = more agile
  Eigen::Vector3d position_m = Eigen::Vector3d::Zero();       // centre of the motion, m
  Eigen::Quaterniond q_w_b0 = Eigen::Quaterniond::Identity(); // mean orientation
  Eigen::Vector3d position_std_m = Eigen::Vector3d::Constant(0.2);  // control-point spread per axis, m
  double rotation_std_rad = 0.3;                              // control-point spread of rotation (axis-angle), rad
  uint64_t seed = 1;

  bool Validate(std::string* why) const;
};

// Defaults suit 100-200 Hz motion capture of hand-held motion: 20 ms knots follow the motion and
// leave the capture noise in the residual (see the mocap test in test_sim_trajectory.cc); knots at
// the sample period interpolate the samples, noise included.
struct SplineFitOptions {
  int order = 6;                  // 4..6
  double knot_spacing_s = 0.02;   // s, >= 1e-6
  int max_iterations = 20;        // Gauss-Newton iterations of the rotation fit, >= 0
  // s^3, >= 0: lambda of the penalty lambda * integral |c''(t)|^2 dt on the control polygon
  // (positions in m, rotation increments in rad), i.e. lambda / dt^3 * sum |c_{j-1} - 2 c_j + c_{j+1}|^2.
  // It bridges gaps in the samples and damps noise there; 1e-8 moves a 20 ms fit of exact 200 Hz
  // samples of brisk motion by 0.03 mm / 0.003 deg at most (velocities by up to 0.015 m/s and
  // 0.025 rad/s, at the ends of the range): test_sim_trajectory.cc.
  double smoothing = 1e-8;
  bool Validate(std::string* why) const;
};

// Residuals of a fit at the samples it was fitted to.
struct SplineFitReport {
  size_t samples = 0;
  size_t control_points = 0;
  int iterations = 0;
  double position_rms_m = 0, position_max_m = 0;
  double rotation_rms_deg = 0, rotation_max_deg = 0;
};

class SplineTrajectory final : public ContinuousTrajectory {
 public:
  // Throws std::invalid_argument for order outside 4..6, dt <= 0, fewer than `order` control
  // points, or sizes that differ.
  SplineTrajectory(int order, int64_t t0_ns, int64_t dt_ns, std::vector<Eigen::Quaterniond> rotations,
                   std::vector<Eigen::Vector3d> positions);

  // Smooth random motion: control points drawn from the options' distribution with the seed.
  static SplineTrajectory random(const RandomSplineOptions& options);
  // Least-squares fit to stamped poses (positions linear, rotations Gauss-Newton on the manifold).
  // The valid range starts at samples.t_begin and covers samples.t_end. Throws
  // std::invalid_argument for invalid options, fewer than 2 samples, or (smoothing 0 only) fewer
  // samples than control points or a system the samples leave singular.
  static SplineTrajectory fit(const Trajectory& samples, const SplineFitOptions& options,
                              SplineFitReport* report = nullptr);

  int64_t t_begin_ns() const override;
  int64_t t_end_ns() const override;
  TrajectoryState evaluate(int64_t t_ns) const override;
  std::string describe() const override;

  int order() const { return order_; }
  int64_t knot_spacing_ns() const { return dt_ns_; }
  size_t num_control_points() const { return positions_.size(); }
  // Control points; the quaternions are normalised and sign-continuous (q_i . q_{i-1} >= 0).
  const std::vector<Eigen::Quaterniond>& control_rotations() const { return rotations_; }
  const std::vector<Eigen::Vector3d>& control_positions() const { return positions_; }

 private:
  int order_;
  int64_t t0_ns_, dt_ns_;
  std::vector<Eigen::Quaterniond> rotations_;
  std::vector<Eigen::Vector3d> positions_;
  std::vector<Eigen::Vector3d> deltas_;  // deltas_[i] = Log(R_i^T R_{i+1}), precomputed
};

// Samples a continuous trajectory every period_ns over its valid range (both ends included).
Trajectory sample_trajectory(const ContinuousTrajectory& trajectory, int64_t period_ns);

}  // namespace evio::simulator
