#include "evio/pipeline/mosaic_pipeline.h"

#include <algorithm>
#include <climits>
#include <cmath>
#include <stdexcept>
#include <utility>

#include "evio/calib/geometry.h"
#include "evio/calib/log.h"
#include "mosaic_pipeline_impl.h"

namespace evio::pipeline {

const char* mosaic_tracker_name(MosaicTracker t) {
  switch (t) {
    case MosaicTracker::kParticleFilter:
      return "pf";
    case MosaicTracker::kOdometry:
      return "odometry";
    case MosaicTracker::kOdometryParticleFilter:
      return "odometry+pf";
    case MosaicTracker::kCmaxSlam:
      return "cmax_slam";
    case MosaicTracker::kAuto:
      return "auto";
  }
  return "?";
}

MosaicTracker resolve_mosaic_tracker(MosaicTracker t, bool use_gyro) {
  if (t != MosaicTracker::kAuto) return t;
  return use_gyro ? MosaicTracker::kParticleFilter : MosaicTracker::kCmaxSlam;
}

std::string mosaic_tracker_reason(MosaicTracker t, bool use_gyro) {
  if (t != MosaicTracker::kAuto) return "set";
  return use_gyro ? "auto: with the gyro" : "auto: events only";
}

bool MosaicPipelineOptions::Validate(std::string* why) const {
  auto fail = [why](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  std::string w;
  if (!mosaic.Validate(&w)) return fail("mosaic: " + w);
  if (!tracker.Validate(&w)) return fail("tracker: " + w);
  if (!cmax.Validate(&w)) return fail("cmax: " + w);
  if (tracker_method != MosaicTracker::kParticleFilter && tracker_method != MosaicTracker::kOdometry &&
      tracker_method != MosaicTracker::kOdometryParticleFilter && tracker_method != MosaicTracker::kCmaxSlam &&
      tracker_method != MosaicTracker::kAuto)
    return fail("tracker_method is not a MosaicTracker");
  {
    backend::CmaxSlamOptions c = cmax_slam;
    c.panorama_width = mosaic.width;
    c.panorama_height = mosaic.height;
    if (!c.Validate(&w)) return fail("cmax_slam: " + w);
  }
  if (!(odometry_noise_rad_per_sqrt_s > 0) || !std::isfinite(odometry_noise_rad_per_sqrt_s))
    return fail("odometry_noise_rad_per_sqrt_s must be finite and > 0 rad/sqrt(s)");
  if (failure_window_ns <= 0) return fail("failure_window_ns must be > 0 ns");
  if (failure_min_events < 0) return fail("failure_min_events must be >= 0");
  if (failure_lost_windows < 1) return fail("failure_lost_windows must be >= 1");
  if (!(failure_min_rate_ratio >= 0) || !std::isfinite(failure_min_rate_ratio))
    return fail("failure_min_rate_ratio must be finite and >= 0");
  if (!std::isfinite(failure_lost_contrast) || !std::isfinite(failure_recovered_contrast) ||
      !(failure_recovered_contrast >= failure_lost_contrast))
    return fail("failure_recovered_contrast must be finite and >= failure_lost_contrast");
  if (!(failure_relocalize_spread_rad >= 0) || !std::isfinite(failure_relocalize_spread_rad))
    return fail("failure_relocalize_spread_rad must be finite and >= 0 rad");
  if (failure_checkpoint_period_ns <= 0) return fail("failure_checkpoint_period_ns must be > 0 ns");
  if (failure_checkpoints < 1) return fail("failure_checkpoints must be >= 1");
  if (failure_global_period_ns <= 0) return fail("failure_global_period_ns must be > 0 ns");
  if (!(failure_global_min_gain >= 1) || !std::isfinite(failure_global_min_gain))
    return fail("failure_global_min_gain must be finite and >= 1");
  if (!relocalization.Validate(&w)) return fail("relocalization: " + w);
  if (reconstruct_events < 1) return fail("reconstruct_events must be >= 1");
  if (reconstruct_period_ns <= 0) return fail("reconstruct_period_ns must be > 0");
  if (reconstruct_latency_events < 0) return fail("reconstruct_latency_events must be >= 0");
  if (threads != 1 && threads != 2) return fail("threads must be 1 or 2");
  if (footprint_period_ns <= 0) return fail("footprint_period_ns must be > 0");
  if (full_reconstruct_every < 1) return fail("full_reconstruct_every must be >= 1");
  if (output_weighting != mapping::PoissonWeighting::kNone && output_weighting != mapping::PoissonWeighting::kInformation)
    return fail("output_weighting must be kNone or kInformation");
  if (bootstrap_ns < 0) return fail("bootstrap_ns must be >= 0");
  if (bootstrap_window_ns <= 0) return fail("bootstrap_window_ns must be > 0");
  if (bootstrap_window_events < 1) return fail("bootstrap_window_events must be >= 1");
  if (bootstrap_min_window_events < 0) return fail("bootstrap_min_window_events must be >= 0");
  if (bootstrap_max_window_ns < bootstrap_window_ns) return fail("bootstrap_max_window_ns must be >= bootstrap_window_ns");
  if (bootstrap_rate_max_events < 0) return fail("bootstrap_rate_max_events must be >= 0");
  if (!(bootstrap_min_contrast_gain >= 1) || !std::isfinite(bootstrap_min_contrast_gain))
    return fail("bootstrap_min_contrast_gain must be finite and >= 1");
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

// Validated, with the tracker resolved (kAuto: by use_gyro).
MosaicPipelineOptions checked(const MosaicPipelineOptions& o) {
  std::string why;
  if (!o.Validate(&why)) throw std::invalid_argument("MosaicPipeline options: " + why);
  MosaicPipelineOptions r = o;
  r.tracker_method = resolve_mosaic_tracker(o.tracker_method, o.use_gyro);
  return r;
}

// The tracker's map (NaN = unseen) as a reconstruction for the snapshot callback.
mapping::MosaicReconstruction map_snapshot(const std::vector<float>& map, int width, int height) {
  mapping::MosaicReconstruction rec;
  rec.log_intensity.resize(height, width);
  rec.seen.resize(height, width);
  for (Eigen::Index k = 0; k < rec.log_intensity.size(); ++k) {
    const float v = map[static_cast<size_t>(k)];
    const bool seen = !std::isnan(v);
    rec.log_intensity.data()[k] = seen ? v : 0.0f;
    rec.seen.data()[k] = seen ? 1 : 0;
  }
  rec.full_solve = false;
  return rec;
}

}  // namespace

MosaicPipeline::Impl::Impl(const MosaicPipelineOptions& o, const calib::CameraCalibration& camera)
    : opt(o),
      cal(camera),
      W(camera.camera.width()),
      H(camera.camera.height()),
      shift(camera.time_shift_ns),
      q_c_b(camera.T_c_b.rotation),
      undistorter(camera.camera),
      mapper(o, undistorter, W, H),
      queue(&mapper, o.threads > 1) {
  cmax = opt.cmax;
  cmax.width = W;
  cmax.height = H;
  cmax.focal_px = std::sqrt(cal.camera.intrinsics().fx * cal.camera.intrinsics().fy);
  std::string why;
  if (!cmax.Validate(&why)) throw std::invalid_argument("MosaicPipeline: contrast maximisation for this camera: " + why);
  result.stats.bootstrap.gyro = opt.use_gyro;
  result.stats.bootstrap.tracker_contrast = opt.tracker.contrast_threshold;
}

std::optional<Eigen::Matrix3d> MosaicPipeline::Impl::boot_ref_at(int64_t t) const {
  if (!boot_ref) return std::nullopt;
  const auto q0 = boot_ref(t0), q = boot_ref(t);
  if (!q0 || !q) return std::nullopt;
  const Eigen::Matrix3d R_b_c = q_c_b.conjugate().toRotationMatrix();
  return Eigen::Matrix3d(mosaic_initial_camera_rotation() * (q0->toRotationMatrix() * R_b_c).transpose() *
                         (q->toRotationMatrix() * R_b_c));
}

// ---- trajectory ------------------------------------------------------------------------------

// A trajectory pose (at most one per trajectory_period_ns) and, with the weighted final solve,
// the camera's footprint every footprint_period_ns: marked now (bootstrap) or as a mapper step.
void MosaicPipeline::Impl::record(int64_t t, const Eigen::Matrix3d& R_w_c) {
  Trajectory& rotation = result.rotation;
  if (!rotation.empty() && t - rotation.t_end_ns() < opt.trajectory_period_ns) return;
  calib::SE3 T;
  T.rotation = Eigen::Quaterniond(R_w_c * cal.T_c_b.rotation.toRotationMatrix()).normalized();  // R_w_b
  T.translation.setZero();
  rotation.push_back({t, T});
  if ((opt.output_weighting == mapping::PoissonWeighting::kInformation || opt.mosaic.map_viewed_texels) &&
      (t_viewed == INT64_MIN || t - t_viewed >= opt.footprint_period_ns)) {
    t_viewed = t;
    if (phase == Phase::kTracking) {
      block.steps.push_back({MapperBlock::Kind::kFootprint, block.events.size(), R_w_c, Eigen::Vector3d::Zero(), 0,
                             mapping::GradientMosaic::ReconstructMode::kAuto, 0});
    } else {
      mapper.mark_footprint(R_w_c);
    }
  }
}

mapping::GradientMosaic::ReconstructMode MosaicPipeline::Impl::next_reconstruct_mode() {
  const bool full = result.stats.reconstructions % opt.full_reconstruct_every == 0;
  ++result.stats.reconstructions;
  return full ? mapping::GradientMosaic::ReconstructMode::kFull : mapping::GradientMosaic::ReconstructMode::kAuto;
}

// ---- tracking and mapping ----------------------------------------------------------------------

// kOdometryParticleFilter, events only: the contrast-maximisation windows after the tracked events
// until one's middle is after t_now, each rate given to the filter as a gyro sample at its
// window's middle (the filter interpolates linearly between them). False while a window may still
// get events.
bool MosaicPipeline::Impl::odometry_ahead(int64_t t_now) {
  while (odo_mid_t <= t_now) {
    const size_t i0 = head + odo_ahead;
    const size_t n = pending.size() - i0;
    if (n == 0) return finishing;  // the data's end: the last rate holds
    const Event* ev = pending.data() + i0;
    const int64_t tw0 = ev[0].t_ns;
    size_t j = 0;
    int64_t tw1 = 0;
    if (!cmax_window(ev, n, tw0, INT64_MAX, &j, &tw1)) return false;
    bool still = false;
    if (cmax_rate(ev, j, tw0, tw1, j == n, &still)) {
      ++result.stats.odometry.windows;
      if (still) ++result.stats.odometry.still_windows;
    } else
      ++result.stats.odometry.short_windows;
    odo_mid_t = tw0 + (tw1 - tw0) / 2;
    odo_ahead += j;
    pf->add_gyro(odo_mid_t, omega_c);
  }
  return true;
}

// Processes one particle-filter batch when its events (and IMU) are complete; false when waiting.
bool MosaicPipeline::Impl::tracking_step() {
  const size_t batch = static_cast<size_t>(opt.tracker.batch_size);
  const size_t n = std::min(available(), batch);
  if (n == 0 || (n < batch && !finishing)) return false;
  const Event* ev = pending.data() + head;
  const int64_t t_now = ev[n - 1].t_ns;
  if (!imu_ready(t_now)) return false;
  if (!opt.use_gyro && opt.tracker_method == MosaicTracker::kOdometryParticleFilter && !odometry_ahead(t_now))
    return false;
  if (opt.use_gyro) {
    if (!imu_started) {
      // The last sample at or before the tracking start.
      const int64_t t_track0 = result.stats.bootstrap.t_end_ns;
      while (next_imu < imu.size() && imu[next_imu].t_ns - shift <= t_track0) ++next_imu;
      if (next_imu > 0) --next_imu;
      imu_started = true;
    }
    // Every sample up to the batch's end and the first one after it (the rate is interpolated).
    for (bool after = false; next_imu < imu.size() && !after; ++next_imu) {
      after = imu[next_imu].t_ns - shift > t_now;
      pf->add_gyro(imu[next_imu].t_ns - shift, frontend::RotationParticleFilter::camera_rate_from_imu(imu[next_imu], q_c_b));
    }
    if (next_imu >= 4096) {  // the filter has every sample before next_imu
      imu.erase(imu.begin(), imu.begin() + static_cast<std::ptrdiff_t>(next_imu));
      next_imu = 0;
    }
  }
  pf->update(ev, n, view);
  pf->flush(view);
  if (!opt.use_gyro && opt.failure_global_relocalize && opt.tracker.probe_every_batches > 0) remember(ev, n);
  watch_quality(t_now, n);
  const Eigen::Matrix3d R_pf = pf->mean().toRotationMatrix();
  const Eigen::Vector3d w_c = pf->angular_velocity_c();
  const int64_t t_pf = pf->time_ns();
  if (lost && opt.failure_freeze_map) {
    result.stats.events_unmapped_lost += static_cast<int64_t>(n);
  } else {
    block.events.insert(block.events.end(), ev, ev + n);
    Eigen::Matrix3d R_map = R_pf;
    Eigen::Vector3d w_map = w_c;
    if (ref_for_mapping) {
      const std::optional<Eigen::Matrix3d> Ra = boot_ref_at(t_pf - 1'000'000), Rb = boot_ref_at(t_pf + 1'000'000),
                                           Rt = boot_ref_at(t_pf);
      if (Ra && Rb && Rt) {
        R_map = *Rt;
        w_map = calib::so3_log(Ra->transpose() * *Rb) / 2e-3;
      }
    }
    block.steps.push_back({MapperBlock::Kind::kEvents, block.events.size(), R_map, w_map, t_pf,
                           mapping::GradientMosaic::ReconstructMode::kAuto, 0});
  }
  if (opt.failure_rollback && !lost && opt.tracker.probe_every_batches > 0 &&
      (cp_times.empty() || t_now - cp_times.back() >= opt.failure_checkpoint_period_ns)) {
    block.steps.push_back({MapperBlock::Kind::kCheckpoint, block.events.size(), Eigen::Matrix3d::Identity(),
                           Eigen::Vector3d::Zero(), t_now, mapping::GradientMosaic::ReconstructMode::kAuto, 0});
    cp_times.push_back(t_now);
    while (cp_times.size() > static_cast<size_t>(opt.failure_checkpoints)) cp_times.pop_front();
  }
  record(t_pf, R_pf);
  if (on_track) {
    // The particles' spread about their mean, in the mean's right tangent.
    const Eigen::Quaterniond mean = pf->mean();
    const std::vector<Eigen::Quaterniond>& particles = pf->particles();
    const std::vector<double> w = pf->weights();
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    double total = 0;
    for (size_t i = 0; i < particles.size() && i < w.size(); ++i) {
      const Eigen::Vector3d d = calib::so3_log(Eigen::Quaterniond(mean.conjugate() * particles[i]));
      cov += w[i] * d * d.transpose();
      total += w[i];
    }
    if (total > 0) cov /= total;
    on_track(t_pf, mean, cov, lost);
  }
  head += n;
  odo_ahead = odo_ahead > n ? odo_ahead - n : 0;
  processed += static_cast<int64_t>(n);
  // The tracker switches to a finished reconstruction once its latency has passed.
  if (recs_in_use < recs_submitted && processed - rec_point >= opt.reconstruct_latency_events) use_reconstruction();
  if (processed - rec_point >= opt.reconstruct_events || t_now - rec_t >= opt.reconstruct_period_ns) {
    if (recs_in_use < recs_submitted) use_reconstruction();  // one reconstruction in flight at most
    block.steps.push_back({MapperBlock::Kind::kReconstruct, block.events.size(), Eigen::Matrix3d::Identity(),
                           Eigen::Vector3d::Zero(), 0, next_reconstruct_mode(), 1 - front});
    queue.submit(&block);
    ++recs_submitted;
    rec_point = processed;
    rec_t = t_now;
    if (opt.reconstruct_latency_events == 0) use_reconstruction();
  } else if (block.events.size() >= kMapperBlockEvents) {
    queue.submit(&block);
  }
  if (t_now >= next_snap) {
    if (on_snapshot) on_snapshot(t_now, map_snapshot(mapper.maps[front], opt.mosaic.width, opt.mosaic.height));
    ++result.stats.snapshots;
    next_snap = t_now + opt.snapshot_period_ns;
  }
  return true;
}

// Waits for the oldest reconstruction not yet in use and switches the tracker's map to it.
void MosaicPipeline::Impl::use_reconstruction() {
  queue.submit(&block);
  queue.wait_reconstructions(recs_in_use + 1);
  ++recs_in_use;
  front = 1 - front;
  if (oracle_map.empty()) view.data = mapper.maps[front].data();
}

void MosaicPipeline::Impl::process() {
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

MosaicPipeline::MosaicPipeline(const MosaicPipelineOptions& options, const calib::CameraCalibration& camera)
    : options_(checked(options)), impl_(std::make_unique<Impl>(options_, camera)) {}

MosaicPipeline::~MosaicPipeline() = default;

void MosaicPipeline::set_snapshot_callback(SnapshotCallback callback) { impl_->on_snapshot = std::move(callback); }
void MosaicPipeline::set_track_callback(TrackCallback callback) { impl_->on_track = std::move(callback); }

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

void MosaicPipeline::set_bootstrap_reference(RotationReference R_w_b_at) { impl_->boot_ref = std::move(R_w_b_at); }

void MosaicPipeline::set_reference_for_mapping(bool on) { impl_->ref_for_mapping = on; }

void MosaicPipeline::set_tracker_map_reference(MapReference map_at_start) { impl_->map_ref = std::move(map_at_start); }

void MosaicPipeline::add_events(EventSpan events) {
  Impl& m = *impl_;
  if (m.finished) throw std::logic_error("MosaicPipeline::add_events after finish()");
  if (events.empty()) return;
  MosaicStats& st = m.result.stats;
  if (m.phase == Impl::Phase::kStart) {
    m.t0 = events.front().t_ns;
    const bool odometry = options_.tracker_method == MosaicTracker::kOdometry || options_.tracker_method == MosaicTracker::kCmaxSlam;
    m.t_boot = odometry ? INT64_MAX : m.t0 + options_.bootstrap_ns;
    if (options_.tracker_method == MosaicTracker::kCmaxSlam) {
      backend::CmaxSlamOptions c = options_.cmax_slam;
      c.panorama_width = options_.mosaic.width;
      c.panorama_height = options_.mosaic.height;
      m.slam = std::make_unique<backend::CmaxSlam>(c, m.t0, m.R);
    }
    st.t_first_event_ns = m.t0;
    m.mapper.collect_segments = options_.calibrate_contrast;
    if (!m.slam) m.record(m.t0, m.R);  // kCmaxSlam: knot 0, once final
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
  m.queue.submit(&m.block);
  m.queue.drain();
  r.stats.events_mapped = m.mapper.events_mapped;
  r.reconstruction = m.mapper.mosaic.reconstruct(mapping::GradientMosaic::ReconstructMode::kFull, m.opt.output_weighting);
  if (m.pf) r.stats.tracker = m.pf->stats();
  if (m.slam) {
    r.stats.cmax_slam = m.slam->stats();
    r.event_map = m.slam->event_map();
  }
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
