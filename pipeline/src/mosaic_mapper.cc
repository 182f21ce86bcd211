#include "mosaic_mapper.h"

#include <algorithm>
#include <utility>

namespace evio::pipeline::internal {

void Mapper::checkpoint(int64_t t) {
  checkpoints.push_back({t, mosaic.checkpoint()});
  while (checkpoints.size() > static_cast<size_t>(opt.failure_checkpoints)) checkpoints.pop_front();
}

void Mapper::restore_before(int64_t t) {
  while (!checkpoints.empty() && checkpoints.back().t > t) checkpoints.pop_back();
  if (checkpoints.empty()) return;
  mosaic.restore(checkpoints.back().state);
  std::fill(last_t.begin(), last_t.end(), INT64_MIN);
}

void Mapper::map_events(const Event* ev, size_t n, const Eigen::Matrix3d& R_w_c, const Eigen::Vector3d& w_c, int64_t t_ref) {
  const Eigen::Matrix3f R = R_w_c.cast<float>();
  const Eigen::Vector3f w = w_c.cast<float>();
  for (size_t k = 0; k < n; ++k) map_event(ev[k], R, w, static_cast<float>(static_cast<double>(ev[k].t_ns - t_ref) * 1e-9));
}

// The camera's field of view at R_w_c on the mosaic, for the weighted solve's viewed-but-event-free
// texels (GradientMosaicOptions::viewed_edge_weight): the bearings of every third sensor pixel
// in both directions (the last row and column included), each marking its 4 x 4 nearest texels.
// At DAVIS240C (f = 200 px) and 1024 texels per turn, 3 sensor px are 2.4 texels on the equator
// and 4 texels at 53 deg latitude, the spacing mark_viewed covers without gaps.
void Mapper::mark_footprint(const Eigen::Matrix3d& R_w_c) {
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

void Mapper::reconstruct(mapping::GradientMosaic::ReconstructMode mode, int target) {
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

void MapperQueue::submit(MapperBlock* block) {
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

void MapperQueue::wait_reconstructions(int64_t n) {
  if (!threaded_) return;
  std::unique_lock<std::mutex> lock(mutex_);
  cv_done_.wait(lock, [&] { return reconstructions_done_ >= n || error_; });
  if (error_) std::rethrow_exception(error_);
}

void MapperQueue::drain() {
  if (!threaded_) return;
  std::unique_lock<std::mutex> lock(mutex_);
  cv_done_.wait(lock, [&] { return finished_ == submitted_ || error_; });
  if (error_) std::rethrow_exception(error_);
}

void MapperQueue::stop() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
    cv_work_.notify_one();
  }
  if (worker_.joinable()) worker_.join();
}

void MapperQueue::run(const MapperBlock& b) {
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

void MapperQueue::loop() {
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

}  // namespace evio::pipeline::internal
