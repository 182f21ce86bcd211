// Speed-accuracy table of the CMax angular-velocity front-end (pipeline::CmaxMotionPipeline, the
// rotation model, what `evio flow --model rotation` runs): for each events-per-window x
// pyramid-levels pair, the RMS angular-velocity error against the ground truth (deg/s, camera
// frame, evaluation::trajectory_angular_velocity) and the time per event (us, one core,
// maximisation and window preparation; reading excluded). The events of the span are read once
// into memory. Prints a Markdown table (and a csv with --csv). The README's tables of this grid come
// from `evio sweep datasets/sweeps/cmax_rotation.yaml`; the tool stays for --diagnose.
//
//   cmax_rotation_table DATASET --gt groundtruth.txt [--calib FILE] [--t-start S] [--t-end S]
//       [--windows 5000,10000,20000] [--levels 1,2,3] [--warm-levels 0] [--blur PX] [--tolerance PX]
//       [--max-window-ms MS] [--dither PX] [--objective NAME]
//       [--diagnose] [--csv OUT.csv] [--label NAME]
//
// --warm-levels: pyramid levels of warm-started windows (0: the same as cold ones). --diagnose adds,
// per configuration, where the error comes from: the error of the maximiser started from the true
// rate (the objective's own optimum near the truth: what a perfect optimiser would give, the cost
// of the constant-rate first-order warp and the objective), and the share of windows whose
// objective is higher at the estimate than at the truth.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "evio/evaluation/angular_velocity.h"
#include "evio/mapping/cmax.h"
#include "evio/pipeline/cmax_motion_pipeline.h"
#include "evio/sensors/dataset.h"
#include "evio/sensors/dataset_calibration.h"
#include "evio/sensors/trajectory.h"
#include "tool_args.h"

namespace {

std::vector<int64_t> int_list(const std::string& s) {
  std::vector<int64_t> v;
  std::stringstream in(s);
  for (std::string x; std::getline(in, x, ',');) v.push_back(std::stoll(x));
  return v;
}

int64_t seconds_ns(const std::string& s) { return static_cast<int64_t>(std::llround(std::stod(s) * 1e9)); }

struct Row {
  int64_t window_events = 0;
  int levels = 0, warm_levels = 0;
  size_t windows = 0;
  double rms_degps = 0, median_degps = 0, max_degps = 0, relative = 0;
  double us_per_event = 0, ms_per_window = 0, iterations = 0;
  int64_t resets = 0;
  double mean_window_ms_span = 0;      // mean window duration, ms of sensor time
  double from_truth_rms_degps = NAN;   // --diagnose: maximiser started at the true rate
  double estimate_above_truth = NAN;   // --diagnose: share of windows scoring higher than the truth
};

}  // namespace

