// YAML configuration machinery shared by the simulator's scene parser and the subcommands that
// read config files (`--config`): command-line overrides (`--set key.sub=value`), and a
// Section that knows its dotted key path and YAML node, rejects unknown keys (typos are errors),
// reads typed values with ranges and units, and turns every problem into an evio::InputError at
// the node's line -- or, for values set on the command line, against that option.
#pragma once

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <yaml-cpp/yaml.h>

#include "evio/calib/error.h"
#include "evio/sensors/time.h"

namespace evio::yaml_config {
using Eigen::Vector2d;
using Eigen::Vector3d;

// ---- seeds ----------------------------------------------------------------------------------------

// Reads and parses a YAML file; an unreadable file or a syntax error is an evio::InputError
// naming the file (and line) with `expected`, the form the command wanted.
inline YAML::Node load_yaml_file(const std::string& path, const std::string& expected) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, 0, "cannot open the config file", expected);
  std::stringstream text;
  text << in.rdbuf();
  try {
    return YAML::Load(text.str());
  } catch (const YAML::Exception& e) {
    throw InputError(path, static_cast<int64_t>(e.mark.line) + 1, "YAML error: " + e.msg, expected);
  }
}

inline uint64_t splitmix64(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

inline uint64_t fnv1a(const std::string& s) {
  uint64_t h = 0xCBF29CE484222325ull;
  for (unsigned char c : s) {
    h ^= c;
    h *= 0x100000001B3ull;
  }
  return h;
}

// Seed of one component ("events", "imu", "scene.planes.0.texture", ...) from the top-level
// seed: SplitMix64 over the seed and an FNV-1a hash of the name. Stable across versions.
inline uint64_t derive_seed(uint64_t seed, const std::string& component) {
  return splitmix64(seed ^ splitmix64(fnv1a(component)));
}

// ---- overrides --------------------------------------------------------------------------------------

struct Override {
  std::string path;  // dotted key path it set
  std::string text;  // as given on the command line, e.g. "--set events.seed=3"
};

inline bool is_index(const std::string& s) {
  return !s.empty() && s.size() < 9 && std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; });
}

inline std::vector<std::string> split_path(const std::string& dotted) {
  std::vector<std::string> parts;
  std::string cur;
  for (char c : dotted) {
    if (c == '.') {
      parts.push_back(cur);
      cur.clear();
    } else {
      cur += c;
    }
  }
  parts.push_back(cur);
  return parts;
}

// A copy without source marks, so errors about it point at the command line.
inline YAML::Node strip_marks(const YAML::Node& n) {
  switch (n.Type()) {
    case YAML::NodeType::Scalar:
      return YAML::Node(n.Scalar());
    case YAML::NodeType::Sequence: {
      YAML::Node out(YAML::NodeType::Sequence);
      for (const YAML::Node& c : n) out.push_back(strip_marks(c));
      return out;
    }
    case YAML::NodeType::Map: {
      YAML::Node out(YAML::NodeType::Map);
      for (const auto& kv : n) out[kv.first.Scalar()] = strip_marks(kv.second);
      return out;
    }
    default:
      return YAML::Node(YAML::NodeType::Null);
  }
}

// Sets root[path] = value, creating maps on the way.
inline void apply_override(const YAML::Node& root, const std::string& dotted, const YAML::Node& value, const std::string& text) {
  const std::string expected = "--set key.sub=value with a dotted key path of the YAML (list entries by index)";
  const std::vector<std::string> parts = split_path(dotted);
  for (const std::string& p : parts) {
    if (p.empty()) throw InputError(text, 0, "empty key in '" + dotted + "'", expected);
  }
  YAML::Node cur;
  cur.reset(root);
  for (size_t i = 0; i < parts.size(); ++i) {
    const std::string& key = parts[i];
    const bool last = i + 1 == parts.size();
    if (cur.IsSequence()) {
      if (!is_index(key) || std::stoul(key) >= cur.size()) {
        throw InputError(text, 0, "'" + key + "' is not an index of the list (size " + std::to_string(cur.size()) + ")",
                         expected);
      }
      const size_t idx = std::stoul(key);
      if (last) {
        cur[idx] = value;
        return;
      }
      YAML::Node next;
      next.reset(cur[idx]);
      cur.reset(next);
      continue;
    }
    if (!cur.IsMap() && !cur.IsNull()) {
      throw InputError(text, 0, "cannot set '" + key + "': its parent is not a map", expected);
    }
    if (last) {
      cur[key] = value;
      return;
    }
    const YAML::Node& ccur = cur;
    if (!ccur[key] || ccur[key].IsNull() || ccur[key].IsScalar()) cur[key] = YAML::Node(YAML::NodeType::Map);
    YAML::Node next;
    next.reset(cur[key]);
    cur.reset(next);
  }
}

