// MosaicPipeline's state and steps (internal to evio::pipeline; the public class is in
// mosaic_pipeline.h). The steps are defined by concern:
//   mosaic_pipeline.cc          options, input buffering, IMU, trajectory, the tracking step, the API
//   mosaic_bootstrap.cc         bootstrap windows (gyro or rotational CMax rates) and the tracker's start
//   mosaic_tracking_monitor.cc  tracking failure: lost / recovered, re-localisation, map rollback
//   mosaic_mapper.cc            the mapping half and its worker thread (mosaic_mapper.h)
#pragma once

#include <climits>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "evio/frontend/event_filters.h"
#include "evio/frontend/rotation_particle_filter.h"
#include "evio/pipeline/mosaic_pipeline.h"
#include "mosaic_mapper.h"

namespace evio::pipeline {

// Tracker events per MapperBlock between reconstructions (a block is also closed at each
// reconstruction): the mapper thread is woken about once per this many events.
constexpr size_t kMapperBlockEvents = 4096;

struct MosaicPipeline::Impl {
  using Mapper = internal::Mapper;
  using MapperBlock = internal::MapperBlock;
  using MapperQueue = internal::MapperQueue;

  Impl(const MosaicPipelineOptions& o, const calib::CameraCalibration& camera);

  enum class Phase { kStart, kBootstrap, kTracking };

  const MosaicPipelineOptions& opt;
  const calib::CameraCalibration cal;
  const int W, H;
  const int64_t shift;  // t_imu = t_cam + shift
  const Eigen::Quaterniond q_c_b;
  const frontend::EventUndistorter undistorter;
  Mapper mapper;
  MapperQueue queue;
  mapping::RotationalCmaxOptions cmax;

  Phase phase = Phase::kStart;
  bool finished = false;
  bool finishing = false;  // finish(): process what is buffered without waiting for more
  SnapshotCallback on_snapshot;
  TrackCallback on_track;

  // Events not yet processed: pending[head, size). Compacted on every add_events.
  std::vector<Event> pending;
  size_t head = 0;
  int64_t processed = 0;

  // IMU (IMU clock): samples older than the ones still needed are pruned in tracking.
  std::vector<ImuSample> imu;
  size_t next_imu = 0;       // tracking: the next sample for the particle filter
  bool imu_started = false;  // tracking: next_imu positioned at the tracking start

  int64_t t_viewed = INT64_MIN;  // the last mark_footprint

  // Bootstrap.
  Eigen::Matrix3d R = mosaic_initial_camera_rotation();
  Eigen::Vector3d omega_c = Eigen::Vector3d::Zero();
  int64_t t0 = 0, t_boot = 0;
  MosaicPipeline::RotationReference boot_ref;  // diagnostic: bootstrap rotations R_w_b(t)
  bool ref_for_mapping = false;                // diagnostic: boot_ref maps the tracked events too
  MosaicPipeline::MapReference map_ref;        // diagnostic: the tracker's fixed map
  std::vector<float> oracle_map;               // its answer (empty: the reconstructions)
  // R_w_c in the mosaic frame from boot_ref (std::nullopt where it has no answer).
  std::optional<Eigen::Matrix3d> boot_ref_at(int64_t t) const;

  // Tracking.
  std::unique_ptr<frontend::RotationParticleFilter> pf;
  frontend::LogIntensityMapView view;
  int front = 0;                       // mapper.maps[front] is the tracker's map
  MapperBlock block;                   // mapper steps not yet submitted
  int64_t rec_point = 0;               // events processed at the last reconstruction's point
  int64_t rec_t = 0;                   // and its time
  int64_t recs_submitted = 0;          // reconstructions of the tracking phase submitted
  int64_t recs_in_use = 0;             // and switched to by the tracker
  int64_t next_snap = INT64_MAX;

  // Odometry ahead of the filter (kOdometryParticleFilter, events only): pending[head + odo_ahead]
  // is the first event of the next contrast-maximisation window, odo_mid_t the middle of the last
  // window (its rate's sample time; INT64_MIN: none yet).
  size_t odo_ahead = 0;
  int64_t odo_mid_t = INT64_MIN;
  bool moved = false;  // a contrast-maximisation window has sharpened its events (cmax_rate)

