// Feature-track quality against ground truth, as in the feature-tracking analyses of event-tracker
// papers (Gehrig et al., EKLT, IJCV 2020; Messikommer et al., data-driven feature tracking, CVPR
// 2023): every observation of a track is compared with the projection of the track's true landmark
// at the observation's true pose; errors are reported overall and as a function of the track's age
// (frames since its first observation), with the tracks' lifetimes and the share lost while their
// landmark was still in view.
//
// The landmark of a track (Reference):
//  - kAnchored: the ray of the track's FIRST observation cast into the true scene (a caller-supplied
//    ray caster, e.g. simulator::PlanarScene::intersect). The error at age k is then the drift accumulated
//    since the track started (plus the first observation's own error, which is 0 by construction):
//    a drift-free tracker has an error that does not grow with age.
//  - kTriangulated: the least-squares point of every observation with the true poses (no scene
//    needed). A drift is partly absorbed by the point, so the figures are lower bounds of the drift.
// Pixels are those of the ideal (undistorted) pinhole with the calibration's fx, fy.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "evio/calib/calibration_io.h"
#include "evio/sensors/trajectory.h"
#include "evio/sensors/vio_types.h"

namespace evio::evaluation {

// Ray caster of the true scene: for a ray origin_w + s dir_w (s > 0) the parameter s of the
// nearest hit, or nullopt.
using RayCaster = std::function<std::optional<double>(const Eigen::Vector3d& origin_w, const Eigen::Vector3d& dir_w)>;

enum class TrackReference { kAnchored, kTriangulated };

struct TrackEvaluationOptions {
  TrackReference reference = TrackReference::kAnchored;
  // Observation times are on the body (IMU) clock, as FeatureObservations are; the true pose of an
  // observation is T_w_b(t) T_c_b^-1 from the ground truth (interpolated).
  // Age histogram: ages 1..max_age_frames (frames since the first observation; larger ages are
  // counted in the last bin), count.
  int max_age_frames = 60;
  // Tracks with fewer observations are not scored (count, >= 2; kTriangulated needs >= 2).
  int min_observations = 2;
  // kTriangulated: tracks whose most separated rays are closer than this are not scored (deg).
  double min_triangulation_angle_deg = 1.0;
  // Lost while visible: a track that ends before the last frame, whose landmark projects into the
  // next frame at least this far inside the image (px) and is not occluded (the ray cast towards
  // it hits within occlusion_tolerance of its range), was lost by the tracker. Needs a ray caster.
  double lost_border_px = 8.0;
  double occlusion_tolerance = 0.01;  // relative range difference
  // Observations farther than this from the landmark's projection count as gross errors: they are
  // excluded from the error statistics and reported in gross_errors (px, > 0).
  double gross_error_px = 10.0;
  // Keep every scored observation's error vector in TrackEvaluation::residuals (for plots and
  // error decompositions).
  bool keep_residuals = false;

  bool Validate(std::string* why) const;
};

struct TrackAgeBin {
  int age_frames = 0;      // frames since the track's first observation
  int64_t count = 0;       // scored observations of this age (gross errors excluded)
  double median_px = 0;    // NaN when count == 0
  double mean_px = 0;
  double p90_px = 0;
};

// One scored observation: observed minus predicted pixel on the ideal pinhole.
struct TrackResidual {
  int64_t t_ns = 0;
  int64_t track_id = 0;
  int age_frames = 0;
  Eigen::Vector2d error_px = Eigen::Vector2d::Zero();
};

struct TrackEvaluation {
  int64_t frames = 0;                  // frames with a true pose
  int64_t tracks = 0;                  // tracks with >= min_observations
  int64_t tracks_scored = 0;           // of those, with a landmark (ray hit / triangulable)
  int64_t observations_scored = 0;     // observations of age >= 1 of scored tracks (gross errors included)
  int64_t gross_errors = 0;            // of those, farther than gross_error_px
  double median_px = 0, mean_px = 0, p90_px = 0;  // over scored observations of age >= 1, no gross errors
  std::vector<TrackAgeBin> by_age;     // ages 1..max_age_frames
  double median_lifetime_frames = 0;   // observations per track (all tracks, also short ones)
  double mean_lifetime_frames = 0;
  double median_lifetime_s = 0;        // first to last observation, s
  int64_t lost_while_visible = 0;      // tracks that ended with their landmark still in view
  int64_t ended = 0;                   // tracks that ended before the last frame
  double lost_fraction = 0;            // lost_while_visible / ended (0 when none ended)
  // Mean observed tracks per frame.
  double mean_tracks_per_frame = 0;
  std::vector<TrackResidual> residuals;  // with keep_residuals (gross errors included)
};

// Scores the tracks of `frames` (time-ordered, body clock) against the true trajectory T_w_b.
// cast is needed for kAnchored and for the lost-while-visible analysis (may be empty with
// kTriangulated: lost_* stay 0). Frames outside the ground truth's span are ignored. Throws
// std::invalid_argument on invalid options, or kAnchored without a ray caster.
TrackEvaluation evaluate_tracks(const std::vector<FeatureObservations>& frames, const Trajectory& groundtruth,
                                const calib::CameraCalibration& camera, const RayCaster& cast,
                                const TrackEvaluationOptions& options = {});

// A compact JSON object of the figures (by_age included).
std::string track_evaluation_json(const TrackEvaluation& e);

}  // namespace evio::evaluation
