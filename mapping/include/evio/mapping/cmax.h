// Contrast maximisation (CMax; Gallego, Rebecq, Scaramuzza, CVPR 2018): the motion parameters of
// an event window are those whose warp, bringing every event to a reference time, gives the
// sharpest image of warped events (IWE). Warps with analytic Jacobians (2-D flow, 3-DoF rotation,
// 4-DoF similarity, 6-DoF with depth or a plane), bilinear voting with per-event weights, Gaussian
// smoothing, objectives with analytic gradients (the gradient is back-propagated through the blur
// and the bilinear votes, so one evaluation costs two passes over the events and the pixels),
// and a coarse-to-fine BFGS maximiser that starts from zero.
//
// Warp models (dt = t_k - t_ref, s; events and IWE in undistorted pixel coordinates, (0,0) the
// top-left pixel centre; first order in dt, i.e. constant velocities over a short window, except
// the two *_accel models, which add a constant translational acceleration a = (ax, ay) px/s^2):
//   flow        p = (vx, vy) px/s:             x' = x - dt v
//   similarity  p = (vx, vy, s, w) px/s, 1/s, rad/s, about the image centre c = (cx, cy):
//               x' = x - dt (v + s (x - c) + w J (x - c)),  J = [[0,-1],[1,0]] (in-plane rotation)
//   flow_accel        p = (vx, vy, ax, ay):         x' = x - dt v - dt^2 a / 2
//   similarity_accel  p = (vx, vy, s, w, ax, ay):   x' = (similarity's x') - dt^2 a / 2
//               v is the velocity at t_ref. Warped to t_ref + shift instead (the IWEs at the window's
//               ends), the point follows the same trajectory: x' = x - (dt - shift) v' - (dt^2 - shift^2) a / 2
//               with v' the first-order part (v, or v + s (x - c) + w J (x - c)).
//   rotation    p = (wx, wy, wz) rad/s, camera frame: bearing b = ((x-cx)/fx, (y-cy)/fy, 1) of a
//               static point is seen at t_ref along d = b + dt w x b (first order of Exp(w dt) b),
//               projected with the pinhole: x' = cx + fx d_x / d_z, y' = cy + fy d_y / d_z
//   6dof        p = (vx, vy, vz, wx, wy, wz) m/s and rad/s (camera's velocity in its own frame):
//               d = b + dt (w x b + rho v), rho the event's inverse depth along the optical axis,
//               1/depth_m, or from a plane n.X = distance: rho = n.b / distance
// A static point's camera coordinates obey dX/dt = -w x X - v, which is where the signs come from.
// Events whose warped depth d_z falls below 0.2 (a rotation of more than ~78 deg within the
// window) do not vote.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "evio/mapping/image.h"

namespace evio::mapping {

enum class WarpModel { kFlow, kSimilarity, kRotation, kSixDof, kFlowAccel, kSimilarityAccel };
// Every model, in enum order (for name tables and option lists).
const std::vector<WarpModel>& warp_models();
// "flow", "similarity", "rotation", "6dof", "flow_accel", "similarity_accel"
const char* warp_model_name(WarpModel m);
std::optional<WarpModel> warp_model_from_name(const std::string& name);
// The names of every model joined with `sep`, e.g. "flow, similarity, ..." (help and error texts).
std::string warp_model_names(const char* sep = ", ");
int warp_dof(WarpModel m);  // 2, 4, 3, 6, 4, 6
// Parameter names with units, in order, e.g. {"vx_pxps", "vy_pxps"}; accelerations "ax_pxps2", "ay_pxps2".
std::vector<std::string> warp_parameter_names(WarpModel m);
// The constant-velocity model an accelerated one extends (flow_accel -> flow, similarity_accel ->
// similarity; its parameters are the first warp_dof of it, the acceleration the last two); m
// itself for the others.
WarpModel warp_velocity_model(WarpModel m);
// The same motion's parameters referred to a reference time dt_s later (a warm start for the next
// window): an accelerated model's velocity becomes v + a dt_s; the other models are unchanged.
Eigen::VectorXd warp_params_at(WarpModel m, const Eigen::VectorXd& p, double dt_s);

// The pinhole of the (undistorted) event coordinates, and the depth model of the 6-DoF warp.
struct WarpGeometry {
  double fx = 200.0, fy = 200.0;  // focal lengths, px
  double cx = 120.0, cy = 90.0;   // principal point, px; also the similarity warp's centre
  double depth_m = 1.0;           // 6dof: scene depth along the optical axis, m, when no plane
  // 6dof plane n.X = plane_distance_m in the camera frame at t_ref (n need not be unit; it is
  // normalised). Used when plane_distance_m > 0; events whose ray misses the plane's front side
  // get rho = 0 (at infinity).
  Eigen::Vector3d plane_normal_c = Eigen::Vector3d(0, 0, 1);
  double plane_distance_m = 0.0;
  bool Validate(std::string* why) const;
};

// One window of events prepared for warping: struct of arrays, times relative to t_ref_ns (so
// 1.7e18 ns stamps lose nothing), normalised coordinates and inverse depth for the 3-D warps.
class CmaxEvents {
 public:
  CmaxEvents() = default;
  CmaxEvents(int64_t t_ref_ns, const WarpGeometry& geometry) : t_ref_ns_(t_ref_ns), geometry_(geometry) {}

