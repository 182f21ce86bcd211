#include "segment_command.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <map>
#include <memory>
#include <ostream>
#include <set>
#include <sstream>

#include <opencv2/core.hpp>

#include "evio/calib/error.h"
#include "evio/calib/json.h"
#include "evio/evaluation/windowed_label_evaluation.h"
#include "evio/sensors/config_table.h"
#include "evio/sensors/image_io.h"
#include "evio/sensors/time.h"
#include "cmax_input.h"
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

// The true labels to score against: --gt, else DATASET/event_labels.txt when present (not with
// --no-gt); nullptr for none. The labels are matched by event order, so --t-start excludes them:
// an error with --gt, and *note says why the dataset's own are not scored.
std::unique_ptr<evaluation::EventLabelReader> open_true_labels(const SegmentArgs& args, std::string* note) {
  std::string path = args.gt;
  if (path.empty() && !args.no_gt) {
    std::error_code ec;
    const fs::path auto_path = fs::path(args.dataset) / "event_labels.txt";
    if (fs::is_directory(args.dataset, ec) && fs::is_regular_file(auto_path, ec)) {
      if (args.t_start_ns) *note = "not scored: --t-start skips events, so the labels cannot be matched";
      else path = auto_path.string();
    }
  }
  if (!path.empty() && args.t_start_ns)
    throw InputError("--gt", 0, "cannot be combined with --t-start (labels are matched by event order)",
                     "--gt without --t-start");
  if (path.empty()) return nullptr;
  return std::make_unique<evaluation::EventLabelReader>(path);
}

// labels.txt in input order: the events wait until their window is segmented, then each is written
// with its cluster (-1: noise, or in no segmented window) and, with true labels, scored (each
// window one group; windowed_label_evaluation.h).
class LabelWriter {
 public:
  LabelWriter(const std::string& path, evaluation::EventLabelReader* truth) : file_(path), truth_(truth) {}

  void push(const SubpixelEvent& e) { pending_.push_back(e); }
  // A segmented window: the events before it (skipped windows) without a label, then its own.
  void write_window(const pipeline::SegmentationWindow& w) {
    flush_until(w.input_begin, nullptr);
    flush_until(w.input_end, &w);
  }
  // The events after the last window, without a label.
  void finish() {
    flush_until(pending_first_ + static_cast<int64_t>(pending_.size()), nullptr);
    file_.close();
  }

  int64_t unsegmented() const { return unsegmented_; }  // events in no segmented window
  const evaluation::WindowedLabelScore& score() const { return score_; }

 private:
  // Writes the pending events up to stream index `end` (exclusive), labels from the window.
  void flush_until(int64_t end, const pipeline::SegmentationWindow* w) {
    size_t wi = 0;
    while (pending_first_ < end && !pending_.empty()) {
      int label = -1;
      if (w) {
        while (wi < w->input_index.size() && w->input_index[wi] < pending_first_) ++wi;
        if (wi < w->input_index.size() && w->input_index[wi] == pending_first_) label = w->labels[wi];
      }
      const bool outside = !w || pending_first_ < w->input_begin;
      if (outside) ++unsegmented_;
      if (truth_) {
        const uint16_t t = truth_->next();
        if (outside) score_.add_outside(t);
        else score_.add(label, t);
      }
      write_line(pending_.front(), label);
      pending_.pop_front();
      ++pending_first_;
    }
    score_.end_window();
  }

  void write_line(const SubpixelEvent& e, int label) {
    char t[32];
    *format_seconds(e.t_ns, t) = '\0';
    const bool integer = e.x == std::floor(e.x) && e.y == std::floor(e.y);
    if (integer) {
      std::fprintf(file_.get(), "%s %d %d %d %d\n", t, static_cast<int>(e.x), static_cast<int>(e.y), e.polarity > 0 ? 1 : 0, label);
    } else {
      std::fprintf(file_.get(), "%s %.6f %.6f %d %d\n", t, e.x, e.y, e.polarity > 0 ? 1 : 0, label);
    }
  }

  TextOut file_;
  evaluation::EventLabelReader* truth_;
  std::deque<SubpixelEvent> pending_;
  int64_t pending_first_ = 0;  // stream index of pending_.front()
  int64_t unsegmented_ = 0;
  evaluation::WindowedLabelScore score_;
};

