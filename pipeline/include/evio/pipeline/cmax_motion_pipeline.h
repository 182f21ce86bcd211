// Streaming single-model contrast maximisation (CMax; Gallego, Rebecq, Scaramuzza, CVPR 2018) over
// a recording, as `evio flow` runs it: events in time order are cut into windows of N events or of
// a fixed duration, each window is warped to its middle time and its motion (2-D flow, rotation,
// similarity or 6-DoF; mapping::ContrastMaximizer) maximised, warm-started from the previous
// window's (the angular-velocity front-end of CMax-SLAM, Guo & Gallego, T-RO 2024, for rotation).
// Sub-pixel events in, one motion estimate per window out; no file I/O, no flags.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "evio/calib/camera.h"
#include "evio/mapping/cmax.h"
#include "evio/mapping/image.h"
#include "evio/mapping/warp_model_selection.h"
#include "evio/pipeline/cmax_windows.h"
#include "evio/sensors/measurements.h"

namespace evio::pipeline {

struct CmaxMotionPipelineOptions {
  // The maximiser's options: model, objective, blur (px), pyramid levels, iterations, tolerance (px),
  // 6-DoF depth (m) or plane. width, height and geometry fx fy cx cy are the camera's (set by the
  // pipeline from the camera, or the sensor size without one).
  mapping::CmaxOptions cmax;
  // Windows: the defaults (CmaxWindowOptions) come from the simulated poster_rotation /
  // boxes_rotation (DAVIS240C, 3 and 6 M events/s, up to ~250 deg/s; docs/results/flow.md): a window
  // needs several pixels of motion (15k events, ~5 ms: 19 deg/s RMS; 120k events or 25 ms: 1.5
  // and 2.7 deg/s), and no more than ~25 ms of it under 17 rad/s^2 (longer windows at slow motion
  // went 8-11 deg/s off); undistortion auto; 1 px dither of integer pixels.
  CmaxWindowOptions window;
  bool warm_start = true;          // start each window from the previous window's parameters
  // Pyramid levels of a warm-started window (0: cmax.pyramid_levels; 1 .. 8). A warm start is
  // already near the optimum, so the coarse levels that give a cold start its reach can go (boxes,
  // 10 s, 120k events: 1 level 2.7 deg/s, 3 levels 4.3 deg/s and 1.7x the time).
  int warm_pyramid_levels = 1;
  // Model selection per window (empty: cmax.model only): every candidate is fitted (each
  // warm-started from its own previous window) with one objective (cmax.objective auto: the
  // normalised gradient magnitude, comparable across models), and the simplest that explains the
  // window wins by mapping::choose_warp_model, the rule `evio segment` applies per cluster.
  // rotation needs the camera. cmax.model is ignored then.
  std::vector<mapping::WarpModel> models;
  double model_gain_per_parameter = 0.01;  // relative objective gain per extra parameter (>= 0)
  bool keep_iwe = false;           // each window carries its IWE before and after warping (unblurred)
  bool keep_events = false;        // each window carries its prepared events (diagnostics)

