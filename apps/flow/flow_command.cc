#include "flow_command.h"

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <ostream>
#include <sstream>

#include "evio/calib/error.h"
#include "evio/calib/json.h"
#include "evio/calib/log.h"
#include "evio/evaluation/angular_velocity_windows.h"
#include "evio/sensors/config_table.h"
#include "evio/sensors/dataset_calibration.h"
#include "evio/sensors/time.h"
#include "evio/sensors/trajectory.h"
#include "cmax_input.h"
#include "evio/mapping/option_tables.h"
#include "option_tables.h"
#include "output_files.h"

namespace evio::apps {
namespace {

namespace fs = std::filesystem;
using yaml_config::Range;
using yaml_config::Table;
using C = FlowConfig;

// The table of `--config` and `--set`: the window, the undistortion and the maximiser's options
// (cmax_table without the keys the camera gives).
const Table<C>& flow_config_table() {
  static const Table<C> table = [] {
    auto self = [](C& c) -> C& { return c; };
    Table<C> window("window settings");
    window.include(cmax_window_table(), &C::window, {"undistortion", "dither_px"})
        .boolean("warm_start", &C::warm_start)
        .integer("warm_pyramid_levels", &C::warm_pyramid_levels, 0, 8)
        .note("warm_pyramid_levels", "0: cmax.pyramid_levels");
    Table<C> cmax("contrast maximisation settings");
    cmax.include(mapping::cmax_table(), &C::cmax, {"width", "height", "fx", "fy", "cx", "cy"});  // those: the camera's
    Table<C> top("flow settings");
    top.boolean("model_selection", &C::model_selection)
        .note("model_selection", "choose the model per window among candidates (--model auto); false: cmax.model")
        .choice_list("candidates", &C::candidates, mapping::warp_model_choices())
        .note("candidates", "model_selection's; rotation and 6dof only with a calibrated camera")
        .number("model_gain_per_parameter", &C::model_gain_per_parameter, Range::kNonNegative, "")
        .note("model_gain_per_parameter", "relative objective gain a richer model needs per extra parameter")
        .section("window", window, self)
        .include(cmax_window_table(), &C::window,
                 {"events", "duration_ms", "max_duration_ms", "min_events"})  // the top-level keys
        .section("cmax", cmax, self)
        .ignored("description")
        .validate();
    return top;
  }();
  return table;
}

// Model selection (--model auto): cfg->models are the candidates the camera allows, the 3-D warps
// (rotation, 6dof) only with a calibrated camera (they need the pinhole); without model selection
// none (cmax.model). Returns the names of the candidates dropped. Throws evio::InputError when none
// is left.
std::vector<std::string> choose_candidates(FlowConfig* cfg, bool calibrated) {
  std::vector<std::string> dropped;
  cfg->models.clear();
  if (!cfg->model_selection) return dropped;
  for (mapping::WarpModel m : cfg->candidates) {
    const bool three_d = m == mapping::WarpModel::kRotation || m == mapping::WarpModel::kSixDof;
    if (three_d && !calibrated) dropped.push_back(mapping::warp_model_name(m));
    else cfg->models.push_back(m);
  }
  if (cfg->models.empty())
    throw InputError("candidates", 0, "no candidate model without a camera calibration",
                     "flow or similarity among the candidates, or --calib");
  return dropped;
}

// The per-window outputs, written as the windows come: motion.csv (the header and columns of
// flow_command.h for `model`: a window's own parameters first, the rest empty), model_selection.csv
// with model selection (every candidate's objective, gain and score), the IWE PNGs before and
// after warping (--png, every png_every-th window); and what the summary and the evaluation need.
class FlowWindowWriter {
 public:
  // candidates: the pipeline's models (model selection), empty for one model. rotation: keep the
  // windows' angular velocities (the one model is rotation).
  FlowWindowWriter(const FlowArgs& args, mapping::WarpModel model, const std::vector<mapping::WarpModel>& candidates,
                   bool signed_iwe, bool rotation)
      : args_(args), dof_(mapping::warp_dof(model)), signed_iwe_(signed_iwe), rotation_(rotation),
        iwe_dir_((fs::path(args.out) / "iwe").string()), gain_sum_(candidates.size(), 0.0),
        score_sum_(candidates.size(), 0.0) {
    if (args.png) fs::create_directories(iwe_dir_);
    csv_.emplace((fs::path(args.out) / "motion.csv").string());
    std::string h = "t_start_s,t_end_s,model";
    for (int i = 0; i < dof_; ++i) h += ",p" + std::to_string(i);
    std::fputs((h + ",contrast_zero,contrast_final,iterations,time_ms\n").c_str(), csv_->get());
    if (candidates.empty()) return;
    selection_csv_.emplace((fs::path(args.out) / "model_selection.csv").string());
    h = "t_start_s,t_end_s,chosen";
    for (mapping::WarpModel m : candidates) {
      const std::string n = mapping::warp_model_name(m);
      h += "," + n + "_objective," + n + "_gain," + n + "_score";
    }
    std::fputs((h + "\n").c_str(), selection_csv_->get());
  }

