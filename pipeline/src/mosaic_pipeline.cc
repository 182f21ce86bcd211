#include "evio/pipeline/mosaic_pipeline.h"

#include <algorithm>
#include <climits>
#include <cmath>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <exception>
#include <limits>
#include <mutex>
#include <random>
#include <stdexcept>
#include <thread>
#include <utility>

#include "evio/calib/equirectangular.h"
#include "evio/calib/fast_math.h"
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

// The mapping half: the gradient EKF mosaic fed by events under given rotations, the camera's
// footprint for the weighted solve, and the tracker's reconstructions (double-buffered maps).
// Called directly during the bootstrap; during tracking it runs the steps of MapperBlocks in
// order, on the caller's thread or on its own (MapperQueue).
struct Mapper {
  Mapper(const MosaicPipelineOptions& o, const frontend::EventUndistorter& u, int W, int H)
      : opt(o),
        undistorter(u),
        W(W),
        H(H),
        mosaic(o.mosaic),
        proj(o.mosaic.width, o.mosaic.height),
        last_t(static_cast<size_t>(W) * static_cast<size_t>(H), INT64_MIN),
        last_uv(static_cast<size_t>(W) * static_cast<size_t>(H)) {}

  const MosaicPipelineOptions& opt;
  const frontend::EventUndistorter& undistorter;
  const int W, H;
  mapping::GradientMosaic mosaic;
  const calib::Equirectangular proj;

  // Per sensor pixel the time and mosaic position of its previous event (a path's start).
  std::vector<int64_t> last_t;
  std::vector<Eigen::Vector2f> last_uv;
  struct Segment {
    Eigen::Vector2d from, to;
    int polarity;
  };
  std::vector<Segment> boot_segments;  // calibration samples of the bootstrap
  bool collect_segments = false;
  int64_t events_mapped = 0;

  // Checkpoints of the mosaic's state (failure_rollback), oldest first.
  struct MapCheckpoint {
    int64_t t;
    mapping::GradientMosaic::Checkpoint state;
  };
  std::deque<MapCheckpoint> checkpoints;
  void checkpoint(int64_t t) {
    checkpoints.push_back({t, mosaic.checkpoint()});
    while (checkpoints.size() > static_cast<size_t>(opt.failure_checkpoints)) checkpoints.pop_front();
  }
  // Back to the newest checkpoint at or before t (none: nothing changes); every pixel's path
  // starts anew.
  void restore_before(int64_t t) {
    while (!checkpoints.empty() && checkpoints.back().t > t) checkpoints.pop_back();
    if (checkpoints.empty()) return;
    mosaic.restore(checkpoints.back().state);
    std::fill(last_t.begin(), last_t.end(), INT64_MIN);
  }

  // The tracker's maps: maps[front] is read by the tracker, a reconstruction is written into the
  // other one after copying over it the region of the previous reconstruction (which only the
  // front has).
  std::vector<float> maps[2];
  mapping::PixelRect last_region{0, 0, 0, 0};

  // The event's direction is R_w_c (b + dt w_c x b): R_w_c at a nearby time, rotated to the
  // event's time to first order (dt |w_c| is a few mrad at most within a particle-filter batch).
  // Single precision and calib::fast_atan2 for the projection (0.002 texel of the double one).
  void map_event(const Event& e, const Eigen::Matrix3f& R_w_c, const Eigen::Vector3f& w_c, float dt) {
    if (e.x >= W || e.y >= H || !undistorter.valid(e.x, e.y)) return;
    const size_t p = static_cast<size_t>(e.y) * static_cast<size_t>(W) + e.x;
    const int64_t prev = last_t[p];
    const Eigen::Vector3f& b = undistorter.bearing(e.x, e.y);
    const Eigen::Vector2f uv = calib::fast_equirectangular_project(R_w_c * (b + dt * w_c.cross(b)), proj.width(), proj.height());
    last_t[p] = e.t_ns;
    const Eigen::Vector2f uv_prev = last_uv[p];
    last_uv[p] = uv;
    if (prev == INT64_MIN) return;
    if (mosaic.update_segment(uv_prev.cast<double>(), uv.cast<double>(), static_cast<double>(e.t_ns - prev) * 1e-9,
                              e.polarity) == mapping::MosaicUpdate::kApplied) {
      ++events_mapped;
      if (collect_segments && (events_mapped % opt.calibration_sample_stride) == 0)
        boot_segments.push_back({uv_prev.cast<double>(), uv.cast<double>(), e.polarity});
    }
  }