  bool Validate(std::string* why) const;
};

// One estimated window.
struct CmaxMotionWindow {
  int64_t index = 0;              // 0, 1, ... over the estimated windows
  int64_t t_start_ns = 0;         // first event (event windows) or window start (time windows), ns
  int64_t t_end_ns = 0;           // last event (event windows) or window end (time windows), ns
  int64_t t_ref_ns = 0;           // warp reference: the middle of [t_start, t_end], ns
  int64_t events = 0;             // events estimated with
  mapping::WarpModel model = mapping::WarpModel::kFlow;  // the one model, or the chosen candidate
  Eigen::VectorXd params;         // mapping::warp_parameter_names(model): px/s, rad/s, 1/s, m/s
  std::vector<mapping::ModelTrial> trials;  // model selection: every candidate, simplest first (else empty)
  double objective_zero = 0;      // objective at zero motion (level 0)
  double objective = 0;           // objective at params (level 0)
  int iterations = 0;             // BFGS iterations, all levels (and both runs after a reset)
  int evaluations = 0;            // objective + gradient evaluations, likewise
  bool warm_started = false;      // started from the previous window's parameters
  bool reset = false;             // the warm start scored below zero motion: re-run from zero
  std::string stop;               // mapping::CmaxResult::stop of the kept run
  double time_ms = 0;             // wall time of this window's maximisation, ms
  mapping::ImageF iwe_zero, iwe;  // with keep_iwe: IWE at zero motion and at params
  mapping::CmaxEvents prepared;   // with keep_events: the events as maximised (undistorted, dithered)
};

struct CmaxMotionStats {
  int64_t events = 0;               // given to process()
  int64_t events_used = 0;          // in estimated windows
  int64_t events_dropped = 0;       // lut: outside the sensor or not undistortable
  int64_t windows = 0;              // estimated
  int64_t windows_skipped = 0;      // with fewer than min_window_events (time windows: empty ones too)
  int64_t warm_starts = 0;          // windows started from the previous parameters
  int64_t resets = 0;               // warm starts rejected (objective below zero motion's)
  int64_t iterations = 0, evaluations = 0;
  double time_ms = 0;               // sum of the windows' time_ms
  std::vector<int64_t> chosen;      // model selection: windows won by each candidate (models() order)
};

class CmaxMotionPipeline {
 public:
  // camera: gives the IWE size and the pinhole (required for the rotation and 6-DoF models) and
  // the undistortion table; without it, the IWE is width x height with cmax.geometry's pinhole.
  // Throws std::invalid_argument for invalid options or sizes, or a 3-D model without a camera.
  CmaxMotionPipeline(const CmaxMotionPipelineOptions& options, int width, int height,
                     const std::optional<calib::PinholeCamera>& camera);
  ~CmaxMotionPipeline();

  // One event, in time order. Returns true when a window was estimated (take it with take_windows()).
  bool process(const SubpixelEvent& e);
  // Ends the stream: estimates the last, partial window when it holds min_window_events and at
  // least half a window (half of window_events, or half of window_ns / max_window_ns in time) or
  // no window was estimated before; otherwise it is counted as skipped.
  void finish();
  // Windows estimated since the last call, in time order.
  std::vector<CmaxMotionWindow> take_windows();

  // The undistortion in use: kNone or kLut once the first window decided it (kAuto before), and why.
  CmaxUndistortion undistortion() const { return windower_->undistortion(); }
  const std::string& undistortion_reason() const { return windower_->undistortion_reason(); }
  // The maximiser's options as used (camera size and pinhole filled in, objective as given).
  // With model selection, cmax.model is the first candidate's.
  const mapping::CmaxOptions& cmax_options() const { return fitters_.front().cold->options(); }
  mapping::CmaxObjective objective() const { return mapping::resolve_objective(o_.cmax.objective, o_.cmax.model); }
  // The candidate models, simplest first (one: cmax.model, without model selection).
  const std::vector<mapping::WarpModel>& models() const { return models_; }
  bool selects_model() const { return !o_.models.empty(); }
  const CmaxMotionStats& stats() const;
  const CmaxMotionPipelineOptions& options() const { return o_; }

 private:
  void estimate(std::vector<CmaxWindow> windows);

  CmaxMotionPipelineOptions o_;
  std::unique_ptr<CmaxWindower> windower_;
  // One fitter per candidate model.
  struct Fitter {
    std::unique_ptr<mapping::ContrastMaximizer> cold, warm;
    std::optional<Eigen::VectorXd> previous;  // its last window's parameters
    int64_t previous_t_ref_ns = 0;            // ... and their reference time
  };
  std::vector<mapping::WarpModel> models_;
  std::vector<Fitter> fitters_;
  std::vector<CmaxMotionWindow> done_;
  mutable CmaxMotionStats stats_;  // the window counts are the windower's, copied in stats()
};

}  // namespace evio::pipeline
