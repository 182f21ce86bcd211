#include "corners_command.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <ostream>
#include <sstream>
#include <vector>

#include <opencv2/imgproc.hpp>
#include <yaml-cpp/yaml.h>

#include "evio/calib/calibration_io.h"
#include "evio/calib/error.h"
#include "evio/evaluation/corner_evaluation.h"
#include "evio/sensors/image_io.h"
#include "evio/sensors/time.h"
#include "evio/simulator/scene_config.h"
#include "evio/simulator/simulator.h"
#include "evio/calib/json.h"
#include "progress.h"
#include "evio/sensors/config_table.h"
#include "evio/sensors/dataset_calibration.h"
#include "evio/frontend/option_tables.h"
#include "option_tables.h"
#include "output_files.h"

namespace evio::apps {
namespace {
namespace fs = std::filesystem;

struct TrackLengths {
  size_t count = 0;
  double mean = 0, median = 0, max = 0;  // corner events per track
  double mean_duration_s = 0;
};

// Track lengths as the tracks end: a count per length (memory bounded by the longest track, not by
// the number of tracks).
class TrackLengthCounter {
 public:
  void add(const frontend::CornerTrack& t) {
    ++by_length_[t.points.size()];
    ++count_;
    points_ += t.points.size();
    duration_s_ += static_cast<double>(t.t_end_ns() - t.t_begin_ns()) * 1e-9;
  }
  TrackLengths summary() const {
    TrackLengths r;
    r.count = count_;
    if (count_ == 0) return r;
    r.mean = static_cast<double>(points_) / static_cast<double>(count_);
    r.max = static_cast<double>(by_length_.rbegin()->first);
    r.mean_duration_s = duration_s_ / static_cast<double>(count_);
    // The median: the middle length (the mean of the two middle ones for an even count).
    const auto nth = [this](size_t k) {  // k-th smallest length, 0-based
      for (const auto& [len, n] : by_length_) {
        if (k < n) return static_cast<double>(len);
        k -= n;
      }
      return 0.0;
    };
    r.median = count_ % 2 ? nth(count_ / 2) : 0.5 * (nth(count_ / 2 - 1) + nth(count_ / 2));
    return r;
  }

 private:
  std::map<size_t, size_t> by_length_;
  size_t count_ = 0, points_ = 0;
  double duration_s_ = 0;
};

}  // namespace

namespace {

using C = CornersConfig;

// The table of `--config` and `--set` (one declaration per key: reading, validation, the resolved
// config); the filters, eFAST, corner tracker and DART share their tables with `evio vio`.
const yaml_config::Table<C>& corners_config_table() {
  using yaml_config::Range;
  using yaml_config::Table;
  static const Table<C> table = [] {
    auto self = [](C& c) -> C& { return c; };
    Table<C> tracker("tracker settings");
    tracker.boolean("enabled", &C::tracks)
        .boolean("descriptors", &C::descriptors)
        .include(frontend::corner_tracker_table(), &C::tracker);
    Table<C> frames("overlay settings");
    frames.duration_ms("every_ms", &C::frames_every_ns, Range::kNonNegative)
        .duration_ms("window_ms", &C::frame_window_ns, Range::kPositive)
        .integer("scale", &C::frame_scale, 1, 8)
        .duration_ms("track_history_ms", &C::frame_track_history_ns, Range::kNonNegative);
    Table<C> top("corners settings");
    top.section("refractory", refractory_section<C>(), self)
        .section("background_activity", background_activity_section<C>(), self)
        .section("efast", frontend::efast_table(), &C::efast)
        .section("tracker", tracker, self)
        .section("dart", frontend::dart_table(), &C::dart)
        .section("frames", frames, self)
        .ignored("description");
    return top;
  }();
  return table;
}

}  // namespace

CornersConfig load_corners_config(const std::string& path, const std::vector<std::string>& sets) {
  return yaml_config::read_config(corners_config_table(), CornersConfig{}, path, sets,
                                  "a corners config YAML (see docs/commands/corners.md)");
}

std::string corners_config_text(const CornersConfig& c) {
  return yaml_config::config_text(corners_config_table(), c,
                                  "# evio corners configuration, resolved: every key with the value used (comments: "
                                  "unit and range).\n# Readable by `evio corners --config`.\n");
}

namespace {

// Overlay of one window: events (ON white, OFF black on grey), corner events of the window
// (green circles) and the recent part of every track (yellow polylines, red head).
class OverlayWriter {
 public:
  OverlayWriter(std::string dir, int w, int h, const CornersConfig& c) : dir_(std::move(dir)), w_(w), h_(h), c_(c) {
    fs::create_directories(dir_);
    reset_image();
  }
  int64_t next_frame_ns = 0;
  int written = 0;