  void map_events(const Event* ev, size_t n, const Eigen::Matrix3d& R_w_c, const Eigen::Vector3d& w_c, int64_t t_ref) {
    const Eigen::Matrix3f R = R_w_c.cast<float>();
    const Eigen::Vector3f w = w_c.cast<float>();
    for (size_t k = 0; k < n; ++k) map_event(ev[k], R, w, static_cast<float>(static_cast<double>(ev[k].t_ns - t_ref) * 1e-9));
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
        mosaic.mark_viewed(calib::fast_equirectangular_project(R * undistorter.bearing(x, y), proj.width(), proj.height())
                               .cast<double>());
      }
  }

  // A reconstruction into maps[target] (the bootstrap's: into both, whole).
  void reconstruct(mapping::GradientMosaic::ReconstructMode mode, int target) {
    std::vector<float>& dst = maps[target];
    const std::vector<float>& src = maps[1 - target];
    if (dst.size() == src.size() && last_region.width > 0 && last_region.height > 0) {
      const mapping::PixelRect& r = last_region;
      for (int j = std::max(r.y, 0); j < std::min(r.y + r.height, mosaic.height()); ++j) {
        const size_t row = static_cast<size_t>(j) * static_cast<size_t>(mosaic.width());
        for (int t = 0; t < r.width; ++t) {
          const size_t k = row + static_cast<size_t>((((r.x + t) % mosaic.width()) + mosaic.width()) % mosaic.width());
          dst[k] = src[k];
        }
      }
    }
    last_region = mosaic.reconstruct_map(mode, &dst);
  }
};

// A run of mapper steps in tracker order, with the events they map.
struct MapperBlock {
  enum class Kind { kEvents, kFootprint, kReconstruct, kCheckpoint, kRestore };
  struct Step {
    Kind kind;
    size_t end;                 // kEvents: maps events [previous kEvents' end, end)
    Eigen::Matrix3d R_w_c;      // kEvents: the rotation at t_ref; kFootprint: the footprint's rotation
    Eigen::Vector3d w_c;        // kEvents: camera-frame angular velocity, rad/s
    int64_t t_ref;              // kEvents; kCheckpoint: its time; kRestore: the newest checkpoint time allowed
    mapping::GradientMosaic::ReconstructMode mode;  // kReconstruct
    int target;                 // kReconstruct: the map written
  };
  std::vector<Event> events;
  std::vector<Step> steps;
  bool empty() const { return steps.empty(); }
  void clear() {
    events.clear();
    steps.clear();
  }
};

// Runs MapperBlocks on the Mapper in submission order: inline (threads = 1) or on one worker
// thread (threads = 2). reconstructions_done() counts finished kReconstruct steps; wait_for()
// blocks until a count is reached (rethrowing a worker exception).
class MapperQueue {
 public:
  MapperQueue(Mapper* mapper, bool threaded) : mapper_(mapper), threaded_(threaded) {}
  ~MapperQueue() { stop(); }

