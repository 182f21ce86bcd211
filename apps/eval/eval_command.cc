#include "eval_command.h"
#include "evio/calib/json.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <ostream>
#include <sstream>
#include <stdexcept>

#include <unistd.h>

#include "evio/calib/error.h"
#include "evio/evaluation/run_summary.h"
#include "evio/sensors/dataset.h"
#include "evio/calib/log.h"
#include "evio/calib/script_path.h"
#include "evio/sensors/time.h"

namespace evio::apps {
namespace fs = std::filesystem;
using evaluation::Stats;

namespace {

std::string fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), f, v);
  return buf;
}

std::string stats_json(const Stats& s) {
  return "{\"rmse\": " + json_number(s.rmse) + ", \"mean\": " + json_number(s.mean) + ", \"median\": " + json_number(s.median) +
         ", \"std\": " + json_number(s.std) + ", \"min\": " + json_number(s.min) + ", \"max\": " + json_number(s.max) +
         ", \"count\": " + std::to_string(s.count) + "}";
}

// File-name-safe prefix.
std::string safe_name(const std::string& s) {
  std::string o;
  for (char c : s) o += std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' || c == '.' ? c : '_';
  return o.empty() ? std::string("estimate") : o;
}

void write_file(const fs::path& p, const std::string& text) {
  std::ofstream f(p, std::ios::binary);
  if (!f) throw InputError(p.string(), 0, "cannot create the output file", "a writable folder");
  f << text;
  if (!f.flush()) throw InputError(p.string(), 0, "write failed", "a writable folder with free space");
}

std::string shell_quote(const std::string& s) {
  std::string o = "'";
  for (char c : s) o += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return o + "'";
}

const char* kPlotHint =
    "install them with `sudo apt-get install python3-numpy python3-matplotlib` (or scripts/setup_deps.sh), "
    "then run `/usr/bin/python3 scripts/plot_trajectory.py ";

}  // namespace

std::vector<EstimateEvaluation> evaluate_all(const EvalArgs& args) {
  std::string why;
  if (!args.options.Validate(&why)) throw InputError("evio eval", 0, "invalid options: " + why);
  if (args.estimates.empty()) throw InputError("evio eval", 0, "no estimate given", "evio eval GT EST [EST2 ...]");
  if (!args.labels.empty() && args.labels.size() != args.estimates.size()) {
    throw InputError("evio eval", 0,
                     std::to_string(args.labels.size()) + " labels for " + std::to_string(args.estimates.size()) +
                         " estimates",
                     "no --label, or one --label per estimate (runs of one method share a label)");
  }
  TextReadOptions gt_read = args.read;
  gt_read.time_unit = args.groundtruth_time_unit;
  const Trajectory gt = read_trajectory(args.groundtruth, gt_read);
  if (args.rre_interval_s < 0 || !std::isfinite(args.rre_interval_s))
    throw InputError("evio eval", 0, "invalid RRE interval", "--rre-interval S with S >= 0 (0: off)");
  // The gyro integrated alone, for the RRE's reference.
  std::optional<Trajectory> gyro = args.gyro_orientation;
  if (!gyro && !args.imu.empty() && args.rre_interval_s > 0) {
    auto reader = open_dataset(args.imu);
    evaluation::GyroIntegrator integrator;
    std::vector<ImuSample> chunk;
    while (reader->read_imu_samples(&chunk, 4096) > 0) {
      for (const ImuSample& s : chunk) integrator.add(s);
      chunk.clear();
    }
    if (integrator.samples() < 2) throw InputError(args.imu, 0, "no IMU samples", "a dataset or imu.txt with IMU samples");
    gyro = integrator.trajectory();
  }
  std::vector<EstimateEvaluation> out;
  for (size_t i = 0; i < args.estimates.size(); ++i) {
    EstimateEvaluation e;
    e.file = args.estimates[i];
    const std::string stem = fs::path(e.file).stem().string();
    e.label = args.labels.empty() ? e.file : args.labels[i];
    e.name = "est" + std::to_string(i) + "_" + safe_name(stem);
    const Trajectory est = read_trajectory(e.file, args.read);
    try {
      e.result = evaluation::evaluate(gt, est, args.options);
    } catch (const std::invalid_argument& ex) {
      throw InputError(e.file, 0, ex.what());
    }
    if (args.rre_interval_s > 0) {
      evaluation::RelativeRotationOptions ro;
      ro.interval_s = args.rre_interval_s;
      e.rre = evaluation::relative_rotation_error(gt, est, ro);
      if (gyro) e.rre_gyro = evaluation::relative_rotation_error_at(gt, *gyro, e.rre->start_ns, e.rre->end_ns, args.rre_interval_s);
    }
    for (size_t k = 1; k < e.result.aligned_estimate.size(); ++k) {
      e.estimate_length_m +=
          (e.result.aligned_estimate[k].translation - e.result.aligned_estimate[k - 1].translation).norm();
    }
    out.push_back(std::move(e));
  }
  return out;
}

