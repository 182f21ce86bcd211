// The event camera simulator's driver (ESIM-style, Rebecq et al., CoRL 2018): renders the scene
// along a continuous body trajectory seen through the camera (extrinsics T_c_b, Kalibr time shift)
// with adaptive time steps bounded by the largest per-pixel image motion and log-intensity change,
// feeds every render to the EventGenerator, renders APS frames with exposure and motion blur, and
// hands ground-truth views (intensity, depth, flow, labels) out at requested times.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "evio/calib/camera.h"
#include "evio/calib/geometry.h"
#include "evio/sensors/measurements.h"
#include "evio/simulator/events.h"
#include "evio/simulator/scene.h"
#include "evio/simulator/trajectory.h"

namespace evio::simulator {

// Adaptive time stepping. The next step is the smallest of
//   max_flow_px / (largest |flow| over the image)       (image motion bound, flow in px/s)
//   max_log_change / (largest |dL/dt| seen in the last step)   (brightness-change bound)
// clamped to [min_step_ns, max_step_ns]. A bound of 0 disables it. Results converge as the
// bounds shrink (events are placed by linear interpolation between renders). Default: the image
// motion bound alone at 1 px: a finer step changes the event counts little at twice the cost
// (docs/results/bench.md). The brightness bound is off by default: sharp (antialiased) edges make
// it choose 10-50 us steps for little change in counts.
struct SteppingOptions {
  double max_flow_px = 1.0;         // px per step, >= 0
  double max_log_change = 0.0;      // log-intensity units per step, >= 0 (0 = off; e.g. 0.05 = C/4 for C = 0.2)
  int64_t min_step_ns = 2'000;      // ns, > 0
  int64_t max_step_ns = 5'000'000;  // ns, >= min_step_ns; also the step of a static scene
  bool Validate(std::string* why) const;
};

// DAVIS-style active-pixel frames: each frame integrates the linear intensity over the exposure
// (exposure_samples renders, so fast motion blurs), maps it to 8 bit as
// 255 * clamp(gain * I, 0, 1)^(1/gamma) + read noise, rounded. Frame stamp: mid-exposure.
struct ApsOptions {
  double rate_hz = 0.0;         // frames per second; 0 = no frames
  double exposure_s = 0.005;    // s, > 0, <= 1/rate_hz
  int exposure_samples = 8;     // renders averaged over the exposure, >= 1
  double gain = 1.0;            // intensity -> [0, 1] scale
  double gamma = 2.2;           // display gamma, > 0
  double read_noise_std = 1.0;  // Gaussian noise, 8-bit grey levels, >= 0
  uint64_t seed = 7;
  bool Validate(std::string* why) const;
};

struct SimulatorOptions {
  calib::PinholeCamera camera;           // intrinsics + distortion, resolution
  calib::SE3 T_c_b;                      // camera from body (Kalibr T_cam_imu)
  int64_t time_shift_ns = 0;             // Kalibr timeshift_cam_imu: t_imu = t_cam + shift, ns
  int supersample = 1;                   // sub-pixel rays per axis (antialiased geometric edges), >= 1
  int threads = 1;                       // render threads (row bands), 1..64; any count gives identical output
  int64_t t_begin_ns = 0;                // simulated span on the body (IMU) clock, ns;
  int64_t t_end_ns = 0;                  //   both 0 = the trajectory's whole valid range
  SteppingOptions stepping;
  EventSimOptions events;
  ApsOptions frames;
  // Give each event the label of the object whose motion caused it: its pixel's label, or, where
  // an occlusion boundary crossed the pixel during the step, the front object's (the larger
  // label: sprites are drawn in label order over the background, 0).
  bool event_labels = false;
  std::vector<int64_t> ground_truth_times_ns;  // body clock; views handed to the sink (sorted)
  // Scene illumination over time: (body-clock time ns, gain > 0) knots, sorted by time; the rendered
  // intensity is multiplied by the gain, interpolated linearly in log gain between knots and held
  // outside them (empty: 1). A fast ramp makes every textured pixel fire |ln(ratio)| / C events at
  // once: an event burst (a light switched on, a flicker).
  std::vector<std::pair<int64_t, double>> illumination;
  bool ground_truth_flow = true;         // include flow in the ground-truth views
  bool Validate(std::string* why) const;
};

// Receives the simulation's outputs in time order. Event stamps and frame stamps are on the
// camera clock (t_cam = t_body - time_shift_ns); ground-truth views carry the body-clock time.
class SimulationSink {
 public:
  virtual ~SimulationSink() = default;
  // One step's events, sorted by time; `labels` (same size) when event labels are on.
  virtual void on_events(const std::vector<Event>& events, const std::vector<uint16_t>* labels) = 0;
  virtual void on_frame(const Frame& frame) { (void)frame; }
  virtual void on_ground_truth(const RenderedView& view, const CameraState& camera) {
    (void)view;
    (void)camera;
  }
};

struct SimulationStats {
  uint64_t events = 0, events_on = 0, events_off = 0;
  uint64_t steps = 0;            // renders fed to the event generator
  uint64_t frames = 0;
  int64_t simulated_ns = 0;      // body-clock span
  int64_t min_step_ns = 0, max_step_ns = 0;
  double wall_s = 0;             // run() wall time, s
  double render_s = 0;           // of which rendering, s
  double events_s = 0;           // of which event generation, s
  double max_flow_pxps = 0;      // largest image speed seen, px/s
};

// log(max(0, I) + log_eps) of a CV_32F linear intensity image (RenderedView::intensity), the log
// scale of the event model (events.h): H x W, row-major (mapping::ImageF).
Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> log_intensity_view(const cv::Mat& intensity,
                                                                                         double log_eps);

class Simulator {
 public:
  // Throws std::invalid_argument when options are invalid or the span lies outside the
  // trajectory's valid range.
  Simulator(std::shared_ptr<const Scene> scene, std::shared_ptr<const ContinuousTrajectory> trajectory,
            SimulatorOptions options);

  // Camera pose and velocity at body-clock time t_ns.
  CameraState camera_state(int64_t t_ns) const;
  // The illumination gain at body-clock time t_ns (options().illumination; 1 when empty).
  double illumination_gain(int64_t t_ns) const;
  // Renders the clean view at body-clock time t_ns (intensity times the illumination gain).
  RenderedView render(int64_t t_ns, bool with_flow) const;
  // The true log intensity of the clean view at camera-clock time t_cam_ns (rendered at
  // t_cam + time_shift on the body clock): log_intensity_view of its intensity with the event
  // model's log_eps, the reference image reconstructions are scored against.
  Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> true_log_view(int64_t t_cam_ns) const;
  // Runs the whole span. `progress` (if set) is called now and then with the fraction done and
  // the events so far.
  SimulationStats run(SimulationSink* sink, const std::function<void(double, uint64_t)>& progress = {});

  const SimulatorOptions& options() const { return o_; }
  int64_t t_begin_ns() const { return t_begin_; }
  int64_t t_end_ns() const { return t_end_; }

 private:
  std::shared_ptr<const Scene> scene_;
  std::shared_ptr<const ContinuousTrajectory> trajectory_;
  SimulatorOptions o_;
  PixelRays rays_;
  calib::SE3 T_b_c_;
  int64_t t_begin_ = 0, t_end_ = 0;
};

}  // namespace evio::simulator