// One cluster of segments.json: its motion, events, objectives and the models tried.
std::string cluster_json(const mapping::SegmentCluster& k) {
  const std::vector<std::string> names = mapping::warp_parameter_names(k.model);
  JsonObject params(9);
  for (size_t i = 0; i < names.size(); ++i) params.number(names[i], k.params[static_cast<Eigen::Index>(i)]);
  std::vector<std::string> tried;
  for (const mapping::ModelTrial& m : k.models)
    tried.push_back(JsonObject(9)
                        .string("model", mapping::warp_model_name(m.model))
                        .number("objective", m.objective)
                        .number("gain_over_simplest", m.gain)
                        .boolean("chosen", m.chosen)
                        .str());
  return JsonObject(9)
      .integer("id", k.id)
      .string("model", mapping::warp_model_name(k.model))
      .raw("params", params.str())
      .number("events", k.events)
      .number("objective", k.objective)
      .number("objective_best_other", k.objective_other)
      .number("gain", k.gain)
      .raw("centroid_px", json_numbers(k.centroid, 9))
      .raw("models_tried", json_array(tried))
      .str();
}

// segments.json, one window per line group, the images (--png, every png_every-th window), and
// the counts of stats.json's model block: windows per cluster count, clusters per warp model, and
// the gains that decided the count (accepted: the smallest gain of the clusters kept; removed: of
// those merged).
class SegmentsWriter {
 public:
  SegmentsWriter(const std::string& path, const std::string& img_dir, bool png, int png_every)
      : file_(path), img_dir_(img_dir), png_(png), png_every_(png_every) {
    std::fputs("{\n  \"windows\": [", file_.get());
  }

  void write(const pipeline::SegmentationWindow& w) {
    ++count_windows_[static_cast<int>(w.clusters.size())];
    for (const mapping::SegmentCluster& k : w.clusters) ++model_clusters_[mapping::warp_model_name(k.model)];
    for (const mapping::CountStep& cs : w.count_steps) (cs.removed ? removed_gains_ : kept_gains_).push_back(cs.smallest_gain);
    window_ms_.push_back(w.time_ms);
    std::string j = std::string(windows_ ? "," : "") + "\n    {\"index\": " + std::to_string(w.index) +
                    ", \"t_start_s\": " + json_number(w.t_start_ns * 1e-9, 9) + ", \"t_end_s\": " + json_number(w.t_end_ns * 1e-9, 9) +
                    ", \"events\": " + std::to_string(w.events) + ", \"time_ms\": " + json_number(w.time_ms, 9) +
                    ", \"alternations\": " + std::to_string(w.alternations) + ", \"evaluations\": " + std::to_string(w.evaluations) +
                    ",\n     \"clusters\": [";
    for (size_t c = 0; c < w.clusters.size(); ++c) {
      ids_used_.insert(w.clusters[c].id);
      j += (c ? ",\n       " : "\n       ") + cluster_json(w.clusters[c]);
    }
    std::vector<std::string> steps;
    for (const mapping::CountStep& st : w.count_steps)
      steps.push_back(JsonObject(9).integer("clusters", st.clusters).number("smallest_gain", st.smallest_gain).boolean("removed", st.removed).str());
    j += "],\n     \"count_steps\": " + json_array(steps) + "}";
    std::fputs(j.c_str(), file_.get());
    if (png_ && w.index % png_every_ == 0) write_pngs(w);
    ++windows_;
  }

  void close() {
    std::fputs("\n  ]\n}\n", file_.get());
    file_.close();
  }

  // stats.json's model block.
  std::string model_json(const mapping::SegmentationOptions& so, int64_t windows) const;
  const std::vector<double>& window_ms() const { return window_ms_; }
  size_t labels_used() const { return ids_used_.size(); }
  int64_t pngs() const { return pngs_; }

 private:
  void write_pngs(const pipeline::SegmentationWindow& w) {
    char name[80];
    std::snprintf(name, sizeof(name), "window_%06lld.png", static_cast<long long>(w.index));
    write_colour_iwe((fs::path(img_dir_) / name).string(), w);
    ++pngs_;
    for (size_t c = 0; c < w.clusters.size(); ++c) {
      std::snprintf(name, sizeof(name), "window_%06lld_cluster_%d.png", static_cast<long long>(w.index), w.clusters[c].id);
      write_iwe_png((fs::path(img_dir_) / name).string(), w.iwe[c], robust_scale(w.iwe[c]), false);
      ++pngs_;
    }
  }

  TextOut file_;
  const std::string img_dir_;
  const bool png_;
  const int png_every_;
  int64_t windows_ = 0, pngs_ = 0;
  std::vector<double> window_ms_;
  std::set<int> ids_used_;
  std::map<int, int64_t> count_windows_;
  std::map<std::string, int64_t> model_clusters_;
  std::vector<double> kept_gains_, removed_gains_;
};

