#include "evio/backend/trajectory_smoothing.h"

#include <Eigen/Geometry>

#include "evio/calib/geometry.h"

namespace evio::backend {
namespace {

// The prediction's IMU motion re-applied to keyframe state k.
VioState reapply(const FramePrediction& f, const VioState& k, const Eigen::Vector3d& g) {
  const double dt = 1e-9 * static_cast<double>(f.prediction.t_ns - f.anchor.t_ns);
  const Eigen::Quaterniond qa = f.anchor.T_w_b.rotation, qx = f.prediction.T_w_b.rotation;
  const Eigen::Quaterniond dR = qa.conjugate() * qx;
  const Eigen::Vector3d dv = qa.conjugate() * (f.prediction.v_w - f.anchor.v_w - g * dt);
  const Eigen::Vector3d dp = qa.conjugate() * (f.prediction.T_w_b.translation - f.anchor.T_w_b.translation -
                                               f.anchor.v_w * dt - 0.5 * g * dt * dt);
  const Eigen::Quaterniond qk = k.T_w_b.rotation;
  VioState out = k;
  out.t_ns = f.prediction.t_ns;
  out.T_w_b = calib::SE3((qk * dR).normalized(), k.T_w_b.translation + k.v_w * dt + 0.5 * g * dt * dt + qk * dp);
  out.v_w = k.v_w + g * dt + qk * dv;
  return out;
}

}  // namespace

std::vector<VioState> repropagate_trajectory(const std::vector<FramePrediction>& frames,
                                             const std::map<int64_t, VioState>& final_keyframes,
                                             const Eigen::Vector3d& gravity_w) {
  // The re-propagated prediction of every keyframe from its predecessor: the mismatch at the end
  // of each interval, by the interval's anchor time.
  struct Mismatch {
    int64_t t_end;
    Eigen::Vector3d dp, dv, dtheta;  // final - re-propagated (world frame; rotation on the left)
  };
  std::map<int64_t, Mismatch> mismatch;
  for (const FramePrediction& f : frames) {
    if (!f.predicted) continue;
    const auto k = final_keyframes.find(f.anchor.t_ns);
    const auto next = final_keyframes.find(f.prediction.t_ns);
    if (k == final_keyframes.end() || next == final_keyframes.end()) continue;
    const VioState x = reapply(f, k->second, gravity_w);
    Mismatch m;
    m.t_end = f.prediction.t_ns;
    m.dp = next->second.T_w_b.translation - x.T_w_b.translation;
    m.dv = next->second.v_w - x.v_w;
    m.dtheta = calib::so3_log(next->second.T_w_b.rotation_matrix() * x.T_w_b.rotation_matrix().transpose());
    mismatch[f.anchor.t_ns] = m;
  }
  std::vector<VioState> out;
  out.reserve(frames.size());
  for (const FramePrediction& f : frames) {
    const auto own = final_keyframes.find(f.state.t_ns);
    if (own != final_keyframes.end()) {
      out.push_back(own->second);
      continue;
    }
    const auto k = f.predicted ? final_keyframes.find(f.anchor.t_ns) : final_keyframes.end();
    if (k == final_keyframes.end()) {
      out.push_back(f.state);
      continue;
    }
    VioState x = reapply(f, k->second, gravity_w);
    const auto m = mismatch.find(f.anchor.t_ns);
    if (m != mismatch.end() && m->second.t_end > f.anchor.t_ns) {
      const double a = static_cast<double>(f.prediction.t_ns - f.anchor.t_ns) /
                       static_cast<double>(m->second.t_end - f.anchor.t_ns);
      x.T_w_b = calib::SE3((calib::so3_exp_quat(a * m->second.dtheta) * x.T_w_b.rotation).normalized(),
                           x.T_w_b.translation + a * m->second.dp);
      x.v_w += a * m->second.dv;
    }
    out.push_back(x);
  }
  return out;
}

}  // namespace evio::backend
