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
  if (!(model_gain_per_parameter >= 0)) return fail("model_gain_per_parameter must be >= 0");
  return true;
}

namespace {

const CmaxMotionPipelineOptions& checked(const CmaxMotionPipelineOptions& o,
                                         const std::optional<calib::PinholeCamera>& camera) {
  std::string why;
  if (!o.Validate(&why)) throw std::invalid_argument("CmaxMotionPipeline: " + why);
  for (mapping::WarpModel m : o.models.empty() ? std::vector<mapping::WarpModel>{o.cmax.model} : o.models) {
    const bool three_d = m == mapping::WarpModel::kRotation || m == mapping::WarpModel::kSixDof;
    if (three_d && !camera)
      throw std::invalid_argument(std::string("CmaxMotionPipeline: the ") + mapping::warp_model_name(m) +
                                  " model needs a camera calibration (its pinhole)");
  }
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
  // Model selection: one objective for every candidate, so that their values compare.
  if (!o_.models.empty() && c.objective == mapping::CmaxObjective::kAuto)
    c.objective = mapping::CmaxObjective::kNormalizedGradientMagnitude;
  models_ = o_.models.empty() ? std::vector<mapping::WarpModel>{c.model} : mapping::sort_warp_models(o_.models);
  c.model = models_.front();
  o_.cmax = c;
  for (mapping::WarpModel m : models_) {
    Fitter f;
    mapping::CmaxOptions cm = c;
    cm.model = m;
    f.cold = std::make_unique<mapping::ContrastMaximizer>(cm);
    if (o_.warm_pyramid_levels > 0) cm.pyramid_levels = o_.warm_pyramid_levels;
    f.warm = std::make_unique<mapping::ContrastMaximizer>(cm);
    fitters_.push_back(std::move(f));
  }
  stats_.chosen.assign(models_.size(), 0);
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
    // Each candidate fitted, warm-started from its own previous window.
    std::vector<mapping::CmaxResult> results;
    std::vector<bool> warm_started, reset;
    for (size_t i = 0; i < models_.size(); ++i) {
      Fitter& f = fitters_[i];
      const bool warm = o_.warm_start && f.previous.has_value();
      mapping::CmaxResult r;
      bool was_reset = false;
      if (warm) {
        // The previous motion carried to this window's reference time (an accelerated model's
        // velocity moves on by a dt; the others are unchanged).
        r = f.warm->maximize(ev, mapping::warp_params_at(models_[i], *f.previous, (cw.t_ref_ns - f.previous_t_ref_ns) * 1e-9));
        if (r.objective_init < r.objective_zero) {  // the previous motion no longer fits: start over from zero
          mapping::CmaxResult c = f.cold->maximize(ev);
          c.iterations += r.iterations;
          c.evaluations += r.evaluations;
          r = std::move(c);
          was_reset = true;
        }
      } else {
        r = f.cold->maximize(ev);
      }
      if (r.params.allFinite()) f.previous = r.params, f.previous_t_ref_ns = cw.t_ref_ns;
      results.push_back(std::move(r));
      warm_started.push_back(warm);
      reset.push_back(was_reset);
    }
    size_t best = 0;
    if (!o_.models.empty()) {
      for (size_t i = 0; i < models_.size(); ++i) {
        mapping::ModelTrial t;
        t.model = models_[i];
        t.params = results[i].params;
        t.objective = results[i].objective;
        w.trials.push_back(t);
      }
      best = mapping::choose_warp_model(&w.trials, o_.model_gain_per_parameter);
      ++stats_.chosen[best];
    }
    const mapping::CmaxResult& r = results[best];
    const bool warm = warm_started[best];
    w.reset = reset[best];
    w.time_ms = std::chrono::duration<double, std::milli>(clock::now() - c0).count();

    w.index = cw.index;
    w.t_start_ns = cw.t_start_ns;
    w.t_end_ns = cw.t_end_ns;
    w.t_ref_ns = cw.t_ref_ns;
    w.events = static_cast<int64_t>(ev.size());
    w.model = models_[best];
    w.params = r.params;
    w.objective_zero = r.objective_zero;
    w.objective = r.objective;
    for (const mapping::CmaxResult& ri : results) w.iterations += ri.iterations, w.evaluations += ri.evaluations;
    w.warm_started = warm;
    w.stop = r.stop;
    if (o_.keep_iwe) {
      w.iwe_zero = fitters_[best].cold->iwe(ev, Eigen::VectorXd::Zero(mapping::warp_dof(w.model)), nullptr, false);
      w.iwe = fitters_[best].cold->iwe(ev, w.params, nullptr, false);
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
