// Keyframe-based visual-inertial sliding-window estimator (Leutenegger et al., OKVIS, IJRR 2015;
// as used for event cameras by Rebecq et al., BMVC 2017 and Vidal et al., Ultimate SLAM, 2018):
// reprojection errors of world landmarks in keyframes plus IMU preintegration errors between
// consecutive keyframe states, over a window of K keyframes solved with Ceres; the oldest
// keyframe is marginalised into a linear prior.
//
// Marginalisation (when the window exceeds K): the oldest keyframe's pose and speed/bias are
// eliminated together with the landmarks it observes that are no longer tracked (not seen in the
// newest keyframe), by the Schur complement of every residual touching them (the IMU error to the
// next keyframe, the previous prior, all reprojection errors of those landmarks). The prior
// spans keyframe states only (its size stays bounded by the window, and no residual couples two
// landmarks, which Ceres' Schur elimination needs). Tracks of marginalised landmarks are closed:
// later observations of them are ignored. The oldest keyframe's observations of triangulated
// landmarks that are still tracked go by tracked_landmark_marginalisation:
//   kDrop: dropped; the landmark keeps its other observations, and is forgotten (re-triangulated
//     later) when fewer than two remain. The prior loses what they said about the poses.
//   kDoubleCount (VINS-Mono): the landmark is marginalised with all its window observations like a
//     finished one, then continues from its position with its observations in the other window
//     keyframes, which the prior and the window then both count.
//   kRestart: the landmark is marginalised with all its window observations and its track
//     restarts: a new landmark from the observations of later keyframes only (nothing counted
//     twice; the landmark's position is not carried over, only what it said about the poses).
//   kSplit: the landmark is marginalised with the older half of its window observations (rounded
//     up; all of them when that is one) and continues from its position with the newer half, so
//     nothing is counted twice and the newest keyframes stay out of the prior's linearisation.
// Untriangulated tracks lose the oldest keyframe's observation in every mode.
//
// Gauge: the first keyframe gets an anchor prior from the initial state (yaw and position tight,
// roll/pitch, velocity and biases from their sigmas); later the marginalisation prior carries it.
// Rotation-only model: each new keyframe is tested against the previous one by Torr's GRIC
// (motion_model_selection.h) on the bearings they share: S (no motion), R (pure rotation,
// homography at infinity, d = 2, k = 3) and G (general motion, essential matrix, d = 3, k = 5),
// with the IMU as one more datum: S and R say the camera centre's velocity does not change over the
// interval (chi2 under the preintegration covariance plus model_selection_accel_sigma_mps2) and,
// once landmarks make the velocity observable, that it does not move (chi2 of the predicted
// displacement under model_selection_velocity_sigma_mps).
// Hysteresis: the model switches on when R has the lowest GRIC, by rotation_only_gric_margin or
// more, for rotation_only_min_keyframes consecutive keyframes, and off as soon as G has the lowest
// GRIC (S, no motion, keeps the current model: zero rotation is a rotation). Static phases select S,
// so a static start stays 6-DoF. A keyframe is rotation-only only where the pixel conditions
// (rotation_only_parallax_px, rotation_only_translation_px) hold as well: GRIC alone took a slow
// sideways motion in front of one plane for a rotation. In a rotation-only keyframe, the untriangulated tracks shared with
// the previous keyframe constrain the relative orientation directly (landmarks at infinity,
// RotationOnlyError), so orientation and gyro bias stay estimated; no landmark is triangulated
// from it. The decision and the statistics per keyframe are in stats().motion_model_tests.
// Bias prior of the first keyframe: sigma = sqrt(turn_on^2 + random_walk^2 * horizon) per axis,
// with the turn-on sigmas as options and the random walks from the IMU noise model (see the
// options for why the turn-on term stays: the random walk alone is far below real turn-on biases).
// Keyframes: a frame becomes a keyframe when the median rotation-compensated displacement of the
// tracks it shares with the last keyframe reaches `keyframe_min_parallax_px`, when fewer than
// `keyframe_min_tracked_ratio` of the last keyframe's tracks remain, or after
// `keyframe_max_interval_s`. Landmarks are triangulated (linear multi-view, all observing
// keyframes) once seen from two keyframes with at least `min_triangulation_angle_deg` between rays.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <deque>
#include <iterator>
#include <map>
#include <memory>
#include <optional>
#include <utility>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "evio/backend/initialization.h"
#include "evio/backend/motion_model_selection.h"
#include "evio/calib/calibration_io.h"
#include "evio/sensors/measurements.h"
#include "evio/sensors/vio_types.h"

