// Rotational CMax-SLAM back-end (Guo and Gallego, IEEE T-RO 2024): the camera's orientation
// R_w_c(t) is a rotation spline on SO(3) with uniformly spaced knots (linear, or the cumulative
// cubic B-spline), refined over a sliding time window so that the window's events, rotated into
// the world frame and projected onto an equirectangular panorama, give the sharpest panoramic image
// of warped events (IWE); optionally refined once more over the whole trajectory at the end.
//
// Model (all rotations R_w_c, camera to world/mosaic frame; bearings unit vectors in the camera):
//   linear: knots R_i at t_i = t0 + i dt;  R(t) = R_i Exp(u w_i),  w_i = Log(R_i^T R_{i+1}),
//           u = (t - t_i) / dt
//   cubic:  control knots R_i at t0 + (i - 1) dt; for t in [t0 + s dt, t0 + (s + 1) dt)
//           R(t) = R_s Exp(l1(u) w_s) Exp(l2(u) w_{s+1}) Exp(l3(u) w_{s+2}) with the cumulative
//           basis l1..l3 (cmax_slam.cc, spline_rotation); C2, near the knots, not through them
//   event k at t_k with bearing b_k lands at (u_k, v_k) = project(R(t_k) b_k) (calib::Equirectangular)
//   IWE   I = G_sigma * (alpha M + sum_k bilinear(u_k, v_k)), over the panorama box the window's
//         events reach, where M is the panoramic event map of the events already finalised
//   cost  f = -Var_box(I) / Var_box(I at the prediction) + prior (see prior_weight), minimised over right perturbations of the
//         window's free knots by Ceres' L-BFGS (GradientProblemSolver) with the analytic gradient:
//         the derivative is back-propagated through the blur (symmetric with zero padding) and the
//         bilinear votes to (u_k, v_k), then through the projection, d(R b)/dphi = -R [b]x for a
//         right perturbation phi of R(t), and the spline's Jacobians (linear:
//           dphi/d(delta_{i+1}) = u Jr(u w) Jr^-1(w),  dphi/d(delta_i) = Exp(u w)^T - u Jr(u w) Jr^-1(w) Exp(w)^T;
//         cubic: the same chain through each of the three factors, spline_rotation).
// alpha = map_weight * min(1, the window's votes / the map's events, both inside the box): the
// map's events pull the window's events onto edges seen before (registration), at a weight
// independent of how many events the map holds once it holds more than the window, and never
// more than one vote per map event (a young map of a few hundred events would otherwise be
// amplified onto its noise). map_weight 0 is the paper's window-only objective.
//
// Sliding window: the window covers the time segments [t_a, t_a + window_knots dt); the knots that
// shape earlier, finalised segments stay fixed (linear: the knot at t_a; cubic: the first three
// control knots) and the knots after them are free. After the optimisation the first step_knots
// segments are finalised: their events join the map M and their rotations no longer change; t_a
// advances by step_knots dt. New knots come from the front-end's odometry (predict()).
//
// Global pass (global_iterations > 0): at finish(), every knot is refined together on an even
// sample of all events, in one full, longitude-wrapping panorama (refine_globally).
#pragma once

#include <cstdint>
#include <deque>
#include <utility>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace evio::backend {

// The rotation spline: linear on SO(3) between knots that are poses, or the cumulative uniform
// cubic B-spline (Kim et al. 1995; Sommer et al. 2020) whose knots are control points (C2, it
// passes near them, not through them).
enum class CmaxSlamSpline { kLinear, kCubic };

