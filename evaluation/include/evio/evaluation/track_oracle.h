// Oracle feature tracks for error budgets: replaces the bearings of a front-end's observations by
// the true projections of their landmarks, keeping the front-end's track topology (which tracks
// exist, when they start and end), optionally with synthetic error added back. Running the VIO
// back-end on oracle tracks splits its error into what the topology and the back-end give (exact
// tracks), what white pixel noise gives, and what a random-walk drift gives, against the real
// tracks (the "oracle breakdown" of an error budget).
//
// The landmark of a track is the ray of its first observation cast into the true scene at the true
// pose (as TrackReference::kAnchored of track_evaluation.h). Observations are on the body (IMU)
// clock; the true camera pose is T_w_b(t) T_c_b^-1 from the ground truth (interpolated).
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <random>
#include <string>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "evio/calib/calibration_io.h"
#include "evio/evaluation/track_evaluation.h"
#include "evio/sensors/trajectory.h"
#include "evio/sensors/vio_types.h"

namespace evio::evaluation {

// What an oracle observation keeps of the front-end's own error e (observed minus true projection,
// px), split per frame into its common mode c (the per-axis median of e over the frame's
// observations within 10 px: the error every track of the frame shares) and the rest:
enum class OracleError {
  kNone,         // the true projection (plus the synthetic noise below)
  kReal,         // the observation as tracked (e); the synthetic noise is still added
  kIndependent,  // e - c: the frame's common mode removed
  kCommonMode    // c: every track of the frame moved by the common mode alone
};
// "none", "real", "independent", "common_mode".
const char* to_string(OracleError e);

struct TrackOracleOptions {
  OracleError keep_error = OracleError::kNone;
  // With keep_error real or independent: observations whose own error e is larger than this are
  // dropped (px, >= 0; 0 = keep all): how much of the error the gross ones (e.g. tracks sliding
  // along an edge) make. Counted in TrackOracleStats::dropped_gross.
  double max_error_px = 0;
  // White noise added to every oracle observation: isotropic Gaussian, standard deviation per
  // axis (px on the ideal pinhole, >= 0).
  double white_noise_px = 0;
  // Random-walk drift: every observation after a track's first adds an isotropic Gaussian step of
  // this standard deviation per axis to the track's accumulated offset (px per frame, >= 0): the
  // error of chained frame-to-frame tracking.
  double drift_px_per_frame = 0;
  uint64_t seed = 1;  // of the noise generator