std::string results_json(const EvalArgs& args, const std::vector<EstimateEvaluation>& results) {
  const auto& o = args.options;
  std::ostringstream j;
  j << "{\n  \"groundtruth\": " << json_string(args.groundtruth) << ",\n";
  j << "  \"protocol\": {\"association\": {\"max_dt_s\": " << json_number(o.association.max_dt_s)
    << ", \"time_offset_s\": " << json_number(o.association.time_offset_s)
    << ", \"interpolate_groundtruth\": " << (o.association.interpolate_groundtruth ? "true" : "false") << "}, "
    << "\"alignment\": {\"method\": " << json_string(evaluation::alignment_name(o.alignment.method))
    << ", \"first_s\": " << json_number(o.alignment.first_s) << ", \"first_poses\": " << o.alignment.first_poses << "}, "
    << "\"rpe\": {\"lengths\": [";
  for (size_t i = 0; i < o.rpe.lengths.size(); ++i) j << (i ? ", " : "") << json_number(o.rpe.lengths[i]);
  j << "], \"lengths_unit\": " << json_string(o.rpe.lengths_in_percent ? "percent of ground-truth path length" : "m")
    << ", \"method\": \"rpg_trajectory_evaluation (Zhang and Scaramuzza, IROS 2018)\"}},\n";
  j << "  \"estimates\": [";
  for (size_t n = 0; n < results.size(); ++n) {
    const EstimateEvaluation& e = results[n];
    const auto& r = e.result;
    j << (n ? ",\n" : "\n") << "    {\"file\": " << json_string(e.file) << ", \"label\": " << json_string(e.label)
      << ", \"name\": " << json_string(e.name) << ", \"align\": " << json_string(evaluation::alignment_name(r.alignment.method))
      << ", \"matched_poses\": " << r.matched_poses << ",\n";
    j << "     \"ate\": {\"trans_m\": " << stats_json(r.ate.trans_m) << ",\n             \"rot_deg\": "
      << stats_json(r.ate.rot_deg) << "},\n";
    j << "     \"mean_position_error_percent\": " << json_number(r.mean_position_error_percent) << ",\n";
    j << "     \"rpe\": [";
    for (size_t k = 0; k < r.rpe.size(); ++k) {
      const auto& q = r.rpe[k];
      j << (k ? ",\n" : "\n") << "       {\"length_m\": " << json_number(q.length_m) << ", \"count\": " << q.count
        << ", \"trans_percent\": " << stats_json(q.trans_percent) << ", \"yaw_deg_per_m\": " << stats_json(q.yaw_deg_per_m)
        << ", \"trans_m\": " << stats_json(q.trans_m) << ", \"rot_deg\": " << stats_json(q.rot_deg)
        << ", \"yaw_deg\": " << stats_json(q.yaw_deg) << "}";
    }
    j << "],\n";
    const auto& a = r.alignment;
    j << "     \"alignment\": {\"rotation\": [";
    for (int row = 0; row < 3; ++row) {
      j << (row ? ", " : "") << "[" << json_number(a.rotation(row, 0)) << ", " << json_number(a.rotation(row, 1)) << ", "
        << json_number(a.rotation(row, 2)) << "]";
    }
    j << "], \"translation\": [" << json_number(a.translation.x()) << ", " << json_number(a.translation.y()) << ", "
      << json_number(a.translation.z()) << "], \"scale\": " << json_number(a.scale) << ", \"pairs_used\": " << a.pairs_used << "},\n";
    j << "     \"groundtruth_length_m\": " << json_number(r.groundtruth_length_m)
      << ", \"estimate_length_m\": " << json_number(e.estimate_length_m)
      << ", \"final_yaw_error_deg\": " << json_number(r.final_yaw_error_deg)
      << ", \"yaw_drift_deg_per_m\": " << json_number(r.yaw_drift_deg_per_m) << ",\n";
    if (e.rre) {
      j << "     \"rre\": {\"interval_s\": " << json_number(e.rre->interval_s) << ", \"count\": " << e.rre->deg.count
        << ", \"deg\": " << stats_json(e.rre->deg);
      if (e.rre_gyro) j << ", \"gyro_count\": " << e.rre_gyro->deg.count << ", \"gyro_deg\": " << stats_json(e.rre_gyro->deg);
      j << "},\n";
    }
    const auto& t = r.pairs.t_ns;
    j << "     \"time_span_s\": [" << (t.empty() ? "null" : format_seconds(t.front())) << ", "
      << (t.empty() ? "null" : format_seconds(t.back())) << "],\n";
    j << "     \"outputs\": {\"aligned_estimate\": " << json_string(e.name + "_aligned.tum")
      << ", \"matched_groundtruth\": " << json_string(e.name + "_groundtruth.tum")
      << ", \"errors\": " << json_string(e.name + "_errors.csv") << "}}";
  }
  j << "\n  ]\n}\n";
  return j.str();
}

