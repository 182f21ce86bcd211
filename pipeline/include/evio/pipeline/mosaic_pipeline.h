// Simultaneous rotational tracking and panorama mosaicing (Kim et al., BMVC 2014) as one
// synchronous library class: a bootstrap (rates from the gyro, or from rotational contrast
// maximisation per window) maps the first events into the pixel-wise EKF gradient mosaic
// (mapping::GradientMosaic), the tracker's contrast is calibrated on that mosaic, then a particle
// filter on SO(3) (frontend::RotationParticleFilter) tracks the camera against the Poisson
// reconstruction of the mosaic, which it keeps building from the tracked rotation.
// Plain data in (events, IMU samples) and out (MosaicResult); no files or flags. With threads = 2
// the mapper (gradient EKF and the tracker's Poisson solves) runs on a second thread, with the
// same results.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "evio/backend/cmax_slam.h"
#include "evio/calib/calibration_io.h"
#include "evio/frontend/rotation_particle_filter.h"
#include "evio/mapping/contrast_maximization.h"
#include "evio/mapping/gradient_mosaic.h"
#include "evio/mapping/rotation_relocalization.h"
#include "evio/sensors/event_buffer.h"
#include "evio/sensors/measurements.h"
#include "evio/sensors/trajectory.h"

namespace evio::pipeline {

// What tracks the rotation after the bootstrap.
//  - kParticleFilter: the particle filter against the mosaic (Kim et al.); its prediction is the
//    gyro's with use_gyro, else each particle's own angular velocity.
//  - kOdometry: no map registration: the bootstrap's rotation source continues to the end, i.e.
//    the gyro's rates integrated (use_gyro) or, events only, the rotational contrast-maximisation
//    rate of each window (bootstrap_window_ns / bootstrap_window_events) integrated. It cannot be
//    lost (every window gives a rate) but drifts with the rate errors; no failure detection.
//  - kOdometryParticleFilter: the particle filter predicted by the odometry's rates: the gyro's
//    with use_gyro (the same as kParticleFilter), else the contrast-maximisation windows' rates,
//    computed ahead of the filter over the buffered events (one sample per window, at its middle,
//    linear in between) with prediction noise odometry_noise_rad_per_sqrt_s. While lost, the
//    filter keeps following the odometry and its particles are spread around it every failure
//    window (failure_relocalize_spread_rad) until the map is found again.
//  - kCmaxSlam: the odometry's rates (gyro or contrast-maximisation windows, as kOdometry) predict
//    the knots of a rotation spline that the CMax-SLAM back-end (backend::CmaxSlam, options
//    cmax_slam) refines over a sliding window by maximising the contrast of the panoramic image of
//    warped events, registered to the panoramic event map of the events before the window. The
//    gradient mosaic maps each event once its window is final (a delay of window_knots knots), and
//    the trajectory is the spline at its knots' times; after the back-end's global pass
//    (cmax_slam.global_iterations) it is the refined spline, while the mosaic stays mapped along
//    the spline before the pass (a caller that can read the data again maps it along the refined
//    trajectory: set_bootstrap_reference with kOdometry, as evio mosaic does). Cannot be lost; no
//    failure detection.
//  - kAuto: chosen by the input (resolve_mosaic_tracker): kCmaxSlam events only, kParticleFilter
//    with use_gyro.
enum class MosaicTracker { kParticleFilter, kOdometry, kOdometryParticleFilter, kCmaxSlam, kAuto };
// "pf", "odometry", "odometry+pf", "cmax_slam", "auto".
const char* mosaic_tracker_name(MosaicTracker t);
// The tracker kAuto stands for, any other unchanged. Events only, kCmaxSlam: the only tracker that
// is never lost there (the filter alone is lost on most scenes it was not developed on, the
// odometry drifts). With a gyro, kParticleFilter: registration to the mosaic bounds the drift of a
// biased consumer gyro, which the gyro integrated (kOdometry) or the back-end predicted by it
// (kCmaxSlam) keep (docs/results/mosaic.md, "The default tracker").
MosaicTracker resolve_mosaic_tracker(MosaicTracker t, bool use_gyro);
// A short reason for the choice, e.g. "auto: events only" ("set" when t is not kAuto).
std::string mosaic_tracker_reason(MosaicTracker t, bool use_gyro);

struct MosaicPipelineOptions {
  MosaicTracker tracker_method = MosaicTracker::kAuto;  // resolved by the pipeline (resolve_mosaic_tracker)
  // kOdometryParticleFilter without the gyro: the filter's rotation noise density around the
  // contrast-maximisation rates, rad/sqrt(s) (> 0); covers the windows' rate errors.
  double odometry_noise_rad_per_sqrt_s = 0.1;
  // kCmaxSlam: the back-end's options; its panorama is the mosaic's (mosaic.width x mosaic.height,
  // whatever panorama_width / panorama_height say).
  backend::CmaxSlamOptions cmax_slam;

