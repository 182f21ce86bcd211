#include "reconstruct_command.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <optional>
#include <ostream>
#include <sstream>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "evio/calib/error.h"
#include "evio/calib/json.h"
#include "evio/evaluation/image_quality_summary.h"
#include "evio/sensors/config_table.h"
#include "evio/sensors/ecd.h"
#include "evio/sensors/time.h"
#include "evio/simulator/scene_config.h"
#include "evio/simulator/simulator.h"
#include "cmax_input.h"
#include "evio/mapping/option_tables.h"
#include "output_files.h"
#include "progress.h"
#include "video_out.h"

namespace evio::apps {
namespace {

namespace fs = std::filesystem;
using yaml_config::Range;
using yaml_config::Table;
using C = ReconstructConfig;
using mapping::ReconstructionMethod;

const std::vector<std::pair<std::string, ReconstructionMethod>>& method_names() {
  static const std::vector<std::pair<std::string, ReconstructionMethod>> names = {
      {"hf", ReconstructionMethod::kHighPass}, {"cf", ReconstructionMethod::kComplementary}, {"akf", ReconstructionMethod::kKalman},
      {"gradient", ReconstructionMethod::kGradient}};
  return names;
}

const Table<C>& reconstruct_config_table() {
  static const Table<C> table = [] {
    using CF = mapping::ComplementaryFilterOptions;
    using KF = mapping::AsyncKalmanFilterOptions;
    using FR = mapping::FrameResponse;
    Table<CF> cf("complementary filter settings");
    cf.number("cutoff_hz", &CF::cutoff_hz, Range::kNonNegative, "Hz")
        .note("cutoff_hz", "crossover frequency f; alpha = 2 pi f rad/s; 0: direct integration")
        .number("contrast_on", &CF::contrast_on, Range::kPositive, "log intensity")
        .number("contrast_off", &CF::contrast_off, Range::kPositive, "log intensity")
        .note("contrast_off", "subtracted per OFF event")
        .number("initial_log_intensity", &CF::initial_log_intensity, Range::kAny, "log intensity")
        .boolean("init_from_first_frame", &CF::init_from_first_frame)
        .note("init_from_first_frame", "the first frame sets the state (the published filter starts from 0)");
    Table<KF> akf("asynchronous Kalman filter settings");
    akf.number("contrast_on", &KF::contrast_on, Range::kPositive, "log intensity")
        .number("contrast_off", &KF::contrast_off, Range::kPositive, "log intensity")
        .number("initial_variance", &KF::initial_variance, Range::kPositive, "log^2")
        .number("event_noise", &KF::event_noise, Range::kNonNegative, "log^2")
        .note("event_noise", "per event: the step's own error")
        .number("process_noise", &KF::process_noise, Range::kNonNegative, "log^2/s")
        .note("process_noise", "per s since the pixel's last event or frame")
        .number("isolated_noise", &KF::isolated_noise, Range::kNonNegative, "log^2/s")
        .note("isolated_noise", "per s since the latest event among the 8 neighbours")
        .number("refractory_noise", &KF::refractory_noise, Range::kNonNegative, "log^2")
        .duration_ms("refractory_period_ms", &KF::refractory_period_ns, Range::kNonNegative)
        .number("frame_noise_std", &KF::frame_noise_std, Range::kPositive, "grey level")
        .note("frame_noise_std", "of a well-exposed pixel (read noise and quantisation)")
        .number("exposure_low", &KF::exposure_low, Range::kNonNegative, "grey level")
        .number("exposure_high", &KF::exposure_high, Range::kNonNegative, "grey level")
        .number("min_exposure_weight", &KF::min_exposure_weight, Range::kPositive, "")
        .note("min_exposure_weight", "frame confidence at 0 and 255 (1 between exposure_low and exposure_high)")
        .number("initial_log_intensity", &KF::initial_log_intensity, Range::kAny, "log intensity");
    using HO = mapping::EventHarrisOptions;
    Table<HO> harris("event Harris settings");
    harris.number("cutoff_hz", &HO::cutoff_hz, Range::kNonNegative, "Hz")
        .note("cutoff_hz", "high-pass cut-off of the gradient state (contrasts: the cf section's)")
        .integer("gradient_size", &HO::gradient_size, 3, 5)
        .note("gradient_size", "Sobel kernel, 3 or 5 px")
        .integer("window_radius", &HO::window_radius, 1, 4)
        .note("window_radius", "Gaussian structure-tensor window (2 r + 1)^2 px")
        .number("window_sigma_px", &HO::window_sigma_px, Range::kPositive, "px")
        .number("k", &HO::harris_k, Range::kNonNegative, "")
        .note("k", "R = det M - k trace(M)^2")
        .number("threshold", &HO::threshold, Range::kNonNegative, "(log/px)^4")
        .note("threshold", "minimum R of a corner event; R scales with contrast^4")
        .integer("nms_radius", &HO::nms_radius, 0, 8)
        .note("nms_radius", "local non-maximum suppression radius, px")
        .integer("border_px", &HO::border_px, 0, 1000)
        .validate();
    Table<FR> frames("frame response settings");
    frames.number("gamma", &FR::gamma, Range::kPositive, "")
        .number("log_offset", &FR::offset, Range::kPositive, "")
        .note("log_offset", "L = gamma log(v/255 + log_offset); 1 as dvs_image_reconstruction; log_eps^(1/gamma) for gamma-encoded frames (0.04: the simulator, gamma 2.2)")
        .number("initial_grey", &FR::initial_grey, Range::kNonNegative, "grey level")
        .validate();
    Table<C> top("reconstruct settings");
    top.choice("method", &C::method, method_names())
        .boolean("use_frames", &C::use_frames)
        .number("rate_hz", &C::rate_hz, Range::kPositive, "Hz")
        .note("rate_hz", "images per second of sensor time (without --at)")
        .number("video_fps", &C::video_fps, Range::kPositive, "Hz")
        .section("cf", cf, &C::cf)
        .section("akf", akf, &C::akf)
        .boolean("gradient_sobel", &C::gradient_sobel)
        .note("gradient_sobel", "method gradient: Sobel 3x3 gradients (forward differences otherwise: exactly the cf image)")
        .section("harris", harris, &C::harris)
        .section("frames", frames, &C::frames)
        .section("display", mapping::log_image_display_table(), &C::display)
        .ignored("description")
        .validate();
    return top;
  }();
  return table;
}


// The frame as 8-bit grey (the filters' input): mono8 as it is, colour converted, 16-bit scaled.
cv::Mat grey8(const cv::Mat& m, const std::string& where) {
  cv::Mat g = m;
  if (g.channels() == 3) cv::cvtColor(m, g, cv::COLOR_BGR2GRAY);
  if (g.channels() == 4) cv::cvtColor(m, g, cv::COLOR_BGRA2GRAY);
  if (g.depth() == CV_16U) g.convertTo(g, CV_8U, 1.0 / 257.0);
  if (g.type() != CV_8UC1) throw InputError(where, 0, "unsupported frame pixel type", "8- or 16-bit grey or colour frames");
  return g;
}

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

// The filter of the configured method (cf's and akf's sections with the frames section and
// use_frames; hf: the complementary filter's high-pass limit), starting at t_start_ns.
std::unique_ptr<mapping::LogIntensityFilter> make_filter(const ReconstructConfig& cfg, int width, int height,
                                                         int64_t t_start_ns) {
  switch (cfg.method) {
    case ReconstructionMethod::kHighPass:
    case ReconstructionMethod::kComplementary: {
      mapping::ComplementaryFilterOptions o = cfg.cf;
      o.frame = cfg.frames;
      o.high_pass = cfg.method == ReconstructionMethod::kHighPass;
      o.use_frames = cfg.use_frames;
      return std::make_unique<mapping::ComplementaryFilter>(width, height, t_start_ns, o);
    }
    case ReconstructionMethod::kGradient: {
      mapping::PoissonGradientOptions o;
      o.filter = cfg.cf;
      o.filter.frame = cfg.frames;
      o.filter.use_frames = cfg.use_frames;
      o.sobel = cfg.gradient_sobel;
      return std::make_unique<mapping::PoissonGradientFilter>(width, height, t_start_ns, o);
    }
    case ReconstructionMethod::kKalman: {
      mapping::AsyncKalmanFilterOptions o = cfg.akf;
      o.frame = cfg.frames;
      o.use_frames = cfg.use_frames;
      return std::make_unique<mapping::AsyncKalmanFilter>(width, height, t_start_ns, o);
    }
  }
  return nullptr;
}

// The true views of a simulated dataset (--gt SCENE.yaml, or DATASET/scene_resolved.yaml that
// `evio simulate` writes): each image scored against the clean view rendered at its time
// (mapping::compare_images); an image that is still flat (nothing to fit) is not scored.
class TrueViewScorer {
 public:
  // nullptr without a scene (none given or found, or --no-gt). Throws evio::InputError when the
  // scene's camera is not the sensor's size.
  static std::unique_ptr<TrueViewScorer> open(const ReconstructArgs& args, int width, int height) {
    std::string scene = args.gt;
    std::error_code ec;
    const fs::path auto_scene = fs::path(args.dataset) / "scene_resolved.yaml";
    if (scene.empty() && !args.no_gt && fs::is_directory(args.dataset, ec) && fs::is_regular_file(auto_scene, ec))
      scene = auto_scene.string();
    if (scene.empty()) return nullptr;
    const simulator::SimulationConfig sc = simulator::load_simulation_config(scene);
    if (sc.simulator.camera.width() != width || sc.simulator.camera.height() != height)
      throw InputError(scene, 0,
                       "the scene's camera is " + std::to_string(sc.simulator.camera.width()) + " x " +
                           std::to_string(sc.simulator.camera.height()) + " px",
                       "the scene the dataset was simulated from (" + std::to_string(width) + " x " +
                           std::to_string(height) + " px)");
    return std::unique_ptr<TrueViewScorer>(new TrueViewScorer(scene, sc));
  }

