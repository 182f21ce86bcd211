#include "evio/pipeline/cmax_motion_pipeline.h"

#include <chrono>
#include <cmath>
#include <stdexcept>

namespace evio::pipeline {

bool CmaxMotionPipelineOptions::Validate(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  std::string w;
  if (!cmax.Validate(&w)) return fail("cmax: " + w);
  if (!window.Validate(&w)) return fail("window: " + w);
  if (warm_pyramid_levels < 0 || warm_pyramid_levels > 8) return fail("warm_pyramid_levels must be in [0, 8] (0: cmax.pyramid_levels)");
  return true;
}

namespace {

const CmaxMotionPipelineOptions& checked(const CmaxMotionPipelineOptions& o,
                                         const std::optional<calib::PinholeCamera>& camera) {
  std::string why;
  if (!o.Validate(&why)) throw std::invalid_argument("CmaxMotionPipeline: " + why);
  const bool three_d = o.cmax.model == mapping::WarpModel::kRotation || o.cmax.model == mapping::WarpModel::kSixDof;
  if (three_d && !camera)
    throw std::invalid_argument(std::string("CmaxMotionPipeline: the ") + mapping::warp_model_name(o.cmax.model) +
                                " model needs a camera calibration (its pinhole)");
  return o;
}

}  // namespace

CmaxMotionPipeline::CmaxMotionPipeline(const CmaxMotionPipelineOptions& options, int width, int height,
                                       const std::optional<calib::PinholeCamera>& camera)
    : o_(checked(options, camera)) {
  windower_ = std::make_unique<CmaxWindower>(o_.window, width, height, camera, o_.cmax.geometry);
  mapping::CmaxOptions c = o_.cmax;
  c.width = windower_->width();
  c.height = windower_->height();
  c.geometry = windower_->geometry();
  o_.cmax = c;
  cold_ = std::make_unique<mapping::ContrastMaximizer>(c);
  mapping::CmaxOptions cw = c;
  if (o_.warm_pyramid_levels > 0) cw.pyramid_levels = o_.warm_pyramid_levels;
  warm_ = std::make_unique<mapping::ContrastMaximizer>(cw);
}

CmaxMotionPipeline::~CmaxMotionPipeline() = default;

bool CmaxMotionPipeline::process(const SubpixelEvent& e) {
  if (!windower_->process(e)) return false;
  estimate(windower_->take());
  return true;
}

void CmaxMotionPipeline::finish() {
  windower_->finish();
  estimate(windower_->take());
}

std::vector<CmaxMotionWindow> CmaxMotionPipeline::take_windows() {
  std::vector<CmaxMotionWindow> out;
  out.swap(done_);
  return out;
}

const CmaxMotionStats& CmaxMotionPipeline::stats() const {
  const CmaxWindowStats& ws = windower_->stats();
  stats_.events = ws.events;
  stats_.events_dropped = ws.events_dropped;
  stats_.windows_skipped = ws.windows_skipped;
  return stats_;
}

void CmaxMotionPipeline::estimate(std::vector<CmaxWindow> windows) {
  using clock = std::chrono::steady_clock;
  for (CmaxWindow& cw : windows) {
    const auto c0 = clock::now();
    mapping::CmaxEvents& ev = cw.events;
    CmaxMotionWindow w;
    const bool warm = o_.warm_start && previous_.has_value();
    mapping::CmaxResult r;
    if (warm) {
      // The previous motion carried to this window's reference time (an accelerated model's
      // velocity moves on by a dt; the others are unchanged).
      r = warm_->maximize(ev, mapping::warp_params_at(o_.cmax.model, *previous_, (cw.t_ref_ns - previous_t_ref_ns_) * 1e-9));
      if (r.objective_init < r.objective_zero) {  // the previous motion no longer fits: start over from zero
        mapping::CmaxResult c = cold_->maximize(ev);
        c.iterations += r.iterations;
        c.evaluations += r.evaluations;
        r = std::move(c);
        w.reset = true;
      }
    } else {
      r = cold_->maximize(ev);
    }
    w.time_ms = std::chrono::duration<double, std::milli>(clock::now() - c0).count();
    if (r.params.allFinite()) previous_ = r.params, previous_t_ref_ns_ = cw.t_ref_ns;

    w.index = cw.index;
    w.t_start_ns = cw.t_start_ns;
    w.t_end_ns = cw.t_end_ns;
    w.t_ref_ns = cw.t_ref_ns;
    w.events = static_cast<int64_t>(ev.size());
    w.model = o_.cmax.model;
    w.params = r.params;
    w.objective_zero = r.objective_zero;
    w.objective = r.objective;
    w.iterations = r.iterations;
    w.evaluations = r.evaluations;
    w.warm_started = warm;
    w.stop = r.stop;
    if (o_.keep_iwe) {
      w.iwe_zero = cold_->iwe(ev, Eigen::VectorXd::Zero(mapping::warp_dof(w.model)), nullptr, false);
      w.iwe = cold_->iwe(ev, w.params, nullptr, false);
    }
    if (o_.keep_events) w.prepared = std::move(ev);
    ++stats_.windows;
    stats_.events_used += w.events;
    stats_.warm_starts += warm ? 1 : 0;
    stats_.resets += w.reset ? 1 : 0;
    stats_.iterations += w.iterations;
    stats_.evaluations += w.evaluations;
    stats_.time_ms += w.time_ms;
    done_.push_back(std::move(w));
  }
}

}  // namespace evio::pipeline
