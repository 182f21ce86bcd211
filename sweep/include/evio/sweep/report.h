// evio sweep: the report of a sweep folder's results.jsonl. Per algorithm and dataset, the Pareto
// front of the headline error against CPU time (cells that no other cell beats in both), as
// Markdown, CSV and LaTeX tables; plots by scripts/plot_sweep.py (matplotlib); one self-contained
// HTML page with the plots embedded as data URIs and every table.
#pragma once

#include <string>
#include <utility>
#include <vector>

namespace evio::sweep {

// Indices of the Pareto-optimal points of (time, error) pairs, fastest first: a point is kept when
// no other point has time <= and error <= with one of them strictly smaller. Points with a
// non-finite coordinate are left out.
std::vector<size_t> pareto_front(const std::vector<std::pair<double, double>>& time_error);

struct SweepReportOptions {
  std::string dir;                      // the sweep folder (results.jsonl in it; report/ is written)
  std::string title;                    // report title (default: the folder name)
  std::string python = "/usr/bin/python3";  // runs scripts/plot_sweep.py (needs matplotlib)
  std::string plot_script;              // default: scripts/plot_sweep.py of the sources or the install
  bool extremes = false;                // show the outcome table even when every cell is ok (spec `report: [extremes]`)
  std::vector<std::string> mean_over;   // grid keys of repeats (spec `mean_over:`, e.g. tracker.seed): per group, a
                                        // table of the cells averaged over them, with its own Pareto front
};

struct SweepReportResult {
  std::vector<std::string> files;  // written, in DIR/report/
  int cells = 0;                   // latest records reported
  bool plots = false;              // the plot script ran and made the plots
  std::string plot_note;           // why there are no plots
};

// Reads DIR/results.jsonl and writes DIR/report/{pareto.md, cells.csv, pareto.tex, index.html,
// plots/*.png} (with opts.mean_over also <algorithm>__<dataset>__means.csv); pareto.md and index.html open with the outcome table (rows = datasets, columns =
// algorithms, cell = ok / error / crash / hang / nonfinite, details as numbered notes) when a cell is
// not ok or opts.extremes is set. Throws InputError when there is no record to report.
SweepReportResult write_sweep_report(const SweepReportOptions& opts);

}  // namespace evio::sweep