  void score(int64_t t_ns, const mapping::ImageF& img) {
    const auto t0 = Clock::now();
    if (img.size() > 0 && img.minCoeff() < img.maxCoeff()) {
      const mapping::ImageQuality q = mapping::compare_images(img, truth_.true_log_view(t_ns - clock_offset_ns_), nullptr);
      scores_.push_back({t_ns * 1e-9, q.psnr_db, q.ssim});
    } else {
      ++unscored_;
    }
    time_s_ += seconds_since(t0);
  }

  // eval.json and its summary line.
  void write_eval(const std::string& path, std::ostream& out) const {
    const evaluation::ImageScoreSummary s = evaluation::summarize_image_scores(scores_);
    std::vector<std::string> per_image;
    for (const evaluation::ImageScore& q : scores_)
      per_image.push_back(JsonObject(9).number("t_s", q.t_s).number("psnr_db", q.psnr_db).number("ssim", q.ssim).str());
    JsonObject j(9, JsonObject::Layout::kLines);
    j.string("scene", scene_)
        .string("reference", "log(I + log_eps) of the clean view rendered at each image's time; PSNR and SSIM after a "
                             "global affine fit (mapping::compare_images)")
        .integer("images_scored", static_cast<int64_t>(s.images))
        .integer("images_unscored", unscored_)
        .number("psnr_db", s.psnr_db_mean)
        .number("ssim", s.ssim_mean)
        .number("ssim_error", 1.0 - s.ssim_mean)
        .number("psnr_db_min", s.psnr_db_min)
        .number("ssim_min", s.ssim_min)
        .number("scoring_time_s", time_s_)
        .raw("per_image", json_array(per_image));
    write_text_file(path, j.str() + "\n");
    out << "evio reconstruct: against the true views of " << scene_ << ": PSNR " << json_number(s.psnr_db_mean, 9)
        << " dB, SSIM " << json_number(s.ssim_mean, 9) << " (mean of " << s.images << " images; " << unscored_
        << " flat images not scored); wrote eval.json\n";
  }

