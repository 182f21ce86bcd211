#include "evio/sweep/spec.h"

#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cctype>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include "evio/calib/error.h"

namespace evio::sweep {
namespace fs = std::filesystem;

namespace {

const char* kSpecForm =
    "a mapping with `datasets:` (a list of {name, path}, {name, scene, duration, seed, set} or {name, generate: [PROGRAM, ARG, ..., {out}]}) and `algorithms:` (a list "
    "of {algorithm, variant, datasets, args, grid, timeout_s}), optional `name:`, `timeout_s:`, `report: [extremes]`, `mean_over: [GRID_KEY]` and `accept_errors: true|false`";

class SpecReader {
 public:
  SpecReader(std::string file, std::string dir) : file_(std::move(file)), dir_(std::move(dir)) {}

  [[noreturn]] void fail(const YAML::Node& n, const std::string& problem, const std::string& expected) const {
    throw InputError(file_, n.Mark().line >= 0 ? n.Mark().line + 1 : 0, problem, expected);
  }

  std::string scalar(const YAML::Node& n, const std::string& what) const {
    if (!n.IsScalar()) fail(n, what + " is not a scalar", "a single value, e.g. `" + what + ": value`");
    return n.Scalar();
  }

  // A scalar value as text, or a sequence/mapping in YAML flow style (a list-valued config key).
  static std::string value_text(const YAML::Node& n) {
    if (n.IsScalar()) return n.Scalar();
    YAML::Emitter e;
    e.SetMapFormat(YAML::Flow);
    e.SetSeqFormat(YAML::Flow);
    e << n;
    return e.c_str();
  }

  double seconds(const YAML::Node& n, const std::string& what) const {
    const std::string s = scalar(n, what);
    try {
      size_t used = 0;
      const double v = std::stod(s, &used);
      if (used == s.size() && v >= 0) return v;
    } catch (const std::exception&) {
    }
    fail(n, what + " '" + s + "' is not a number of seconds >= 0", "e.g. `" + what + ": 60`");
  }

  std::vector<std::string> strings(const YAML::Node& n, const std::string& what) const {
    std::vector<std::string> out;
    if (n.IsScalar()) return {n.Scalar()};
    if (!n.IsSequence()) fail(n, what + " is not a list", "a list, e.g. `" + what + ": [a, b]`");
    for (const YAML::Node& v : n) out.push_back(scalar(v, what + " item"));
    return out;
  }

  std::string name(const YAML::Node& n, const std::string& what) const {
    std::string s = scalar(n, what);
    const bool ok = !s.empty() && std::all_of(s.begin(), s.end(), [](char c) {
      return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.' || c == '+';
    });
    if (!ok) fail(n, what + " '" + s + "' is not a plain name", "letters, digits, '_', '-', '.', '+' (it names a folder)");
    return s;
  }

  // `{env:NAME}` replaced by the environment variable NAME (e.g. where the real data lives); an unset or
  // empty variable is an error at the node's line.
  std::string with_env(const YAML::Node& n, std::string s) const {
    for (size_t p = s.find("{env:"); p != std::string::npos; p = s.find("{env:", p)) {
      const size_t end = s.find('}', p);
      if (end == std::string::npos) fail(n, "'" + s + "' has an unclosed {env:", "{env:NAME}, NAME an environment variable");
      const std::string var = s.substr(p + 5, end - p - 5);
      const char* v = std::getenv(var.c_str());
      if (v == nullptr || *v == '\0') fail(n, "'" + s + "' needs the environment variable " + var + ", which is not set", "export " + var + "=VALUE");
      s.replace(p, end + 1 - p, v);
      p += std::strlen(v);
    }
    return s;
  }

  std::string existing_path(const YAML::Node& n, const std::string& what) const {
    const std::string s = with_env(n, scalar(n, what));
    fs::path p(s);
    if (p.is_relative()) p = fs::path(dir_) / p;
    p = p.lexically_normal();
    std::error_code ec;
    if (!fs::exists(p, ec)) fail(n, what + " " + p.string() + ": no such file or directory", "a path relative to the spec's folder or absolute");
    return p.string();
  }

  // `{spec_dir}` replaced by the spec's folder (a generator's program or its files next to the spec).
  std::string substitute_spec_dir(std::string s) const {
    for (size_t p = s.find("{spec_dir}"); p != std::string::npos; p = s.find("{spec_dir}", p + dir_.size())) s.replace(p, 10, dir_);
    return s;
  }

  void keys(const YAML::Node& n, const std::set<std::string>& allowed, const std::string& what, const std::string& form) const {
    if (!n.IsMap()) fail(n, what + " is not a mapping", form);
    for (const auto& kv : n) {
      const std::string k = kv.first.Scalar();
      if (!allowed.count(k)) {
        std::string why = "unknown key '" + k;
        why += "' in ";
        why += what;
        fail(kv.first, why, form);
      }
    }
  }

