// Known-map test scenario for the rotation particle filter (frontend/rotation_particle_filter.h):
// a smooth textured log-intensity panorama (a sum of plane waves on the unit sphere), a camera
// rotating about a varying axis, and an idealised event generator (per pixel, log intensity at the
// pixel's direction, an event at each +-C crossing, crossing times interpolated linearly, plus
// Gaussian timestamp noise and optional uniformly random noise events). Shared by the tests and
// bench/bench_rotation_pf.cc.
#pragma once

#include <cstdint>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "evio/frontend/rotation_particle_filter.h"
#include "evio/sensors/measurements.h"

namespace evio::frontend::test {

struct PanoramaScenarioConfig {
  double peak_speed_deg_s = 150;  // angular speed after the ramp, deg/s
  double duration_s = 0.5;        // sequence length, s; speed ramps up (raised cosine) over the first quarter
  double contrast = 0.2;          // event threshold C, log intensity
  double timestamp_noise_ns = 5000;  // std of Gaussian noise added to event times, ns
  double noise_event_fraction = 0.0;  // random noise events, as a fraction of the signal events
  double gyro_noise_rad_s = 0.01;     // white noise std per gyro sample, rad/s
  Eigen::Vector3d gyro_bias_rad_s = Eigen::Vector3d(0.004, -0.003, 0.005);  // constant, camera frame
  int64_t gyro_period_ns = 1'000'000;  // 1 kHz
  int map_width = 1024;  // the filter's map (the generator renders a 2x finer panorama)
  uint64_t seed = 7;
};

struct PanoramaScenario {
  int sensor_width = 240, sensor_height = 180;
  std::vector<Eigen::Vector3f> bearings;  // ideal pinhole fx = fy = 200, cx = 120, cy = 90
  int map_width = 0, map_height = 0;
  std::vector<float> map;  // the filter's map: the panorama at its texel centres
  std::vector<Event> events;
  std::vector<std::pair<int64_t, Eigen::Vector3d>> gyro;  // camera-frame rates with noise and bias
  int64_t truth_step_ns = 20'000;
  std::vector<Eigen::Quaterniond> truth;  // R_w_c at k * truth_step_ns
  LogIntensityMapView view() const { return {map_width, map_height, map.data()}; }
  Eigen::Quaterniond truth_at(int64_t t_ns) const;  // interpolated
  int64_t end_ns() const { return truth_step_ns * static_cast<int64_t>(truth.size() - 1); }
};

PanoramaScenario make_panorama_scenario(const PanoramaScenarioConfig& config);

struct PanoramaRunResult {
  double rms_rad = 0, max_rad = 0;  // rotation error over the evaluation times (every 1 ms)
  double filter_seconds = 0;        // wall time inside the filter
  double events_per_s = 0;          // events / filter_seconds
  std::vector<Eigen::Quaterniond> means;  // the estimate at each evaluation time
  std::vector<int64_t> times_ns;
  std::vector<Eigen::Vector3d> omega_c;  // angular_velocity_c() at each evaluation time
  RotationParticleFilterStats stats;
};

// Runs the filter from the true initial rotation with the true map; with use_gyro the scenario's
// gyro samples are added in time order before the events that follow them. chunk_ns: events are
// passed to update() in chunks of this duration (evaluation every 1 ms regardless).
PanoramaRunResult run_panorama_filter(const PanoramaScenario& s, const RotationParticleFilterOptions& options,
                                      bool use_gyro, int64_t chunk_ns = 1'000'000);

}  // namespace evio::frontend::test
