// track_quality: scores the feature tracks of an `evio vio` run on a simulated sequence against the
// simulator's ground truth (evio::evaluation::evaluate_tracks): each observation of
// OUT/observations.txt against the projection of its track's true landmark (the first
// observation's ray cast into the scene of SCENE.yaml, and the least-squares point of the
// track with the true poses), error as a function of track age, track lifetime, and the share of
// tracks lost while their landmark was in view. Prints a table; --json writes the figures.
//   track_quality SEQ SCENE.yaml OBSERVATIONS.txt [--json FILE] [--residuals FILE] [--lag-scan] [--set key=value ...]
// SEQ is the `evio simulate` folder (groundtruth.txt, calib.yaml); SCENE.yaml the scene it was
// simulated from (with the same --set overrides, e.g. trajectory.path for the mocap replay), or
// SEQ/meta.json for a room sequence of the crosscheck simulator (../shared/crosscheck_sim).
#include <cmath>
#include <cstdio>
#include <exception>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "evio/calib/calibration_io.h"
#include "evio/evaluation/box_room_scene.h"
#include "evio/evaluation/track_evaluation.h"
#include "evio/simulator/scene.h"
#include "evio/sensors/trajectory.h"
#include "evio/simulator/scene_config.h"

namespace {

using namespace evio;  // NOLINT

// observations.txt of `evio vio`: "t[s] track_id bx by bz", frames in time order.
std::vector<FeatureObservations> read_observations(const std::string& path) {
  std::ifstream f(path);
  if (!f) throw std::runtime_error(path + ": cannot open (expected the observations.txt of an evio vio run)");
  std::vector<FeatureObservations> frames;
  std::string line;
  int64_t n = 0;
  while (std::getline(f, line)) {
    ++n;
    if (line.empty() || line[0] == '#') continue;
    std::istringstream s(line);
    double t = 0, bx = 0, by = 0, bz = 0;
    long long id = 0;
    if (!(s >> t >> id >> bx >> by >> bz)) {
      throw std::runtime_error(path + ":" + std::to_string(n) + ": expected 't[s] track_id bx by bz', got '" + line + "'");
    }
    const int64_t t_ns = std::llround(t * 1e9);
    if (frames.empty() || frames.back().t_ns != t_ns) {
      FeatureObservations fr;
      fr.t_ns = t_ns;
      fr.frame_id = static_cast<int64_t>(frames.size());
      frames.push_back(fr);
    }
    frames.back().observations.push_back({id, Eigen::Vector3d(bx, by, bz).normalized()});
  }
  return frames;
}

void print(const char* name, const evaluation::TrackEvaluation& e) {
  std::printf("%s: %lld tracks (%lld scored), %lld observations scored, %lld gross (> 10 px)\n", name,
              static_cast<long long>(e.tracks), static_cast<long long>(e.tracks_scored),
              static_cast<long long>(e.observations_scored), static_cast<long long>(e.gross_errors));
  std::printf("  error px: median %.3f, mean %.3f, p90 %.3f\n", e.median_px, e.mean_px, e.p90_px);
  std::printf("  by age (frames): ");
  for (int a : {1, 2, 5, 10, 20, 40}) {
    if (a > static_cast<int>(e.by_age.size())) break;
    const auto& b = e.by_age[static_cast<size_t>(a - 1)];
    std::printf("%d: %.3f (n %lld)  ", a, b.median_px, static_cast<long long>(b.count));
  }
  std::printf("\n");
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 4) {
    std::fprintf(stderr, "usage: track_quality SEQ SCENE.yaml OBSERVATIONS.txt [--json FILE] [--residuals FILE] [--lag-scan] [--set key=value ...]\n");
    return 2;
  }
  try {
    const std::string seq = argv[1], scene_yaml = argv[2], obs_path = argv[3];
    std::string json;
    bool lag_scan = false;
    std::string residuals;
    simulator::SimulateOverrides ov;
    for (int i = 4; i < argc; ++i) {
      const std::string a = argv[i];
      if (a == "--json" && i + 1 < argc) {
        json = argv[++i];
      } else if (a == "--residuals" && i + 1 < argc) {
        residuals = argv[++i];
      } else if (a == "--lag-scan") {
        lag_scan = true;
      } else if (a == "--set" && i + 1 < argc) {
        ov.set.push_back(argv[++i]);
      } else {
        throw std::runtime_error("unknown argument '" + a + "'");
      }
    }
    // The true scene: evio's planar scene YAML, or the meta.json of a crosscheck-simulator room.
    evaluation::RayCaster cast;
    if (scene_yaml.size() > 5 && scene_yaml.substr(scene_yaml.size() - 5) == ".json") {
      cast = evaluation::load_crosscheck_room(scene_yaml).caster();
    } else {
      const simulator::SimulationConfig cfg = simulator::load_simulation_config(scene_yaml, ov);
      auto planes = std::dynamic_pointer_cast<const simulator::PlanarScene>(cfg.scene);
      if (!planes) throw std::runtime_error(scene_yaml + ": track_quality needs a planes scene (got " + cfg.scene_type + ")");
      cast = [planes](const Eigen::Vector3d& o, const Eigen::Vector3d& d) { return planes->intersect(o, d); };
    }
    const auto cams = calib::load_kalibr_camchain(seq + "/calib.yaml");
    if (cams.empty()) throw std::runtime_error(seq + "/calib.yaml: no camera");
    const Trajectory gt = read_tum(seq + "/groundtruth.txt");
    const std::vector<FeatureObservations> frames = read_observations(obs_path);
    evaluation::TrackEvaluationOptions anchored, triangulated;
    triangulated.reference = evaluation::TrackReference::kTriangulated;
    anchored.keep_residuals = !residuals.empty();
    const auto a = evaluation::evaluate_tracks(frames, gt, cams.front(), cast, anchored);
    if (!residuals.empty()) {
      std::ofstream f(residuals);
      f << "# t[s] track_id age_frames ex_px ey_px  (anchored: observed - true projection)\n";
      char line[160];
      for (const auto& r : a.residuals) {
        std::snprintf(line, sizeof(line), "%.9f %lld %d %.4f %.4f\n", 1e-9 * static_cast<double>(r.t_ns),
                      static_cast<long long>(r.track_id), r.age_frames, r.error_px.x(), r.error_px.y());
        f << line;
      }
    }
    const auto t = evaluation::evaluate_tracks(frames, gt, cams.front(), cast, triangulated);
    std::printf("%s: %lld frames, %.1f tracks per frame, lifetime median %.0f frames (%.3f s), mean %.1f frames, "
                "lost while visible %lld of %lld ended (%.1f%%)\n",
                obs_path.c_str(), static_cast<long long>(a.frames), a.mean_tracks_per_frame, a.median_lifetime_frames,
                a.median_lifetime_s, a.mean_lifetime_frames, static_cast<long long>(a.lost_while_visible),
                static_cast<long long>(a.ended), 100 * a.lost_fraction);
    print("anchored (drift since the track's first observation)", a);
    print("triangulated (least-squares landmark from the true poses)", t);
    // Timing diagnostic: the anchored error against ground truth whose translation lags by tau
    // (events' translation is not motion-compensated, so an event frame shows the translational
    // part of the motion at its events' mean time rather than at its reference time).
    if (lag_scan) {
      std::printf("translation lag scan (anchored median / age-10 median px):");
      for (double tau_ms : {0.0, 5.0, 10.0, 15.0, 20.0}) {
        std::vector<StampedPose> lagged;
        for (const StampedPose& p : gt.poses()) {
          const auto q = gt.interpolate(p.t_ns - static_cast<int64_t>(tau_ms * 1e6));
          if (q) lagged.push_back({p.t_ns, calib::SE3(p.T_w_b.rotation, q->translation)});
        }
        const auto l = evaluation::evaluate_tracks(frames, Trajectory(lagged), cams.front(), cast, anchored);
        std::printf("  %g ms: %.3f / %.3f", tau_ms, l.median_px, l.by_age[9].median_px);
      }
      std::printf("\n");
    }
    if (!json.empty()) {
      std::ofstream f(json);
      f << "{\"anchored\": " << evaluation::track_evaluation_json(a)
        << ",\n \"triangulated\": " << evaluation::track_evaluation_json(t) << "}\n";
      if (!f) throw std::runtime_error(json + ": write failed");
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "track_quality: %s\n", e.what());
    return 1;
  }
  return 0;
}
