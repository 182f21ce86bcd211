// Motion-compensated event frames for feature-based VIO (Rebecq, Horstschaefer, Scaramuzza,
// "Real-time Visual-Inertial Odometry for Event Cameras using Keyframe-based Nonlinear
// Optimization", BMVC 2017): every N events are warped to one reference time with the rotation
// integrated from the gyroscope (optionally also the translation from a camera velocity and a
// median scene depth) and splatted bilinearly into an image in undistorted pinhole coordinates.
#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core/mat.hpp>

#include "evio/calib/calibration_io.h"
#include "evio/sensors/event_buffer.h"
#include "evio/sensors/measurements.h"

namespace evio::frontend {

struct EventFrameOptions {
  // Events per frame. Default 15000: about a third of the 43,200 pixels of a DAVIS240
  // (240x180), enough to draw every textured edge of a typical ECD scene (shapes, poster, boxes)
  // once or twice without smearing; at the 0.5-3 M events/s of those sequences a frame spans
  // 5-30 ms. This is evio's choice for DAVIS240-sized sensors (scale it with the pixel count for
  // others), not a number taken from the paper.
  int events_per_frame = 15000;
  // Longest frame window, ns (default 50 ms). When the next event is this late after the
  // frame's first event the frame is closed with the events it has (event-rate drops, a still
  // camera), so frames keep coming at >= 1 / max_window_ns.
  int64_t max_window_ns = 50'000'000;
  // Low event rates (a hover, a low-texture view): a frame that reaches max_window_ns with fewer
  // than min_events events is not dropped but keeps its events until it has min_events, up to this
  // long (ns, >= max_window_ns; 0: off, such frames are dropped). The motion compensation
  // carries the longer window: slow motion is what makes the rate low (VioPipeline turns them on
  // once initialised).
  int64_t sparse_max_window_ns = 500'000'000;
  // ... only after this long without a frame (ns): a short dip of the rate (a velocity
  // reversal) drops its sparse frames, and only a real starvation gets the long ones,
  // whose compensation over 0.1-0.5 s is less precise than a 50 ms frame's.
  int64_t sparse_after_ns = 200'000'000;
  // Shortest frame window, ns, at most max_window_ns (default 0: N events decide). At high event rates
  // a frame then holds more than events_per_frame events (every event until min_window_ns), which
  // bounds the frame rate at 1 / min_window_ns: adaptive to the event rate.
  int64_t min_window_ns = 0;
  // Overlapping windows: this fraction of each emitted frame's events (its latest ones) starts the
  // next frame (default 0: disjoint windows). Frames then come 1 / (1 - overlap) times
  // as often, each still holding events_per_frame events (at least min_window_ns). max_window_ns
  // and min_events count only the events a frame adds: carried events alone never make a frame,
  // and they are discarded once max_window_ns older than the next event (a still camera).
  double overlap = 0.0;
  // Frames with fewer events (closed by max_window_ns or flush) are dropped and counted in
  // EventFrameStats::frames_dropped_sparse; min_events <= events_per_frame. Default 1000.
  int min_events = 1000;
  // Warp every event to the frame's reference time with the rotation from the gyroscope.
  bool motion_compensation = true;
  // Also compensate translation with set_motion()'s camera velocity and median depth (needs
  // motion_compensation; without a set_motion() call it changes nothing).
  bool use_depth = false;
  // Accumulate polarity (+1/-1) instead of counts (the paper's frames count events, ignoring
  // polarity, which is the default).
  bool use_polarity = false;
  // Normalisation to the CV_8UC1 image: with counts, the clip value c is the clip_percentile
  // quantile of the non-zero accumulator pixels and image = round(255 * min(a, c) / c); with
  // polarity, c is that quantile of |a| and image = round(127.5 + 127.5 * clamp(a / c, -1, 1)).
  // false: image = saturate_cast<uint8>(round(a)) (counts) or 128 + a (polarity), no scaling.
  bool normalize = true;
  double clip_percentile = 0.99;  // fraction; 1 = the maximum
  // Fixed clip instead of the percentile: c = clip_count (events per pixel, accumulator units),
  // the same for every frame whatever its content (0: the clip_percentile quantile).
  double clip_count = 0.0;
  // Rotation knots: the gyro is integrated (bias removed, midpoint rule on the linearly
  // interpolated rate) into camera-frame rotation matrices every knot_spacing_ns, ns
  // (default 0.5 ms); each event's rotation is the linear blend of the two neighbouring knot
  // matrices applied to its bearing. The blend's error is below theta^2 / 8 rad for a knot step of
  // theta rad: 2.6 mrad at 300 deg/s and 0.5 ms, so below 1e-6 rad (2e-4 px at f = 200 px).
  int64_t knot_spacing_ns = 500'000;
  // IMU coverage: the samples must bracket [t_begin, t_ref] on the IMU clock (t_imu = t_cam +
  // time_shift_ns), up to max_imu_extrapolation_ns at either end (ns, default 0: the gyro
  // rate is held constant over that gap), and no two consecutive samples inside may be more than
  // max_imu_gap_ns apart (ns, default 20 ms). Otherwise the frame is built without
  // compensation and counted in EventFrameStats::frames_uncompensated.
  int64_t max_imu_extrapolation_ns = 0;
  int64_t max_imu_gap_ns = 20'000'000;
  // Event lag, px along the image motion (default 0: none). An event fires once the log
  // intensity at its pixel has changed by the contrast threshold since the pixel's previous event,
  // i.e. after the edge that caused it has moved C / |grad log I| onward; frames warped with the
  // true motion then lie behind the edges along the flow, by about the same distance at every
  // speed (a property of the texture's edges, not of the motion; docs/results/vio.md). Compensated
  // frames move each warped event this far along the image motion at its position at the
  // reference time (the gyro's rotation, and with use_depth the translation at the event's depth).
  double event_lag_px = 0.0;
  // Keep the CV_32F accumulator (before normalisation) in EventFrame::accumulator.
  bool keep_accumulator = true;
  // Motion-compensated time surface instead of event counts (> 0; default 0: counts). Each pixel
  // holds the largest exp(-(t_end - t_e) / tau) of the warped events that land on it (bilinear
  // weights), tau = this fraction of the frame's span t_end - t_begin: an edge that fired at all
  // is bright however many events it gave, so the image depends less on how the motion's direction
  // meets the gradients than counts (proportional to |grad L . flow|) do. Then normalised as the
  // counts are. Not with use_polarity.
  double time_surface_tau_fraction = 0.0;

