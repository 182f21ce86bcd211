// VioPipeline's state and steps (internal to evio::pipeline; the public class is in
// vio_pipeline.h). The steps are defined by concern:
//   vio_pipeline.cc        options, IMU buffering, the front-ends (event frames, reconstruction,
//                          corners), the estimator feed, output states and keyframe chaining, the API
//   vio_initialization.cc  when and how the first state is found (static, alignment, given; on stalls)
//   vio_aps_merge.cc       APS frames: tracking and the merge with the event frames (events+aps)
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "evio/backend/sliding_window_estimator.h"
#include "evio/backend/trajectory_smoothing.h"
#include "evio/pipeline/vio_pipeline.h"

namespace evio::pipeline {

struct VioPipeline::Impl {
  Impl(const VioPipelineOptions& o, const calib::CameraCalibration& camera, const calib::ImuNoise& imu_noise);

  // The undistorted pinhole of the event frames and the undistorted APS frames.
  calib::CameraIntrinsics ideal_pinhole() const {
    calib::CameraIntrinsics ideal = cal.camera.intrinsics();
    ideal.model = calib::DistortionModel::kNone;
    ideal.distortion.clear();
    return ideal;
  }

  const VioPipelineOptions& opt;
  const calib::CameraCalibration cal;
  const calib::ImuNoise noise;
  const int width, height;
  const int64_t shift;  // t_imu = t_cam + shift
  const bool use_frames;
  const bool use_events, use_aps;

  InitialStateProvider initial_state;
  ObservationCallback on_observations;
  ObservationFilter observation_filter;
  TrackingImageCallback on_tracking_image;
  FrameMotionOracle frame_motion_oracle;
  // Output states: to on_state, or collected in result. A frame's trajectory state waits in
  // `predictions` until the keyframes around it have left the window (release()); final_keyframes
  // holds the keyframes' last optimised states from the oldest anchor still needed on.
  VioPipeline::StateCallback on_state;
  std::deque<backend::FramePrediction> predictions;  // per causal state not yet released
  std::map<int64_t, VioState> final_keyframes;
  // keyframe_chaining: per keyframe, its pose relative to the next keyframe in the latest solve that
  // held both, T_k^-1 T_k+1 (by k's time), and the output states chained from those relatives.
  std::map<int64_t, std::pair<int64_t, calib::SE3>> relative_to_next;
  std::map<int64_t, VioState> chained_keyframes;
  int64_t last_causal_t = std::numeric_limits<int64_t>::min();
  int64_t last_keyframe_out = std::numeric_limits<int64_t>::min();
  bool finished = false;

  // IMU (IMU clock): every sample still needed by the initialisation, the estimator or the
  // rotation prior; older ones are pruned (prune_imu).
  std::vector<ImuSample> imu;
  size_t next_imu = 0;  // the next sample for the estimator
  // Event chunks waiting for the IMU to cover them (copies of add_events' spans).
  std::deque<std::vector<Event>> waiting;

  // Front-end.
  const frontend::EventUndistorter undistorter;
  frontend::RefractoryFilter refractory;
  frontend::BackgroundActivityFilter background;
  std::unique_ptr<frontend::EventFrameBuilder> frame_builder;
  // tracking_image kReconstruction: the high-pass filter (made at the first event), its frame clock
  // and the undistortion of its images.
  std::unique_ptr<mapping::ComplementaryFilter> recon;
  std::unique_ptr<frontend::FrameUndistorter> recon_undistorter;
  int64_t recon_frame_start = -1;  // camera clock: the current frame's first event (-1: none yet)
  int64_t recon_frame_events = 0;
  mapping::ImageF recon_log;
  cv::Mat recon_grey;
  std::unique_ptr<frontend::FeatureTracker> frame_tracker;
  std::unique_ptr<frontend::EfastDetector> detector;
  std::unique_ptr<frontend::CornerTracker> corner_tracker;
  std::vector<Event> filtered;
  std::vector<frontend::EventFrame> built;
  int64_t prev_frame_t = -1;  // camera clock, last event frame
  std::optional<FeatureObservations> last_tracked;  // the latest event frame's tracks (for the frame-motion oracle)
  std::vector<double> depth_scratch;                // landmark depths (median_landmark_depth)
  std::optional<frontend::FrameMotion> latest_motion;  // use_depth without frame_velocity_at_reference
  int64_t next_obs = 0;       // camera clock, next corner observation frame
  bool have_events = false;
  int64_t last_stall_init_ns = std::numeric_limits<int64_t>::min() / 2;  // IMU clock, try_init_on_stall
  int64_t frame_id = 0;

  // APS frames.
  std::unique_ptr<frontend::FrameUndistorter> aps_undistorter;
  std::unique_ptr<frontend::FeatureTracker> aps_tracker;
  std::deque<Frame> waiting_frames;           // waiting for the IMU to cover them
  int64_t prev_aps_t = -1;                    // camera clock, last tracked APS frame
  std::vector<int64_t> aps_times;             // IMU clock, every APS frame added (events+aps)
  std::deque<FeatureObservations> aps_ready;  // events+aps: tracked, waiting for the event frame after them
  std::optional<FeatureObservations> last_event_obs;  // events+aps: the latest event frame (IMU clock)
  int64_t last_emitted_t = std::numeric_limits<int64_t>::min();  // IMU clock, last frame to the estimator

