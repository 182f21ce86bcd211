#include "evio/sweep/report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

#include "evio/calib/error.h"
#include "evio/calib/script_path.h"
#include "evio/sweep/engine.h"
#include "evio/sweep/results.h"
#include "evio/sweep/spec.h"

namespace evio::sweep {
namespace fs = std::filesystem;

namespace {

// The cells of one algorithm on one dataset, fastest first (failed cells last).
struct Group {
  std::string algorithm, dataset, error_metric, error_label, note;
  std::vector<const SweepRecord*> rows;
  std::vector<std::string> metric_names;  // union over the rows, in first-seen order
  std::vector<bool> on_front;             // per row
  std::string file_stem() const { return algorithm + "__" + dataset; }
  double error(size_t i) const { return error_metric.empty() ? NAN : rows[i]->metric(error_metric); }
};

std::string fmt(double v, const char* form = "%.4g") {
  if (!std::isfinite(v)) return "-";
  char buf[40];
  std::snprintf(buf, sizeof(buf), form, v);
  return buf;
}

std::string params_text(const SweepRecord& r) {
  std::string s;
  for (const auto& [k, v] : r.params) {
    if (!s.empty()) s += ", ";
    s += k;
    s += '=';
    s += v;
  }
  return s.empty() ? "(defaults)" : s;
}

std::string exit_text(const SweepRecord& r) {
  return std::to_string(r.exit_code) + (r.timed_out ? " (timeout)" : r.exit_code < 0 ? " (signal)" : "");
}

std::vector<Group> make_groups(const std::map<std::string, SweepRecord>& latest) {
  std::map<std::pair<size_t, std::string>, Group> by;  // (algorithm order, dataset)
  const auto& algs = sweep_algorithms();
  for (const auto& [id, r] : latest) {
    const size_t order = static_cast<size_t>(std::find(algs.begin(), algs.end(), r.algorithm) - algs.begin());
    Group& g = by[{order, r.dataset}];
    g.algorithm = r.algorithm;
    g.dataset = r.dataset;
    g.rows.push_back(&r);
    if (g.error_metric.empty() && !r.error_metric.empty()) g.error_metric = r.error_metric;
    if (g.note.empty()) g.note = r.note;
    for (const auto& m : r.metrics) {
      if (std::find(g.metric_names.begin(), g.metric_names.end(), m.first) == g.metric_names.end()) g.metric_names.push_back(m.first);
    }
  }
  std::vector<Group> out;
  for (auto& [key, g] : by) {
    std::stable_sort(g.rows.begin(), g.rows.end(), [](const SweepRecord* a, const SweepRecord* b) {
      if ((a->exit_code == 0) != (b->exit_code == 0)) return a->exit_code == 0;
      return a->cpu_s < b->cpu_s;
    });
    if (key.first < algs.size()) g.error_label = sweep_algorithm_info(g.algorithm).error_label;  // else an unknown name
    if (g.error_label.empty()) g.error_label = g.error_metric;
    std::vector<std::pair<double, double>> te;
    for (size_t i = 0; i < g.rows.size(); ++i) {
      te.emplace_back(g.rows[i]->exit_code == 0 ? g.rows[i]->cpu_s : NAN, g.error(i));
    }
    g.on_front.assign(g.rows.size(), false);
    for (size_t i : pareto_front(te)) g.on_front[i] = true;
    out.push_back(std::move(g));
  }
  return out;
}

std::string csv_field(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string o = "\"";
  for (char c : s) o += c == '"' ? std::string("\"\"") : std::string(1, c);
  return o + "\"";
}

std::string latex(const std::string& s) {
  std::string o;
  for (char c : s) {
    switch (c) {
      case '_': case '%': case '&': case '#': case '$': case '{': case '}': o += '\\'; o += c; break;
      case '~': o += "\\textasciitilde{}"; break;
      case '^': o += "\\textasciicircum{}"; break;
      case '\\': o += "\\textbackslash{}"; break;
      default: o += c;
    }
  }
  return o;
}

std::string html(const std::string& s) {
  std::string o;
  for (char c : s) {
    switch (c) {
      case '<': o += "&lt;"; break;
      case '>': o += "&gt;"; break;
      case '&': o += "&amp;"; break;
      case '"': o += "&quot;"; break;
      default: o += c;
    }
  }
  return o;
}

std::string base64(const std::string& bytes) {
  static const char* k = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string o;
  size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const unsigned v = (static_cast<unsigned char>(bytes[i]) << 16) | (static_cast<unsigned char>(bytes[i + 1]) << 8) |
                       static_cast<unsigned char>(bytes[i + 2]);
    o += {k[v >> 18], k[(v >> 12) & 63], k[(v >> 6) & 63], k[v & 63]};
  }
  if (i + 1 == bytes.size()) {
    const unsigned v = static_cast<unsigned char>(bytes[i]) << 16;
    o += {k[v >> 18], k[(v >> 12) & 63], '=', '='};
  } else if (i + 2 == bytes.size()) {
    const unsigned v = (static_cast<unsigned char>(bytes[i]) << 16) | (static_cast<unsigned char>(bytes[i + 1]) << 8);
    o += {k[v >> 18], k[(v >> 12) & 63], k[(v >> 6) & 63], '='};
  }
  return o;
}

// A table as rows of cells; rendered in each format.
struct Table {
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> rows;

