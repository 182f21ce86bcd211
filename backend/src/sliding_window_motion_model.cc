// SlidingWindowEstimator's motion model per keyframe (see the estimator's header comment): Torr's
// GRIC of the shared bearings against the reference view (S: no motion, R: rotation, G: general;
// two_view_gric in motion_model_selection.h) with the IMU's datum that the static centre neither
// accelerates nor moves, an IMU veto on R, hysteresis over rotation_only_min_keyframes keyframes and
// rotation_only_min_duration_s, and the pixel conditions (rotation_only_parallax_px,
// rotation_only_translation_px) as necessary conditions. The IMU-origin centre on a lever arm is
// measured in docs/results/vio.md ("Pure rotation").
#include <algorithm>
#include <cmath>
#include <exception>
#include <optional>
#include <vector>

#include "evio/backend/motion_model_selection.h"
#include "sliding_window_internal.h"

namespace evio::backend {

using internal::median;
using internal::pos_of;
using internal::quat_of;

bool SlidingWindowEstimator::choose_rotation_only(const Keyframe& prev, const FeatureObservations& frame,
                                                  const VioState& predicted, const ImuPreintegration& pre) {
  SlidingWindowStats::MotionModelTest test;
  test.t_ns = frame.t_ns;
  // The static centre of a rotation in place: the camera centre, or the IMU origin (see the IMU test).
  Eigen::Vector3d centre_b = -(camera_.T_c_b.rotation.conjugate() * camera_.T_c_b.translation);
  const bool enabled = options_.rotation_only_model && options_.rotation_only_parallax_px != 0;
  std::vector<Eigen::Vector3d> b0, b1;
  const auto shared = [&](const Keyframe& k) {
    b0.clear();
    b1.clear();
    for (const FeatureObservation& o : frame.observations) {
      const auto it = k.obs.find(o.track_id);
      if (it == k.obs.end() || closed_tracks_.count(o.track_id)) continue;
      b0.push_back(it->second);
      b1.push_back(o.bearing_c);
    }
    return static_cast<int>(b0.size());
  };
  // The reference view. Longest baseline (default): the oldest window keyframe at least
  // model_selection_min_interval_s before the frame that still shares model_selection_min_tracks
  // tracks with it. A slow translation far from the scene (0.1 m/s at 2-4 m) shows under a pixel of
  // parallax over the 50 ms between keyframes of a fast rotation, and R wins every such test; over
  // the window's span it shows. Otherwise the newest such keyframe (keyframes made by track losses
  // can be 10 ms apart: too little baseline for a translation to show). Else the previous keyframe.
  const Keyframe* ref = &prev;
  std::optional<ImuPreintegration> ref_pre;
  const auto try_reference = [&](const Keyframe& k) {
    if (&k == &prev) return true;
    try {
      ref_pre = ImuPreintegration::between(imu_, k.t_ns, frame.t_ns, predicted.bias_gyro, predicted.bias_accel, noise_);
      ref = &k;
      return true;
    } catch (const std::exception&) {
      ref_pre.reset();
      return false;
    }
  };
  if (enabled && options_.model_selection_longest_baseline) {
    for (const auto& kp : window_) {
      const Keyframe& k = *kp;
      if (1e-9 * static_cast<double>(frame.t_ns - k.t_ns) < options_.model_selection_min_interval_s) break;
      if (shared(k) < options_.model_selection_min_tracks) continue;
      if (try_reference(k)) break;
    }
  } else if (enabled && 1e-9 * static_cast<double>(frame.t_ns - prev.t_ns) < options_.model_selection_min_interval_s) {
    for (auto it = window_.rbegin(); it != window_.rend(); ++it) {
      const Keyframe& k = **it;
      if (1e-9 * static_cast<double>(frame.t_ns - k.t_ns) < options_.model_selection_min_interval_s) continue;
      if (shared(k) < options_.model_selection_min_tracks) break;
      try_reference(k);
      break;
    }
  }
  test.tracks = shared(*ref);
  test.baseline_s = 1e-9 * static_cast<double>(frame.t_ns - ref->t_ns);
  const ImuPreintegration& ref_interval = ref_pre ? *ref_pre : pre;
  if (enabled && test.tracks >= options_.model_selection_min_tracks) {
    // Predicted relative camera motion T_c1_c0 = T_c_b T_b1_w T_w_b0 T_b_c.
    const calib::SE3 T_w_b0(quat_of(ref->pose), pos_of(ref->pose));
    const calib::SE3 T_c1_c0 = camera_.T_c_b * predicted.T_w_b.inverse() * T_w_b0 * camera_.T_c_b.inverse();
    const Eigen::Matrix3d R_prior = T_c1_c0.rotation.toRotationMatrix();
    // IMU datum: the change of the camera centre's velocity over the interval, zero under S and R.
    const bool use_imu = options_.model_selection_accel_sigma_mps2 > 0 && ref_interval.dt_s() > 0;
    double chi2 = 0;
    int dof = 0;
    if (use_imu) {
      const VioState ps = state_of(*ref);
      const Eigen::Matrix3d R0 = quat_of(ref->pose).toRotationMatrix();
      const Eigen::Matrix3d R1 = predicted.T_w_b.rotation.toRotationMatrix();
      const double dt = ref_interval.dt_s();
      const Eigen::Vector3d p_b_c = -(camera_.T_c_b.rotation.conjugate() * camera_.T_c_b.translation);  // camera centre in b
      const Eigen::Vector3d w0 = ImuPreintegration::interpolate(imu_, ref->t_ns).gyro - ps.bias_gyro;
      const Eigen::Vector3d w1 = ImuPreintegration::interpolate(imu_, frame.t_ns).gyro - ps.bias_gyro;
      const Eigen::Matrix3d cov = R0 * ref_interval.covariance().block<3, 3>(3, 3) * R0.transpose() +
                                  std::pow(options_.model_selection_accel_sigma_mps2 * dt, 2) * Eigen::Matrix3d::Identity();
      const Eigen::LDLT<Eigen::Matrix3d> cov_ldlt = cov.ldlt();
      // The velocity change of the body point c over the interval (zero for a static centre).
      const auto accel_chi2 = [&](const Eigen::Vector3d& c) {
        const Eigen::Vector3d dv = R0 * ref_interval.delta_v() + options_.gravity_w * dt + R1 * w1.cross(c) - R0 * w0.cross(c);
        return dv.dot(cov_ldlt.solve(dv));
      };
      chi2 = accel_chi2(p_b_c);
      const bool imu_candidate = options_.rotation_only_imu_centre && p_b_c.norm() > 0;
      double chi2_imu_origin = imu_candidate ? accel_chi2(Eigen::Vector3d::Zero()) : 0;
      dof = 3;
      // The predicted displacement of the camera centre, when landmarks make the velocity observable.
      int triangulated = 0;
      for (const auto& [track, lm] : landmarks_) triangulated += lm.triangulated ? 1 : 0;
      test.landmarks = triangulated;
      // How well the reference keyframe's velocity is known: at the last keyframe whose window had
      // model_selection_min_tracks triangulated landmarks (or at the initialisation, with its own
      // sigma), growing at model_selection_velocity_drift_mps2 since then while only the IMU
      // carried it. A fast turn leaves no landmarks for a while; the velocity is still known.
      const double sigma_v = std::hypot(velocity_anchor_sigma_mps_,
                                        options_.model_selection_velocity_drift_mps2 * 1e-9 *
                                            static_cast<double>(std::max<int64_t>(0, ref->t_ns - velocity_anchor_t_ns_)));
      if (options_.model_selection_velocity_sigma_mps > 0 && velocity_anchor_sigma_mps_ > 0) {
        const Eigen::Matrix3d cov_p =
            R0 * ref_interval.covariance().block<3, 3>(6, 6) * R0.transpose() +
            (std::pow(sigma_v * dt, 2) +
             std::pow(0.5 * options_.model_selection_velocity_drift_mps2 * dt * dt, 2)) * Eigen::Matrix3d::Identity();
        const Eigen::LDLT<Eigen::Matrix3d> cov_p_ldlt = cov_p.ldlt();
        const auto move_chi2 = [&](const Eigen::Vector3d& c) {
          const Eigen::Vector3d dp = predicted.T_w_b.translation + R1 * c - (pos_of(ref->pose) + R0 * c);
          return dp.dot(cov_p_ldlt.solve(dp));
        };
        chi2 += move_chi2(p_b_c);
        if (imu_candidate) chi2_imu_origin += move_chi2(Eigen::Vector3d::Zero());
        dof += 3;
      }
      if (imu_candidate && chi2_imu_origin < chi2) {
        chi2 = chi2_imu_origin;
        centre_b = Eigen::Vector3d::Zero();
        test.centre_imu = true;
      }
    }
    const TwoViewGric g = two_view_gric(b0, b1, R_prior, T_c1_c0.translation, focal_px_, options_.pixel_sigma, dof, chi2);
    test.gric_static = g.gric_static;
    test.gric_rotation = g.gric_rotation;
    test.gric_general = g.gric_general;
    test.imu_chi2 = g.imu_chi2;
    test.imu_dof = g.imu_dof;
    test.best = g.best;
    test.image_best = g.image_best;
    // IMU veto: a camera centre whose velocity change (or displacement) the IMU rejects cannot
    // be rotating in place, whatever the image test says.
    if (test.best == TwoViewModel::kRotation && g.imu_dof > 0 && options_.model_selection_imu_veto_p > 0 &&
        g.imu_chi2 > chi2_upper_quantile(g.imu_dof, options_.model_selection_imu_veto_p)) {
      test.best = TwoViewModel::kGeneral;
      test.imu_veto = true;
    }
  }
  if (test.best == TwoViewModel::kNone) {
    rotation_only_active_ = false;
    rotation_only_run_ = 0;
  } else {
    // A test is decisive for G when the IMU vetoes R or G wins by the margin; for R when R wins by
    // the margin. Anything else (S, or a win by less than the margin: drifting tracks over a
    // keyframe interval of 0.1-0.2 s can favour G by a few units in a pure rotation) leaves the
    // state and the run as they are.
    const double margin = options_.rotation_only_gric_margin;
    const bool g_wins = test.best == TwoViewModel::kGeneral &&
                        (test.imu_veto || test.gric_general + margin <= std::min(test.gric_static, test.gric_rotation));
    const bool r_wins = test.best == TwoViewModel::kRotation &&
                        test.gric_rotation + margin <= std::min(test.gric_static, test.gric_general);
    if (g_wins) {
      rotation_only_active_ = false;
      rotation_only_run_ = 0;
    } else if (r_wins && !rotation_only_active_) {
      ++rotation_only_run_;
    }
    if (rotation_only_run_ == 1 && r_wins) rotation_only_run_start_ns_ = frame.t_ns;
    rotation_only_active_ = rotation_only_run_ >= options_.rotation_only_min_keyframes &&
                            static_cast<double>(frame.t_ns - rotation_only_run_start_ns_) * 1e-9 >=
                                options_.rotation_only_min_duration_s;
  }
  // Necessary condition kept from the former pixel test: the median rotation-compensated
  // displacement below rotation_only_parallax_px and, once landmarks are triangulated, the
  // IMU-predicted translation seen at their median depth below rotation_only_translation_px. The
  // GRIC test alone cannot tell a slow sideways motion in front of a single plane from a rotation
  // (a fronto-parallel plane's homography: it took a slow replay of poster_6dof for a rotation and
  // drifted in yaw); the pixel test alone switched on during 6-DoF motion from a moving start. Both
  // must agree.
  bool small_motion = false;
  if (rotation_only_active_) {
    size_t common = 0;
    small_motion = parallax_px(frame, predicted, &common) < options_.rotation_only_parallax_px;
    // The translation over the test's baseline (from the reference view), seen at the median depth.
    const Eigen::Matrix3d R_c_w = camera_.T_c_b.rotation.toRotationMatrix() * quat_of(ref->pose).toRotationMatrix().transpose();
    std::vector<double> depth;
    for (const auto& [track, lm] : landmarks_) {
      if (!lm.triangulated) continue;
      const double z = (R_c_w * (Eigen::Vector3d(lm.p[0], lm.p[1], lm.p[2]) - pos_of(ref->pose))).z();
      if (z > 0) depth.push_back(z);
    }
    // Without landmarks in the window (a fast turn leaves none), the depth last seen: a
    // translation does not become invisible because the landmarks that showed it left the view.
    double d = 0;
    if (!depth.empty()) {
      d = std::max(median(depth), options_.min_depth_m);
    } else if (last_median_depth_m_ > 0) {
      d = last_median_depth_m_;
    }
    // No depth seen yet (the start, or a scene at infinity): the translation cannot be judged in
    // pixels; the IMU datum of the test alone speaks for it.
    if (small_motion && d > 0) {
      small_motion = focal_px_ * (R_c_w * (predicted.T_w_b.translation - pos_of(ref->pose))).norm() / d <
                     options_.rotation_only_translation_px;
    }
  }
  test.run = rotation_only_run_;
  // The translational part of the image motion: the body's predicted speed over the median
  // landmark depth (for the rotation tracker's start and stop, VioPipelineOptions).
  if (last_median_depth_m_ > 0) test.translation_flow_deg_s = predicted.v_w.norm() / last_median_depth_m_ * 180.0 / M_PI;
  test.rotation_only = rotation_only_active_ && small_motion;
  rotation_centre_b_ = centre_b;
  stats_.motion_model_tests.push_back(test);
  return test.rotation_only;
}

}  // namespace evio::backend
