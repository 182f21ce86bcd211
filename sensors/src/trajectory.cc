#include "evio/sensors/trajectory.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <stdexcept>

#include "evio/calib/error.h"
#include "evio/sensors/line_reader.h"
#include "text_common.h"

namespace evio {
using detail::is_space;
using detail::quote_line;
using detail::skip_space;

Trajectory::Trajectory(std::vector<StampedPose> poses) : poses_(std::move(poses)) {
  for (size_t i = 1; i < poses_.size(); ++i) {
    if (poses_[i].t_ns <= poses_[i - 1].t_ns) {
      throw std::invalid_argument("Trajectory: stamps not strictly increasing at pose " + std::to_string(i));
    }
  }
}

void Trajectory::push_back(const StampedPose& pose) {
  if (!poses_.empty() && pose.t_ns <= poses_.back().t_ns) {
    throw std::invalid_argument("Trajectory::push_back: stamp " + std::to_string(pose.t_ns) +
                                " ns not after the last one " + std::to_string(poses_.back().t_ns));
  }
  poses_.push_back(pose);
}

std::optional<calib::SE3> Trajectory::interpolate(int64_t t_ns) const {
  if (poses_.empty() || t_ns < poses_.front().t_ns || t_ns > poses_.back().t_ns) return std::nullopt;
  const auto it = std::lower_bound(poses_.begin(), poses_.end(), t_ns,
                                   [](const StampedPose& p, int64_t t) { return p.t_ns < t; });
  if (it->t_ns == t_ns) return it->T_w_b;
  const StampedPose& b = *it;
  const StampedPose& a = *(it - 1);
  // Fraction from an int64 difference: exact even for stamps near 1.7e18 ns.
  const double s = static_cast<double>(t_ns - a.t_ns) / static_cast<double>(b.t_ns - a.t_ns);
  return calib::se3_interpolate(a.T_w_b, b.T_w_b, s);
}

double Trajectory::path_length_m() const {
  double len = 0;
  for (size_t i = 1; i < poses_.size(); ++i) {
    len += (poses_[i].T_w_b.translation - poses_[i - 1].T_w_b.translation).norm();
  }
  return len;
}

namespace {

// Validates and stores one pose; `q` is (x, y, z, w).
void add_pose(Trajectory* traj, int64_t t, const double pos[3], const double q[4], int64_t line_no,
              std::string_view line, const std::string& form, detail::BadLineHandler* h) {
  for (int i = 0; i < 3; ++i) {
    if (!std::isfinite(pos[i]) || !std::isfinite(q[i]) || !std::isfinite(q[3])) {
      h->bad("non-finite", line_no, "NaN or infinite value in " + quote_line(line), form);
      return;
    }
  }
  const double norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  if (std::fabs(norm - 1.0) > 1e-2) {
    h->bad("quaternion", line_no, "quaternion norm " + std::to_string(norm) + " is not 1 in " + quote_line(line),
           form + ", unit quaternion");
    return;
  }
  if (!traj->empty() && t <= traj->poses().back().t_ns) {
    h->bad("time order", line_no,
           "timestamp " + format_seconds(t) + " s is not after the previous pose's " +
               format_seconds(traj->poses().back().t_ns) + " s",
           form + ", strictly increasing time");
    return;
  }
  StampedPose p;
  p.t_ns = t;
  p.T_w_b = calib::SE3(Eigen::Quaterniond(q[3], q[0], q[1], q[2]), Eigen::Vector3d(pos[0], pos[1], pos[2]));
  traj->push_back(p);
}

// Parses `t` and then `n` doubles separated by spaces/commas; false unless exactly that.
bool parse_row(std::string_view line, int exponent, int64_t* t, double* v, int n) {
  const char* end = line.data() + line.size();
  const char* p = skip_space(line.data(), end);
  if (!detail::parse_time(p, end, exponent, t) || (p != end && !is_space(*p))) return false;
  for (int i = 0; i < n; ++i) {
    p = skip_space(p, end);
    if (!detail::parse_double(p, end, &v[i]) || (p != end && !is_space(*p))) return false;
  }
  return skip_space(p, end) == end;
}

}  // namespace

Trajectory read_tum(const std::string& path, const TextReadOptions& options, ReadReport* report) {
  ReadReport local;
  ReadReport& r = report != nullptr ? *report : local;
  r = ReadReport();
  r.path = path;
  LineReader lines(path);
  const int e = detail::prepare_time_unit(path, options, 0, "pose", 0.1, 1e5, 10, &r);
  detail::BadLineHandler handler(path, options.on_bad_line, &r);
  const std::string form = std::string("TUM `t tx ty tz qx qy qz qw`: time in ") + time_unit_name(r.time_unit) +
                           ", position in m, quaternion x y z w";
  Trajectory traj;
  std::string_view line;
  while (lines.next(&line)) {
    if (detail::is_comment_or_blank(line)) continue;
    int64_t t = 0;
    double v[7];
    if (!parse_row(line, e, &t, v, 7)) {
      const int n = detail::count_tokens(line);
      handler.bad("malformed", lines.line_number(),
                  (n != 8 ? "expected 8 columns, found " + std::to_string(n) : std::string("a value is not a number")) +
                      " in " + quote_line(line),
                  form);
      continue;
    }
    add_pose(&traj, t, v, v + 3, lines.line_number(), line, form, &handler);
  }
  r.records = static_cast<int64_t>(traj.size());
  r.lines = lines.line_number();
  handler.finish();
  return traj;
}

void write_tum(const std::string& path, const Trajectory& trajectory) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) throw InputError(path, 0, std::string("cannot create: ") + std::strerror(errno), "a writable path");
  bool ok = std::fputs("# t[s] tx ty tz qx qy qz qw  (T_w_b: p_w = R * p_b + t)\n", f) >= 0;
  for (const StampedPose& p : trajectory) {
    char buf[512];
    char* w = format_seconds(p.t_ns, buf);
    const Eigen::Quaterniond& q = p.T_w_b.rotation;
    const double vals[7] = {p.T_w_b.translation.x(), p.T_w_b.translation.y(), p.T_w_b.translation.z(),
                            q.x(), q.y(), q.z(), q.w()};
    for (double d : vals) {
      *w++ = ' ';
      w = std::to_chars(w, buf + sizeof(buf) - 2, d).ptr;
    }
    *w++ = '\n';
    ok = ok && std::fwrite(buf, 1, static_cast<size_t>(w - buf), f) == static_cast<size_t>(w - buf);
  }
  ok = (std::fclose(f) == 0) && ok;
  if (!ok) throw InputError(path, 0, "write failed", "a writable path with free space");
}