std::vector<SummaryRow> summarize(const std::vector<EstimateEvaluation>& results) {
  std::vector<std::pair<std::string, const evaluation::EvaluationResult*>> runs;
  runs.reserve(results.size());
  for (const auto& e : results) runs.emplace_back(e.label, &e.result);
  return evaluation::summarize_runs(runs);
}

std::string summary_csv(const std::vector<SummaryRow>& rows) {
  std::string o = "label,metric,runs,mean,median,min,max\n";
  for (const auto& r : rows) {
    std::string label = r.label;
    if (label.find_first_of(",\"\n") != std::string::npos) {
      std::string q = "\"";
      for (char c : label) q += c == '"' ? std::string("\"\"") : std::string(1, c);
      label = q + "\"";
    }
    o += label + "," + r.metric + "," + std::to_string(r.runs) + "," + json_number(r.mean) + "," + json_number(r.median) + "," +
         json_number(r.min) + "," + json_number(r.max) + "\n";
  }
  return o;
}

std::string summary_yaml(const std::vector<SummaryRow>& rows) {
  std::string o = "# evio eval summary over runs: per method label and metric\nmethods:\n";
  std::string current;
  bool first = true;
  for (const auto& r : rows) {
    if (first || r.label != current) {
      o += "  " + json_string(r.label) + ":\n";  // a JSON string is a valid YAML double-quoted scalar
      current = r.label;
      first = false;
    }
    o += "    " + r.metric + ": {runs: " + std::to_string(r.runs) + ", mean: " + json_number(r.mean) +
         ", median: " + json_number(r.median) + ", min: " + json_number(r.min) + ", max: " + json_number(r.max) + "}\n";
  }
  return o;
}

std::string summary_json(const std::vector<SummaryRow>& rows) {
  std::string o = "{\"methods\": [";
  std::string current;
  bool first = true;
  for (const auto& r : rows) {
    if (first || r.label != current) {
      o += std::string(first ? "\n" : "}},\n") + "  {\"label\": " + json_string(r.label) + ", \"metrics\": {";
      current = r.label;
      first = false;
    } else {
      o += ", ";
    }
    o += "\"" + r.metric + "\": {\"runs\": " + std::to_string(r.runs) + ", \"mean\": " + json_number(r.mean) +
         ", \"median\": " + json_number(r.median) + ", \"min\": " + json_number(r.min) + ", \"max\": " + json_number(r.max) + "}";
  }
  if (!first) o += "}}\n";
  return o + "]}\n";
}

