// Contrast maximisation for a rotating camera (Gallego & Scaramuzza, "Accurate angular velocity
// estimation with an event camera", RA-L 2017; Gallego et al., CVPR 2018): the constant angular
// velocity over a short window that, when every event is rotated back to a reference time, gives
// the sharpest image of warped events (IWE).
//
// Model. An event k with unit bearing b_k (camera frame at its time t_k) of a point at infinity is
// seen at the reference time t_ref along d_k = Exp(omega dt_k) b_k, dt_k = t_k - t_ref (camera
// frame at t_ref; omega in the camera frame, rad/s, constant over the window). d_k is projected
// with an ideal pinhole (focal_px, principal point at the image centre) and voted bilinearly into
// the IWE, which is smoothed by a Gaussian of blur_sigma_px; the objective is the IWE's variance.
// Exp is expanded to second order in omega dt (error below 0.1% of the rotation for |omega dt|
// under 0.1 rad; keep windows short: 500 deg/s over 10 ms is 0.087 rad).
// Optimiser: derivative-free pattern search in 3-D (coordinate steps, halved when no step
// improves), run coarse to fine: first with blur_sigma_px * coarse_blur_factor and
// initial_step_radps, then at blur_sigma_px from the coarse result. Deterministic.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace evio::mapping {

struct RotationalCmaxOptions {
  int width = 240;                   // IWE columns, px; the sensor's size is the natural choice
  int height = 180;                  // IWE rows, px
  double focal_px = 200.0;           // focal length of the IWE's ideal pinhole, px
  double blur_sigma_px = 1.0;        // Gaussian smoothing of the IWE at the fine stage, px
  double coarse_blur_factor = 3.0;   // the coarse stage blurs by blur_sigma_px times this
  double initial_step_radps = 1.0;   // first pattern-search step per axis, rad/s
  double min_step_radps = 0.002;     // the search stops when the step falls below this, rad/s (<= initial)
  int max_evaluations = 600;         // objective evaluations over both stages
  bool Validate(std::string* why) const;
};

struct RotationalCmaxResult {
  Eigen::Vector3d omega_c = Eigen::Vector3d::Zero();  // camera-frame angular velocity, rad/s
  double contrast = 0;       // IWE variance at omega_c (fine stage), events^2 per pixel^2
  double contrast_zero = 0;  // IWE variance without warping (omega = 0), same units
  int evaluations = 0;       // objective evaluations used
  int events = 0;            // events that projected into the IWE at omega_c
};

// bearings[k] (camera frame, need not be unit; z > 0 expected) and t_ns[k] of each event (same
// size, any order); t_ref_ns the reference time (ns); omega_init the starting guess (rad/s).
// Throws std::invalid_argument for invalid options or mismatched sizes. No events gives
// omega_init back with zero contrast.
RotationalCmaxResult estimate_angular_velocity(const std::vector<Eigen::Vector3f>& bearings,
                                               const std::vector<int64_t>& t_ns, int64_t t_ref_ns,
                                               const Eigen::Vector3d& omega_init,
                                               const RotationalCmaxOptions& options = {});

// The objective alone: variance of the IWE for omega (rad/s) at blur sigma_px; *in_image (optional)
// receives the number of events that landed inside.
double rotational_iwe_variance(const std::vector<Eigen::Vector3f>& bearings, const std::vector<int64_t>& t_ns,
                               int64_t t_ref_ns, const Eigen::Vector3d& omega, const RotationalCmaxOptions& options,
                               double sigma_px, int* in_image = nullptr);

}  // namespace evio::mapping