std::string SegmentsWriter::model_json(const mapping::SegmentationOptions& so, int64_t windows) const {
  int modal = 0;
  int64_t modal_n = -1;
  for (const auto& [c, n] : count_windows_)
    if (n > modal_n) modal = c, modal_n = n;
  auto mean = [](const std::vector<double>& v) {
    double m = 0;
    for (double x : v) m += x;
    return v.empty() ? NAN : m / static_cast<double>(v.size());
  };
  std::ostringstream summary;
  summary << (so.clusters > 0 ? "fixed " : "auto ") << modal << " clusters in " << modal_n << " of " << windows << " windows;";
  for (const auto& [m, n] : model_clusters_) summary << " " << m << " " << n;
  summary << " clusters";
  JsonObject per_count(9), per_model(9);
  for (const auto& [c, n] : count_windows_) per_count.integer(std::to_string(c), n);
  for (const auto& [m, n] : model_clusters_) per_model.integer(m, n);
  std::vector<std::string> candidates;
  for (mapping::WarpModel m : so.models) candidates.push_back(mapping::warp_model_name(m));
  return JsonObject(9)
      .string("summary", summary.str())
      .raw("count", JsonObject(9)
                        .string("selection", so.clusters > 0 ? "fixed" : "auto")
                        .integer("clusters", so.clusters)
                        .integer("max_clusters", so.max_clusters)
                        .number("min_cluster_gain", so.min_cluster_gain)
                        .integer("modal", modal)
                        .raw("windows_per_count", per_count.str())
                        .number("accepted_smallest_gain_mean", mean(kept_gains_))
                        .integer("removed", static_cast<int64_t>(removed_gains_.size()))
                        .number("removed_gain_mean", mean(removed_gains_))
                        .str())
      .raw("warp", JsonObject(9)
                       .raw("candidates", json_strings(candidates))
                       .number("gain_per_parameter", so.model_gain_per_parameter)
                       .raw("clusters_per_model", per_model.str())
                       .str())
      .string("per_window", "segments.json")
      .str();
}

// eval.json: the labels' accuracy over all true-labelled events and inside segmented windows, per
// true label. Throws evio::InputError when the file has more labels than the stream had events
// (unless --t-end cut the stream).
void write_label_eval(const SegmentArgs& args, evaluation::EventLabelReader* truth, const evaluation::WindowedLabelScore& s,
                      int64_t events, std::ostream& out) {
  if (!args.t_end_ns && truth->more())
    throw InputError(truth->path(), 0, "more labels than the " + std::to_string(events) + " events",
                     "one label per event of the dataset, in event order");
  const evaluation::LabelAgreement& in = s.in_windows();
  JsonObject per_label(9);
  for (const auto& [l, c] : in.scored_per_label) {
    const auto it = in.correct_per_label.find(l);
    const int64_t ok = it == in.correct_per_label.end() ? 0 : it->second;
    per_label.raw(std::to_string(l), JsonObject(9)
                                         .integer("events_in_windows", c)
                                         .number("accuracy_in_windows", static_cast<double>(ok) / static_cast<double>(c))
                                         .str());
  }
  JsonObject j(9, JsonObject::Layout::kLines);
  j.string("labels", truth->path())
      .string("protocol", evaluation::kWindowedLabelProtocol)
      .integer("events_scored", s.scored())
      .integer("events_correct", s.correct())
      .number("accuracy", s.accuracy())
      .number("label_error", 1.0 - s.accuracy())
      .integer("events_in_windows_scored", in.scored)
      .number("accuracy_in_windows", s.accuracy_in_windows())
      .raw("per_label", per_label.str());
  write_text_file((fs::path(args.out) / "eval.json").string(), j.str() + "\n");
  out << "evio segment: labels against " << truth->path() << ": accuracy " << json_number(s.accuracy(), 9) << " over "
      << s.scored() << " events (" << json_number(s.accuracy_in_windows(), 9) << " inside segmented windows); wrote eval.json\n";
}

// The median window time as stats.json gives it (the upper middle of the sorted times; 0 for none).
double median_window_ms(std::vector<double> ms) {
  std::sort(ms.begin(), ms.end());
  return ms.empty() ? 0.0 : ms[ms.size() / 2];
}

}  // namespace