int main(int argc, char** argv) {
  std::string dataset, gt_path, calib, csv, label = "events";
  std::vector<int64_t> windows = {5000, 10000, 20000, 40000}, levels = {1, 2, 3};
  int warm_levels = 0;
  double blur = -1, tolerance = -1, dither = -1;
  std::string objective = "auto";
  int64_t max_window_ns = 0;
  bool diagnose = false;
  int64_t t_start = INT64_MIN, t_end = INT64_MAX;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&] { return next_arg(argc, argv, &i); };
    if (a == "--gt") gt_path = next();
    else if (a == "--calib") calib = next();
    else if (a == "--t-start") t_start = seconds_ns(next());
    else if (a == "--t-end") t_end = seconds_ns(next());
    else if (a == "--windows") windows = int_list(next());
    else if (a == "--levels") levels = int_list(next());
    else if (a == "--warm-levels") warm_levels = std::stoi(next());
    else if (a == "--blur") blur = std::stod(next());
    else if (a == "--max-window-ms") max_window_ns = seconds_ns(next()) / 1000;
    else if (a == "--tolerance") tolerance = std::stod(next());
    else if (a == "--dither") dither = std::stod(next());
    else if (a == "--objective") objective = next();
    else if (a == "--diagnose") diagnose = true;
    else if (a == "--csv") csv = next();
    else if (a == "--label") label = next();
    else if (!a.empty() && a[0] != '-' && dataset.empty()) dataset = a;
    else {
      std::fprintf(stderr, "unknown argument %s\n", a.c_str());
      return 2;
    }
  }
  if (dataset.empty() || gt_path.empty()) {
    std::fprintf(stderr, "usage: cmax_rotation_table DATASET --gt FILE [--calib FILE] [--t-start S] [--t-end S] "
                         "[--windows N,...] [--levels L,...] [--warm-levels L] [--blur PX] [--tolerance PX] [--max-window-ms MS] [--dither PX] [--objective NAME] "
                         "[--diagnose] [--csv OUT] [--label NAME]\n");
    return 2;
  }
  try {
    auto reader = evio::open_dataset(dataset);
    const evio::DatasetCalibration found = evio::find_dataset_calibration(dataset, calib, *reader);
    if (!found.camera) throw std::runtime_error("no camera calibration");
    const evio::Trajectory gt = evio::read_trajectory(gt_path);
    evio::evaluation::BodyToCamera b2c;
    if (found.camera->has_T_c_b) {
      b2c.R_c_b = found.camera->T_c_b.rotation.toRotationMatrix();
      b2c.time_shift_ns = found.camera->time_shift_ns;
    }
    if (t_start != INT64_MIN) reader->seek_events(t_start);
    std::vector<evio::SubpixelEvent> events, chunk;
    const auto r0 = std::chrono::steady_clock::now();
    for (bool done = false; !done;) {
      chunk.clear();
      if (reader->read_subpixel_events(&chunk, size_t{1} << 20) == 0) break;
      for (const auto& e : chunk) {
        if (e.t_ns < t_start) continue;
        if (e.t_ns >= t_end) {
          done = true;
          break;
        }
        events.push_back(e);
      }
    }
    if (events.empty()) throw std::runtime_error("no events in the span");
    const double span_s = static_cast<double>(events.back().t_ns - events.front().t_ns) * 1e-9;
    std::fprintf(stderr, "%zu events over %.3f s read in %.1f s; calibration %s (T_c_b %s)\n", events.size(), span_s,
                 std::chrono::duration<double>(std::chrono::steady_clock::now() - r0).count(), found.camera->source.c_str(),
                 found.camera->has_T_c_b ? "applied" : "identity");

    std::vector<Row> rows;
    for (int64_t W : windows) {
      for (int64_t L : levels) {
        evio::pipeline::CmaxMotionPipelineOptions o;
        o.cmax.model = evio::mapping::WarpModel::kRotation;
        o.cmax.pyramid_levels = static_cast<int>(L);
        if (blur >= 0) o.cmax.blur_sigma_px = blur;
        if (tolerance > 0) o.cmax.tolerance_px = tolerance;
        o.window.max_window_ns = max_window_ns;
        if (dither >= 0) o.window.dither_px = dither;
        if (!evio::mapping::cmax_objective_from_name(objective)) throw std::runtime_error("unknown objective " + objective);
        o.cmax.objective = *evio::mapping::cmax_objective_from_name(objective);
        o.window.window_events = W;
        o.warm_pyramid_levels = warm_levels;
        o.keep_events = diagnose;
        evio::pipeline::CmaxMotionPipeline p(o, 0, 0, found.camera->camera);
        // --diagnose, per window as it comes (its events are dropped after): the maximiser on the
        // same prepared events started from the true rate, and the objective there and at the estimate.
        evio::mapping::CmaxOptions co = p.cmax_options();
        co.pyramid_levels = 1;
        evio::mapping::ContrastMaximizer m(co);
        std::vector<Eigen::Vector3d> est, ref, from_truth;
        size_t above = 0, compared = 0, n_windows = 0;
        double span_ms = 0;
        auto take = [&]() {
          for (auto& x : p.take_windows()) {
            ++n_windows;
            const Eigen::Vector3d g = evio::evaluation::trajectory_angular_velocity(gt, x.t_start_ns, x.t_end_ns, b2c)
                                          .value_or(Eigen::Vector3d::Constant(NAN));
            est.push_back(x.params);
            ref.push_back(g);
            span_ms += static_cast<double>(x.t_end_ns - x.t_start_ns) * 1e-6;
            if (!diagnose) continue;
            if (!g.allFinite()) {
              from_truth.push_back(Eigen::Vector3d::Constant(NAN));
              continue;
            }
            from_truth.push_back(m.maximize(x.prepared, g).params);
            above += m.objective(x.prepared, x.params, 0) > m.objective(x.prepared, g, 0);
            ++compared;
          }
        };
        for (const auto& e : events)
          if (p.process(e)) take();
        p.finish();
        take();
        const auto e = evio::evaluation::angular_velocity_errors(est, ref);
        const auto& st = p.stats();
        Row r;
        r.window_events = W;
        r.levels = static_cast<int>(L);
        r.warm_levels = warm_levels > 0 ? warm_levels : static_cast<int>(L);
        r.windows = n_windows;
        r.rms_degps = e.rms_degps;
        r.median_degps = e.median_degps;
        r.max_degps = e.max_degps;
        r.relative = e.relative_rms;
        r.us_per_event = st.events_used > 0 ? 1e3 * st.time_ms / static_cast<double>(st.events_used) : 0;
        r.ms_per_window = st.windows > 0 ? st.time_ms / static_cast<double>(st.windows) : 0;
        r.iterations = st.windows > 0 ? static_cast<double>(st.iterations) / static_cast<double>(st.windows) : 0;
        r.resets = st.resets;
        r.mean_window_ms_span = n_windows == 0 ? 0 : span_ms / static_cast<double>(n_windows);
        if (diagnose) {
          r.from_truth_rms_degps = evio::evaluation::angular_velocity_errors(from_truth, ref).rms_degps;
          r.estimate_above_truth = compared ? static_cast<double>(above) / static_cast<double>(compared) : NAN;
        }
        rows.push_back(r);
        std::fprintf(stderr, "  %lld events x %d levels (warm %d): RMS %.3f deg/s, %.3f us/event, %zu windows%s\n",
                     static_cast<long long>(W), r.levels, r.warm_levels, r.rms_degps, r.us_per_event, r.windows,
                     diagnose ? (", from truth RMS " + std::to_string(r.from_truth_rms_degps) + " deg/s").c_str() : "");
      }
    }

    const evio::mapping::CmaxOptions d;
    std::printf("\n%s: %zu events over %.2f s, rotation model, one core; objective %s, blur %g px, tolerance %g px, dither %g px, max window %s\n\n",
                label.c_str(), events.size(), span_s, objective.c_str(), blur >= 0 ? blur : d.blur_sigma_px,
                tolerance > 0 ? tolerance : d.tolerance_px, dither >= 0 ? dither : evio::pipeline::CmaxMotionPipelineOptions{}.window.dither_px,
                max_window_ns > 0 ? (std::to_string(static_cast<double>(max_window_ns) * 1e-6) + " ms").c_str() : "none");
    std::printf("| events/window | window ms | levels (cold/warm) | windows | RMS error deg/s | median | max | rel. RMS %% | us/event | ms/window | iterations | resets |%s\n",
                diagnose ? " from-truth RMS deg/s | est. > truth |" : "");
    std::printf("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|%s\n", diagnose ? "---:|---:|" : "");
    for (const Row& r : rows) {
      std::printf("| %lld | %.2f | %d/%d | %zu | %.3f | %.3f | %.2f | %.2f | %.3f | %.3f | %.1f | %lld |", static_cast<long long>(r.window_events),
                  r.mean_window_ms_span, r.levels, r.warm_levels, r.windows, r.rms_degps, r.median_degps, r.max_degps,
                  100 * r.relative, r.us_per_event, r.ms_per_window, r.iterations, static_cast<long long>(r.resets));
      if (diagnose) std::printf(" %.3f | %.1f%% |", r.from_truth_rms_degps, 100 * r.estimate_above_truth);
      std::printf("\n");
    }
    if (!csv.empty()) {
      std::ofstream f(csv);
      f << "label,window_events,window_ms,levels,warm_levels,windows,rms_degps,median_degps,max_degps,relative_rms,"
           "us_per_event,ms_per_window,iterations,resets,from_truth_rms_degps,estimate_above_truth\n";
      for (const Row& r : rows) {
        f << label << "," << r.window_events << "," << r.mean_window_ms_span << "," << r.levels << "," << r.warm_levels << ","
          << r.windows << "," << r.rms_degps << "," << r.median_degps << "," << r.max_degps << "," << r.relative << ","
          << r.us_per_event << "," << r.ms_per_window << "," << r.iterations << "," << r.resets << ","
          << r.from_truth_rms_degps << "," << r.estimate_above_truth << "\n";
      }
      if (!f) throw std::runtime_error("cannot write " + csv);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "cmax_rotation_table: %s\n", e.what());
    return 1;
  }
  return 0;
}