  SweepDataset dataset(const YAML::Node& n) const {
    const std::string form = "{name: NAME, path: RECORDING}, {name: NAME, scene: SCENE.yaml, duration: S, seed: N, set: [key=value]} "
                             "or {name: NAME, generate: [PROGRAM, ARG, ..., {out}]}";
    SweepDataset d;
    if (n.IsScalar()) {
      d.path = existing_path(n, "dataset path");
    } else {
      keys(n, {"name", "path", "scene", "duration", "seed", "set", "generate"}, "a dataset", form);
      if (n["generate"]) {
        if (n["path"] || n["scene"] || n["duration"] || n["seed"] || n["set"]) fail(n, "`generate` takes no path, scene, duration, seed or set", form);
        if (!n["name"]) fail(n, "a generated dataset needs a `name`", form);
        d.name = name(n["name"], "name");
        for (const std::string& a : strings(n["generate"], "generate")) d.generate.push_back(substitute_spec_dir(with_env(n["generate"], a)));
        if (d.generate.empty()) fail(n["generate"], "`generate` is empty", form);
        if (std::none_of(d.generate.begin(), d.generate.end(), [](const std::string& a) { return a.find("{out}") != std::string::npos; }))
          fail(n["generate"], "`generate` has no {out}", "the dataset folder as {out} among the generator's arguments");
        return d;
      }
      if (n["path"].IsDefined() == n["scene"].IsDefined()) fail(n, "a dataset needs exactly one of `path`, `scene` and `generate`", form);
      if (n["path"]) d.path = existing_path(n["path"], "path");
      if (n["scene"]) d.scene = existing_path(n["scene"], "scene");
      if (n["path"] && (n["duration"] || n["seed"] || n["set"])) fail(n, "duration, seed and set apply to a `scene` only", form);
      if (n["duration"]) {
        seconds(n["duration"], "duration");  // checked; passed on as written
        d.duration_s = n["duration"].Scalar();
      }
      if (n["seed"]) d.seed = scalar(n["seed"], "seed");
      if (n["set"]) {
        if (n["set"].IsMap()) {
          for (const auto& kv : n["set"]) d.set.push_back(kv.first.Scalar() + "=" + with_env(kv.second, value_text(kv.second)));
        } else {
          for (const std::string& s : strings(n["set"], "set")) d.set.push_back(with_env(n["set"], s));
        }
      }
      if (n["name"]) d.name = name(n["name"], "name");
    }
    if (d.name.empty()) {  // the file or folder name without extension
      fs::path p = fs::path(d.simulated() ? d.scene : d.path);
      if (!p.has_filename()) p = p.parent_path();
      d.name = p.stem().string();
    }
    return d;
  }

  SweepAlgorithm algorithm(const YAML::Node& n, const std::set<std::string>& dataset_names) const {
    const std::string form = "{algorithm: vio|mosaic|corners|flow|segment|reconstruct, variant: NAME, datasets: [NAME], "
                             "args: [--flag, value], grid: {config.key: [v1, v2]}, timeout_s: S}";
    keys(n, {"algorithm", "variant", "datasets", "args", "grid", "timeout_s"}, "an algorithm entry", form);
    SweepAlgorithm a;
    a.line = n.Mark().line + 1;
    if (!n["algorithm"]) fail(n, "an algorithm entry without `algorithm`", form);
    a.algorithm = scalar(n["algorithm"], "algorithm");
    const auto& known = sweep_algorithms();
    if (std::find(known.begin(), known.end(), a.algorithm) == known.end()) {
      std::string list;
      for (const std::string& k : known) list += (list.empty() ? "" : ", ") + k;
      fail(n["algorithm"], "unknown algorithm '" + a.algorithm + "'", "one of " + list);
    }
    if (n["variant"]) a.variant = name(n["variant"], "variant");
    if (n["datasets"]) {
      a.datasets = strings(n["datasets"], "datasets");
      for (const std::string& d : a.datasets) {
        if (!dataset_names.count(d)) fail(n["datasets"], "unknown dataset '" + d + "'", "a name from `datasets:`");
      }
    }
    if (n["args"]) {
      for (const std::string& s : strings(n["args"], "args")) a.args.push_back(with_env(n["args"], s));
      for (const std::string& s : a.args) {
        if (s == "-o" || s == "--out" || s.rfind("--out=", 0) == 0) fail(n["args"], "args sets --out", "arguments other than --out (each cell's folder is its --out)");
      }
    }
    if (n["grid"]) {
      const YAML::Node g = n["grid"];
      if (!g.IsMap()) fail(g, "grid is not a mapping", "config keys to lists of values, e.g. `grid: {frames.events_per_frame: [5000, 15000]}`");
      for (const auto& kv : g) {
        const std::string key = kv.first.Scalar();
        const bool ok = !key.empty() && std::all_of(key.begin(), key.end(), [](char c) {
          return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '.';
        });
        if (!ok) fail(kv.first, "grid key '" + key + "' is not a config key", "a dotted key of the command's config, e.g. frames.events_per_frame");
        std::vector<std::string> values;
        if (kv.second.IsSequence()) {
          for (const YAML::Node& v : kv.second) values.push_back(value_text(v));
        } else if (kv.second.IsScalar()) {
          values.push_back(kv.second.Scalar());
        }
        if (values.empty()) fail(kv.second, "grid key '" + key + "' has no values", "a non-empty list, e.g. `" + key + ": [1, 2]`");
        a.grid.emplace_back(key, values);
      }
    }
    if (n["timeout_s"]) a.timeout_s = seconds(n["timeout_s"], "timeout_s");
    return a;
  }