SegmentConfig load_segment_config(const std::string& path, const std::vector<std::string>& sets) {
  return yaml_config::read_config(segment_config_table(), SegmentConfig{}, path, sets,
                                  "a segment config YAML (see docs/commands/segment.md)");
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

  // ---- inputs: the dataset and its camera ----------------------------------------------------------
  CmaxInput input = open_cmax_input(args.dataset, args.dataset_options, args.calib, cfg.segmentation.models);

  // ---- the pipeline, and the resolved config --------------------------------------------------------
  cfg.keep_iwe = args.png;
  pipeline::SegmentationPipeline pipe(cfg, input.sensor.width, input.sensor.height, input.camera);
  SegmentConfig resolved = cfg;
  resolved.segmentation = pipe.segmentation_options();
  fs::create_directories(args.out);
  write_text_file((fs::path(args.out) / "segment_config.yaml").string(), segment_config_text(resolved));
  const std::string img_dir = (fs::path(args.out) / "images").string();
  if (args.png) fs::create_directories(img_dir);

  // ---- the true labels (--gt or DATASET/event_labels.txt), scored per window -----------------------
  std::string gt_note;
  const std::unique_ptr<evaluation::EventLabelReader> truth = open_true_labels(args, &gt_note);

  // ---- the event stream: labels.txt in input order, segments.json and images per window ----------
  LabelWriter labels((fs::path(args.out) / "labels.txt").string(), truth.get());
  SegmentsWriter segments((fs::path(args.out) / "segments.json").string(), img_dir, args.png, args.png_every);
  const CmaxStreamTotals totals = stream_cmax_events(
      input.reader.get(), args.t_start_ns, args.t_end_ns, "evio segment", args.progress,
      [&](const SubpixelEvent& e) {
        labels.push(e);
        return pipe.process(e);
      },
      [&pipe] { pipe.finish(); },
      [&] {
        for (const pipeline::SegmentationWindow& w : pipe.take_windows()) {
          labels.write_window(w);
          segments.write(w);
        }
      },
      [&pipe] { return std::to_string(pipe.stats().windows) + " windows"; });
  labels.finish();
  segments.close();

  // ---- eval.json, stats.json and the summary -------------------------------------------------------
  if (truth) write_label_eval(args, truth.get(), labels.score(), totals.events, out);
  else if (!gt_note.empty()) out << "evio segment: event_labels.txt " << gt_note << "\n";

  const pipeline::SegmentationStats& st = pipe.stats();
  const pipeline::CmaxWindowStats& ws = pipe.windows().stats();
  const double median_ms = median_window_ms(segments.window_ms());
  const double us_per_event = ws.events_used ? st.time_ms * 1e3 / static_cast<double>(ws.events_used) : 0.0;
  JsonObject j(9, JsonObject::Layout::kLines);
  j.raw("model", segments.model_json(pipe.segmentation_options(), st.windows))
      .integer("events", totals.events)
      .integer("events_segmented", ws.events_used)
      .integer("events_labelled", st.events_labelled)
      .integer("events_noise", st.events_noise)
      .integer("events_in_no_window", labels.unsegmented())
      .integer("events_dropped", ws.events_dropped)
      .integer("windows", st.windows)
      .integer("windows_skipped", ws.windows_skipped)
      .integer("labels_used", static_cast<int64_t>(segments.labels_used()))
      .number("time_s", totals.process_s)
      .raw("time_per_window_ms", JsonObject(9)
                                     .number("mean", st.windows ? st.time_ms / static_cast<double>(st.windows) : 0.0)
                                     .number("median", median_ms)
                                     .number("max", st.max_window_ms)
                                     .str())
      .number("time_per_event_us", us_per_event)
      .integer("alternations", st.alternations)
      .integer("evaluations", st.evaluations)
      .string("undistortion", pipeline::cmax_undistortion_name(pipe.windows().undistortion()))
      .string("undistortion_reason", pipe.windows().undistortion_reason())
      .boolean("dithered", pipe.windows().dithered())
      .string("objective", mapping::cmax_objective_name(pipe.objective()))
      .integer("pngs", segments.pngs());
  write_text_file((fs::path(args.out) / "stats.json").string(), j.str() + "\n");

  out << "evio segment: " << totals.events << " events, " << st.windows << " windows (" << ws.windows_skipped
      << " skipped), " << segments.labels_used() << " labels; " << json_number(median_ms, 9) << " ms per window (median), "
      << json_number(us_per_event, 9) << " us per event\n"
      << "undistortion: " << pipeline::cmax_undistortion_name(pipe.windows().undistortion()) << " ("
      << pipe.windows().undistortion_reason() << ")\n"
      << "wrote " << args.out << "/labels.txt, segments.json, stats.json, segment_config.yaml"
      << (args.png ? ", images/" : "") << "\n";
  return 0;
}

}  // namespace evio::apps
