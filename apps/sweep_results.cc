#include "sweep_results.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <yaml-cpp/yaml.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "json_util.h"

namespace evio::apps {
namespace fs = std::filesystem;

namespace {

// A metric read from a cell's output file: a dotted path into its JSON (list items by index).
struct MetricSource {
  const char* name;
  const char* file;
  const char* path;
};

struct AlgorithmMetrics {
  SweepAlgorithmInfo info;
  std::vector<MetricSource> metrics;
  const char* duration_path;        // in stats.json; nullptr: unknown
  const char* duration_start_path;  // subtracted when set (reconstruct: t_last_s - t_first_s)
};

const std::vector<AlgorithmMetrics>& algorithm_metrics() {
  static const std::vector<AlgorithmMetrics> k = {
      {{"vio", true, "ate_rmse_m", "ATE RMSE m",
        "eval.json of `evio vio --gt` (rpg_trajectory_evaluation protocol, the command's alignment); rpe_trans_percent: "
        "mean relative translation error at the first RPE length"},
       {{"ate_rmse_m", "eval.json", "estimates.0.ate.trans_m.rmse"},
        {"ate_rot_rmse_deg", "eval.json", "estimates.0.ate.rot_deg.rmse"},
        {"rpe_trans_percent", "eval.json", "estimates.0.rpe.0.trans_percent.mean"},
        {"mean_position_error_percent", "eval.json", "estimates.0.mean_position_error_percent"},
        {"yaw_drift_deg_per_m", "eval.json", "estimates.0.yaw_drift_deg_per_m"},
        {"keyframes", "stats.json", "keyframes"},
        {"rotation_only_keyframes", "stats.json", "rotation_only_keyframes"}},
       "sequence_duration_s", nullptr},
      {{"mosaic", true, "rot_rms_deg", "rotation RMS deg",
        "eval.json of `evio mosaic --gt`: rotation error after the initial orientation, panorama PSNR/SSIM against the "
        "simulator's panorama when it exists"},
       {{"rot_rms_deg", "eval.json", "rot_rms_deg"},
        {"rot_max_deg", "eval.json", "rot_max_deg"},
        {"psnr_db", "eval.json", "mosaic_quality.psnr_db"},
        {"ssim", "eval.json", "mosaic_quality.ssim"},
        {"events", "stats.json", "events"},
        {"mean_particles", "stats.json", "tracker.mean_particles"}},
       "sequence_duration_s", nullptr},
      {{"flow", false, "angular_velocity_rms_degps", "angular velocity RMS deg/s",
        "stats.json of `evio flow`: angular-velocity error against the dataset's ground truth (rotation model only; "
        "other models have no ground-truth error), events vs gyro"},
       {{"angular_velocity_rms_degps", "stats.json", "groundtruth.rms_error_degps"},
        {"angular_velocity_median_degps", "stats.json", "groundtruth.median_error_degps"},
        {"events_vs_gyro_rms_degps", "stats.json", "gyro.events_vs_gyro_rms_degps"},
        {"windows", "stats.json", "windows"},
        {"events", "stats.json", "events"},
        {"time_per_event_us", "stats.json", "time_per_event_us"}},
       "duration_s", nullptr},
      {{"corners", false, "f_error", "1 - F (precision, recall)",
        "eval.json of `evio corners` on a simulated scene with checkerboard planes: corner events against the grid "
        "nodes projected through the true pose (2 px); f_error = 1 - harmonic mean of precision and (corner, 50 ms) "
        "recall"},
       {{"f_error", "eval.json", "f_error"},
        {"precision", "eval.json", "precision"},
        {"pair_recall", "eval.json", "pair_recall"},
        {"corners", "stats.json", "corners"},
        {"reduction_rate", "stats.json", "reduction_rate"},
        {"tracks", "stats.json", "tracks.count"},
        {"events", "stats.json", "events"},
        {"ns_per_event", "stats.json", "ns_per_event"}},
       "duration_s", nullptr},
      {{"segment", false, "label_error", "label error (1 - accuracy)",
        "eval.json of `evio segment` against the simulator's event_labels.txt: per window, clusters mapped to true "
        "objects by majority; label_error = 1 - share of true-labelled events right (unsegmented count as wrong)"},
       {{"label_error", "eval.json", "label_error"},
        {"accuracy_in_windows", "eval.json", "accuracy_in_windows"},
        {"windows", "stats.json", "windows"},
        {"labels_used", "stats.json", "labels_used"},
        {"events_labelled", "stats.json", "events_labelled"},
        {"events_noise", "stats.json", "events_noise"},
        {"time_per_event_us", "stats.json", "time_per_event_us"}},
       nullptr, nullptr},
      {{"reconstruct", false, "ssim_error", "1 - SSIM",
        "eval.json of `evio reconstruct` on a simulated dataset: every image against the clean view rendered at its "
        "time (log intensity, global affine fit); ssim_error = 1 - mean SSIM, psnr_db the mean PSNR"},
       {{"ssim_error", "eval.json", "ssim_error"},
        {"psnr_db", "eval.json", "psnr_db"},
        {"ssim", "eval.json", "ssim"},
        {"images", "stats.json", "images"},
        {"events", "stats.json", "events"},
        {"time_per_event_ns", "stats.json", "time_per_event_ns"}},
       "t_last_s", "t_first_s"},
  };
  return k;
}

const AlgorithmMetrics& metrics_of(const std::string& algorithm) {
  for (const AlgorithmMetrics& a : algorithm_metrics()) {
    if (a.info.name == algorithm) return a;
  }
  throw std::invalid_argument("evio sweep: no metrics for the algorithm '" + algorithm + "'");
}

// The number at a dotted path, NaN when the path or the number is missing.
double number_at(const YAML::Node& root, const std::string& path) {
  if (!root) return NAN;
  YAML::Node n;
  n.reset(root);  // Node::operator= would assign into the document: walk by reset()
  std::stringstream ss(path);
  std::string part;
  while (std::getline(ss, part, '.')) {
    if (n.IsSequence()) {
      char* end = nullptr;
      const unsigned long i = std::strtoul(part.c_str(), &end, 10);
      if (*end != '\0' || i >= n.size()) return NAN;
      n.reset(n[i]);
    } else if (n.IsMap()) {
      const YAML::Node child = n[part];
      if (!child) return NAN;
      n.reset(child);
    } else {
      return NAN;
    }
  }
  if (!n.IsScalar()) return NAN;
  try {
    return n.as<double>();
  } catch (const YAML::Exception&) {
    return NAN;
  }
}

YAML::Node load_json(const std::string& file) {
  std::error_code ec;
  if (!fs::exists(file, ec)) return YAML::Node();
  try {
    return YAML::LoadFile(file);  // JSON is YAML's flow style
  } catch (const YAML::Exception& e) {
    log_warning("evio sweep: " + file + ": cannot parse (" + e.msg + ")");
    return YAML::Node();
  }
}

// A parameter value as JSON: a number when the YAML value is one, a string otherwise.
std::string json_value(const std::string& v) {
  char* end = nullptr;
  const double d = std::strtod(v.c_str(), &end);
  if (!v.empty() && *end == '\0' && std::isfinite(d) && v.find_first_of("xXnN") == std::string::npos) return v;
  if (v == "true" || v == "false") return v;
  return "\"" + json_escape(v) + "\"";
}

std::string quoted(const std::string& s) { return "\"" + json_escape(s) + "\""; }

std::string text(const YAML::Node& n, const char* key) {
  const YAML::Node v = n[key];
  return v && v.IsScalar() ? v.Scalar() : std::string();
}

double num(const YAML::Node& n, const char* key) {
  const YAML::Node v = n[key];
  if (!v || !v.IsScalar()) return NAN;
  try {
    return v.as<double>();
  } catch (const YAML::Exception&) {
    return NAN;
  }
}

}  // namespace

double SweepRecord::metric(const std::string& name) const {
  for (const auto& [k, v] : metrics) {
    if (k == name) return v;
  }
  return NAN;
}

const SweepAlgorithmInfo& sweep_algorithm_info(const std::string& algorithm) { return metrics_of(algorithm).info; }

void read_cell_metrics(const std::string& algorithm, const std::string& out_dir, SweepRecord* r) {
  const AlgorithmMetrics& a = metrics_of(algorithm);
  std::map<std::string, YAML::Node> files;
  auto file = [&](const std::string& name) -> const YAML::Node& {
    auto it = files.find(name);
    if (it == files.end()) it = files.emplace(name, load_json((fs::path(out_dir) / name).string())).first;
    return it->second;
  };
  r->metrics.clear();
  for (const MetricSource& m : a.metrics) r->metrics.emplace_back(m.name, number_at(file(m.file), m.path));
  r->error_metric = a.info.error_metric;
  // corners, segment, reconstruct score themselves only on datasets with the truth (simulated):
  // without their eval.json the cell has no headline error, as for a command without one.
  for (const MetricSource& m : a.metrics) {
    std::error_code ec;
    if (!a.info.gt_flag && m.name == a.info.error_metric && std::string(m.file) == "eval.json" &&
        !fs::exists(fs::path(out_dir) / m.file, ec))
      r->error_metric.clear();
  }
  r->note = a.info.note;
  r->duration_s = NAN;
  if (a.duration_path) {
    r->duration_s = number_at(file("stats.json"), a.duration_path);
    if (a.duration_start_path) r->duration_s -= number_at(file("stats.json"), a.duration_start_path);
  }
}

std::string sweep_record_json(const SweepRecord& r) {
  std::ostringstream j;
  j << "{\"cell\": " << quoted(r.cell) << ", \"algorithm\": " << quoted(r.algorithm) << ", \"variant\": " << quoted(r.variant)
    << ", \"dataset\": " << quoted(r.dataset) << ", \"dataset_path\": " << quoted(r.dataset_path) << ", \"params\": {";
  for (size_t i = 0; i < r.params.size(); ++i) j << (i ? ", " : "") << quoted(r.params[i].first) << ": " << json_value(r.params[i].second);
  j << "}, \"args\": [";
  for (size_t i = 0; i < r.args.size(); ++i) j << (i ? ", " : "") << quoted(r.args[i]);
  j << "], \"exit_code\": " << r.exit_code << ", \"timed_out\": " << (r.timed_out ? "true" : "false")
    << ", \"wall_s\": " << json_number(r.wall_s, 6) << ", \"cpu_s\": " << json_number(r.cpu_s, 6)
    << ", \"peak_rss_mb\": " << json_number(r.peak_rss_mb, 6) << ", \"duration_s\": " << json_number(r.duration_s, 9)
    << ", \"real_time_factor\": " << json_number(r.duration_s > 0 ? r.wall_s / r.duration_s : NAN, 6)
    << ", \"real_time_factor_cpu\": " << json_number(r.duration_s > 0 ? r.cpu_s / r.duration_s : NAN, 6)
    << ", \"metrics\": {";
  for (size_t i = 0; i < r.metrics.size(); ++i) j << (i ? ", " : "") << quoted(r.metrics[i].first) << ": " << json_number(r.metrics[i].second, 9);
  j << "}, \"error_metric\": " << (r.error_metric.empty() ? "null" : quoted(r.error_metric)) << ", \"note\": " << quoted(r.note)
    << ", \"engine\": " << quoted(r.engine) << ", \"host\": " << quoted(r.host) << ", \"started_utc\": " << quoted(r.started_utc)
    << "}\n";
  return j.str();
}

void append_sweep_record(const std::string& results_path, const SweepRecord& r) {
  std::string line = sweep_record_json(r);
  const int fd = open(results_path.c_str(), O_RDWR | O_APPEND | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) throw std::runtime_error(results_path + ": cannot open for appending: " + std::strerror(errno));
  while (flock(fd, LOCK_EX) != 0 && errno == EINTR) {
  }
  // A line left torn by a crash (no final newline) stays its own, skipped line.
  struct stat st {};
  char last = '\n';
  if (fstat(fd, &st) == 0 && st.st_size > 0 && pread(fd, &last, 1, st.st_size - 1) == 1 && last != '\n') line.insert(0, "\n");
  ssize_t n;
  do {
    n = write(fd, line.data(), line.size());
  } while (n < 0 && errno == EINTR);
  const int err = errno;
  flock(fd, LOCK_UN);
  close(fd);
  if (n != static_cast<ssize_t>(line.size())) {
    throw std::runtime_error(results_path + ": short write of a result line (" + std::strerror(err) + ")");
  }
}

std::vector<SweepRecord> read_sweep_records(const std::string& results_path) {
  std::vector<SweepRecord> out;
  std::ifstream f(results_path);
  std::string line;
  for (int no = 1; std::getline(f, line); ++no) {
    if (line.empty()) continue;
    YAML::Node n;
    try {
      n = YAML::Load(line);
    } catch (const YAML::Exception&) {
    }
    if (!n.IsMap() || text(n, "cell").empty() || !n["exit_code"]) {
      log_warning("evio sweep: " + results_path + ":" + std::to_string(no) + ": not a result record, skipped (a torn write?)");
      continue;
    }
    SweepRecord r;
    r.cell = text(n, "cell");
    r.algorithm = text(n, "algorithm");
    r.variant = text(n, "variant");
    r.dataset = text(n, "dataset");
    r.dataset_path = text(n, "dataset_path");
    if (n["params"].IsMap()) {
      for (const auto& kv : n["params"]) r.params.emplace_back(kv.first.Scalar(), kv.second.Scalar());
    }
    if (n["args"].IsSequence()) {
      for (const YAML::Node& a : n["args"]) r.args.push_back(a.Scalar());
    }
    r.exit_code = static_cast<int>(num(n, "exit_code"));
    r.timed_out = text(n, "timed_out") == "true";
    r.wall_s = num(n, "wall_s");
    r.cpu_s = num(n, "cpu_s");
    r.peak_rss_mb = num(n, "peak_rss_mb");
    r.duration_s = num(n, "duration_s");
    if (n["metrics"].IsMap()) {
      for (const auto& kv : n["metrics"]) r.metrics.emplace_back(kv.first.Scalar(), num(n["metrics"], kv.first.Scalar().c_str()));
    }
    r.error_metric = text(n, "error_metric");
    if (r.error_metric == "null" || r.error_metric == "~") r.error_metric.clear();
    r.note = text(n, "note");
    r.engine = text(n, "engine");
    r.host = text(n, "host");
    r.started_utc = text(n, "started_utc");
    out.push_back(std::move(r));
  }
  return out;
}

std::string sweep_read_file(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

void sweep_write_file(const std::string& path, const std::string& text) {
  std::ofstream f(path, std::ios::binary);
  f << text;
  if (!f.flush()) throw InputError(path, 0, "write failed", "a writable folder with free space");
}

std::map<std::string, SweepRecord> latest_sweep_records(const std::vector<SweepRecord>& records) {
  std::map<std::string, SweepRecord> out;
  for (const SweepRecord& r : records) out[r.cell] = r;
  return out;
}

}  // namespace evio::apps
