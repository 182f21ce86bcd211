// Frame-to-frame feature tracker of the VIO front-end on (motion-compensated, undistorted) 8-bit
// event frames: FAST corners with grid bucketing, pyramidal Lucas-Kanade (Bouguet's KLT, OpenCV)
// with a forward-backward check (Kalal et al. 2010), and RANSAC outlier rejection with OpenGV:
// the 2-point translation-only model with the IMU rotation prior (Kneip et al., "Robust real-time
// visual odometry with a single camera and an IMU", BMVC 2011) or Nister's 5-point essential matrix.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "evio/calib/camera.h"
#include "evio/sensors/vio_types.h"

namespace evio::frontend {

enum class RansacModel {
  kNone,      // no geometric verification
  kTwoPoint,  // translation only, rotation from the IMU: epipolar-plane angle test (no triangulation)
  kTwoPointTriangulating,  // the same model scored by OpenGV (TranslationOnlySacProblem): each pair
                           // triangulated and reprojected; rejects correct tracks over short baselines
  kFivePoint  // essential matrix, Nister's 5-point solver (opengv CentralRelativePoseSacProblem)
};

// "none", "two_point", "two_point_triangulating", "five_point".
const char* ransac_model_name(RansacModel model);

// Smallest number of correspondences ransac_inliers() runs RANSAC on: OpenGV's sample size,
// 2 for kTwoPoint and kTwoPointTriangulating, 8 for kFivePoint (5 for Nister's solver + 3 to pick among its solutions),
// 0 for kNone.
int ransac_min_correspondences(RansacModel model);

// Geometric verification of bearing correspondences (unit vectors in the camera frame; index i of
// both lists is one correspondence) between a previous and a current view.
//   model:          kNone returns all true.
//   R_cur_prev:     rotation prior for kTwoPoint, p_cur = R_cur_prev p_prev; nullptr = identity
//                   (pure translation). Ignored by kFivePoint.
//   threshold_rad:  angular threshold theta (rad); OpenGV scores a correspondence by the sum over
//                   both views of 1 - cos(reprojection angle) of the triangulated point and keeps
//                   it when the score is below 1 - cos(theta).
//   max_iterations: RANSAC iteration cap (OpenGV also stops at 99% confidence).
//   seed:           seeds OpenGV's sampler (its std::mt19937 is re-seeded from `seed` for every
//                   call), so the same input and seed give the same result.
// Degenerate input rule: with fewer correspondences than ransac_min_correspondences(model), or
// when no minimal sample gives a model, nothing can be verified and every correspondence is
// returned as an inlier (all true; an empty input gives an empty result). Throws
// std::invalid_argument when the two lists differ in size or threshold_rad/max_iterations are not
// positive.
std::vector<bool> ransac_inliers(const std::vector<Eigen::Vector3d>& bearings_prev,
                                 const std::vector<Eigen::Vector3d>& bearings_cur,
                                 RansacModel model, const Eigen::Matrix3d* R_cur_prev,
                                 double threshold_rad, int max_iterations, uint64_t seed);

// How FeatureTracker aligns a track to its template (FeatureTrackerOptions::klt_warp).
// Translation-only KLT against a patch that has turned in the image is off by the turn angle times
// the offset of the window's gradient centroid from the feature (about 4.6 px per radian with a
// 27 px window on photographic textures), and against a patch that has grown by the scale change
// times that offset; over a track's templates these add into a drift.
enum class KltWarp {
  kNone,          // OpenCV's pyramidal KLT against the template, translation only
  kRotation,      // KLT from the previous frame, then aligned (translation) to the template warped by
                  // the IMU rotation: the local affine map of K R_cur_ref K^-1 at the feature
  kRotationScale  // as kRotation, and a scale change about the feature estimated with the translation
                  // (translation along the optical axis, not in the IMU's rotation)
};
// "none", "rotation", "rotation_scale".
const char* klt_warp_name(KltWarp warp);

struct FeatureTrackerOptions {
  // Bucketing grid over the image (cells). Detection never fills a cell beyond max_per_cell
  // features (tracks already in the cell count).
  int grid_cols = 6;
  int grid_rows = 4;
  int max_features = 150;  // total features after detection (count)
  int max_per_cell = 8;    // features per grid cell after detection (count)
  // FAST-9 threshold: intensity difference (8-bit grey levels, 0..255) between the centre and the
  // contiguous arc of the Bresenham circle, on the 8-bit event frame (e.g. scaled event counts).
  int fast_threshold = 20;
  int min_distance_px = 8;  // minimum distance of a new feature to any other feature (px)
  int klt_window_px = 21;     // KLT search window side (px, odd)
  int klt_pyramid_levels = 3; // pyramid levels above full resolution (OpenCV maxLevel; 0 = none)
  int klt_max_iterations = 30;  // per pyramid level (count); also stops at klt_epsilon_px updates
  double klt_epsilon_px = 0.01;  // KLT stops when an update moves the feature less than this (px)
  // Forward-backward check: a track is dropped when tracking the new position back into the
  // previous frame lands farther than this from where it started (px).
  double forward_backward_max_px = 1.0;
  // Reference template (frames). 1 tracks every feature from the previous frame (chained
  // KLT: each frame's alignment error adds to the track, a random walk). N > 1 aligns each feature
  // against the frame where its reference was taken (the patch of its detection frame, refreshed
  // every N frames), with the previous position as the initial guess: errors add once per N frames
  // instead of once per frame. The forward-backward check runs against the reference frame.
  int template_max_age_frames = 1;
  // With template_max_age_frames > 1: a track that fails against its reference (KLT status, image
  // border or forward-backward check) is tracked from the previous frame instead (chained), and
  // its reference restarts at the current frame. Without it such a track is lost: templates of
  // event frames age quickly (edges change with the motion direction), and tracks live shorter.
  bool template_fallback = false;
  // With template_max_age_frames > 1: a template whose frame is turned by more than this against
  // the current one (deg, from the chained IMU rotation priors; 0 = no limit) is not used:
  // the track goes from the previous frame and its template restarts. Translation-only KLT
  // against a turned template is biased (an in-plane turn of ten degrees or more shifts it by
  // more than a pixel, and the forward-backward check still passes). A frame without the IMU
  // rotation restarts every template. With klt_warp the turn is taken out of the alignment and
  // this limit only bounds how far a template may have turned before it is renewed.
  double template_max_rotation_deg = 0;
  // Warped template alignment (see KltWarp): each track's KLT result from the previous frame is
  // refined against its template (or, chained, the previous frame's patch) warped by the camera
  // rotation since that patch's frame. A refinement that moves the KLT result by more than
  // forward_backward_max_px, leaves the image, or meets a flat patch fails: the track falls back to
  // the previous frame's patch (template_fallback) or is lost. Tracks whose rotation is unknown (a
  // frame without the IMU rotation) keep the plain KLT result.
  KltWarp klt_warp = KltWarp::kNone;
  // Long-baseline verification (frames; 0 = off): besides the RANSAC between consecutive
  // frames, the tracks that existed at an anchor frame are verified by a second 2-point RANSAC
  // between their anchor positions and the current ones (rotation from the chained IMU priors);
  // the anchor moves to the current frame every anchor_frames frames. A track sliding slowly
  // (along an edge, or drifting) passes every frame-to-frame test but not one over more parallax.
  // Needs the IMU rotation in every track() call (the anchor restarts where one is missing).
  int anchor_frames = 0;
  double anchor_ransac_threshold_px = 1.0;  // inlier threshold of that RANSAC (px, as ransac_threshold_px)
  // Geometric verification. kTwoPoint needs the IMU rotation: when track() gets no R_cur_prev it
  // falls back to kFivePoint.
  RansacModel ransac = RansacModel::kTwoPoint;
  // Inlier threshold (px on the ideal pinhole), converted to the angle atan(px / f) with
  // f = sqrt(fx fy), passed to OpenGV as 1 - cos(angle).
  double ransac_threshold_px = 1.0;
  int ransac_max_iterations = 200;  // count
  // New features are detected when fewer tracks than this survive a frame (count, at most max_features;
  // the first frame always detects).
  int min_tracks_before_detection = 100;
  // Features closer than this to the image border are not detected, and tracks that move closer
  // are dropped as KLT losses (px).
  int border_px = 4;
  uint64_t seed = 1;  // RANSAC seed (each frame's RANSAC seed is derived from it and the frame id)
  // Re-acquisition: a lost track's template (its reference patch) is kept this long (s; 0:
  // off); track() looks for it again where its caller predicts it (e.g. its landmark projected with
  // the IMU-propagated pose after an event-rate drop), and on success the track continues under
  // its id. The KLT result must pass the forward-backward check and lie within reacquire_max_px
  // of the prediction (px), and the template must not have turned by more than
  // 2 x template_max_rotation_deg (when that is set).
  double reacquire_max_age_s = 3.0;
  double reacquire_max_px = 6.0;