// Applies command-line overrides `key.sub=value` (value in YAML syntax, list entries by index) to
// root, in order; returns what each set, for error messages that name the option.
inline std::vector<Override> apply_set_overrides(const YAML::Node& root, const std::vector<std::string>& sets) {
  std::vector<Override> applied;
  for (const std::string& s : sets) {
    const std::string text = "--set " + s;
    const size_t eq = s.find('=');
    if (eq == std::string::npos || eq == 0) {
      throw InputError(text, 0, "no '=' after the key", "--set key.sub=value, e.g. --set events.seed=3");
    }
    const std::string key = s.substr(0, eq);
    YAML::Node value;
    try {
      value = strip_marks(YAML::Load(s.substr(eq + 1)));
    } catch (const YAML::Exception& e) {
      throw InputError(text, 0, "value is not valid YAML: " + e.msg, "--set key.sub=value (value in YAML syntax)");
    }
    apply_override(root, key, value, text);
    applied.push_back({key, text});
  }
  return applied;
}

// ---- the parser -------------------------------------------------------------------------------------

class Parser {
 public:
  Parser(std::string file, std::vector<Override> overrides) : file_(std::move(file)), overrides_(std::move(overrides)) {}

  [[noreturn]] void fail(const YAML::Node& at, const std::string& key_path, const std::string& problem,
                         const std::string& expected) const {
    const std::string what = key_path.empty() ? problem : key_path + ": " + problem;
    const YAML::Mark mark = at.IsDefined() ? at.Mark() : YAML::Mark::null_mark();
    if (mark.is_null()) {
      // Came from the command line: name the option that set it (the longest matching path).
      const Override* best = nullptr;
      for (const Override& o : overrides_) {
        const bool related = key_path.rfind(o.path, 0) == 0 || o.path.rfind(key_path, 0) == 0;
        if (related && (best == nullptr || o.path.size() > best->path.size())) best = &o;
      }
      throw InputError(best != nullptr ? best->text : file_ + " (command-line override)", 0, what, expected);
    }
    throw InputError(file_, static_cast<int64_t>(mark.line) + 1, what, expected);
  }

  const std::string& file() const { return file_; }

 private:
  std::string file_;
  std::vector<Override> overrides_;
};

enum class Range { kAny, kPositive, kNonNegative, kUnit };  // kUnit: [0, 1]

// Shortest decimal text that reads back to exactly v ("0.1", not "0.10000000000000001");
// ".inf" / "-.inf" / ".nan" as YAML spells them.
inline std::string yaml_number(double v) {
  if (std::isnan(v)) return ".nan";
  if (std::isinf(v)) return v > 0 ? ".inf" : "-.inf";
  char buf[64];
  for (int precision = 1; precision <= 17; ++precision) {
    std::snprintf(buf, sizeof(buf), "%.*g", precision, v);
    if (std::strtod(buf, nullptr) == v) break;
  }
  // Plain decimals for ordinary magnitudes ("10", not "1e+01").
  if (std::string(buf).find('e') != std::string::npos && std::abs(v) >= 1e-4 && std::abs(v) < 1e15) {
    char fixed[64];
    for (int decimals = 0; decimals <= 20; ++decimals) {
      std::snprintf(fixed, sizeof(fixed), "%.*f", decimals, v);
      if (std::strtod(fixed, nullptr) == v) return fixed;
    }
  }
  return buf;
}