namespace evio::backend {

class ImuPreintegration;
class ImuError;
class LinearPrior;
class ReprojectionError;

enum class RobustLoss { kNone, kHuber, kCauchy };

// What marginalising the oldest keyframe does with its observations of landmarks still tracked
// in the newest keyframe (see the header comment).
enum class TrackedLandmarkMarginalisation { kDrop, kDoubleCount, kRestart, kSplit };

struct SlidingWindowOptions {
  int window_size = 10;                    // keyframes K in the window, >= 2
  int max_iterations = 10;                 // Ceres iterations per keyframe, >= 1
  double function_tolerance = 1e-6;        // Ceres stops when the cost changes by less than this fraction, in (0, 1)
  double max_solver_time_s = 0.0;          // wall time limit per solve, s (0: none)
  RobustLoss loss = RobustLoss::kHuber;    // on reprojection errors
  double loss_scale = 1.345;               // in units of pixel sigma (whitened residual)
  double pixel_sigma = 0.5;                // observation noise on the undistorted image, px, > 0
  double keyframe_min_parallax_px = 6.0;   // median rotation-compensated displacement, px
  double keyframe_min_tracked_ratio = 0.6; // share of the last keyframe's tracks still seen
  double keyframe_max_interval_s = 0.2;    // s
  // Frames with fewer observations than keyframe_min_tracks (count, >= 0) become keyframes only
  // every keyframe_max_interval_without_tracks_s (s, > 0): through an event-rate drop the window
  // keeps the keyframes before it, whose landmarks the re-acquired tracks observe again.
  int keyframe_min_tracks = 5;
  double keyframe_max_interval_without_tracks_s = 1.0;
  double min_triangulation_angle_deg = 1.0;  // between the most separated rays, deg
  // After a solve, larger errors are outliers, px, for observations of sigma pixel_sigma; the
  // threshold scales with an observation's own sigma (a fixed number of sigmas: events next to APS
  // observations at 1.5 px are dropped beyond 6 px). A fixed 2 px for every sigma was measured
  // worse with events+aps (mean over six scenes and three seeds 0.223% against 0.193%).
  double max_reprojection_px = 2.0;
  double min_depth_m = 0.05;               // landmarks closer to any observing camera are rejected, m
  // The oldest keyframe's observations of still-tracked (triangulated) landmarks at
  // marginalisation (header comment): dropped (kDrop), or marginalised with the landmark and all
  // its window observations, the landmark then continuing with them (kDoubleCount, VINS-Mono) or
  // restarting from later keyframes (kRestart), or with the older half only (kSplit, default).
  // Mean position error over the six simulated scenes x 6 RANSAC seeds (datasets/vio/simulator.yaml),
  // events / events+aps: drop 0.548 / 0.195%, restart 0.473 / 0.173%, split 0.505 / 0.139%
  // (double_count, 3 seeds: 0.508 / 0.214% against drop 0.548 / 0.191%). Split is the default: it
  // counts nothing twice, improves both means, and its worst scenes are within 6% of drop with
  // events (mocap 0.700 -> 0.743%) and 0.055 -> 0.073% with events+aps (restart: room 0.175 ->
  // 0.292%, mocap 0.055 -> 0.090% with events+aps).
  TrackedLandmarkMarginalisation tracked_landmark_marginalisation = TrackedLandmarkMarginalisation::kSplit;
  // Rotation-only model, chosen per keyframe by GRIC with hysteresis (see the header comment).
  bool rotation_only_model = true;         // false: every keyframe uses the 6-DoF model
  // In a rotation-only keyframe the camera centre also stays where it was at the previous keyframe
  // (StaticCentreError, sigma model_selection_velocity_sigma_mps x the interval, at least 1 mm):
  // what the model says, so that the IMU alone does not carry the position away in a hover or a
  // pan where no landmark can be triangulated.
  bool rotation_only_static_centre = true;
  // The centre of a rotation in place may be the camera's optical centre (a tripod turning the
  // camera) or the IMU's origin (a rig turning about its IMU, the camera on a lever arm): the IMU
  // test of the model takes the candidate the IMU agrees with better, and the static centre holds
  // that point. false: the camera centre only. Over a distant scene a lever arm of a few cm is not
  // seen in the image, but the IMU sees its centripetal acceleration and vetoed the model.
  bool rotation_only_imu_centre = true;
  // GRIC_R must be below GRIC_S and GRIC_G by at least this much (GRIC units: -2 log likelihood,
  // i.e. chi2 units of the whitened residuals), >= 0. 10 is e^5 ~ 150 times more likely.
  double rotation_only_gric_margin = 10.0;
  // ... on this many consecutive keyframes before the model switches on (keyframes, >= 1). Three
  // keyframes span 0.2-0.6 s: the onset of a translation (acceleration from rest, banking) looks
  // rotational for a keyframe or two before its parallax shows.
  int rotation_only_min_keyframes = 3;
  // ... and from the first of those keyframes to the current one at least this long (s, >= 0).
  // Keyframes made by track losses can come every 10 ms: three of them are no evidence of a
  // rotation in place (boxes_6dof at 0.1 m/s and 25 deg/s: R won 9 keyframes within 0.17 s with
  // template-tracked features; a hover-to-flight onset: 4 keyframes in 0.2 s).
  double rotation_only_min_duration_s = 0.25;
  int model_selection_min_tracks = 10;     // fewer shared tracks: no test, the 6-DoF model (tracks, >= 6)
  // The test's reference view is at least this much older than the new keyframe (the newest
  // window keyframe that is and still shares model_selection_min_tracks tracks; else the previous
  // one): keyframes made by track losses can be 10 ms apart (boxes_6dof), too little baseline for
  // a translation to show (s, >= 0).
  double model_selection_min_interval_s = 0.05;
  // true: the test's reference view is the oldest window keyframe (at least
  // model_selection_min_interval_s old) that still shares model_selection_min_tracks tracks: the
  // longest baseline the window offers, so a slow translation far from the scene shows its parallax;
  // false: the newest such keyframe.
  bool model_selection_longest_baseline = false;
  // IMU veto: R cannot win when the IMU datum rejects a static camera centre at this significance
  // (its chi2 above the chi-square upper quantile for its degrees of freedom: 16.27 for the
  // velocity change alone, 3 dof; 22.46 with the displacement, 6 dof). On boxes_6dof at 0.1-0.15
  // m/s the image test chose R with the IMU at chi2 35-48 (3 dof), and at 32 (6 dof) where the
  // former threshold of 5.42 per dof (p = 0.001 for 3 dof but 1e-5 for 6) let it through.
  // 0 disables the veto; else in (0, 1).
  double model_selection_imu_veto_p = 0.001;
  // IMU datum of the test: 1-sigma of the camera centre's mean acceleration over the interval that
  // the accelerometer noise density does not explain (accelerometer bias and gravity-direction
  // errors of the estimate, lever-arm errors), m/s^2, >= 0; 0: the IMU is not used in the test.
  double model_selection_accel_sigma_mps2 = 0.2;
  // Second IMU datum, used when the window holds at least model_selection_min_tracks triangulated
  // landmarks (the velocity is then observable): the camera centre's predicted displacement since
  // the previous keyframe, zero under S and R, with this 1-sigma of the previous keyframe's velocity
  // estimate, m/s, >= 0 (0: not used). Slow translation in front of a plane (poster_6dof mocap
  // replay, 0.1-0.2 m/s, 1-2 m) looks rotational to the image test (a fronto-parallel plane's
  // homography); this datum only helps once landmarks are triangulated.
  double model_selection_velocity_sigma_mps = 0.02;
  // Growth of that sigma while no landmarks constrain the velocity (after the initialisation, or
  // when a fast turn leaves none in the window): the IMU alone carries the velocity, with the
  // accelerometer-bias and tilt errors of the estimate (m/s^2, >= 0). The datum is then used with
  // sigma = hypot(sigma at the last landmark-rich keyframe or at the initialisation, this * time since);
  // the same acceleration error enters the predicted displacement as this * dt^2 / 2.
  double model_selection_velocity_drift_mps2 = 0.05;
  // Pixel conditions of the former test, kept as necessary conditions next to the GRIC test (both
  // must agree, see choose_rotation_only): the median rotation-compensated displacement from the
  // previous keyframe below rotation_only_parallax_px (0 disables the model), and the
  // IMU-predicted translation at the median landmark depth below rotation_only_translation_px
  // (without triangulated landmarks the displacement alone), px, >= 0.
  double rotation_only_parallax_px = 1.5;
  double rotation_only_translation_px = 0.3;
  Eigen::Vector3d gravity_w = Eigen::Vector3d(0, 0, -9.81);  // m/s^2
  bool compute_covariance = false;         // covariance of the newest keyframe's pose after each solve
  // Online camera-IMU time offset (TimeOffsetReprojectionError): a correction td (s) to the
  // calibrated shift, estimated with the keyframe states from each observation's image velocity
  // (its track's previous frame), with a zero-mean prior of time_offset_sigma_s (s, > 0) on the
  // first keyframe that marginalisation carries on. Rotation-only links do not use it.
  bool estimate_time_offset = false;
  double time_offset_sigma_s = 0.01;
  // Anchor prior on the first keyframe (1 sigma).
  double init_sigma_roll_pitch_rad = 0.02;
  double init_sigma_yaw_rad = 1e-4;
  double init_sigma_position_m = 1e-4;
  double init_sigma_velocity_mps = 0.1;
  // Biases: sigma = sqrt(turn_on^2 + random_walk^2 * init_bias_horizon_s) with the random walks of
  // the IMU noise model: the initial biases are a turn-on estimate (datasheet, calibration or a
  // static initialiser) that the bias random walk has had up to the horizon to leave. The random
  // walk alone is no prior for real IMUs: an MPU-6150 class IMU (2e-5 rad/s^2/sqrt(Hz)) gives
  // 1.5e-4 rad/s over 60 s while its turn-on gyro bias is easily 0.01 rad/s, hence the turn-on terms
  // (the former fixed sigmas) stay the main part; noisier IMUs get a wider prior. Where the bias
  // is known better (a calibrated IMU, a simulator that starts at zero bias), a smaller turn-on
  // sigma keeps the visual tracks from pulling it: their slowly varying common-mode error looks
  // like a gyro bias. A still start measures the bias, and initialize() then takes its sigma.
  // Default 5e-4 rad/s (0.03 deg/s): an IMU whose noise model comes with the calibration (a
  // Kalibr imu0 section) and a bias that has been calibrated or that a still start measures. With
  // 0.01 rad/s the event tracks' slowly varying common-mode error went into the gyro bias (0.2-2
  // deg/s off on the crosscheck sequences; docs/results/vio.md). Give an uncalibrated MEMS gyro
  // its datasheet turn-on bias (0.01 rad/s in datasets/vio/davis240c.yaml and davis346.yaml).
  double init_bias_gyro_turn_on_radps = 5e-4;   // rad/s, > 0
  double init_bias_accel_turn_on_mps2 = 0.1;    // m/s^2, > 0
  double init_bias_horizon_s = 60.0;            // s, >= 0
  // Rotation-tracker factors (add_tracked_rotation): a keyframe whose bearings alone do not call
  // for a translation (the model test's image_best is S, R or none: rotation-dominant motion, even
  // where the IMU datum rejects a static centre and the rotation-only model stays off) and whose
  // time two samples of one tracker segment at most tracker_max_gap_s apart bracket gets the tracker's
  // orientation (slerped; covariance interpolated). The segment's first such keyframe is its
  // anchor; every later one gets a RelativeRotationError to the anchor, whose covariance is the two
  // orientations' (the tracker's particle spread) plus tracker_min_sigma_deg^2 per axis (the
  // spread leaves out the panorama's own error: parallax, the map's registration). A segment whose
  // orientations begin before the window's oldest keyframe (a tracker that ran before its
  // orientations were given) is anchored instead at the earliest marginalised keyframe they
  // bracket (among the last 4096), as that keyframe's last estimate. The anchor keeps its last estimate as a constant once
  // it is marginalised, so a revisit of the panorama pulls the newest keyframes back to it without
  // moving any state by a jump (a Huber loss of scale tracker_loss_scale sigmas: the pull of a
  // large correction stays, bounded). Jump test: the tracker's rotation since the segment's
  // previous keyframe against the estimate's between the two (the gyro's, at this scale) under both
  // orientations' covariances, twice the floor and the gyro's white noise over the interval; a chi2
  // (3 dof) beyond the upper quantile of probability tracker_reject_p is a registration jump: the
  // keyframe gets no factor and anchors the segment anew (the panorama's frame has moved for the
  // tracker). The factors are not marginalised.
  double tracker_max_gap_s = 0.05;        // s, > 0
  double tracker_min_sigma_deg = 0.3;     // deg, > 0
  double tracker_loss_scale = 2.0;        // sigmas, > 0
  double tracker_reject_p = 0.001;        // probability in (0, 1)
  // A keyframe that gets a tracker factor and is not rotation-only also gets a StaticCentreError
  // to the previous keyframe: its camera centre moves by at most what its bearings cannot show,
  // sigma = tracker_centre_px * (median landmark depth) / focal (m; none before any depth is
  // known). Without it nothing but the IMU carries the position through a rotation-dominant span
  // (too little baseline to triangulate), and a consumer gyro's bias takes it away. px, >= 0 (0: off).
  double tracker_centre_px = 1.0;
  bool Validate(std::string* why) const;
};

struct SlidingWindowStats {
  int64_t frames = 0;
  int64_t keyframes = 0;
  int64_t landmarks_triangulated = 0;
  int64_t outliers_removed = 0;
  int64_t landmarks_marginalised = 0;       // landmarks of finished tracks marginalised
  int64_t observations_dropped = 0;       // oldest keyframe's observations not marginalised (tracks still open)
  int64_t tracked_landmarks_marginalised = 0;  // still-tracked landmarks marginalised (kDoubleCount, kRestart)
  int64_t rotation_only_keyframes = 0;  // keyframes that used the rotation-only model
  std::vector<std::pair<int64_t, bool>> motion_model;  // per keyframe: (t_ns, rotation-only)
  // Per keyframe after the first: the model-selection test and the decision.
  struct MotionModelTest {
    int64_t t_ns = 0;
    int tracks = 0;                 // shared tracks with the reference keyframe (n of the GRIC)
    double baseline_s = 0;          // time from the reference keyframe (s)
    double gric_static = 0, gric_rotation = 0, gric_general = 0;  // GRIC units (-2 log likelihood)
    double imu_chi2 = 0;            // chi2 of "the centre does not accelerate (3 dof) / move (3 more)" (centre_imu)
    int imu_dof = 0;                // its degrees of freedom (0: the IMU datum was not used)
    int landmarks = 0;              // triangulated landmarks in the window at the test
    TwoViewModel best = TwoViewModel::kNone;  // lowest GRIC (kNone: too few tracks, not tested); kGeneral when vetoed
    bool imu_veto = false;          // R had the lowest GRIC but the IMU rejected a static centre
    bool centre_imu = false;        // the IMU's origin, not the camera centre, was the likelier static centre
    int run = 0;                    // consecutive keyframes R has won by the margin
    bool rotation_only = false;     // the decision after hysteresis
    TwoViewModel image_best = TwoViewModel::kNone;  // lowest GRIC of the bearings alone (no IMU terms)
    // The body's predicted speed over the median landmark depth (deg/s: the translational part of
    // the image motion); -1 before any depth is known.
    double translation_flow_deg_s = -1;
  };
  std::vector<MotionModelTest> motion_model_tests;
  std::vector<double> solve_time_s;   // per keyframe (solve + marginalisation)
  // Per solve: how well the window's measurements agree with the estimate.
  struct Health {
    int64_t t_ns = 0;                 // the newest keyframe
    double visual_chi2_per_dof = 0;   // reprojection errors (whitened by their sigma), per residual dimension
    double imu_chi2_per_dof = 0;      // IMU preintegration errors (whitened), per residual dimension
    int observations = 0;             // reprojection errors in the solve
    int landmarks = 0;                // landmarks in the solve
    double gyro_bias_sigmas = 0;      // |b_g - initial b_g| over the first keyframe's prior sigma (largest axis)
  };
  std::vector<Health> health;
  double time_offset_s = 0;           // estimate_time_offset: td after the last solve (s)
  std::vector<int> solve_landmarks;   // landmarks in each solve
  // Rotation-tracker factors (add_tracked_rotation), one per keyframe that got one, time order.
  struct TrackerFactor {
    int64_t t_ns = 0;          // the keyframe
    int64_t anchor_t_ns = 0;   // its segment's anchor keyframe
    int64_t segment = 0;       // the tracker's segment (panorama), as add_tracked_rotation numbered it
    double sigma_deg = 0;      // the factor's largest axis sigma, deg
    double error_deg = 0;      // |Log(measured^T estimated)| after the last solve that held it, deg (dropped: the jump)
    double chi2 = 0;           // its whitened squared residual then (3 dof, without the loss)
    bool dropped = false;      // failed the jump test: no factor, the keyframe anchors the segment anew
    Eigen::Quaterniond measured = Eigen::Quaterniond::Identity();  // the camera's rotation R_ca_ck from the anchor
  };
  std::vector<TrackerFactor> tracker_factors;
  int64_t tracker_samples = 0;   // orientations given to add_tracked_rotation
  int64_t tracker_anchors = 0;   // keyframes that anchored a segment
};

class SlidingWindowEstimator {
 public:
  // camera: T_c_b and the focal length (fx, for pixel units); noise: Kalibr densities.
  // Throws std::invalid_argument on invalid options or noise.
  SlidingWindowEstimator(const SlidingWindowOptions& options, const calib::CameraCalibration& camera,
                         const calib::ImuNoise& noise);
  ~SlidingWindowEstimator();