  mapping::GradientMosaicOptions mosaic;            // equirectangular mosaic size (px), C, EKF noise, ...
  // particles, batch_size (events), event_stride, ...; probes every 4th batch here (the filter's
  // own default is none): tracker.probe_every_batches and probe_offset_rad drive the failure
  // detection below.
  frontend::RotationParticleFilterOptions tracker = [] {
    frontend::RotationParticleFilterOptions t;
    t.probe_every_batches = 4;
    return t;
  }();

  // Drive the bootstrap and the particles' prediction with the gyro (add_imu); false: events only.
  bool use_gyro = false;

  // Poisson reconstruction of the tracker's map, scheduled by events: after the first
  // particle-filter batch that ends at least reconstruct_events events (count, >= 1) after the
  // previous reconstruction's point, or reconstruct_period_ns (ns, > 0) after it, whichever comes
  // first. Events rather than a clock: the event rate grows with the rotation speed, so a fixed
  // count re-solves after about the same rotation at every speed and the solves' cost per event
  // stays bounded (a region solve of the field of view costs about as much at any speed); the
  // period bounds the map's age on slow, sparse streams. Defaults 200000 events and 100 ms: on
  // poster_rotation 2 s (3.2 M events/s, 63 ms) with the gyro 50000 / 150000 / 300000 events gave
  // 0.167 / 0.124 / 0.093 deg RMS (a fixed 20 ms: 0.169; seed-to-seed spread about +-20 %) and
  // 1.17 / 1.24 / 1.30 M events/s of CPU time.
  int64_t reconstruct_events = 200'000;
  int64_t reconstruct_period_ns = 100'000'000;
  // The tracker switches to a reconstruction reconstruct_latency_events events (count, >= 0) after
  // its point (at the first batch ending there or later; 0 = the next batch). The results do not
  // depend on `threads`; with threads = 2 the mapper solves during those events instead of the
  // tracker waiting for it. A new reconstruction is never started before the previous one is in use.
  int64_t reconstruct_latency_events = 0;
  // Mapper thread: 1 = everything on the caller's thread; 2 = the tracker's events are mapped
  // into the gradient mosaic and the tracker's maps reconstructed on a second thread (from the
  // tracking start on). The output is bit-identical for 1 and 2 (count, 1 or 2).
  int threads = 1;
  // Every this many reconstructions (counting the bootstrap's) one is a full solve, the others
  // are GradientMosaic's kAuto (incremental region solve where it suffices), count (>= 1).
  int full_reconstruct_every = 50;
  // The final reconstruction (MosaicResult::reconstruction): kInformation = weighted least squares
  // with the EKF's information per edge (mosaic.weighted_poisson), seeded by the unweighted solve,
  // which is returned too (reconstruction.unweighted_log_intensity); kNone = the unweighted spectral
  // solve only. The tracker's reconstructions are always unweighted (spectral / region solves).
  // Default kInformation: on 3 s with the gyro it raised the mosaic's PSNR / SSIM against the true
  // panorama from 28.61 dB / 0.903 to 29.38 dB / 0.912 (poster_rotation) and from 19.04 / 0.753 to
  // 19.73 / 0.774 (shapes_rotation), for one solve of about 0.4 s (docs/results/mosaic.md). With it,
  // the camera's field of view is marked on the mosaic every footprint_period_ns
  // (GradientMosaic::mark_viewed) for the weights of event-free texels.
  mapping::PoissonWeighting output_weighting = mapping::PoissonWeighting::kInformation;
  // With kInformation: the field of view is marked at the first trajectory pose at least this long
  // after the previous marking, ns (> 0).
  int64_t footprint_period_ns = 20'000'000;

