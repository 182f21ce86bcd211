// The mosaic pipeline's mapping half (internal to evio::pipeline; MosaicPipeline in
// mosaic_pipeline.h): the pixel-wise EKF gradient mosaic (Kim et al., BMVC 2014;
// mapping::GradientMosaic) fed by events under given rotations, with its checkpoints, the camera's
// footprint and the tracker's double-buffered reconstructions (Mapper); the mapper steps of the
// tracking phase in tracker order (MapperBlock), run on the caller's thread or on one worker
// thread with the same results (MapperQueue).
#pragma once

#include <climits>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

#include <Eigen/Core>

#include "evio/calib/equirectangular.h"
#include "evio/calib/fast_math.h"
#include "evio/frontend/event_filters.h"
#include "evio/mapping/gradient_mosaic.h"
#include "evio/pipeline/mosaic_pipeline.h"
#include "evio/sensors/measurements.h"

namespace evio::pipeline::internal {

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
  void checkpoint(int64_t t);
  // Back to the newest checkpoint at or before t (none: nothing changes); every pixel's path
  // starts anew.
  void restore_before(int64_t t);

  // The tracker's maps: maps[front] is read by the tracker, a reconstruction is written into the
  // other one after copying over it the region of the previous reconstruction (which only the
  // front has).
  std::vector<float> maps[2];
  mapping::PixelRect last_region{0, 0, 0, 0};

  // The event's direction is R_w_c (b + dt w_c x b): R_w_c at a nearby time, rotated to the
  // event's time to first order (dt |w_c| is a few mrad at most within a particle-filter batch).
  // Single precision and calib::fast_atan2 for the projection (0.002 texel of the double one).
  // Defined here: called per event by the bootstrap too.
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

  void map_events(const Event* ev, size_t n, const Eigen::Matrix3d& R_w_c, const Eigen::Vector3d& w_c, int64_t t_ref);

  // The camera's field of view at R_w_c on the mosaic, for the weighted solve's viewed-but-event-free
  // texels (GradientMosaicOptions::viewed_edge_weight); see the definition for the sampling.
  void mark_footprint(const Eigen::Matrix3d& R_w_c);

  // A reconstruction into maps[target] (the bootstrap's: into both, whole).
  void reconstruct(mapping::GradientMosaic::ReconstructMode mode, int target);
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
// thread (threads = 2). wait_reconstructions() blocks until a number of kReconstruct steps has
// finished, drain() until every submitted block has (both rethrow a worker exception).
class MapperQueue {
 public:
  MapperQueue(Mapper* mapper, bool threaded) : mapper_(mapper), threaded_(threaded) {}
  ~MapperQueue() { stop(); }

  void submit(MapperBlock* block);
  // Blocks until at least n reconstructions are done.
  void wait_reconstructions(int64_t n);
  // Blocks until every submitted block has run.
  void drain();
  void stop();

 private:
  void run(const MapperBlock& b);
  void loop();

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

}  // namespace evio::pipeline::internal