  void write(const std::vector<pipeline::CmaxMotionWindow>& windows) {
    char t0[32], t1[32];
    for (const pipeline::CmaxMotionWindow& w : windows) {
      *format_seconds(w.t_start_ns, t0) = '\0';
      *format_seconds(w.t_end_ns, t1) = '\0';
      std::fprintf(csv_->get(), "%s,%s,%s", t0, t1, mapping::warp_model_name(w.model));
      for (int i = 0; i < dof_; ++i) {
        if (i < w.params.size()) std::fprintf(csv_->get(), ",%.9g", w.params[i]);
        else std::fputc(',', csv_->get());
      }
      std::fprintf(csv_->get(), ",%.9g,%.9g,%d,%.3f\n", w.objective_zero, w.objective, w.iterations, w.time_ms);
      if (args_.png && w.index % args_.png_every == 0) write_pngs(w);
      if (selection_csv_) {
        std::fprintf(selection_csv_->get(), "%s,%s,%s", t0, t1, mapping::warp_model_name(w.model));
        for (size_t i = 0; i < w.trials.size(); ++i) {
          const mapping::ModelTrial& t = w.trials[i];
          std::fprintf(selection_csv_->get(), ",%.9g,%.9g,%.9g", t.objective, t.gain, t.score);
          gain_sum_[i] += t.gain;
          score_sum_[i] += t.score;
        }
        std::fputc('\n', selection_csv_->get());
      }
      window_ms_.push_back(w.time_ms);
      if (rotation_) rotations_.push_back({w.t_start_ns, w.t_end_ns, w.params.head<3>()});
    }
  }

  void close() {
    csv_->close();
    if (selection_csv_) selection_csv_->close();
  }

  const std::vector<double>& window_ms() const { return window_ms_; }
  const std::vector<evaluation::AngularVelocityWindow>& rotations() const { return rotations_; }
  // Model selection: candidate i's gain and score summed over the windows.
  double gain_sum(size_t i) const { return gain_sum_[i]; }
  double score_sum(size_t i) const { return score_sum_[i]; }
  int64_t pngs() const { return pngs_; }

 private:
  void write_pngs(const pipeline::CmaxMotionWindow& w) {
    const double scale = robust_scale(w.iwe);
    char name[64];
    std::snprintf(name, sizeof(name), "window_%06lld_before.png", static_cast<long long>(w.index));
    write_iwe_png((fs::path(iwe_dir_) / name).string(), w.iwe_zero, scale, signed_iwe_);
    std::snprintf(name, sizeof(name), "window_%06lld_after.png", static_cast<long long>(w.index));
    write_iwe_png((fs::path(iwe_dir_) / name).string(), w.iwe, scale, signed_iwe_);
    pngs_ += 2;
  }