namespace {
// Lower-case column name without unit brackets and spaces: "q_RS_w []" -> "q_rs_w".
std::string normalise_column(std::string_view s, std::string* unit) {
  std::string out;
  bool in_bracket = false;
  for (char c : s) {
    if (c == '[') {
      in_bracket = true;
      continue;
    }
    if (c == ']') {
      in_bracket = false;
      continue;
    }
    if (in_bracket) {
      unit->push_back(c);
      continue;
    }
    if (c == ' ' || c == '\t' || c == '#') continue;
    out.push_back(static_cast<char>(std::tolower(static_cast<unsigned char>(c))));
  }
  return out;
}

int find_column(const std::vector<std::string>& names, std::initializer_list<std::string> candidates) {
  for (const std::string& c : candidates) {
    const auto it = std::find(names.begin(), names.end(), c);
    if (it != names.end()) return static_cast<int>(it - names.begin());
  }
  return -1;
}
}  // namespace

Trajectory read_euroc_csv(const std::string& path, const TextReadOptions& options, ReadReport* report) {
  ReadReport local;
  ReadReport& r = report != nullptr ? *report : local;
  r = ReadReport();
  r.path = path;
  LineReader lines(path);
  std::string_view line;
  // Header: the first non-blank line, starting with '#' or with a letter.
  std::vector<std::string> names;
  std::string time_unit_text;
  while (lines.next(&line)) {
    const char* p = skip_space(line.data(), line.data() + line.size());
    if (p == line.data() + line.size()) continue;
    if (*p == '#' || std::isalpha(static_cast<unsigned char>(*p))) {
      size_t start = 0;
      for (;;) {
        const size_t comma = line.find(',', start);
        std::string unit;
        names.push_back(normalise_column(line.substr(start, comma == std::string_view::npos ? std::string_view::npos : comma - start), &unit));
        if (names.size() == 1) time_unit_text = unit;
        if (comma == std::string_view::npos) break;
        start = comma + 1;
      }
    }
    break;
  }
  const std::string form =
      "csv with a header naming timestamp, position (x y z | p_RS_R_x ...) and quaternion (qx qy qz qw | q_RS_w ...) columns";
  if (names.empty()) throw InputError(path, 1, "no header line naming the columns", form);
  int pos[3], quat[4];
  const char* axes = "xyzw";
  for (int i = 0; i < 4; ++i) {
    const std::string a(1, axes[i]);
    if (i < 3) pos[i] = find_column(names, {a, "p" + a, "t" + a, "p_" + a, "pos_" + a, "position_" + a, "p_rs_r_" + a});
    quat[i] = find_column(names, {"q" + a, "q_" + a, "q_rs_" + a, "quat_" + a, "rotation_" + a});
  }
  for (int i = 0; i < 4; ++i) {
    if ((i < 3 && pos[i] <= 0) || quat[i] <= 0) {
      throw InputError(path, 1, "header does not name all position and quaternion columns", form);
    }
  }
  TextReadOptions opts = options;
  if (opts.time_unit == TimeUnit::kAuto) {
    const auto u = time_unit_from_name(time_unit_text);
    opts.time_unit = u && *u != TimeUnit::kAuto ? *u : TimeUnit::kNanoseconds;
  }
  const int e = detail::prepare_time_unit(path, opts, 0, "pose", 0.1, 1e5, 10, &r);
  if (options.time_unit == TimeUnit::kAuto) {
    r.time_unit_reason = time_unit_text.empty() ? "csv default ns" : "header [" + time_unit_text + "]";
  }
  detail::BadLineHandler handler(path, options.on_bad_line, &r);
  const int ncols = static_cast<int>(names.size());
  const std::string row_form = form + "; " + std::to_string(ncols) + " columns per row, time in " + time_unit_name(r.time_unit);
  Trajectory traj;
  std::vector<double> v(static_cast<size_t>(std::max(ncols - 1, 0)));
  while (lines.next(&line)) {
    if (detail::is_comment_or_blank(line)) continue;
    int64_t t = 0;
    if (!parse_row(line, e, &t, v.data(), ncols - 1)) {
      const int n = detail::count_tokens(line);
      handler.bad("malformed", lines.line_number(),
                  (n != ncols ? "expected " + std::to_string(ncols) + " columns, found " + std::to_string(n)
                              : std::string("a value is not a number")) +
                      " in " + quote_line(line),
                  row_form);
      continue;
    }
    const double p3[3] = {v[pos[0] - 1], v[pos[1] - 1], v[pos[2] - 1]};
    const double q4[4] = {v[quat[0] - 1], v[quat[1] - 1], v[quat[2] - 1], v[quat[3] - 1]};
    add_pose(&traj, t, p3, q4, lines.line_number(), line, row_form, &handler);
  }
  r.records = static_cast<int64_t>(traj.size());
  r.lines = lines.line_number();
  handler.finish();
  return traj;
}

