#include "vio_simulation.h"

#include <algorithm>
#include <fstream>
#include <sstream>
#include <random>
#include <stdexcept>
#include <unordered_map>

#include "evio/simulator/scene.h"
#include "evio/simulator/scene_config.h"

namespace evio::test {

VioState VioSimulation::true_state(int64_t t_ns) const {
  const simulator::TrajectoryState s = trajectory->evaluate(t_ns);
  VioState v;
  v.t_ns = t_ns;
  v.T_w_b = s.T_w_b;
  v.v_w = s.v_w;
  // Nearest IMU sample's true bias.
  auto it = std::lower_bound(biases.begin(), biases.end(), t_ns,
                             [](const simulator::ImuBiasSample& b, int64_t t) { return b.t_ns < t; });
  if (it == biases.end()) it = biases.end() - 1;
  v.bias_gyro = it->gyro;
  v.bias_accel = it->accel;
  return v;
}

Trajectory VioSimulation::groundtruth_at_frames() const {
  std::vector<StampedPose> poses;
  for (const auto& f : frames) poses.push_back({f.t_ns, trajectory->evaluate(f.t_ns).T_w_b});
  return Trajectory(std::move(poses));
}

VioSimulation make_vio_simulation(const VioSimOptions& o) {
  simulator::SimulateOverrides ov;
  // The texture is irrelevant here: keep it tiny so loading is fast.
  {
    std::ifstream f(o.scene_yaml);
    std::stringstream text;
    text << f.rdbuf();
    ov.set.push_back(text.str().find("type: panorama") != std::string::npos ? "scene.texture.size=[64,32]"
                                                                             : "scene.planes.0.texture.size=[64,64]");
  }
  if (o.scene_duration_s > 0) ov.duration_s = o.scene_duration_s;
  if (!o.trajectory_file.empty()) ov.set.push_back("trajectory.path=" + o.trajectory_file);
  simulator::SimulationConfig cfg = simulator::load_simulation_config(o.scene_yaml, ov);
  const auto* planes = dynamic_cast<const simulator::PlanarScene*>(cfg.scene.get());
  if (planes == nullptr && dynamic_cast<const simulator::PanoramaScene*>(cfg.scene.get()) == nullptr) {
    throw std::invalid_argument(o.scene_yaml + ": neither a planes nor a panorama scene");
  }

  VioSimulation v;
  v.camera = cfg.camera;
  v.imu_noise = cfg.imu.noise;
  v.gravity_w = cfg.imu.gravity_w;
  v.trajectory = cfg.trajectory;
  v.t_begin_ns = cfg.trajectory->t_begin_ns() + static_cast<int64_t>(std::llround(o.t_begin_s * 1e9));
  v.t_end_ns = std::min(cfg.trajectory->t_end_ns(), v.t_begin_ns + static_cast<int64_t>(std::llround(o.duration_s * 1e9)));
  if (v.t_end_ns <= v.t_begin_ns) throw std::invalid_argument("VIO simulation: empty time span");

  simulator::ImuSimOptions imu = cfg.imu;
  imu.enable_noise = o.imu_noise;
  imu.initial_bias_gyro_radps = o.bias_gyro;
  imu.initial_bias_accel_mps2 = o.bias_accel;
  imu.seed = o.seed;
  v.imu = simulator::simulate_imu(*cfg.trajectory, v.t_begin_ns, v.t_end_ns, imu, &v.biases);

  std::mt19937_64 rng(o.seed);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  if (planes != nullptr) {
    // Landmarks: uniform over the planes' areas.
    double total_area = 0;
    for (const auto& p : planes->planes()) total_area += p.width_m * p.height_m;
    for (const auto& p : planes->planes()) {
      const int n = static_cast<int>(std::lround(o.landmarks * p.width_m * p.height_m / total_area));
      for (int i = 0; i < n; ++i) {
        v.landmarks_w.push_back(p.center_w + (u01(rng) - 0.5) * p.width_m * p.axis_u_w +
                                (u01(rng) - 0.5) * p.height_m * p.axis_v_w);
      }
    }
  } else {
    // Panorama: uniform on a sphere around the start position.
    const Eigen::Vector3d c = cfg.trajectory->evaluate(v.t_begin_ns).T_w_b.translation;
    std::normal_distribution<double> g(0.0, 1.0);
    for (int i = 0; i < o.landmarks; ++i) {
      v.landmarks_w.push_back(c + o.sphere_radius_m * Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized());
    }
  }

  const calib::PinholeCamera& cam = v.camera.camera;
  const calib::SE3 T_c_b = v.camera.T_c_b;
  std::normal_distribution<double> noise(0.0, o.pixel_sigma);
  std::vector<int64_t> track_of(v.landmarks_w.size(), -1);  // current track id, -1: not in view
  int64_t next_track = 0;
  const int64_t period = static_cast<int64_t>(std::llround(1e9 / o.frame_rate_hz));
  int64_t frame_id = 0;
  for (int64_t t = v.t_begin_ns; t <= v.t_end_ns; t += period) {
    const calib::SE3 T_c_w = T_c_b * v.trajectory->evaluate(t).T_w_b.inverse();
    FeatureObservations f;
    f.t_ns = t;
    f.frame_id = frame_id++;
    for (size_t k = 0; k < v.landmarks_w.size(); ++k) {
      const Eigen::Vector3d p_c = T_c_w.rotation * v.landmarks_w[k] + T_c_w.translation;
      Eigen::Vector2d px;
      const bool seen = p_c.z() > 0.1 && cam.project(p_c, &px) && cam.in_image(px, o.border_px);
      if (!seen) {
        track_of[k] = -1;
        continue;
      }
      if (track_of[k] < 0) track_of[k] = next_track++;
      Eigen::Vector2d meas = px + Eigen::Vector2d(noise(rng), noise(rng));
      if (u01(rng) < o.outlier_fraction) {
        meas = Eigen::Vector2d(o.border_px + u01(rng) * (cam.width() - 1 - 2 * o.border_px),
                               o.border_px + u01(rng) * (cam.height() - 1 - 2 * o.border_px));
        ++v.outliers;
      }
      Eigen::Vector3d bearing;
      if (!cam.unproject(meas, &bearing)) continue;
      f.observations.push_back({track_of[k], bearing});
    }
    v.frames.push_back(std::move(f));
  }
  return v;
}

}  // namespace evio::test