  // Bootstrap: the events of the first bootstrap_ns (ns, >= 0) after the first event are mapped
  // with rotations integrated from gyro or contrast-maximisation rates, not tracked.
  int64_t bootstrap_ns = 300'000'000;
  // Events only: a contrast-maximisation window closes after bootstrap_window_ns (ns, > 0) or
  // bootstrap_window_events events (count, >= 1), whichever comes first; the rate of each window
  // starts from the previous one. Defaults 50 ms, 40000 events: about 11 ms at 3.5 M events/s,
  // 50 ms below 0.8 M events/s. Fixed 10 ms windows gave 3.7 deg of error in the first 0.2 s at
  // 66 deg/s (too little motion per window); fixed 30 ms ones diverged at 270 deg/s.
  int64_t bootstrap_window_ns = 50'000'000;
  int bootstrap_window_events = 40000;
  // Events only, the floor: a window that holds fewer than bootstrap_min_window_events events
  // (count, >= 0; 0: no floor) when bootstrap_window_ns has passed stays open until it holds that
  // many or bootstrap_max_window_ns (ns, >= bootstrap_window_ns) has passed. On a few hundred
  // events (a slow or still camera) the maximiser's optimum can be a fast rotation that is not
  // there: the events of a 240 x 180 sensor gather on a few texels; longer windows at low event
  // rates hold slow motion, which a constant rate over the window models.
  int bootstrap_min_window_events = 2000;
  int64_t bootstrap_max_window_ns = 200'000'000;
  // Events only, a static start: until the first contrast-maximisation window whose rate sharpens
  // its image of warped events by at least this factor over no rotation (IWE variance at the rate
  // / at zero, >= 1), windows are still: rate zero (the simplest motion that explains the events;
  // on a still camera's noise events the maximiser's optimum is a rotation that is not there).
  // From that window on, only a rate that sharpens less than none at all (gain < 1) reads as
  // still: a moving window's gain also depends on the motion within it (dense scenes close their
  // windows by the event count after a few pixels of motion), so the threshold would zero real
  // rates there.
  double bootstrap_min_contrast_gain = 1.15;
  // Events only: a window's contrast-maximisation rate uses at most this many of its events,
  // evenly strided (count, >= 0; 0: all). The rate's cost is linear in the events it warps.
  int bootstrap_rate_max_events = 0;
  // With the gyro: bootstrap windows of min(bootstrap_window_ns, this), ns (> 0); within one the
  // rate at each event's time is held constant from the event window's start.
  int64_t gyro_bootstrap_window_ns = 1'000'000;
  // With the gyro: step of the rotation's integration over a bootstrap window (midpoint rate), ns (> 0).
  int64_t gyro_integration_step_ns = 1'000'000;
  // Rotational CMax of the bootstrap windows: blur_px (px), optimiser settings. Its IWE size and
  // focal length are taken from the camera (width, height, sqrt(fx fy)).
  mapping::RotationalCmaxOptions cmax;

  // The tracker's contrast: true = the bootstrap mosaic's mean log-intensity change per event along
  // the bootstrap's paths, clamped to [min_contrast_ratio, 1] x tracker.contrast_threshold; false =
  // tracker.contrast_threshold as given. The reconstruction is smoother than the scene, so its
  // change per event is below the sensor's C; tracking with the sensor's C against it makes the
  // tracker over-rotate (previous_mean) until it matches.
  bool calibrate_contrast = true;
  // In [0, 1] (default 0.8). A slow bootstrap sees little texture: on a 66 deg/s scene it measured
  // 0.128 for C = 0.2 and tracking with that diverged (45 deg RMS over 3 s; 5.7 deg at 0.16).
  double min_contrast_ratio = 0.8;
  // One mapped bootstrap event in this many gives a calibration sample (its path), count (>= 1).
  int calibration_sample_stride = 8;
  // Only paths between texels with at least this many accepted EKF updates count, count (>= 0): a
  // young texel's gradient is still shrunk towards the prior's zero, which would bias C low.
  int calibration_min_texel_updates = 5;
  // Fewer usable samples than this (count, >= 1), or a non-positive mean: keep
  // tracker.contrast_threshold (MosaicResult::bootstrap.contrast_calibrated = false).
  int calibration_min_samples = 1000;