  // kCmaxSlam: the back-end, the events waiting for their window to be final (then mapped), the
  // knots recorded in the trajectory so far, and whether the back-end has finished.
  std::unique_ptr<backend::CmaxSlam> slam;
  std::deque<Event> slam_waiting;
  size_t slam_recorded = 0;
  bool slam_finished = false;
  // Maps the waiting events the back-end has finalised and records its final knots.
  void slam_drain();

  // Tracking failure (mosaic_tracking_monitor.cc).
  bool lost = false;
  int64_t probe_seen_t = INT64_MIN, window_t0 = INT64_MIN;
  double window_sum = 0, quality_sum = 0;
  int64_t window_n = 0, window_events = 0;
  int64_t window_all_events = 0;  // every event of the window's batches
  double rate_mean = 0;           // running mean of window_all_events
  int low_windows = 0;         // consecutive decided windows below the lost level
  int64_t low_since = 0;       // start of the first of them
  std::mt19937_64 relocalize_rng{0x5eed};
  // Checkpoint times issued to the mapper (mirrors Mapper::checkpoints).
  std::deque<int64_t> cp_times;
  // The tracker's most recent events (ring of bootstrap_window_events), for the global search.
  std::vector<Event> recent;
  size_t recent_next = 0;
  int64_t last_global_t = INT64_MIN;

  MosaicResult result;

  size_t available() const { return pending.size() - head; }

  // ---- IMU (mosaic_pipeline.cc; gyro_c_at in mosaic_bootstrap.cc) -------------------------------

  // True when every IMU sample up to the camera-clock time t_cam has come (one after it has).
  bool imu_covers(int64_t t_cam) const { return !imu.empty() && imu.back().t_ns - shift > t_cam; }
  // True when the newest buffered event is more than imu_wait_ns ahead of the newest IMU sample (of
  // the oldest buffered event without any IMU): the gyro is missing there, do not wait for it.
  bool imu_missing() const {
    if (available() == 0) return false;
    const int64_t newest = imu.empty() ? pending[head].t_ns : imu.back().t_ns - shift;
    return pending.back().t_ns - newest > opt.imu_wait_ns;
  }
  bool imu_ready(int64_t t_cam) const { return !opt.use_gyro || finishing || imu_covers(t_cam) || imu_missing(); }
  Eigen::Vector3d gyro_c_at(int64_t t_cam) const;

  // ---- trajectory (mosaic_pipeline.cc) ----------------------------------------------------------
  void record(int64_t t, const Eigen::Matrix3d& R_w_c);
  mapping::GradientMosaic::ReconstructMode next_reconstruct_mode();

  // ---- bootstrap (mosaic_bootstrap.cc) ----------------------------------------------------------
  // Events only: the end of the contrast-maximisation window that starts with ev[0] at tw0, over
  // the n events ev[0..n): *count events (closed by bootstrap_window_events), *tw1 its end (the
  // count's closing event, tw0 + bootstrap_window_ns, or t_limit, whichever is first). False when
  // the window may still get events (it reaches the end of ev[0..n) before its end, not finishing).
  bool cmax_window(const Event* ev, size_t n, int64_t tw0, int64_t t_limit, size_t* count, int64_t* tw1) const;
  // The rotational contrast-maximisation rate of the events ev[0..n) around tw0, from omega_c;
  // omega_c is kept when the window was cut short (`cut`: by the bootstrap's or the data's end)
  // below half the window's time and events (too little motion to constrain the rate), and set to
  // zero when the window reads as still (*still = true; see bootstrap_min_contrast_gain).
  // Returns true when a rate was estimated.
  bool cmax_rate(const Event* ev, size_t n, int64_t tw0, int64_t tw1, bool cut, bool* still);
  bool bootstrap_step();
  void end_bootstrap(int64_t t_track0);

  // ---- tracking failure (mosaic_tracking_monitor.cc) --------------------------------------------
  void watch_quality(int64_t t_now, size_t batch_events);
  void relocalize();
  void rollback_map(int64_t t_bound, int64_t t_now);
  void remember(const Event* ev, size_t n);
  bool global_relocalize(int64_t t_now);

  // ---- tracking and mapping (mosaic_pipeline.cc) ------------------------------------------------
  bool odometry_ahead(int64_t t_now);
  bool tracking_step();
  void use_reconstruction();
  void process();
};

}  // namespace evio::pipeline