// The values a number may take: an interval of the real line, each end open or closed (an
// infinite end is open). The Range cases are intervals: kAny (-inf, inf), kPositive (0, inf),
// kNonNegative [0, inf), kUnit [0, 1]. Readers take finite numbers only, whatever the interval.
class Interval {
 public:
  Interval(Range r) {  // NOLINT(google-explicit-constructor): every Range is an interval
    switch (r) {
      case Range::kPositive: *this = above(0); break;
      case Range::kNonNegative: *this = at_least(0); break;
      case Range::kUnit: *this = closed(0, 1); break;
      default: break;
    }
  }
  static Interval closed(double lo, double hi) { return {lo, false, hi, false}; }       // [lo, hi]
  static Interval open_closed(double lo, double hi) { return {lo, true, hi, false}; }   // (lo, hi]
  static Interval closed_open(double lo, double hi) { return {lo, false, hi, true}; }   // [lo, hi)
  static Interval open(double lo, double hi) { return {lo, true, hi, true}; }           // (lo, hi)
  static Interval at_least(double lo) { return {lo, false, kInf, true}; }               // [lo, inf)
  static Interval above(double lo) { return {lo, true, kInf, true}; }                   // (lo, inf)

  double lo() const { return lo_; }
  double hi() const { return hi_; }
  bool lo_open() const { return lo_open_; }
  bool hi_open() const { return hi_open_; }

  bool contains(double v) const {
    return (lo_open_ ? v > lo_ : v >= lo_) && (hi_open_ ? v < hi_ : v <= hi_);
  }
  // "> 0", ">= 0", "<= 1", "in [0, 1]", "in (0, 64]"; empty for the whole line.
  std::string text() const {
    const bool has_lo = std::isfinite(lo_), has_hi = std::isfinite(hi_);
    if (has_lo && has_hi) {
      return std::string("in ") + (lo_open_ ? "(" : "[") + yaml_number(lo_) + ", " + yaml_number(hi_) +
             (hi_open_ ? ")" : "]");
    }
    if (has_lo) return (lo_open_ ? "> " : ">= ") + yaml_number(lo_);
    if (has_hi) return (hi_open_ ? "< " : "<= ") + yaml_number(hi_);
    return {};
  }
  // The expected form in messages: "a number > 0", "a number in (0, 1]", "a number".
  std::string number_text() const {
    const std::string t = text();
    return t.empty() ? "a number" : "a number " + t;
  }

 private:
  static constexpr double kInf = std::numeric_limits<double>::infinity();
  Interval(double lo, bool lo_open, double hi, bool hi_open)
      : lo_(lo), hi_(hi), lo_open_(lo_open || !std::isfinite(lo)), hi_open_(hi_open || !std::isfinite(hi)) {}

  double lo_ = -kInf, hi_ = kInf;
  bool lo_open_ = true, hi_open_ = true;
};

inline bool parse_finite(const std::string& s, double* v) {
  if (s.empty()) return false;
  errno = 0;
  char* end = nullptr;
  const double d = std::strtod(s.c_str(), &end);
  if (end != s.c_str() + s.size() || errno == ERANGE || !std::isfinite(d)) return false;
  *v = d;
  return true;
}

// One YAML map with its dotted path.
class Section {
 public:
  Section(const Parser* parser, const YAML::Node& node, std::string path) : p_(parser), path_(std::move(path)) {
    node_.reset(node);
  }

  const YAML::Node& node() const { return node_; }
  const std::string& path() const { return path_; }
  const Parser& parser() const { return *p_; }
  std::string key_path(const std::string& key) const { return path_.empty() ? key : path_ + "." + key; }

  [[noreturn]] void fail(const std::string& problem, const std::string& expected) const {
    p_->fail(node_, path_, problem, expected);
  }
  [[noreturn]] void fail_at(const std::string& key, const std::string& problem, const std::string& expected) const {
    const YAML::Node& n = node_;
    p_->fail(has(key) ? n[key] : n, key_path(key), problem, expected);
  }