  // Initial state (from an initialiser or a known start). Frames before its time are ignored.
  // sigmas: what the initialiser measured (e.g. static_initialization's standard errors); each
  // one > 0 replaces, in the first keyframe's prior, the gyro bias turn-on sigma or
  // init_sigma_velocity_mps of the options. Throws std::invalid_argument on non-finite sigmas.
  void initialize(const VioState& state, const InitialSigmas& sigmas = {});
  bool initialized() const { return initial_.has_value(); }

  // IMU samples in time order (body clock).
  void add_imu(const ImuSample& sample);
  // A rotation tracker's orientation of the camera (see the tracker_* options): q_m_c in the
  // frame m of the tracker's panorama, cov_c its covariance on the right (camera tangent, rad^2),
  // segment the panorama's id (orientations of different segments are unrelated). In time order
  // (body clock; a sample not after the previous one is ignored). Throws std::invalid_argument on
  // non-finite values.
  struct TrackedRotation {
    int64_t t_ns = 0;
    Eigen::Quaterniond q_m_c = Eigen::Quaterniond::Identity();
    Eigen::Matrix3d cov_c = Eigen::Matrix3d::Zero();
    int64_t segment = 0;
  };
  void add_tracked_rotation(const TrackedRotation& r);
  // A frame's observations (camera clock = body clock - T_c_b time shift already removed by the
  // caller); each observation's sigma_px (0: options.pixel_sigma) weighs its reprojection error.
  // Needs IMU samples up to its time. Returns true when it became a keyframe (and the window was
  // solved).
  bool add_frame(const FeatureObservations& frame);