  // Tracking failure. Every tracker.probe_every_batches-th particle-filter batch (0: no
  // detection) is also weighed under six rotations tracker.probe_offset_rad off the mean
  // (RotationParticleFilterOptions::probe_*): the cloud's log-likelihood per event minus the
  // probes' is positive while the estimate sits on the map's optimum and near zero once the filter
  // is lost, whatever the scene. Its mean over failure_window_ns (ns, > 0) below
  // failure_lost_contrast (failure_lost_windows decided windows in a row) starts a lost segment; a
  // window mean at or above failure_recovered_contrast (>= the lost level) ends it. Measured on
  // 1.5-4 s rotation sequences (decided 100 ms windows): tracking 0.13-0.44 (poster slow / medium
  // / fast, boxes, shapes with the gyro), lost -0.04-0.02 (shapes events only, from 0.7 s).
  int64_t failure_window_ns = 100'000'000;
  // A window decides nothing when its probed batches weighed fewer events than failure_min_events
  // (count, >= 0) or its event count is below failure_min_rate_ratio (>= 0) times the running mean
  // of the windows' counts: near a still moment the measurement hardly depends on the rotation.
  // The turning points of a slow pan (12-16 deg/s against 66 at the peak) gave 0.3-0.4 s of low
  // contrast while tracking at 0.4-0.6 deg (poster slow 30 s events only; shapes slow 30 s with
  // the gyro). A floor on the tracker's own speed hid real losses instead (a lost filter's
  // velocity is small: boxes slow lost at 1 s was reported at 20.8 s).
  int failure_min_events = 1000;
  double failure_min_rate_ratio = 0.5;
  double failure_lost_contrast = 0.05;
  // Decided windows in a row below failure_lost_contrast that start a lost segment (count, >= 1;
  // default 2: one low window at a slow turning point of poster slow 30 s was a false alarm).
  int failure_lost_windows = 2;
  double failure_recovered_contrast = 0.1;
  // While lost, events are not mapped (the mosaic is not written with a wrong rotation).
  bool failure_freeze_map = true;
  // While lost, events only, each failure window ends by spreading the particles around the mean
  // by this much (rad, >= 0; 0: no re-localisation), so the cloud can find the map's optimum again.
  // Not with the gyro: its prediction holds, and a "lost" there is a poor map (shapes slow).
  double failure_relocalize_spread_rad = 0.05;
  // Map rollback: while tracking, the mosaic's state is checkpointed every
  // failure_checkpoint_period_ns (ns, > 0; the newest failure_checkpoints kept, count >= 1, 25 MB
  // each at 1024 x 512). When a loss is declared, the mosaic goes back to the newest checkpoint at
  // least one failure window before the first low window (the map agrees with a wrong rotation
  // for a while, so a loss is detected some 0.3 s after the departure), undoing what was mapped
  // with the wrong rotation, and the tracker's map is re-solved. false: no checkpoints. Default
  // false: on the 30-s tables no lost run recovered with it, and with the gyro it turned the
  // mirrored-view test's loss into a false recovery (the tracker's events then fall on texels the
  // rollback emptied, and the probe contrast of the rest rose above the recovered level).
  bool failure_rollback = false;
  int64_t failure_checkpoint_period_ns = 250'000'000;
  int failure_checkpoints = 4;
  // While lost, events only: at most once per failure_global_period_ns (ns, > 0) a failure window
  // also searches the whole known mosaic for the view (mapping::RelocalizationMap): the window's
  // most recent events (at most bootstrap_window_ns and bootstrap_window_events, as a bootstrap
  // window) are moved to its end with their contrast-maximisation angular velocity, and the best
  // rotation replaces the particles (at the CMax velocity) when its score beats the estimate's by
  // failure_global_min_gain (ratio, >= 1). false: local spreads only. Default false: on the 30-s
  // tables (boxes fast, shapes) the searches jumped (1-18 times per run) but no run came back to
  // the truth, and some windows then read as recovered while 40-100 deg off: by the time a loss
  // is declared the map around the view was written with the wrong rotation. The search itself
  // finds a view on a known map within 0.12-0.28 deg (tests/mapping/test_rotation_relocalization.cc).
  bool failure_global_relocalize = false;
  int64_t failure_global_period_ns = 500'000'000;
  double failure_global_min_gain = 1.2;
  mapping::RotationRelocalizationOptions relocalization;

  // The rotation trajectory keeps one pose per this period at most, ns (> 0).
  int64_t trajectory_period_ns = 5'000'000;
  // Snapshot callback (set_snapshot_callback) at the first tracked batch and then after every
  // batch at least this long after the previous snapshot, ns (>= 0; 0 = none).
  int64_t snapshot_period_ns = 0;

