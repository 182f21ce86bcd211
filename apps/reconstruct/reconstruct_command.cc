#include "reconstruct_command.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <ostream>
#include <sstream>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "evio/calib/error.h"
#include "evio/sensors/config_table.h"
#include "evio/sensors/ecd.h"
#include "evio/sensors/time.h"
#include "evio/simulator/scene_config.h"
#include "evio/simulator/simulator.h"
#include "cmax_input.h"
#include "evio/calib/json.h"
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
                                  "a reconstruct config YAML (see README.md, `evio reconstruct`)");
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
  using clock = std::chrono::steady_clock;
  const ReconstructConfig cfg = resolve_reconstruct_config(args);
  CmaxInput input = open_cmax_input(args.dataset, args.dataset_options, args.calib, {});
  DatasetReader* reader = input.reader.get();
  const int width = input.sensor.width, height = input.sensor.height;

  std::vector<Frame> frames;
  if (cfg.use_frames) {
    frames = reader->read_frames();
    if (frames.empty())
      throw InputError(args.dataset, 0, "--use-frames: the dataset has no APS frames", "a recording with frames, or no --use-frames");
  }
  // Times of the images: --at, or every 1/rate from the first event.
  std::vector<int64_t> at = args.at_ns;
  std::sort(at.begin(), at.end());
  const int64_t period_ns = std::max<int64_t>(1, std::llround(1e9 / cfg.rate_hz));

  fs::create_directories(fs::path(args.out) / "images");
  {
    TextOut f((fs::path(args.out) / "reconstruct_config.yaml").string());
    std::fputs(reconstruct_config_text(cfg).c_str(), f.get());
    f.close();
  }
  TextOut list((fs::path(args.out) / "images.txt").string());
  std::fputs("# timestamp[s] image (evio reconstruct)\n", list.get());
  VideoOut video;
  std::string video_status = "not requested";
  if (args.video) {
    std::string why;
    video_status = video.open((fs::path(args.out) / "video.mp4").string(), cfg.video_fps, width, height, &why)
                       ? "written"
                       : "unavailable: " + why;
    if (!video.is_open()) out << "evio reconstruct: --video: no video.mp4 written (" << why << ")\n";
  }

  // True views of a simulated dataset (--gt SCENE.yaml, or DATASET/scene_resolved.yaml that
  // `evio simulate` writes): each image scored against the clean view rendered at its time.
  std::string gt_scene = args.gt;
  {
    std::error_code ec;
    const fs::path auto_scene = fs::path(args.dataset) / "scene_resolved.yaml";
    if (gt_scene.empty() && !args.no_gt && fs::is_directory(args.dataset, ec) && fs::is_regular_file(auto_scene, ec))
      gt_scene = auto_scene.string();
  }
  std::unique_ptr<simulator::Simulator> truth;
  int64_t truth_clock_offset_ns = 0;  // output.clock_offset_ns of the scene: written stamp - simulator time
  if (!gt_scene.empty()) {
    const simulator::SimulationConfig sc = simulator::load_simulation_config(gt_scene);
    if (sc.simulator.camera.width() != width || sc.simulator.camera.height() != height)
      throw InputError(gt_scene, 0,
                       "the scene's camera is " + std::to_string(sc.simulator.camera.width()) + " x " +
                           std::to_string(sc.simulator.camera.height()) + " px",
                       "the scene the dataset was simulated from (" + std::to_string(width) + " x " +
                           std::to_string(height) + " px)");
    truth = std::make_unique<simulator::Simulator>(sc.scene, sc.trajectory, sc.simulator);
    truth_clock_offset_ns = sc.clock_offset_ns;
  }
  struct ScoredImage {
    double t_s, psnr_db, ssim;
  };
  std::vector<ScoredImage> scored;
  int64_t unscored = 0;  // images whose estimate is still flat (nothing to fit)
  double gt_s = 0;       // rendering and scoring, s

  std::unique_ptr<mapping::LogIntensityFilter> filter;
  double filter_s = 0, readout_s = 0;  // in process/add_frame; in log_intensity
  int64_t images = 0, events = 0, t_first = 0, t_last = 0;
  size_t next_frame = 0, next_at = 0;
  int64_t next_rate = 0;
  mapping::ImageF img;
  auto write_image_at = [&](int64_t t) {
    const auto c0 = clock::now();
    filter->log_intensity(t, &img);
    readout_s += std::chrono::duration<double>(clock::now() - c0).count();
    char name[64];
    std::snprintf(name, sizeof(name), "images/frame_%08lld", static_cast<long long>(images));
    const std::string base = (fs::path(args.out) / name).string();
    mapping::write_log_image_png8(base + ".png", img, nullptr, cfg.display);
    mapping::write_log_image_tiff(base + ".tiff", img, nullptr);
    std::fprintf(list.get(), "%s %s.png\n", format_seconds(t).c_str(), name);
    if (truth) {
      const auto g0 = clock::now();
      if (img.size() > 0 && img.minCoeff() < img.maxCoeff()) {
        const mapping::ImageQuality q = mapping::compare_images(img, truth->true_log_view(t - truth_clock_offset_ns), nullptr);
        scored.push_back({t * 1e-9, q.psnr_db, q.ssim});
      } else {
        ++unscored;
      }
      gt_s += std::chrono::duration<double>(clock::now() - g0).count();
    }
    if (video.is_open()) {
      const mapping::ImageF d = mapping::log_image_to_display(img, nullptr, cfg.display);
      cv::Mat m(height, width, CV_8UC1);
      for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) m.at<uint8_t>(y, x) = static_cast<uint8_t>(std::lround(255.0 * d(y, x)));
      video.write(m);
    }
    ++images;
  };
  auto fuse_frame = [&](Frame& f) {
    if (f.image.empty()) load_frame_image(&f);
    const cv::Mat g = grey8(f.image, f.path.empty() ? args.dataset : f.path);
    f.image.release();
    if (g.cols != width || g.rows != height)
      throw InputError(f.path.empty() ? args.dataset : f.path, 0,
                       "frame of " + std::to_string(g.cols) + " x " + std::to_string(g.rows) + " px",
                       "frames of the sensor's size " + std::to_string(width) + " x " + std::to_string(height));
    const auto c0 = clock::now();
    filter->add_frame(f.t_ns, mapping::GreyView{g.data, g.cols, g.rows, static_cast<std::ptrdiff_t>(g.step)});
    filter_s += std::chrono::duration<double>(clock::now() - c0).count();
  };
  // Everything due at or before t (frames at t_f <= t, images at times < t), in time order.
  auto due_before = [&](int64_t t, bool inclusive_images) {
    for (;;) {
      const int64_t tf = next_frame < frames.size() ? frames[next_frame].t_ns : INT64_MAX;
      const int64_t ti = at.empty() ? next_rate : (next_at < at.size() ? at[next_at] : INT64_MAX);
      const bool image_due = inclusive_images ? ti <= t : ti < t;
      if (tf <= t && tf <= ti) {
        fuse_frame(frames[next_frame++]);
      } else if (image_due) {
        write_image_at(ti);
        if (at.empty()) next_rate += period_ns; else ++next_at;
      } else {
        return;
      }
    }
  };

  // --corners: event Harris corner events on every event, written as `evio corners` writes them.
  std::unique_ptr<mapping::EventHarrisDetector> harris;
  std::unique_ptr<TextOut> corners_file;
  bool zero_one = true;  // polarity convention of the input, known after the first chunk
  double harris_s = 0;
  if (args.corners) {
    corners_file = std::make_unique<TextOut>((fs::path(args.out) / "corners.txt").string());
    std::fputs("# t[s] x y p   (event Harris corner events, polarity as in the input)\n", corners_file->get());
  }
  char line[96];

  Progress progress("evio reconstruct", args.progress, "events");
  EventBuffer chunk;
  const auto wall0 = clock::now();
  for (;;) {
    chunk.clear();
    if (reader->read_events(&chunk, 1 << 16) == 0) break;
    const Event* ev = chunk.data();
    const size_t n = chunk.size();
    if (!filter) {
      t_first = ev[0].t_ns;
      if (!frames.empty()) t_first = std::min(t_first, frames.front().t_ns);
      next_rate = ev[0].t_ns;
      if (args.corners) {
        mapping::EventHarrisOptions h = cfg.harris;
        h.contrast_on = cfg.cf.contrast_on;
        h.contrast_off = cfg.cf.contrast_off;
        harris = std::make_unique<mapping::EventHarrisDetector>(width, height, t_first, h);
        zero_one = reader->event_report().polarity != PolarityConvention::kMinusPlusOne;
      }
      switch (cfg.method) {
        case ReconstructionMethod::kHighPass:
        case ReconstructionMethod::kComplementary: {
          mapping::ComplementaryFilterOptions o = cfg.cf;
          o.frame = cfg.frames;
          o.high_pass = cfg.method == ReconstructionMethod::kHighPass;
          o.use_frames = cfg.use_frames;
          filter = std::make_unique<mapping::ComplementaryFilter>(width, height, t_first, o);
          break;
        }
        case ReconstructionMethod::kGradient: {
          mapping::PoissonGradientOptions o;
          o.filter = cfg.cf;
          o.filter.frame = cfg.frames;
          o.filter.use_frames = cfg.use_frames;
          o.sobel = cfg.gradient_sobel;
          filter = std::make_unique<mapping::PoissonGradientFilter>(width, height, t_first, o);
          break;
        }
        case ReconstructionMethod::kKalman: {
          mapping::AsyncKalmanFilterOptions o = cfg.akf;
          o.frame = cfg.frames;
          o.use_frames = cfg.use_frames;
          filter = std::make_unique<mapping::AsyncKalmanFilter>(width, height, t_first, o);
          break;
        }
      }
    }
    // Batches of events between the next frame or image time.
    size_t i = 0;
    while (i < n) {
      due_before(ev[i].t_ns, false);
      const int64_t tf = next_frame < frames.size() ? frames[next_frame].t_ns : INT64_MAX;
      const int64_t ti = at.empty() ? next_rate : (next_at < at.size() ? at[next_at] : INT64_MAX);
      size_t j = i;
      while (j < n && ev[j].t_ns <= tf && ev[j].t_ns < ti) ++j;  // events at t_f precede the frame
      if (j == i) j = i + 1;
      const auto c0 = clock::now();
      filter->process(ev + i, j - i);
      filter_s += std::chrono::duration<double>(clock::now() - c0).count();
      i = j;
    }
    if (harris) {
      const auto c0 = clock::now();
      for (size_t k = 0; k < n; ++k) {
        if (!harris->process(ev[k])) continue;
        char* end = format_seconds(ev[k].t_ns, line);
        *end = '\0';
        std::fprintf(corners_file->get(), "%s %d %d %d\n", line, ev[k].x, ev[k].y, ev[k].polarity > 0 ? 1 : (zero_one ? 0 : -1));
      }
      harris_s += std::chrono::duration<double>(clock::now() - c0).count();
    }
    events += static_cast<int64_t>(n);
    t_last = ev[n - 1].t_ns;
    progress.update(reader->progress(), events, std::to_string(images) + " images");
  }
  if (!filter) throw InputError(args.dataset, 0, "no events", "a recording with events");
  // Images at --at times after the last event; with --rate, up to the last event.
  due_before(at.empty() ? t_last : std::max(t_last, at.back()), true);
  list.close();
  video.close();
  if (corners_file) corners_file->close();
  const double wall_s = std::chrono::duration<double>(clock::now() - wall0).count();

  const mapping::ReconstructionStats& st = filter->stats();
  const double ns_per_event = events ? filter_s * 1e9 / static_cast<double>(events) : 0.0;
  {
    TextOut f((fs::path(args.out) / "stats.json").string());
    std::ostringstream j;
    const std::string method = mapping::reconstruction_method_name(cfg.method);
    j << "{\n  \"model\": {\"summary\": \"" << method
      << (cfg.use_frames ? ", frames fused: " + std::to_string(st.frames) : std::string(", events only (frames not used)"))
      << "\", \"method\": \"" << method << "\", \"selection\": \"fixed\", \"use_frames\": " << (cfg.use_frames ? "true" : "false")
      << ", \"frames_fused\": " << st.frames << "}";
    j << ",\n  \"method\": \"" << method << "\",\n  \"use_frames\": "
      << (cfg.use_frames ? "true" : "false") << ",\n  \"events\": " << events << ",\n  \"events_outside_sensor\": "
      << st.events_outside << ",\n  \"frames_fused\": " << st.frames << ",\n  \"images\": " << images
      << ",\n  \"t_first_s\": " << json_number(t_first * 1e-9, 9) << ",\n  \"t_last_s\": " << json_number(t_last * 1e-9, 9)
      << ",\n  \"filter_time_s\": " << json_number(filter_s, 9) << ",\n  \"time_per_event_ns\": " << json_number(ns_per_event, 9)
      << ",\n  \"events_per_s\": " << json_number(filter_s > 0 ? static_cast<double>(events) / filter_s : 0.0, 9)
      << ",\n  \"readout_time_s\": " << json_number(readout_s, 9) << ",\n  \"wall_time_s\": " << json_number(wall_s, 9) << ",\n  \"rebases\": " << st.rebases;
    if (harris)
      j << ",\n  \"corner_events\": " << harris->stats().corners << ",\n  \"harris_time_s\": " << json_number(harris_s, 9)
        << ",\n  \"harris_time_per_event_ns\": " << json_number(events ? harris_s * 1e9 / static_cast<double>(events) : 0.0, 9);
    j << ",\n  \"video\": \""
      << json_escape(video_status) << "\"\n}\n";
    std::fputs(j.str().c_str(), f.get());
    f.close();
  }
  if (truth) {
    double psnr = 0, ssim = 0, psnr_min = INFINITY, ssim_min = INFINITY;
    for (const ScoredImage& q : scored) {
      psnr += q.psnr_db / static_cast<double>(scored.size());
      ssim += q.ssim / static_cast<double>(scored.size());
      psnr_min = std::min(psnr_min, q.psnr_db);
      ssim_min = std::min(ssim_min, q.ssim);
    }
    if (scored.empty()) psnr = ssim = psnr_min = ssim_min = NAN;
    TextOut f((fs::path(args.out) / "eval.json").string());
    std::ostringstream j;
    j << "{\n  \"scene\": \"" << json_escape(gt_scene) << "\",\n  \"reference\": \"log(I + log_eps) of the clean view "
      << "rendered at each image's time; PSNR and SSIM after a global affine fit (mapping::compare_images)\""
      << ",\n  \"images_scored\": " << scored.size() << ",\n  \"images_unscored\": " << unscored
      << ",\n  \"psnr_db\": " << json_number(psnr, 9) << ",\n  \"ssim\": " << json_number(ssim, 9) << ",\n  \"ssim_error\": " << json_number(1.0 - ssim, 9)
      << ",\n  \"psnr_db_min\": " << json_number(psnr_min, 9) << ",\n  \"ssim_min\": " << json_number(ssim_min, 9)
      << ",\n  \"scoring_time_s\": " << json_number(gt_s, 9) << ",\n  \"per_image\": [";
    for (size_t k = 0; k < scored.size(); ++k)
      j << (k ? ", " : "") << "{\"t_s\": " << json_number(scored[k].t_s, 9) << ", \"psnr_db\": " << json_number(scored[k].psnr_db, 9)
        << ", \"ssim\": " << json_number(scored[k].ssim, 9) << "}";
    j << "]\n}\n";
    std::fputs(j.str().c_str(), f.get());
    f.close();
    out << "evio reconstruct: against the true views of " << gt_scene << ": PSNR " << json_number(psnr, 9) << " dB, SSIM "
        << json_number(ssim, 9) << " (mean of " << scored.size() << " images; " << unscored << " flat images not scored); wrote eval.json\n";
  }
  out << "evio reconstruct: " << mapping::reconstruction_method_name(cfg.method) << (cfg.use_frames ? " with frames" : "")
      << ", " << events << " events, " << st.frames << " frames fused, " << images << " images; filter "
      << json_number(ns_per_event, 9) << " ns per event (" << json_number(filter_s > 0 ? events / filter_s * 1e-6 : 0.0, 9)
      << " M events/s), wall " << json_number(wall_s, 9) << " s\n"
      << "wrote " << args.out << "/images.txt, images/, stats.json, reconstruct_config.yaml"
      << (video_status == "written" ? ", video.mp4" : "") << (harris ? ", corners.txt" : "") << "\n";
  if (harris)
    out << "event Harris: " << harris->stats().corners << " corner events (" << json_number(harris_s * 1e9 / std::max<int64_t>(1, events), 9)
        << " ns per event)\n";
  return 0;
}

}  // namespace evio::apps