  // Latest estimate: the newest keyframe, or the last frame propagated from it with the IMU.
  VioState latest_state() const { return latest_; }
  // The last frame add_frame accepted after the first keyframe: the state predicted for it from
  // the newest keyframe with the IMU (before any solve), and that keyframe's state at the time
  // (for trajectory re-propagation, backend/trajectory_smoothing.h). nullopt before.
  const std::optional<std::pair<VioState, VioState>>& last_prediction() const { return last_prediction_; }
  std::vector<VioState> keyframe_states() const;
  // Covariance of the newest keyframe's pose in its tangent space [dtheta (rad, body frame), dp
  // (m, world)], when compute_covariance is set and the last solve's covariance was computable.
  const std::optional<Eigen::Matrix<double, 6, 6>>& latest_pose_covariance() const { return latest_cov_; }
  // Triangulated landmarks in the window (world frame), by track id.
  std::unordered_map<int64_t, Eigen::Vector3d> landmarks() const;
  const SlidingWindowStats& stats() const { return stats_; }
  const SlidingWindowOptions& options() const { return options_; }
  // Estimated time-offset correction td (s; 0 unless options().estimate_time_offset): observations
  // stamped t show the scene at t + td.
  double time_offset_s() const { return time_offset_[0]; }
  // Information matrix (J^T J) of the current prior over the window's keyframe states, in window
  // order per keyframe [pose tangent (6: dtheta body, dp world), v_w, b_g, b_a (9)], then td (1)
  // when estimate_time_offset; zero where the prior does not reach. Empty before the first keyframe.
  Eigen::MatrixXd prior_information() const;