 private:
  TrueViewScorer(std::string scene, const simulator::SimulationConfig& sc)
      : scene_(std::move(scene)), truth_(sc.scene, sc.trajectory, sc.simulator), clock_offset_ns_(sc.clock_offset_ns) {}

  std::string scene_;
  simulator::Simulator truth_;
  int64_t clock_offset_ns_;  // output.clock_offset_ns of the scene: written stamp - simulator time
  std::vector<evaluation::ImageScore> scores_;
  int64_t unscored_ = 0;     // images whose estimate is still flat
  double time_s_ = 0;        // rendering and scoring, s
};

// Each image's outputs: images/frame_NNNNNNNN.png and .tiff, its line of images.txt, a frame of
// video.mp4 (--video), and its score against the true view (a simulated dataset).
class ImageWriter {
 public:
  // Opens images.txt and the video (images/ exists); says on `out` when no video can be written.
  ImageWriter(const ReconstructArgs& args, const ReconstructConfig& cfg, int width, int height, std::ostream& out)
      : out_dir_(args.out), display_(cfg.display), width_(width), height_(height) {
    list_.emplace((fs::path(args.out) / "images.txt").string());
    std::fputs("# timestamp[s] image (evio reconstruct)\n", list_->get());
    if (!args.video) return;
    std::string why;
    video_status_ = video_.open((fs::path(args.out) / "video.mp4").string(), cfg.video_fps, width, height, &why)
                        ? "written"
                        : "unavailable: " + why;
    if (!video_.is_open()) out << "evio reconstruct: --video: no video.mp4 written (" << why << ")\n";
  }

