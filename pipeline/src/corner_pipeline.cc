#include "evio/pipeline/corner_pipeline.h"

#include <stdexcept>

namespace evio::pipeline {

bool CornerPipelineOptions::Validate(std::string* why) const {
  std::string w;
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!refractory.Validate(&w)) return fail("refractory: " + w);
  if (!background_activity.Validate(&w)) return fail("background_activity: " + w);
  if (!efast.Validate(&w)) return fail("efast: " + w);
  if (!tracker.Validate(&w)) return fail("tracker: " + w);
  if (!dart.Validate(&w)) return fail("dart: " + w);
  return true;
}

namespace {
const CornerPipelineOptions& checked(const CornerPipelineOptions& o, int width, int height) {
  std::string why;
  if (!o.Validate(&why)) throw std::invalid_argument("CornerPipeline: " + why);
  if (width <= 0 || height <= 0) throw std::invalid_argument("CornerPipeline: the sensor size must be positive");
  return o;
}
}  // namespace

CornerPipeline::CornerPipeline(const CornerPipelineOptions& options, int width, int height,
                               const std::optional<calib::PinholeCamera>& camera)
    : o_(checked(options, width, height)),
      width_(width),
      height_(height),
      refractory_(width, height, options.refractory),
      background_(width, height, options.background_activity),
      detector_(width, height, options.efast) {
  if (camera) undistorter_ = std::make_unique<frontend::EventUndistorter>(*camera);
  if (o_.tracks) tracker_ = std::make_unique<frontend::CornerTracker>(width, height, o_.tracker);
  if (o_.tracks && o_.descriptors) dart_ = std::make_unique<frontend::DartExtractor>(o_.dart);
}

CornerPipeline::~CornerPipeline() = default;

bool CornerPipeline::process(const Event& e) {
  ++stats_.events;
  if (e.x >= width_ || e.y >= height_) {
    ++stats_.outside;
    return false;
  }
  if (undistorter_ && !undistorter_->valid(e.x, e.y)) {
    ++stats_.not_undistortable;
    return false;
  }
  if (o_.refractory_enabled && !refractory_.accept(e)) return false;
  if (o_.background_activity_enabled && !background_.accept(e)) return false;
  if (!detector_.process(e)) return false;
  ++stats_.corners;
  if (tracker_) {
    const bool has = dart_ && dart_->compute(detector_.sae(), e.x, e.y, e.t_ns, e.polarity, &descriptor_);
    stats_.descriptors += has ? 1 : 0;
    tracker_->add(e, has ? &descriptor_ : nullptr);
  }
  return true;
}

std::vector<frontend::CornerTrack> CornerPipeline::take_finished_tracks() {
  return tracker_ ? tracker_->take_finished() : std::vector<frontend::CornerTrack>{};
}

std::vector<frontend::CornerTrack> CornerPipeline::finish() {
  return tracker_ ? tracker_->finish() : std::vector<frontend::CornerTrack>{};
}

std::optional<int64_t> CornerPipeline::refractory_passed() const {
  if (!o_.refractory_enabled) return std::nullopt;
  return static_cast<int64_t>(refractory_.stats().passed);
}

std::optional<int64_t> CornerPipeline::background_activity_passed() const {
  if (!o_.background_activity_enabled) return std::nullopt;
  return static_cast<int64_t>(background_.stats().passed);
}

}  // namespace evio::pipeline