  void add_event(const Event& e) {
    if (e.t_ns < next_frame_ns - c_.frame_window_ns) return;
    img_.at<uint8_t>(e.y, e.x) = e.polarity > 0 ? 255 : 0;
  }
  void add_corner(const Event& e) {
    if (e.t_ns >= next_frame_ns - c_.frame_window_ns) corners_.push_back(e);
  }
  // Writes the overlay for time next_frame_ns; tracks are the tracker's active ones.
  void write(const frontend::CornerTracker* tracker) {
    cv::Mat big;
    cv::resize(img_, big, cv::Size(w_ * c_.frame_scale, h_ * c_.frame_scale), 0, 0, cv::INTER_NEAREST);
    cv::Mat color;
    cv::cvtColor(big, color, cv::COLOR_GRAY2BGR);
    const double s = c_.frame_scale;
    auto P = [s](double x, double y) { return cv::Point(static_cast<int>(std::lround((x + 0.5) * s)), static_cast<int>(std::lround((y + 0.5) * s))); };
    for (const Event& e : corners_) cv::circle(color, P(e.x, e.y), static_cast<int>(2 * s), cv::Scalar(0, 200, 0), 1, cv::LINE_AA);
    if (tracker) {
      tracker->visit_active([&](const frontend::CornerTrack& t) {
        std::vector<cv::Point> pts;
        for (auto it = t.points.rbegin(); it != t.points.rend() && next_frame_ns - it->t_ns <= c_.frame_track_history_ns; ++it) {
          pts.push_back(P(it->x, it->y));
        }
        if (pts.size() < 2) return;
        cv::polylines(color, pts, false, cv::Scalar(0, 220, 255), 1, cv::LINE_AA);
        cv::circle(color, pts.front(), 2, cv::Scalar(0, 0, 255), cv::FILLED);
      });
    }
    char name[64];
    std::snprintf(name, sizeof(name), "frame_%06d.png", written);
    const std::string path = (fs::path(dir_) / name).string();
    if (!write_image(path, color)) throw InputError(path, 0, "cannot write the PNG", "a writable output folder");
    ++written;
    reset_image();
  }