  bool Validate(std::string* why) const;
};

struct EventFrame {
  int64_t t_ns = 0;        // reference time (camera clock): the last event's time
  int64_t t_begin_ns = 0;  // first event's time, ns
  int64_t t_end_ns = 0;    // last event's time, ns (== t_ns)
  size_t events = 0;       // events accumulated (including those warped outside the image)
  size_t events_outside = 0;  // events that fell outside the image after warping (or invalid pixels)
  bool motion_compensated = false;  // false: compensation off, or no IMU coverage
  cv::Mat image;        // CV_8UC1, undistorted pinhole coordinates (fx, fy, cx, cy of the calibration)
  cv::Mat accumulator;  // CV_32F bilinear votes, same geometry; empty unless keep_accumulator
};

struct EventFrameStats {
  int64_t frames_emitted = 0;
  int64_t frames_uncompensated = 0;   // emitted without compensation although it was on (IMU missing)
  int64_t frames_dropped_sparse = 0;  // closed with fewer than min_events
  int64_t events_dropped_sparse = 0;  // events in those frames
  int64_t imu_rejected = 0;           // IMU samples not after the previous one
  int64_t events_outside_sensor = 0;  // events with x >= width or y >= height, ignored
};

// The translation compensation's inputs for one frame (use_depth): the camera velocity in the
// camera frame at the frame's reference time (m/s, held constant over the frame) and either the
// median scene z-depth (m, > 0) or a scene plane n_c . P = plane_d_m (camera frame, n_c unit,
// plane_d_m > 0 m; 0: none, the depth is used).
struct FrameMotion {
  Eigen::Vector3d v_c = Eigen::Vector3d::Zero();
  double depth_m = 0;
  Eigen::Vector3d plane_n_c = Eigen::Vector3d::UnitZ();
  double plane_d_m = 0;
};
// Asked by build_frame, once per compensated frame with use_depth, for the motion at the frame's
// reference time t_ref_ns (camera clock); false: the frame keeps the motion set before.
using FrameMotionProvider = std::function<bool(int64_t t_ref_ns, FrameMotion* motion)>;

class EventFrameBuilder {
 public:
  // Throws std::invalid_argument when the options are invalid.
  EventFrameBuilder(const calib::CameraCalibration& camera, const EventFrameOptions& options);

