#include "segment_command.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <ostream>
#include <set>
#include <sstream>

#include <opencv2/core.hpp>

#include "evio/calib/error.h"
#include "evio/evaluation/label_evaluation.h"
#include "evio/sensors/config_table.h"
#include "evio/sensors/image_io.h"
#include "evio/sensors/time.h"
#include "cmax_input.h"
#include "evio/calib/json.h"
#include "evio/mapping/option_tables.h"
#include "option_tables.h"
#include "output_files.h"

namespace evio::apps {
namespace {

namespace fs = std::filesystem;
using yaml_config::Range;
using yaml_config::Table;
using C = SegmentConfig;
using S = mapping::SegmentationOptions;

const Table<C>& segment_config_table() {
  static const Table<C> table = [] {
    auto self = [](C& c) -> C& { return c; };
    Table<C> window("window settings");
    window.include(cmax_window_table(), &C::window, {"undistortion", "dither_px"})
        .boolean("warm_start", &C::warm_start)
        .note("warm_start", "start from the previous window's clusters: labels persist");
    Table<S> seg("segmentation settings");
    seg.integer("clusters", &S::clusters, 0, 16)
        .note("clusters", "0: automatic, up to max_clusters")
        .integer("max_clusters", &S::max_clusters, 1, 16)
        .choice_list("models", &S::models, mapping::warp_model_choices())
        .note("models", "the count is decided on the richest; each cluster takes the simplest good enough")
        .choice("init", &S::init, {{"kmeans", mapping::SegmentationInit::kKmeans}, {"greedy", mapping::SegmentationInit::kGreedy}})
        .integer("tile_px", &S::tile_px, 8, 10000)
        .integer("min_tile_events", &S::min_tile_events, 5, 1000000000)
        .integer("iterations", &S::iterations, 1, 1000)
        .integer("motion_iterations", &S::motion_iterations, 1, 1000)
        .number("association_tolerance", &S::association_tolerance, Range::kNonNegative, "")
        .number("min_cluster_share", &S::min_cluster_share, Range::kNonNegative, "")
        .note("min_cluster_share", "share of the window's events below which a cluster dies")
        .number("min_cluster_gain", &S::min_cluster_gain, Range::kPositive, "")
        .note("min_cluster_gain", "relative sharpness a cluster's events must gain under its own motion")
        .number("model_gain_per_parameter", &S::model_gain_per_parameter, Range::kNonNegative, "")
        .number("noise_support", &S::noise_support, Range::kNonNegative, "lone votes")
        .number("new_motion_px", &S::new_motion_px, Range::kNonNegative, "px")
        .integer("split_rounds", &S::split_rounds, 0, 8)
        .note("split_rounds", "rounds of new clusters for tiles the clusters leave unexplained, kept if they survive the merges")
        .integer("footprint_radius_px", &S::footprint_radius_px, 0, 100)
        .seed("seed", &S::seed)
        .validate();
    Table<mapping::CmaxOptions> cmax("contrast maximisation settings");
    cmax.include(mapping::cmax_table(), [](mapping::CmaxOptions& o) -> mapping::CmaxOptions& { return o; },
                 {"model", "width", "height", "fx", "fy", "cx", "cy", "pyramid_levels"});
    Table<C> top("segment settings");
    top.section("window", window, self)
        .include(cmax_window_table(), &C::window, {"events", "duration_ms", "max_duration_ms", "min_events"})
        .section("segmentation", seg, [](C& c) -> S& { return c.segmentation; })
        .section("cmax", cmax, [](C& c) -> mapping::CmaxOptions& { return c.segmentation.cmax; })
        .ignored("description")
        .validate();
    return top;
  }();
  return table;
}


// The true per-event labels (the simulator's event_labels.txt: one integer per line, in the
// order of the dataset's events), read in step with the events.
class TrueLabels {
 public:
  explicit TrueLabels(const std::string& path) : path_(path), f_(path) {
    if (!f_) throw InputError(path, 0, "cannot open the true labels", kExpected);
  }
  uint16_t next() {
    std::string l;
    if (!std::getline(f_, l)) throw InputError(path_, line_, "fewer labels than events", kExpected);
    ++line_;
    char* end = nullptr;
    const unsigned long v = std::strtoul(l.c_str(), &end, 10);
    if (end == l.c_str() || v > 65535) throw InputError(path_, line_, "'" + l + "' is not a label", kExpected);
    return static_cast<uint16_t>(v);
  }
  bool more() {
    std::string l;
    while (std::getline(f_, l))
      if (l.find_first_not_of(" \t\r") != std::string::npos) return true;
    return false;
  }
  const std::string& path() const { return path_; }