  // With the gyro, events wait until the IMU covers them (a sample after the last event of the
  // step that needs it). Events further than this ahead of the newest IMU sample (camera clock)
  // are processed without waiting (the gyro is missing there), ns (>= 0).
  int64_t imu_wait_ns = 1'000'000'000;

  bool Validate(std::string* why) const;
};

// The mosaic frame puts the first camera's optical axis on the equator, looking along +x, image
// right = -y, image down = -z (the simulator's rpy [-90, 0, -90] start), away from the poles:
// R_w_c of the first event.
Eigen::Matrix3d mosaic_initial_camera_rotation();

struct MosaicBootstrapStats {
  bool gyro = false;              // rates from the gyro (else rotational contrast maximisation)
  int64_t t_end_ns = 0;           // tracking starts here (camera clock)
  int64_t cmax_windows = 0;       // contrast-maximisation windows (events only)
  int64_t short_windows = 0;      // a last window under half the window's time and events: previous rate kept
  int64_t still_windows = 0;      // of cmax_windows, read as still (bootstrap_min_contrast_gain): rate zero
  int64_t events = 0;             // events of the bootstrap
  double tracker_contrast = 0;    // the tracker's C, log units
  bool contrast_calibrated = false;  // tracker_contrast from the bootstrap mosaic (else as configured)
  int64_t contrast_samples = 0;   // calibration samples used
};

// The odometry's contrast-maximisation windows after the bootstrap (events only,
// kOdometryParticleFilter; with kOdometry the bootstrap runs to the end).
struct MosaicOdometryStats {
  int64_t windows = 0;        // windows whose rate was estimated
  int64_t short_windows = 0;  // a last window under half the window's time and events: previous rate kept
  int64_t still_windows = 0;  // of windows, read as still (bootstrap_min_contrast_gain): rate zero
};

// A span of lost tracking (camera clock): from the start of the first failure window below the
// lost level to the end of the window that recovered (or the last event).
struct MosaicLostSegment {
  int64_t t_begin_ns = 0;
  int64_t t_end_ns = 0;
  bool recovered = false;        // a window reached failure_recovered_contrast again
  int64_t relocalizations = 0;   // particle spreads while lost
  int64_t global_searches = 0;   // searches of the whole mosaic while lost
  int64_t global_jumps = 0;      // of which moved the particles to the view found
  // The mosaic's state was rolled back to its checkpoint at this time (camera clock; INT64_MIN: no
  // rollback, e.g. no checkpoint old enough).
  int64_t map_rolled_back_to_ns = INT64_MIN;
};

struct MosaicStats {
  int64_t events = 0;                 // events given to add_events
  int64_t imu_samples = 0;            // IMU samples given to add_imu
  int64_t t_first_event_ns = 0;       // camera clock; both 0 without events
  int64_t t_last_event_ns = 0;
  int64_t events_mapped = 0;          // events whose path updated the mosaic
  int64_t reconstructions = 0;        // Poisson solves for the tracker (the bootstrap's included)
  int64_t snapshots = 0;              // snapshot callbacks
  int64_t seen_pixels = 0;            // of the final reconstruction
  double seen_fraction = 0;           // seen_pixels / mosaic texels
  MosaicBootstrapStats bootstrap;
  MosaicOdometryStats odometry;
  backend::CmaxSlamStats cmax_slam;  // kCmaxSlam only
  frontend::RotationParticleFilterStats tracker;
  // Tracking quality (tracker.probe_every_batches > 0): the failure windows' mean probe contrast
  // (log-likelihood per event), lowest and mean over the windows; events not mapped while lost.
  int64_t quality_windows = 0;
  int64_t quality_windows_undecided = 0;  // windows under failure_min_events or failure_min_rate_ratio
  double quality_min = 0;
  double quality_mean = 0;
  int64_t events_unmapped_lost = 0;
};

struct MosaicResult {
  // R_w_b as T_w_b (zero translation) in the mosaic frame, camera clock, at most one pose per
  // trajectory_period_ns: the first event, each bootstrap window's end, then the tracker's batches.
  Trajectory rotation;
  // The final full Poisson reconstruction (H x W log intensity up to an offset, seen mask), weighted
  // per output_weighting.
  mapping::MosaicReconstruction reconstruction;
  MosaicStats stats;
  std::vector<MosaicLostSegment> tracking_lost;
  // kCmaxSlam: the back-end's panoramic event map (events per texel, reconstruction-sized,
  // row-major); empty otherwise.
  std::vector<float> event_map;
};

class MosaicPipeline {
 public:
  // Called at each snapshot time (camera clock) with the tracker's current reconstruction (log
  // intensity, 0 where unseen, and the seen mask), on the caller's thread.
  using SnapshotCallback = std::function<void(int64_t t_ns, const mapping::MosaicReconstruction&)>;

