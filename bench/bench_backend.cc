// Sliding-window VIO back-end, whole-run benchmark on simulated measurements of the real
// poster_6dof motion-capture trajectory (59.8 s; datasets/poster_6dof_mocap.yaml: IMU with the
// simulator's noise model, landmarks on the poster wall at 20 Hz, 0.5 px noise, 2% outliers):
// for window sizes K, the mean position error (% of distance, SE3 alignment on the first 5 s), yaw
// drift, solve time per keyframe (median, p99) and the real-time factor (estimator wall time /
// sequence duration), one core. Usage: bench_backend [K ...] (default 3 5 10 20).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "evio/backend/sliding_window_estimator.h"
#include "evio/evaluation/trajectory_evaluation.h"
#include "vio_simulation.h"

int main(int argc, char** argv) {
  std::vector<int> ks;
  for (int i = 1; i < argc; ++i) ks.push_back(std::atoi(argv[i]));
  if (ks.empty()) ks = {3, 5, 10, 20};
  evio::test::VioSimOptions so;
  so.scene_yaml = std::string(EVIO_SOURCE_DIR) + "/datasets/poster_6dof_mocap.yaml";
  so.duration_s = 60.0;
  const char* env = std::getenv("EVIO_REAL_DATA");
  so.trajectory_file = (env ? std::string(env) : std::string(EVIO_SOURCE_DIR) + "/../shared/data/real") +
                       "/trajectories/poster_6dof_mocap.csv";
  evio::test::VioSimulation sim;
  try {
    sim = evio::test::make_vio_simulation(so);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_backend: cannot build the simulation (%s); the real motion-capture trajectory is "
                         "needed (../shared/data/real/trajectories)\n", e.what());
    return 1;
  }
  const double duration = (sim.frames.back().t_ns - sim.frames.front().t_ns) * 1e-9;
  std::printf("poster_6dof mocap, %.1f s, %zu frames at 20 Hz, %zu IMU samples\n", duration, sim.frames.size(), sim.imu.size());
  std::printf("%4s %10s %8s %12s %14s %11s %10s %8s %8s\n", "K", "keyframes", "MPE %", "ATE rmse m", "yaw drift d/m",
              "median ms", "p99 ms", "RTF", "iters");
  for (int K : ks) {
    evio::backend::SlidingWindowOptions o;
    o.window_size = K;
    evio::backend::SlidingWindowEstimator est(o, sim.camera, sim.imu_noise);
    est.initialize(sim.true_state(sim.frames.front().t_ns));
    std::vector<evio::StampedPose> poses;
    size_t next_imu = 0;
    const auto t0 = std::chrono::steady_clock::now();
    for (const auto& f : sim.frames) {
      while (next_imu < sim.imu.size() && sim.imu[next_imu].t_ns <= f.t_ns + 5'000'000) est.add_imu(sim.imu[next_imu++]);
      est.add_frame(f);
      poses.push_back({f.t_ns, est.latest_state().T_w_b});
    }
    const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    evio::evaluation::EvaluationOptions eo;
    eo.alignment.method = evio::evaluation::Alignment::kSE3;
    eo.alignment.first_s = 5.0;
    const auto r = evio::evaluation::evaluate(sim.groundtruth_at_frames(), evio::Trajectory(poses), eo);
    std::vector<double> t = est.stats().solve_time_s;
    std::sort(t.begin(), t.end());
    const double med = t[t.size() / 2], p99 = t[std::min(t.size() - 1, static_cast<size_t>(0.99 * t.size()))];
    std::printf("%4d %10lld %8.3f %12.4f %14.4f %11.2f %10.2f %8.4f %8d\n", K, static_cast<long long>(est.stats().keyframes),
                r.mean_position_error_percent, r.ate.trans_m.rmse, r.yaw_drift_deg_per_m, 1e3 * med, 1e3 * p99,
                wall / duration, o.max_iterations);
    std::printf("{\"bench\": \"backend\", \"K\": %d, \"mean_position_error_percent\": %.6f, \"yaw_drift_deg_per_m\": %.6f, "
                "\"solve_ms_median\": %.3f, \"solve_ms_p99\": %.3f, \"real_time_factor\": %.5f}\n",
                K, r.mean_position_error_percent, r.yaw_drift_deg_per_m, 1e3 * med, 1e3 * p99, wall / duration);
  }
  return 0;
}