 private:
  void reset_image() {
    img_ = cv::Mat(h_, w_, CV_8UC1, cv::Scalar(128));
    corners_.clear();
  }
  std::string dir_;
  int w_, h_;
  const CornersConfig& c_;
  cv::Mat img_;
  std::vector<Event> corners_;
};

}  // namespace

namespace {

// The camera and the sensor size: --calib, else the dataset folder's calib.yaml (`evio simulate`
// writes it: size of a scaled camera), else the dataset's own; never assumed.
struct CornersCamera {
  std::optional<calib::CameraCalibration> cal;
  SensorSize sensor;
};

CornersCamera open_corners_camera(const CornersArgs& args, DatasetReader& reader) {
  CornersCamera c;
  if (!args.calib.empty()) {
    const bool yaml = fs::path(args.calib).extension() == ".yaml" || fs::path(args.calib).extension() == ".yml";
    if (yaml) {
      c.cal = calib::load_kalibr_camchain(args.calib).front();
    } else {
      const SensorSize s = reader.sensor_size();
      c.cal = calib::load_ecd_calib(args.calib, s.known() ? s.width : 240, s.known() ? s.height : 180);
    }
  } else {
    c.cal = find_dataset_calibration(args.dataset, "", reader).camera;
  }
  c.sensor = reader.sensor_size();
  if (c.cal) c.sensor = {c.cal->camera.width(), c.cal->camera.height()};
  if (!c.sensor.known()) {
    throw InputError(args.dataset, 0, "the sensor size is unknown (no calibration in the dataset)",
                     "--calib FILE (Kalibr camchain YAML or ECD calib.txt) or --sensor WxH");
  }
  return c;
}

// True corners of a simulated dataset (--gt SCENE.yaml, or DATASET/scene_resolved.yaml that
// `evio simulate` writes): the checkerboard grid nodes projected through the true camera pose.
struct CornerTruth {
  std::string scene;
  std::vector<simulator::SceneCorner> corners;
  std::unique_ptr<simulator::Simulator> sim;
  std::unique_ptr<evaluation::CornerEventScorer> scorer;  // null without true corners
};

std::unique_ptr<CornerTruth> open_corner_truth(const CornersArgs& args, SensorSize sensor, std::ostream& out) {
  auto truth = std::make_unique<CornerTruth>();
  truth->scene = args.gt;
  std::error_code ec;
  const fs::path auto_scene = fs::path(args.dataset) / "scene_resolved.yaml";
  if (truth->scene.empty() && !args.no_gt && fs::is_directory(args.dataset, ec) && fs::is_regular_file(auto_scene, ec))
    truth->scene = auto_scene.string();
  if (truth->scene.empty()) return truth;
  const simulator::SimulationConfig sc = simulator::load_simulation_config(truth->scene);
  if (sc.simulator.camera.width() != sensor.width || sc.simulator.camera.height() != sensor.height)
    throw InputError(truth->scene, 0,
                     "the scene's camera is " + std::to_string(sc.simulator.camera.width()) + " x " +
                         std::to_string(sc.simulator.camera.height()) + " px",
                     "the scene the dataset was simulated from (" + std::to_string(sensor.width) + " x " +
                         std::to_string(sensor.height) + " px)");
  truth->corners = sc.corners;
  if (truth->corners.empty()) {
    out << "evio corners: " << truth->scene << " has no true corners (checkerboard planes): no eval.json\n";
    return truth;
  }
  truth->sim = std::make_unique<simulator::Simulator>(sc.scene, sc.trajectory, sc.simulator);
  const simulator::Simulator* sim = truth->sim.get();
  // Written stamp -> simulator time: minus the scene's output.clock_offset_ns, plus its time shift.
  const int64_t shift = sc.simulator.time_shift_ns - sc.clock_offset_ns;
  std::vector<bool> inner;
  for (const simulator::SceneCorner& c : truth->corners) inner.push_back(c.inner);
  const std::vector<simulator::SceneCorner>* corners = &truth->corners;
  truth->scorer = std::make_unique<evaluation::CornerEventScorer>(
      sensor.width, sensor.height, static_cast<int>(corners->size()), inner,
      [sim, shift, corners](int64_t t_ns, std::vector<Eigen::Vector2d>* px) {
        px->assign(corners->size(), Eigen::Vector2d::Constant(NAN));
        const calib::SE3 T_c_w = sim->camera_state(t_ns + shift).T_w_c.inverse();
        for (size_t c = 0; c < corners->size(); ++c) {
          Eigen::Vector2d p;
          if (sim->options().camera.project(T_c_w * (*corners)[c].p_w, &p)) (*px)[c] = p;
        }
      },
      sim->t_begin_ns() - shift, sim->t_end_ns() - shift);
  return truth;
}

// corners.txt (every corner event as it is decided) and tracks.txt (one line per track point, each
// track written when it ends, not kept in memory).
class CornerFiles {
 public:
  CornerFiles(const fs::path& out, bool tracks, const std::optional<calib::CameraCalibration>& cal)
      : corners_((out / "corners.txt").string()), cal_(cal) {
    std::fputs("# t[s] x y p   (eFAST corner events, polarity as in the input)\n", corners_.get());
    if (!tracks) return;
    tracks_ = std::make_unique<TextOut>((out / "tracks.txt").string());
    std::fputs(cal ? "# track_id t[s] x y x_undistorted y_undistorted   (px; smoothed track positions; tracks in the order they ended)\n"
                   : "# track_id t[s] x y   (px; smoothed track positions; tracks in the order they ended)\n",
               tracks_->get());
  }
  void corner(const Event& e, bool zero_one) {
    *format_seconds(e.t_ns, line_) = '\0';
    std::fprintf(corners_.get(), "%s %d %d %d\n", line_, e.x, e.y, e.polarity > 0 ? 1 : (zero_one ? 0 : -1));
  }
  void tracks(const std::vector<frontend::CornerTrack>& ended) {
    for (const auto& t : ended) {
      lengths_.add(t);
      for (const auto& p : t.points) {
        *format_seconds(p.t_ns, line_) = '\0';
        std::fprintf(tracks_->get(), "%lld %s %.3f %.3f", static_cast<long long>(t.id), line_, p.x, p.y);
        if (cal_) {
          const auto& k = cal_->camera.intrinsics();
          Eigen::Vector2d n;
          if (cal_->camera.undistort(Eigen::Vector2d((p.x - k.cx) / k.fx, (p.y - k.cy) / k.fy), &n)) {
            std::fprintf(tracks_->get(), " %.3f %.3f", k.fx * n.x() + k.cx, k.fy * n.y() + k.cy);
          } else {
            std::fputs(" nan nan", tracks_->get());
          }
        }
        std::fputc('\n', tracks_->get());
      }
    }
  }
  void close_corners() { corners_.close(); }
  void close_tracks() { tracks_->close(); }
  TrackLengths lengths() const { return lengths_.summary(); }

