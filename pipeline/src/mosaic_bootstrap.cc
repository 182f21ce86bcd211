// MosaicPipeline's bootstrap: before the tracker (Kim et al., BMVC 2014) has a map, the events of
// the first bootstrap_ns are mapped into the gradient mosaic under rotations integrated from the
// gyro or from rotational contrast-maximisation rates per window (mapping::estimate_angular_velocity);
// then the bootstrap mosaic is reconstructed, the tracker's contrast calibrated on it (mean
// log-intensity change per event along the bootstrap's paths) and the particle filter started at
// the bootstrap's last rotation and rate.
#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "evio/calib/geometry.h"
#include "evio/calib/log.h"
#include "mosaic_pipeline_impl.h"

namespace evio::pipeline {

// Camera-frame rate at the camera-clock time, linear between the samples around it (held before
// the first and after the last; zero without any sample). Holding each sample until the next
// would lag the gyro bootstrap by half a sample period.
Eigen::Vector3d MosaicPipeline::Impl::gyro_c_at(int64_t t_cam) const {
  if (imu.empty()) return Eigen::Vector3d::Zero();
  const int64_t t = t_cam + shift;
  auto it = std::upper_bound(imu.begin(), imu.end(), t, [](int64_t a, const ImuSample& s) { return a < s.t_ns; });
  if (it == imu.begin()) return frontend::RotationParticleFilter::camera_rate_from_imu(*it, q_c_b);
  const ImuSample& a = *(it - 1);
  if (it == imu.end()) return frontend::RotationParticleFilter::camera_rate_from_imu(a, q_c_b);
  const double s = static_cast<double>(t - a.t_ns) / static_cast<double>(it->t_ns - a.t_ns);
  return (1 - s) * frontend::RotationParticleFilter::camera_rate_from_imu(a, q_c_b) +
         s * frontend::RotationParticleFilter::camera_rate_from_imu(*it, q_c_b);
}

// ---- bootstrap: rotation from the gyro or from contrast-maximisation rates ---------------------

bool MosaicPipeline::Impl::cmax_window(const Event* ev, size_t n, int64_t tw0, int64_t t_limit, size_t* count,
                                       int64_t* tw1) const {
  int64_t end = std::min(t_limit, tw0 + opt.bootstrap_window_ns);
  const size_t max_events = static_cast<size_t>(opt.bootstrap_window_events);
  const size_t min_events = std::min(max_events, static_cast<size_t>(opt.bootstrap_min_window_events));
  size_t j = 0;
  while (j < n && ev[j].t_ns < end && j < max_events) ++j;
  if (j < min_events && end < t_limit && (j < n || !finishing)) {
    // Too few events by window_ns: open until the floor's count or max_window_ns.
    end = std::min(t_limit, tw0 + opt.bootstrap_max_window_ns);
    while (j < n && ev[j].t_ns < end && j < min_events) ++j;
    if (j < n && ev[j].t_ns < end) end = ev[j].t_ns;  // closed by the floor's count
  }
  if (j == n && !finishing) return false;  // the window may hold more events
  if (j < n && ev[j].t_ns < end) end = ev[j].t_ns;  // closed by the event count
  *count = j;
  *tw1 = end;
  return true;
}

bool MosaicPipeline::Impl::cmax_rate(const Event* ev, size_t n, int64_t tw0, int64_t tw1, bool cut, bool* still) {
  *still = false;
  if (cut && 2 * static_cast<int64_t>(n) < opt.bootstrap_window_events && 2 * (tw1 - tw0) < opt.bootstrap_window_ns)
    return false;  // a sub-millisecond window can give a rate many times the true one: the previous rate holds
  std::vector<Eigen::Vector3f> b;
  std::vector<int64_t> t;
  b.reserve(n);
  t.reserve(n);
  // At most bootstrap_rate_max_events of them, evenly strided (0: all).
  const size_t cap = static_cast<size_t>(opt.bootstrap_rate_max_events);
  const size_t stride = cap > 0 && n > cap ? (n + cap - 1) / cap : 1;
  for (size_t k = 0; k < n; k += stride) {
    if (ev[k].x >= W || ev[k].y >= H || !undistorter.valid(ev[k].x, ev[k].y)) continue;
    b.push_back(undistorter.bearing(ev[k].x, ev[k].y));
    t.push_back(ev[k].t_ns);
  }
  const auto r = mapping::estimate_angular_velocity(b, t, tw0, omega_c, cmax);
  // Before the first moving window (a static start) the gain threshold applies; afterwards only a
  // rate that is worse than none reads as still.
  const double min_gain = moved ? 1.0 : opt.bootstrap_min_contrast_gain;
  *still = !(r.contrast >= min_gain * r.contrast_zero);
  if (!*still) moved = true;
  omega_c = *still ? Eigen::Vector3d::Zero() : r.omega_c;
  return true;
}

// Processes one bootstrap window when its events (and IMU) are complete; false when waiting. With
// kOdometry and kCmaxSlam the bootstrap runs to the end of the data.
bool MosaicPipeline::Impl::bootstrap_step() {
  const bool odometry_only = opt.tracker_method == MosaicTracker::kOdometry || opt.tracker_method == MosaicTracker::kCmaxSlam;
  if (available() == 0) {
    if (!finishing) return false;
    if (odometry_only) {
      result.stats.bootstrap.t_end_ns = result.stats.t_last_event_ns;
      if (slam && !slam_finished) {
        slam->finish(result.stats.t_last_event_ns);
        slam_finished = true;
        slam_drain();
        // The global pass moved knots already recorded: the trajectory is the refined spline.
        if (slam->stats().global_refined) {
          std::vector<StampedPose> poses(result.rotation.begin(), result.rotation.end());
          const Eigen::Matrix3d R_c_b = cal.T_c_b.rotation.toRotationMatrix();
          for (StampedPose& p : poses) p.T_w_b.rotation = Eigen::Quaterniond(slam->rotation(p.t_ns) * R_c_b).normalized();
          result.rotation = Trajectory(std::move(poses));
        }
      }
      return false;
    }
    end_bootstrap(result.stats.t_last_event_ns);
    return true;
  }
  const Event* ev = pending.data() + head;
  const size_t n = available();
  const int64_t tw0 = ev[0].t_ns;
  if (tw0 >= t_boot) {
    end_bootstrap(tw0);
    return true;
  }
  size_t j = 0;
  int64_t tw1 = 0;
  if (opt.use_gyro) {
    tw1 = std::min(t_boot, tw0 + std::min(opt.bootstrap_window_ns, opt.gyro_bootstrap_window_ns));
    while (j < n && ev[j].t_ns < tw1) ++j;
    if (j == n && !finishing) return false;  // the window may hold more events
  } else if (!cmax_window(ev, n, tw0, t_boot, &j, &tw1)) {
    return false;
  }
  if (!imu_ready(tw1)) return false;
  const std::optional<Eigen::Matrix3d> R_ref0 = boot_ref_at(tw0), R_ref1 = boot_ref_at(tw1);
  const bool use_ref = R_ref0 && R_ref1;
  if (use_ref) {
    omega_c = tw1 > tw0 ? Eigen::Vector3d(calib::so3_log(R_ref0->transpose() * *R_ref1) / (1e-9 * static_cast<double>(tw1 - tw0)))
                        : omega_c;
  } else if (!opt.use_gyro) {
    // The first window is never kept short: there is no previous rate.
    const bool cut = result.stats.bootstrap.cmax_windows > 0 && (tw1 == t_boot || j == n);
    bool still = false;
    if (cmax_rate(ev, j, tw0, tw1, cut, &still)) {
      ++result.stats.bootstrap.cmax_windows;
      if (still) ++result.stats.bootstrap.still_windows;
    } else
      ++result.stats.bootstrap.short_windows;
  }
  if (slam) {
    // The back-end gets the bearings now; the mosaic maps the events once their window is final.
    for (size_t k = 0; k < j; ++k) {
      const Event& e = ev[k];
      slam_waiting.push_back(e);
      if (e.x < W && e.y < H && undistorter.valid(e.x, e.y)) slam->add_event(e.t_ns, undistorter.bearing(e.x, e.y));
    }
  }
  for (size_t k = 0; k < j && !slam; ++k) {
    const Event& e = ev[k];
    const Eigen::Vector3d w_c = opt.use_gyro ? gyro_c_at(e.t_ns) : omega_c;
    std::optional<Eigen::Matrix3d> R_g = use_ref ? boot_ref_at(e.t_ns) : std::nullopt;
    const Eigen::Matrix3d R_e = R_g ? *R_g : Eigen::Matrix3d(R * calib::so3_exp(w_c * (static_cast<double>(e.t_ns - tw0) * 1e-9)));
    mapper.map_event(e, R_e.cast<float>(), Eigen::Vector3f::Zero(), 0.0f);
  }
  // Advance R to the window's end (gyro: integrate the samples inside).
  if (use_ref) {
    R = *R_ref1;
  } else if (opt.use_gyro) {
    for (int64_t t = tw0; t < tw1;) {
      const int64_t dt = std::min<int64_t>(opt.gyro_integration_step_ns, tw1 - t);
      R = R * calib::so3_exp(gyro_c_at(t + dt / 2) * (static_cast<double>(dt) * 1e-9));
      t += dt;
    }
  } else {
    R = R * calib::so3_exp(omega_c * (static_cast<double>(tw1 - tw0) * 1e-9));
  }
  if (slam) {
    // The odometry's rotation predicts the back-end's new knots.
    slam->predict(tw1, R);
    slam->update(tw1);
    slam_drain();
  } else {
    record(tw1, R);
  }
  head += j;
  processed += static_cast<int64_t>(j);
  result.stats.bootstrap.events += static_cast<int64_t>(j);
  return true;
}

void MosaicPipeline::Impl::slam_drain() {
  const int64_t t_final = slam_finished ? INT64_MAX : slam->finalized_until_ns();
  while (!slam_waiting.empty() && slam_waiting.front().t_ns < t_final) {
    const Event& e = slam_waiting.front();
    mapper.map_event(e, slam->rotation(e.t_ns).cast<float>(), Eigen::Vector3f::Zero(), 0.0f);
    slam_waiting.pop_front();
  }
  const int64_t t_knots = slam_finished ? result.stats.t_last_event_ns : slam->finalized_until_ns();
  // The spline at its knots' times (the knots themselves with the linear spline).
  for (; slam_recorded < slam->knots() && slam->knot_time(slam_recorded) <= t_knots; ++slam_recorded)
    if (slam->knot_time(slam_recorded) >= t0) record(slam->knot_time(slam_recorded), slam->rotation(slam->knot_time(slam_recorded)));
  if (slam_finished) record(result.stats.t_last_event_ns, slam->rotation(result.stats.t_last_event_ns));
}

// The bootstrap mosaic's reconstruction, the tracker's contrast and the particle filter at t_track0.
void MosaicPipeline::Impl::end_bootstrap(int64_t t_track0) {
  mapper.reconstruct(next_reconstruct_mode(), 0);  // maps[0], whole
  mapper.maps[1] = mapper.maps[0];
  mapper.last_region = mapping::PixelRect{0, 0, 0, 0};
  front = 0;
  if (map_ref) {
    oracle_map = map_ref(mosaic_initial_camera_rotation() * q_c_b.toRotationMatrix(), t0);
    if (oracle_map.size() != static_cast<size_t>(opt.mosaic.width) * static_cast<size_t>(opt.mosaic.height))
      throw std::invalid_argument("MosaicPipeline: the tracker map reference is not mosaic.width x mosaic.height");
  }
  const std::vector<float>& map = oracle_map.empty() ? mapper.maps[0] : oracle_map;
  mapper.collect_segments = false;
  MosaicBootstrapStats& bs = result.stats.bootstrap;
  bs.t_end_ns = t_track0;
  double contrast_used = opt.tracker.contrast_threshold;
  if (opt.calibrate_contrast) {
    const frontend::LogIntensityMapView v0{opt.mosaic.width, opt.mosaic.height, map.data()};
    double sum = 0;
    auto mature = [&](const Eigen::Vector2d& uv) {
      const int iu = static_cast<int>(std::floor(uv.x())), iv = static_cast<int>(std::floor(uv.y()));
      if (iv < 0 || iv >= opt.mosaic.height) return false;
      const int w = opt.mosaic.width;
      return mapper.mosaic.observations(((iu % w) + w) % w, iv) >= static_cast<uint32_t>(opt.calibration_min_texel_updates);
    };
    for (const Mapper::Segment& sg : mapper.boot_segments) {
      if (!mature(sg.from) || !mature(sg.to)) continue;
      const float a = v0.sample(static_cast<float>(sg.to.x()), static_cast<float>(sg.to.y()));
      const float b = v0.sample(static_cast<float>(sg.from.x()), static_cast<float>(sg.from.y()));
      if (std::isnan(a) || std::isnan(b)) continue;
      sum += sg.polarity * static_cast<double>(a - b);
      ++bs.contrast_samples;
    }
    if (bs.contrast_samples >= opt.calibration_min_samples && sum > 0) {
      contrast_used = std::clamp(sum / static_cast<double>(bs.contrast_samples),
                                 opt.min_contrast_ratio * opt.tracker.contrast_threshold, opt.tracker.contrast_threshold);
      bs.contrast_calibrated = true;
    } else {
      log_warning("MosaicPipeline: too few bootstrap events (" + std::to_string(bs.contrast_samples) +
                  ") to calibrate the tracker's contrast; using tracker.contrast_threshold " +
                  std::to_string(contrast_used));
    }
  }
  mapper.boot_segments = {};
  bs.tracker_contrast = contrast_used;
  frontend::RotationParticleFilterOptions tracker_options = opt.tracker;
  tracker_options.contrast_threshold = contrast_used;
  if (!opt.use_gyro && opt.tracker_method == MosaicTracker::kOdometryParticleFilter) {
    // The odometry's rates are the filter's gyro: one sample per window.
    tracker_options.gyro_noise_rad_per_sqrt_s = opt.odometry_noise_rad_per_sqrt_s;
    tracker_options.gyro_max_age_ns = std::max(tracker_options.gyro_max_age_ns, opt.bootstrap_window_ns);
  }
  pf = std::make_unique<frontend::RotationParticleFilter>(undistorter, tracker_options);
  pf->reset(Eigen::Quaterniond(R), t_track0);
  if (!opt.use_gyro) pf->set_velocity(omega_c);  // the last contrast-maximisation rate (kParticleVelocity)
  view.width = opt.mosaic.width;
  view.height = opt.mosaic.height;
  view.data = oracle_map.empty() ? mapper.maps[front].data() : oracle_map.data();
  rec_point = processed;
  rec_t = t_track0;
  next_snap = opt.snapshot_period_ns > 0 ? t_track0 : INT64_MAX;
  phase = Phase::kTracking;
}

}  // namespace evio::pipeline