  std::string markdown() const {
    std::string s = "|";
    for (const auto& h : header) s += " " + h + " |";
    s += "\n|";
    for (size_t i = 0; i < header.size(); ++i) s += "---|";
    s += "\n";
    for (const auto& r : rows) {
      s += "|";
      for (const auto& c : r) s += " " + c + " |";
      s += "\n";
    }
    return s;
  }
  std::string csv() const {
    std::string s;
    for (size_t i = 0; i < header.size(); ++i) s += (i ? "," : "") + csv_field(header[i]);
    s += "\n";
    for (const auto& row : rows) {
      for (size_t i = 0; i < row.size(); ++i) s += (i ? "," : "") + csv_field(row[i]);
      s += "\n";
    }
    return s;
  }
  std::string html_table() const {
    std::string s = "<table>\n<tr>";
    for (const auto& h : header) s += "<th>" + html(h) + "</th>";
    s += "</tr>\n";
    for (const auto& r : rows) {
      s += "<tr>";
      for (const auto& c : r) s += "<td>" + html(c) + "</td>";
      s += "</tr>\n";
    }
    return s + "</table>\n";
  }
  std::string latex_table(const std::string& caption) const {
    std::string s = "\\begin{table}[ht]\n\\centering\n\\caption{" + latex(caption) + "}\n\\begin{tabular}{" +
                    std::string(header.size(), 'l') + "}\n\\hline\n";
    for (size_t i = 0; i < header.size(); ++i) s += (i ? " & " : "") + latex(header[i]);
    s += " \\\\\n\\hline\n";
    for (const auto& r : rows) {
      for (size_t i = 0; i < r.size(); ++i) s += (i ? " & " : "") + latex(r[i]);
      s += " \\\\\n";
    }
    return s + "\\hline\n\\end{tabular}\n\\end{table}\n";
  }
};

// The outcome of a record; records written before outcomes existed get it from the exit code.
std::string outcome_of(const SweepRecord& r) {
  if (!r.outcome.empty()) return r.outcome;
  if (r.timed_out) return "hang";
  return r.exit_code == 0 ? "ok" : r.exit_code == 1 ? "error" : "crash";
}

// The outcome table: rows = datasets, columns = algorithms (variants apart), each cell the distinct
// outcomes of its cells; a note per cell that is not ok (its error line, exit code or bad value).
struct OutcomeTable {
  Table table;                                                     // text cells: "ok", "error [1]"
  std::vector<std::vector<std::vector<std::string>>> outcomes;     // per row and column: its distinct outcomes
  std::vector<std::vector<std::vector<std::pair<int, std::string>>>> notes;  // per row and column: (note number, detail)
  std::vector<std::string> footnotes;                              // "[n] cell: detail"
  std::map<std::string, int> counts;                               // outcome -> cells
};

OutcomeTable outcome_table(const std::map<std::string, SweepRecord>& latest) {
  std::vector<std::string> datasets, columns;
  const auto& algs = sweep_algorithms();
  auto column_of = [](const SweepRecord& r) { return r.algorithm + (r.variant.empty() ? "" : " (" + r.variant + ")"); };
  std::vector<std::pair<size_t, std::string>> col_keys;
  for (const auto& [id, r] : latest) {
    if (std::find(datasets.begin(), datasets.end(), r.dataset) == datasets.end()) datasets.push_back(r.dataset);
    const std::pair<size_t, std::string> key{static_cast<size_t>(std::find(algs.begin(), algs.end(), r.algorithm) - algs.begin()), column_of(r)};
    if (std::find(col_keys.begin(), col_keys.end(), key) == col_keys.end()) col_keys.push_back(key);
  }
  std::sort(datasets.begin(), datasets.end());
  std::sort(col_keys.begin(), col_keys.end());
  for (const auto& k : col_keys) columns.push_back(k.second);
  OutcomeTable t;
  t.table.header = {"dataset"};
  t.table.header.insert(t.table.header.end(), columns.begin(), columns.end());
  t.outcomes.assign(datasets.size(), std::vector<std::vector<std::string>>(columns.size()));
  t.notes.assign(datasets.size(), std::vector<std::vector<std::pair<int, std::string>>>(columns.size()));
  std::vector<std::vector<std::vector<std::string>>> words(datasets.size(), std::vector<std::vector<std::string>>(columns.size()));
  for (const auto& [id, r] : latest) {
    const size_t d = static_cast<size_t>(std::find(datasets.begin(), datasets.end(), r.dataset) - datasets.begin());
    const size_t c = static_cast<size_t>(std::find(columns.begin(), columns.end(), column_of(r)) - columns.begin());
    const std::string o = outcome_of(r);
    ++t.counts[o];
    std::string word = o;
    if (o != "ok") {
      std::string detail = r.outcome_detail.empty() ? "exit code " + std::to_string(r.exit_code) : r.outcome_detail;
      t.footnotes.push_back("[" + std::to_string(t.footnotes.size() + 1) + "] " + r.cell + ": " + detail);
      t.notes[d][c].emplace_back(static_cast<int>(t.footnotes.size()), detail);
      word += " [" + std::to_string(t.footnotes.size()) + "]";
    }
    if (std::find(t.outcomes[d][c].begin(), t.outcomes[d][c].end(), o) == t.outcomes[d][c].end()) t.outcomes[d][c].push_back(o);
    if (o != "ok" || std::find(words[d][c].begin(), words[d][c].end(), word) == words[d][c].end()) words[d][c].push_back(word);
  }
  for (size_t d = 0; d < datasets.size(); ++d) {
    std::vector<std::string> row = {datasets[d]};
    for (size_t c = 0; c < columns.size(); ++c) {
      std::string cell;
      for (const std::string& w : words[d][c]) cell += (cell.empty() ? "" : ", ") + w;
      row.push_back(cell.empty() ? "-" : cell);
    }
    t.table.rows.push_back(std::move(row));
  }
  return t;
}

std::string outcome_summary(const OutcomeTable& t) {
  std::string s;
  for (const char* o : {"ok", "error", "crash", "hang", "nonfinite"}) {
    const auto it = t.counts.find(o);
    s += (s.empty() ? "" : ", ") + std::to_string(it == t.counts.end() ? 0 : it->second) + " " + o;
  }
  return "Outcomes: " + s + " (ok: exit code 0 and every output number finite; error: exit code 1 with a one-line "
         "message; crash: a signal or another exit code; hang: killed after the timeout; nonfinite: exit code 0 with NaN "
         "or Inf in an output).";
}

// The HTML of the outcome table: each cell coloured by its worst outcome, details on hover.
std::string outcome_html(const OutcomeTable& t) {
  std::string s = "<table class=\"outcomes\">\n<tr>";
  for (const auto& h : t.table.header) s += "<th>" + html(h) + "</th>";
  s += "</tr>\n";
  for (size_t d = 0; d < t.table.rows.size(); ++d) {
    s += "<tr><td>" + html(t.table.rows[d][0]) + "</td>";
    for (size_t c = 0; c + 1 < t.table.rows[d].size(); ++c) {
      std::string cls = "ok";
      for (const char* o : {"error", "nonfinite", "hang", "crash"}) {
        if (std::find(t.outcomes[d][c].begin(), t.outcomes[d][c].end(), o) != t.outcomes[d][c].end()) cls = o;
      }
      std::string title;
      for (const auto& [n, detail] : t.notes[d][c]) title += (title.empty() ? "" : "\n") + ("[" + std::to_string(n) + "] ") + detail;
      s += "<td class=\"" + cls + "\"" + (title.empty() ? "" : " title=\"" + html(title) + "\"") + ">" + html(t.table.rows[d][c + 1]) + "</td>";
    }
    s += "</tr>\n";
  }
  s += "</table>\n";
  if (!t.footnotes.empty()) {
    s += "<ol class=\"notes\">\n";
    for (const std::string& f : t.footnotes) s += "<li>" + html(f.substr(f.find("] ") + 2)) + "</li>\n";
    s += "</ol>\n";
  }
  return s;
}

Table front_table(const Group& g) {
  Table t{{"variant", "params", g.error_label, "CPU s", "wall s", "peak RSS MiB", "cell"}, {}};
  for (size_t i = 0; i < g.rows.size(); ++i) {
    if (!g.on_front[i]) continue;
    const SweepRecord& r = *g.rows[i];
    t.rows.push_back({r.variant, params_text(r), fmt(g.error(i)), fmt(r.cpu_s, "%.2f"), fmt(r.wall_s, "%.2f"),
                      fmt(r.peak_rss_mb, "%.0f"), r.cell});
  }
  return t;
}

// form: printf form of the numbers (shortened for the pages, full for the CSV).
Table cells_table(const Group& g, const char* form = nullptr) {
  auto f = [form](double v, const char* page_form) { return fmt(v, form ? form : page_form); };
  Table t{{"cell", "variant", "params", "exit", "wall s", "CPU s", "real-time factor", "peak RSS MiB"}, {}};
  for (const std::string& m : g.metric_names) t.header.push_back(m);
  t.header.push_back("Pareto");
  for (size_t i = 0; i < g.rows.size(); ++i) {
    const SweepRecord& r = *g.rows[i];
    std::vector<std::string> row = {r.cell, r.variant, params_text(r), exit_text(r), f(r.wall_s, "%.2f"),
                                    f(r.cpu_s, "%.2f"), f(r.duration_s > 0 ? r.wall_s / r.duration_s : NAN, "%.2f"),
                                    f(r.peak_rss_mb, "%.0f")};
    for (const std::string& m : g.metric_names) row.push_back(f(r.metric(m), "%.4g"));
    row.push_back(g.on_front[i] ? "yes" : "");
    t.rows.push_back(std::move(row));
  }
  return t;
}

std::string group_title(const Group& g) { return g.algorithm + " on " + g.dataset; }

// The cells of a group that differ only in the repeat keys (mean_over), averaged: each metric's mean
// and sample standard deviation over the cells that ran (exit 0) and have it.
struct MeanRow {
  std::string variant, params;           // params without the repeat keys
  std::vector<const SweepRecord*> rows;  // the repeats
  size_t ok = 0;                         // repeats with exit code 0 and a finite headline error (or no headline)
  double cpu_s = NAN, wall_s = NAN, peak_rss_mb = NAN;  // means of the ok repeats (peak RSS: their maximum)
  bool on_front = false;                 // on the Pareto front of the means (only rows whose every repeat is ok)
};

struct MeanStat {
  double mean = NAN, sd = NAN, min = NAN, max = NAN;
  size_t n = 0;
};

MeanStat mean_stat(const std::vector<double>& v) {
  MeanStat s;
  for (double x : v) {
    if (!std::isfinite(x)) continue;
    ++s.n;
    s.mean = s.n == 1 ? x : s.mean + (x - s.mean) / static_cast<double>(s.n);
    s.min = s.n == 1 ? x : std::min(s.min, x);
    s.max = s.n == 1 ? x : std::max(s.max, x);
  }
  if (s.n >= 2) {
    double ss = 0;
    for (double x : v) {
      if (std::isfinite(x)) ss += (x - s.mean) * (x - s.mean);
    }
    s.sd = std::sqrt(ss / static_cast<double>(s.n - 1));
  }
  return s;
}

std::vector<MeanRow> mean_rows(const Group& g, const std::vector<std::string>& over) {
  std::vector<MeanRow> out;
  std::map<std::string, size_t> index;
  for (const SweepRecord* r : g.rows) {
    std::string rest;
    for (const auto& [k, v] : r->params) {
      if (std::find(over.begin(), over.end(), k) != over.end()) continue;
      rest += (rest.empty() ? "" : ", ") + k + "=" + v;
    }
    if (rest.empty()) rest = "(defaults)";
    const auto [it, fresh] = index.emplace(r->variant + "\n" + rest, out.size());
    if (fresh) out.push_back(MeanRow{r->variant, rest, {}});
    out[it->second].rows.push_back(r);
  }
  for (MeanRow& m : out) {
    std::vector<double> cpu, wall;
    for (const SweepRecord* r : m.rows) {
      const bool good = r->exit_code == 0 && (g.error_metric.empty() || std::isfinite(r->metric(g.error_metric)));
      if (!good) continue;
      ++m.ok;
      cpu.push_back(r->cpu_s);
      wall.push_back(r->wall_s);
      m.peak_rss_mb = std::isfinite(m.peak_rss_mb) ? std::max(m.peak_rss_mb, r->peak_rss_mb) : r->peak_rss_mb;
    }
    m.cpu_s = mean_stat(cpu).mean;
    m.wall_s = mean_stat(wall).mean;
  }
  std::stable_sort(out.begin(), out.end(), [](const MeanRow& a, const MeanRow& b) {
    if ((a.ok > 0) != (b.ok > 0)) return a.ok > 0;
    return a.cpu_s < b.cpu_s;
  });
  if (!g.error_metric.empty()) {
    std::vector<std::pair<double, double>> te;
    for (const MeanRow& m : out) {
      std::vector<double> e;
      for (const SweepRecord* r : m.rows) {
        if (r->exit_code == 0) e.push_back(r->metric(g.error_metric));
      }
      te.emplace_back(m.ok == m.rows.size() ? m.cpu_s : NAN, mean_stat(e).mean);
    }
    for (size_t i : pareto_front(te)) out[i].on_front = true;
  }
  return out;
}

MeanStat metric_stat(const MeanRow& m, const std::string& metric) {
  std::vector<double> v;
  for (const SweepRecord* r : m.rows) {
    if (r->exit_code == 0) v.push_back(r->metric(metric));
  }
  return mean_stat(v);
}

// The averaged table: the headline error's mean, sd, min and max (the pages), every metric's mean, sd
// and count (the CSV, form "%.9g").
Table means_table(const Group& g, const std::vector<MeanRow>& rows, bool csv) {
  auto f = [csv](double v, const char* page_form) { return fmt(v, csv ? "%.9g" : page_form); };
  Table t{{"variant", "params", "cells ok"}, {}};
  const std::string label = g.error_metric.empty() ? "" : g.error_label;
  if (!csv && !label.empty()) {
    for (const char* s : {" mean", " sd", " min", " max"}) t.header.push_back(label + s);
  }
  for (const char* s : {"CPU s mean", "wall s mean", "peak RSS MiB max"}) t.header.push_back(s);
  if (csv) {
    for (const std::string& m : g.metric_names) {
      for (const char* s : {"_mean", "_sd", "_n"}) t.header.push_back(m + s);
    }
  }
  if (!label.empty()) t.header.push_back("Pareto");
  for (const MeanRow& m : rows) {
    std::vector<std::string> row = {m.variant, m.params, std::to_string(m.ok) + "/" + std::to_string(m.rows.size())};
    if (!csv && !label.empty()) {
      const MeanStat e = metric_stat(m, g.error_metric);
      for (double v : {e.mean, e.sd, e.min, e.max}) row.push_back(f(v, "%.4g"));
    }
    for (double v : {m.cpu_s, m.wall_s}) row.push_back(f(v, "%.2f"));
    row.push_back(f(m.peak_rss_mb, "%.0f"));
    if (csv) {
      for (const std::string& name : g.metric_names) {
        const MeanStat s = metric_stat(m, name);
        row.push_back(f(s.mean, ""));
        row.push_back(f(s.sd, ""));
        row.push_back(std::to_string(s.n));
      }
    }
    if (!label.empty()) row.push_back(m.on_front ? "yes" : "");
    t.rows.push_back(std::move(row));
  }
  return t;
}

std::string join(const std::vector<std::string>& v, const std::string& sep) {
  std::string s;
  for (const std::string& x : v) s += (s.empty() ? "" : sep) + x;
  return s;
}

std::string front_caption(const Group& g) {
  return g.error_metric.empty() ? "" : "Pareto front of " + g.error_label + " against CPU time";
}

}  // namespace