 private:
  std::string file_, dir_;
};

// The report's keys of a spec: `name:`, `report: [extremes]`, `mean_over: [GRID_KEY]`.
SweepReportSettings report_settings(const SpecReader& r, const YAML::Node& root) {
  SweepReportSettings rs;
  if (root["name"]) rs.name = r.scalar(root["name"], "name");
  if (root["report"]) {
    for (const std::string& s : r.strings(root["report"], "report")) {
      if (s != "extremes") r.fail(root["report"], "unknown report section '" + s + "'", "`report: [extremes]`");
      rs.extremes = true;
    }
  }
  if (root["mean_over"]) {
    rs.mean_over = r.strings(root["mean_over"], "mean_over");
    if (rs.mean_over.empty()) r.fail(root["mean_over"], "mean_over is empty", "grid keys, e.g. `mean_over: [tracker.seed]`");
  }
  return rs;
}

uint64_t fnv1a(const std::string& s) {
  uint64_t h = 1469598103934665603ull;
  for (unsigned char c : s) h = (h ^ c) * 1099511628211ull;
  return h;
}

std::string substitute(std::string s, const std::string& key, const std::string& value) {
  for (size_t p = s.find(key); p != std::string::npos; p = s.find(key, p + value.size())) s.replace(p, key.size(), value);
  return s;
}

}  // namespace

const std::vector<std::string>& sweep_algorithms() {
  static const std::vector<std::string> k = {"vio", "mosaic", "corners", "flow", "segment", "reconstruct"};
  return k;
}

SweepSpec parse_sweep_spec(const std::string& text, const std::string& file, const std::string& dir) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& e) {
    throw InputError(file, e.mark.line >= 0 ? e.mark.line + 1 : 0, "YAML syntax: " + e.msg, kSpecForm);
  }
  SpecReader r(file, dir);
  if (!root.IsMap()) throw InputError(file, root.IsDefined() && !root.IsNull() ? root.Mark().line + 1 : 0, "the spec is not a mapping", kSpecForm);
  r.keys(root, {"name", "timeout_s", "report", "mean_over", "accept_errors", "datasets", "algorithms"}, "the spec", kSpecForm);
  SweepSpec spec;
  spec.file = file;
  spec.dir = dir;
  const SweepReportSettings rs = report_settings(r, root);
  spec.name = rs.name;
  spec.report_extremes = rs.extremes;
  spec.mean_over = rs.mean_over;
  if (root["timeout_s"]) spec.timeout_s = r.seconds(root["timeout_s"], "timeout_s");
  if (root["accept_errors"]) {
    const std::string v = r.scalar(root["accept_errors"], "accept_errors");
    if (v != "true" && v != "false") r.fail(root["accept_errors"], "accept_errors '" + v + "' is not true or false", "`accept_errors: true`");
    spec.accept_errors = v == "true";
  }
  const YAML::Node ds = root["datasets"], as = root["algorithms"];
  if (!ds || !ds.IsSequence() || ds.size() == 0) r.fail(ds ? ds : root, "`datasets:` is missing or not a non-empty list", kSpecForm);
  if (!as || !as.IsSequence() || as.size() == 0) r.fail(as ? as : root, "`algorithms:` is missing or not a non-empty list", kSpecForm);
  std::set<std::string> names;
  for (const YAML::Node& d : ds) {
    spec.datasets.push_back(r.dataset(d));
    if (!names.insert(spec.datasets.back().name).second) {
      r.fail(d, "two datasets named '" + spec.datasets.back().name + "'", "unique names (set `name:`)");
    }
  }
  for (const YAML::Node& a : as) spec.algorithms.push_back(r.algorithm(a, names));
  for (const std::string& k : spec.mean_over) {
    const bool in_grid = std::any_of(spec.algorithms.begin(), spec.algorithms.end(), [&](const SweepAlgorithm& a) {
      return std::any_of(a.grid.begin(), a.grid.end(), [&](const auto& g) { return g.first == k; });
    });
    if (!in_grid) r.fail(root["mean_over"], "mean_over key '" + k + "' is not a grid key of any algorithm entry", "grid keys, e.g. `mean_over: [tracker.seed]`");
  }
  return spec;
}