  const FlowArgs& args_;
  const int dof_;
  const bool signed_iwe_, rotation_;
  const std::string iwe_dir_;
  std::optional<TextOut> csv_, selection_csv_;
  std::vector<double> gain_sum_, score_sum_;
  std::vector<double> window_ms_;
  std::vector<evaluation::AngularVelocityWindow> rotations_;
  int64_t pngs_ = 0;
};

// The rotation model's references and their comparison with the windows' angular velocities.
struct RotationEvaluation {
  std::string gt_source;   // where the ground truth came from (empty: none)
  size_t gyro_samples = 0;
  std::string convention;  // how body poses and gyro rates were turned into the camera frame
  evaluation::AngularVelocityWindowsEvaluation result;
};

// The references (the ground truth: --gt, else the dataset's own when it has at least 3 poses; the
// gyro: the dataset's IMU) in the camera frame by the calibration's T_c_b and time shift (none:
// identity), against each window's estimate.
RotationEvaluation evaluate_rotation(const FlowArgs& args, DatasetReader* reader, const DatasetCalibration& found,
                                     const std::vector<evaluation::AngularVelocityWindow>& windows) {
  RotationEvaluation r;
  std::optional<Trajectory> gt;
  if (!args.gt.empty()) {
    gt = read_trajectory(args.gt);
    r.gt_source = args.gt;
  } else if (auto own = reader->read_groundtruth(); own && own->size() >= 3) {
    gt = std::move(own);
    r.gt_source = "the dataset's ground truth";
  }
  const std::vector<ImuSample> imu = reader->read_imu();
  r.gyro_samples = imu.size();
  evaluation::BodyToCamera b2c;
  if (found.camera && found.camera->has_T_c_b) {
    b2c.R_c_b = found.camera->T_c_b.rotation.toRotationMatrix();
    b2c.time_shift_ns = found.camera->time_shift_ns;
    r.convention = "body (IMU) poses and gyro rates, turned into the camera frame with R_c_b of T_c_b from " +
                   found.camera->source + " and read at t_cam + " + std::to_string(b2c.time_shift_ns) + " ns";
  } else {
    r.convention = "no camera-IMU extrinsics in the calibration: the ground truth is taken as the camera's pose (T_w_c) "
                   "and the gyro as measured in the camera frame (R_c_b = identity, no time shift)";
  }
  r.result = evaluation::evaluate_angular_velocity_windows(windows, gt ? &*gt : nullptr, imu, b2c);
  return r;
}

// motion_eval.csv: per window the estimate, the ground truth's and the gyro's rates and the errors.
// A reference that does not cover the window leaves its fields empty: every number written is finite.
void write_motion_eval_csv(const std::string& path, const std::vector<evaluation::AngularVelocityWindow>& windows,
                           const evaluation::AngularVelocityWindowsEvaluation& e) {
  TextOut f(path);
  std::string h = "t_start_s,t_end_s,wx_radps,wy_radps,wz_radps";
  if (e.has_groundtruth) h += ",gt_wx_radps,gt_wy_radps,gt_wz_radps,error_degps";
  if (e.has_gyro) h += ",gyro_wx_radps,gyro_wy_radps,gyro_wz_radps,events_vs_gyro_degps";
  if (e.has_groundtruth && e.has_gyro) h += ",gyro_vs_gt_degps";
  std::fputs((h + "\n").c_str(), f.get());
  char t0[32], t1[32];
  for (size_t k = 0; k < windows.size(); ++k) {
    const Eigen::Vector3d& w = windows[k].estimate;
    const Eigen::Vector3d& g = e.groundtruth[k];
    const Eigen::Vector3d& y = e.gyro[k];
    *format_seconds(windows[k].t_start_ns, t0) = '\0';
    *format_seconds(windows[k].t_end_ns, t1) = '\0';
    std::fprintf(f.get(), "%s,%s,%.9g,%.9g,%.9g", t0, t1, w.x(), w.y(), w.z());
    const bool has_g = g.allFinite(), has_y = y.allFinite();
    if (e.has_groundtruth && has_g)
      std::fprintf(f.get(), ",%.9g,%.9g,%.9g,%.6g", g.x(), g.y(), g.z(), evaluation::angular_velocity_error_degps(w, g));
    if (e.has_groundtruth && !has_g) std::fputs(",,,,", f.get());
    if (e.has_gyro && has_y)
      std::fprintf(f.get(), ",%.9g,%.9g,%.9g,%.6g", y.x(), y.y(), y.z(), evaluation::angular_velocity_error_degps(w, y));
    if (e.has_gyro && !has_y) std::fputs(",,,,", f.get());
    if (e.has_groundtruth && e.has_gyro && has_g && has_y)
      std::fprintf(f.get(), ",%.6g", evaluation::angular_velocity_error_degps(y, g));
    if (e.has_groundtruth && e.has_gyro && !(has_g && has_y)) std::fputc(',', f.get());
    std::fputc('\n', f.get());
  }
  f.close();
}

// stats.json's evaluation members (reference_convention, groundtruth, gyro).
void add_rotation_members(JsonObject* stats, const RotationEvaluation& r) {
  const evaluation::AngularVelocityWindowsEvaluation& e = r.result;
  stats->string("reference_convention", r.convention);
  if (e.has_groundtruth) {
    const evaluation::AngularVelocityErrors& g = e.estimate_vs_groundtruth;
    stats->raw("groundtruth", JsonObject(9)
                                  .string("source", r.gt_source)
                                  .integer("windows", static_cast<int64_t>(g.count))
                                  .number("rms_error_degps", g.rms_degps)
                                  .raw("rms_error_axis_degps", json_numbers(g.rms_axis_degps, 9))
                                  .number("median_error_degps", g.median_degps)
                                  .number("max_error_degps", g.max_degps)
                                  .number("groundtruth_rms_degps", g.reference_rms_degps)
                                  .number("relative_rms_error", g.relative_rms)
                                  .str());
  }
  if (e.has_gyro) {
    JsonObject gyro(9);
    gyro.integer("samples", static_cast<int64_t>(r.gyro_samples))
        .integer("windows", static_cast<int64_t>(e.estimate_vs_gyro.count))
        .number("events_vs_gyro_rms_degps", e.estimate_vs_gyro.rms_degps)
        .number("events_vs_gyro_median_degps", e.estimate_vs_gyro.median_degps);
    if (e.has_groundtruth) gyro.number("gyro_vs_groundtruth_rms_degps", e.gyro_vs_groundtruth.rms_degps);
    stats->raw("gyro", gyro.str());
  }
}

// The evaluation's lines of the summary.
std::string rotation_summary(const RotationEvaluation& r) {
  const evaluation::AngularVelocityWindowsEvaluation& e = r.result;
  std::ostringstream t;
  if (e.has_groundtruth) {
    const evaluation::AngularVelocityErrors& g = e.estimate_vs_groundtruth;
    t << "ground truth  " << g.count << " windows (" << r.gt_source << "): angular velocity error RMS "
      << json_number(g.rms_degps, 9) << " deg/s (per axis " << json_number(g.rms_axis_degps.x(), 9) << ", "
      << json_number(g.rms_axis_degps.y(), 9) << ", " << json_number(g.rms_axis_degps.z(), 9) << "), median "
      << json_number(g.median_degps, 9) << ", max " << json_number(g.max_degps, 9) << "; "
      << json_number(100 * g.relative_rms, 9) << "% of the true rate's RMS " << json_number(g.reference_rms_degps, 9)
      << " deg/s\n";
  }
  if (e.has_gyro) {
    t << "gyro          " << e.estimate_vs_gyro.count << " windows: events vs gyro RMS "
      << json_number(e.estimate_vs_gyro.rms_degps, 9) << " deg/s";
    if (e.has_groundtruth) t << ", gyro vs ground truth RMS " << json_number(e.gyro_vs_groundtruth.rms_degps, 9) << " deg/s";
    t << "\n";
  }
  t << "references    " << r.convention << "\n";
  return t.str();
}

// stats.json's model block and the summary's model line: the one model, or the selection's winners
// and the candidates' mean numbers.
struct ModelBlock {
  std::string json, text;
};

ModelBlock model_block(const FlowConfig& cfg, mapping::WarpModel model, const pipeline::CmaxMotionPipeline& pipe,
                       const FlowWindowWriter& windows, const std::vector<std::string>& dropped) {
  ModelBlock b;
  JsonObject j(9);
  if (!cfg.model_selection) {
    b.text = mapping::warp_model_name(model) + std::string(" (fixed: --model or cmax.model)");
    j.string("selection", "fixed").string("chosen", mapping::warp_model_name(model));
    b.json = j.string("summary", b.text).str();
    return b;
  }
  const pipeline::CmaxMotionStats& st = pipe.stats();
  const std::vector<mapping::WarpModel>& candidates = pipe.models();
  const double n_windows = static_cast<double>(st.windows);
  std::ostringstream t;
  t << "auto over " << st.windows << " windows:";
  std::vector<std::string> rows;
  for (size_t i = 0; i < candidates.size(); ++i) {
    const double share = st.windows > 0 ? static_cast<double>(st.chosen[i]) / n_windows : 0.0;
    rows.push_back(JsonObject(9)
                       .string("model", mapping::warp_model_name(candidates[i]))
                       .integer("parameters", mapping::warp_dof(candidates[i]))
                       .integer("windows_chosen", st.chosen[i])
                       .number("share_chosen", share)
                       .number("mean_gain", st.windows > 0 ? windows.gain_sum(i) / n_windows : 0.0)
                       .number("mean_score", st.windows > 0 ? windows.score_sum(i) / n_windows : 0.0)
                       .str());
    t << (i ? "," : "") << " " << mapping::warp_model_name(candidates[i]) << " " << json_number(100.0 * share, 9) << "%";
  }
  size_t top = 0;
  for (size_t i = 1; i < candidates.size(); ++i)
    if (st.chosen[i] > st.chosen[top]) top = i;
  const std::string chosen = st.windows > 0 ? mapping::warp_model_name(candidates[top]) : "none";
  t << " (" << chosen << " most often)";
  b.text = t.str();
  j.string("selection", "auto")
      .string("rule", "the simplest candidate unless a richer one's relative objective gain exceeds "
                      "gain_per_parameter per extra parameter (as evio segment per cluster)")
      .string("objective", mapping::cmax_objective_name(pipe.objective()))
      .number("gain_per_parameter", cfg.model_gain_per_parameter)
      .integer("windows", st.windows)
      .raw("dropped_uncalibrated", json_strings(dropped))
      .raw("candidates", json_array(rows))
      .string("chosen", chosen)
      .string("per_window", "model_selection.csv");
  b.json = j.string("summary", b.text).str();
  return b;
}

// The median of the values (0 when there is none).
double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// The run's speed figures (stats.json and the summary).
struct FlowSpeed {
  double duration_s = 0;             // first to last event, s
  double mean_ms = 0, median_ms = 0, max_ms = 0;  // per window
  double us_per_event = 0;           // maximisation time per event used
  double us_per_event_all = 0;       // processing time per event read
  double iterations_per_window = 0;
};

FlowSpeed flow_speed(const pipeline::CmaxMotionStats& st, const CmaxStreamTotals& totals, const std::vector<double>& window_ms) {
  FlowSpeed s;
  const double windows = static_cast<double>(st.windows);
  s.duration_s = totals.events > 1 ? static_cast<double>(totals.t_last_ns - totals.t_first_ns) * 1e-9 : 0.0;
  s.mean_ms = st.windows > 0 ? st.time_ms / windows : 0.0;
  s.median_ms = median(window_ms);
  s.max_ms = window_ms.empty() ? 0.0 : *std::max_element(window_ms.begin(), window_ms.end());
  s.us_per_event = st.events_used > 0 ? 1e3 * st.time_ms / static_cast<double>(st.events_used) : 0.0;
  s.us_per_event_all = totals.events > 0 ? 1e6 * totals.process_s / static_cast<double>(totals.events) : 0.0;
  s.iterations_per_window = st.windows > 0 ? static_cast<double>(st.iterations) / windows : 0.0;
  return s;
}

// stats.json, without the evaluation's members (add_rotation_members appends them).
JsonObject flow_stats(const FlowArgs& args, const FlowConfig& cfg, mapping::WarpModel model, SensorSize sensor,
                      const pipeline::CmaxMotionPipeline& pipe, const CmaxStreamTotals& totals, const FlowSpeed& speed,
                      const std::string& model_json, int64_t pngs) {
  const pipeline::CmaxMotionStats& st = pipe.stats();
  const pipeline::CmaxWindowOptions& w = cfg.window;
  JsonObject j(9, JsonObject::Layout::kLines);
  j.string("dataset", args.dataset)
      .raw("model", model_json)
      .raw("parameters", json_strings(mapping::warp_parameter_names(model)))
      .string("objective", mapping::cmax_objective_name(pipe.objective()))
      .raw("sensor", json_numbers(std::vector<int>{sensor.width, sensor.height}))
      .raw("undistortion", JsonObject(9)
                               .string("option", pipeline::cmax_undistortion_name(w.undistortion))
                               .string("used", pipeline::cmax_undistortion_name(pipe.undistortion()))
                               .string("reason", pipe.undistortion_reason())
                               .str())
      .raw("window", JsonObject(9)
                         .integer("events_per_window", w.window_ns > 0 ? 0 : w.window_events)
                         .number("duration_ms", static_cast<double>(w.window_ns) * 1e-6)
                         .number("max_duration_ms", static_cast<double>(w.max_window_ns) * 1e-6)
                         .integer("min_events", w.min_window_events)
                         .boolean("warm_start", cfg.warm_start)
                         .str())
      .integer("pyramid_levels", cfg.cmax.pyramid_levels)
      .integer("warm_pyramid_levels", cfg.warm_pyramid_levels > 0 ? cfg.warm_pyramid_levels : cfg.cmax.pyramid_levels)
      .integer("events", totals.events)
      .integer("events_used", st.events_used)
      .integer("events_dropped", st.events_dropped)
      .number("duration_s", speed.duration_s)
      .integer("windows", st.windows)
      .integer("windows_skipped", st.windows_skipped)
      .integer("warm_starts", st.warm_starts)
      .integer("resets", st.resets)
      .integer("iterations", st.iterations)
      .number("iterations_per_window", speed.iterations_per_window)
      .integer("evaluations", st.evaluations)
      .raw("time_per_window_ms",
           JsonObject(9).number("mean", speed.mean_ms).number("median", speed.median_ms).number("max", speed.max_ms).str())
      .number("time_per_event_us", speed.us_per_event)
      .number("processing_time_s", totals.process_s)
      .number("processing_time_per_event_us", speed.us_per_event_all)
      .number("events_per_s", totals.process_s > 0 ? static_cast<double>(totals.events) / totals.process_s : 0.0)
      .integer("pngs", pngs);
  return j;
}

}  // namespace

FlowConfig load_flow_config(const std::string& path, const std::vector<std::string>& sets) {
  return yaml_config::read_config(flow_config_table(), FlowConfig{}, path, sets,
                                  "a flow config YAML (see docs/commands/flow.md)");
}

std::string flow_config_text(const FlowConfig& c) {
  return yaml_config::config_text(flow_config_table(), c,
                                  "# evio flow configuration, resolved: every key with the value used (comments: unit "
                                  "and range).\n# Readable by `evio flow --config`. cmax.width/height/fx/fy/cx/cy: the "
                                  "camera's.\n");
}

FlowConfig resolve_flow_config(const FlowArgs& args) {
  FlowConfig cfg = load_flow_config(args.config, args.set);
  if (args.model == "auto") {
    cfg.model_selection = true;
  } else if (!args.model.empty()) {
    cfg.model_selection = false;
    const auto m = mapping::warp_model_from_name(args.model);
    if (!m) throw InputError("--model", 0, "unknown model '" + args.model + "'", "auto, " + mapping::warp_model_names());
    cfg.cmax.model = *m;
  }
  if (!args.objective.empty()) {
    const auto o = mapping::cmax_objective_from_name(args.objective);
    if (!o) throw InputError("--objective", 0, "unknown objective '" + args.objective + "'",
                             "auto, variance, mean_square, gradient_magnitude or normalized_gradient_magnitude");
    cfg.cmax.objective = *o;
  }
  if (args.window_events > 0) {
    cfg.window.window_events = args.window_events;
    cfg.window.window_ns = 0;
  }
  if (args.window_ns > 0) cfg.window.window_ns = args.window_ns;
  if (args.pyramid_levels > 0) cfg.cmax.pyramid_levels = args.pyramid_levels;
  {
    std::string why;
    if (!cfg.Validate(&why)) throw InputError(args.config.empty() ? "the flags" : args.config, 0, why, "valid flow settings");
  }
  return cfg;
}

int run_flow(const FlowArgs& args, std::ostream& out) {
  FlowConfig cfg = resolve_flow_config(args);
  if (args.t_start_ns && args.t_end_ns && *args.t_end_ns <= *args.t_start_ns)
    throw InputError("--t-end", 0, "--t-end must be after --t-start", "--t-start S --t-end S with S in seconds");
  if (args.png_every < 1) throw InputError("--png-every", 0, "must be >= 1", "a positive window count");

  // ---- inputs: the dataset, its camera and calibration -------------------------------------------
  CmaxInput input = open_cmax_input(args.dataset, args.dataset_options, args.calib,
                                    cfg.model_selection ? std::vector<mapping::WarpModel>{} : std::vector<mapping::WarpModel>{cfg.cmax.model});
  const std::vector<std::string> dropped = choose_candidates(&cfg, input.camera.has_value());
  // The model of motion.csv's columns: the one model, or the richest candidate.
  const mapping::WarpModel model = cfg.model_selection ? mapping::sort_warp_models(cfg.models).back() : cfg.cmax.model;
  const bool rotation = !cfg.model_selection && model == mapping::WarpModel::kRotation;

  // ---- the pipeline, and the resolved config (with the camera's size and pinhole as used) --------
  cfg.keep_iwe = args.png;
  pipeline::CmaxMotionPipeline pipe(cfg, input.sensor.width, input.sensor.height, input.camera);
  FlowConfig resolved = cfg;
  resolved.cmax = pipe.cmax_options();
  fs::create_directories(args.out);
  write_text_file((fs::path(args.out) / "flow_config.yaml").string(), flow_config_text(resolved));

  // ---- the event stream, each window written as it comes ------------------------------------------
  FlowWindowWriter writer(args, model, cfg.model_selection ? pipe.models() : std::vector<mapping::WarpModel>{},
                          cfg.cmax.use_polarity, rotation);
  const CmaxStreamTotals totals = stream_cmax_events(
      input.reader.get(), args.t_start_ns, args.t_end_ns, "evio flow", args.progress,
      [&pipe](const SubpixelEvent& e) { return pipe.process(e); }, [&pipe] { pipe.finish(); },
      [&] { writer.write(pipe.take_windows()); }, [&pipe] { return std::to_string(pipe.stats().windows) + " windows"; });
  writer.close();

  // ---- rotation: the windows against the ground truth and the gyro --------------------------------
  std::optional<RotationEvaluation> evaluated;
  if (rotation) {
    RotationEvaluation r = evaluate_rotation(args, input.reader.get(), input.calibration, writer.rotations());
    if (r.result.has_groundtruth || r.result.has_gyro) {
      log_info("evio flow: reference angular velocities: " + r.convention);
      write_motion_eval_csv((fs::path(args.out) / "motion_eval.csv").string(), writer.rotations(), r.result);
      evaluated = std::move(r);
    }
  } else if (!args.gt.empty()) {
    out << "note          --gt is evaluated with the rotation model only; ignored for " << mapping::warp_model_name(model) << "\n";
  }

  // ---- stats.json and the summary -------------------------------------------------------------------
  const pipeline::CmaxMotionStats& st = pipe.stats();
  const FlowSpeed speed = flow_speed(st, totals, writer.window_ms());
  const ModelBlock block = model_block(cfg, model, pipe, writer, dropped);
  JsonObject stats = flow_stats(args, cfg, model, input.sensor, pipe, totals, speed, block.json, writer.pngs());
  if (evaluated) add_rotation_members(&stats, *evaluated);
  write_text_file((fs::path(args.out) / "stats.json").string(), stats.str() + "\n");

  out << "events        " << totals.events << " over " << json_number(speed.duration_s, 9) << " s, " << st.windows
      << " windows (" << st.windows_skipped << " skipped with fewer than " << cfg.window.min_window_events << " events)\n";
  out << "model         " << block.text << ", objective " << mapping::cmax_objective_name(pipe.objective()) << ", pyramid "
      << cfg.cmax.pyramid_levels << " levels (warm starts: " << (cfg.warm_pyramid_levels > 0 ? cfg.warm_pyramid_levels : cfg.cmax.pyramid_levels)
      << "), " << st.warm_starts << " warm starts, " << st.resets << " resets\n";
  out << "undistortion  " << pipeline::cmax_undistortion_name(pipe.undistortion()) << ": " << pipe.undistortion_reason() << "\n";
  out << "speed         " << json_number(speed.mean_ms, 9) << " ms per window (median " << json_number(speed.median_ms, 9)
      << ", max " << json_number(speed.max_ms, 9) << "), " << json_number(speed.us_per_event, 9) << " us per event, "
      << json_number(speed.iterations_per_window, 9) << " iterations per window (one core; reading excluded)\n";
  if (evaluated) out << rotation_summary(*evaluated);
  out << "wrote " << args.out << "/motion.csv" << (evaluated ? ", motion_eval.csv" : "")
      << (cfg.model_selection ? ", model_selection.csv" : "") << ", stats.json, flow_config.yaml";
  if (args.png) out << ", iwe/ (" << writer.pngs() << " PNG)";
  out << "\n";
  return 0;
}

}  // namespace evio::apps
