// Image reconstruction against the simulator's ground truth (shared by tests/mapping's quality
// test and bench/reconstruct_quality): a scene YAML simulated in memory with APS frames and true
// intensity views at chosen times, then hf / cf / akf run on its events (and frames) and compared
// with log(I + log_eps) of the true view by mapping::compare_images (PSNR and SSIM after a global
// affine fit, as for the mosaics). The frames' response is the simulator's: v = 255 (gain I)^(1/gamma),
// so L = gamma log(v/255 + offset) with offset = log_eps^(1/gamma) is the events' log scale.
#pragma once

#include <algorithm>
#include <cmath>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "evio/mapping/mosaic_image.h"
#include "evio/mapping/reconstruction.h"
#include "evio/simulator/scene_config.h"
#include "evio/simulator/simulator.h"

namespace evio_test {

struct SimulatedRecording {
  int width = 0, height = 0;
  std::vector<evio::Event> events;
  std::vector<evio::Frame> frames;
  std::vector<int64_t> gt_t_ns;                 // camera clock
  std::vector<evio::mapping::ImageF> gt_log;    // log(I + log_eps)
  // With true_frames: at each APS frame's time, the true view mapped to 8 bits by the APS response
  // without motion blur or read noise (an ideal frame: only quantisation and clamping).
  std::vector<evio::Frame> true_frames;
  double contrast_pos = 0.2, contrast_neg = 0.2, log_eps = 1e-3, frame_gamma = 2.2, frame_gain = 1.0;
};

// Simulates `yaml` (with --set style overrides; seed > 0 replaces the scene's seed) for
// duration_s with true views every period_s from period_s on (and ideal frames with true_frames).
inline SimulatedRecording simulate_recording(const std::string& yaml, double duration_s, double period_s,
                                             const std::vector<std::string>& sets = {}, uint64_t seed = 0,
                                             bool true_frames = false) {
  evio::simulator::SimulateOverrides ov;
  ov.duration_s = duration_s;
  ov.set = sets;
  if (seed > 0) ov.seed = seed;
  evio::simulator::SimulationConfig cfg = evio::simulator::load_simulation_config(yaml, ov);
  evio::simulator::SimulatorOptions so = cfg.simulator;
  so.ground_truth_flow = false;
  so.ground_truth_times_ns.clear();
  evio::simulator::Simulator probe(cfg.scene, cfg.trajectory, so);
  const int64_t period = static_cast<int64_t>(std::llround(period_s * 1e9));
  for (int64_t t = probe.t_begin_ns() + period; t < probe.t_end_ns(); t += period) so.ground_truth_times_ns.push_back(t);
  // The frames' mid-exposure times on the body clock (the simulator's frame schedule).
  std::vector<int64_t> frame_times;
  if (true_frames && so.frames.rate_hz > 0) {
    const double fp = 1e9 / so.frames.rate_hz;
    const int64_t ex = static_cast<int64_t>(std::llround(so.frames.exposure_s * 1e9));
    for (uint64_t k = 0;; ++k) {
      const int64_t t0 = probe.t_begin_ns() + static_cast<int64_t>(std::llround(k * fp));
      if (t0 + ex > probe.t_end_ns()) break;
      frame_times.push_back(t0 + ex / 2);
    }
    so.ground_truth_times_ns.insert(so.ground_truth_times_ns.end(), frame_times.begin(), frame_times.end());
    std::sort(so.ground_truth_times_ns.begin(), so.ground_truth_times_ns.end());
    so.ground_truth_times_ns.erase(std::unique(so.ground_truth_times_ns.begin(), so.ground_truth_times_ns.end()),
                                   so.ground_truth_times_ns.end());
  }
  evio::simulator::Simulator sim(cfg.scene, cfg.trajectory, so);
  struct Sink : evio::simulator::SimulationSink {
    SimulatedRecording* r;
    int64_t shift;
    std::vector<int64_t> views, frame_times;  // body clock
    double gain = 1, gamma = 2.2;
    void on_events(const std::vector<evio::Event>& ev, const std::vector<uint16_t>*) override {
      r->events.insert(r->events.end(), ev.begin(), ev.end());
    }
    void on_frame(const evio::Frame& f) override {
      evio::Frame c = f;
      c.image = f.image.clone();
      r->frames.push_back(c);
    }
    void on_ground_truth(const evio::simulator::RenderedView& v, const evio::simulator::CameraState&) override {
      if (std::binary_search(frame_times.begin(), frame_times.end(), v.t_ns)) {
        evio::Frame f;
        f.t_ns = v.t_ns - shift;
        f.image.create(v.intensity.rows, v.intensity.cols, CV_8UC1);
        for (int y = 0; y < v.intensity.rows; ++y)
          for (int x = 0; x < v.intensity.cols; ++x) {
            const double lin = std::clamp(gain * v.intensity.at<float>(y, x), 0.0, 1.0);
            f.image.at<uint8_t>(y, x) = static_cast<uint8_t>(std::clamp(std::lround(255.0 * std::pow(lin, 1.0 / gamma)), 0L, 255L));
          }
        r->true_frames.push_back(f);
      }
      if (!std::binary_search(views.begin(), views.end(), v.t_ns)) return;
      r->gt_t_ns.push_back(v.t_ns - shift);
      r->gt_log.push_back(evio::simulator::log_intensity_view(v.intensity, r->log_eps));
    }
  } sink;
  SimulatedRecording r;
  r.width = so.camera.width();
  r.height = so.camera.height();
  r.contrast_pos = so.events.contrast_threshold_pos;
  r.contrast_neg = so.events.contrast_threshold_neg;
  r.log_eps = so.events.log_eps;
  r.frame_gamma = so.frames.gamma;
  r.frame_gain = so.frames.gain;
  sink.r = &r;
  sink.shift = so.time_shift_ns;
  sink.frame_times = frame_times;
  for (int64_t t = probe.t_begin_ns() + period; t < probe.t_end_ns(); t += period) sink.views.push_back(t);
  sink.gain = so.frames.gain;
  sink.gamma = so.frames.gamma;
  sim.run(&sink);
  return r;
}

// The frame response matching the simulator's APS model (gain folded into the offset's scale is
// not modelled: gain 1 assumed).
inline evio::mapping::FrameResponse simulator_frame_response(const SimulatedRecording& r) {
  evio::mapping::FrameResponse f;
  f.gamma = r.frame_gamma;
  f.offset = std::pow(r.log_eps, 1.0 / r.frame_gamma);
  f.initial_grey = 127.5;
  return f;
}

struct MethodQuality {
  std::string method;
  std::vector<double> t_s, psnr_db, ssim;  // per ground-truth time
  double mean_psnr = 0, mean_ssim = 0;
};

// Runs `filter` over the recording's events (unless !events) and `frames` (none when null; each
// fused after the events at or before its time) and scores it at every ground-truth time;
// on_view, when set, also gets each view's index, estimate and the time since the last frame fused
// (-1 before the first).
using ViewCallback = std::function<void(size_t view, const evio::mapping::ImageF& estimate, double since_frame_s)>;
inline MethodQuality score_filter(const std::string& name, evio::mapping::LogIntensityFilter* filter,
                                  const SimulatedRecording& r, const std::vector<evio::Frame>* frames,
                                  bool events = true, const ViewCallback& on_view = nullptr) {
  MethodQuality q;
  q.method = name;
  const size_t n_events = events ? r.events.size() : 0;
  const size_t n_frames = frames ? frames->size() : 0;
  int64_t last_frame = INT64_MIN;
  size_t i = 0, k = 0;
  for (size_t g = 0; g < r.gt_t_ns.size(); ++g) {
    const int64_t t = r.gt_t_ns[g];
    for (;;) {
      const int64_t tf = k < n_frames ? (*frames)[k].t_ns : INT64_MAX;
      if (tf > t) break;
      size_t j = i;
      while (j < n_events && r.events[j].t_ns <= tf) ++j;
      filter->process(r.events.data() + i, j - i);
      i = j;
      const cv::Mat& m = (*frames)[k].image;
      filter->add_frame(tf, evio::mapping::GreyView{m.data, m.cols, m.rows, static_cast<std::ptrdiff_t>(m.step)});
      last_frame = tf;
      ++k;
    }
    size_t j = i;
    while (j < n_events && r.events[j].t_ns <= t) ++j;
    filter->process(r.events.data() + i, j - i);
    i = j;
    const evio::mapping::ImageF est = filter->log_intensity(t);
    const evio::mapping::ImageQuality iq = evio::mapping::compare_images(est, r.gt_log[g], nullptr);
    if (on_view) on_view(g, est, last_frame == INT64_MIN ? -1.0 : (t - last_frame) * 1e-9);
    q.t_s.push_back(t * 1e-9);
    q.psnr_db.push_back(iq.psnr_db);
    q.ssim.push_back(iq.ssim);
  }
  for (size_t g = 0; g < q.ssim.size(); ++g) {
    q.mean_psnr += q.psnr_db[g] / static_cast<double>(q.ssim.size());
    q.mean_ssim += q.ssim[g] / static_cast<double>(q.ssim.size());
  }
  return q;
}
inline MethodQuality score_filter(const std::string& name, evio::mapping::LogIntensityFilter* filter,
                                  const SimulatedRecording& r, bool frames) {
  return score_filter(name, filter, r, frames ? &r.frames : nullptr);
}

// hf (events only), cf and akf (with frames) with the recording's thresholds and frame response;
// cutoff_hz for hf and cf.
inline std::vector<MethodQuality> score_methods(const SimulatedRecording& r, double cutoff_hz = 0.5,
                                                evio::mapping::AsyncKalmanFilterOptions akf = {}) {
  const int64_t t0 = std::min(r.events.empty() ? 0 : r.events.front().t_ns, r.frames.empty() ? INT64_MAX : r.frames.front().t_ns);
  evio::mapping::ComplementaryFilterOptions cf;
  cf.cutoff_hz = cutoff_hz;
  cf.contrast_on = r.contrast_pos;
  cf.contrast_off = r.contrast_neg;
  cf.frame = simulator_frame_response(r);
  evio::mapping::ComplementaryFilterOptions hf = cf;
  hf.high_pass = true;
  hf.use_frames = false;
  akf.contrast_on = r.contrast_pos;
  akf.contrast_off = r.contrast_neg;
  akf.frame = cf.frame;
  std::vector<MethodQuality> out;
  evio::mapping::ComplementaryFilter f_hf(r.width, r.height, t0, hf), f_cf(r.width, r.height, t0, cf);
  evio::mapping::AsyncKalmanFilter f_akf(r.width, r.height, t0, akf);
  out.push_back(score_filter("hf", &f_hf, r, false));
  out.push_back(score_filter("cf", &f_cf, r, true));
  out.push_back(score_filter("akf", &f_akf, r, true));
  return out;
}

}  // namespace evio_test