std::string summary_latex(const std::vector<SummaryRow>& rows) {
  std::string o =
      "% evio eval: mean over runs. Method & ATE RMSE [m] & rot. RMSE [deg] & mean pos. error [%] & "
      "RPE trans. [%] & yaw drift [deg/m] \\\\\n";
  auto tex_escape = [](const std::string& s) {
    std::string t;
    for (char c : s) {
      if (std::string("&%$#_{}").find(c) != std::string::npos) t += '\\';
      t += c;
    }
    return t;
  };
  for (size_t i = 0; i < rows.size();) {
    const std::string label = rows[i].label;
    o += tex_escape(label);
    for (; i < rows.size() && rows[i].label == label; ++i) {
      o += " & " + (rows[i].runs == 0 ? std::string("--") : fmt("%.3f", rows[i].mean));
    }
    o += " \\\\\n";
  }
  return o;
}

std::string results_table(const EvalArgs& args, const std::vector<EstimateEvaluation>& results) {
  std::ostringstream t;
  const auto& o = args.options;
  t << "ground truth  " << args.groundtruth << "\n";
  t << "protocol      align " << evaluation::alignment_name(o.alignment.method);
  if (o.alignment.first_s > 0) t << " on the first " << fmt("%g", o.alignment.first_s) << " s";
  if (o.alignment.first_poses > 0) t << " on the first " << o.alignment.first_poses << " poses";
  t << ", max dt " << fmt("%g", o.association.max_dt_s) << " s, offset " << fmt("%g", o.association.time_offset_s)
    << " s" << (o.association.interpolate_groundtruth ? ", ground truth interpolated" : "")
    << ", RPE lengths rpg_trajectory_evaluation\n";
  size_t width = 8;
  for (const auto& e : results) width = std::max(width, e.label.size());
  char buf[256];
  std::snprintf(buf, sizeof(buf), "%-*s %7s %9s %9s %9s %9s %7s", static_cast<int>(width), "estimate", "matched",
                "ATE rmse", "ATE mean", "ATE max", "rot rmse", "MPE");
  t << buf;
  // RPE columns from the first estimate (lengths in % differ in metres per ground-truth segment).
  if (!results.empty()) {
    for (const auto& q : results.front().result.rpe) {
      std::snprintf(buf, sizeof(buf), " %9s", ("RPE@" + fmt("%.3g", q.length_m) + "m").c_str());
      t << buf;
    }
  }
  t << " " << "yaw drift";
  const bool any_rre = std::any_of(results.begin(), results.end(), [](const EstimateEvaluation& e) { return e.rre.has_value(); });
  const bool any_gyro = std::any_of(results.begin(), results.end(), [](const EstimateEvaluation& e) { return e.rre_gyro.has_value(); });
  if (any_rre) t << "  " << fmt("RRE@%gs", args.rre_interval_s) << (any_gyro ? " (gyro)" : "");
  t << "\n";
  std::snprintf(buf, sizeof(buf), "%-*s %7s %9s %9s %9s %9s %7s", static_cast<int>(width), "", "poses", "m", "m",
                "m", "deg", "%");
  t << buf;
  if (!results.empty()) {
    for (size_t k = 0; k < results.front().result.rpe.size(); ++k) t << "         %";
  }
  t << "     deg/m" << (any_rre ? "  deg rms" : "") << "\n";
  for (const auto& e : results) {
    const auto& r = e.result;
    std::snprintf(buf, sizeof(buf), "%-*s %7zu %9.4f %9.4f %9.4f %9.3f %7.3f", static_cast<int>(width),
                  e.label.c_str(), r.matched_poses, r.ate.trans_m.rmse, r.ate.trans_m.mean, r.ate.trans_m.max,
                  r.ate.rot_deg.rmse, r.mean_position_error_percent);
    t << buf;
    for (const auto& q : r.rpe) {
      if (q.count == 0) {
        std::snprintf(buf, sizeof(buf), " %9s", "-");
      } else {
        std::snprintf(buf, sizeof(buf), " %9.3f", q.trans_percent.mean);
      }
      t << buf;
    }
    std::snprintf(buf, sizeof(buf), " %9.5f", r.yaw_drift_deg_per_m);
    t << buf;
    if (e.rre) {
      std::snprintf(buf, sizeof(buf), "  %.4f", e.rre->deg.rmse);
      t << buf;
      if (e.rre_gyro) {
        std::snprintf(buf, sizeof(buf), " (%.4f)", e.rre_gyro->deg.rmse);
        t << buf;
      }
    }
    t << "\n";
  }
  return t.str();
}

