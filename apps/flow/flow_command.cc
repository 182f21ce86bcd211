#include "flow_command.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <ostream>
#include <sstream>

#include <opencv2/core.hpp>

#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio/evaluation/angular_velocity.h"
#include "evio/sensors/config_table.h"
#include "evio/sensors/dataset_calibration.h"
#include "evio/sensors/image_io.h"
#include "evio/sensors/time.h"
#include "evio/sensors/trajectory.h"
#include "cmax_input.h"
#include "evio/calib/json.h"
#include "output_files.h"
#include "evio/mapping/option_tables.h"
#include "option_tables.h"
#include "progress.h"

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

std::string vec3(const Eigen::Vector3d& v) { return "[" + json_number(v.x(), 9) + ", " + json_number(v.y(), 9) + ", " + json_number(v.z(), 9) + "]"; }

struct WindowRecord {
  int64_t t0 = 0, t1 = 0;
  Eigen::VectorXd params;
  double time_ms = 0;
  int iterations = 0;
};

double windows_d(int64_t n) { return static_cast<double>(n); }

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

}  // namespace

FlowConfig load_flow_config(const std::string& path, const std::vector<std::string>& sets) {
  return yaml_config::read_config(flow_config_table(), FlowConfig{}, path, sets,
                                  "a flow config YAML (see README.md, `evio flow`)");
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
  CmaxInput input = open_cmax_input(args.dataset, args.dataset_options, args.calib,
                                    cfg.model_selection ? std::vector<mapping::WarpModel>{} : std::vector<mapping::WarpModel>{cfg.cmax.model});
  // Model selection: the candidates, the 3-D warps only with a calibrated camera (they need the pinhole).
  std::vector<std::string> dropped;
  cfg.models.clear();
  if (cfg.model_selection) {
    for (mapping::WarpModel m : cfg.candidates) {
      const bool three_d = m == mapping::WarpModel::kRotation || m == mapping::WarpModel::kSixDof;
      if (three_d && !input.camera) dropped.push_back(mapping::warp_model_name(m));
      else cfg.models.push_back(m);
    }
    if (cfg.models.empty()) throw InputError("candidates", 0, "no candidate model without a camera calibration", "flow or similarity among the candidates, or --calib");
  }
  const bool selecting = cfg.model_selection;
  // The model of motion.csv's columns: the one model, or the richest candidate (a window's own
  // model's parameters first, the rest empty).
  const mapping::WarpModel model = selecting ? mapping::sort_warp_models(cfg.models).back() : cfg.cmax.model;
  const bool rotation = !selecting && model == mapping::WarpModel::kRotation;
  DatasetReader* reader = input.reader.get();
  const std::optional<calib::PinholeCamera>& camera = input.camera;
  const SensorSize sensor = input.sensor;
  const DatasetCalibration& found = input.calibration;

  cfg.keep_iwe = args.png;
  pipeline::CmaxMotionPipeline pipe(cfg, sensor.width, sensor.height, camera);
  // The resolved config holds the camera's size and pinhole as used.
  FlowConfig resolved = cfg;
  resolved.cmax = pipe.cmax_options();
  fs::create_directories(args.out);
  {
    TextOut f((fs::path(args.out) / "flow_config.yaml").string());
    std::fputs(flow_config_text(resolved).c_str(), f.get());
    f.close();
  }
  const std::string iwe_dir = (fs::path(args.out) / "iwe").string();
  if (args.png) fs::create_directories(iwe_dir);

  // motion.csv: the header as documented in flow_command.h (p0.. per model).
  const int dof = mapping::warp_dof(model);
  TextOut csv((fs::path(args.out) / "motion.csv").string());
  {
    std::string h = "t_start_s,t_end_s,model";
    for (int i = 0; i < dof; ++i) h += ",p" + std::to_string(i);
    h += ",contrast_zero,contrast_final,iterations,time_ms\n";
    std::fputs(h.c_str(), csv.get());
  }

  // Model selection: model_selection.csv, one row per window with every candidate's numbers.
  const std::vector<mapping::WarpModel>& candidates = pipe.models();
  std::vector<double> gain_sum(candidates.size(), 0.0), score_sum(candidates.size(), 0.0);
  std::optional<TextOut> sel_csv;
  if (selecting) {
    sel_csv.emplace((fs::path(args.out) / "model_selection.csv").string());
    std::string h = "t_start_s,t_end_s,chosen";
    for (mapping::WarpModel m : candidates) {
      const std::string n = mapping::warp_model_name(m);
      h += "," + n + "_objective," + n + "_gain," + n + "_score";
    }
    std::fputs((h + "\n").c_str(), sel_csv->get());
  }
  std::vector<WindowRecord> records;
  int64_t pngs = 0;
  const bool signed_iwe = cfg.cmax.use_polarity;
  auto handle = [&](std::vector<pipeline::CmaxMotionWindow> windows) {
    char t0[32], t1[32];
    for (pipeline::CmaxMotionWindow& w : windows) {
      *format_seconds(w.t_start_ns, t0) = '\0';
      *format_seconds(w.t_end_ns, t1) = '\0';
      std::fprintf(csv.get(), "%s,%s,%s", t0, t1, mapping::warp_model_name(w.model));
      for (int i = 0; i < dof; ++i) {
        if (i < w.params.size()) std::fprintf(csv.get(), ",%.9g", w.params[i]);
        else std::fputc(',', csv.get());
      }
      std::fprintf(csv.get(), ",%.9g,%.9g,%d,%.3f\n", w.objective_zero, w.objective, w.iterations, w.time_ms);
      if (args.png && w.index % args.png_every == 0) {
        const double scale = robust_scale(w.iwe);
        char name[64];
        std::snprintf(name, sizeof(name), "window_%06lld_before.png", static_cast<long long>(w.index));
        write_iwe_png((fs::path(iwe_dir) / name).string(), w.iwe_zero, scale, signed_iwe);
        std::snprintf(name, sizeof(name), "window_%06lld_after.png", static_cast<long long>(w.index));
        write_iwe_png((fs::path(iwe_dir) / name).string(), w.iwe, scale, signed_iwe);
        pngs += 2;
      }
      if (sel_csv) {
        std::fprintf(sel_csv->get(), "%s,%s,%s", t0, t1, mapping::warp_model_name(w.model));
        for (size_t i = 0; i < w.trials.size(); ++i) {
          const mapping::ModelTrial& t = w.trials[i];
          std::fprintf(sel_csv->get(), ",%.9g,%.9g,%.9g", t.objective, t.gain, t.score);
          gain_sum[i] += t.gain;
          score_sum[i] += t.score;
        }
        std::fputc('\n', sel_csv->get());
      }
      records.push_back({w.t_start_ns, w.t_end_ns, w.params, w.time_ms, w.iterations});
    }
  };

  // ---- the event stream -------------------------------------------------------------------------
  const CmaxStreamTotals totals = stream_cmax_events(
      reader, args.t_start_ns, args.t_end_ns, "evio flow", args.progress,
      [&pipe](const SubpixelEvent& e) { return pipe.process(e); }, [&pipe] { pipe.finish(); },
      [&] { handle(pipe.take_windows()); }, [&pipe] { return std::to_string(pipe.stats().windows) + " windows"; });
  const int64_t events = totals.events, t_first = totals.t_first_ns, t_last = totals.t_last_ns;
  const double process_s = totals.process_s;
  csv.close();
  if (sel_csv) sel_csv->close();
  const pipeline::CmaxMotionStats& st = pipe.stats();

  // ---- rotation: ground truth and gyro per window -----------------------------------------------
  std::string eval_json;
  std::ostringstream eval_text;
  if (rotation) {
    std::optional<Trajectory> gt;
    std::string gt_source;
    if (!args.gt.empty()) {
      gt = read_trajectory(args.gt);
      gt_source = args.gt;
    } else if (auto own = reader->read_groundtruth(); own && own->size() >= 3) {
      gt = std::move(own);
      gt_source = "the dataset's ground truth";
    }
    std::vector<ImuSample> imu = reader->read_imu();
    evaluation::BodyToCamera b2c;
    std::string convention;
    if (found.camera && found.camera->has_T_c_b) {
      b2c.R_c_b = found.camera->T_c_b.rotation.toRotationMatrix();
      b2c.time_shift_ns = found.camera->time_shift_ns;
      convention = "body (IMU) poses and gyro rates, turned into the camera frame with R_c_b of T_c_b from " +
                   found.camera->source + " and read at t_cam + " + std::to_string(b2c.time_shift_ns) + " ns";
    } else {
      convention = "no camera-IMU extrinsics in the calibration: the ground truth is taken as the camera's pose (T_w_c) "
                   "and the gyro as measured in the camera frame (R_c_b = identity, no time shift)";
    }
    if (gt || imu.size() >= 2) {
      log_info("evio flow: reference angular velocities: " + convention);
      TextOut f((fs::path(args.out) / "motion_eval.csv").string());
      std::string h = "t_start_s,t_end_s,wx_radps,wy_radps,wz_radps";
      if (gt) h += ",gt_wx_radps,gt_wy_radps,gt_wz_radps,error_degps";
      if (imu.size() >= 2) h += ",gyro_wx_radps,gyro_wy_radps,gyro_wz_radps,events_vs_gyro_degps";
      if (gt && imu.size() >= 2) h += ",gyro_vs_gt_degps";
      std::fputs((h + "\n").c_str(), f.get());
      const Eigen::Vector3d nan3 = Eigen::Vector3d::Constant(std::nan(""));
      std::vector<Eigen::Vector3d> est, ref, gyr;
      char t0[32], t1[32];
      for (const WindowRecord& r : records) {
        const Eigen::Vector3d w = r.params.head<3>();
        const Eigen::Vector3d g = gt ? evaluation::trajectory_angular_velocity(*gt, r.t0, r.t1, b2c).value_or(nan3) : nan3;
        const Eigen::Vector3d y = imu.size() >= 2 ? evaluation::mean_gyro(imu, r.t0, r.t1, b2c).value_or(nan3) : nan3;
        est.push_back(w);
        ref.push_back(g);
        gyr.push_back(y);
        *format_seconds(r.t0, t0) = '\0';
        *format_seconds(r.t1, t1) = '\0';
        std::fprintf(f.get(), "%s,%s,%.9g,%.9g,%.9g", t0, t1, w.x(), w.y(), w.z());
        const double deg = 180.0 / M_PI;
        // A reference that does not cover the window (the ground truth's or the gyro's ends) leaves
        // its fields empty: every number written is finite.
        const bool has_g = g.allFinite(), has_y = y.allFinite();
        if (gt && has_g) std::fprintf(f.get(), ",%.9g,%.9g,%.9g,%.6g", g.x(), g.y(), g.z(), (w - g).norm() * deg);
        if (gt && !has_g) std::fputs(",,,,", f.get());
        if (imu.size() >= 2 && has_y) std::fprintf(f.get(), ",%.9g,%.9g,%.9g,%.6g", y.x(), y.y(), y.z(), (w - y).norm() * deg);
        if (imu.size() >= 2 && !has_y) std::fputs(",,,,", f.get());
        if (gt && imu.size() >= 2 && has_g && has_y) std::fprintf(f.get(), ",%.6g", (y - g).norm() * deg);
        if (gt && imu.size() >= 2 && !(has_g && has_y)) std::fputc(',', f.get());
        std::fputc('\n', f.get());
      }
      f.close();
      std::ostringstream j;
      j << ",\n  \"reference_convention\": " << json_string(convention);
      if (gt) {
        const evaluation::AngularVelocityErrors e = evaluation::angular_velocity_errors(est, ref);
        j << ",\n  \"groundtruth\": {\"source\": " << json_string(gt_source) << ", \"windows\": " << e.count
          << ", \"rms_error_degps\": " << json_number(e.rms_degps, 9) << ", \"rms_error_axis_degps\": " << vec3(e.rms_axis_degps)
          << ", \"median_error_degps\": " << json_number(e.median_degps, 9) << ", \"max_error_degps\": " << json_number(e.max_degps, 9)
          << ", \"groundtruth_rms_degps\": " << json_number(e.reference_rms_degps, 9) << ", \"relative_rms_error\": " << json_number(e.relative_rms, 9) << "}";
        eval_text << "ground truth  " << e.count << " windows (" << gt_source << "): angular velocity error RMS "
                  << json_number(e.rms_degps, 9) << " deg/s (per axis " << json_number(e.rms_axis_degps.x(), 9) << ", " << json_number(e.rms_axis_degps.y(), 9) << ", "
                  << json_number(e.rms_axis_degps.z(), 9) << "), median " << json_number(e.median_degps, 9) << ", max " << json_number(e.max_degps, 9)
                  << "; " << json_number(100 * e.relative_rms, 9) << "% of the true rate's RMS " << json_number(e.reference_rms_degps, 9) << " deg/s\n";
      }
      if (imu.size() >= 2) {
        const evaluation::AngularVelocityErrors e = evaluation::angular_velocity_errors(est, gyr);
        j << ",\n  \"gyro\": {\"samples\": " << imu.size() << ", \"windows\": " << e.count
          << ", \"events_vs_gyro_rms_degps\": " << json_number(e.rms_degps, 9) << ", \"events_vs_gyro_median_degps\": " << json_number(e.median_degps, 9);
        eval_text << "gyro          " << e.count << " windows: events vs gyro RMS " << json_number(e.rms_degps, 9) << " deg/s";
        if (gt) {
          const evaluation::AngularVelocityErrors eg = evaluation::angular_velocity_errors(gyr, ref);
          j << ", \"gyro_vs_groundtruth_rms_degps\": " << json_number(eg.rms_degps, 9);
          eval_text << ", gyro vs ground truth RMS " << json_number(eg.rms_degps, 9) << " deg/s";
        }
        j << "}";
        eval_text << "\n";
      }
      eval_text << "references    " << convention << "\n";
      eval_json = j.str();
    }
  } else if (!args.gt.empty()) {
    out << "note          --gt is evaluated with the rotation model only; ignored for " << mapping::warp_model_name(model) << "\n";
  }

  // ---- stats.json and the summary -----------------------------------------------------------------
  std::vector<double> times;
  for (const WindowRecord& r : records) times.push_back(r.time_ms);
  const double duration_s = events > 1 ? static_cast<double>(t_last - t_first) * 1e-9 : 0.0;
  const double windows = static_cast<double>(st.windows);
  const double mean_ms = st.windows > 0 ? st.time_ms / windows : 0.0;
  const double max_ms = times.empty() ? 0.0 : *std::max_element(times.begin(), times.end());
  const double us_per_event = st.events_used > 0 ? 1e3 * st.time_ms / static_cast<double>(st.events_used) : 0.0;
  const double us_per_event_all = events > 0 ? 1e6 * process_s / static_cast<double>(events) : 0.0;
  const char* objective = mapping::cmax_objective_name(pipe.objective());
  // The model block: the one model, or the selection's winners and the candidates' mean numbers.
  std::string model_json, model_text;
  {
    std::ostringstream j, t;
    if (!selecting) {
      t << mapping::warp_model_name(model) << " (fixed: --model or cmax.model)";
      j << "{\"selection\": \"fixed\", \"chosen\": " << json_string(mapping::warp_model_name(model));
    } else {
      j << "{\"selection\": \"auto\", \"rule\": \"the simplest candidate unless a richer one's relative objective gain "
           "exceeds gain_per_parameter per extra parameter (as evio segment per cluster)\", \"objective\": "
        << json_string(objective) << ", \"gain_per_parameter\": " << json_number(cfg.model_gain_per_parameter, 9)
        << ", \"windows\": " << st.windows << ", \"dropped_uncalibrated\": [";
      for (size_t i = 0; i < dropped.size(); ++i) j << (i ? ", " : "") << json_string(dropped[i]);
      j << "], \"candidates\": [";
      t << "auto over " << st.windows << " windows:";
      for (size_t i = 0; i < candidates.size(); ++i) {
        const double n = static_cast<double>(st.chosen[i]);
        const double share = st.windows > 0 ? n / windows_d(st.windows) : 0.0;
        j << (i ? ", " : "") << "{\"model\": " << json_string(mapping::warp_model_name(candidates[i])) << ", \"parameters\": "
          << mapping::warp_dof(candidates[i]) << ", \"windows_chosen\": " << st.chosen[i] << ", \"share_chosen\": " << json_number(share, 9)
          << ", \"mean_gain\": " << json_number(st.windows > 0 ? gain_sum[i] / windows_d(st.windows) : 0.0, 9)
          << ", \"mean_score\": " << json_number(st.windows > 0 ? score_sum[i] / windows_d(st.windows) : 0.0, 9) << "}";
        t << (i ? "," : "") << " " << mapping::warp_model_name(candidates[i]) << " " << json_number(100.0 * share, 9) << "%";
      }
      size_t top = 0;
      for (size_t i = 1; i < candidates.size(); ++i)
        if (st.chosen[i] > st.chosen[top]) top = i;
      j << "], \"chosen\": " << json_string(st.windows > 0 ? mapping::warp_model_name(candidates[top]) : "none")
        << ", \"per_window\": \"model_selection.csv\"";
      t << " (" << (st.windows > 0 ? mapping::warp_model_name(candidates[top]) : "none") << " most often)";
    }
    model_text = t.str();
    j << ", \"summary\": " << json_string(model_text) << "}";
    model_json = j.str();
  }
  {
    TextOut f((fs::path(args.out) / "stats.json").string());
    std::ostringstream j;
    j << "{\n  \"dataset\": " << json_string(args.dataset) << ",\n  \"model\": " << model_json << ",\n  \"parameters\": [";
    const auto names = mapping::warp_parameter_names(model);
    for (size_t i = 0; i < names.size(); ++i) j << (i ? ", " : "") << json_string(names[i]);
    j << "],\n  \"objective\": " << json_string(objective) << ",\n  \"sensor\": [" << sensor.width << ", " << sensor.height
      << "],\n  \"undistortion\": {\"option\": " << json_string(pipeline::cmax_undistortion_name(cfg.window.undistortion))
      << ", \"used\": " << json_string(pipeline::cmax_undistortion_name(pipe.undistortion())) << ", \"reason\": "
      << json_string(pipe.undistortion_reason()) << "},\n  \"window\": {\"events_per_window\": " << (cfg.window.window_ns > 0 ? 0 : cfg.window.window_events)
      << ", \"duration_ms\": " << json_number(static_cast<double>(cfg.window.window_ns) * 1e-6, 9)
      << ", \"max_duration_ms\": " << json_number(static_cast<double>(cfg.window.max_window_ns) * 1e-6, 9) << ", \"min_events\": " << cfg.window.min_window_events
      << ", \"warm_start\": " << (cfg.warm_start ? "true" : "false") << "},\n  \"pyramid_levels\": " << cfg.cmax.pyramid_levels
      << ",\n  \"warm_pyramid_levels\": " << (cfg.warm_pyramid_levels > 0 ? cfg.warm_pyramid_levels : cfg.cmax.pyramid_levels)
      << ",\n  \"events\": " << events << ",\n  \"events_used\": " << st.events_used
      << ",\n  \"events_dropped\": " << st.events_dropped << ",\n  \"duration_s\": " << json_number(duration_s, 9)
      << ",\n  \"windows\": " << st.windows << ",\n  \"windows_skipped\": " << st.windows_skipped
      << ",\n  \"warm_starts\": " << st.warm_starts << ",\n  \"resets\": " << st.resets
      << ",\n  \"iterations\": " << st.iterations << ",\n  \"iterations_per_window\": " << json_number(st.windows > 0 ? static_cast<double>(st.iterations) / windows : 0.0, 9)
      << ",\n  \"evaluations\": " << st.evaluations
      << ",\n  \"time_per_window_ms\": {\"mean\": " << json_number(mean_ms, 9) << ", \"median\": " << json_number(median(times), 9)
      << ", \"max\": " << json_number(max_ms, 9) << "},\n  \"time_per_event_us\": " << json_number(us_per_event, 9)
      << ",\n  \"processing_time_s\": " << json_number(process_s, 9) << ",\n  \"processing_time_per_event_us\": " << json_number(us_per_event_all, 9)
      << ",\n  \"events_per_s\": " << json_number(process_s > 0 ? static_cast<double>(events) / process_s : 0.0, 9)
      << ",\n  \"pngs\": " << pngs << eval_json << "\n}\n";
    std::fputs(j.str().c_str(), f.get());
    f.close();
  }

  out << "events        " << events << " over " << json_number(duration_s, 9) << " s, " << st.windows << " windows ("
      << st.windows_skipped << " skipped with fewer than " << cfg.window.min_window_events << " events)\n";
  out << "model         " << model_text << ", objective " << objective << ", pyramid "
      << cfg.cmax.pyramid_levels << " levels (warm starts: " << (cfg.warm_pyramid_levels > 0 ? cfg.warm_pyramid_levels : cfg.cmax.pyramid_levels)
      << "), " << st.warm_starts << " warm starts, " << st.resets << " resets\n";
  out << "undistortion  " << pipeline::cmax_undistortion_name(pipe.undistortion()) << ": " << pipe.undistortion_reason() << "\n";
  out << "speed         " << json_number(mean_ms, 9) << " ms per window (median " << json_number(median(times), 9) << ", max " << json_number(max_ms, 9)
      << "), " << json_number(us_per_event, 9) << " us per event, " << json_number(st.windows > 0 ? static_cast<double>(st.iterations) / windows : 0.0, 9)
      << " iterations per window (one core; reading excluded)\n";
  out << eval_text.str();
  out << "wrote " << args.out << "/motion.csv" << (eval_json.empty() ? "" : ", motion_eval.csv")
      << (selecting ? ", model_selection.csv" : "")
      << ", stats.json, flow_config.yaml";
  if (args.png) out << ", iwe/ (" << pngs << " PNG)";
  out << "\n";
  return 0;
}

}  // namespace evio::apps