  void set_scorer(TrueViewScorer* truth) { truth_ = truth; }

  void write(int64_t t_ns, const mapping::ImageF& img) {
    char name[64];
    std::snprintf(name, sizeof(name), "images/frame_%08lld", static_cast<long long>(images_));
    const std::string base = (fs::path(out_dir_) / name).string();
    mapping::write_log_image_png8(base + ".png", img, nullptr, display_);
    mapping::write_log_image_tiff(base + ".tiff", img, nullptr);
    std::fprintf(list_->get(), "%s %s.png\n", format_seconds(t_ns).c_str(), name);
    if (truth_) truth_->score(t_ns, img);
    if (video_.is_open()) {
      const mapping::ImageF d = mapping::log_image_to_display(img, nullptr, display_);
      cv::Mat m(height_, width_, CV_8UC1);
      for (int y = 0; y < height_; ++y)
        for (int x = 0; x < width_; ++x) m.at<uint8_t>(y, x) = static_cast<uint8_t>(std::lround(255.0 * d(y, x)));
      video_.write(m);
    }
    ++images_;
  }

  void close() {
    list_->close();
    video_.close();
  }

  int64_t images() const { return images_; }
  const std::string& video_status() const { return video_status_; }

 private:
  const std::string out_dir_;
  const mapping::LogImageDisplayOptions display_;
  const int width_, height_;
  std::optional<TextOut> list_;
  VideoOut video_;
  std::string video_status_ = "not requested";
  TrueViewScorer* truth_ = nullptr;
  int64_t images_ = 0;
};

// The filter fed in time order: events in batches up to the next frame or image time (events at a
// frame's time precede it), frames fused when due, and an image read out at each requested time
// (--at, or every period from the first event) and handed to the ImageWriter. The filter starts at
// the first event, or the first frame when that is earlier.
class FilterStream {
 public:
  FilterStream(const ReconstructConfig& cfg, int width, int height, std::vector<Frame> frames, std::vector<int64_t> at,
               const std::string& dataset, ImageWriter* images)
      : cfg_(cfg), width_(width), height_(height), frames_(std::move(frames)), at_(std::move(at)),
        period_ns_(std::max<int64_t>(1, std::llround(1e9 / cfg.rate_hz))), dataset_(dataset), images_(images) {
    std::sort(at_.begin(), at_.end());
  }

  void process(const Event* ev, size_t n) {
    if (!filter_) {
      t_first_ = ev[0].t_ns;
      if (!frames_.empty()) t_first_ = std::min(t_first_, frames_.front().t_ns);
      next_rate_ = ev[0].t_ns;
      filter_ = make_filter(cfg_, width_, height_, t_first_);
    }
    size_t i = 0;
    while (i < n) {
      due_before(ev[i].t_ns, false);
      const int64_t tf = next_frame_time(), ti = next_image_time();
      size_t j = i;
      while (j < n && ev[j].t_ns <= tf && ev[j].t_ns < ti) ++j;
      if (j == i) j = i + 1;
      const auto t0 = Clock::now();
      filter_->process(ev + i, j - i);
      filter_s_ += seconds_since(t0);
      i = j;
    }
    t_last_ = ev[n - 1].t_ns;
  }

  // The images after the last event: at the --at times left; with --rate, up to the last event.
  // Throws evio::InputError when there was no event.
  void finish() {
    if (!filter_) throw InputError(dataset_, 0, "no events", "a recording with events");
    due_before(at_.empty() ? t_last_ : std::max(t_last_, at_.back()), true);
  }