int run_eval(const EvalArgs& args, std::ostream& out) {
  const std::vector<EstimateEvaluation> results = evaluate_all(args);
  out << results_table(args, results);
  const std::string dir = !args.out.empty() ? args.out : args.plot;
  if (dir.empty()) return 0;
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw InputError(dir, 0, "cannot create the output folder: " + ec.message(), "a writable path");
  const fs::path d(dir);
  write_file(d / "results.json", results_json(args, results));
  for (const auto& e : results) {
    const auto& r = e.result;
    std::vector<StampedPose> aligned, matched;
    std::string csv = "# t [s], trans_error [m], rot_error [deg]\n";
    for (size_t k = 0; k < r.pairs.size(); ++k) {
      aligned.push_back({r.pairs.t_ns[k], r.aligned_estimate[k]});
      matched.push_back({r.pairs.t_ns[k], r.pairs.groundtruth[k]});
      csv += format_seconds(r.pairs.t_ns[k]) + "," + json_number(r.ate.trans_errors_m[k]) + "," +
             json_number(r.ate.rot_errors_deg[k]) + "\n";
    }
    write_tum((d / (e.name + "_aligned.tum")).string(), Trajectory(std::move(aligned)));
    write_tum((d / (e.name + "_groundtruth.tum")).string(), Trajectory(std::move(matched)));
    write_file(d / (e.name + "_errors.csv"), csv);
  }
  const std::vector<SummaryRow> rows = summarize(results);
  write_file(d / "summary.csv", summary_csv(rows));
  write_file(d / "summary.yaml", summary_yaml(rows));
  write_file(d / "summary.json", summary_json(rows));
  write_file(d / "summary.tex", summary_latex(rows));
  out << "wrote " << (d / "results.json").string() << ", summary.{csv,yaml,json,tex} and per-estimate "
      << "*_aligned.tum, *_groundtruth.tum, *_errors.csv\n";
  if (args.plot.empty()) return 0;

  const std::string script = find_evio_script("plot_trajectory.py", args.plot_script);
  if (script.empty()) {
    log_warning("evio eval --plot: scripts/plot_trajectory.py not found (give it with --plot-script); numeric "
                "outputs are in " + dir);
    return 0;
  }
  const std::string py = args.python;
  const bool have_python = access(py.c_str(), X_OK) == 0;
  const std::string check = shell_quote(py) + " -c 'import numpy, matplotlib' >/dev/null 2>&1";
  if (!have_python || std::system(check.c_str()) != 0) {
    log_warning(std::string("evio eval --plot: ") + (have_python ? py + " cannot import numpy and matplotlib"
                                                                  : py + " not found") +
                "; " + kPlotHint + dir + " --out " + args.plot + "`. Numeric outputs are in " + dir);
    return 0;
  }
  const std::string cmd = shell_quote(py) + " " + shell_quote(script) + " " + shell_quote(dir) + " --out " +
                          shell_quote(args.plot);
  out.flush();
  const int rc = std::system(cmd.c_str());
  if (rc != 0) throw std::runtime_error("plot script failed (" + cmd + ")");
  out << "plots in " << args.plot << "\n";
  return 0;
}

}  // namespace evio::apps
