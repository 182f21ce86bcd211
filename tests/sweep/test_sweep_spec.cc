// evio::sweep spec (spec.h): parsing and its errors (file:line and the expected form),
// environment variables in paths, set and args, the report keys (mean_over, report, accept_errors),
// and the expansion into cells (grid product in order, ids stable across runs).
#include "evio/sweep/spec.h"

#include <stdlib.h>

#include <filesystem>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "evio/calib/error.h"
#include "evio_test/temp_dir.h"

namespace evio::sweep {
namespace {

namespace fs = std::filesystem;

// The error message of parsing `text` as a spec in dir (empty when it parses).
std::string spec_error(const std::string& text, const std::string& dir) {
  try {
    parse_sweep_spec(text, "spec.yaml", dir);
  } catch (const InputError& e) {
    return e.what();
  }
  return {};
}

TEST(SweepSpec, ParsesDatasetsAlgorithmsAndGrids) {
  evio_test::TempDir tmp;
  fs::create_directories(tmp.file("rec"));
  tmp.write("scene.yaml", "x: 1\n");
  const SweepSpec s = parse_sweep_spec(
      "name: t\ntimeout_s: 5\ndatasets:\n  - rec\n  - {name: sim, scene: scene.yaml, duration: 0.5, seed: 3, set: {a.b: [1, 2]}}\n"
      "algorithms:\n  - algorithm: vio\n    variant: small\n    args: [--config, '{spec_dir}/c.yaml']\n"
      "    grid: {frames.events_per_frame: [5000, 15000], window.size: 5}\n    timeout_s: 9\n"
      "  - {algorithm: corners, datasets: [sim]}\n",
      "spec.yaml", tmp.path());
  EXPECT_EQ(s.name, "t");
  EXPECT_EQ(s.timeout_s, 5);
  ASSERT_EQ(s.datasets.size(), 2u);
  EXPECT_EQ(s.datasets[0].name, "rec");
  EXPECT_FALSE(s.datasets[0].simulated());
  EXPECT_EQ(s.datasets[1].name, "sim");
  EXPECT_EQ(s.datasets[1].duration_s, "0.5");
  EXPECT_EQ(s.datasets[1].set, std::vector<std::string>{"a.b=[1, 2]"});
  EXPECT_EQ(simulate_arguments(s.datasets[1], "/o"),
            (std::vector<std::string>{"simulate", tmp.file("scene.yaml"), "--out", "/o", "--duration", "0.5", "--seed", "3", "--set", "a.b=[1, 2]"}));
  ASSERT_EQ(s.algorithms.size(), 2u);
  EXPECT_EQ(s.algorithms[0].variant, "small");
  ASSERT_EQ(s.algorithms[0].grid.size(), 2u);
  EXPECT_EQ(s.algorithms[0].grid[0].second, (std::vector<std::string>{"5000", "15000"}));
  EXPECT_EQ(s.algorithms[0].grid[1].second, std::vector<std::string>{"5"});
  EXPECT_EQ(s.algorithms[0].timeout_s, 9);
  EXPECT_EQ(s.algorithms[1].datasets, std::vector<std::string>{"sim"});
}

TEST(SweepSpec, EnvironmentVariablesInPathsSetAndArgs) {
  evio_test::TempDir tmp;
  fs::create_directories(tmp.file("real/rec"));
  tmp.write("scene.yaml", "x: 1\n");
  ::setenv("EVIO_SWEEP_TEST_DATA", tmp.file("real").c_str(), 1);
  const SweepSpec s = parse_sweep_spec(
      "datasets:\n  - {name: r, path: '{env:EVIO_SWEEP_TEST_DATA}/rec'}\n"
      "  - {name: sim, scene: scene.yaml, set: {trajectory.path: '{env:EVIO_SWEEP_TEST_DATA}/t.csv'}}\n"
      "  - {name: sim2, scene: scene.yaml, set: ['a={env:EVIO_SWEEP_TEST_DATA}']}\n"
      "algorithms:\n  - {algorithm: vio, args: [--calib, '{env:EVIO_SWEEP_TEST_DATA}/c.yaml']}\n",
      "spec.yaml", tmp.path());
  EXPECT_EQ(s.datasets[0].path, tmp.file("real/rec"));
  EXPECT_EQ(s.datasets[1].set, std::vector<std::string>{"trajectory.path=" + tmp.file("real") + "/t.csv"});
  EXPECT_EQ(s.datasets[2].set, std::vector<std::string>{"a=" + tmp.file("real")});
  EXPECT_EQ(s.algorithms[0].args, (std::vector<std::string>{"--calib", tmp.file("real") + "/c.yaml"}));
  ::unsetenv("EVIO_SWEEP_TEST_DATA");
  const std::string e = spec_error("datasets:\n  - {name: r, path: '{env:EVIO_SWEEP_TEST_DATA}/rec'}\nalgorithms: [{algorithm: vio}]\n", tmp.path());
  EXPECT_NE(e.find("spec.yaml:2: '{env:EVIO_SWEEP_TEST_DATA}/rec' needs the environment variable EVIO_SWEEP_TEST_DATA, which is not set"),
            std::string::npos) << e;
  EXPECT_NE(e.find("expected: export EVIO_SWEEP_TEST_DATA=VALUE"), std::string::npos) << e;
}

TEST(SweepSpec, ErrorsNameFileLineAndExpectedForm) {
  evio_test::TempDir tmp;
  fs::create_directories(tmp.file("rec"));
  const std::string ds = "datasets: [rec]\n";
  struct Case {
    std::string text, error;
  };
  const std::vector<Case> cases = {
      {"datasets: [rec\n", "spec.yaml:"},  // YAML syntax
      {"- 1\n", "spec.yaml:1: the spec is not a mapping"},
      {ds + "algorithms: []\n", "spec.yaml:2: `algorithms:` is missing or not a non-empty list"},
      {ds + "algorithms:\n  - algorithm: vio\nfoo: 1\n", "spec.yaml:4: unknown key 'foo' in the spec"},
      {"datasets: [nothere]\nalgorithms: [{algorithm: vio}]\n", "spec.yaml:1: dataset path " + tmp.file("nothere") + ": no such file"},
      {ds + "algorithms:\n  - algorithm: vioo\n", "spec.yaml:3: unknown algorithm 'vioo' (expected: one of vio, mosaic, corners, flow, segment, reconstruct)"},
      {ds + "algorithms:\n  - {algorithm: vio, datasets: [x]}\n", "spec.yaml:3: unknown dataset 'x'"},
      {ds + "algorithms:\n  - {algorithm: vio, args: [--out, x]}\n", "spec.yaml:3: args sets --out"},
      {ds + "algorithms:\n  - algorithm: vio\n    grid: {'a b': [1]}\n", "spec.yaml:4: grid key 'a b' is not a config key"},
      {ds + "algorithms:\n  - algorithm: vio\n    grid:\n      a.b: []\n", "spec.yaml:5: grid key 'a.b' has no values"},
      {ds + "algorithms:\n  - {algorithm: vio, timeout_s: soon}\n", "spec.yaml:3: timeout_s 'soon' is not a number of seconds"},
      {"datasets: [rec, rec]\nalgorithms: [{algorithm: vio}]\n", "spec.yaml:1: two datasets named 'rec'"},
      {"datasets: [{name: a, path: rec, duration: 1}]\nalgorithms: [{algorithm: vio}]\n", "duration, seed and set apply to a `scene` only"},
      {"datasets: [{name: 'a/b', path: rec}]\nalgorithms: [{algorithm: vio}]\n", "name 'a/b' is not a plain name"},
      {ds + "algorithms:\n  - algorithm: vio\n  - algorithm: vio\n", "spec.yaml:4: the cell vio-rec-"},
  };
  for (const Case& c : cases) {
    std::string e = spec_error(c.text, tmp.path());
    if (e.empty()) {  // the duplicate cell is found by the expansion
      try {
        expand_sweep_cells(parse_sweep_spec(c.text, "spec.yaml", tmp.path()), tmp.file("data"));
      } catch (const InputError& x) {
        e = x.what();
      }
    }
    EXPECT_NE(e.find(c.error), std::string::npos) << "spec:\n" << c.text << "error: " << e;
    EXPECT_NE(e.find("expected"), std::string::npos) << e;
  }
  EXPECT_NE(spec_error("", tmp.path()).find("the spec is not a mapping"), std::string::npos);
}

TEST(SweepSpec, MeanOverNamesGridKeys) {
  evio_test::TempDir tmp;
  const std::string err = spec_error("mean_over: [tracker.seed]\ndatasets: [{name: a, path: .}]\nalgorithms:\n"
                                     "  - {algorithm: vio, grid: {frames.events_per_frame: [1, 2]}}\n", tmp.path());
  EXPECT_NE(err.find("spec.yaml:1: mean_over key 'tracker.seed' is not a grid key of any algorithm entry"), std::string::npos) << err;
  EXPECT_EQ(spec_error("mean_over: tracker.seed\ndatasets: [{name: a, path: .}]\nalgorithms:\n"
                       "  - {algorithm: vio, grid: {tracker.seed: [1, 2]}}\n", tmp.path()), "");
}

// The report keys of a spec are checked: `report:` names known sections, `accept_errors:` is true or false.
TEST(SweepSpec, ReportSectionsAndAcceptErrorsAreChecked) {
  evio_test::TempDir tmp;
  fs::create_directories(tmp.file("rec"));
  EXPECT_NE(spec_error("report: [pareto]\ndatasets: [rec]\nalgorithms: [{algorithm: flow}]\n", tmp.file("")).find("unknown report section 'pareto'"), std::string::npos);
  EXPECT_NE(spec_error("accept_errors: maybe\ndatasets: [rec]\nalgorithms: [{algorithm: flow}]\n", tmp.file("")).find("accept_errors 'maybe' is not true or false"), std::string::npos);
}

TEST(SweepCells, GridProductInOrderWithStableIds) {
  evio_test::TempDir tmp;
  fs::create_directories(tmp.file("rec"));
  tmp.write("scene.yaml", "x: 1\n");
  const std::string text =
      "datasets: [rec, {name: sim, scene: scene.yaml}]\nalgorithms:\n"
      "  - {algorithm: flow, args: ['{dataset}/x', '{spec_dir}'], grid: {a: [1, 2, 3], b: [x, y]}}\n"
      "  - {algorithm: corners, datasets: [sim], timeout_s: 2}\n";
  const SweepSpec s = parse_sweep_spec(text, "spec.yaml", tmp.path());
  const std::vector<SweepCell> cells = expand_sweep_cells(s, tmp.file("data"));
  ASSERT_EQ(cells.size(), 2u * 6u + 1u);
  EXPECT_EQ(cells[0].params, (std::vector<std::pair<std::string, std::string>>{{"a", "1"}, {"b", "x"}}));
  EXPECT_EQ(cells[1].params, (std::vector<std::pair<std::string, std::string>>{{"a", "1"}, {"b", "y"}}));
  EXPECT_EQ(cells[5].params, (std::vector<std::pair<std::string, std::string>>{{"a", "3"}, {"b", "y"}}));
  EXPECT_EQ(cells[0].dataset, "rec");
  EXPECT_EQ(cells[6].dataset, "sim");
  EXPECT_TRUE(cells[6].simulated);
  EXPECT_EQ(cells[6].dataset_path, tmp.file("data") + "/sim");
  EXPECT_EQ(cells[0].args, (std::vector<std::string>{tmp.file("rec") + "/x", tmp.path()}));
  EXPECT_EQ(cells[12].algorithm, "corners");
  EXPECT_EQ(cells[12].timeout_s, 2);
  std::set<std::string> ids;
  for (const SweepCell& c : cells) {
    ids.insert(c.id);
    EXPECT_EQ(c.id.rfind(c.algorithm + "-" + c.dataset + "-", 0), 0u) << c.id;
  }
  EXPECT_EQ(ids.size(), cells.size());
  // The same spec gives the same ids (what --resume matches); another value another id.
  EXPECT_EQ(expand_sweep_cells(parse_sweep_spec(text, "other.yaml", tmp.path()), tmp.file("data"))[3].id, cells[3].id);
  std::string changed = text;
  changed.replace(changed.find("[1, 2, 3]"), 9, "[1, 2, 4]");
  const auto cells2 = expand_sweep_cells(parse_sweep_spec(changed, "spec.yaml", tmp.path()), tmp.file("data"));
  EXPECT_EQ(cells2[0].id, cells[0].id);
  EXPECT_NE(cells2[4].id, cells[4].id);
}

}  // namespace
}  // namespace evio::sweep