 private:
  struct Keyframe;
  struct Landmark;
  VioState state_of(const Keyframe& k) const;
  VioState propagate(const Keyframe& from, int64_t t_ns) const;
  // Median rotation-compensated displacement (px) of the tracks the frame shares with the last
  // keyframe; *common receives their number.
  double parallax_px(const FeatureObservations& frame, const VioState& predicted, size_t* common) const;
  // The GRIC test of the new keyframe (state `predicted`, observations `frame`) against `prev`,
  // with the preintegration `pre` from prev to it; updates the hysteresis and the stats.
  bool choose_rotation_only(const Keyframe& prev, const FeatureObservations& frame, const VioState& predicted,
                            const ImuPreintegration& pre);
  bool is_keyframe(const FeatureObservations& frame, const VioState& predicted) const;
  // The observation's noise: its sigma_px, or options_.pixel_sigma when it gives none.
  double sigma_of(const FeatureObservation& o) const;
  // The first keyframe's gyro-bias prior sigma per axis (rad/s): the initialiser's, else the options'.
  double gyro_bias_prior_sigma() const;
  void triangulate(int64_t track, Landmark* lm);
  void solve();
  void remove_outliers();
  void marginalize_oldest();
  // Rotation-tracker factors: window keyframes get the tracker's orientation where its samples
  // bracket them; after a solve, each factor's error and chi2 (and drop).
  void attach_tracked_rotations();
  void review_tracker_factors();