  // Unknown keys are errors (they are usually typos).
  void allow(const std::vector<std::string>& keys) const {
    for (const auto& kv : node_) {
      const std::string key = kv.first.IsScalar() ? kv.first.Scalar() : std::string("?");
      if (std::find(keys.begin(), keys.end(), key) == keys.end()) {
        std::string list;
        for (const std::string& k : keys) list += (list.empty() ? "" : ", ") + k;
        p_->fail(kv.first, key_path(key), "unknown key '" + key + "'", "one of: " + list);
      }
    }
  }

  bool has(const std::string& key) const {
    const YAML::Node& n = node_;
    const YAML::Node v = n[key];
    return v && !v.IsNull();
  }
  YAML::Node get(const std::string& key) const {
    const YAML::Node& n = node_;
    return n[key];
  }

  // A sub-map (required, or an empty map added to the tree when absent and not required, so
  // that derived seeds are recorded in the resolved YAML).
  Section child(const std::string& key, bool required, const std::string& expected) const {
    if (!has(key)) {
      if (required) fail("missing key '" + key + "'", expected);
      node_[key] = YAML::Node(YAML::NodeType::Map);
    }
    const YAML::Node v = get(key);
    if (!v.IsMap()) p_->fail(v, key_path(key), "is not a map", expected);
    return Section(p_, v, key_path(key));
  }

  double number(const std::string& key, double def, Range r, const std::string& unit) const {
    if (!has(key)) return def;
    return number_of(get(key), key_path(key), r, unit);
  }
  double number_of(const YAML::Node& n, const std::string& kp, const Interval& r, const std::string& unit) const {
    const std::string expected = r.number_text() + (unit.empty() ? "" : " (" + unit + ")");
    double v = 0;
    if (!n.IsScalar() || !parse_finite(n.Scalar(), &v)) {
      p_->fail(n, kp, "is not a finite number" + (n.IsScalar() ? " ('" + n.Scalar() + "')" : std::string()), expected);
    }
    if (!r.contains(v)) p_->fail(n, kp, "is out of range (" + n.Scalar() + ")", expected);
    return v;
  }

  int integer(const std::string& key, int def, int lo, int hi) const {
    if (!has(key)) return def;
    const std::string expected = "an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]";
    const YAML::Node n = get(key);
    double v = 0;
    if (!n.IsScalar() || !parse_finite(n.Scalar(), &v) || v != std::floor(v) || v < lo || v > hi) {
      p_->fail(n, key_path(key), "is not an integer in range" + (n.IsScalar() ? " ('" + n.Scalar() + "')" : std::string()),
               expected);
    }
    return static_cast<int>(v);
  }

  bool boolean(const std::string& key, bool def) const {
    if (!has(key)) return def;
    const YAML::Node n = get(key);
    const std::string s = n.IsScalar() ? n.Scalar() : std::string();
    if (s == "true" || s == "True" || s == "yes" || s == "on") return true;
    if (s == "false" || s == "False" || s == "no" || s == "off") return false;
    p_->fail(n, key_path(key), "is not a boolean" + (n.IsScalar() ? " ('" + s + "')" : std::string()), "true or false");
  }

  std::string string(const std::string& key, const std::string& def, const std::vector<std::string>& allowed) const {
    std::string list;
    for (const std::string& a : allowed) list += (list.empty() ? "" : " | ") + a;
    if (!has(key)) {
      if (def.empty()) fail("missing key '" + key + "'", key + ": " + (list.empty() ? "a string" : list));
      return def;
    }
    const YAML::Node n = get(key);
    if (!n.IsScalar()) p_->fail(n, key_path(key), "is not a string", list.empty() ? "a string" : list);
    std::string s = n.Scalar();
    if (!allowed.empty() && std::find(allowed.begin(), allowed.end(), s) == allowed.end()) {
      p_->fail(n, key_path(key), "'" + s + "' is not allowed", list);
    }
    return s;
  }