SweepReportSettings load_sweep_report_settings(const std::string& file) {
  std::ifstream f(file);
  if (!f) throw InputError(file, 0, "cannot open the sweep spec", kSpecForm);
  std::stringstream text;
  text << f.rdbuf();
  YAML::Node root;
  try {
    root = YAML::Load(text.str());
  } catch (const YAML::Exception& e) {
    throw InputError(file, e.mark.line >= 0 ? e.mark.line + 1 : 0, "YAML syntax: " + e.msg, kSpecForm);
  }
  if (!root.IsMap()) throw InputError(file, 0, "the spec is not a mapping", kSpecForm);
  SpecReader r(file, ".");
  return report_settings(r, root);
}

SweepSpec load_sweep_spec(const std::string& file) {
  std::ifstream f(file);
  if (!f) throw InputError(file, 0, "cannot open the sweep spec", kSpecForm);
  std::stringstream text;
  text << f.rdbuf();
  std::string dir = fs::path(file).parent_path().string();
  if (dir.empty()) dir = ".";
  return parse_sweep_spec(text.str(), file, dir);
}

std::vector<std::string> simulate_arguments(const SweepDataset& d, const std::string& out_dir) {
  std::vector<std::string> a = {"simulate", d.scene, "--out", out_dir};
  if (!d.duration_s.empty()) a.insert(a.end(), {"--duration", d.duration_s});
  if (!d.seed.empty()) a.insert(a.end(), {"--seed", d.seed});
  for (const std::string& s : d.set) a.insert(a.end(), {"--set", s});
  return a;
}

std::vector<SweepCell> expand_sweep_cells(const SweepSpec& spec, const std::string& data_dir) {
  std::vector<SweepCell> cells;
  std::set<std::string> ids;
  for (const SweepAlgorithm& a : spec.algorithms) {
    for (const SweepDataset& d : spec.datasets) {
      if (!a.datasets.empty() && std::find(a.datasets.begin(), a.datasets.end(), d.name) == a.datasets.end()) continue;
      const std::string path = d.simulated() ? (fs::path(data_dir) / d.name).string() : d.path;
      // What the dataset is (not where): a regenerated scene with other settings is another cell.
      std::string identity = d.simulated() ? "scene\n" + d.scene + "\n" + d.duration_s + "\n" + d.seed : "path\n" + d.path;
      for (const std::string& g : d.generate) identity += "\ngenerate " + g;
      for (const std::string& s : d.set) identity += "\n" + s;
      std::vector<size_t> index(a.grid.size(), 0);
      while (true) {
        SweepCell c;
        c.algorithm = a.algorithm;
        c.variant = a.variant;
        c.dataset = d.name;
        c.dataset_path = path;
        c.simulated = d.simulated();
        c.timeout_s = a.timeout_s >= 0 ? a.timeout_s : spec.timeout_s;
        for (const std::string& s : a.args) c.args.push_back(substitute(substitute(s, "{dataset}", path), "{spec_dir}", spec.dir));
        for (size_t k = 0; k < a.grid.size(); ++k) c.params.emplace_back(a.grid[k].first, a.grid[k].second[index[k]]);
        std::string key = c.algorithm + "\n" + c.variant + "\n" + identity + "\nargs";
        for (const std::string& s : a.args) key += "\n" + s;
        key += "\nparams";
        for (const auto& [k, v] : c.params) {
          key += '\n';
          key += k;
          key += '=';
          key += v;
        }
        char hex[20];
        std::snprintf(hex, sizeof(hex), "%08llx", static_cast<unsigned long long>(fnv1a(key) & 0xffffffffull));
        c.id = c.algorithm + (c.variant.empty() ? "" : "-" + c.variant) + "-" + c.dataset + "-" + hex;
        if (!ids.insert(c.id).second) {
          throw InputError(spec.file, a.line, "the cell " + c.id + " appears twice", "algorithm entries that differ in variant, args or grid");
        }
        cells.push_back(std::move(c));
        // Next grid point: the last key varies fastest.
        size_t k = a.grid.size();
        while (k > 0 && ++index[k - 1] == a.grid[k - 1].second.size()) index[--k] = 0;
        if (k == 0) break;
      }
    }
  }
  return cells;
}

}  // namespace evio::sweep