 private:
  static constexpr const char* kExpected =
      "one label per event of the dataset, in event order (0 background, 1..N objects, 65535 noise)";
  std::string path_;
  std::ifstream f_;
  int64_t line_ = 0;
};

// A colour per label (BGR), well apart for the first few; -1 (noise) grey.
cv::Vec3b label_colour(int id) {
  static const cv::Vec3b palette[] = {{60, 76, 231}, {113, 204, 46}, {219, 152, 52}, {15, 196, 241},
                                      {182, 89, 155}, {34, 126, 230}, {160, 160, 22}, {94, 73, 52},
                                      {133, 160, 243}, {0, 84, 211}};
  if (id < 0) return {128, 128, 128};
  return palette[static_cast<size_t>(id) % (sizeof(palette) / sizeof(palette[0]))];
}

// The clusters' IWEs (each its own events, warped by its motion) in their colours, added.
void write_colour_iwe(const std::string& path, const pipeline::SegmentationWindow& w) {
  if (w.iwe.empty()) return;
  const int rows = static_cast<int>(w.iwe[0].rows()), cols = static_cast<int>(w.iwe[0].cols());
  cv::Mat acc(rows, cols, CV_32FC3, cv::Scalar(0, 0, 0));
  for (size_t j = 0; j < w.iwe.size(); ++j) {
    const double scale = robust_scale(w.iwe[j]);
    const cv::Vec3b c = label_colour(w.clusters[j].id);
    for (int y = 0; y < rows; ++y)
      for (int x = 0; x < cols; ++x) {
        const float v = std::min(1.0f, std::fabs(w.iwe[j](y, x)) / static_cast<float>(scale));
        if (v > 0) acc.at<cv::Vec3f>(y, x) += cv::Vec3f(c[0] * v, c[1] * v, c[2] * v);
      }
  }
  cv::Mat out;
  acc.convertTo(out, CV_8UC3);  // saturating
  if (!write_image(path, out)) throw InputError(path, 0, "cannot write the PNG", "a writable output folder");
}

}  // namespace

SegmentConfig load_segment_config(const std::string& path, const std::vector<std::string>& sets) {
  return yaml_config::read_config(segment_config_table(), SegmentConfig{}, path, sets,
                                  "a segment config YAML (see README.md, `evio segment`)");
}

std::string segment_config_text(const SegmentConfig& c) {
  return yaml_config::config_text(segment_config_table(), c,
                                  "# evio segment configuration, resolved: every key with the value used (comments: "
                                  "unit and range).\n# Readable by `evio segment --config`. The pinhole and image size "
                                  "are the camera's.\n");
}

SegmentConfig resolve_segment_config(const SegmentArgs& args) {
  SegmentConfig cfg = load_segment_config(args.config, args.set);
  if (args.window_events > 0) {
    cfg.window.window_events = args.window_events;
    cfg.window.window_ns = 0;
  }
  if (args.window_ns > 0) cfg.window.window_ns = args.window_ns;
  if (!args.clusters.empty()) {
    if (args.clusters == "auto") {
      cfg.segmentation.clusters = 0;
    } else {
      char* end = nullptr;
      const long n = std::strtol(args.clusters.c_str(), &end, 10);
      if (end == args.clusters.c_str() || *end != '\0' || n < 1 || n > 16)
        throw InputError("--clusters", 0, "'" + args.clusters + "' is not a cluster count", "auto or an integer in [1, 16]");
      cfg.segmentation.clusters = static_cast<int>(n);
    }
  }
  if (!args.models.empty()) {
    std::vector<mapping::WarpModel> models;
    std::string word;
    for (char c : args.models + ",") {
      if (c != ',') {
        word += c;
        continue;
      }
      const auto m = mapping::warp_model_from_name(word);
      if (!m) throw InputError("--models", 0, "unknown model '" + word + "'", "a comma-separated list of " + mapping::warp_model_names());
      if (std::find(models.begin(), models.end(), *m) == models.end()) models.push_back(*m);
      word.clear();
    }
    cfg.segmentation.models = models;
  }
  std::string why;
  if (!cfg.Validate(&why)) throw InputError(args.config.empty() ? "the flags" : args.config, 0, why, "valid segment settings");
  return cfg;
}

int run_segment(const SegmentArgs& args, std::ostream& out) {
  SegmentConfig cfg = resolve_segment_config(args);
  if (args.t_start_ns && args.t_end_ns && *args.t_end_ns <= *args.t_start_ns)
    throw InputError("--t-end", 0, "--t-end must be after --t-start", "--t-start S --t-end S with S in seconds");
  if (args.png_every < 1) throw InputError("--png-every", 0, "must be >= 1", "a positive window count");

  CmaxInput input = open_cmax_input(args.dataset, args.dataset_options, args.calib, cfg.segmentation.models);
  DatasetReader* reader = input.reader.get();
  const std::optional<calib::PinholeCamera>& camera = input.camera;
  const SensorSize sensor = input.sensor;

  cfg.keep_iwe = args.png;
  pipeline::SegmentationPipeline pipe(cfg, sensor.width, sensor.height, camera);
  SegmentConfig resolved = cfg;
  resolved.segmentation = pipe.segmentation_options();
  fs::create_directories(args.out);
  {
    TextOut f((fs::path(args.out) / "segment_config.yaml").string());
    std::fputs(segment_config_text(resolved).c_str(), f.get());
    f.close();
  }
  const std::string img_dir = (fs::path(args.out) / "images").string();
  if (args.png) fs::create_directories(img_dir);

  // --gt (or DATASET/event_labels.txt): the true labels, scored per window (label_evaluation.h).
  std::string gt_path = args.gt;
  std::string gt_note;
  if (gt_path.empty() && !args.no_gt) {
    std::error_code ec;
    const fs::path auto_path = fs::path(args.dataset) / "event_labels.txt";
    if (fs::is_directory(args.dataset, ec) && fs::is_regular_file(auto_path, ec)) {
      if (args.t_start_ns) gt_note = "not scored: --t-start skips events, so the labels cannot be matched";
      else gt_path = auto_path.string();
    }
  }
  if (!gt_path.empty() && args.t_start_ns)
    throw InputError("--gt", 0, "cannot be combined with --t-start (labels are matched by event order)",
                     "--gt without --t-start");
  std::unique_ptr<TrueLabels> truth;
  if (!gt_path.empty()) truth = std::make_unique<TrueLabels>(gt_path);
  evaluation::LabelAgreement in_windows;
  int64_t unsegmented_scored = 0;  // true-labelled events in no segmented window (wrong)
  std::vector<int> group_pred;
  std::vector<uint16_t> group_truth;

  // labels.txt in input order: the events wait in `pending` until their window is segmented.
  TextOut labels_file((fs::path(args.out) / "labels.txt").string());
  std::deque<SubpixelEvent> pending;
  int64_t pending_first = 0;  // stream index of pending.front()
  int64_t noise_written = 0, unsegmented = 0;
  std::map<int, int64_t> per_label;
  auto write_line = [&](const SubpixelEvent& e, int label) {
    char t[32];
    *format_seconds(e.t_ns, t) = '\0';
    const bool integer = e.x == std::floor(e.x) && e.y == std::floor(e.y);
    if (integer) {
      std::fprintf(labels_file.get(), "%s %d %d %d %d\n", t, static_cast<int>(e.x), static_cast<int>(e.y), e.polarity > 0 ? 1 : 0, label);
    } else {
      std::fprintf(labels_file.get(), "%s %.6f %.6f %d %d\n", t, e.x, e.y, e.polarity > 0 ? 1 : 0, label);
    }
    if (label < 0) ++noise_written;
    ++per_label[label];
  };
  // Writes the pending events up to stream index `end` (exclusive), labels from the window.
  auto flush_until = [&](int64_t end, const pipeline::SegmentationWindow* w) {
    size_t wi = 0;
    while (pending_first < end && !pending.empty()) {
      int label = -1;
      if (w) {
        while (wi < w->input_index.size() && w->input_index[wi] < pending_first) ++wi;
        if (wi < w->input_index.size() && w->input_index[wi] == pending_first) label = w->labels[wi];
      }
      const bool outside = !w || pending_first < w->input_begin;
      if (outside) ++unsegmented;
      if (truth) {
        const uint16_t t = truth->next();
        if (outside) {
          unsegmented_scored += t != evaluation::kNoiseLabel;
        } else {
          group_pred.push_back(label);
          group_truth.push_back(t);
        }
      }
      write_line(pending.front(), label);
      pending.pop_front();
      ++pending_first;
    }
    if (!group_pred.empty()) {  // one window: one majority mapping of its clusters
      in_windows.add(evaluation::score_labels(group_pred, group_truth));
      group_pred.clear();
      group_truth.clear();
    }
  };

  TextOut seg_json((fs::path(args.out) / "segments.json").string());
  std::fputs("{\n  \"windows\": [", seg_json.get());
  int64_t windows = 0, pngs = 0;
  std::vector<double> window_ms;
  std::set<int> ids_used;
  // The model block: windows per cluster count, clusters per warp model, and the gains that
  // decided the count (accepted: the smallest gain of the clusters kept; removed: of those merged).
  std::map<int, int64_t> count_windows;
  std::map<std::string, int64_t> model_clusters;
  std::vector<double> kept_gains, removed_gains;
  auto handle = [&](std::vector<pipeline::SegmentationWindow> ws) {
    for (const pipeline::SegmentationWindow& w : ws) {
      ++count_windows[static_cast<int>(w.clusters.size())];
      for (const mapping::SegmentCluster& k : w.clusters) ++model_clusters[mapping::warp_model_name(k.model)];
      for (const mapping::CountStep& cs : w.count_steps) (cs.removed ? removed_gains : kept_gains).push_back(cs.smallest_gain);
      flush_until(w.input_begin, nullptr);  // skipped windows before this one: no label
      flush_until(w.input_end, &w);
      window_ms.push_back(w.time_ms);
      std::ostringstream j;
      j << (windows ? "," : "") << "\n    {\"index\": " << w.index << ", \"t_start_s\": " << json_number(w.t_start_ns * 1e-9, 9)
        << ", \"t_end_s\": " << json_number(w.t_end_ns * 1e-9, 9) << ", \"events\": " << w.events << ", \"time_ms\": " << json_number(w.time_ms, 9)
        << ", \"alternations\": " << w.alternations << ", \"evaluations\": " << w.evaluations << ",\n     \"clusters\": [";
      for (size_t c = 0; c < w.clusters.size(); ++c) {
        const mapping::SegmentCluster& k = w.clusters[c];
        ids_used.insert(k.id);
        const std::vector<std::string> names = mapping::warp_parameter_names(k.model);
        j << (c ? "," : "") << "\n       {\"id\": " << k.id << ", \"model\": " << json_string(mapping::warp_model_name(k.model))
          << ", \"params\": {";
        for (size_t i = 0; i < names.size(); ++i) j << (i ? ", " : "") << json_string(names[i]) << ": " << json_number(k.params[static_cast<Eigen::Index>(i)], 9);
        j << "}, \"events\": " << json_number(k.events, 9) << ", \"objective\": " << json_number(k.objective, 9)
          << ", \"objective_best_other\": " << json_number(k.objective_other, 9) << ", \"gain\": " << json_number(k.gain, 9)
          << ", \"centroid_px\": [" << json_number(k.centroid.x(), 9) << ", " << json_number(k.centroid.y(), 9) << "], \"models_tried\": [";
        for (size_t m = 0; m < k.models.size(); ++m)
          j << (m ? ", " : "") << "{\"model\": " << json_string(mapping::warp_model_name(k.models[m].model))
            << ", \"objective\": " << json_number(k.models[m].objective, 9) << ", \"gain_over_simplest\": " << json_number(k.models[m].gain, 9)
            << ", \"chosen\": " << (k.models[m].chosen ? "true" : "false") << "}";
        j << "]}";
      }
      j << "],\n     \"count_steps\": [";
      for (size_t s = 0; s < w.count_steps.size(); ++s) {
        const mapping::CountStep& st = w.count_steps[s];
        j << (s ? ", " : "") << "{\"clusters\": " << st.clusters << ", \"smallest_gain\": " << json_number(st.smallest_gain, 9)
          << ", \"removed\": " << (st.removed ? "true" : "false") << "}";
      }
      j << "]}";
      std::fputs(j.str().c_str(), seg_json.get());
      if (args.png && w.index % args.png_every == 0) {
        char name[80];
        std::snprintf(name, sizeof(name), "window_%06lld.png", static_cast<long long>(w.index));
        write_colour_iwe((fs::path(img_dir) / name).string(), w);
        ++pngs;
        for (size_t c = 0; c < w.clusters.size(); ++c) {
          std::snprintf(name, sizeof(name), "window_%06lld_cluster_%d.png", static_cast<long long>(w.index), w.clusters[c].id);
          write_iwe_png((fs::path(img_dir) / name).string(), w.iwe[c], robust_scale(w.iwe[c]), false);
          ++pngs;
        }
      }
      ++windows;
    }
  };

  const CmaxStreamTotals totals = stream_cmax_events(
      reader, args.t_start_ns, args.t_end_ns, "evio segment", args.progress,
      [&](const SubpixelEvent& e) {
        pending.push_back(e);
        return pipe.process(e);
      },
      [&pipe] { pipe.finish(); }, [&] { handle(pipe.take_windows()); },
      [&pipe] { return std::to_string(pipe.stats().windows) + " windows"; });
  const int64_t events = totals.events;
  const double process_s = totals.process_s;
  flush_until(pending_first + static_cast<int64_t>(pending.size()), nullptr);
  labels_file.close();
  std::fputs("\n  ]\n}\n", seg_json.get());
  seg_json.close();

  if (truth) {
    if (!args.t_end_ns && truth->more())
      throw InputError(truth->path(), 0, "more labels than the " + std::to_string(events) + " events",
                       "one label per event of the dataset, in event order");
    const int64_t scored = in_windows.scored + unsegmented_scored;
    const double accuracy = scored > 0 ? static_cast<double>(in_windows.correct) / static_cast<double>(scored) : NAN;
    TextOut f((fs::path(args.out) / "eval.json").string());
    std::ostringstream j;
    j << "{\n  \"labels\": " << json_string(truth->path())
      << ",\n  \"protocol\": \"per window, each cluster mapped to the true label most of its events carry; accuracy over "
         "events with a true object label (not noise); events labelled -1 or in no segmented window count as wrong\""
      << ",\n  \"events_scored\": " << scored << ",\n  \"events_correct\": " << in_windows.correct
      << ",\n  \"accuracy\": " << json_number(accuracy, 9) << ",\n  \"label_error\": " << json_number(1.0 - accuracy, 9)
      << ",\n  \"events_in_windows_scored\": " << in_windows.scored
      << ",\n  \"accuracy_in_windows\": " << json_number(in_windows.scored ? in_windows.accuracy() : NAN, 9)
      << ",\n  \"per_label\": {";
    bool first = true;
    for (const auto& [l, c] : in_windows.scored_per_label) {
      const auto it = in_windows.correct_per_label.find(l);
      const int64_t ok = it == in_windows.correct_per_label.end() ? 0 : it->second;
      j << (first ? "" : ", ") << "\"" << l << "\": {\"events_in_windows\": " << c
        << ", \"accuracy_in_windows\": " << json_number(static_cast<double>(ok) / static_cast<double>(c), 9) << "}";
      first = false;
    }
    j << "}\n}\n";
    std::fputs(j.str().c_str(), f.get());
    f.close();
    out << "evio segment: labels against " << truth->path() << ": accuracy " << json_number(accuracy, 9) << " over " << scored
        << " events (" << json_number(in_windows.scored ? in_windows.accuracy() : NAN, 9) << " inside segmented windows); wrote eval.json\n";
  } else if (!gt_note.empty()) {
    out << "evio segment: event_labels.txt " << gt_note << "\n";
  }

  const pipeline::SegmentationStats& st = pipe.stats();
  const pipeline::CmaxWindowStats& ws = pipe.windows().stats();
  std::sort(window_ms.begin(), window_ms.end());
  const double median_ms = window_ms.empty() ? 0.0 : window_ms[window_ms.size() / 2];
  {
    TextOut f((fs::path(args.out) / "stats.json").string());
    std::ostringstream j;
    const mapping::SegmentationOptions& so = pipe.segmentation_options();
    int modal = 0;
    int64_t modal_n = -1;
    for (const auto& [c, n] : count_windows)
      if (n > modal_n) modal = c, modal_n = n;
    auto mean = [](const std::vector<double>& v) {
      double m = 0;
      for (double x : v) m += x;
      return v.empty() ? NAN : m / static_cast<double>(v.size());
    };
    std::ostringstream summary;
    summary << (so.clusters > 0 ? "fixed " : "auto ") << modal << " clusters in " << modal_n << " of " << st.windows << " windows;";
    for (const auto& [m, n] : model_clusters) summary << " " << m << " " << n;
    summary << " clusters";
    j << "{\n  \"model\": {\"summary\": " << json_string(summary.str()) << ", \"count\": {\"selection\": "
      << json_string(so.clusters > 0 ? "fixed" : "auto") << ", \"clusters\": " << so.clusters << ", \"max_clusters\": " << so.max_clusters
      << ", \"min_cluster_gain\": " << json_number(so.min_cluster_gain, 9) << ", \"modal\": " << modal << ", \"windows_per_count\": {";
    bool first = true;
    for (const auto& [c, n] : count_windows) j << (first ? "" : ", ") << "\"" << c << "\": " << n, first = false;
    j << "}, \"accepted_smallest_gain_mean\": " << json_number(mean(kept_gains), 9) << ", \"removed\": " << removed_gains.size()
      << ", \"removed_gain_mean\": " << json_number(mean(removed_gains), 9) << "}, \"warp\": {\"candidates\": [";
    for (size_t i = 0; i < so.models.size(); ++i) j << (i ? ", " : "") << json_string(mapping::warp_model_name(so.models[i]));
    j << "], \"gain_per_parameter\": " << json_number(so.model_gain_per_parameter, 9) << ", \"clusters_per_model\": {";
    first = true;
    for (const auto& [m, n] : model_clusters) j << (first ? "" : ", ") << json_string(m) << ": " << n, first = false;
    j << "}}, \"per_window\": \"segments.json\"}";
    j << ",\n  \"events\": " << events << ",\n  \"events_segmented\": " << ws.events_used
      << ",\n  \"events_labelled\": " << st.events_labelled << ",\n  \"events_noise\": " << st.events_noise
      << ",\n  \"events_in_no_window\": " << unsegmented << ",\n  \"events_dropped\": " << ws.events_dropped
      << ",\n  \"windows\": " << st.windows << ",\n  \"windows_skipped\": " << ws.windows_skipped
      << ",\n  \"labels_used\": " << ids_used.size() << ",\n  \"time_s\": " << json_number(process_s, 9)
      << ",\n  \"time_per_window_ms\": {\"mean\": " << json_number(st.windows ? st.time_ms / static_cast<double>(st.windows) : 0.0, 9)
      << ", \"median\": " << json_number(median_ms, 9) << ", \"max\": " << json_number(st.max_window_ms, 9) << "}"
      << ",\n  \"time_per_event_us\": " << json_number(ws.events_used ? st.time_ms * 1e3 / static_cast<double>(ws.events_used) : 0.0, 9)
      << ",\n  \"alternations\": " << st.alternations << ",\n  \"evaluations\": " << st.evaluations
      << ",\n  \"undistortion\": " << json_string(pipeline::cmax_undistortion_name(pipe.windows().undistortion()))
      << ",\n  \"undistortion_reason\": " << json_string(pipe.windows().undistortion_reason())
      << ",\n  \"dithered\": " << (pipe.windows().dithered() ? "true" : "false")
      << ",\n  \"objective\": " << json_string(mapping::cmax_objective_name(pipe.objective()))
      << ",\n  \"pngs\": " << pngs << "\n}\n";
    std::fputs(j.str().c_str(), f.get());
    f.close();
  }
  out << "evio segment: " << events << " events, " << st.windows << " windows (" << ws.windows_skipped
      << " skipped), " << ids_used.size() << " labels; " << json_number(median_ms, 9) << " ms per window (median), "
      << json_number(ws.events_used ? st.time_ms * 1e3 / static_cast<double>(ws.events_used) : 0.0, 9) << " us per event\n"
      << "undistortion: " << pipeline::cmax_undistortion_name(pipe.windows().undistortion()) << " ("
      << pipe.windows().undistortion_reason() << ")\n"
      << "wrote " << args.out << "/labels.txt, segments.json, stats.json, segment_config.yaml"
      << (args.png ? ", images/" : "") << "\n";
  return 0;
}

}  // namespace evio::apps
