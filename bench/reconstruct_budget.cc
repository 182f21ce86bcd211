// Where the reconstruction error comes from: one scene simulated in memory with APS frames and ideal
// frames (the true view at each frame's time through the APS response, without motion blur or read
// noise), then hf, cf and akf run with events and APS frames, with ideal frames, with frames only
// (no events) and with events only; the last frame alone is a baseline. Per variant: mean PSNR /
// SSIM, the fitted contrast scale, and the RMS error after the fit (log units) split by the true
// view's exposure (the APS grey level it would give: under < 25, over > 230) and by the time since
// the last frame fused.
//   reconstruct_budget SCENE.yaml [--duration S] [--period S] [--seed N] [--cutoff-hz F]
//                      [--set key=value ...] [--akf key=value ...] [--only NAME,...]
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "evio_test/simulated_reconstruction.h"
#include "tool_args.h"

namespace {

using evio::mapping::AsyncKalmanFilter;
using evio::mapping::AsyncKalmanFilterOptions;
using evio::mapping::ComplementaryFilter;
using evio::mapping::ComplementaryFilterOptions;

void set_akf(AsyncKalmanFilterOptions* o, const std::string& kv) {
  const size_t eq = kv.find('=');
  const std::string k = kv.substr(0, eq);
  const double v = std::atof(kv.substr(eq + 1).c_str());
  if (k == "initial_variance") o->initial_variance = v;
  else if (k == "event_noise") o->event_noise = v;
  else if (k == "process_noise") o->process_noise = v;
  else if (k == "isolated_noise") o->isolated_noise = v;
  else if (k == "refractory_noise") o->refractory_noise = v;
  else if (k == "refractory_period_ms") o->refractory_period_ns = static_cast<int64_t>(v * 1e6);
  else if (k == "exposure_low") o->exposure_low = v;
  else if (k == "exposure_high") o->exposure_high = v;
  else if (k == "min_exposure_weight") o->min_exposure_weight = v;
  else if (k == "frame_noise_std") o->frame_noise_std = v;
  else {
    std::fprintf(stderr, "unknown akf key %s\n", k.c_str());
    std::exit(2);
  }
}

struct Budget {
  // exposure classes: under, normal, over; since-frame bins of 10 ms (the last is >= 30 ms)
  double se[3] = {0, 0, 0}, sum[3] = {0, 0, 0};
  int64_t n[3] = {0, 0, 0};
  double se_t[4] = {0, 0, 0, 0};
  int64_t n_t[4] = {0, 0, 0, 0};
  double scale = 0;
  int views = 0;
};

}  // namespace