 private:
  TextOut corners_;
  std::unique_ptr<TextOut> tracks_;
  const std::optional<calib::CameraCalibration>& cal_;
  TrackLengthCounter lengths_;
  char line_[96];
};

struct CornersRun {
  int64_t events = 0, t_first = 0, t_last = 0;
  double processing_s = 0, overlay_s = 0;  // overlay drawing/PNG time is not processing time
  double scoring_s = 0;
  double duration_s() const { return events > 1 ? static_cast<double>(t_last - t_first) * 1e-9 : 0.0; }
};

// The events through the front-end in chunks; corner events and ended tracks written as they come,
// overlays drawn every frames_every_ns, and (after the processing timer) the chunk's decisions scored.
CornersRun stream_corners(const CornersArgs& args, const CornersConfig& cfg, DatasetReader& reader, SensorSize sensor,
                          pipeline::CornerPipeline& front, CornerFiles& files, OverlayWriter* overlay,
                          evaluation::CornerEventScorer* scorer) {
  const frontend::CornerTracker* tracker = front.tracker();
  Progress progress("evio corners", args.progress, "events");
  CornersRun run;
  EventBuffer chunk;
  std::vector<uint8_t> flags;  // the chunk's corner decisions, scored after the processing timer
  bool zero_one = true;        // polarity convention of the input, known after the first chunk
  bool first_chunk = true;
  for (;;) {
    chunk.clear();
    if (reader.read_events(&chunk, size_t{1} << 20) == 0) break;
    if (first_chunk) {
      zero_one = reader.event_report().polarity != PolarityConvention::kMinusPlusOne;
      run.t_first = chunk.front().t_ns;
      if (overlay) overlay->next_frame_ns = run.t_first + cfg.frames_every_ns;
      first_chunk = false;
    }
    run.t_last = chunk.back().t_ns;
    const auto t0 = std::chrono::steady_clock::now();
    if (scorer) flags.assign(chunk.size(), 0);
    size_t k = 0;
    for (const Event& e : chunk.span()) {
      ++run.events;
      ++k;
      if (overlay && e.x < sensor.width && e.y < sensor.height) {
        while (e.t_ns >= overlay->next_frame_ns) {
          const auto w0 = std::chrono::steady_clock::now();
          overlay->write(tracker);
          overlay->next_frame_ns += cfg.frames_every_ns;
          run.overlay_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - w0).count();
        }
        overlay->add_event(e);
      }
      if (!front.process(e)) continue;
      if (scorer) flags[k - 1] = 1;
      files.corner(e, zero_one);
      if (overlay) overlay->add_corner(e);
    }
    std::vector<frontend::CornerTrack> ended = front.take_finished_tracks();
    run.processing_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (scorer) {
      const auto s0 = std::chrono::steady_clock::now();
      size_t i = 0;
      for (const Event& e : chunk.span()) scorer->add(e, flags[i++] != 0);
      run.scoring_s += std::chrono::duration<double>(std::chrono::steady_clock::now() - s0).count();
    }
    if (tracker) files.tracks(ended);  // not processing time (as the overlays)
    progress.update(reader.progress(), run.events, std::to_string(front.stats().corners) + " corners");
  }
  files.close_corners();
  if (tracker) {
    files.tracks(front.finish());
    files.close_tracks();
  }
  if (overlay && run.events > 0) overlay->write(nullptr);
  return run;
}

void write_corners_stats(const CornersArgs& args, const CornersConfig& cfg, SensorSize sensor, const pipeline::CornerPipeline& front,
                         const CornersRun& run, const TrackLengths& tl, int frames_written) {
  const frontend::CornerTracker* tracker = front.tracker();
  const frontend::EfastStats& es = front.efast_stats();
  const int64_t events = run.events, corners = front.stats().corners;
  const double duration_s = run.duration_s();
  TextOut f((fs::path(args.out) / "stats.json").string());
  std::ostringstream j;
  // The model block: eFAST tests each event on its own (no frames, no model to choose); what ran.
  const std::string stages = std::string("eFAST per event") + (tracker ? (cfg.descriptors ? " + DART + tracker" : " + tracker") : "");
  j << "{\n  \"model\": {\"summary\": " << json_string(stages + ": per-event detector, no frames, no model choice")
    << ", \"detector\": \"efast\", \"filter_sae\": " << json_bool(cfg.efast.filter_sae)
    << ", \"tracker\": " << json_bool(tracker) << ", \"descriptors\": " << json_bool(cfg.descriptors)
    << ", \"frames\": null}";
  j << ",\n  \"dataset\": " << json_string(args.dataset) << ",\n  \"sensor\": [" << sensor.width << ", " << sensor.height
    << "],\n  \"events\": " << events << ",\n  \"events_outside_sensor\": " << front.stats().outside
    << ",\n  \"corners\": " << corners << ",\n  \"reduction_rate\": " << json_number(corners > 0 ? static_cast<double>(events) / static_cast<double>(corners) : 0.0)
    << ",\n  \"ns_per_event\": " << json_number(events > 0 ? (run.processing_s - run.overlay_s) * 1e9 / static_cast<double>(events) : 0.0)
    << ",\n  \"duration_s\": " << json_number(duration_s)
    << ",\n  \"corners_per_second\": " << json_number(duration_s > 0 ? static_cast<double>(corners) / duration_s : 0.0) << ",\n  \"filters\": {\"refractory\": "
    << (front.refractory_passed() ? std::to_string(*front.refractory_passed()) : "null")
    << ", \"background_activity\": "
    << (front.background_activity_passed() ? std::to_string(*front.background_activity_passed()) : "null")
    << "},\n  \"efast\": {\"filter_sae\": " << json_bool(cfg.efast.filter_sae) << ", \"tested\": " << es.tested
    << ", \"inner_passed\": " << es.inner_passed << ", \"outer_share\": "
    << json_number(es.tested > 0 ? static_cast<double>(es.inner_passed) / static_cast<double>(es.tested) : 0.0)
    << "},\n  \"descriptors\": " << front.stats().descriptors << ",\n  \"descriptor_decisions\": "
    << (tracker ? tracker->stats().descriptor_decisions : 0) << ",\n  \"tracks\": {\"count\": " << tl.count << ", \"mean_length\": " << json_number(tl.mean)
    << ", \"median_length\": " << json_number(tl.median) << ", \"max_length\": " << json_number(tl.max)
    << ", \"mean_duration_s\": " << json_number(tl.mean_duration_s) << "},\n  \"frames_written\": " << frames_written << "\n}\n";
  std::fputs(j.str().c_str(), f.get());
  f.close();
}

void write_corners_eval(const CornersArgs& args, const CornerTruth& truth, const CornersRun& run, std::ostream& out) {
  const evaluation::CornerMetrics m = truth.scorer->finish();
  const evaluation::CornerScoringOptions so;
  auto num9 = [](double v) { return json_number(v, 9); };
  TextOut f((fs::path(args.out) / "eval.json").string());
  std::ostringstream j;
  j << "{\n  \"scene\": " << json_string(truth.scene) << ",\n  \"true_corners\": " << truth.corners.size()
    << ",\n  \"protocol\": \"a corner event is right when a true corner (checkerboard grid node projected through the "
       "true pose) lies within match_radius_px of its pixel at its time; pair recall over (corner, bin) pairs with the "
       "corner visible >= border_px inside the image and moving >= min_speed_pxps\""
    << ",\n  \"match_radius_px\": " << num9(so.match_radius_px) << ",\n  \"bin_s\": " << num9(so.bin_ns * 1e-9)
    << ",\n  \"min_speed_pxps\": " << num9(so.min_speed_pxps) << ",\n  \"border_px\": " << num9(so.border_px)
    << ",\n  \"events\": " << m.events << ",\n  \"corner_events\": " << m.corner_events
    << ",\n  \"true_positives\": " << m.true_positives << ",\n  \"precision\": " << num9(m.precision())
    << ",\n  \"chance\": " << num9(m.chance()) << ",\n  \"event_recall\": " << num9(m.event_recall())
    << ",\n  \"pair_recall\": " << num9(m.pair_recall()) << ",\n  \"pairs\": " << m.pairs
    << ",\n  \"inner_pair_recall\": " << num9(m.inner_pair_recall()) << ",\n  \"inner_pairs\": " << m.inner_pairs
    << ",\n  \"f_score\": " << num9(m.f_score()) << ",\n  \"f_error\": " << num9(1.0 - m.f_score())
    << ",\n  \"scoring_time_s\": " << num9(run.scoring_s) << "\n}\n";
  std::fputs(j.str().c_str(), f.get());
  f.close();
  char b[320];
  std::snprintf(b, sizeof(b),
                "ground truth  precision %.3f (chance %.3f), (corner, %.0f ms bin) recall %.3f, F %.3f against %zu true "
                "corners; wrote eval.json\n",
                m.precision(), m.chance(), so.bin_ns * 1e-6, m.pair_recall(), m.f_score(), truth.corners.size());
  out << b;
}

void print_corners_summary(std::ostream& out, const CornersArgs& args, const CornersConfig& cfg, const CornersCamera& cam,
                           const pipeline::CornerPipeline& front, const CornersRun& run, const TrackLengths& tl,
                           const OverlayWriter* overlay) {
  const frontend::CornerTracker* tracker = front.tracker();
  const frontend::EfastStats& es = front.efast_stats();
  const int64_t events = run.events, corners = front.stats().corners, outside = front.stats().outside;
  const double duration_s = run.duration_s();
  char buf[512];
  std::snprintf(buf, sizeof(buf),
                "events        %lld over %.3f s (sensor %dx%d%s)\n"
                "corners       %lld (reduction %.1fx, %.0f corners/s, outer circle reached by %.1f%% of tested events)\n"
                "speed         %.1f ns/event (filters + eFAST%s + corner output, one core; reading excluded)\n",
                static_cast<long long>(events), duration_s, cam.sensor.width, cam.sensor.height,
                cam.cal ? ", calibrated" : ", no calibration", static_cast<long long>(corners),
                corners > 0 ? static_cast<double>(events) / static_cast<double>(corners) : 0.0,
                duration_s > 0 ? static_cast<double>(corners) / duration_s : 0.0,
                es.tested > 0 ? 100.0 * static_cast<double>(es.inner_passed) / static_cast<double>(es.tested) : 0.0,
                events > 0 ? (run.processing_s - run.overlay_s) * 1e9 / static_cast<double>(events) : 0.0,
                tracker ? (cfg.descriptors ? " + DART + tracker" : " + tracker") : "");
  out << buf;
  if (tracker) {
    std::snprintf(buf, sizeof(buf), "tracks        %zu (>= %zu corner events): length mean %.1f, median %.0f, max %.0f; mean duration %.3f s\n",
                  tl.count, cfg.tracker.min_length, tl.mean, tl.median, tl.max, tl.mean_duration_s);
    out << buf;
  }
  if (outside > 0) out << "warning       " << outside << " events outside the " << cam.sensor.width << "x" << cam.sensor.height << " sensor were skipped\n";
  out << "wrote " << args.out << "/corners.txt" << (tracker ? ", tracks.txt" : "") << ", stats.json, corners_config.yaml";
  if (overlay) out << ", frames/ (" << overlay->written << " PNG)";
  out << "\n";
}

}  // namespace