  bool Validate(std::string* why) const;
};

// Lucas-Kanade alignment of a patch whose warp into the current image is known up to its
// translation (and optionally a similarity about the feature): the window (window_px x window_px,
// odd) of `ref` around ref_px, mapped into `cur` by
//   x_cur = cur_px + exp(log_scale) R(turn_rad) A_cur_ref (x_ref - ref_px),
// is aligned by inverse-compositional Gauss-Newton steps (Baker and Matthews 2004; Scharr
// derivatives of the warped template, bilinear interpolation) on cur_px (in: the initial position;
// out: the aligned one), and on log_scale and turn_rad when those are given (out: the estimates,
// starting from 0; nullptr: fixed at 0), until a step moves the window by less than epsilon_px or
// after max_iterations. Template pixels that fall outside `ref` are left out (at least half the
// window must remain). Images 8-bit single-channel. Returns false (outputs unchanged) when
// A_cur_ref is singular, the window would leave `cur`, the patch has no texture in some direction
// (smallest eigenvalue of its mean gradient matrix below 1 grey level^2/px^2), or the alignment
// moves cur_px by 2 px or more per axis, the turn by 0.1 rad or the log-scale by 0.1 or more.
bool align_warped_patch(const cv::Mat& ref, const cv::Point2f& ref_px, const Eigen::Matrix2d& A_cur_ref,
                        const cv::Mat& cur, int window_px, int max_iterations, double epsilon_px, cv::Point2f* cur_px,
                        double* turn_rad = nullptr, double* log_scale = nullptr);

// The local affine map at pixel ref_px of the infinite homography K R_cur_ref K^-1 (pure rotation,
// points at infinity) of an ideal pinhole: d x_cur / d x_ref (2x2). Identity when ref_px maps
// behind the current camera.
Eigen::Matrix2d rotation_homography_jacobian(const calib::CameraIntrinsics& K, const Eigen::Matrix3d& R_cur_ref,
                                             const cv::Point2f& ref_px);

struct FeatureTrackerStats {
  int64_t frames = 0;           // frames processed
  int64_t detected = 0;         // new tracks started
  int64_t tracked = 0;          // track continuations that survived every check (sum over frames)
  int64_t lost_klt = 0;         // KLT failure or left the image (minus border)
  int64_t lost_fb = 0;          // forward-backward check failed
  int64_t rejected_ransac = 0;  // RANSAC outliers
  int64_t rejected_anchor = 0;     // long-baseline RANSAC outliers (anchor_frames)
  int64_t template_fallbacks = 0;
  int64_t template_rotation_refreshes = 0;  // templates dropped for template_max_rotation_deg
  int64_t reacquired = 0;       // lost tracks found again at their predicted position (reacquire_*)
  int64_t lost_warp = 0;        // klt_warp refinements that failed without a fallback (see that option)
};

// A lost track's predicted position in the frame given to FeatureTracker::track (px, ideal pinhole).
struct TrackPrediction {
  int64_t track_id = 0;
  Eigen::Vector2d px = Eigen::Vector2d::Zero();
};

class FeatureTracker {
 public:
  // ideal_pinhole: the IDEAL pinhole of the frames (fx, fy, cx, cy; frames are undistorted, the
  // distortion fields must be kNone), width x height. Throws std::invalid_argument when the
  // intrinsics or the options are invalid.
  FeatureTracker(const calib::CameraIntrinsics& ideal_pinhole, const FeatureTrackerOptions& options);