  // Back-end and results.
  std::unique_ptr<backend::SlidingWindowEstimator> est;
  std::vector<FeatureObservations> pending;  // frames before initialisation
  VioResult result;
  bool in_gap = false;     // emitting the empty frames of an event-rate drop
  int64_t few_since = -1;  // start of the current run of frames with too few tracks (IMU clock)
  // IMU-only spans: the last frame that gave the initialised estimator at least
  // tracking_lost_min_tracks observations (IMU clock; -1: none yet), and whether the frames since
  // were empty gap frames (no events) or frames with too few tracks.
  int64_t last_visual_t = -1;
  bool gap_since_visual = false;

  // Rotation tracker (options rotation_tracker): runs while the motion model is rotation-only.
  std::unique_ptr<MosaicPipeline> rot_tracker;
  int64_t rot_segment = 0;          // the current segment's id (the estimator's tracker segment)
  bool rot_lost = false;            // the tracker reported lost since its last orientation
  int rot_run = 0;                  // consecutive keyframes against the tracker's state (to start or stop it)
  std::set<int64_t> tracker_keyframes;  // keyframes (IMU clock) with a tracker factor, until chained
  size_t tracker_factors_seen = 0;      // entries of the estimator's tracker_factors taken
  int64_t rot_imu_fed_t = std::numeric_limits<int64_t>::min();  // IMU clock, last sample given to it
  int64_t rot_run_start_t = 0;       // IMU clock: the first keyframe of the current run
  std::deque<Event> rot_history;     // raw events of the last rotation_tracker_history_ns while the tracker is off
  // A held tracker (rotation_tracker_from_start: the first one, from the recording's start;
  // rotation_tracker_hold_on_stop: a stopped one): whether the first was started, whether the
  // tracker's orientations are held back (the start rule has not opened), those orientations,
  // and the consecutive keyframes that meet the start rule.
  bool rot_lead_started = false;
  bool rot_lead = false;
  std::vector<backend::SlidingWindowEstimator::TrackedRotation> rot_held;
  int rot_lead_start_run = 0;
  int64_t rot_hold_start_t = -1;  // IMU clock: the held tracker's first keyframe (-1: none yet)
  bool rot_fed = false;  // the tracker's orientations have gone to the estimator
  // After the keyframe at t_kf (IMU clock): starts or stops the tracker. can_start: the keyframe
  // meets the start rule; can_continue: it does not count towards the stop.
  void update_rotation_tracker(int64_t t_kf, bool can_start, bool can_continue);
  // A tracker whose first event is at or after from_t (IMU clock), fed the IMU from a little before.
  void start_rotation_tracker(int64_t from_t);
  void start_rotation_tracker_lead(int64_t t_first_event);
  // rotation_tracker_held_output: the final keyframes not yet output take the held tracker's
  // rotation (called as its orientations are released, before rot_held is cleared).
  void correct_held_output();
  void keep_rotation_tracker_history(EventSpan chunk);
  void rotation_tracker_events(EventSpan chunk);
  void rotation_tracker_imu();
  void rotation_tracker_spans();

  // ---- IMU ------------------------------------------------------------------------------------

  // True when every IMU sample up to the camera-clock time t_cam + imu_lookahead_ns has come.
  bool imu_covers(int64_t t_cam) const {
    return !imu.empty() && imu.back().t_ns > t_cam + shift + opt.imu_lookahead_ns;
  }
  // True when the newest waiting event is more than imu_wait_ns ahead of the newest IMU sample (of
  // the oldest waiting event without any IMU): the IMU is missing there, do not wait for it.
  bool imu_missing() const {
    const int64_t newest = imu.empty() ? waiting.front().front().t_ns + shift : imu.back().t_ns;
    return waiting.back().back().t_ns + shift - newest > opt.imu_wait_ns;
  }

  void prune_imu();

  // ---- back-end (vio_pipeline.cc) -------------------------------------------------------------
  void output(VioPipeline::StateKind kind, const VioState& s);
  void release(int64_t t_final);
  void chain_final(int64_t t_final);
  void feed(const FeatureObservations& f);
  void health_segments();
  void close_imu_only_span(int64_t t);
  std::string lost_reason() const { return "fewer than " + std::to_string(opt.tracking_lost_min_tracks) + " tracks"; }

  // ---- initialisation (vio_initialization.cc) -------------------------------------------------
  int64_t stalled_frames_until() const;
  void try_init_on_stall();
  void try_init(bool final_attempt);

  // ---- front-end (vio_pipeline.cc) ------------------------------------------------------------
  void handle_frame(FeatureObservations f);
  void emit_corner_frame(int64_t t_cam);
  void track_event_frame(const frontend::EventFrame& ef);
  bool propagated_state(int64_t t, VioState* out) const;
  std::vector<frontend::TrackPrediction> lost_track_predictions(int64_t t) const;
  void emit_gap_frames(int64_t t_cam);
  bool rotation_prior(int64_t t0_cam, int64_t t1_cam, Eigen::Matrix3d* R_cur_prev) const;
  void emit(FeatureObservations f);
  void feed_back_motion(const FeatureObservations& f);
  bool median_landmark_depth(const VioState& st, double* depth_m);
  bool frame_motion_at(int64_t t, frontend::FrameMotion* m);
  void process(EventSpan chunk);
  void reconstruct_and_track(const std::vector<Event>& ev);
  void close_recon_frame(int64_t t_cam);
  void drain(bool all);

  // ---- APS frames (vio_aps_merge.cc) ----------------------------------------------------------
  void emit_event_frame(FeatureObservations e);
  static void append_interpolated(const FeatureObservations& a, const FeatureObservations& b, FeatureObservations* out);
  void track_aps_frame(const Frame& fr);
  void drain_frames(bool all);

  void check_open() const {
    if (finished) throw std::logic_error("VioPipeline: input after finish()");
  }
};

}  // namespace evio::pipeline
