#include "make_ecd_sequence.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <random>
#include <vector>

#include "evio/calib/calibration_io.h"
#include "evio/sensors/ecd.h"
#include "evio/sensors/trajectory.h"

namespace evio::bench {

EventBuffer make_synthetic_events(const SequenceSpec& spec) {
  std::mt19937_64 rng(spec.seed);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  std::uniform_int_distribution<int> ux(0, spec.width - 1), uy(0, spec.height - 1);
  const double dt_mean_ns = 1e9 / spec.event_rate_hz;
  const double sweep_period_s = 0.5;  // the edge crosses the sensor twice a second
  EventBuffer events;
  events.reserve(static_cast<size_t>(spec.events));
  double t = 1e6;  // start 1 ms in
  for (int64_t i = 0; i < spec.events; ++i) {
    t += -std::log(1.0 - u01(rng)) * dt_mean_ns;  // Poisson arrivals
    Event e;
    e.t_ns = static_cast<int64_t>(t);
    if (u01(rng) < 0.9) {  // on the moving edge
      const double phase = std::fmod(t * 1e-9 / sweep_period_s, 1.0);
      const double x = phase * (spec.width - 1) + 1.5 * (u01(rng) - 0.5);
      e.x = static_cast<uint16_t>(std::clamp(x, 0.0, spec.width - 1.0));
      e.y = static_cast<uint16_t>(uy(rng));
      e.polarity = static_cast<int8_t>(e.y % 40 < 20 ? 1 : -1);
    } else {  // background activity
      e.x = static_cast<uint16_t>(ux(rng));
      e.y = static_cast<uint16_t>(uy(rng));
      e.polarity = static_cast<int8_t>(u01(rng) < 0.5 ? 1 : -1);
    }
    events.push_back(e);
  }
  return events;
}

std::string make_ecd_sequence(const std::string& dir, const SequenceSpec& spec) {
  std::filesystem::create_directories(dir);
  const std::string events_path = dir + "/events.txt";
  const EventBuffer events = make_synthetic_events(spec);
  EcdEventWriter writer(events_path);
  writer.write(events.span());
  writer.close();
  std::mt19937_64 rng(spec.seed + 1);
  const double t = events.empty() ? 1e6 : static_cast<double>(events.back().t_ns);
  if (!spec.side_files) return events_path;

  // Camera yawing at a constant 0.5 rad/s about the body z axis, gravity along -z in the world.
  const int64_t t_end = static_cast<int64_t>(t) + 1000000;
  const double yaw_rate = 0.5;
  std::vector<ImuSample> imu;
  std::normal_distribution<double> noise(0.0, 1e-3);
  for (int64_t ts = 0; ts <= t_end; ts += 1000000) {
    ImuSample s;
    s.t_ns = ts;
    s.gyro = Eigen::Vector3d(noise(rng), noise(rng), yaw_rate + noise(rng));
    s.accel = Eigen::Vector3d(noise(rng), noise(rng), 9.81 + noise(rng));
    imu.push_back(s);
  }
  write_ecd_imu(dir + "/imu.txt", imu);
  Trajectory gt;
  for (int64_t ts = 0; ts <= t_end; ts += 10000000) {
    const double yaw = yaw_rate * static_cast<double>(ts) * 1e-9;
    gt.push_back({ts, calib::SE3(calib::so3_exp_quat(Eigen::Vector3d(0, 0, yaw)), Eigen::Vector3d(0, 0, 1))});
  }
  write_tum(dir + "/groundtruth.txt", gt);
  calib::CameraIntrinsics intr;
  intr.width = spec.width;
  intr.height = spec.height;
  intr.fx = intr.fy = 200.0;
  intr.cx = spec.width / 2.0;
  intr.cy = spec.height / 2.0;
  intr.model = calib::DistortionModel::kRadtan;
  intr.distortion = {-0.35, 0.15, 0.0, 0.0, 0.0};
  calib::write_ecd_calib(dir + "/calib.txt", calib::PinholeCamera(intr));
  return events_path;
}

}  // namespace evio::bench