  // Gyro (body frame, rad/s) for the rotation, on the IMU clock (t_imu = t_cam + time_shift_ns).
  // Samples must come in increasing time order (others are counted in imu_rejected and ignored);
  // add the IMU before the events it covers.
  void add_imu(const ImuSample& s);
  // Gyroscope bias, rad/s, subtracted from every sample of frames built from now on.
  void set_gyro_bias(const Eigen::Vector3d& b_g);
  // Camera velocity in the camera frame (m/s, assumed constant over a frame) and the median scene
  // z-depth (m, > 0) for use_depth. Each event's point at that depth is moved by v_c (t_k - t_ref).
  void set_motion(const Eigen::Vector3d& v_c, double median_depth_m);
  // The same with a scene plane n_c . P = d_m (camera frame, n_c unit, d_m > 0 m) instead of one
  // depth: each event's point is where its bearing meets the plane (z = d_m b_z / (n_c . b)).
  void set_motion_plane(const Eigen::Vector3d& v_c, const Eigen::Vector3d& n_c, double d_m);
  // The motion of each frame at its own reference time instead (set_motion's velocity, set once,
  // is stale by the time the next frame closes, and a stale velocity makes event tracks run ahead
  // along their motion; docs/design-notes.md). An empty function removes it. A provider's answer is
  // checked like set_motion's.
  void set_motion_provider(FrameMotionProvider provider) { provider_ = std::move(provider); }
  // Turns the sparse windows (options().sparse_max_window_ns) on or off from the next frame on
  // (a caller may hold them off until its estimate can compensate long windows).
  void set_sparse_windows(bool on) { sparse_on_ = on; }

  // Adds time-ordered events (camera clock); appends every completed frame to *out.
  void add_events(EventSpan events, std::vector<EventFrame>* out);
  // Emits the partial frame (when it has >= min_events; otherwise it is dropped and counted).
  void flush(std::vector<EventFrame>* out);

  // Builds one frame from `events` (time-ordered) warped to t_ref_ns (camera clock), with the
  // IMU buffered so far, independently of the N-event grouping. Used by add_events; public for
  // callers that need frames at chosen times (e.g. two halves of a window at a common time).
  EventFrame build_frame(EventSpan events, int64_t t_ref_ns);

  const EventFrameStats& stats() const { return stats_; }
  const EventFrameOptions& options() const { return o_; }
  // The undistorted pinhole the images are drawn in: [fx 0 cx; 0 fy cy; 0 0 1].
  Eigen::Matrix3d K() const;

 private:
  // Fills knots_ (camera-frame rotations R_c(ref)_c(t) at t_knot0_ + i * spacing) for the window;
  // false when the IMU does not cover it.
  bool compute_knots(int64_t t_begin_cam, int64_t t_end_cam, int64_t t_ref_cam);
  // Gyro at IMU-clock time t by linear interpolation (held constant beyond the ends).
  Eigen::Vector3d gyro_at(int64_t t_imu) const;
  void emit_pending(std::vector<EventFrame>* out);
  void prune_imu(int64_t t_keep_imu);

  EventFrameOptions o_;
  int width_ = 0, height_ = 0;
  float fx_ = 0, fy_ = 0, cx_ = 0, cy_ = 0;
  std::vector<Eigen::Vector3f> bearings_;  // per pixel, row-major; NaN where invalid
  Eigen::Matrix3d R_c_b_ = Eigen::Matrix3d::Identity();
  int64_t time_shift_ns_ = 0;

  std::deque<ImuSample> imu_;
  Eigen::Vector3d bias_gyro_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d v_c_ = Eigen::Vector3d::Zero();
  double depth_m_ = 0;  // 0: no depth set
  Eigen::Vector3d plane_n_ = Eigen::Vector3d::UnitZ();
  double plane_d_ = 0;  // > 0: per-event depth from the plane (set_motion_plane)
  FrameMotionProvider provider_;
  bool sparse_on_ = true;
  int64_t last_emitted_end_ns_ = std::numeric_limits<int64_t>::min();  // camera clock: the last emitted frame's last event

  std::vector<Event> pending_;
  size_t fresh_ = 0;  // pending_[0, fresh_) were carried from the previous frame (overlap)
  int64_t last_event_t_ns_ = 0;  // camera clock
  bool have_last_event_ = false;
  int64_t t_knot0_ = 0;  // camera clock
  std::vector<Eigen::Matrix3f> knots_;
  std::vector<float> scratch_;
  EventFrameStats stats_;
};

}  // namespace evio::frontend