  void reserve(size_t n);
  // x, y in px (any finite value, outside the image too), polarity +1/-1.
  void push_back(float x, float y, int64_t t_ns, int polarity);
  void clear();
  // The events at the given indices (in that order), same t_ref and geometry.
  CmaxEvents select(const std::vector<uint32_t>& indices) const;

  size_t size() const { return x.size(); }
  bool empty() const { return x.empty(); }
  int64_t t_ref_ns() const { return t_ref_ns_; }
  const WarpGeometry& geometry() const { return geometry_; }
  // Smallest and largest dt over the window, s (0 when empty).
  double dt_min_s() const { return dt_min_; }
  double dt_max_s() const { return dt_max_; }

  std::vector<float> x, y;     // px
  std::vector<float> dt_s;     // t_k - t_ref, s
  std::vector<float> pol;      // +1 / -1
  std::vector<float> xn, yn;   // (x - cx) / fx, (y - cy) / fy
  std::vector<float> rho;      // inverse depth along the optical axis, 1/m (6dof only)

 private:
  int64_t t_ref_ns_ = 0;
  WarpGeometry geometry_;
  double dt_min_ = 0, dt_max_ = 0;
};

// Dither for events on integer pixels: two offsets uniform in [-0.5, 0.5) from a hash
// (splitmix64) of the event's stamp and pixel, so the same event gets the same offset whatever
// window it falls in. A pixel integrates over its area; without a dither every event votes exactly
// on a pixel centre at zero motion, a spurious sharpness peak at v = 0 (and along the axes) that
// pulls small motions to zero. Sub-pixel input (undistorted events) needs none.
void pixel_dither(int64_t t_ns, float x, float y, float* ox, float* oy);

// Warps event k with parameters p (size warp_dof(m)) to t_ref + dt_shift_s. *J (optional) gets
// d(x', y')/dp, 2 x dof. Returns false when the event does not vote (warped depth below 0.2).
bool warp_event(WarpModel m, const CmaxEvents& ev, size_t k, const Eigen::VectorXd& p, Eigen::Vector2d* warped,
                Eigen::Matrix<double, 2, Eigen::Dynamic>* J = nullptr, double dt_shift_s = 0.0);

// Bilinear samples of img (a level-0 IWE, H x W) at each event's warped position under (m, p);
// 0 where the position is outside the image or the event does not vote. out is resized to ev.size().
void sample_at_warped(const ImageF& img, WarpModel m, const CmaxEvents& ev, const Eigen::VectorXd& p,
                      std::vector<float>* out);

enum class CmaxObjective {
  // Variance for flow and flow_accel (their warps keep areas: no collapse); mean squared gradient magnitude for
  // rotation (it weighs edges, not blobs, and the roll about the optical axis, which moves pixels
  // least, gains most; docs/design-notes.md); normalised gradient magnitude for
  // similarity, similarity_accel and 6dof, whose dilation / forward motion can shrink all events into a point, which
  // maximises the variance (the variance objective drives a similarity warp to a large spurious
  // dilation).
  kAuto,
  kVariance,      // variance of the IWE (Gallego et al. CVPR 2018), events^2 / px^2
  kMeanSquare,    // mean of the squared IWE (Stoffregen & Kleeman CVPR 2019)
  kGradientMagnitude,  // mean squared magnitude of the IWE's central-difference gradient
  // Anti-collapse, normalised (Shiba, Aoki, Gallego 2022): the gradient-magnitude objective of the
  // IWEs warped to both ends of the window, each divided by that of the unwarped IWE, averaged.
  // A warp that collapses events at one end spreads them at the other (dt changes sign), so
  // shrinking everything into a few pixels does not pay; 1 means "as sharp as no motion".
  kNormalizedGradientMagnitude,
};
// The objective kAuto stands for with model m (others: themselves).
CmaxObjective resolve_objective(CmaxObjective o, WarpModel m);
const char* cmax_objective_name(CmaxObjective o);  // "auto", "variance", "mean_square", "gradient_magnitude", "normalized_gradient_magnitude"
std::optional<CmaxObjective> cmax_objective_from_name(const std::string& name);

struct CmaxOptions {
  WarpModel model = WarpModel::kFlow;
  CmaxObjective objective = CmaxObjective::kAuto;
  int width = 240;              // IWE columns at level 0, px: the sensor's width
  int height = 180;             // IWE rows at level 0, px
  double blur_sigma_px = 1.0;   // Gaussian smoothing of the IWE, in each level's own pixels (0 = none)
  bool use_polarity = false;    // IWE sums polarities (signed) instead of counts
  // Coarse-to-fine: level L votes into an IWE 2^L times smaller, so a blur of blur_sigma_px there
  // spans 2^L level-0 pixels and the objective sees displacements that large from zero. The
  // optimiser runs levels pyramid_levels-1 .. 0, each warm-started from the last.
  int pyramid_levels = 3;
  int max_iterations = 40;      // BFGS iterations per level
  // Level 0 ends when a step (taken, or the next one proposed) moves the events by less than this,
  // RMS in px.
  double tolerance_px = 0.005;
  // The same for the coarse levels, in that level's pixels. A coarse level only has to bring
  // the estimate into the next finer level's basin (about its blur, one pixel there), and its own
  // optimum differs from the finer level's by more than this, so tightening it further buys
  // nothing but evaluations.
  double coarse_tolerance_px = 0.05;
  // Coarse levels use at most this many events (an even stride over the window; 0 = all), since
  // a 2^L-times smaller IWE needs fewer events for the same votes per pixel. Level 0 uses all.
  int max_events_coarse = 0;
  WarpGeometry geometry;        // pinhole and depth model (rotation, similarity centre, 6dof)
  bool Validate(std::string* why) const;
};

struct CmaxLevelStats {
  int level = 0;        // pyramid level (0 = full resolution)
  int stride = 1;       // every stride-th event was used
  int iterations = 0;   // BFGS iterations at this level
  int evaluations = 0;  // objective + gradient evaluations at this level
  double objective = 0; // objective at the level's end (that level's scale)
};

struct CmaxResult {
  WarpModel model = WarpModel::kFlow;
  CmaxObjective objective_used = CmaxObjective::kVariance;  // never kAuto
  Eigen::VectorXd params;        // see the warp models above for units
  double objective_zero = 0;     // objective at p = 0, level 0
  double objective_init = 0;     // objective at the initial guess, level 0
  double objective = 0;          // objective at params, level 0
  int iterations = 0;            // BFGS iterations over all levels
  int evaluations = 0;           // objective (+gradient) evaluations over all levels
  int events = 0;                // events in the window
  std::vector<CmaxLevelStats> per_level;  // coarse to fine
  // Why the finest level stopped: "converged", "max_iterations", "no_events", "zero_gradient",
  // "line_search"; "kept_initial" when the result would have been worse than the initial guess
  // at level 0 (a coarse level's optimum that level 0 does not share), so the guess was kept.
  std::string stop;
};

// Holds the image buffers between calls (one per thread). Deterministic.
class ContrastMaximizer {
 public:
  // Throws std::invalid_argument with the Validate() message for invalid options.
  explicit ContrastMaximizer(const CmaxOptions& options);
  const CmaxOptions& options() const { return options_; }

