// Rotational CMax-SLAM back-end (Guo and Gallego, IEEE T-RO 2024): the camera's orientation
// R_w_c(t) is a linear rotation spline on SO(3) with uniformly spaced knots, refined over a sliding
// time window so that the window's events, rotated into the world frame and projected onto an
// equirectangular panorama, give the sharpest panoramic image of warped events (IWE).
//
// Model (all rotations R_w_c, camera to world/mosaic frame; bearings unit vectors in the camera):
//   knots R_i at t_i = t0 + i dt;  R(t) = R_i Exp(u w_i),  w_i = Log(R_i^T R_{i+1}),  u = (t - t_i) / dt
//   event k at t_k with bearing b_k lands at (u_k, v_k) = project(R(t_k) b_k) (calib::Equirectangular)
//   IWE   I = G_sigma * (alpha M + sum_k bilinear(u_k, v_k)), over the panorama box the window's
//         events reach, where M is the panoramic event map of the events already finalised
//   cost  f = -Var_box(I) / Var_box(I at the prediction) + prior (see prior_weight), minimised over right perturbations of the
//         window's free knots by Ceres' L-BFGS (GradientProblemSolver) with the analytic gradient:
//         the derivative is back-propagated through the blur (symmetric with zero padding) and the
//         bilinear votes to (u_k, v_k), then through the projection, d(R b)/dphi = -R [b]x for a
//         right perturbation phi of R(t), and the linear spline's Jacobians
//           dphi/d(delta_{i+1}) = u Jr(u w) Jr^-1(w),  dphi/d(delta_i) = Exp(u w)^T - u Jr(u w) Jr^-1(w) Exp(w)^T.
// alpha = map_weight * (the window's votes / the map's events, both inside the box): the map's
// events pull the window's events onto edges seen before (registration), at a weight independent
// of how many events the map holds. map_weight 0 is the paper's window-only objective.
//
// Sliding window: the window covers [t_a, t_a + window_knots dt); the knot at t_a stays fixed
// (earlier, finalised events depend on it) and the knots after it are free. After the
// optimisation the first step_knots segments are finalised: their events join the map M and
// their rotations no longer change; t_a advances by step_knots dt. New knots come from the
// front-end's odometry (predict()).
#pragma once

#include <cstdint>
#include <deque>
#include <utility>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace evio::backend {

struct CmaxSlamOptions {
  int64_t knot_spacing_ns = 20'000'000;  // dt between the spline's knots, ns (> 0)
  int window_knots = 10;                 // spline segments optimised together (>= 2)
  int step_knots = 5;                    // segments finalised per window (1 .. window_knots)
  int panorama_width = 1024;             // equirectangular IWE columns, px (>= 16)
  int panorama_height = 512;             // rows, px (>= 8)
  double blur_sigma_px = 1.0;            // Gaussian smoothing of the IWE, px (0 = none)
  // A first optimisation with this wider blur, px, brings a window whose prediction is several
  // pixels off into the fine blur's basin (0 or <= blur_sigma_px: none).
  double coarse_blur_sigma_px = 4.0;
  // Events of a window used in its optimisation (an even stride; 0 = all). Every event still
  // joins the event map when finalised.
  int max_window_events = 30000;
  int max_iterations = 30;               // L-BFGS iterations per window (>= 1)
  double map_weight = 1.0;               // weight of the finalised event map in the window's IWE (>= 0)
  // Weight of the prior that keeps the free knots near the front-end's prediction: the cost is
  // -Var(I) / Var(I at the prediction) + prior_weight / 2 * mean over the free knots of |delta|^2
  // (delta: a knot's right perturbation, rad), per rad^2 (>= 0). It removes the window's gauge
  // freedom (without a map, turning every free knot together barely changes the contrast) at a
  // cost of about prior_weight / 2 * delta^2 per knot moved, small against the contrast gains
  // of true corrections.
  double prior_weight = 10.0;
  // Weight of the prior that keeps each segment's rotation Log(R_i^T R_{i+1}) near the prediction,
  // per rad^2 (>= 0): -Var / Var(prediction) gains + rate_prior_weight / 2 * the mean over the
  // window's segments of the change squared (to first order). Where the events are few (a static
  // start) it keeps the segments' motion as predicted instead of fitting it to noise.
  double rate_prior_weight = 100.0;
  // The first window (no map yet) keeps the front-end's prediction and starts the map.
  bool keep_first_window = true;
  // The box the window's events may move in during the optimisation: their initial box grown by
  // this margin, px (>= 0). Events that leave it do not vote.
  double box_margin_px = 24.0;
  bool Validate(std::string* why) const;
};

