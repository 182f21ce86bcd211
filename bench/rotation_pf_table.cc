// Speed-accuracy table of the rotation particle filter (frontend/rotation_particle_filter.h) on the
// known-map scenario (tests/frontend/panorama_rotation_scenario.h): rotation RMS / max error and
// events/s (one core, filter time only) for particle counts x batch sizes, without and with gyro.
// Usage: rotation_pf_table [speed_deg_s=150] [duration_s=0.5] [particles,...] [batches,...]
//        [gyro: 0 no, 1 yes, 2 both] [motion_noise_rad_per_sqrt_s] [motion model: 0 random walk, 1 constant velocity, 2 particle velocity]
//        [velocity_noise_rad_s_per_sqrt_s] [relative_max_interval_ms] [relative_max_path_rad]
//        [likelihood_std] [gyro_noise_rad_per_sqrt_s]   (omitted: the library defaults)
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <string>
#include <vector>

#include "panorama_rotation_scenario.h"

namespace {
std::vector<int> parse_list(const char* s) {
  std::vector<int> v;
  std::stringstream ss(s);
  std::string tok;
  while (std::getline(ss, tok, ',')) v.push_back(std::atoi(tok.c_str()));
  return v;
}
}  // namespace

int main(int argc, char** argv) {
  using namespace evio::frontend;
  test::PanoramaScenarioConfig cfg;
  cfg.peak_speed_deg_s = argc > 1 ? std::atof(argv[1]) : 150.0;
  cfg.duration_s = argc > 2 ? std::atof(argv[2]) : 0.5;
  const std::vector<int> particles = parse_list(argc > 3 ? argv[3] : "100,300,1000,3000");
  const std::vector<int> batches = parse_list(argc > 4 ? argv[4] : "1,10,100");
  const int gyro_mode = argc > 5 ? std::atoi(argv[5]) : 2;
  const test::PanoramaScenario s = test::make_panorama_scenario(cfg);
  std::printf("scenario: peak %.0f deg/s, %.2f s, %zu events (%.2f M events/s)\n", cfg.peak_speed_deg_s,
              cfg.duration_s, s.events.size(), 1e-6 * s.events.size() / cfg.duration_s);
  std::printf("%-5s %9s %6s %10s %10s %12s %8s %9s %8s\n", "gyro", "particles", "batch", "rms_mrad", "max_mrad",
              "events_per_s", "rt_factor", "resamples", "lin_frac");
  for (int g = 0; g < 2; ++g) {
    if (gyro_mode != 2 && gyro_mode != g) continue;
    for (int n : particles)
      for (int b : batches) {
        RotationParticleFilterOptions o;
        o.num_particles = n;
        o.batch_size = b;
        if (argc > 6) o.motion_noise_rad_per_sqrt_s = std::atof(argv[6]);
        if (argc > 7)
          o.motion_model = std::atoi(argv[7]) == 2   ? RotationMotionModel::kParticleVelocity
                           : std::atoi(argv[7]) == 1 ? RotationMotionModel::kConstantVelocity
                                                     : RotationMotionModel::kRandomWalk;
        if (argc > 8) o.likelihood_std = std::atof(argv[8]);
        if (argc > 9) o.gyro_noise_rad_per_sqrt_s = std::atof(argv[9]);
        if (argc > 10) o.velocity_noise_rad_s_per_sqrt_s = std::atof(argv[10]);
        if (argc > 11) o.relative_max_interval_ns = static_cast<int64_t>(std::atof(argv[11]) * 1e6);
        if (argc > 12) o.relative_max_path_rad = std::atof(argv[12]);
        const test::PanoramaRunResult r = test::run_panorama_filter(s, o, g == 1);
        std::printf("%-5s %9d %6d %10.2f %10.2f %12.0f %8.2f %9lld %8.3f\n", g ? "yes" : "no", n, b, 1e3 * r.rms_rad,
                    1e3 * r.max_rad, r.events_per_s, r.events_per_s * cfg.duration_s / s.events.size() > 0 ?
                    (s.events.size() / cfg.duration_s) / r.events_per_s : 0.0,
                    static_cast<long long>(r.stats.resamples),
                    r.stats.weighted_batches > 0 ? static_cast<double>(r.stats.linearized_batches) / r.stats.weighted_batches : 0.0);
        std::fflush(stdout);
      }
  }
  return 0;
}