  // Maximises the objective from init (size warp_dof, or empty for zero). weights (optional, one
  // per event, >= 0) scale each event's vote, for soft cluster associations.
  CmaxResult maximize(const CmaxEvents& ev, const Eigen::VectorXd& init = Eigen::VectorXd(),
                      const float* weights = nullptr);

  // The objective at p on pyramid level `level`, and its gradient d/dp when gradient != nullptr.
  double objective(const CmaxEvents& ev, const Eigen::VectorXd& p, int level, const float* weights = nullptr,
                   Eigen::VectorXd* gradient = nullptr);

  // The IWE (blurred when blurred = true) at level 0 (or `level`), warped to t_ref + dt_shift_s.
  ImageF iwe(const CmaxEvents& ev, const Eigen::VectorXd& p, const float* weights = nullptr, bool blurred = true,
             int level = 0, double dt_shift_s = 0.0);

 private:
  struct Level;
  double evaluate(const CmaxEvents& ev, const Eigen::VectorXd& p, int level, const float* weights, int stride,
                  Eigen::VectorXd* gradient, double reference_value);
  double plain_objective(const CmaxEvents& ev, const Eigen::VectorXd& p, int level, const float* weights, int stride,
                         double dt_shift, Eigen::VectorXd* gradient);

  CmaxOptions options_;
  CmaxObjective objective_ = CmaxObjective::kVariance;  // options_.objective resolved
  std::vector<float> pad_, img_, tmp_, adj_;
  std::vector<int32_t> cell_;      // per event used: its padded IWE cell, -1 when it does not vote
  std::vector<float> fa_, fb_;     // and its position in the cell, [0, 1)
  std::vector<float> kernel_;
};

// Convenience: one call, one window.
CmaxResult maximize_contrast(const CmaxEvents& ev, const CmaxOptions& options,
                             const Eigen::VectorXd& init = Eigen::VectorXd(), const float* weights = nullptr);

}  // namespace evio::mapping