  void submit(MapperBlock* block) {
    if (block->empty()) return;
    if (!threaded_) {
      run(*block);
      block->clear();
      return;
    }
    std::unique_lock<std::mutex> lock(mutex_);
    if (!worker_.joinable()) worker_ = std::thread([this] { loop(); });
    if (free_.empty()) free_.emplace_back();
    MapperBlock b = std::move(free_.back());
    free_.pop_back();
    std::swap(b, *block);
    block->clear();
    queue_.push_back(std::move(b));
    ++submitted_;
    cv_work_.notify_one();
  }
  // Blocks until at least n reconstructions are done.
  void wait_reconstructions(int64_t n) {
    if (!threaded_) return;
    std::unique_lock<std::mutex> lock(mutex_);
    cv_done_.wait(lock, [&] { return reconstructions_done_ >= n || error_; });
    if (error_) std::rethrow_exception(error_);
  }
  // Blocks until every submitted block has run.
  void drain() {
    if (!threaded_) return;
    std::unique_lock<std::mutex> lock(mutex_);
    cv_done_.wait(lock, [&] { return finished_ == submitted_ || error_; });
    if (error_) std::rethrow_exception(error_);
  }
  void stop() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
      cv_work_.notify_one();
    }
    if (worker_.joinable()) worker_.join();
  }

 private:
  void run(const MapperBlock& b) {
    size_t begin = 0;
    for (const MapperBlock::Step& s : b.steps) {
      switch (s.kind) {
        case MapperBlock::Kind::kEvents:
          mapper_->map_events(b.events.data() + begin, s.end - begin, s.R_w_c, s.w_c, s.t_ref);
          begin = s.end;
          break;
        case MapperBlock::Kind::kFootprint:
          mapper_->mark_footprint(s.R_w_c);
          break;
        case MapperBlock::Kind::kCheckpoint:
          mapper_->checkpoint(s.t_ref);
          break;
        case MapperBlock::Kind::kRestore:
          mapper_->restore_before(s.t_ref);
          break;
        case MapperBlock::Kind::kReconstruct:
          mapper_->reconstruct(s.mode, s.target);
          if (threaded_) {
            std::lock_guard<std::mutex> lock(mutex_);
            ++reconstructions_done_;
            cv_done_.notify_all();
          }
          break;
      }
    }
  }
  void loop() {
    std::unique_lock<std::mutex> lock(mutex_);
    for (;;) {
      cv_work_.wait(lock, [&] { return stop_ || !queue_.empty(); });
      if (queue_.empty()) return;  // stop_ and nothing left
      MapperBlock b = std::move(queue_.front());
      queue_.pop_front();
      lock.unlock();
      try {
        run(b);
      } catch (...) {
        lock.lock();
        error_ = std::current_exception();
        cv_done_.notify_all();
        return;
      }
      b.clear();
      lock.lock();
      free_.push_back(std::move(b));
      ++finished_;
      cv_done_.notify_all();
    }
  }

  Mapper* mapper_;
  const bool threaded_;
  std::thread worker_;
  std::mutex mutex_;
  std::condition_variable cv_work_, cv_done_;
  std::deque<MapperBlock> queue_;
  std::vector<MapperBlock> free_;
  int64_t submitted_ = 0, finished_ = 0, reconstructions_done_ = 0;
  bool stop_ = false;
  std::exception_ptr error_;
};

}  // namespace

// Tracker events per MapperBlock between reconstructions (a block is also closed at each
// reconstruction): the mapper thread is woken about once per this many events.
constexpr size_t kMapperBlockEvents = 4096;

struct MosaicPipeline::Impl {
  Impl(const MosaicPipelineOptions& o, const calib::CameraCalibration& camera)
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

  enum class Phase { kStart, kBootstrap, kTracking };

  const MosaicPipelineOptions& opt;
  const calib::CameraCalibration cal;
  const int W, H;
  const int64_t shift;  // t_imu = t_cam + shift
  const Eigen::Quaterniond q_c_b;
  const frontend::EventUndistorter undistorter;
  Mapper mapper;
  MapperQueue queue;
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

  int64_t t_viewed = INT64_MIN;  // the last mark_footprint

  // Bootstrap.
  Eigen::Matrix3d R = mosaic_initial_camera_rotation();
  Eigen::Vector3d omega_c = Eigen::Vector3d::Zero();
  int64_t t0 = 0, t_boot = 0;
  MosaicPipeline::RotationReference boot_ref;  // diagnostic: bootstrap rotations R_w_b(t)
  bool ref_for_mapping = false;                // diagnostic: boot_ref maps the tracked events too
  MosaicPipeline::MapReference map_ref;        // diagnostic: the tracker's fixed map
  std::vector<float> oracle_map;               // its answer (empty: the reconstructions)
  // R_w_c in the mosaic frame from boot_ref (std::nullopt where it has no answer).
  std::optional<Eigen::Matrix3d> boot_ref_at(int64_t t) const {
    if (!boot_ref) return std::nullopt;
    const auto q0 = boot_ref(t0), q = boot_ref(t);
    if (!q0 || !q) return std::nullopt;
    const Eigen::Matrix3d R_b_c = q_c_b.conjugate().toRotationMatrix();
    return Eigen::Matrix3d(mosaic_initial_camera_rotation() * (q0->toRotationMatrix() * R_b_c).transpose() *
                           (q->toRotationMatrix() * R_b_c));
  }