  // Tracks into a new 8-bit single-channel frame of the camera's size (throws
  // std::invalid_argument otherwise). R_cur_prev (optional): rotation of the previous camera frame
  // into the current one from the IMU (p_cur = R_cur_prev p_prev for points at infinity); used to
  // predict KLT positions and by the 2-point RANSAC. Returns the observations of this frame (every
  // surviving track, in track order, then every new one; bearing = normalised K^-1 [u v 1]).
  // frame_id counts the frames given to track() from 0.
  // predictions (optional): where lost tracks (lost_track_ids) should be in this frame; each one
  // whose template is still kept is looked for there (reacquire_*).
  FeatureObservations track(int64_t t_ns, const cv::Mat& frame,
                            const Eigen::Matrix3d* R_cur_prev = nullptr,
                            const std::vector<TrackPrediction>* predictions = nullptr);
  // Ids of the lost tracks whose templates are kept for re-acquisition (sorted).
  std::vector<int64_t> lost_track_ids() const;

  // Pixels that carry image content (CV_8UC1 of the camera's size, non-zero = valid; empty: all):
  // no feature is detected, and no track continues, where its KLT window would reach an invalid
  // pixel (e.g. the border of an undistorted frame that repeats the nearest sensor pixel, a
  // texture that does not move with the scene). Throws std::invalid_argument for another size or type.
  void set_valid_mask(const cv::Mat& mask);