  bool Validate(std::string* why) const;
};

struct TrackOracleStats {
  int64_t replaced = 0;  // observations replaced by their true projection
  int64_t dropped = 0;   // observations removed: outside the ground truth, no scene hit for the
                         // track's first ray, or landmark behind the camera
  double common_mode_rms_px = 0;  // rms over frames of the common mode c (keep_error != kNone)
  int64_t frames = 0;             // frames with a common mode (keep_error != kNone)
  int64_t dropped_gross = 0;      // observations dropped by max_error_px
  // The front-end's own error by track age (keep_error != kNone): observations whose age (frames
  // since the track's first observation) lies in [kAgeBucketStart[k], kAgeBucketStart[k + 1]),
  // the last bucket open-ended. Error against the first observation's landmark, so a track that
  // drifts shows an error growing with age and one with white error a flat one.
  static constexpr int kAgeBuckets = 7;
  static constexpr int kAgeBucketStart[kAgeBuckets] = {1, 2, 4, 8, 16, 32, 64};
  // |e - c| is also binned (kBinPx wide, the last bin open-ended) for robust quantiles: the rms
  // is dominated by the few gross errors (tracks sliding along an edge) that the back-end's robust
  // loss and outlier test remove.
  static constexpr double kBinPx = 0.02;
  static constexpr int kBins = 1000;
  struct AgeBucket {
    int64_t count = 0;
    double error_rms_px = 0;        // rms of |e|
    double independent_rms_px = 0;  // rms of |e - c| (the frame's common mode removed)
    double sq_sum = 0, independent_sq_sum = 0;
    std::array<int64_t, kBins> independent_hist{};
    // Quantile q in [0, 1] of |e - c| (px, the upper edge of its bin; 0 without observations).
    double independent_quantile_px(double q) const;
  };
  AgeBucket by_age[kAgeBuckets];
};

// The ground-truth state at t_ns (pose interpolated; velocity by a central difference over 10 ms;
// zero biases), or nullopt where the ground truth does not cover t_ns +- 5 ms.
std::optional<VioState> groundtruth_state(const Trajectory& groundtruth, int64_t t_ns);

// The true motion the event frames' translation compensation needs at a front-end frame (IMU
// clock): the velocity of the camera centre in the camera frame (m/s; central difference of the
// ground-truth camera positions over 10 ms, so a camera-IMU lever arm is included) and the median z-depth (m) of the frame's tracks (each bearing cast into the scene
// at the true pose). False when the ground truth does not cover the frame or no ray hits.
// plane_c (optional): the least-squares plane n . P = d (camera frame, n unit, d > 0) through
// those scene points (d = 0 when fewer than 3 hit or they do not span a plane).
bool true_frame_motion(const Trajectory& groundtruth, const calib::SE3& T_c_b, const RayCaster& cast,
                       const FeatureObservations& frame, Eigen::Vector3d* v_c, double* depth_m,
                       Eigen::Vector4d* plane_c = nullptr);

// One front-end observation as the oracle measured it (keep_error != kNone), for studies of the
// tracks' error (e.g. scripts/track_error_study.py): its own error e and its frame's common mode c
// (as OracleError), and the truth it is measured against.
struct OracleObservation {
  int64_t t_ns = 0;     // frame time (IMU clock)
  int64_t track_id = 0;
  int64_t age = 0;      // observations of the track before this one (0: its first)
  Eigen::Vector2d error_px = Eigen::Vector2d::Zero();        // e: observed minus true projection (px)
  Eigen::Vector2d common_mode_px = Eigen::Vector2d::Zero();  // c: the frame's common mode (px)
  Eigen::Vector2d true_px = Eigen::Vector2d::Zero();         // true projection (px, ideal pinhole)
  // Image velocity of the true projection (px/s; the landmark projected at t -+ 2 ms of the ground
  // truth), zero where the ground truth does not cover t -+ 2 ms.
  Eigen::Vector2d true_flow_px_s = Eigen::Vector2d::Zero();
  double depth_m = 0;   // z-depth of the landmark in the true camera frame (m)
  Eigen::Quaterniond q_c_w = Eigen::Quaterniond::Identity();  // true camera orientation, world -> camera
};

class TrackOracle {
 public:
  // Throws std::invalid_argument on invalid options or an empty ray caster.
  TrackOracle(const Trajectory& groundtruth, const calib::CameraCalibration& camera, RayCaster cast,
              const TrackOracleOptions& options = {});

  // Replaces the observations of one frame in place (frames in time order).
  void apply(FeatureObservations* frame);
  const TrackOracleStats& stats() const { return stats_; }
  // Called for every observation apply() measures (keep_error != kNone), in frame order, before
  // max_error_px drops any.
  void set_observation_sink(std::function<void(const OracleObservation&)> sink) { sink_ = std::move(sink); }

 private:
  struct Landmark {
    bool valid = false;
    Eigen::Vector3d X_w = Eigen::Vector3d::Zero();
    Eigen::Vector2d drift_px = Eigen::Vector2d::Zero();
    int64_t age = 0;  // observations of the track before the current one
  };
  Trajectory gt_;
  calib::CameraCalibration camera_;
  RayCaster cast_;
  TrackOracleOptions options_;
  TrackOracleStats stats_;
  std::map<int64_t, Landmark> landmarks_;
  std::mt19937_64 rng_;
  double common_mode_sq_sum_ = 0;
  std::function<void(const OracleObservation&)> sink_;
};

}  // namespace evio::evaluation