  SlidingWindowOptions options_;
  calib::CameraCalibration camera_;
  calib::ImuNoise noise_;
  double focal_px_;
  std::optional<VioState> initial_;
  InitialSigmas initial_sigmas_;  // <= 0: from the options
  std::vector<ImuSample> imu_;                  // pruned to the window
  std::deque<std::unique_ptr<Keyframe>> window_;
  std::unordered_map<int64_t, Landmark> landmarks_;
  std::unordered_set<int64_t> closed_tracks_;
  std::array<double, 1> time_offset_{};  // td (s), a parameter block when estimate_time_offset
  // Each track's last observation (frame time, undistorted normalised-plane point), for image
  // velocities (estimate_time_offset only; tracks not in the last frame are dropped).
  struct SeenTrack {
    int64_t t_ns = 0;
    Eigen::Vector2d m = Eigen::Vector2d::Zero();  // normalised-plane point
    Eigen::Vector2d v = Eigen::Vector2d::Zero();  // from the frame before (1/s)
    bool has_v = false;
  };
  std::unordered_map<int64_t, SeenTrack> last_seen_;
  std::unique_ptr<LinearPrior> prior_;
  VioState latest_;
  std::optional<std::pair<VioState, VioState>> last_prediction_;  // (anchor keyframe, predicted)
  std::optional<Eigen::Matrix<double, 6, 6>> latest_cov_;
  bool rotation_only_active_ = false;  // hysteresis state of the rotation-only model
  Eigen::Vector3d rotation_centre_b_ = Eigen::Vector3d::Zero();  // the latest test's static centre (body frame)
  double last_median_depth_m_ = 0;     // median camera depth of the triangulated landmarks at the last solve that had any (m)
  // The velocity is known (model selection's displacement datum) to velocity_anchor_sigma_mps_ at
  // velocity_anchor_t_ns_: the initialisation, or the last solve with enough triangulated landmarks.
  int64_t velocity_anchor_t_ns_ = 0;
  double velocity_anchor_sigma_mps_ = 0;
  int rotation_only_run_ = 0;          // consecutive keyframes R has won by the margin
  int64_t rotation_only_run_start_ns_ = 0;  // time of the first of them
  SlidingWindowStats stats_;
  std::deque<TrackedRotation> tracked_;  // tracker samples not yet older than the window
  // Per tracker segment: its anchor keyframe (while in the window) or its last estimate (after).
  struct TrackerAnchor {
    int64_t t_ns = 0;
    Eigen::Quaterniond q_m_c = Eigen::Quaterniond::Identity();
    Eigen::Matrix3d cov_c = Eigen::Matrix3d::Zero();
    std::array<double, 7> pose{};   // the marginalised anchor's last estimate (constant in solves)
    const Keyframe* kf = nullptr;   // in the window
    // The segment's latest keyframe with the tracker's orientation (in the window; for the jump test).
    const Keyframe* last = nullptr;
    Eigen::Quaterniond last_q = Eigen::Quaterniond::Identity();
    Eigen::Matrix3d last_cov = Eigen::Matrix3d::Zero();
  };
  std::map<int64_t, TrackerAnchor> tracker_anchors_;   // by anchor id
  // Marginalised keyframes' last estimates (time, pose), oldest first, at most kMaxPastKeyframes:
  // the anchors of tracker segments whose orientations begin before the window.
  static constexpr size_t kMaxPastKeyframes = 4096;
  std::deque<std::pair<int64_t, std::array<double, 7>>> past_keyframes_;
  std::map<int64_t, int64_t> tracker_segments_;         // the caller's segment -> its current anchor id
  int64_t next_tracker_anchor_ = 0;
};

// The tracker's orientation at t from time-ordered samples [begin, end) of
// SlidingWindowEstimator::TrackedRotation: the sample at t, or the two that bracket it slerped
// (orientation) and blended (covariance), both of one segment and at most max_gap_ns apart.
// False when there is none.
template <class It>
bool tracked_rotation_at(It begin, It end, int64_t t, int64_t max_gap_ns, SlidingWindowEstimator::TrackedRotation* out) {
  using R = SlidingWindowEstimator::TrackedRotation;
  const It after = std::lower_bound(begin, end, t, [](const R& r, int64_t u) { return r.t_ns < u; });
  if (after == end || (after == begin && after->t_ns != t)) return false;
  const R& s1 = *after;
  const R& s0 = after->t_ns == t ? *after : *std::prev(after);
  if (s0.segment != s1.segment || s1.t_ns - s0.t_ns > max_gap_ns) return false;
  const double a = s1.t_ns > s0.t_ns ? static_cast<double>(t - s0.t_ns) / static_cast<double>(s1.t_ns - s0.t_ns) : 0.0;
  out->t_ns = t;
  out->segment = s0.segment;
  out->q_m_c = s0.q_m_c.slerp(a, s1.q_m_c).normalized();
  out->cov_c = (1 - a) * s0.cov_c + a * s1.cov_c;
  return true;
}

}  // namespace evio::backend