std::vector<size_t> pareto_front(const std::vector<std::pair<double, double>>& time_error) {
  std::vector<size_t> idx;
  for (size_t i = 0; i < time_error.size(); ++i) {
    if (std::isfinite(time_error[i].first) && std::isfinite(time_error[i].second)) idx.push_back(i);
  }
  std::stable_sort(idx.begin(), idx.end(), [&](size_t a, size_t b) { return time_error[a] < time_error[b]; });
  std::vector<size_t> front;
  double best = INFINITY;
  for (size_t i : idx) {
    if (time_error[i].second < best) {
      best = time_error[i].second;
      front.push_back(i);
    }
  }
  return front;
}

SweepReportResult write_sweep_report(const SweepReportOptions& opts) {
  const fs::path dir(opts.dir);
  const fs::path results = dir / "results.jsonl";
  const auto latest = latest_sweep_records(read_sweep_records(results.string()));
  if (latest.empty()) throw InputError(results.string(), 0, "no result record to report", "a results.jsonl written by `evio sweep`");
  const std::vector<Group> groups = make_groups(latest);
  const fs::path rep = dir / "report";
  fs::create_directories(rep / "plots");
  SweepReportResult res;
  res.cells = static_cast<int>(latest.size());
  int failed = 0;
  for (const auto& [id, r] : latest) failed += r.exit_code != 0;
  std::string title = opts.title;
  if (title.empty()) title = "evio sweep: " + fs::absolute(dir).lexically_normal().filename().string();
  const std::string summary = std::to_string(latest.size()) + " cells (" + std::to_string(failed) + " failed) from " +
                              results.string() + ". Time: the CPU time of each cell's process (user + system, s); wall " +
                              "time and peak RSS as measured by the sweep. Pareto front: the cells no other cell beats in " +
                              "both error and CPU time.";

  // CSV: every cell, with its group's headline error (what the plot script reads).
  std::string csv = "cell,algorithm,variant,dataset,params,exit_code,timed_out,wall_s,cpu_s,peak_rss_mb,real_time_factor,"
                    "error_metric,error,pareto\n";
  for (const Group& g : groups) {
    for (size_t i = 0; i < g.rows.size(); ++i) {
      const SweepRecord& r = *g.rows[i];
      csv += csv_field(r.cell) + "," + r.algorithm + "," + csv_field(r.variant) + "," + csv_field(r.dataset) + "," +
             csv_field(params_text(r)) + "," + std::to_string(r.exit_code) + "," + (r.timed_out ? "1" : "0") + "," +
             fmt(r.wall_s, "%.6g") + "," + fmt(r.cpu_s, "%.6g") + "," + fmt(r.peak_rss_mb, "%.6g") + "," +
             fmt(r.duration_s > 0 ? r.wall_s / r.duration_s : NAN, "%.6g") + "," + g.error_metric + "," +
             fmt(g.error(i), "%.9g") + "," + (g.on_front[i] ? "1" : "0") + "\n";
    }
  }
  sweep_write_file(rep / "cells.csv", csv);
  res.files.push_back((rep / "cells.csv").string());

  // The averages over repeat keys, which the plot script reads too.
  for (const Group& g : groups) {
    if (opts.mean_over.empty()) break;
    const fs::path mfile = rep / (g.file_stem() + "__means.csv");
    sweep_write_file(mfile, means_table(g, mean_rows(g, opts.mean_over), true).csv());
    res.files.push_back(mfile.string());
  }

  // Plots: one PNG (and PDF) per group with an error metric, by the project's matplotlib script.
  const std::string script = find_evio_script("plot_sweep.py", opts.plot_script);
  bool any_error = false;
  for (const Group& g : groups) any_error |= !g.error_metric.empty();
  if (!any_error) {
    res.plot_note = "no algorithm in this sweep reports an error against ground truth, so there is nothing to plot";
  } else if (script.empty()) {
    res.plot_note = "scripts/plot_sweep.py was not found";
  } else {
    SweepJob job{opts.python, {script, (rep / "cells.csv").string(), (rep / "plots").string()},
                 (rep / "plot.log").string(), (rep / "plot_errors.log").string(), 300, ""};
    const SweepOutcome o = run_job(job);
    if (o.exit_code == 0) {
      res.plots = true;
    } else {
      std::string err = sweep_read_file(job.stderr_path);
      while (!err.empty() && err.back() == '\n') err.pop_back();
      const size_t nl = err.rfind('\n');
      res.plot_note = opts.python + " " + script + " failed (exit code " + std::to_string(o.exit_code) + ")" +
                      (err.empty() ? "" : ": " + err.substr(nl == std::string::npos ? 0 : nl + 1)) +
                      "; the plots need Debian's python3-matplotlib (sudo apt-get install python3-matplotlib)";
    }
  }

  std::string md = "# " + title + "\n\n" + summary + "\n";
  const OutcomeTable outcomes = outcome_table(latest);
  const bool show_outcomes = opts.extremes || outcomes.counts.size() > 1 || !outcomes.counts.count("ok");
  std::string outcome_body;
  if (show_outcomes) {
    md += "\n## Outcomes\n\n" + outcome_summary(outcomes) + "\n\n" + outcomes.table.markdown();
    if (!outcomes.footnotes.empty()) md += "\n";
    for (const std::string& f : outcomes.footnotes) md += "- " + f + "\n";
    outcome_body = "<h2 id=\"outcomes\">Outcomes</h2>\n<p>" + html(outcome_summary(outcomes)) + "</p>\n" + outcome_html(outcomes);
    std::string ocsv = "dataset,algorithm,variant,cell,outcome,exit_code,detail\n";
    for (const auto& [id, r] : latest) {
      ocsv += csv_field(r.dataset) + "," + r.algorithm + "," + csv_field(r.variant) + "," + csv_field(r.cell) + "," + outcome_of(r) + "," +
              std::to_string(r.exit_code) + "," + csv_field(r.outcome_detail) + "\n";
    }
    sweep_write_file(rep / "outcomes.csv", ocsv);
    res.files.push_back((rep / "outcomes.csv").string());
  }
  if (!res.plot_note.empty()) md += "\nPlots are missing: " + res.plot_note + ".\n";
  std::string tex = "% " + title + " (evio sweep --report)\n% " + summary + "\n";
  std::string body;
  for (const Group& g : groups) {
    md += "\n## " + group_title(g) + "\n\n" + g.note + "\n";
    body += "<h2 id=\"" + html(g.file_stem()) + "\">" + html(group_title(g)) + "</h2>\n<p>" + html(g.note) + "</p>\n";
    const Table cells = cells_table(g);
    if (g.error_metric.empty()) {
      md += "\nNo ground-truth error from this command: no Pareto front, stats only.\n";
      body += "<p>No ground-truth error from this command: no Pareto front, stats only.</p>\n";
      tex += "\n% " + group_title(g) + ": no ground-truth error from this command; every cell:\n" +
             cells.latex_table(group_title(g) + ": every cell (no ground-truth error)");
    } else {
      const Table front = front_table(g);
      const std::string none = "No successful cell has a finite " + g.error_label + ": no Pareto front.";
      if (front.rows.empty()) {
        md += "\n" + none + "\n";
        tex += "\n% " + group_title(g) + ": " + none + "\n";
      } else {
        md += "\n" + front_caption(g) + ":\n\n" + front.markdown();
        tex += "\n" + front.latex_table(group_title(g) + ": " + front_caption(g));
      }
      const fs::path png = rep / "plots" / (g.file_stem() + ".png");
      std::error_code ec;
      if (res.plots && fs::exists(png, ec)) {
        md += "\n![" + group_title(g) + "](plots/" + g.file_stem() + ".png)\n";
        body += "<img alt=\"" + html(group_title(g)) + "\" src=\"data:image/png;base64," + base64(sweep_read_file(png)) + "\">\n";
      } else {
        body += "<p class=\"missing\">Plot missing: " + html(res.plots ? "the script made no plot for this group" : res.plot_note) + ".</p>\n";
      }
      body += front.rows.empty() ? "<p>" + html(none) + "</p>\n" : "<h3>" + html(front_caption(g)) + "</h3>\n" + front.html_table();
    }
    if (!opts.mean_over.empty()) {
      const std::vector<MeanRow> means = mean_rows(g, opts.mean_over);
      const std::string caption = "Means over " + join(opts.mean_over, ", ") + " (cells that differ only in " +
                                  (opts.mean_over.size() > 1 ? "these keys" : "it") + "; the Pareto front of the means " +
                                  "counts only rows whose every cell ran)";
      const Table mt = means_table(g, means, false);
      md += "\n" + caption + ":\n\n" + mt.markdown();
      body += "<h3>" + html(caption) + "</h3>\n" + mt.html_table();
      tex += "\n" + mt.latex_table(group_title(g) + ": means over " + join(opts.mean_over, ", "));
    }
    md += "\nEvery cell:\n\n" + cells.markdown();
    body += "<h3>Every cell</h3>\n" + cells.html_table();
    sweep_write_file(rep / (g.file_stem() + ".csv"), cells_table(g, "%.9g").csv());
    res.files.push_back((rep / (g.file_stem() + ".csv")).string());
  }
  // Model selection: what each cell's algorithm chose, and on what numbers (its stats.json "model").
  {
    Table models{{"algorithm", "dataset", "variant", "params", "cell", "model chosen"}, {}};
    for (const Group& g : groups) {
      for (const SweepRecord* r : g.rows) {
        std::string m = sweep_model_summary(*r);
        for (char& c : m) c = c == '|' ? '/' : c;
        models.rows.push_back({r->algorithm, r->dataset, r->variant, params_text(*r), r->cell,
                               m.empty() ? (r->exit_code == 0 ? "(not reported)" : "(failed: " + exit_text(*r) + ")") : m});
      }
    }
    const std::string note = "The model each cell's algorithm chose and the numbers behind it, from the \"model\" object of its "
                             "stats.json (the whole object is in results.jsonl).";
    md += "\n## Model selection\n\n" + note + "\n\n" + models.markdown();
    body += "<h2 id=\"model-selection\">Model selection</h2>\n<p>" + html(note) + "</p>\n" + models.html_table();
    tex += "\n" + models.latex_table("Model selection per cell");
  }
  sweep_write_file(rep / "pareto.md", md);
  sweep_write_file(rep / "pareto.tex", tex);
  std::string page = "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>" + html(title) +
                     "</title>\n<style>body{font-family:sans-serif;margin:2em;max-width:80em}table{border-collapse:collapse;"
                     "margin:0.5em 0 1.5em}td,th{border:1px solid #bbb;padding:2px 6px;font-size:90%;text-align:left}"
                     "th{background:#eee}img{max-width:100%}.missing{color:#a00}td.ok{background:#dfd}td.error{background:#ffd}"
                     "td.crash,td.hang,td.nonfinite{background:#fcc}</style>\n</head>\n<body>\n<h1>" +
                     html(title) + "</h1>\n<p>" + html(summary) + "</p>\n";
  if (!res.plot_note.empty()) page += "<p class=\"missing\">Plots are missing: " + html(res.plot_note) + ".</p>\n";
  page += outcome_body + "<ul>\n";
  for (const Group& g : groups) page += "<li><a href=\"#" + html(g.file_stem()) + "\">" + html(group_title(g)) + "</a></li>\n";
  page += "<li><a href=\"#model-selection\">Model selection</a></li>\n";
  page += "</ul>\n" + body + "</body>\n</html>\n";
  sweep_write_file(rep / "index.html", page);
  for (const char* f : {"pareto.md", "pareto.tex", "index.html"}) res.files.push_back((rep / f).string());
  return res;
}

}  // namespace evio::sweep