struct CmaxSlamStats {
  int64_t windows = 0;        // windows optimised
  int64_t skipped_windows = 0;  // windows with too few events to optimise (kept as predicted)
  int64_t iterations = 0;     // L-BFGS iterations, all windows
  int64_t evaluations = 0;    // cost + gradient evaluations, all windows
  int64_t events_used = 0;    // events in the windows' optimisations (each window counts its own)
  int64_t events_mapped = 0;  // events finalised into the event map
  double mean_contrast_gain = 0;  // mean over windows of Var(I) after / before the window's optimisation
};

class CmaxSlam {
 public:
  // The spline starts at t0_ns with R_w_c0. Throws std::invalid_argument on invalid options.
  CmaxSlam(const CmaxSlamOptions& options, int64_t t0_ns, const Eigen::Matrix3d& R_w_c0);

  // One event: time (>= t0, non-decreasing), unit bearing in the camera frame.
  void add_event(int64_t t_ns, const Eigen::Vector3f& bearing_c);
  // The front-end's prediction: its rotation R_w_c at t_ns (an odometry in any world frame;
  // only its motion is used; t_ns increasing, else ignored). Adds every knot up to t_ns, each
  // rotated from the previous knot by the odometry's rotation between their times (linear on SO(3)
  // between the odometry's samples; the first sample is (t0_ns, R_w_c0)).
  void predict(int64_t t_ns, const Eigen::Matrix3d& R_odometry);
  // Optimises and finalises every window whose events are all in (every event before
  // t_complete_ns has been added) and whose knots exist.
  void update(int64_t t_complete_ns);
  // End of data at t_end_ns (>= the last event): optimises what is left and finalises every
  // event (knots past the predicted ones continue the last segment's rotation).
  void finish(int64_t t_end_ns);

  // Events before this time are final: their rotations no longer change.
  int64_t finalized_until_ns() const { return t_a_; }
  // R_w_c(t) on the spline (held at the ends outside the knots).
  Eigen::Matrix3d rotation(int64_t t_ns) const;
  // The knots: times and rotations.
  size_t knots() const { return knots_.size(); }
  int64_t knot_time(size_t i) const { return t0_ + static_cast<int64_t>(i) * dt_; }
  const Eigen::Matrix3d& knot(size_t i) const { return knots_[i]; }

  // The panoramic event map: finalised events per texel, panorama_height rows of
  // panorama_width, row-major (unblurred counts).
  const std::vector<float>& event_map() const { return map_; }
  const CmaxSlamStats& stats() const { return stats_; }
  const CmaxSlamOptions& options() const { return opt_; }

 private:
  struct Ev {
    int64_t t;
    float bx, by, bz;
  };
  void optimize_window(int64_t ta, int64_t tb);
  void finalize_until(int64_t t);

  CmaxSlamOptions opt_;
  int64_t t0_, dt_;
  std::vector<Eigen::Matrix3d> knots_;
  std::deque<std::pair<int64_t, Eigen::Matrix3d>> odo_;  // the odometry's samples from the last knot's on
  Eigen::Matrix3d odo_at_last_knot_;
  std::deque<Ev> events_;  // events at or after t_a_
  int64_t t_a_;
  // rotation(): the last final segment asked for and its Log(R_s^T R_{s+1}).
  mutable int64_t cached_segment_ = -1;
  mutable Eigen::Vector3d cached_w_ = Eigen::Vector3d::Zero();
  std::vector<float> map_;
  double gain_sum_ = 0;
  CmaxSlamStats stats_;
};

// The window cost f = -Var(I) of the model above and its gradient, for checks: knots [fixed, last]
// of a spline starting at t0_ns with spacing options.knot_spacing_ns, the first fixed and the
// others perturbed on the right by x (3 per free knot); events (t_ns[k], bearing_c[k]) inside
// [knot_time(fixed), knot_time(last)); map (panorama-sized, may be empty) the event map M. The
// box is taken at x = 0. gradient (optional) gets df/dx.
double cmax_slam_window_cost(const std::vector<Eigen::Matrix3d>& knots, int64_t t0_ns, int fixed, int last,
                             const std::vector<int64_t>& t_ns, const std::vector<Eigen::Vector3d>& bearing_c,
                             const std::vector<float>& map, const CmaxSlamOptions& options,
                             const std::vector<double>& x, std::vector<double>* gradient);

}  // namespace evio::backend