struct CmaxSlamOptions {
  CmaxSlamSpline spline = CmaxSlamSpline::kLinear;
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
  // A time segment with fewer events than this (count, >= 0; 0: off) has its rate prior weighted by
  // min_segment_events / its events (at most / 1): a few hundred events of a slow or still camera
  // are gathered by a motion that is not there, while the front-end's prediction over its longer
  // window holds.
  double min_segment_events = 1000;
  // The first window (no map yet) keeps the front-end's prediction and starts the map.
  bool keep_first_window = true;
  // The box the window's events may move in during the optimisation: their initial box grown by
  // this margin, px (>= 0). Events that leave it do not vote.
  double box_margin_px = 24.0;
  // The global pass at the end (finish()): L-BFGS iterations per blur level over every knot
  // together (the first stays: it is the world frame), maximising the contrast of one panoramic
  // IWE of an even sample of all events (0 = no global pass). Its parameters are the knots'
  // increments (see refine_globally), so a step the sliding window left in the trajectory is
  // undone by one parameter where the panorama overlaps itself.
  int global_iterations = 100;
  // The global pass's prior on the segments' rotations: this weight over the trajectory's total
  // rotation (rad) times the sum over the segments of the (pseudo-Huber, ~L1) norm of each one's
  // change (rad), against a contrast normalised to 1 (>= 0). L1 rather than the windows'
  // quadratic prior: undoing a step changes one segment, while the contrast of a whole panorama
  // also rises when every segment turns less (its events swept onto fewer texels); turning a
  // fraction a less everywhere costs global_rate_weight * a at any length.
  double global_rate_weight = 1.5;
  // Events in the global pass's sample (>= 1000); at most this many are kept in memory.
  int global_max_events = 300000;
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
  bool global_refined = false;     // the global pass ran and changed the knots
  int64_t global_iterations = 0;   // its L-BFGS iterations, all blur levels
  int64_t global_events = 0;       // events in its sample
  double global_contrast_gain = 0;  // Var(I) after / before it (0: it did not run or did not gain)
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
  // The knots: times and rotations (the cubic spline's are control points, not poses on it).
  size_t knots() const { return knots_.size(); }
  // Knot i's time: t0 + i dt (linear), t0 + (i - 1) dt (cubic: the time segment [t0 + s dt,
  // t0 + (s + 1) dt) has control knots s .. s + 3, so knots 0 and 1 are at and before the start).
  int64_t knot_time(size_t i) const { return t0_ + (static_cast<int64_t>(i) - offset_) * dt_; }
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
  // The global pass (options.global_iterations): every knot after the first, as the running
  // sums of left increments R_j = Exp(eps_1 + ... + eps_j) R_j0, refined by L-BFGS on the contrast
  // of the full (longitude-wrapping) panoramic IWE of kept_, coarse then fine blur, with the
  // segments' rate prior; kept only if the cost decreases.
  void refine_globally();

  CmaxSlamOptions opt_;
  int64_t t0_, dt_;
  int order_;    // control knots per time segment: 2 (linear), 4 (cubic)
  int offset_;   // knots before the first segment's start: 0 (linear), 1 (cubic)
  std::vector<Eigen::Matrix3d> knots_;
  std::deque<std::pair<int64_t, Eigen::Matrix3d>> odo_;  // the odometry's samples from the last knot's on
  Eigen::Matrix3d odo_at_last_knot_;
  std::deque<Ev> events_;  // events at or after t_a_
  int64_t t_a_;
  // rotation(): the last final time segment asked for and the Logs between its control knots.
  mutable int64_t cached_segment_ = -1;
  mutable Eigen::Vector3d cached_w_[3];
  std::vector<Ev> kept_;      // the global pass's sample of the events
  int64_t kept_stride_ = 1, seen_ = 0;
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

// The global pass (CmaxSlamOptions::global_iterations) on its own: knots of a spline starting at
// t0_ns with spacing options.knot_spacing_ns, refined on the events (t_ns[k], bearing_c[k]) inside
// the knots' span. refined: the cost decreased and knots holds the refined spline (the first
// knot unchanged); otherwise knots is the input.
struct CmaxSlamGlobalResult {
  std::vector<Eigen::Matrix3d> knots;
  bool refined = false;
  int64_t iterations = 0;     // L-BFGS iterations, all blur levels
  double contrast_gain = 0;   // Var(I) after / before (refined only)
};
CmaxSlamGlobalResult cmax_slam_refine_globally(const std::vector<Eigen::Matrix3d>& knots, int64_t t0_ns, const std::vector<int64_t>& t_ns,
                                               const std::vector<Eigen::Vector3d>& bearing_c, const CmaxSlamOptions& options);
// The global pass's cost at blur options.blur_sigma_px and its gradient, for checks: eps holds
// the knots' left increments (3 per knot; knot j turned by Exp(theta_j - the events' mean of
// theta), theta_j = eps_0 + ... + eps_j), the cost is -Var(I) / Var(I at eps = 0) of the full
// panorama + the robust rate prior.
double cmax_slam_global_cost(const std::vector<Eigen::Matrix3d>& knots, int64_t t0_ns, const std::vector<int64_t>& t_ns,
                             const std::vector<Eigen::Vector3d>& bearing_c, const CmaxSlamOptions& options,
                             const std::vector<double>& eps, std::vector<double>* gradient);

}  // namespace evio::backend
