#include "evio/backend/sliding_window_estimator.h"
#include "evio/backend/option_tables.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

#include <ceres/ceres.h>
#include <Eigen/Geometry>

#include "evio/backend/imu_error.h"
#include "evio/backend/imu_preintegration.h"
#include "evio/backend/marginalization.h"
#include "evio/backend/pose_manifold.h"
#include "evio/backend/reprojection_error.h"
#include "sliding_window_internal.h"

namespace evio::backend {

using internal::make_loss;
using internal::median;
using internal::pos_of;
using internal::problem_options;
using internal::quat_of;

namespace {

constexpr double kDegToRad = M_PI / 180.0;

}  // namespace

bool SlidingWindowOptions::Validate(std::string* why) const {
  // Every field's range (gravity_w: finite) is in the config table; no condition between fields.
  return sliding_window_table().check(*this, why);
}

SlidingWindowEstimator::SlidingWindowEstimator(const SlidingWindowOptions& options, const calib::CameraCalibration& camera,
                                               const calib::ImuNoise& noise)
    : options_(options), camera_(camera), noise_(noise), focal_px_(camera.camera.intrinsics().fx) {
  std::string why;
  if (!options.Validate(&why)) throw std::invalid_argument("sliding window options: " + why);
  if (!noise.Validate(&why)) throw std::invalid_argument("IMU noise: " + why);
  if (!(focal_px_ > 0)) throw std::invalid_argument("sliding window: camera focal length must be > 0 px");
}

SlidingWindowEstimator::~SlidingWindowEstimator() = default;

void SlidingWindowEstimator::initialize(const VioState& state, const InitialSigmas& sigmas) {
  if (!std::isfinite(sigmas.bias_gyro_radps) || !std::isfinite(sigmas.velocity_mps)) {
    throw std::invalid_argument("initialize: initial sigmas must be finite");
  }
  initial_ = state;
  initial_sigmas_ = sigmas;
  latest_ = state;
  velocity_anchor_t_ns_ = state.t_ns;
  velocity_anchor_sigma_mps_ = sigmas.velocity_mps > 0 ? sigmas.velocity_mps : options_.init_sigma_velocity_mps;
}

void SlidingWindowEstimator::add_imu(const ImuSample& sample) {
  if (!imu_.empty() && sample.t_ns <= imu_.back().t_ns) return;  // duplicates / out of order: ignored
  imu_.push_back(sample);
}

VioState SlidingWindowEstimator::state_of(const Keyframe& k) const {
  VioState s;
  s.t_ns = k.t_ns;
  s.T_w_b = calib::SE3(quat_of(k.pose), pos_of(k.pose));
  s.v_w = Eigen::Vector3d(k.sb[0], k.sb[1], k.sb[2]);
  s.bias_gyro = Eigen::Vector3d(k.sb[3], k.sb[4], k.sb[5]);
  s.bias_accel = Eigen::Vector3d(k.sb[6], k.sb[7], k.sb[8]);
  return s;
}

VioState SlidingWindowEstimator::propagate(const Keyframe& from, int64_t t_ns) const {
  const VioState s = state_of(from);
  const ImuPreintegration pre = ImuPreintegration::between(imu_, from.t_ns, t_ns, s.bias_gyro, s.bias_accel, noise_);
  const double dt = pre.dt_s();
  const Eigen::Quaterniond q = s.T_w_b.rotation;
  VioState out = s;
  out.t_ns = t_ns;
  out.T_w_b = calib::SE3((q * pre.delta_q()).normalized(),
                         s.T_w_b.translation + s.v_w * dt + 0.5 * options_.gravity_w * dt * dt + q * pre.delta_p());
  out.v_w = s.v_w + options_.gravity_w * dt + q * pre.delta_v();
  return out;
}

std::vector<VioState> SlidingWindowEstimator::keyframe_states() const {
  std::vector<VioState> out;
  for (const auto& k : window_) out.push_back(state_of(*k));
  return out;
}

std::unordered_map<int64_t, Eigen::Vector3d> SlidingWindowEstimator::landmarks() const {
  std::unordered_map<int64_t, Eigen::Vector3d> out;
  for (const auto& [id, lm] : landmarks_) {
    if (lm.triangulated) out[id] = Eigen::Vector3d(lm.p[0], lm.p[1], lm.p[2]);
  }
  return out;
}

Eigen::MatrixXd SlidingWindowEstimator::prior_information() const {
  if (window_.empty()) return {};
  // Column of each window block in the output.
  std::unordered_map<const double*, int> col;
  int n = 0;
  for (const auto& k : window_) {
    col[k->pose.data()] = n;
    col[k->sb.data()] = n + 6;
    n += 15;
  }
  if (options_.estimate_time_offset) col[time_offset_.data()] = n++;
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(n, n);
  if (!prior_) return H;
  const Eigen::MatrixXd& J = prior_->jacobian();
  std::vector<std::pair<int, int>> cols;  // (column in J, column in H) per block, with its tangent size
  std::vector<int> sizes;
  int c = 0;
  for (const PriorBlock& b : prior_->blocks()) {
    const auto it = col.find(b.parameters);
    if (it != col.end()) {
      cols.emplace_back(c, it->second);
      sizes.push_back(b.tangent_size());
    }
    c += b.tangent_size();
  }
  for (size_t i = 0; i < cols.size(); ++i)
    for (size_t j = 0; j < cols.size(); ++j)
      H.block(cols[i].second, cols[j].second, sizes[i], sizes[j]) =
          J.middleCols(cols[i].first, sizes[i]).transpose() * J.middleCols(cols[j].first, sizes[j]);
  return H;
}

double SlidingWindowEstimator::parallax_px(const FeatureObservations& frame, const VioState& predicted, size_t* common) const {
  const Keyframe& last = *window_.back();
  const Eigen::Matrix3d R_c_b = camera_.T_c_b.rotation.toRotationMatrix();
  // Rotation taking a bearing of the last keyframe's camera into the current camera.
  const Eigen::Matrix3d R_cj_ci = R_c_b * predicted.T_w_b.rotation.toRotationMatrix().transpose() *
                                  quat_of(last.pose).toRotationMatrix() * R_c_b.transpose();
  std::vector<double> disp;
  for (const FeatureObservation& o : frame.observations) {
    const auto it = last.obs.find(o.track_id);
    if (it == last.obs.end()) continue;
    const Eigen::Vector3d b = R_cj_ci * it->second;
    if (b.z() <= 1e-6 || o.bearing_c.z() <= 1e-6) continue;
    disp.push_back(focal_px_ * (b.head<2>() / b.z() - o.bearing_c.head<2>() / o.bearing_c.z()).norm());
  }
  if (common) *common = disp.size();
  return median(disp);
}

bool SlidingWindowEstimator::is_keyframe(const FeatureObservations& frame, const VioState& predicted) const {
  const Keyframe& last = *window_.back();
  const double interval = static_cast<double>(frame.t_ns - last.t_ns) * 1e-9;
  // A frame with (almost) no tracks adds only an IMU node: rarely, so that an event-rate drop does
  // not fill the window with them and push out the keyframes whose landmarks the tracks come back to.
  if (static_cast<int>(frame.observations.size()) < options_.keyframe_min_tracks) {
    return interval >= options_.keyframe_max_interval_without_tracks_s;
  }
  if (interval >= options_.keyframe_max_interval_s) return true;
  size_t common = 0;
  const double parallax = parallax_px(frame, predicted, &common);
  if (!last.obs.empty() && static_cast<double>(common) < options_.keyframe_min_tracked_ratio * static_cast<double>(last.obs.size())) {
    return true;
  }
  return parallax >= options_.keyframe_min_parallax_px;
}

void SlidingWindowEstimator::triangulate(int64_t track, Landmark* lm) {
  const Eigen::Matrix3d R_b_c = camera_.T_c_b.rotation.toRotationMatrix().transpose();
  const Eigen::Vector3d t_b_c = -(R_b_c * camera_.T_c_b.translation);
  // Up to two rounds: a linear multi-view solution, then without the observations it does not
  // explain (an outlier among few observations would otherwise spoil the point or reject it).
  for (int round = 0; round < 2; ++round) {
    std::vector<Keyframe*> kfs;
    std::vector<Eigen::Vector3d> centres, dirs;
    for (const auto& k : window_) {
      const auto it = k->obs.find(track);
      if (it == k->obs.end()) continue;
      const Eigen::Matrix3d R_w_b = quat_of(k->pose).toRotationMatrix();
      kfs.push_back(k.get());
      centres.push_back(R_w_b * t_b_c + pos_of(k->pose));
      dirs.push_back((R_w_b * R_b_c * it->second).normalized());
    }
    if (centres.size() < 2) return;
    double max_angle = 0;
    for (size_t i = 0; i < dirs.size(); ++i)
      for (size_t j = i + 1; j < dirs.size(); ++j) max_angle = std::max(max_angle, std::acos(std::clamp(dirs[i].dot(dirs[j]), -1.0, 1.0)));
    if (max_angle < options_.min_triangulation_angle_deg * kDegToRad) return;
    Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
    Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
    for (size_t i = 0; i < dirs.size(); ++i) {
      const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - dirs[i] * dirs[i].transpose();
      A += P;
      rhs += P * centres[i];
    }
    const Eigen::Vector3d X = A.ldlt().solve(rhs);
    if (!X.allFinite()) return;
    // Depth and reprojection checks in every observing keyframe.
    std::vector<Keyframe*> bad;
    bool behind = false;
    for (Keyframe* k : kfs) {
      const Eigen::Vector3d p_c = camera_.T_c_b.rotation * (quat_of(k->pose).conjugate() * (X - pos_of(k->pose))) +
                                  camera_.T_c_b.translation;
      if (p_c.z() < options_.min_depth_m) {
        behind = true;
        break;
      }
      const Eigen::Vector3d& b = k->obs.at(track);
      const double err = focal_px_ * (p_c.head<2>() / p_c.z() - b.head<2>() / b.z()).norm();
      if (err > options_.max_reprojection_px) bad.push_back(k);
    }
    if (!behind && bad.empty()) {
      lm->p = {X.x(), X.y(), X.z()};
      lm->triangulated = true;
      ++stats_.landmarks_triangulated;
      return;
    }
    // Round 2 only when the disagreement is confined to a minority of the observations.
    if (round == 1 || behind || 2 * bad.size() >= kfs.size() || kfs.size() - bad.size() < 2) return;
    for (Keyframe* k : bad) {
      k->obs.erase(track);
      k->reproj.erase(track);
      k->reproj_td.erase(track);
      k->rot.erase(track);
      ++stats_.outliers_removed;
    }
  }
}

double SlidingWindowEstimator::gyro_bias_prior_sigma() const {
  return initial_sigmas_.bias_gyro_radps > 0 ? initial_sigmas_.bias_gyro_radps
                                             : std::sqrt(std::pow(options_.init_bias_gyro_turn_on_radps, 2) +
                                                         std::pow(noise_.gyroscope_random_walk, 2) * options_.init_bias_horizon_s);
}

double SlidingWindowEstimator::sigma_of(const FeatureObservation& o) const {
  return o.sigma_px > 0 && std::isfinite(o.sigma_px) ? o.sigma_px : options_.pixel_sigma;
}

bool SlidingWindowEstimator::add_frame(const FeatureObservations& frame) {
  if (!initial_ || frame.t_ns < initial_->t_ns) return false;
  if (imu_.empty() || imu_.back().t_ns < frame.t_ns || imu_.front().t_ns > frame.t_ns) return false;
  // A frame at (or before) the newest keyframe's time adds no interval: ignored.
  if (!window_.empty() && frame.t_ns <= window_.back()->t_ns) return false;
  ++stats_.frames;
  // Image velocities of this frame's tracks from their previous frame (time offset only). A
  // velocity is used only when it predicts this observation from the one before within
  // max_reprojection_px (constant velocity over three frames): a single outlier observation, in this
  // frame or the previous one, would otherwise give a huge velocity that pulls the offset.
  std::unordered_map<int64_t, Eigen::Vector2d> velocity;
  if (options_.estimate_time_offset) {
    std::unordered_map<int64_t, SeenTrack> seen;
    for (const FeatureObservation& o : frame.observations) {
      if (!(o.bearing_c.z() > 1e-6)) continue;
      SeenTrack now;
      now.t_ns = frame.t_ns;
      now.m = o.bearing_c.head<2>() / o.bearing_c.z();
      const auto it = last_seen_.find(o.track_id);
      if (it != last_seen_.end() && frame.t_ns > it->second.t_ns) {
        const double dt = 1e-9 * static_cast<double>(frame.t_ns - it->second.t_ns);
        now.v = (now.m - it->second.m) / dt;
        now.has_v = true;
        if (it->second.has_v && focal_px_ * (now.v - it->second.v).norm() * dt <= options_.max_reprojection_px) {
          velocity[o.track_id] = now.v;
        }
      }
      seen[o.track_id] = now;
    }
    last_seen_ = std::move(seen);
  }
  VioState predicted;
  if (window_.empty()) {
    // First keyframe: the initial state propagated to the frame, anchored by a prior.
    predicted = *initial_;
    if (frame.t_ns > initial_->t_ns) {
      Keyframe tmp;
      tmp.t_ns = initial_->t_ns;
      const Eigen::Quaterniond q = initial_->T_w_b.rotation;
      tmp.pose = {q.x(), q.y(), q.z(), q.w(), initial_->T_w_b.translation.x(), initial_->T_w_b.translation.y(),
                  initial_->T_w_b.translation.z()};
      for (int i = 0; i < 3; ++i) {
        tmp.sb[static_cast<size_t>(i)] = initial_->v_w(i);
        tmp.sb[static_cast<size_t>(3 + i)] = initial_->bias_gyro(i);
        tmp.sb[static_cast<size_t>(6 + i)] = initial_->bias_accel(i);
      }
      predicted = propagate(tmp, frame.t_ns);
    }
  } else {
    predicted = propagate(*window_.back(), frame.t_ns);
    latest_ = predicted;
    last_prediction_ = std::make_pair(state_of(*window_.back()), predicted);
    // A frame within 2 ms of the newest keyframe (the last frame of a recording) never becomes
    // one: over a single IMU sample the preintegration's covariance is not positive definite.
    if (frame.t_ns - window_.back()->t_ns < 2'000'000 || !is_keyframe(frame, predicted)) return false;
  }

  auto kf = std::make_unique<Keyframe>();
  kf->t_ns = frame.t_ns;
  kf->frame_id = frame.frame_id;
  const Eigen::Quaterniond q = predicted.T_w_b.rotation;
  kf->pose = {q.x(), q.y(), q.z(), q.w(), predicted.T_w_b.translation.x(), predicted.T_w_b.translation.y(),
              predicted.T_w_b.translation.z()};
  for (int i = 0; i < 3; ++i) {
    kf->sb[static_cast<size_t>(i)] = predicted.v_w(i);
    kf->sb[static_cast<size_t>(3 + i)] = predicted.bias_gyro(i);
    kf->sb[static_cast<size_t>(6 + i)] = predicted.bias_accel(i);
  }
  if (!window_.empty()) {
    const Keyframe& prev = *window_.back();
    const VioState ps = state_of(prev);
    kf->pre = std::make_unique<ImuPreintegration>(
        ImuPreintegration::between(imu_, prev.t_ns, kf->t_ns, ps.bias_gyro, ps.bias_accel, noise_));
    kf->rotation_only = choose_rotation_only(prev, frame, predicted, *kf->pre);
    kf->tracker_eligible = stats_.motion_model_tests.back().image_best != TwoViewModel::kGeneral;
    if (kf->rotation_only && options_.rotation_only_static_centre) {
      // The model says the centre does not move: by at most the velocity sigma over the interval.
      const double dt = 1e-9 * static_cast<double>(kf->t_ns - prev.t_ns);
      kf->static_centre = std::make_unique<StaticCentreError>(rotation_centre_b_, std::max(1e-3, options_.model_selection_velocity_sigma_mps * dt));
    }
    if (kf->rotation_only) {
      for (const FeatureObservation& o : frame.observations) {
        const auto it = prev.obs.find(o.track_id);
        if (it == prev.obs.end() || !(o.bearing_c.z() > 1e-6)) continue;
        kf->rot[o.track_id] =
            std::make_unique<RotationOnlyError>(it->second, o.bearing_c, camera_.T_c_b, focal_px_, sigma_of(o));
      }
    }
    kf->imu_error = std::make_unique<ImuError>(*kf->pre, options_.gravity_w);
  }
  for (const FeatureObservation& o : frame.observations) {
    if (closed_tracks_.count(o.track_id) || !(o.bearing_c.z() > 1e-6)) continue;
    kf->obs[o.track_id] = o.bearing_c;
    kf->reproj[o.track_id] = std::make_unique<ReprojectionError>(o.bearing_c, camera_.T_c_b, focal_px_, sigma_of(o));
    if (options_.estimate_time_offset) {
      const auto v = velocity.find(o.track_id);
      kf->reproj_td[o.track_id] = std::make_unique<TimeOffsetReprojectionError>(
          o.bearing_c, v == velocity.end() ? Eigen::Vector2d::Zero() : v->second, camera_.T_c_b, focal_px_, sigma_of(o));
    }
  }
  const bool first = window_.empty();
  stats_.motion_model.emplace_back(kf->t_ns, kf->rotation_only);
  stats_.rotation_only_keyframes += kf->rotation_only ? 1 : 0;
  window_.push_back(std::move(kf));
  ++stats_.keyframes;
  if (first) {
    // Anchor: yaw and position tight (unobservable), roll/pitch, velocity and biases loose.
    Keyframe& k = *window_.front();
    PriorBlock pose_block{k.pose.data(), 7, true, std::vector<double>(k.pose.begin(), k.pose.end())};
    PriorBlock sb_block{k.sb.data(), 9, false, std::vector<double>(k.sb.begin(), k.sb.end())};
    // Rotation tangent is body-frame; express the tight yaw about the world z in body axes.
    const Eigen::Matrix3d R = quat_of(k.pose).toRotationMatrix();
    const Eigen::Vector3d z_b = R.transpose() * Eigen::Vector3d::UnitZ();
    const Eigen::Matrix3d info_rot = z_b * z_b.transpose() / std::pow(options_.init_sigma_yaw_rad, 2) +
                                     (Eigen::Matrix3d::Identity() - z_b * z_b.transpose()) / std::pow(options_.init_sigma_roll_pitch_rad, 2);
    Eigen::MatrixXd S_pose = Eigen::MatrixXd::Zero(6, 6);
    S_pose.topLeftCorner(3, 3) = Eigen::LLT<Eigen::Matrix3d>(info_rot).matrixU();
    S_pose.bottomRightCorner(3, 3) = Eigen::Matrix3d::Identity() / options_.init_sigma_position_m;
    Eigen::MatrixXd S_sb = Eigen::MatrixXd::Zero(9, 9);
    S_sb.diagonal() << Eigen::Vector3d::Constant(
        1.0 / (initial_sigmas_.velocity_mps > 0 ? initial_sigmas_.velocity_mps : options_.init_sigma_velocity_mps)),
        Eigen::Vector3d::Constant(1.0 / gyro_bias_prior_sigma()),
        Eigen::Vector3d::Constant(1.0 / std::sqrt(std::pow(options_.init_bias_accel_turn_on_mps2, 2) +
                                                  std::pow(noise_.accelerometer_random_walk, 2) * options_.init_bias_horizon_s));
    if (options_.estimate_time_offset) {
      PriorBlock td_block{time_offset_.data(), 1, false, {time_offset_[0]}};
      prior_ = LinearPrior::anchor({pose_block, sb_block, td_block},
                                   {S_pose, S_sb, Eigen::MatrixXd::Constant(1, 1, 1.0 / options_.time_offset_sigma_s)});
    } else {
      prior_ = LinearPrior::anchor({pose_block, sb_block}, {S_pose, S_sb});
    }
  }
  // Landmarks: triangulate tracks seen from two or more keyframes; not in a rotation-only
  // keyframe (any apparent parallax there is noise or an outlier).
  for (const auto& [track, b] : window_.back()->rotation_only ? decltype(window_.back()->obs){} : window_.back()->obs) {
    (void)b;
    Landmark& lm = landmarks_[track];
    if (!lm.triangulated) triangulate(track, &lm);
  }
  const auto t0 = std::chrono::steady_clock::now();
  attach_tracked_rotations();
  solve();
  review_tracker_factors();
  remove_outliers();
  if (static_cast<int>(window_.size()) > options_.window_size) {
    // A segment's anchor leaving the window stays as its last estimate.
    for (auto& [id, anchor] : tracker_anchors_) {
      if (anchor.last == window_.front().get()) anchor.last = nullptr;
      if (anchor.kf != window_.front().get()) continue;
      anchor.pose = anchor.kf->pose;
      anchor.kf = nullptr;
    }
    past_keyframes_.emplace_back(window_.front()->t_ns, window_.front()->pose);
    if (past_keyframes_.size() > kMaxPastKeyframes) past_keyframes_.pop_front();
    marginalize_oldest();
  }
  stats_.solve_time_s.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
  stats_.time_offset_s = time_offset_[0];
  latest_ = state_of(*window_.back());
  if (!stats_.health.empty() && initial_) {
    stats_.health.back().gyro_bias_sigmas = (latest_.bias_gyro - initial_->bias_gyro).cwiseAbs().maxCoeff() / gyro_bias_prior_sigma();
  }
  {
    const Keyframe& k = *window_.back();
    const Eigen::Matrix3d R_c_w = camera_.T_c_b.rotation.toRotationMatrix() * quat_of(k.pose).toRotationMatrix().transpose();
    std::vector<double> depth;
    for (const auto& [track, lm] : landmarks_) {
      if (!lm.triangulated) continue;
      const double z = (R_c_w * (Eigen::Vector3d(lm.p[0], lm.p[1], lm.p[2]) - pos_of(k.pose))).z();
      if (z > 0) depth.push_back(z);
    }
    if (!depth.empty()) last_median_depth_m_ = std::max(median(depth), options_.min_depth_m);
    if (static_cast<int>(depth.size()) >= options_.model_selection_min_tracks) {
      velocity_anchor_t_ns_ = k.t_ns;
      velocity_anchor_sigma_mps_ = options_.model_selection_velocity_sigma_mps;
    }
  }
  // Keep IMU samples from just before the oldest keyframe.
  const int64_t keep = window_.front()->t_ns;
  auto it = std::lower_bound(imu_.begin(), imu_.end(), keep, [](const ImuSample& s, int64_t t) { return s.t_ns < t; });
  if (it != imu_.begin()) --it;
  imu_.erase(imu_.begin(), it);
  return true;
}

void SlidingWindowEstimator::solve() {
  PoseManifold manifold;
  const auto loss = make_loss(options_.loss, options_.loss_scale);
  ceres::Problem problem(problem_options());
  // The landmarks in the solve: triangulated and seen from two or more window keyframes.
  std::vector<int64_t> used_tracks;
  for (auto& [track, lm] : landmarks_) {
    if (!lm.triangulated) continue;
    int n = 0;
    for (auto& k : window_) n += k->obs.count(track) ? 1 : 0;
    if (n >= 2) used_tracks.push_back(track);
  }
  std::sort(used_tracks.begin(), used_tracks.end());
  // The solve works on copies of the parameters in one buffer, [landmarks by track id | per
  // keyframe pose, speed/bias], copied back afterwards: Ceres orders the blocks of an ordering group
  // by address, and the buffer's fixed layout keeps the result independent of heap addresses.
  std::vector<double> buf(3 * used_tracks.size() + 16 * window_.size() + 1);
  std::unordered_map<const double*, double*> at;  // live block -> its copy in buf
  std::vector<std::pair<double*, int>> live;       // live block, size (to copy back)
  size_t off = 0;
  auto stage = [&](double* p, int size) {
    std::copy(p, p + size, buf.data() + off);
    at[p] = buf.data() + off;
    live.emplace_back(p, size);
    off += static_cast<size_t>(size);
  };
  for (int64_t track : used_tracks) stage(landmarks_.at(track).p.data(), 3);
  for (auto& k : window_) {
    stage(k->pose.data(), 7);
    stage(k->sb.data(), 9);
  }
  if (options_.estimate_time_offset) stage(time_offset_.data(), 1);
  auto in_buf = [&](const double* p) {
    const auto it = at.find(p);
    return it != at.end() ? it->second : const_cast<double*>(p);
  };
  for (auto& k : window_) {
    problem.AddParameterBlock(in_buf(k->pose.data()), 7, &manifold);
    problem.AddParameterBlock(in_buf(k->sb.data()), 9);
  }
  std::vector<ceres::ResidualBlockId> imu_blocks, visual_blocks;  // for the health check after the solve
  for (size_t i = 1; i < window_.size(); ++i) {
    Keyframe& a = *window_[i - 1];
    Keyframe& b = *window_[i];
    imu_blocks.push_back(problem.AddResidualBlock(b.imu_error.get(), nullptr,
                                                  {in_buf(a.pose.data()), in_buf(a.sb.data()), in_buf(b.pose.data()), in_buf(b.sb.data())}));
  }
  std::vector<double*> outside;  // prior blocks not in the window (not expected)
  if (prior_) {
    std::vector<double*> blocks;
    for (const PriorBlock& pb : prior_->blocks()) {
      blocks.push_back(in_buf(pb.parameters));
      if (!at.count(pb.parameters)) outside.push_back(blocks.back());
    }
    problem.AddResidualBlock(prior_.get(), nullptr, blocks);
  }
  // Rotation-only links of untriangulated tracks.
  for (size_t i = 1; i < window_.size(); ++i) {
    Keyframe& a = *window_[i - 1];
    Keyframe& b = *window_[i];
    for (auto& [track, cost] : b.rot) {
      const auto lit = landmarks_.find(track);
      if (lit != landmarks_.end() && lit->second.triangulated) continue;
      problem.AddResidualBlock(cost.get(), loss.get(), in_buf(a.pose.data()), in_buf(b.pose.data()));
    }
    if (b.static_centre) problem.AddResidualBlock(b.static_centre.get(), nullptr, in_buf(a.pose.data()), in_buf(b.pose.data()));
  }
  // Rotation-tracker factors to their segments' anchors (a marginalised anchor: constant).
  std::vector<double*> frozen;
  const auto tracker_loss = make_loss(RobustLoss::kHuber, options_.tracker_loss_scale);
  for (auto& k : window_) {
    if (!k->tracker_factor) continue;
    TrackerAnchor& anchor = tracker_anchors_.at(k->tracker_anchor_id);
    double* pa = nullptr;
    if (anchor.kf) {
      pa = in_buf(anchor.kf->pose.data());
    } else {
      pa = anchor.pose.data();
      if (!problem.HasParameterBlock(pa)) {
        problem.AddParameterBlock(pa, 7, &manifold);
        problem.SetParameterBlockConstant(pa);
        frozen.push_back(pa);
      }
    }
    problem.AddResidualBlock(k->tracker_factor.get(), tracker_loss.get(), pa, in_buf(k->pose.data()));
  }
  for (auto& [track, lm] : landmarks_) {
    if (!at.count(lm.p.data())) continue;  // not used
    for (auto& k : window_) {
      if (options_.estimate_time_offset) {
        const auto it = k->reproj_td.find(track);
        if (it == k->reproj_td.end()) continue;
        visual_blocks.push_back(problem.AddResidualBlock(it->second.get(), loss.get(), in_buf(k->pose.data()), in_buf(lm.p.data()),
                                                         in_buf(time_offset_.data())));
        continue;
      }
      const auto it = k->reproj.find(track);
      if (it == k->reproj.end()) continue;
      visual_blocks.push_back(problem.AddResidualBlock(it->second.get(), loss.get(), in_buf(k->pose.data()), in_buf(lm.p.data())));
    }
  }
  stats_.solve_landmarks.push_back(static_cast<int>(used_tracks.size()));
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_SCHUR;
  // Eliminate exactly the landmarks (group 0), keep poses and speed/bias blocks (group 1): every
  // eliminated row is then a 2-row reprojection error on a 3-D landmark and a 6-D pose tangent,
  // which Ceres' fixed-size <2, 3, 6> Schur eliminator handles (its automatic ordering also
  // eliminates some 9-D speed/bias blocks, which falls back to the slow dynamic-size one).
  auto ordering = std::make_shared<ceres::ParameterBlockOrdering>();
  for (int64_t track : used_tracks) ordering->AddElementToGroup(in_buf(landmarks_.at(track).p.data()), 0);
  for (auto& k : window_) {
    ordering->AddElementToGroup(in_buf(k->pose.data()), 1);
    ordering->AddElementToGroup(in_buf(k->sb.data()), 1);
  }
  if (options_.estimate_time_offset) ordering->AddElementToGroup(in_buf(time_offset_.data()), 1);
  for (double* p : outside) ordering->AddElementToGroup(p, 1);
  for (double* p : frozen) ordering->AddElementToGroup(p, 1);
  so.linear_solver_ordering = ordering;
  so.max_num_iterations = options_.max_iterations;
  so.function_tolerance = options_.function_tolerance;
  so.num_threads = 1;
  so.logging_type = ceres::SILENT;
  so.minimizer_progress_to_stdout = false;
  if (options_.max_solver_time_s > 0) so.max_solver_time_in_seconds = options_.max_solver_time_s;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  // Health: the whitened residuals' chi2 per degree of freedom after the solve (about 1 when the
  // measurements agree with the estimate and with their noise models), without the robust loss.
  const auto chi2_per_dof = [&problem](const std::vector<ceres::ResidualBlockId>& ids, int dof_per_block) {
    if (ids.empty()) return 0.0;
    ceres::Problem::EvaluateOptions eo;
    eo.residual_blocks = ids;
    eo.apply_loss_function = false;
    double cost = 0;
    problem.Evaluate(eo, &cost, nullptr, nullptr, nullptr);
    return 2.0 * cost / static_cast<double>(ids.size() * static_cast<size_t>(dof_per_block));
  };
  SlidingWindowStats::Health h;
  h.t_ns = window_.back()->t_ns;
  h.visual_chi2_per_dof = chi2_per_dof(visual_blocks, 2);
  h.imu_chi2_per_dof = chi2_per_dof(imu_blocks, 15);
  h.observations = static_cast<int>(visual_blocks.size());
  h.landmarks = static_cast<int>(used_tracks.size());
  stats_.health.push_back(h);
  for (const auto& [p, size] : live) std::copy(at[p], at[p] + size, p);
  latest_cov_.reset();
  if (options_.compute_covariance) {
    ceres::Covariance::Options co;
    co.algorithm_type = ceres::DENSE_SVD;
    co.null_space_rank = -1;  // pseudo-inverse: the gauge is fixed by the prior, but be safe
    ceres::Covariance cov(co);
    const double* pose = in_buf(window_.back()->pose.data());
    const std::vector<std::pair<const double*, const double*>> blocks = {{pose, pose}};
    if (cov.Compute(blocks, &problem)) {
      Eigen::Matrix<double, 6, 6, Eigen::RowMajor> c;
      if (cov.GetCovarianceBlockInTangentSpace(pose, pose, c.data())) latest_cov_ = c;
    }
  }
}

void SlidingWindowEstimator::remove_outliers() {
  for (auto& k : window_) {
    for (auto it = k->obs.begin(); it != k->obs.end();) {
      const int64_t track = it->first;
      const auto lit = landmarks_.find(track);
      if (lit == landmarks_.end() || !lit->second.triangulated) {
        ++it;
        continue;
      }
      double r[2];
      const double* params[3] = {k->pose.data(), lit->second.p.data(), time_offset_.data()};
      const bool ok = options_.estimate_time_offset ? k->reproj_td.at(track)->Evaluate(params, r, nullptr)
                                                    : k->reproj[track]->Evaluate(params, r, nullptr);
      const double err_px = ok ? std::hypot(r[0], r[1]) * options_.pixel_sigma : 1e9;
      if (err_px > options_.max_reprojection_px) {
        k->reproj.erase(track);
        k->reproj_td.erase(track);
        it = k->obs.erase(it);
        ++stats_.outliers_removed;
      } else {
        ++it;
      }
    }
  }
  for (auto& [track, lm] : landmarks_) {
    if (!lm.triangulated) continue;
    int n = 0;
    for (auto& k : window_) n += k->obs.count(track) ? 1 : 0;
    if (n < 2) lm.triangulated = false;
  }
}

}  // namespace evio::backend