  // Tracking.
  std::unique_ptr<frontend::RotationParticleFilter> pf;
  frontend::LogIntensityMapView view;
  int front = 0;                       // mapper.maps[front] is the tracker's map
  MapperBlock block;                   // mapper steps not yet submitted
  int64_t rec_point = 0;               // events processed at the last reconstruction's point
  int64_t rec_t = 0;                   // and its time
  int64_t recs_submitted = 0;          // reconstructions of the tracking phase submitted
  int64_t recs_in_use = 0;             // and switched to by the tracker
  int64_t next_snap = INT64_MAX;

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

  // Camera-frame rate at the camera-clock time, linear between the samples around it (held before
  // the first and after the last; zero without any sample). Holding each sample until the next
  // lagged the gyro bootstrap by half a sample period (poster fast: 0.29 deg RMS).
  Eigen::Vector3d gyro_c_at(int64_t t_cam) const {
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

  // ---- trajectory ------------------------------------------------------------------------------

  // A trajectory pose (at most one per trajectory_period_ns) and, with the weighted final solve,
  // the camera's footprint every footprint_period_ns: marked now (bootstrap) or as a mapper step.
  void record(int64_t t, const Eigen::Matrix3d& R_w_c) {
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

  mapping::GradientMosaic::ReconstructMode next_reconstruct_mode() {
    const bool full = result.stats.reconstructions % opt.full_reconstruct_every == 0;
    ++result.stats.reconstructions;
    return full ? mapping::GradientMosaic::ReconstructMode::kFull : mapping::GradientMosaic::ReconstructMode::kAuto;
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
    const std::optional<Eigen::Matrix3d> R_ref0 = boot_ref_at(tw0), R_ref1 = boot_ref_at(tw1);
    const bool use_ref = R_ref0 && R_ref1;
    if (use_ref) {
      omega_c = tw1 > tw0 ? Eigen::Vector3d(calib::so3_log(R_ref0->transpose() * *R_ref1) / (1e-9 * static_cast<double>(tw1 - tw0)))
                          : omega_c;
    } else if (!opt.use_gyro && result.stats.bootstrap.cmax_windows > 0 && tw1 == t_boot &&
               2 * static_cast<int64_t>(j) < opt.bootstrap_window_events && 2 * (tw1 - tw0) < opt.bootstrap_window_ns) {
      // The bootstrap's last window, cut short by its end: too little motion to constrain the rate
      // (boxes_rotation slow 30 s: 1166 events over 0.73 ms gave about 320 deg/s against the true
      // 26; the tracker started from it and was 19 deg off 0.1 s later, then lost). The previous
      // window's rate holds.
      ++result.stats.bootstrap.short_windows;
    } else if (!opt.use_gyro) {
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
    record(tw1, R);
    head += j;
    processed += static_cast<int64_t>(j);
    result.stats.bootstrap.events += static_cast<int64_t>(j);
    return true;
  }

  // The bootstrap mosaic's reconstruction, the tracker's contrast and the particle filter at t_track0.
  void end_bootstrap(int64_t t_track0) {
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

  // ---- tracking failure ---------------------------------------------------------------------------

  bool lost = false;
  int64_t probe_seen_t = INT64_MIN, window_t0 = INT64_MIN;
  double window_sum = 0, quality_sum = 0;
  int64_t window_n = 0, window_events = 0;
  int64_t window_all_events = 0;  // every event of the window's batches
  double rate_mean = 0;           // running mean of window_all_events
  int low_windows = 0;         // consecutive decided windows below the lost level
  int64_t low_since = 0;       // start of the first of them
  std::mt19937_64 relocalize_rng{0x5eed};

  // Collects the tracker's probe contrast; at the end of each failure window decides lost /
  // recovered and re-localises while lost.
  void watch_quality(int64_t t_now, size_t batch_events) {
    if (opt.tracker.probe_every_batches <= 0) return;
    window_all_events += static_cast<int64_t>(batch_events);
    if (window_t0 == INT64_MIN) window_t0 = t_now;
    if (pf->last_probe_t_ns() != probe_seen_t && std::isfinite(pf->last_probe_contrast())) {
      probe_seen_t = pf->last_probe_t_ns();
      window_sum += pf->last_probe_contrast();
      window_events += pf->last_batch_loglik_events();
      ++window_n;
    }
    if (t_now - window_t0 < opt.failure_window_ns) return;
    // Event rate against its running mean (exponential, about 20 windows): a near-still moment.
    const double rate = static_cast<double>(window_all_events);
    const bool moving = rate_mean <= 0 || rate >= opt.failure_min_rate_ratio * rate_mean;
    rate_mean = rate_mean <= 0 ? rate : 0.95 * rate_mean + 0.05 * rate;
    window_all_events = 0;
    if (window_n > 0 && window_events >= opt.failure_min_events && moving) {
      const double q = window_sum / static_cast<double>(window_n);
      MosaicStats& st = result.stats;
      st.quality_min = st.quality_windows == 0 ? q : std::min(st.quality_min, q);
      quality_sum += q;
      ++st.quality_windows;
      st.quality_mean = quality_sum / static_cast<double>(st.quality_windows);
      low_windows = q < opt.failure_lost_contrast ? low_windows + 1 : 0;
      if (low_windows == 1) low_since = window_t0;
      if (!lost && low_windows >= opt.failure_lost_windows) {
        lost = true;
        result.tracking_lost.push_back({low_since, t_now, false, 0});
        log_warning("MosaicPipeline: tracking lost at " + std::to_string(1e-9 * static_cast<double>(low_since)) +
                    " s (probe contrast " + std::to_string(q) + " per event)");
        if (opt.failure_rollback) rollback_map(low_since - opt.failure_window_ns, t_now);
      } else if (lost && q >= opt.failure_recovered_contrast) {
        lost = false;
        result.tracking_lost.back().t_end_ns = t_now;
        result.tracking_lost.back().recovered = true;
      }
      if (lost) {
        result.tracking_lost.back().t_end_ns = t_now;
        const bool jumped = !opt.use_gyro && opt.failure_global_relocalize && global_relocalize(t_now);
        if (!jumped && opt.failure_relocalize_spread_rad > 0 && !opt.use_gyro) relocalize();
      }
    } else if (window_n > 0) {
      ++result.stats.quality_windows_undecided;
      if (lost) result.tracking_lost.back().t_end_ns = t_now;
    }
    window_sum = 0;
    window_events = 0;
    window_n = 0;
    window_t0 = t_now;
  }

  // Spreads the particles around the mean (Gaussian, failure_relocalize_spread_rad per axis),
  // equal weights; their velocities stay.
  void relocalize() {
    std::normal_distribution<double> g(0.0, opt.failure_relocalize_spread_rad);
    const Eigen::Quaterniond m = pf->mean();
    std::vector<Eigen::Quaterniond> p(pf->particles().size());
    for (size_t i = 0; i < p.size(); ++i) {
      const Eigen::Vector3d d(g(relocalize_rng), g(relocalize_rng), g(relocalize_rng));
      p[i] = i == 0 ? m : (m * calib::so3_exp_quat(d)).normalized();
    }
    pf->set_particles(p, std::vector<double>(p.size(), 1.0));
    ++result.tracking_lost.back().relocalizations;
  }

  // Checkpoint times issued to the mapper (mirrors Mapper::checkpoints).
  std::deque<int64_t> cp_times;

  // Rolls the mosaic back to the newest checkpoint at or before t_bound and gives the tracker a
  // full reconstruction of it.
  void rollback_map(int64_t t_bound, int64_t t_now) {
    while (!cp_times.empty() && cp_times.back() > t_bound) cp_times.pop_back();
    if (cp_times.empty()) return;
    result.tracking_lost.back().map_rolled_back_to_ns = cp_times.back();
    block.steps.push_back({MapperBlock::Kind::kRestore, block.events.size(), Eigen::Matrix3d::Identity(),
                           Eigen::Vector3d::Zero(), t_bound, mapping::GradientMosaic::ReconstructMode::kAuto, 0});
    if (recs_in_use < recs_submitted) use_reconstruction();  // one reconstruction in flight at most
    block.steps.push_back({MapperBlock::Kind::kReconstruct, block.events.size(), Eigen::Matrix3d::Identity(),
                           Eigen::Vector3d::Zero(), 0, mapping::GradientMosaic::ReconstructMode::kFull, 1 - front});
    ++result.stats.reconstructions;
    queue.submit(&block);
    ++recs_submitted;
    rec_point = processed;
    rec_t = t_now;
    use_reconstruction();
  }

  // The tracker's most recent events (ring of bootstrap_window_events), for the global search.
  std::vector<Event> recent;
  size_t recent_next = 0;
  int64_t last_global_t = INT64_MIN;
  void remember(const Event* ev, size_t n) {
    const size_t cap = static_cast<size_t>(opt.bootstrap_window_events);
    if (recent.size() < cap) {
      const size_t k = std::min(n, cap - recent.size());
      recent.insert(recent.end(), ev, ev + k);
      ev += k;
      n -= k;
      recent_next = recent.size() % cap;
    }
    for (size_t k = 0; k < n; ++k) {
      recent[recent_next] = ev[k];
      recent_next = (recent_next + 1) % cap;
    }
  }

  // Searches the whole known mosaic for the view of the most recent events (see
  // failure_global_relocalize); true when the particles were moved there.
  bool global_relocalize(int64_t t_now) {
    if (last_global_t != INT64_MIN && t_now - last_global_t < opt.failure_global_period_ns) return false;
    last_global_t = t_now;
    MosaicLostSegment& seg = result.tracking_lost.back();
    ++seg.global_searches;
    // The window: the ring in time order, the events within bootstrap_window_ns of the newest.
    std::vector<Event> win;
    const size_t n = recent.size();
    for (size_t k = 0; k < n; ++k) win.push_back(recent[(recent_next + k) % n]);
    if (win.empty()) return false;
    const int64_t t_ref = win.back().t_ns;
    std::vector<Eigen::Vector3f> b;
    std::vector<int64_t> t;
    for (const Event& e : win) {
      if (t_ref - e.t_ns > opt.bootstrap_window_ns) continue;
      if (e.x >= W || e.y >= H || !undistorter.valid(e.x, e.y)) continue;
      b.push_back(undistorter.bearing(e.x, e.y));
      t.push_back(e.t_ns);
    }
    if (b.size() < 100) return false;
    const Eigen::Vector3d w = mapping::estimate_angular_velocity(b, t, t_ref, pf->angular_velocity_c(), cmax).omega_c;
    for (size_t k = 0; k < b.size(); ++k)
      b[k] = (calib::so3_exp(w * (1e-9 * static_cast<double>(t[k] - t_ref))).cast<float>() * b[k]).eval();
    const mapping::RelocalizationMap rmap(view.data, opt.mosaic.width, opt.mosaic.height, opt.relocalization);
    const mapping::RotationRelocalizationResult r = rmap.search(b);
    if (!r.valid) return false;
    // The estimate at t_ref (the filter is at t_now >= t_ref, within one batch).
    const double current = rmap.score(pf->mean().toRotationMatrix(), b);
    if (!(r.score > opt.failure_global_min_gain * current)) return false;
    pf->reset(Eigen::Quaterniond(r.R_w_c), pf->time_ns());
    pf->set_velocity(w);
    ++seg.global_jumps;
    return true;
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
    head += n;
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
  void use_reconstruction() {
    queue.submit(&block);
    queue.wait_reconstructions(recs_in_use + 1);
    ++recs_in_use;
    front = 1 - front;
    if (oracle_map.empty()) view.data = mapper.maps[front].data();
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
    m.t_boot = m.t0 + options_.bootstrap_ns;
    st.t_first_event_ns = m.t0;
    m.mapper.collect_segments = options_.calibrate_contrast;
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
  m.queue.submit(&m.block);
  m.queue.drain();
  r.stats.events_mapped = m.mapper.events_mapped;
  r.reconstruction = m.mapper.mosaic.reconstruct(mapping::GradientMosaic::ReconstructMode::kFull, m.opt.output_weighting);
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
