#include "vio_stats.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <ostream>
#include <sstream>
#include <vector>

#include "evio/backend/motion_model_selection.h"
#include "evio/calib/error.h"
#include "evio/calib/json.h"
#include "evio/sensors/time.h"

namespace evio::apps {
namespace {

// A JSON list body of spans: {"t_begin": s, "t_end": s, "reason": "..."}, comma-separated.
void write_segments(std::ostream& j, const std::vector<pipeline::VioSegment>& segments) {
  for (size_t i = 0; i < segments.size(); ++i) {
    const pipeline::VioSegment& l = segments[i];
    j << (i ? ", " : "") << "{\"t_begin\": " << format_seconds(l.t_begin_ns) << ", \"t_end\": " << format_seconds(l.t_end_ns)
      << ", \"reason\": \"" << l.what << "\"}";
  }
}

double median_solve_s(const backend::SlidingWindowStats& st) {
  std::vector<double> solve = st.solve_time_s;
  std::sort(solve.begin(), solve.end());
  return solve.empty() ? 0 : solve[solve.size() / 2];
}

// The model block: the motion model per segment with the keyframes and GRIC numbers that decided
// it (margin: GRIC of the general model minus that of rotation-only; > rotation_only_gric_margin
// for rotation_only_min_keyframes keyframes switches rotation-only on), and the frames' sizes.
std::string model_json(const VioConfig& cfg, const pipeline::VioResult& r, double duration_s) {
  const pipeline::VioStats& vs = r.stats;
  const backend::SlidingWindowStats& st = vs.window;
  std::ostringstream mj, summary;
  double rot_s = 0, all_s = 0;
  mj << "{\"motion\": {\"selection\": " << (cfg.window.rotation_only_model ? "\"auto\"" : "\"fixed\"")
     << ", \"rule\": \"GRIC per keyframe with hysteresis and the IMU and parallax conditions (backend/sliding_window_estimator.h)\""
     << ", \"gric_margin\": " << json_number(cfg.window.rotation_only_gric_margin, 10) << ", \"min_keyframes\": "
     << cfg.window.rotation_only_min_keyframes << ", \"keyframes\": " << st.keyframes
     << ", \"rotation_only_keyframes\": " << st.rotation_only_keyframes << ", \"segments\": [";
  for (size_t i = 0; i < r.motion_models.size(); ++i) {
    const pipeline::VioSegment& m = r.motion_models[i];
    int keyframes = 0, tested = 0;
    double margin = 0;
    for (const auto& t : st.motion_model_tests) {
      if (t.t_ns < m.t_begin_ns || t.t_ns > m.t_end_ns) continue;
      ++keyframes;
      if (t.best == backend::TwoViewModel::kNone) continue;
      ++tested;
      margin += t.gric_general - t.gric_rotation;
    }
    const double d = static_cast<double>(m.t_end_ns - m.t_begin_ns) * 1e-9;
    all_s += d;
    if (m.what == "rotation_only") rot_s += d;
    mj << (i ? ", " : "") << "{\"model\": \"" << m.what << "\", \"t_start_s\": " << format_seconds(m.t_begin_ns)
       << ", \"t_end_s\": " << format_seconds(m.t_end_ns) << ", \"keyframes\": " << keyframes
       << ", \"gric_margin_mean\": " << json_number(tested ? margin / tested : NAN, 10) << "}";
  }
  const double share = all_s > 0 ? rot_s / all_s : 0.0;
  mj << "], \"rotation_only_s\": " << json_number(rot_s, 10) << ", \"rotation_only_share\": " << json_number(share, 10) << "}";
  summary << "rotation_only " << json_number(100.0 * share, 10) << "% of the time (" << st.rotation_only_keyframes << " of " << st.keyframes
          << " keyframes)";
  if (cfg.frontend == pipeline::VioFrontEnd::kFrames) {
    const frontend::EventFrameOptions& fo = cfg.frames;
    const int64_t frames = vs.event_frames.frames_emitted;
    const bool adaptive = fo.min_window_ns > 0;
    const double per_frame = frames > 0 ? static_cast<double>(vs.events) / static_cast<double>(frames) : NAN;
    mj << ", \"frames\": {\"events_per_frame\": " << fo.events_per_frame << ", \"adaptive\": " << json_bool(adaptive)
       << ", \"min_window_ms\": " << json_number(fo.min_window_ns * 1e-6, 10) << ", \"max_window_ms\": " << json_number(fo.max_window_ns * 1e-6, 10)
       << ", \"frames\": " << frames << ", \"mean_events_per_frame\": " << json_number(per_frame, 10)
       << ", \"mean_frame_interval_ms\": " << json_number(frames > 0 ? 1e3 * duration_s / static_cast<double>(frames) : NAN, 10) << "}";
    summary << "; frames " << (adaptive ? "adaptive" : "fixed") << ", " << json_number(per_frame, 10) << " events per frame";
  }
  mj << ", \"summary\": " << json_string(summary.str()) << "}";
  return mj.str();
}

// The model-selection test per keyframe (GRIC of the static, rotation and general models; the
// decision after hysteresis and the pixel conditions), then the per-keyframe health checks.
void write_keyframe_lists(std::ostream& j, const backend::SlidingWindowStats& st) {
  j << "],\n  \"motion_model_tests\": [";
  for (size_t i = 0; i < st.motion_model_tests.size(); ++i) {
    const auto& m = st.motion_model_tests[i];
    j << (i ? ",\n    " : "\n    ") << "{\"t\": " << format_seconds(m.t_ns) << ", \"tracks\": " << m.tracks
      << ", \"baseline_s\": " << json_number(m.baseline_s, 10)
      << ", \"gric_static\": " << json_number(m.gric_static, 10) << ", \"gric_rotation\": " << json_number(m.gric_rotation, 10)
      << ", \"gric_general\": " << json_number(m.gric_general, 10) << ", \"imu_chi2\": " << json_number(m.imu_chi2, 10)
      << ", \"imu_dof\": " << m.imu_dof << ", \"landmarks\": " << m.landmarks << ", \"best\": \""
      << backend::two_view_model_name(m.best) << "\", \"image_best\": \"" << backend::two_view_model_name(m.image_best)
      << "\", \"translation_flow_deg_s\": " << json_number(m.translation_flow_deg_s, 6)
      << ", \"imu_veto\": " << json_bool(m.imu_veto)
      << ", \"centre\": \"" << (m.centre_imu ? "imu" : "camera") << "\", \"rotation_only\": " << json_bool(m.rotation_only) << "}";
  }
}

void write_health(std::ostream& j, const backend::SlidingWindowStats& st, const pipeline::VioResult& r) {
  j << "],\n  \"health\": {\"keyframes\": [";
  for (size_t i = 0; i < st.health.size(); ++i) {
    const auto& h = st.health[i];
    j << (i ? ",\n    " : "\n    ") << "{\"t\": " << format_seconds(h.t_ns) << ", \"visual_chi2_per_dof\": " << json_number(h.visual_chi2_per_dof, 10)
      << ", \"imu_chi2_per_dof\": " << json_number(h.imu_chi2_per_dof, 10) << ", \"observations\": " << h.observations
      << ", \"landmarks\": " << h.landmarks << ", \"gyro_bias_sigmas\": " << json_number(h.gyro_bias_sigmas, 10) << "}";
  }
  j << "], \"unreliable_segments\": [";
  write_segments(j, r.unreliable);
  j << "]}";
}

// The rotation tracker (rotation_tracker.enabled): its segments and spans, and every factor with
// its residual after the last solve that held it.
void write_rotation_tracker(std::ostream& j, const VioConfig& cfg, const pipeline::VioResult& r) {
  const pipeline::VioStats& vs = r.stats;
  const backend::SlidingWindowStats& st = vs.window;
  int64_t dropped = 0;
  for (const auto& f : st.tracker_factors) dropped += f.dropped ? 1 : 0;
  j << ",\n  \"rotation_tracker\": {\"enabled\": " << json_bool(cfg.rotation_tracker) << ", \"segments\": " << vs.rotation_tracker_segments
    << ", \"discarded\": " << vs.rotation_tracker_discarded << ", \"corrected_keyframes\": " << vs.rotation_tracker_corrected_keyframes << ", \"events\": " << vs.rotation_tracker_events << ", \"lost_samples\": " << vs.rotation_tracker_lost_samples << ", \"time_s\": " << json_number(vs.rotation_tracker_time_s, 10)
    << ", \"samples\": " << st.tracker_samples << ", \"anchors\": " << st.tracker_anchors
    << ", \"factors_added\": " << st.tracker_factors.size() << ", \"factors_dropped\": " << dropped << ",\n    \"spans\": [";
  write_segments(j, r.rotation_tracker);
  j << "],\n    \"factors\": [";
  for (size_t i = 0; i < st.tracker_factors.size(); ++i) {
    const auto& f = st.tracker_factors[i];
    j << (i ? ",\n      " : "\n      ")
      << "{\"t\": " << format_seconds(f.t_ns) << ", \"anchor_t\": " << format_seconds(f.anchor_t_ns) << ", \"segment\": " << f.segment
      << ", \"sigma_deg\": " << json_number(f.sigma_deg, 6) << ", \"residual_deg\": " << json_number(f.error_deg, 6)
      << ", \"chi2\": " << json_number(f.chi2, 6) << ", \"dropped\": " << json_bool(f.dropped) << ", \"measured_xyzw\": ["
      << json_number(f.measured.x(), 10) << ", " << json_number(f.measured.y(), 10) << ", " << json_number(f.measured.z(), 10) << ", "
      << json_number(f.measured.w(), 10) << "]}";
  }
  j << "]}";
}

void write_frontend_stats(std::ostream& j, const VioConfig& cfg, const pipeline::VioStats& vs) {
  j << ",\n  \"frontend_stats\": {";
  if (cfg.frontend == pipeline::VioFrontEnd::kFrames) {
    const auto& ts = vs.tracker;
    const auto& fs_ = vs.event_frames;
    j << "\"event_frames\": " << fs_.frames_emitted << ", \"frames_uncompensated\": " << fs_.frames_uncompensated
      << ", \"frames_dropped_sparse\": " << fs_.frames_dropped_sparse << ", \"tracks_detected\": " << ts.detected
      << ", \"tracked\": " << ts.tracked << ", \"lost_klt\": " << ts.lost_klt << ", \"lost_forward_backward\": " << ts.lost_fb
      << ", \"rejected_ransac\": " << ts.rejected_ransac << ", \"template_fallbacks\": " << ts.template_fallbacks
      << ", \"rejected_anchor\": " << ts.rejected_anchor << ", \"template_rotation_refreshes\": " << ts.template_rotation_refreshes
      << ", \"reacquired\": " << ts.reacquired << ", \"lost_rotation_warp\": " << ts.lost_warp;
  } else {
    j << "\"corner_events\": " << vs.corner_events << ", \"corner_tracks_started\": " << vs.corner_tracker.tracks_started;
  }
  if (cfg.inputs != pipeline::VioInputs::kEvents) {
    const auto& as = vs.aps_tracker;
    j << ", \"aps_frames\": " << vs.aps_frames << ", \"aps_frames_dropped\": " << vs.aps_frames_dropped
      << ", \"aps_tracks_detected\": " << as.detected << ", \"aps_tracked\": " << as.tracked << ", \"aps_lost_klt\": " << as.lost_klt
      << ", \"aps_lost_forward_backward\": " << as.lost_fb << ", \"aps_rejected_ransac\": " << as.rejected_ransac;
  }
  j << "}";
}

void write_oracle(std::ostream& j, const VioArgs& args, const evaluation::TrackOracle& oracle) {
  j << ",\n  \"oracle\": {\"scene\": " << json_string(args.oracle_scene) << ", \"white_noise_px\": " << json_number(args.oracle_noise_px, 10)
    << ", \"drift_px_per_frame\": " << json_number(args.oracle_drift_px, 10) << ", \"replaced\": " << oracle.stats().replaced
    << ", \"dropped\": " << oracle.stats().dropped << ", \"keep_error\": \"" << args.oracle_error
    << "\", \"common_mode_rms_px\": " << json_number(oracle.stats().common_mode_rms_px, 10)
    << ", \"max_error_px\": " << json_number(args.oracle_max_error_px, 10) << ", \"dropped_gross\": " << oracle.stats().dropped_gross
    << ",\n    \"error_by_track_age\": [";
  for (int k = 0; k < evaluation::TrackOracleStats::kAgeBuckets; ++k) {
    const auto& b = oracle.stats().by_age[k];
    j << (k ? ",\n      " : "\n      ")
      << JsonObject(4)
             .integer("age_from_frames", evaluation::TrackOracleStats::kAgeBucketStart[k])
             .integer("observations", b.count)
             .number("error_rms_px", b.error_rms_px)
             .number("independent_rms_px", b.independent_rms_px)
             .number("independent_median_px", b.independent_quantile_px(0.5))
             .number("independent_p90_px", b.independent_quantile_px(0.9))
             .str();
  }
  j << "]}";
}

}  // namespace

void write_vio_stats(const std::string& path, const VioArgs& args, const VioConfig& cfg, const pipeline::VioResult& r,
                     const VioRunSummary& run, const evaluation::TrackOracle* oracle) {
  const pipeline::VioStats& vs = r.stats;
  const backend::SlidingWindowStats& st = vs.window;
  std::ofstream j(path);
  j << "{\n  \"dataset\": " << json_string(args.dataset) << ",\n  \"model\": " << model_json(cfg, r, run.duration_s)
    << ",\n  \"inputs\": \"" << pipeline::to_string(cfg.inputs) << "\",\n  \"frontend\": \"" << pipeline::to_string(cfg.frontend)
    << "\",\n  \"events\": " << vs.events << ",\n  \"corners\": " << vs.corner_events << ",\n  \"frames\": " << st.frames
    << ",\n  \"keyframes\": " << st.keyframes << ",\n  \"landmarks\": " << run.landmarks
    << ",\n  \"processing_time_s\": " << json_number(run.processing_s, 10) << ",\n  \"sequence_duration_s\": " << json_number(run.duration_s, 10)
    << ",\n  \"real_time_factor\": " << json_number(run.duration_s > 0 ? run.processing_s / run.duration_s : 0.0, 10)
    << ",\n  \"solve_ms_median\": " << json_number(1e3 * median_solve_s(st), 10) << ",\n  \"initialisation\": {\"method\": \""
    << run.init_method << "\", \"t\": " << format_seconds(r.init_t_ns) << "},\n  \"imu_noise_from\": " << json_string(run.noise_source)
    << ",\n  \"motion_model_segments\": [";
  for (size_t i = 0; i < r.motion_models.size(); ++i) {
    const pipeline::VioSegment& m = r.motion_models[i];
    j << (i ? ", " : "") << "{\"t_begin\": " << format_seconds(m.t_begin_ns) << ", \"t_end\": " << format_seconds(m.t_end_ns)
      << ", \"model\": \"" << m.what << "\"}";
  }
  write_keyframe_lists(j, st);
  j << "],\n  \"tracking_lost_segments\": [";
  write_segments(j, r.tracking_lost);
  write_health(j, st, r);
  j << ",\n  \"imu_only_segments\": [";
  write_segments(j, r.imu_only);
  double imu_only_s = 0;
  for (const pipeline::VioSegment& l : r.imu_only) imu_only_s += 1e-9 * static_cast<double>(l.t_end_ns - l.t_begin_ns);
  j << "],\n  \"imu_only_s\": " << json_number(imu_only_s, 10);
  write_frontend_stats(j, cfg, vs);
  write_rotation_tracker(j, cfg, r);
  if (oracle) write_oracle(j, args, *oracle);
  j << ",\n  \"outliers_removed\": " << st.outliers_removed << ",\n  \"landmarks_marginalised\": " << st.landmarks_marginalised
    << ",\n  \"observations_dropped\": " << st.observations_dropped
    << ",\n  \"tracked_landmarks_marginalised\": " << st.tracked_landmarks_marginalised << ",\n  \"rotation_only_keyframes\": " << st.rotation_only_keyframes;
  if (cfg.window.estimate_time_offset) j << ",\n  \"time_offset_correction_s\": " << json_number(st.time_offset_s, 10);
  j << "\n}\n";
  j.close();
  if (!j) throw InputError(path, 0, "write failed (disk full?)", "a writable output folder");
}

void print_vio_summary(std::ostream& out, const pipeline::VioResult& r, const VioRunSummary& run) {
  const pipeline::VioStats& vs = r.stats;
  const backend::SlidingWindowStats& st = vs.window;
  char buf[512];
  std::snprintf(buf, sizeof(buf),
                "events        %lld over %.2f s, %lld corner events, %lld frames, %lld keyframes, %zu landmarks\n"
                "initialised   at %s s by %s\n"
                "speed         %.2f s processing, real-time factor %.3f (one core), solve %.1f ms median\n",
                static_cast<long long>(vs.events), run.duration_s, static_cast<long long>(vs.corner_events),
                static_cast<long long>(st.frames), static_cast<long long>(st.keyframes), run.landmarks,
                format_seconds(r.init_t_ns).c_str(), run.init_method.c_str(), run.processing_s,
                run.duration_s > 0 ? run.processing_s / run.duration_s : 0.0, 1e3 * median_solve_s(st));
  out << buf;
  out << "motion model  ";
  for (const auto& m : r.motion_models) out << m.what << " " << format_seconds(m.t_begin_ns) << ".." << format_seconds(m.t_end_ns) << "  ";
  out << "\n";
  if (vs.rotation_tracker_segments > 0) {
    size_t kept = 0;
    for (const auto& f : vs.window.tracker_factors) kept += f.dropped ? 0 : 1;
    std::snprintf(buf, sizeof(buf), "rotation tracker %lld segment(s), %zu factors (%zu dropped), %.2f s of tracking\n",
                  static_cast<long long>(vs.rotation_tracker_segments), kept, vs.window.tracker_factors.size() - kept,
                  vs.rotation_tracker_time_s);
    out << buf;
  }
  if (!r.tracking_lost.empty()) out << "tracking lost " << r.tracking_lost.size() << " segment(s), see stats.json\n";
}

}  // namespace evio::apps
