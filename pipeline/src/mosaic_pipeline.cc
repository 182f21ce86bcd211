#include "evio/pipeline/mosaic_pipeline.h"

#include <algorithm>
#include <climits>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <utility>

#include "evio/calib/equirectangular.h"
#include "evio/calib/geometry.h"
#include "evio/calib/log.h"
#include "evio/frontend/event_filters.h"

namespace evio::pipeline {

bool MosaicPipelineOptions::Validate(std::string* why) const {
  auto fail = [why](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  std::string w;
  if (!mosaic.Validate(&w)) return fail("mosaic: " + w);
  if (!tracker.Validate(&w)) return fail("tracker: " + w);
  if (!cmax.Validate(&w)) return fail("cmax: " + w);
  if (reconstruct_period_ns <= 0) return fail("reconstruct_period_ns must be > 0");
  if (full_reconstruct_every < 1) return fail("full_reconstruct_every must be >= 1");
  if (output_weighting != mapping::PoissonWeighting::kNone && output_weighting != mapping::PoissonWeighting::kInformation)
    return fail("output_weighting must be kNone or kInformation");
  if (bootstrap_ns < 0) return fail("bootstrap_ns must be >= 0");
  if (bootstrap_window_ns <= 0) return fail("bootstrap_window_ns must be > 0");
  if (bootstrap_window_events < 1) return fail("bootstrap_window_events must be >= 1");
  if (gyro_bootstrap_window_ns <= 0) return fail("gyro_bootstrap_window_ns must be > 0");
  if (gyro_integration_step_ns <= 0) return fail("gyro_integration_step_ns must be > 0");
  if (!(min_contrast_ratio >= 0 && min_contrast_ratio <= 1)) return fail("min_contrast_ratio must be in [0, 1]");
  if (calibration_sample_stride < 1) return fail("calibration_sample_stride must be >= 1");
  if (calibration_min_texel_updates < 0) return fail("calibration_min_texel_updates must be >= 0");
  if (calibration_min_samples < 1) return fail("calibration_min_samples must be >= 1");
  if (trajectory_period_ns <= 0) return fail("trajectory_period_ns must be > 0");
  if (snapshot_period_ns < 0) return fail("snapshot_period_ns must be >= 0");
  if (imu_wait_ns < 0) return fail("imu_wait_ns must be >= 0");
  return true;
}

Eigen::Matrix3d mosaic_initial_camera_rotation() {
  Eigen::Matrix3d R;
  R.col(0) = Eigen::Vector3d(0, -1, 0);
  R.col(1) = Eigen::Vector3d(0, 0, -1);
  R.col(2) = Eigen::Vector3d(1, 0, 0);
  return R;
}

namespace {

const MosaicPipelineOptions& checked(const MosaicPipelineOptions& o) {
  std::string why;
  if (!o.Validate(&why)) throw std::invalid_argument("MosaicPipeline options: " + why);
  return o;
}

// Log intensity of a reconstruction for the tracker: NaN where unseen.
void to_map(const mapping::MosaicReconstruction& rec, std::vector<float>* map) {
  const auto& L = rec.log_intensity;
  map->resize(static_cast<size_t>(L.size()));
  for (Eigen::Index j = 0; j < L.rows(); ++j)
    for (Eigen::Index i = 0; i < L.cols(); ++i)
      (*map)[static_cast<size_t>(j * L.cols() + i)] = rec.seen(j, i) ? L(j, i) : std::nanf("");
}

}  // namespace

struct MosaicPipeline::Impl {
  Impl(const MosaicPipelineOptions& o, const calib::CameraCalibration& camera)
      : opt(o),
        cal(camera),
        W(camera.camera.width()),
        H(camera.camera.height()),
        shift(camera.time_shift_ns),
        q_c_b(camera.T_c_b.rotation),
        undistorter(camera.camera),
        mosaic(o.mosaic),
        proj(o.mosaic.width, o.mosaic.height),
        last_t(static_cast<size_t>(W) * static_cast<size_t>(H), INT64_MIN),
        last_uv(static_cast<size_t>(W) * static_cast<size_t>(H)) {
    cmax = opt.cmax;
    cmax.width = W;
    cmax.height = H;
    cmax.focal_px = std::sqrt(cal.camera.intrinsics().fx * cal.camera.intrinsics().fy);
    std::string why;
    if (!cmax.Validate(&why)) throw std::invalid_argument("MosaicPipeline: contrast maximisation for this camera: " + why);
    result.stats.bootstrap.gyro = opt.use_gyro;
    result.stats.bootstrap.tracker_contrast = opt.tracker.contrast_threshold;
  }

  enum class Phase { kStart, kBootstrap, kTracking };

  const MosaicPipelineOptions& opt;
  const calib::CameraCalibration cal;
  const int W, H;
  const int64_t shift;  // t_imu = t_cam + shift
  const Eigen::Quaterniond q_c_b;
  const frontend::EventUndistorter undistorter;
  mapping::GradientMosaic mosaic;
  const calib::Equirectangular proj;
  mapping::RotationalCmaxOptions cmax;

  Phase phase = Phase::kStart;
  bool finished = false;
  bool finishing = false;  // finish(): process what is buffered without waiting for more
  SnapshotCallback on_snapshot;

  // Events not yet processed: pending[head, size). Compacted on every add_events.
  std::vector<Event> pending;
  size_t head = 0;
  int64_t processed = 0;

  // IMU (IMU clock): samples older than the ones still needed are pruned in tracking.
  std::vector<ImuSample> imu;
  size_t next_imu = 0;       // tracking: the next sample for the particle filter
  bool imu_started = false;  // tracking: next_imu positioned at the tracking start

  // Mapper: per sensor pixel the time and mosaic position of its previous event (a path's start).
  std::vector<int64_t> last_t;
  std::vector<Eigen::Vector2d> last_uv;
  struct Segment {
    Eigen::Vector2d from, to;
    int polarity;
  };
  std::vector<Segment> boot_segments;  // calibration samples of the bootstrap
  bool collect_segments = false;

  int64_t t_viewed = INT64_MIN;  // the last mark_footprint

  // Bootstrap.
  Eigen::Matrix3d R = mosaic_initial_camera_rotation();
  Eigen::Vector3d omega_c = Eigen::Vector3d::Zero();
  int64_t t0 = 0, t_boot = 0;

  // Tracking.
  std::unique_ptr<frontend::RotationParticleFilter> pf;
  std::vector<float> map;
  frontend::LogIntensityMapView view;
  mapping::MosaicReconstruction rec;
  int64_t next_rec = 0, next_snap = INT64_MAX;

  MosaicResult result;

  size_t available() const { return pending.size() - head; }

  // ---- IMU ------------------------------------------------------------------------------------

  // True when every IMU sample up to the camera-clock time t_cam has come (one after it has).
  bool imu_covers(int64_t t_cam) const { return !imu.empty() && imu.back().t_ns - shift > t_cam; }
  // True when the newest buffered event is more than imu_wait_ns ahead of the newest IMU sample (of
  // the oldest buffered event without any IMU): the gyro is missing there, do not wait for it.
  bool imu_missing() const {
    if (available() == 0) return false;
    const int64_t newest = imu.empty() ? pending[head].t_ns : imu.back().t_ns - shift;
    return pending.back().t_ns - newest > opt.imu_wait_ns;
  }
  bool imu_ready(int64_t t_cam) const { return !opt.use_gyro || finishing || imu_covers(t_cam) || imu_missing(); }

  // Camera-frame rate of the last sample at or before the camera-clock time (the first sample
  // before it; zero without any sample), piecewise constant.
  Eigen::Vector3d gyro_c_at(int64_t t_cam) const {
    if (imu.empty()) return Eigen::Vector3d::Zero();
    const int64_t t = t_cam + shift;
    auto it = std::upper_bound(imu.begin(), imu.end(), t, [](int64_t a, const ImuSample& s) { return a < s.t_ns; });
    if (it != imu.begin()) --it;
    return frontend::RotationParticleFilter::camera_rate_from_imu(*it, q_c_b);
  }

  // ---- mapper and trajectory ------------------------------------------------------------------

  // The event's direction is R_w_c (b + dt w_c x b): R_w_c at a nearby time, rotated to the
  // event's time to first order (dt |w_c| is a few mrad at most within a particle-filter batch).
  void map_event(const Event& e, const Eigen::Matrix3d& R_w_c, const Eigen::Vector3d& w_c, double dt) {
    if (e.x >= W || e.y >= H || !undistorter.valid(e.x, e.y)) return;
    const size_t p = static_cast<size_t>(e.y) * static_cast<size_t>(W) + e.x;
    const int64_t prev = last_t[p];
    const Eigen::Vector3d b = undistorter.bearing(e.x, e.y).cast<double>();
    const Eigen::Vector2d uv = proj.project(R_w_c * (b + dt * w_c.cross(b)));
    last_t[p] = e.t_ns;
    const Eigen::Vector2d uv_prev = last_uv[p];
    last_uv[p] = uv;
    if (prev == INT64_MIN) return;
    if (mosaic.update_segment(uv_prev, uv, static_cast<double>(e.t_ns - prev) * 1e-9, e.polarity) ==
        mapping::MosaicUpdate::kApplied) {
      ++result.stats.events_mapped;
      if (collect_segments && (result.stats.events_mapped % opt.calibration_sample_stride) == 0)
        boot_segments.push_back({uv_prev, uv, e.polarity});
    }
  }

  void record(int64_t t, const Eigen::Matrix3d& R_w_c) {
    Trajectory& rotation = result.rotation;
    if (!rotation.empty() && t - rotation.t_end_ns() < opt.trajectory_period_ns) return;
    calib::SE3 T;
    T.rotation = Eigen::Quaterniond(R_w_c * cal.T_c_b.rotation.toRotationMatrix()).normalized();  // R_w_b
    T.translation.setZero();
    rotation.push_back({t, T});
    if (opt.output_weighting == mapping::PoissonWeighting::kInformation &&
        (t_viewed == INT64_MIN || t - t_viewed >= opt.reconstruct_period_ns)) {
      t_viewed = t;
      mark_footprint(R_w_c);
    }
  }

  // The camera's field of view at R_w_c on the mosaic, for the weighted solve's viewed-but-event-free
  // texels (GradientMosaicOptions::viewed_edge_weight): the bearings of every third sensor pixel
  // in both directions (the last row and column included), each marking its 4 x 4 nearest texels.
  // At DAVIS240C (f = 200 px) and 1024 texels per turn, 3 sensor px are 2.4 texels on the equator
  // and 4 texels at 53 deg latitude, the spacing mark_viewed covers without gaps.
  void mark_footprint(const Eigen::Matrix3d& R_w_c) {
    constexpr int kStride = 3;
    const Eigen::Matrix3f R = R_w_c.cast<float>();
    auto next = [](int v, int n) { return v == n - 1 ? n : std::min(v + kStride, n - 1); };
    for (int y = 0; y < H; y = next(y, H))
      for (int x = 0; x < W; x = next(x, W)) {
        if (!undistorter.valid(x, y)) continue;
        mosaic.mark_viewed(proj.project((R * undistorter.bearing(x, y)).cast<double>()));
      }
  }

  mapping::MosaicReconstruction reconstruct_for_tracker() {
    const bool full = result.stats.reconstructions % opt.full_reconstruct_every == 0;
    ++result.stats.reconstructions;
    return mosaic.reconstruct(full ? mapping::GradientMosaic::ReconstructMode::kFull
                                   : mapping::GradientMosaic::ReconstructMode::kAuto);
  }

  // ---- bootstrap: rotation from the gyro or from contrast-maximisation rates ---------------------

  // Processes one bootstrap window when its events (and IMU) are complete; false when waiting.
  bool bootstrap_step() {
    if (available() == 0) {
      if (!finishing) return false;
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
    int64_t tw1 = std::min(t_boot, tw0 + (opt.use_gyro ? std::min(opt.bootstrap_window_ns, opt.gyro_bootstrap_window_ns)
                                                       : opt.bootstrap_window_ns));
    const size_t max_events = opt.use_gyro ? std::numeric_limits<size_t>::max() : static_cast<size_t>(opt.bootstrap_window_events);
    size_t j = 0;
    while (j < n && ev[j].t_ns < tw1 && j < max_events) ++j;
    if (j == n && !finishing) return false;  // the window may hold more events
    if (j < n && ev[j].t_ns < tw1) tw1 = ev[j].t_ns;  // closed by the event count
    if (!imu_ready(tw1)) return false;
    if (!opt.use_gyro) {
      std::vector<Eigen::Vector3f> b;
      std::vector<int64_t> t;
      for (size_t k = 0; k < j; ++k) {
        if (ev[k].x >= W || ev[k].y >= H || !undistorter.valid(ev[k].x, ev[k].y)) continue;
        b.push_back(undistorter.bearing(ev[k].x, ev[k].y));
        t.push_back(ev[k].t_ns);
      }
      omega_c = mapping::estimate_angular_velocity(b, t, tw0, omega_c, cmax).omega_c;
      ++result.stats.bootstrap.cmax_windows;
    }
    for (size_t k = 0; k < j; ++k) {
      const Event& e = ev[k];
      const Eigen::Vector3d w_c = opt.use_gyro ? gyro_c_at(e.t_ns) : omega_c;
      const Eigen::Matrix3d R_e = R * calib::so3_exp(w_c * (static_cast<double>(e.t_ns - tw0) * 1e-9));
      map_event(e, R_e, Eigen::Vector3d::Zero(), 0.0);
    }
    // Advance R to the window's end (gyro: integrate the samples inside).
    if (opt.use_gyro) {
      for (int64_t t = tw0; t < tw1;) {
        const int64_t dt = std::min<int64_t>(opt.gyro_integration_step_ns, tw1 - t);
        R = R * calib::so3_exp(gyro_c_at(t + dt / 2) * (static_cast<double>(dt) * 1e-9));
        t += dt;
      }
    } else {
      R = R * calib::so3_exp(omega_c * (static_cast<double>(tw1 - tw0) * 1e-9));
    }
    record(tw1, R);
    head += j;
    processed += static_cast<int64_t>(j);
    result.stats.bootstrap.events += static_cast<int64_t>(j);
    return true;
  }

  // The bootstrap mosaic's reconstruction, the tracker's contrast and the particle filter at t_track0.
  void end_bootstrap(int64_t t_track0) {
    rec = reconstruct_for_tracker();
    to_map(rec, &map);
    collect_segments = false;
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
        return mosaic.observations(((iu % w) + w) % w, iv) >= static_cast<uint32_t>(opt.calibration_min_texel_updates);
      };
      for (const Segment& sg : boot_segments) {
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
    boot_segments = {};
    bs.tracker_contrast = contrast_used;
    frontend::RotationParticleFilterOptions tracker_options = opt.tracker;
    tracker_options.contrast_threshold = contrast_used;
    pf = std::make_unique<frontend::RotationParticleFilter>(undistorter, tracker_options);
    pf->reset(Eigen::Quaterniond(R), t_track0);
    view.width = opt.mosaic.width;
    view.height = opt.mosaic.height;
    view.data = map.data();
    next_rec = t_track0 + opt.reconstruct_period_ns;
    next_snap = opt.snapshot_period_ns > 0 ? t_track0 : INT64_MAX;
    phase = Phase::kTracking;
  }

  // ---- tracking and mapping ----------------------------------------------------------------------

  // Processes one particle-filter batch when its events (and IMU) are complete; false when waiting.
  bool tracking_step() {
    const size_t batch = static_cast<size_t>(opt.tracker.batch_size);
    const size_t n = std::min(available(), batch);
    if (n == 0 || (n < batch && !finishing)) return false;
    const Event* ev = pending.data() + head;
    const int64_t t_now = ev[n - 1].t_ns;
    if (!imu_ready(t_now)) return false;
    if (opt.use_gyro) {
      if (!imu_started) {
        // The last sample at or before the tracking start.
        const int64_t t_track0 = result.stats.bootstrap.t_end_ns;
        while (next_imu < imu.size() && imu[next_imu].t_ns - shift <= t_track0) ++next_imu;
        if (next_imu > 0) --next_imu;
        imu_started = true;
      }
      for (; next_imu < imu.size() && imu[next_imu].t_ns - shift <= t_now; ++next_imu)
        pf->add_gyro(imu[next_imu].t_ns - shift, frontend::RotationParticleFilter::camera_rate_from_imu(imu[next_imu], q_c_b));
      if (next_imu >= 4096) {  // the filter has every sample before next_imu
        imu.erase(imu.begin(), imu.begin() + static_cast<std::ptrdiff_t>(next_imu));
        next_imu = 0;
      }
    }
    pf->update(ev, n, view);
    pf->flush(view);
    const Eigen::Matrix3d R_pf = pf->mean().toRotationMatrix();
    const Eigen::Vector3d w_c = pf->angular_velocity_c();
    const int64_t t_pf = pf->time_ns();
    for (size_t k = 0; k < n; ++k) map_event(ev[k], R_pf, w_c, static_cast<double>(ev[k].t_ns - t_pf) * 1e-9);
    record(t_pf, R_pf);
    if (t_now >= next_rec) {
      rec = reconstruct_for_tracker();
      to_map(rec, &map);
      view.data = map.data();
      next_rec = t_now + opt.reconstruct_period_ns;
    }
    if (t_now >= next_snap) {
      if (on_snapshot) on_snapshot(t_now, rec);
      ++result.stats.snapshots;
      next_snap = t_now + opt.snapshot_period_ns;
    }
    head += n;
    processed += static_cast<int64_t>(n);
    return true;
  }

  void process() {
    for (;;) {
      if (phase == Phase::kBootstrap) {
        if (!bootstrap_step()) return;
      } else if (phase == Phase::kTracking) {
        if (!tracking_step()) return;
      } else {
        return;
      }
    }
  }
};

MosaicPipeline::MosaicPipeline(const MosaicPipelineOptions& options, const calib::CameraCalibration& camera)
    : options_(checked(options)), impl_(std::make_unique<Impl>(options_, camera)) {}

MosaicPipeline::~MosaicPipeline() = default;

void MosaicPipeline::set_snapshot_callback(SnapshotCallback callback) { impl_->on_snapshot = std::move(callback); }

void MosaicPipeline::add_imu(const ImuSample& sample) {
  Impl& m = *impl_;
  if (m.finished) throw std::logic_error("MosaicPipeline::add_imu after finish()");
  ++m.result.stats.imu_samples;
  if (!options_.use_gyro) return;
  if (!m.imu.empty() && sample.t_ns < m.imu.back().t_ns) {
    log_warning("MosaicPipeline: IMU sample out of time order dropped");
    return;
  }
  m.imu.push_back(sample);
  m.process();
}

void MosaicPipeline::add_events(EventSpan events) {
  Impl& m = *impl_;
  if (m.finished) throw std::logic_error("MosaicPipeline::add_events after finish()");
  if (events.empty()) return;
  MosaicStats& st = m.result.stats;
  if (m.phase == Impl::Phase::kStart) {
    m.t0 = events.front().t_ns;
    m.t_boot = m.t0 + options_.bootstrap_ns;
    st.t_first_event_ns = m.t0;
    m.collect_segments = options_.calibrate_contrast;
    m.record(m.t0, m.R);
    m.phase = Impl::Phase::kBootstrap;
  }
  st.events += static_cast<int64_t>(events.size());
  st.t_last_event_ns = events.back().t_ns;
  m.pending.erase(m.pending.begin(), m.pending.begin() + static_cast<std::ptrdiff_t>(m.head));
  m.head = 0;
  m.pending.insert(m.pending.end(), events.begin(), events.end());
  m.process();
}

MosaicResult MosaicPipeline::finish() {
  Impl& m = *impl_;
  if (m.finished) throw std::logic_error("MosaicPipeline::finish called twice");
  m.finishing = true;
  m.process();
  m.finished = true;
  m.pending = {};
  m.head = 0;
  MosaicResult& r = m.result;
  r.reconstruction = m.mosaic.reconstruct(mapping::GradientMosaic::ReconstructMode::kFull, m.opt.output_weighting);
  if (m.pf) r.stats.tracker = m.pf->stats();
  int64_t seen = 0;
  for (Eigen::Index k = 0; k < r.reconstruction.seen.size(); ++k) seen += r.reconstruction.seen.data()[k] ? 1 : 0;
  r.stats.seen_pixels = seen;
  r.stats.seen_fraction = r.reconstruction.seen.size() > 0
                              ? static_cast<double>(seen) / static_cast<double>(r.reconstruction.seen.size())
                              : 0.0;
  return std::move(r);
}

int64_t MosaicPipeline::events_processed() const { return impl_->processed; }

size_t MosaicPipeline::buffered_events() const { return impl_->available(); }

}  // namespace evio::pipeline