int main(int argc, char** argv) {
  std::string scene, only, dump;  // dump: folder for PNGs of view dump_view (truth, each variant fitted, |error|)
  int dump_view = 0;
  int trace_x = -1, trace_y = -1;  // print this pixel's truth, estimate (fitted) and variance at every view
  std::vector<std::string> sets, akf_sets;
  double duration = 2.0, period = 0.25, cutoff = 0.5;
  uint64_t seed = 0;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&] { return next_arg(argc, argv, &i); };
    if (a == "--duration") duration = std::atof(next().c_str());
    else if (a == "--period") period = std::atof(next().c_str());
    else if (a == "--cutoff-hz") cutoff = std::atof(next().c_str());
    else if (a == "--seed") seed = std::strtoull(next().c_str(), nullptr, 10);
    else if (a == "--set") sets.push_back(next());
    else if (a == "--akf") akf_sets.push_back(next());
    else if (a == "--dump") dump = next();
    else if (a == "--dump-view") dump_view = std::atoi(next().c_str());
    else if (a == "--trace") std::sscanf(next().c_str(), "%d,%d", &trace_x, &trace_y);
    else if (a == "--only") only = "," + next() + ",";
    else scene = a;
  }
  if (scene.empty()) {
    std::fprintf(stderr, "usage: reconstruct_budget SCENE.yaml [--duration S] [--period S] [--seed N] [--cutoff-hz F] [--set k=v] [--akf k=v] [--only a,b]\n");
    return 2;
  }
  const evio_test::SimulatedRecording r = evio_test::simulate_recording(scene, duration, period, sets, seed, true);
  const int64_t t0 = std::min(r.events.front().t_ns, r.frames.front().t_ns);
  ComplementaryFilterOptions cf;
  cf.cutoff_hz = cutoff;
  cf.contrast_on = r.contrast_pos;
  cf.contrast_off = r.contrast_neg;
  cf.frame = evio_test::simulator_frame_response(r);
  ComplementaryFilterOptions hf = cf;
  hf.high_pass = true;
  hf.use_frames = false;
  ComplementaryFilterOptions last = cf;
  last.cutoff_hz = 1e6;  // the state is the last frame
  AsyncKalmanFilterOptions akf;
  akf.contrast_on = r.contrast_pos;
  akf.contrast_off = r.contrast_neg;
  akf.frame = cf.frame;
  for (const auto& kv : akf_sets) set_akf(&akf, kv);
  AsyncKalmanFilterOptions akf_events = akf;
  akf_events.use_frames = false;

  // The exposure class of each true view's pixels (the APS grey level of the true intensity).
  std::vector<std::vector<uint8_t>> cls(r.gt_log.size());
  for (size_t g = 0; g < r.gt_log.size(); ++g) {
    const auto& l = r.gt_log[g];
    cls[g].resize(static_cast<size_t>(l.rows()) * l.cols());
    for (int y = 0; y < l.rows(); ++y)
      for (int x = 0; x < l.cols(); ++x) {
        const double lin = std::clamp(r.frame_gain * (std::exp(l(y, x)) - r.log_eps), 0.0, 1.0);
        const double v = 255.0 * std::pow(lin, 1.0 / r.frame_gamma);
        cls[g][static_cast<size_t>(y) * l.cols() + x] = v < 25 ? 0 : v > 230 ? 2 : 1;
      }
  }

  {
    int64_t c[3] = {0, 0, 0};
    for (const auto& v : cls)
      for (uint8_t k : v) ++c[k];
    const double n = static_cast<double>(c[0] + c[1] + c[2]);
    std::printf("true exposure: under %.1f%%, normal %.1f%%, over %.1f%% of view pixels\n", 100 * c[0] / n, 100 * c[1] / n,
                100 * c[2] / n);
  }
  struct Variant {
    std::string name;
    std::function<std::unique_ptr<evio::mapping::LogIntensityFilter>()> make;
    const std::vector<evio::Frame>* frames;
    bool events;
  };
  auto cfm = [&](const ComplementaryFilterOptions& o) {
    return [&r, t0, o]() { return std::unique_ptr<evio::mapping::LogIntensityFilter>(new ComplementaryFilter(r.width, r.height, t0, o)); };
  };
  auto akfm = [&](const AsyncKalmanFilterOptions& o) {
    return [&r, t0, o]() { return std::unique_ptr<evio::mapping::LogIntensityFilter>(new AsyncKalmanFilter(r.width, r.height, t0, o)); };
  };
  const std::vector<Variant> variants = {
      {"hf", cfm(hf), nullptr, true},
      {"cf", cfm(cf), &r.frames, true},
      {"akf", akfm(akf), &r.frames, true},
      {"last_frame", cfm(last), &r.frames, false},
      {"cf_ideal", cfm(cf), &r.true_frames, true},
      {"akf_ideal", akfm(akf), &r.true_frames, true},
      {"last_ideal", cfm(last), &r.true_frames, false},
      {"akf_frames_only", akfm(akf), &r.frames, false},
      {"akf_events_only", akfm(akf_events), nullptr, true},
  };
  std::printf("%s: %zu events, %zu frames, %zu views, seed %llu, cf cut-off %.3g Hz\n", scene.c_str(), r.events.size(),
              r.frames.size(), r.gt_t_ns.size(), static_cast<unsigned long long>(seed), cutoff);
  std::printf("| variant | PSNR | SSIM | scale | RMS under / normal / over | mean under / normal / over | RMS by ms since frame 0-10 / 10-20 / 20-30 / 30+ |\n");
  std::printf("|---|---:|---:|---:|---|---|---|\n");
  for (const Variant& v : variants) {
    if (!only.empty() && only.find("," + v.name + ",") == std::string::npos) continue;
    Budget b;
    auto filter = v.make();
    const evio_test::MethodQuality q = evio_test::score_filter(
        v.name, filter.get(), r, v.frames, v.events, [&](size_t g, const evio::mapping::ImageF& est, double since) {
          const evio::mapping::ImageQuality iq = evio::mapping::compare_images(est, r.gt_log[g], nullptr);
          if (!dump.empty() && static_cast<int>(g) == dump_view) {
            evio::mapping::ImageF fit = est, err = est;
            for (int y = 0; y < est.rows(); ++y)
              for (int x = 0; x < est.cols(); ++x) {
                fit(y, x) = static_cast<float>(iq.scale * est(y, x) + iq.offset);
                err(y, x) = std::fabs(fit(y, x) - r.gt_log[g](y, x));
              }
            evio::mapping::LogImageDisplayOptions d;
            d.low_percentile = 0;
            d.high_percentile = 100;
            evio::mapping::write_log_image_png8(dump + "/" + v.name + ".png", fit, nullptr, d);
            evio::mapping::write_log_image_png8(dump + "/" + v.name + "_abs_error.png", err, nullptr, d);
            evio::mapping::write_log_image_png8(dump + "/truth.png", r.gt_log[g], nullptr, d);
          }
          if (trace_x >= 0) {
            float p = NAN;
            if (auto* k = dynamic_cast<AsyncKalmanFilter*>(filter.get())) {
              evio::mapping::ImageF pv;
              k->variance(r.gt_t_ns[g], &pv);
              p = pv(trace_y, trace_x);
            }
            std::printf("trace %s t %.4f truth %.3f est %.3f P %.4g since_frame %.4f\n", v.name.c_str(), r.gt_t_ns[g] * 1e-9,
                        r.gt_log[g](trace_y, trace_x), iq.scale * est(trace_y, trace_x) + iq.offset, p, since);
          }
          b.scale += iq.scale;
          ++b.views;
          const int bin = since < 0 ? 3 : std::min(3, static_cast<int>(since * 100));
          const auto& l = r.gt_log[g];
          for (int y = 0; y < l.rows(); ++y)
            for (int x = 0; x < l.cols(); ++x) {
              const double e = iq.scale * est(y, x) + iq.offset - l(y, x);
              const int c = cls[g][static_cast<size_t>(y) * l.cols() + x];
              b.se[c] += e * e;
              b.sum[c] += e;
              ++b.n[c];
              b.se_t[bin] += e * e;
              ++b.n_t[bin];
            }
        });
    auto rms = [](double se, int64_t n) { return n ? std::sqrt(se / n) : NAN; };
    std::printf("| %s | %.2f | %.3f | %.2f | %.3f / %.3f / %.3f | %+.3f / %+.3f / %+.3f | %.3f / %.3f / %.3f / %.3f |\n", v.name.c_str(), q.mean_psnr,
                q.mean_ssim, b.scale / std::max(1, b.views), rms(b.se[0], b.n[0]), rms(b.se[1], b.n[1]), rms(b.se[2], b.n[2]),
                b.sum[0] / std::max<int64_t>(1, b.n[0]), b.sum[1] / std::max<int64_t>(1, b.n[1]), b.sum[2] / std::max<int64_t>(1, b.n[2]),
                rms(b.se_t[0], b.n_t[0]), rms(b.se_t[1], b.n_t[1]), rms(b.se_t[2], b.n_t[2]), rms(b.se_t[3], b.n_t[3]));
    std::fflush(stdout);
  }
  return 0;
}