  int64_t t_first_ns() const { return t_first_; }
  int64_t t_last_ns() const { return t_last_; }
  const mapping::ReconstructionStats& stats() const { return filter_->stats(); }
  double filter_s() const { return filter_s_; }    // in process() and add_frame()
  double readout_s() const { return readout_s_; }  // in log_intensity()

 private:
  int64_t next_frame_time() const { return next_frame_ < frames_.size() ? frames_[next_frame_].t_ns : INT64_MAX; }
  int64_t next_image_time() const { return at_.empty() ? next_rate_ : (next_at_ < at_.size() ? at_[next_at_] : INT64_MAX); }

  // Everything due at or before t (frames at t_f <= t, images at times < t, or <= t when
  // inclusive_images), in time order.
  void due_before(int64_t t, bool inclusive_images) {
    for (;;) {
      const int64_t tf = next_frame_time(), ti = next_image_time();
      const bool image_due = inclusive_images ? ti <= t : ti < t;
      if (tf <= t && tf <= ti) {
        fuse_frame(frames_[next_frame_++]);
      } else if (image_due) {
        write_image_at(ti);
        if (at_.empty()) next_rate_ += period_ns_; else ++next_at_;
      } else {
        return;
      }
    }
  }

  void fuse_frame(Frame& f) {
    if (f.image.empty()) load_frame_image(&f);
    const std::string& where = f.path.empty() ? dataset_ : f.path;
    const cv::Mat g = grey8(f.image, where);
    f.image.release();
    if (g.cols != width_ || g.rows != height_)
      throw InputError(where, 0, "frame of " + std::to_string(g.cols) + " x " + std::to_string(g.rows) + " px",
                       "frames of the sensor's size " + std::to_string(width_) + " x " + std::to_string(height_));
    const auto t0 = Clock::now();
    filter_->add_frame(f.t_ns, mapping::GreyView{g.data, g.cols, g.rows, static_cast<std::ptrdiff_t>(g.step)});
    filter_s_ += seconds_since(t0);
  }

  void write_image_at(int64_t t) {
    const auto t0 = Clock::now();
    filter_->log_intensity(t, &img_);
    readout_s_ += seconds_since(t0);
    images_->write(t, img_);
  }

  const ReconstructConfig& cfg_;
  const int width_, height_;
  std::vector<Frame> frames_;
  std::vector<int64_t> at_;
  const int64_t period_ns_;
  const std::string dataset_;
  ImageWriter* images_;
  std::unique_ptr<mapping::LogIntensityFilter> filter_;
  double filter_s_ = 0, readout_s_ = 0;
  int64_t t_first_ = 0, t_last_ = 0;
  size_t next_frame_ = 0, next_at_ = 0;
  int64_t next_rate_ = 0;
  mapping::ImageF img_;
};

// --corners: event Harris corner events (contrasts: the cf section's) on every event, written to
// corners.txt as `evio corners` writes them (polarity as in the input).
class CornerWriter {
 public:
  CornerWriter(const std::string& path, const ReconstructConfig& cfg, int width, int height)
      : file_(path), cfg_(cfg), width_(width), height_(height) {
    std::fputs("# t[s] x y p   (event Harris corner events, polarity as in the input)\n", file_.get());
  }

  bool started() const { return harris_ != nullptr; }
  // The detector starts at t_start_ns; zero_one: the input's polarity is 0/1 (else -1/+1).
  void start(int64_t t_start_ns, bool zero_one) {
    mapping::EventHarrisOptions h = cfg_.harris;
    h.contrast_on = cfg_.cf.contrast_on;
    h.contrast_off = cfg_.cf.contrast_off;
    harris_ = std::make_unique<mapping::EventHarrisDetector>(width_, height_, t_start_ns, h);
    zero_one_ = zero_one;
  }

  void process(const Event* ev, size_t n) {
    const auto t0 = Clock::now();
    char line[96];
    for (size_t k = 0; k < n; ++k) {
      if (!harris_->process(ev[k])) continue;
      *format_seconds(ev[k].t_ns, line) = '\0';
      std::fprintf(file_.get(), "%s %d %d %d\n", line, ev[k].x, ev[k].y, ev[k].polarity > 0 ? 1 : (zero_one_ ? 0 : -1));
    }
    time_s_ += seconds_since(t0);
  }

  void close() { file_.close(); }
  int64_t corners() const { return harris_ ? harris_->stats().corners : 0; }
  double time_s() const { return time_s_; }