namespace {

// csv: a .csv extension, or a first line that is not a `#` comment starting with a letter (a
// header) or holding a comma. `#` lines are skipped (TUM comments; a `#timestamp,...` header is
// followed by comma-separated rows anyway).
bool looks_like_csv(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (ext == ".csv") return true;
  std::ifstream f(path);
  std::string line;
  while (std::getline(f, line)) {
    const size_t k = line.find_first_not_of(" \t\r");
    if (k == std::string::npos || line[k] == '#') continue;
    return std::isalpha(static_cast<unsigned char>(line[k])) || line.find(',') != std::string::npos;
  }
  return false;
}

}  // namespace

Trajectory read_trajectory(const std::string& path, const TextReadOptions& options) {
  std::error_code ec;
  if (!std::filesystem::exists(path, ec)) throw InputError(path, 0, "no such file", "a TUM or csv trajectory file");
  const bool csv = looks_like_csv(path);
  Trajectory t = csv ? read_euroc_csv(path, options) : read_tum(path, options);
  const std::string form = csv ? "csv: a header line, then `timestamp[ns], x, y, z, qx, qy, qz, qw` rows"
                               : "TUM: lines `t tx ty tz qx qy qz qw` (t in s)";
  if (t.empty()) throw InputError(path, 0, "no poses in the file", "at least 2 poses; " + form);
  if (t.size() < 2) throw InputError(path, 0, "only 1 pose: a trajectory needs at least 2", form);
  return t;
}

}  // namespace evio
