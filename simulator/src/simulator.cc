// Simulator driver: adaptive stepping over the body trajectory, event generation per render,
// APS frames and ground-truth views. See simulator.h for the model.
#include "evio/simulator/simulator.h"
#include "evio/calib/error.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <exception>
#include <stdexcept>
#include <thread>
#include <utility>

#include <opencv2/core.hpp>

#include "random.h"

namespace evio::simulator {
namespace {

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// Largest |flow| over the image, px/s (0 for an empty image).
double max_flow_norm(const cv::Mat& flow) {
  if (flow.empty()) return 0;
  double best2 = 0;
  for (int y = 0; y < flow.rows; ++y) {
    const auto* row = flow.ptr<cv::Vec2f>(y);
    for (int x = 0; x < flow.cols; ++x) {
      const double fx = row[x][0], fy = row[x][1];
      best2 = std::max(best2, fx * fx + fy * fy);
    }
  }
  return std::sqrt(best2);
}

}  // namespace

bool SteppingOptions::Validate(std::string* why) const {
  if (!(std::isfinite(max_flow_px) && max_flow_px >= 0)) return validation_failed(why, "stepping.max_flow_px must be >= 0 (px)");
  if (!(std::isfinite(max_log_change) && max_log_change >= 0))
    return validation_failed(why, "stepping.max_log_change must be >= 0 (log-intensity units)");
  if (min_step_ns <= 0) return validation_failed(why, "stepping.min_step_ns must be > 0 (ns)");
  if (max_step_ns < min_step_ns) return validation_failed(why, "stepping.max_step_ns must be >= min_step_ns (ns)");
  return true;
}

bool ApsOptions::Validate(std::string* why) const {
  if (!(std::isfinite(rate_hz) && rate_hz >= 0)) return validation_failed(why, "frames.rate_hz must be >= 0 (Hz)");
  if (rate_hz == 0) return true;
  if (!(std::isfinite(exposure_s) && exposure_s > 0 && exposure_s <= 1.0 / rate_hz))
    return validation_failed(why, "frames.exposure_s must be in (0, 1/rate_hz] (s)");
  if (exposure_samples < 1) return validation_failed(why, "frames.exposure_samples must be >= 1");
  if (!(std::isfinite(gain) && gain > 0)) return validation_failed(why, "frames.gain must be > 0");
  if (!(std::isfinite(gamma) && gamma > 0)) return validation_failed(why, "frames.gamma must be > 0");
  if (!(std::isfinite(read_noise_std) && read_noise_std >= 0))
    return validation_failed(why, "frames.read_noise_std must be >= 0 (grey levels)");
  return true;
}

bool SimulatorOptions::Validate(std::string* why) const {
  if (!camera.intrinsics().Validate(why)) return false;
  if (supersample < 1 || supersample > 8) return validation_failed(why, "supersample must be in 1..8");
  if (threads < 1 || threads > 64) return validation_failed(why, "threads must be in 1..64");
  if (t_end_ns < t_begin_ns) return validation_failed(why, "t_end_ns must be >= t_begin_ns");
  if (!stepping.Validate(why) || !events.Validate(why) || !frames.Validate(why)) return false;
  if (!std::is_sorted(ground_truth_times_ns.begin(), ground_truth_times_ns.end()))
    return validation_failed(why, "ground_truth_times_ns must be sorted");
  for (size_t i = 0; i < illumination.size(); ++i) {
    if (!(std::isfinite(illumination[i].second) && illumination[i].second > 0))
      return validation_failed(why, "illumination gains must be finite and > 0");
    if (i > 0 && illumination[i].first <= illumination[i - 1].first)
      return validation_failed(why, "illumination knots must have increasing times");
  }
  return true;
}

Simulator::Simulator(std::shared_ptr<const Scene> scene, std::shared_ptr<const ContinuousTrajectory> trajectory,
                     SimulatorOptions options)
    : scene_(std::move(scene)),
      trajectory_(std::move(trajectory)),
      o_(std::move(options)),
      rays_(o_.camera, std::max(1, o_.supersample)),
      T_b_c_(o_.T_c_b.inverse()) {
  if (!scene_ || !trajectory_) throw std::invalid_argument("simulator: scene and trajectory are required");
  std::string why;
  if (!o_.Validate(&why)) throw std::invalid_argument("simulator: " + why);
  t_begin_ = o_.t_begin_ns;
  t_end_ = o_.t_end_ns;
  if (t_begin_ == 0 && t_end_ == 0) {
    t_begin_ = trajectory_->t_begin_ns();
    t_end_ = trajectory_->t_end_ns();
  }
  if (t_begin_ < trajectory_->t_begin_ns() || t_end_ > trajectory_->t_end_ns() || t_end_ <= t_begin_)
    throw std::invalid_argument("simulator: the span [" + std::to_string(t_begin_) + ", " + std::to_string(t_end_) +
                                "] ns must be non-empty and inside the trajectory's range [" +
                                std::to_string(trajectory_->t_begin_ns()) + ", " +
                                std::to_string(trajectory_->t_end_ns()) + "] ns");
}

CameraState Simulator::camera_state(int64_t t_ns) const {
  const TrajectoryState s = trajectory_->evaluate(t_ns);
  CameraState c;
  c.t_ns = t_ns;
  c.T_w_c = s.T_w_b * T_b_c_;
  // Camera origin p_w_c = p_w_b + R_w_b t_b_c, so v_w_c = v_w + R_w_b (omega_b x t_b_c).
  const Eigen::Vector3d v_w_c = s.v_w + s.T_w_b.rotation * s.omega_b.cross(T_b_c_.translation);
  c.v_c = c.T_w_c.rotation.conjugate() * v_w_c;
  c.omega_c = o_.T_c_b.rotation * s.omega_b;
  return c;
}

double Simulator::illumination_gain(int64_t t_ns) const {
  const auto& k = o_.illumination;
  if (k.empty()) return 1.0;
  if (t_ns <= k.front().first) return k.front().second;
  if (t_ns >= k.back().first) return k.back().second;
  size_t i = 1;
  while (k[i].first < t_ns) ++i;
  const double a = static_cast<double>(t_ns - k[i - 1].first) / static_cast<double>(k[i].first - k[i - 1].first);
  return std::exp((1.0 - a) * std::log(k[i - 1].second) + a * std::log(k[i].second));
}

Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> log_intensity_view(const cv::Mat& intensity,
                                                                                         double log_eps) {
  if (intensity.type() != CV_32FC1) throw std::invalid_argument("log_intensity_view: expects a CV_32F image");
  Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> l(intensity.rows, intensity.cols);
  for (int y = 0; y < intensity.rows; ++y) {
    const float* in = intensity.ptr<float>(y);
    for (int x = 0; x < intensity.cols; ++x) l(y, x) = static_cast<float>(std::log(std::max(0.0f, in[x]) + log_eps));
  }
  return l;
}

Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> Simulator::true_log_view(int64_t t_cam_ns) const {
  return log_intensity_view(render(t_cam_ns + o_.time_shift_ns, false).intensity, o_.events.log_eps);
}

RenderedView Simulator::render(int64_t t_ns, bool with_flow) const {
  RenderedView view;
  RenderRequest request;
  request.flow = with_flow;
  const CameraState camera = camera_state(t_ns);
  const int h = o_.camera.height(), w = o_.camera.width();
  const int bands = std::min(o_.threads, h);
  if (bands <= 1) {
    scene_->render(camera, rays_, request, &view);
  } else {
    // Disjoint row bands of one view, rendered concurrently into images allocated here.
    view.intensity.create(h, w, CV_32F);
    view.depth.create(h, w, CV_32F);
    view.label.create(h, w, CV_16U);
    if (with_flow) view.flow.create(h, w, CV_32FC2);
    std::vector<std::exception_ptr> errors(bands);
    auto band = [&](int i) {
      try {
        RenderRequest r = request;
        r.row_begin = h * i / bands;
        r.row_end = h * (i + 1) / bands;
        scene_->render(camera, rays_, r, &view);
      } catch (...) {
        errors[i] = std::current_exception();
      }
    };
    std::vector<std::thread> workers;
    workers.reserve(bands - 1);
    for (int i = 1; i < bands; ++i) workers.emplace_back(band, i);
    band(0);
    for (std::thread& t : workers) t.join();
    for (const std::exception_ptr& e : errors)
      if (e) std::rethrow_exception(e);
  }
  const double gain = illumination_gain(t_ns);
  if (gain != 1.0) view.intensity *= gain;
  view.t_ns = t_ns;
  return view;
}

SimulationStats Simulator::run(SimulationSink* sink, const std::function<void(double, uint64_t)>& progress) {
  using Clock = std::chrono::steady_clock;
  const auto wall0 = Clock::now();
  SimulationStats stats;
  stats.simulated_ns = t_end_ - t_begin_;
  stats.min_step_ns = std::numeric_limits<int64_t>::max();
  const SteppingOptions& st = o_.stepping;
  const bool need_flow = st.max_flow_px > 0;
  const bool need_labels = o_.event_labels;
  const int64_t shift = o_.time_shift_ns;

  EventGenerator generator(o_.camera.width(), o_.camera.height(), o_.events);
  auto timed_render = [&](int64_t t, bool flow) {
    const auto r0 = Clock::now();
    RenderedView v = render(t, flow);
    stats.render_s += seconds_since(r0);
    return v;
  };

  RenderedView view = timed_render(t_begin_, need_flow);
  generator.reset(view.intensity, t_begin_ - shift);

  // Frames: frame k is exposed over [t_begin + k*period, t_begin + k*period + exposure] and
  // stamped at mid-exposure; only frames whose exposure fits in the span.
  const bool frames_on = o_.frames.rate_hz > 0;
  const double period_ns = frames_on ? 1e9 / o_.frames.rate_hz : 0;
  const int64_t exposure_ns = frames_on ? static_cast<int64_t>(std::llround(o_.frames.exposure_s * 1e9)) : 0;
  uint64_t next_frame = 0;
  internal::NormalSampler frame_noise(o_.frames.seed);
  auto frame_start = [&](uint64_t k) { return t_begin_ + static_cast<int64_t>(std::llround(k * period_ns)); };
  auto emit_frames_until = [&](int64_t t) {
    while (frames_on && frame_start(next_frame) + exposure_ns <= t_end_ && frame_start(next_frame) + exposure_ns / 2 <= t) {
      const int64_t t0 = frame_start(next_frame);
      const int n = o_.frames.exposure_samples;
      cv::Mat sum = cv::Mat::zeros(o_.camera.height(), o_.camera.width(), CV_64F);
      for (int i = 0; i < n; ++i) {
        const int64_t ti = t0 + static_cast<int64_t>(std::llround((i + 0.5) * exposure_ns / n));
        cv::Mat acc;
        timed_render(ti, false).intensity.convertTo(acc, CV_64F);
        sum += acc;
      }
      Frame frame;
      frame.t_ns = t0 + exposure_ns / 2 - shift;
      frame.image.create(sum.rows, sum.cols, CV_8UC1);
      const double inv_gamma = 1.0 / o_.frames.gamma;
      for (int y = 0; y < sum.rows; ++y) {
        const double* in = sum.ptr<double>(y);
        uint8_t* out = frame.image.ptr<uint8_t>(y);
        for (int x = 0; x < sum.cols; ++x) {
          const double lin = std::clamp(o_.frames.gain * in[x] / n, 0.0, 1.0);
          double v = 255.0 * std::pow(lin, inv_gamma);
          if (o_.frames.read_noise_std > 0) v += o_.frames.read_noise_std * frame_noise.next();
          out[x] = static_cast<uint8_t>(std::clamp(std::lround(v), 0L, 255L));
        }
      }
      if (sink) sink->on_frame(frame);
      ++stats.frames;
      ++next_frame;
    }
  };

  size_t next_gt = 0;
  const auto& gt_times = o_.ground_truth_times_ns;
  while (next_gt < gt_times.size() && gt_times[next_gt] < t_begin_) ++next_gt;
  auto emit_ground_truth_until = [&](int64_t t) {
    while (next_gt < gt_times.size() && gt_times[next_gt] <= t && gt_times[next_gt] <= t_end_) {
      const int64_t tg = gt_times[next_gt++];
      const RenderedView v = timed_render(tg, o_.ground_truth_flow);
      if (sink) sink->on_ground_truth(v, camera_state(tg));
    }
  };
  emit_ground_truth_until(t_begin_);

  std::vector<Event> events;
  std::vector<uint16_t> labels;
  cv::Mat previous_label, motion_label;
  if (need_labels) view.label.copyTo(previous_label);
  int64_t t = t_begin_;
  int64_t last_dt = 0;
  int64_t next_progress = t_begin_;
  const int64_t progress_every = std::max<int64_t>(1, (t_end_ - t_begin_) / 200);
  while (t < t_end_) {
    // Next step from the image-motion and brightness-change bounds.
    double dt_s = static_cast<double>(st.max_step_ns) * 1e-9;
    if (need_flow) {
      const double f = max_flow_norm(view.flow);
      stats.max_flow_pxps = std::max(stats.max_flow_pxps, f);
      if (f > 0) dt_s = std::min(dt_s, st.max_flow_px / f);
    }
    if (st.max_log_change > 0) {
      if (last_dt == 0) {
        dt_s = std::min(dt_s, static_cast<double>(st.min_step_ns) * 1e-9);
      } else {
        const double rate = generator.last_max_log_change() / (static_cast<double>(last_dt) * 1e-9);
        if (rate > 0) dt_s = std::min(dt_s, st.max_log_change / rate);
      }
    }
    int64_t dt = static_cast<int64_t>(std::llround(dt_s * 1e9));
    dt = std::clamp(dt, st.min_step_ns, st.max_step_ns);
    const int64_t t_next = (t_end_ - t <= dt) ? t_end_ : t + dt;
    dt = t_next - t;
    stats.min_step_ns = std::min(stats.min_step_ns, dt);
    stats.max_step_ns = std::max(stats.max_step_ns, dt);

    view = timed_render(t_next, need_flow);
    events.clear();
    labels.clear();
    const auto e0 = Clock::now();
    if (need_labels) {
      // The object whose motion caused an event: where an occlusion boundary crossed the pixel
      // during the step (label changed), the front object, which has the larger label (sprites
      // are drawn in label order over the background, 0); elsewhere the pixel's label. Labelling
      // by the end label alone would give a sprite's trailing-edge events to the background
      // uncovered behind it, although they move with the sprite.
      cv::max(previous_label, view.label, motion_label);
      generator.step(view.intensity, t_next - shift, &events, &motion_label, &labels);
      view.label.copyTo(previous_label);
    } else {
      generator.step(view.intensity, t_next - shift, &events);
    }
    stats.events_s += seconds_since(e0);
    for (const Event& e : events) (e.polarity > 0 ? stats.events_on : stats.events_off)++;
    stats.events += events.size();
    ++stats.steps;
    if (sink && !events.empty()) sink->on_events(events, need_labels ? &labels : nullptr);
    emit_frames_until(t_next);
    emit_ground_truth_until(t_next);
    last_dt = dt;
    t = t_next;
    if (progress && t >= next_progress) {
      progress(static_cast<double>(t - t_begin_) / static_cast<double>(t_end_ - t_begin_), stats.events);
      next_progress = t + progress_every;
    }
  }
  if (stats.steps == 0) stats.min_step_ns = 0;
  stats.wall_s = seconds_since(wall0);
  return stats;
}

}  // namespace evio::simulator