int run_corners(const CornersArgs& args, std::ostream& out) {
  CornersConfig cfg = load_corners_config(args.config, args.set);
  if (args.filter_sae) cfg.efast.filter_sae = true;
  if (args.frames_every_ns >= 0) cfg.frames_every_ns = args.frames_every_ns;
  auto reader = open_dataset(args.dataset, args.dataset_options);
  const CornersCamera cam = open_corners_camera(args, *reader);
  fs::create_directories(args.out);
  {
    TextOut f((fs::path(args.out) / "corners_config.yaml").string());
    const std::string text = corners_config_text(cfg);
    std::fputs(text.c_str(), f.get());
    f.close();
  }
  std::optional<calib::PinholeCamera> camera;
  if (cam.cal) camera = cam.cal->camera;
  std::string why;
  if (!cfg.Validate(&why)) throw InputError(args.config.empty() ? "--filter-sae" : args.config, 0, why, "valid settings");
  pipeline::CornerPipeline front(cfg, cam.sensor.width, cam.sensor.height, camera);
  std::unique_ptr<OverlayWriter> overlay;
  if (cfg.frames_every_ns > 0)
    overlay = std::make_unique<OverlayWriter>((fs::path(args.out) / "frames").string(), cam.sensor.width, cam.sensor.height, cfg);
  const std::unique_ptr<CornerTruth> truth = open_corner_truth(args, cam.sensor, out);

  CornerFiles files(args.out, front.tracker() != nullptr, cam.cal);
  const CornersRun run = stream_corners(args, cfg, *reader, cam.sensor, front, files, overlay.get(), truth->scorer.get());
  const TrackLengths tl = files.lengths();
  write_corners_stats(args, cfg, cam.sensor, front, run, tl, overlay ? overlay->written : 0);
  if (truth->scorer) write_corners_eval(args, *truth, run, out);
  print_corners_summary(out, args, cfg, cam, front, run, tl, overlay.get());
  return 0;
}

}  // namespace evio::apps