  // camera: intrinsics (undistortion), T_c_b (only its rotation: the gyro's frame and the written
  // body orientation) and time_shift_ns (t_imu = t_cam + shift). Throws std::invalid_argument when
  // the options are invalid.
  MosaicPipeline(const MosaicPipelineOptions& options, const calib::CameraCalibration& camera);
  ~MosaicPipeline();
  MosaicPipeline(const MosaicPipeline&) = delete;
  MosaicPipeline& operator=(const MosaicPipeline&) = delete;

  void set_snapshot_callback(SnapshotCallback callback);

  // Called after each particle-filter batch (trackers pf and odometry+pf) with the batch's time
  // (camera clock), the camera's orientation in the mosaic frame, the particles' weighted covariance
  // (right, camera tangent, rad^2) and whether the tracker counts as lost, on the caller's thread:
  // for an estimator that takes the orientation as it comes (evio vio's rotation tracker).
  using TrackCallback =
      std::function<void(int64_t t_ns, const Eigen::Quaterniond& q_m_c, const Eigen::Matrix3d& cov_c, bool lost)>;
  void set_track_callback(TrackCallback callback);

  // Diagnostic (splitting the error into bootstrap and tracking): the bootstrap maps its events with
  // these body rotations R_w_b(t) (camera clock; e.g. the ground truth), expressed in the mosaic
  // frame relative to the first event's, instead of gyro or contrast-maximisation rates; the
  // tracker's initial velocity is their difference over the last window. A time the function
  // cannot answer (std::nullopt) falls back to the rates. Call before the first add_events.
  using RotationReference = std::function<std::optional<Eigen::Quaterniond>(int64_t t_ns)>;
  void set_bootstrap_reference(RotationReference R_w_b_at);

  // Diagnostic (the map's error without the tracker's feedback): with true, the set_bootstrap_reference
  // rotations also map every tracked event (the tracker's estimate is still written as the trajectory
  // and the tracker still tracks against the reconstructions). Call before the first add_events.
  void set_reference_for_mapping(bool on);

  // Diagnostic (splitting the tracker's error from the map's): the tracker weighs its particles
  // against this fixed map instead of the mosaic's reconstructions (the mosaic is still built and
  // returned). Called once, at the tracking start, with R_m_b0 (the body's rotation at the first
  // event in the mosaic frame) and that event's time; returns options.mosaic.height rows of
  // options.mosaic.width log intensities (row-major, NaN = unknown), e.g. the true panorama
  // rendered in the mosaic frame. The tracker's contrast is calibrated on it (calibrate_contrast).
  // Call before the first add_events.
  using MapReference = std::function<std::vector<float>(const Eigen::Matrix3d& R_m_b0, int64_t t0_ns)>;
  void set_tracker_map_reference(MapReference map_at_start);

  // IMU samples in time order (IMU clock), used with use_gyro (ignored otherwise). They may all
  // come first or be interleaved with add_events.
  void add_imu(const ImuSample& sample);
  // Raw events in time order (camera clock), e.g. chunks as read. Events are kept only until the
  // bootstrap window or tracker batch they belong to is complete, so memory stays bounded by one
  // window (or batch) plus one chunk; the results do not depend on the chunking, nor on how the
  // IMU is interleaved as long as it arrives within imu_wait_ns of the events.
  void add_events(EventSpan events);
  // Processes everything buffered, reconstructs the final mosaic (full solve) and returns the
  // results. No input is accepted afterwards (std::logic_error).
  MosaicResult finish();

  // Events processed so far (bootstrap and tracker), for progress reports.
  int64_t events_processed() const;
  // Events held now: waiting for their bootstrap window or tracker batch to complete, or for the IMU.
  size_t buffered_events() const;
  // The options as they run: tracker_method resolved (never kAuto).
  const MosaicPipelineOptions& options() const { return options_; }

 private:
  struct Impl;
  MosaicPipelineOptions options_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace evio::pipeline