  std::vector<double> numbers(const std::string& key, size_t size, Range r, const std::string& unit) const {
    const YAML::Node n = get(key);
    const std::string expected = "a list of " + std::to_string(size) + " numbers" + (unit.empty() ? "" : " (" + unit + ")");
    if (!n.IsSequence() || n.size() != size) {
      p_->fail(n, key_path(key), n.IsSequence() ? "has " + std::to_string(n.size()) + " entries" : "is not a list",
               expected);
    }
    std::vector<double> out;
    for (size_t i = 0; i < size; ++i) out.push_back(number_of(n[i], key_path(key) + "." + std::to_string(i), r, unit));
    return out;
  }
  std::vector<double> any_numbers(const std::string& key, Range r, const std::string& unit) const {
    const YAML::Node n = get(key);
    if (!n.IsSequence()) p_->fail(n, key_path(key), "is not a list", "a list of numbers (" + unit + ")");
    std::vector<double> out;
    for (size_t i = 0; i < n.size(); ++i) out.push_back(number_of(n[i], key_path(key) + "." + std::to_string(i), r, unit));
    return out;
  }
  Vector3d vec3(const std::string& key, const Vector3d& def, Range r, const std::string& unit) const {
    if (!has(key)) return def;
    const std::vector<double> v = numbers(key, 3, r, unit);
    return Vector3d(v[0], v[1], v[2]);
  }
  Vector2d vec2(const std::string& key, const Vector2d& def, Range r, const std::string& unit) const {
    if (!has(key)) return def;
    const std::vector<double> v = numbers(key, 2, r, unit);
    return Vector2d(v[0], v[1]);
  }

  // Seconds -> ns, exactly for decimal text.
  int64_t time_ns(const std::string& key, int64_t def, Range r) const {
    if (!has(key)) return def;
    return time_ns_of(get(key), key_path(key), r);
  }
  int64_t time_ns_of(const YAML::Node& n, const std::string& kp, Range r) const {
    const double v = number_of(n, kp, r, "s");
    const std::string& s = n.Scalar();
    const char* b = s.c_str();
    int64_t t = 0;
    if (parse_decimal_time_ns(b, s.c_str() + s.size(), 9, &t) && b == s.c_str() + s.size()) return t;
    if (std::abs(v) > 9e9) p_->fail(n, kp, "is too large", "seconds below 9e9");
    return std::llround(v * 1e9);
  }

  // A seed: given, or derived from the top-level seed and this key's path, then written back
  // into the tree so scene_resolved.yaml holds every seed used.
  uint64_t seed(const std::string& key, uint64_t top_seed) {
    if (has(key)) {
      const YAML::Node n = get(key);
      const std::string s = n.IsScalar() ? n.Scalar() : std::string();
      if (s.empty() || s.size() > 20 || !std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; })) {
        p_->fail(n, key_path(key), "is not a seed", "an unsigned integer");
      }
      errno = 0;
      const unsigned long long v = std::strtoull(s.c_str(), nullptr, 10);
      if (errno == ERANGE) p_->fail(n, key_path(key), "is not a seed", "an unsigned 64-bit integer");
      return v;
    }
    const uint64_t v = derive_seed(top_seed, key_path(key));
    node_[key] = v;
    return v;
  }

  void set(const std::string& key, const YAML::Node& value) { node_[key] = value; }

 private:
  const Parser* p_;
  mutable YAML::Node node_;  // a handle into the tree: resolved values are written back
  std::string path_;
};

// A list of maps under `key`.
inline std::vector<Section> list_of_maps(const Section& s, const std::string& key, const std::string& expected) {
  std::vector<Section> out;
  if (!s.has(key)) return out;
  const YAML::Node n = s.get(key);
  if (!n.IsSequence()) s.parser().fail(n, s.key_path(key), "is not a list", expected);
  for (size_t i = 0; i < n.size(); ++i) {
    const std::string kp = s.key_path(key) + "." + std::to_string(i);
    if (!n[i].IsMap()) s.parser().fail(n[i], kp, "is not a map", expected);
    out.emplace_back(&s.parser(), n[i], kp);
  }
  return out;
}

}  // namespace evio::yaml_config
