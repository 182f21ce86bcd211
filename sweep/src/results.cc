#include "evio/sweep/results.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio/calib/json.h"

namespace evio::sweep {
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
  // Numeric output files checked for NaN/Inf ('*' matches within a name); a TIFF may name its coverage
  // mask after ':' (NaN is the TIFF's documented "not seen" value where the mask is 0).
  std::vector<const char*> outputs;
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
        {"mean_position_error_percent_causal", "eval.json", "estimates.1.mean_position_error_percent"},
        {"yaw_drift_deg_per_m", "eval.json", "estimates.0.yaw_drift_deg_per_m"},
        {"final_yaw_error_deg", "eval.json", "estimates.0.final_yaw_error_deg"},
        {"rre_1s_deg", "eval.json", "estimates.0.rre.deg.rmse"},
        {"rre_1s_gyro_deg", "eval.json", "estimates.0.rre.gyro_deg.rmse"},
        {"keyframes", "stats.json", "keyframes"},
        {"rotation_only_keyframes", "stats.json", "rotation_only_keyframes"}},
       "sequence_duration_s", nullptr,
       {"trajectory.tum", "trajectory_causal.tum", "keyframes.txt", "observations.txt", "stats.json", "eval.json"}},
      {{"mosaic", true, "rot_rms_deg", "rotation RMS deg",
        "eval.json of `evio mosaic --gt`: rotation error after the initial orientation, panorama PSNR/SSIM against the "
        "simulator's panorama when it exists"},
       {{"rot_rms_deg", "eval.json", "rot_rms_deg"},
        {"rot_max_deg", "eval.json", "rot_max_deg"},
        {"psnr_db", "eval.json", "mosaic_quality.psnr_db"},
        {"ssim", "eval.json", "mosaic_quality.ssim"},
        {"events", "stats.json", "events"},
        {"mean_particles", "stats.json", "tracker.mean_particles"},
        {"events_per_cpu_s", "stats.json", "events_per_cpu_s"}},
       "sequence_duration_s", nullptr,
       {"rotation.tum", "stats.json", "eval.json", "panorama_log.tiff:panorama_seen.png"}},
      {{"flow", false, "angular_velocity_rms_degps", "angular velocity RMS deg/s",
        "stats.json of `evio flow`: angular-velocity error against the dataset's ground truth (rotation model only; "
        "other models have no ground-truth error), events vs gyro"},
       {{"angular_velocity_rms_degps", "stats.json", "groundtruth.rms_error_degps"},
        {"angular_velocity_median_degps", "stats.json", "groundtruth.median_error_degps"},
        {"events_vs_gyro_rms_degps", "stats.json", "gyro.events_vs_gyro_rms_degps"},
        {"windows", "stats.json", "windows"},
        {"events", "stats.json", "events"},
        {"time_per_event_us", "stats.json", "time_per_event_us"}},
       "duration_s", nullptr,
       {"motion.csv", "motion_eval.csv", "stats.json"}},
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
       "duration_s", nullptr,
       {"corners.txt", "tracks.txt", "stats.json", "eval.json"}},
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
       nullptr, nullptr,
       {"labels.txt", "segments.json", "stats.json", "eval.json"}},
      {{"reconstruct", false, "ssim_error", "1 - SSIM",
        "eval.json of `evio reconstruct` on a simulated dataset: every image against the clean view rendered at its "
        "time (log intensity, global affine fit); ssim_error = 1 - mean SSIM, psnr_db the mean PSNR"},
       {{"ssim_error", "eval.json", "ssim_error"},
        {"psnr_db", "eval.json", "psnr_db"},
        {"ssim", "eval.json", "ssim"},
        {"images", "stats.json", "images"},
        {"events", "stats.json", "events"},
        {"time_per_event_ns", "stats.json", "time_per_event_ns"}},
       "t_last_s", "t_first_s",
       {"images.txt", "images/*.tiff", "corners.txt", "stats.json", "eval.json"}},
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
  return json_string(v);
}

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

// A parsed JSON value back as compact JSON: quoted scalars (tag "!") stay strings, plain ones are
// numbers, true, false or null when they read as such.
std::string to_json(const YAML::Node& n) {
  if (n.IsMap()) {
    std::string s = "{";
    bool first = true;
    for (const auto& kv : n) {
      s += (first ? "" : ", ") + json_string(kv.first.Scalar()) + ": " + to_json(kv.second);
      first = false;
    }
    return s + "}";
  }
  if (n.IsSequence()) {
    std::string s = "[";
    for (size_t i = 0; i < n.size(); ++i) s += (i ? ", " : "") + to_json(n[i]);
    return s + "]";
  }
  if (!n.IsScalar()) return "null";
  const std::string& v = n.Scalar();
  if (n.Tag() != "!") {
    if (v == "true" || v == "false" || v == "null") return v;
    char* end = nullptr;
    const double d = std::strtod(v.c_str(), &end);
    if (!v.empty() && *end == '\0' && std::isfinite(d)) return v;
  }
  return json_string(v);
}

}  // namespace