  // Current tracks' pixel positions (for drawing overlays), in the order of the last observations.
  std::vector<std::pair<int64_t, cv::Point2f>> current() const;
  const FeatureTrackerStats& stats() const { return stats_; }
  const FeatureTrackerOptions& options() const { return options_; }

  // Unit bearing of a pixel of the ideal pinhole: normalised K^-1 [u v 1].
  Eigen::Vector3d bearing(const cv::Point2f& px) const;

 private:
  struct Track {
    int64_t id;
    cv::Point2f px;      // position in the last frame
    int64_t ref_frame;   // frame id of the reference template
    cv::Point2f ref_px;  // position in the reference frame
    bool anchored = false;  // existed at the anchor frame (anchor_frames)
    cv::Point2f anchor_px;  // position there
  };
  int cell_of(const cv::Point2f& px) const;
  bool inside(const cv::Point2f& px) const;
  void detect(const cv::Mat& frame);
  // Long-baseline RANSAC of the anchored tracks (anchor_frames); drops its outliers.
  void verify_against_anchor(std::vector<Track>* tracks, const Eigen::Matrix3d* R_cur_prev);

  calib::CameraIntrinsics K_;
  FeatureTrackerOptions options_;
  FeatureTrackerStats stats_;
  std::vector<Track> tracks_;
  cv::Mat valid_;  // eroded valid-pixel mask (set_valid_mask); empty: every pixel
  std::vector<cv::Mat> prev_pyramid_;
  // The frames still referenced by a track's template: pyramid, and the rotation from there to
  // the current frame (chained IMU priors; unknown once a frame came without one).
  struct RefFrame {
    int64_t frame;
    std::vector<cv::Mat> pyramid;
    Eigen::Matrix3d R_cur_ref;
    bool rotation_known;
  };
  std::vector<RefFrame> ref_frames_;
  // Lost tracks kept for re-acquisition: their reference template and when they were lost.
  struct LostTrack {
    int64_t ref_frame;
    cv::Point2f ref_px;
    int64_t lost_t_ns;
  };
  std::map<int64_t, LostTrack> lost_;  // by track id
  // Finds lost tracks again at their predictions (appends to tracks_); `pyramid`: this frame's.
  void reacquire(int64_t t_ns, const std::vector<cv::Mat>& pyramid, int levels, const std::vector<TrackPrediction>& predictions);
  int64_t next_id_ = 0;
  int64_t frame_id_ = 0;
  int64_t anchor_frame_ = -1;                                   // -1: no anchor
  Eigen::Matrix3d R_cur_anchor_ = Eigen::Matrix3d::Identity();  // anchor camera -> current camera
};

}  // namespace evio::frontend
