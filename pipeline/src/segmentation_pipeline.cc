#include "evio/pipeline/segmentation_pipeline.h"

#include <algorithm>
#include <chrono>
#include <stdexcept>

namespace evio::pipeline {

bool SegmentationPipelineOptions::Validate(std::string* why) const {
  std::string w;
  if (!window.Validate(&w)) {
    if (why) *why = "window: " + w;
    return false;
  }
  if (!segmentation.Validate(&w)) {
    if (why) *why = "segmentation: " + w;
    return false;
  }
  return true;
}

SegmentationPipeline::SegmentationPipeline(const SegmentationPipelineOptions& options, int width, int height,
                                           const std::optional<calib::PinholeCamera>& camera)
    : options_(options) {
  std::string why;
  if (!options_.Validate(&why)) throw std::invalid_argument("segmentation pipeline: " + why);
  for (mapping::WarpModel m : options_.segmentation.models)
    if ((m == mapping::WarpModel::kRotation || m == mapping::WarpModel::kSixDof) && !camera)
      throw std::invalid_argument(std::string("segmentation pipeline: the ") + mapping::warp_model_name(m) +
                                  " model needs a camera calibration (its pinhole)");
  windower_ = std::make_unique<CmaxWindower>(options_.window, width, height, camera, options_.segmentation.cmax.geometry);
  mapping::SegmentationOptions s = options_.segmentation;
  s.cmax.width = windower_->width();
  s.cmax.height = windower_->height();
  s.cmax.geometry = windower_->geometry();
  options_.segmentation = s;
  segmenter_ = std::make_unique<mapping::MotionSegmenter>(s);
}

SegmentationPipeline::~SegmentationPipeline() = default;

bool SegmentationPipeline::process(const SubpixelEvent& e) {
  if (!windower_->process(e)) return false;
  run(windower_->take());
  return true;
}

void SegmentationPipeline::finish() {
  windower_->finish();
  run(windower_->take());
}

std::vector<SegmentationWindow> SegmentationPipeline::take_windows() {
  std::vector<SegmentationWindow> out;
  out.swap(done_);
  return out;
}

void SegmentationPipeline::run(std::vector<CmaxWindow> windows) {
  using clock = std::chrono::steady_clock;
  for (CmaxWindow& cw : windows) {
    const auto c0 = clock::now();
    const bool warm = options_.warm_start && !previous_.empty();
    mapping::SegmentationResult r = segmenter_->segment(cw.events, warm ? &previous_ : nullptr, &stats_.next_id);
    SegmentationWindow w;
    w.time_ms = std::chrono::duration<double, std::milli>(clock::now() - c0).count();
    w.index = cw.index;
    w.t_start_ns = cw.t_start_ns, w.t_end_ns = cw.t_end_ns, w.t_ref_ns = cw.t_ref_ns;
    w.events = static_cast<int64_t>(cw.events.size());
    w.count_steps = r.count_steps;
    w.alternations = r.alternations;
    w.evaluations = r.evaluations;
    w.input_begin = cw.input_begin, w.input_end = cw.input_end;
    if (options_.keep_iwe) {
      const mapping::SegmentationOptions& so = segmenter_->options();
      for (const mapping::SegmentCluster& c : r.clusters) {
        std::vector<uint32_t> mine;
        for (size_t k = 0; k < r.labels.size(); ++k)
          if (r.labels[k] == c.id) mine.push_back(static_cast<uint32_t>(k));
        mapping::CmaxOptions o = so.cmax;
        o.model = c.model;
        mapping::ContrastMaximizer cm(o);
        w.iwe.push_back(cm.iwe(cw.events.select(mine), c.params, nullptr, false));
      }
      mapping::ContrastMaximizer cm(so.cmax);
      w.iwe_zero = cm.iwe(cw.events, Eigen::VectorXd::Zero(mapping::warp_dof(so.cmax.model)), nullptr, false);
    }
    for (int l : r.labels) (l >= 0 ? stats_.events_labelled : stats_.events_noise)++;
    w.labels = std::move(r.labels);
    w.input_index = std::move(cw.input_index);
    w.clusters = r.clusters;
    previous_ = std::move(r.clusters);
    ++stats_.windows;
    stats_.alternations += w.alternations;
    stats_.evaluations += w.evaluations;
    stats_.time_ms += w.time_ms;
    stats_.max_window_ms = std::max(stats_.max_window_ms, w.time_ms);
    done_.push_back(std::move(w));
  }
}

}  // namespace evio::pipeline