std::string sweep_model_summary(const SweepRecord& r) {
  if (r.model_json.empty()) return "";
  try {
    const YAML::Node n = YAML::Load(r.model_json);
    return n.IsMap() ? text(n, "summary") : std::string();
  } catch (const YAML::Exception&) {
    return "";
  }
}

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
  const YAML::Node& stats = file("stats.json");
  r->model_json.clear();
  if (stats.IsMap()) {
    const YAML::Node model = stats["model"];  // invalid (false) when absent: IsMap() on it would throw
    if (model && model.IsMap()) r->model_json = to_json(model);
  }
}

namespace {

// A file name matches a pattern whose '*' matches any run of characters within the name.
bool name_matches(const std::string& pattern, const std::string& name) {
  const size_t star = pattern.find('*');
  if (star == std::string::npos) return pattern == name;
  const std::string head = pattern.substr(0, star), tail = pattern.substr(star + 1);
  return name.size() >= head.size() + tail.size() && name.compare(0, head.size(), head) == 0 &&
         name.compare(name.size() - tail.size(), tail.size(), tail) == 0;
}

// A word of a text output that spells a non-finite number (how printf, iostreams and JSON writers
// print NaN and Inf).
bool nonfinite_word(std::string w) {
  std::transform(w.begin(), w.end(), w.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (!w.empty() && (w[0] == '-' || w[0] == '+')) w.erase(0, 1);
  return w == "nan" || w == "inf" || w == "infinity" || w.rfind("nan(", 0) == 0;
}

std::string nonfinite_in_text(const fs::path& file, const std::string& rel) {
  std::ifstream f(file);
  std::string line;
  for (int no = 1; std::getline(f, line); ++no) {
    std::string word;
    for (size_t i = 0; i <= line.size(); ++i) {
      const char c = i < line.size() ? line[i] : ' ';
      if (std::isspace(static_cast<unsigned char>(c)) || c == ',' || c == ':' || c == '[' || c == ']' || c == '{' ||
          c == '}' || c == '"' || c == ';') {
        if (nonfinite_word(word)) return rel + ":" + std::to_string(no) + ": " + word;
        word.clear();
      } else {
        word += c;
      }
    }
  }
  return "";
}

// A float TIFF: no Inf anywhere; no NaN where the mask (an 8-bit PNG, same size) is non-zero, or
// anywhere when there is no mask file.
std::string nonfinite_in_tiff(const fs::path& file, const std::string& rel, const fs::path& mask_file) {
  cv::Mat m = cv::imread(file.string(), cv::IMREAD_UNCHANGED);
  if (m.empty() || (m.depth() != CV_32F && m.depth() != CV_64F) || m.channels() != 1) return "";
  m.convertTo(m, CV_64F);
  const cv::Mat mask = mask_file.empty() ? cv::Mat() : cv::imread(mask_file.string(), cv::IMREAD_GRAYSCALE);
  const bool masked = !mask.empty() && mask.size() == m.size();
  for (int y = 0; y < m.rows; ++y) {
    for (int x = 0; x < m.cols; ++x) {
      const double v = m.at<double>(y, x);
      if (std::isinf(v) || (std::isnan(v) && (!masked || mask.at<uint8_t>(y, x) != 0))) {
        return rel + ": pixel (" + std::to_string(x) + ", " + std::to_string(y) + ") is " + (std::isnan(v) ? "NaN" : "Inf") +
               (masked ? " where " + mask_file.filename().string() + " marks it seen" : "");
      }
    }
  }
  return "";
}

}  // namespace

std::string find_nonfinite_output(const std::string& algorithm, const std::string& out_dir) {
  for (const char* entry : metrics_of(algorithm).outputs) {
    const std::string e(entry);
    const size_t colon = e.find(':');
    const fs::path rel(e.substr(0, colon));
    const std::string mask = colon == std::string::npos ? "" : e.substr(colon + 1);
    const fs::path folder = fs::path(out_dir) / rel.parent_path();
    std::vector<std::string> names;
    std::error_code ec;
    for (fs::directory_iterator it(folder, ec), end; !ec && it != end; it.increment(ec)) {
      if (it->is_regular_file(ec) && name_matches(rel.filename().string(), it->path().filename().string())) {
        names.push_back(it->path().filename().string());
      }
    }
    std::sort(names.begin(), names.end());
    for (const std::string& n : names) {
      const std::string r = (rel.parent_path() / n).string();
      const std::string found = fs::path(n).extension() == ".tiff"
                                    ? nonfinite_in_tiff(folder / n, r, mask.empty() ? fs::path() : fs::path(out_dir) / mask)
                                    : nonfinite_in_text(folder / n, r);
      if (!found.empty()) return found;
    }
  }
  return "";
}

void classify_cell_outcome(const std::string& algorithm, const std::string& out_dir, const std::string& stderr_path,
                           SweepRecord* r) {
  r->outcome_detail.clear();
  if (r->timed_out) {
    r->outcome = "hang";
    r->outcome_detail = "killed after the timeout";
  } else if (r->exit_code == 1) {
    r->outcome = "error";
    std::ifstream f(stderr_path);
    std::string line;
    while (std::getline(f, line)) {
      while (!line.empty() && std::isspace(static_cast<unsigned char>(line.back()))) line.pop_back();
      if (!line.empty()) r->outcome_detail = line;
    }
    if (r->outcome_detail.size() > 400) r->outcome_detail = r->outcome_detail.substr(0, 400) + "...";
  } else if (r->exit_code != 0) {
    r->outcome = "crash";
    r->outcome_detail = r->exit_code < 0 ? "killed by signal " + std::to_string(-r->exit_code) : "exit code " + std::to_string(r->exit_code);
  } else {
    r->outcome_detail = find_nonfinite_output(algorithm, out_dir);
    r->outcome = r->outcome_detail.empty() ? "ok" : "nonfinite";
  }
}

bool sweep_outcome_is_defect(const std::string& outcome) {
  return outcome == "crash" || outcome == "hang" || outcome == "nonfinite";
}

std::string sweep_record_json(const SweepRecord& r) {
  std::ostringstream j;
  j << "{\"cell\": " << json_string(r.cell) << ", \"algorithm\": " << json_string(r.algorithm) << ", \"variant\": " << json_string(r.variant)
    << ", \"dataset\": " << json_string(r.dataset) << ", \"dataset_path\": " << json_string(r.dataset_path) << ", \"params\": {";
  for (size_t i = 0; i < r.params.size(); ++i) j << (i ? ", " : "") << json_string(r.params[i].first) << ": " << json_value(r.params[i].second);
  j << "}, \"args\": [";
  for (size_t i = 0; i < r.args.size(); ++i) j << (i ? ", " : "") << json_string(r.args[i]);
  j << "], \"exit_code\": " << r.exit_code << ", \"timed_out\": " << json_bool(r.timed_out)
    << ", \"wall_s\": " << json_number(r.wall_s, 6) << ", \"cpu_s\": " << json_number(r.cpu_s, 6)
    << ", \"peak_rss_mb\": " << json_number(r.peak_rss_mb, 6) << ", \"duration_s\": " << json_number(r.duration_s, 9)
    << ", \"real_time_factor\": " << json_number(r.duration_s > 0 ? r.wall_s / r.duration_s : NAN, 6)
    << ", \"real_time_factor_cpu\": " << json_number(r.duration_s > 0 ? r.cpu_s / r.duration_s : NAN, 6)
    << ", \"metrics\": {";
  for (size_t i = 0; i < r.metrics.size(); ++i) j << (i ? ", " : "") << json_string(r.metrics[i].first) << ": " << json_number(r.metrics[i].second, 9);
  j << "}, \"error_metric\": " << (r.error_metric.empty() ? "null" : json_string(r.error_metric)) << ", \"note\": " << json_string(r.note)
    << ", \"outcome\": " << json_string(r.outcome) << ", \"outcome_detail\": " << json_string(r.outcome_detail)
    << ", \"engine\": " << json_string(r.engine) << ", \"host\": " << json_string(r.host) << ", \"started_utc\": " << json_string(r.started_utc)
    << ", \"model\": " << (r.model_json.empty() ? "null" : r.model_json) << "}\n";
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
    r.outcome = text(n, "outcome");
    r.outcome_detail = text(n, "outcome_detail");
    r.engine = text(n, "engine");
    r.host = text(n, "host");
    r.started_utc = text(n, "started_utc");
    if (const YAML::Node model = n["model"]; model && model.IsMap()) r.model_json = to_json(model);
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

}  // namespace evio::sweep