 private:
  TextOut file_;
  const ReconstructConfig& cfg_;
  const int width_, height_;
  std::unique_ptr<mapping::EventHarrisDetector> harris_;
  bool zero_one_ = true;
  double time_s_ = 0;
};

// stats.json.
std::string reconstruct_stats(const ReconstructConfig& cfg, const FilterStream& run, int64_t events, int64_t images,
                              double wall_s, const CornerWriter* corners, const std::string& video_status) {
  const mapping::ReconstructionStats& st = run.stats();
  const std::string method = mapping::reconstruction_method_name(cfg.method);
  const double filter_s = run.filter_s();
  JsonObject j(9, JsonObject::Layout::kLines);
  j.raw("model", JsonObject(9)
                     .string("summary", method + (cfg.use_frames ? ", frames fused: " + std::to_string(st.frames)
                                                                 : std::string(", events only (frames not used)")))
                     .string("method", method)
                     .string("selection", "fixed")
                     .boolean("use_frames", cfg.use_frames)
                     .integer("frames_fused", st.frames)
                     .str())
      .string("method", method)
      .boolean("use_frames", cfg.use_frames)
      .integer("events", events)
      .integer("events_outside_sensor", st.events_outside)
      .integer("frames_fused", st.frames)
      .integer("images", images)
      .number("t_first_s", run.t_first_ns() * 1e-9)
      .number("t_last_s", run.t_last_ns() * 1e-9)
      .number("filter_time_s", filter_s)
      .number("time_per_event_ns", events ? filter_s * 1e9 / static_cast<double>(events) : 0.0)
      .number("events_per_s", filter_s > 0 ? static_cast<double>(events) / filter_s : 0.0)
      .number("readout_time_s", run.readout_s())
      .number("wall_time_s", wall_s)
      .integer("rebases", st.rebases);
  if (corners)
    j.integer("corner_events", corners->corners())
        .number("harris_time_s", corners->time_s())
        .number("harris_time_per_event_ns", events ? corners->time_s() * 1e9 / static_cast<double>(events) : 0.0);
  j.string("video", video_status);
  return j.str() + "\n";
}

}  // namespace

bool ReconstructConfig::Validate(std::string* why) const {
  if (!(rate_hz > 0 && rate_hz <= 1e6)) {
    if (why) *why = "rate_hz must be in (0, 1e6]";
    return false;
  }
  mapping::ComplementaryFilterOptions c = cf;
  c.frame = frames;
  mapping::AsyncKalmanFilterOptions k = akf;
  k.frame = frames;
  return c.Validate(why) && k.Validate(why) && harris.Validate(why) && display.Validate(why);
}

ReconstructConfig load_reconstruct_config(const std::string& path, const std::vector<std::string>& sets) {
  return yaml_config::read_config(reconstruct_config_table(), ReconstructConfig{}, path, sets,
                                  "a reconstruct config YAML (see docs/commands/reconstruct.md)");
}

std::string reconstruct_config_text(const ReconstructConfig& c) {
  return yaml_config::config_text(reconstruct_config_table(), c,
                                  "# evio reconstruct configuration, resolved: every key with the value used (comments: "
                                  "unit and range).\n# Readable by `evio reconstruct --config`. Section cf is also the "
                                  "high-pass filter's (method hf: reference 0, no frames).\n");
}

ReconstructConfig resolve_reconstruct_config(const ReconstructArgs& args) {
  ReconstructConfig cfg = load_reconstruct_config(args.config, args.set);
  if (!args.method.empty()) {
    bool found = false;
    for (const auto& [name, m] : method_names())
      if (name == args.method) {
        cfg.method = m;
        found = true;
      }
    if (!found) throw InputError("--method", 0, "unknown method '" + args.method + "'", "hf, cf, akf or gradient");
  }
  if (args.use_frames) cfg.use_frames = true;
  if (args.rate_hz) cfg.rate_hz = *args.rate_hz;
  if (args.cutoff_hz) cfg.cf.cutoff_hz = *args.cutoff_hz;
  if (args.contrast_on) cfg.cf.contrast_on = cfg.akf.contrast_on = *args.contrast_on;
  if (args.contrast_off) cfg.cf.contrast_off = cfg.akf.contrast_off = *args.contrast_off;
  if (args.cutoff_hz && cfg.method == ReconstructionMethod::kKalman)
    throw InputError("--cutoff-hz", 0, "the Kalman filter has no cut-off (its gain comes from the noise models)",
                     "--method hf or cf, or the akf section's noise settings");
  if (cfg.method == ReconstructionMethod::kHighPass && cfg.use_frames)
    throw InputError("--use-frames", 0, "the high-pass filter uses events only", "--method cf or akf with --use-frames");
  std::string why;
  if (!cfg.Validate(&why)) throw InputError(args.config.empty() ? "the flags" : args.config, 0, why, "valid reconstruct settings");
  return cfg;
}

int run_reconstruct(const ReconstructArgs& args, std::ostream& out) {
  const ReconstructConfig cfg = resolve_reconstruct_config(args);

  // ---- inputs: the dataset, its sensor size and (--use-frames) its APS frames ---------------------
  CmaxInput input = open_cmax_input(args.dataset, args.dataset_options, args.calib, {});
  DatasetReader* reader = input.reader.get();
  const int width = input.sensor.width, height = input.sensor.height;
  std::vector<Frame> frames;
  if (cfg.use_frames) {
    frames = reader->read_frames();
    if (frames.empty())
      throw InputError(args.dataset, 0, "--use-frames: the dataset has no APS frames", "a recording with frames, or no --use-frames");
  }

  // ---- outputs, the true views (a simulated dataset) and the filter --------------------------------
  fs::create_directories(fs::path(args.out) / "images");
  write_text_file((fs::path(args.out) / "reconstruct_config.yaml").string(), reconstruct_config_text(cfg));
  ImageWriter images(args, cfg, width, height, out);
  const std::unique_ptr<TrueViewScorer> truth = TrueViewScorer::open(args, width, height);
  images.set_scorer(truth.get());
  FilterStream run(cfg, width, height, std::move(frames), args.at_ns, args.dataset, &images);
  std::unique_ptr<CornerWriter> corners;
  if (args.corners) corners = std::make_unique<CornerWriter>((fs::path(args.out) / "corners.txt").string(), cfg, width, height);

  // ---- the event stream ------------------------------------------------------------------------------
  Progress progress("evio reconstruct", args.progress, "events");
  EventBuffer chunk;
  int64_t events = 0;
  const auto wall0 = Clock::now();
  for (;;) {
    chunk.clear();
    if (reader->read_events(&chunk, 1 << 16) == 0) break;
    run.process(chunk.data(), chunk.size());
    if (corners && !corners->started())  // the input's polarity convention is known after the first chunk
      corners->start(run.t_first_ns(), reader->event_report().polarity != PolarityConvention::kMinusPlusOne);
    if (corners) corners->process(chunk.data(), chunk.size());
    events += static_cast<int64_t>(chunk.size());
    progress.update(reader->progress(), events, std::to_string(images.images()) + " images");
  }
  run.finish();
  images.close();
  if (corners) corners->close();
  const double wall_s = seconds_since(wall0);

  // ---- stats.json, eval.json and the summary ---------------------------------------------------------
  write_text_file((fs::path(args.out) / "stats.json").string(),
                  reconstruct_stats(cfg, run, events, images.images(), wall_s, corners.get(), images.video_status()));
  if (truth) truth->write_eval((fs::path(args.out) / "eval.json").string(), out);
  const double filter_s = run.filter_s();
  out << "evio reconstruct: " << mapping::reconstruction_method_name(cfg.method) << (cfg.use_frames ? " with frames" : "")
      << ", " << events << " events, " << run.stats().frames << " frames fused, " << images.images() << " images; filter "
      << json_number(events ? filter_s * 1e9 / static_cast<double>(events) : 0.0, 9) << " ns per event ("
      << json_number(filter_s > 0 ? events / filter_s * 1e-6 : 0.0, 9) << " M events/s), wall " << json_number(wall_s, 9) << " s\n"
      << "wrote " << args.out << "/images.txt, images/, stats.json, reconstruct_config.yaml"
      << (images.video_status() == "written" ? ", video.mp4" : "") << (corners ? ", corners.txt" : "") << "\n";
  if (corners)
    out << "event Harris: " << corners->corners() << " corner events ("
        << json_number(corners->time_s() * 1e9 / std::max<int64_t>(1, events), 9) << " ns per event)\n";
  return 0;
}

}  // namespace evio::apps
