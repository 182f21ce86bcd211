// Simulated ground truth for corner-event detectors: a textured plane carrying a checkerboard of
// a few large squares, seen by a DAVIS240C-like pinhole camera (no distortion) on a smooth 6-DoF
// sinusoid trajectory, simulated with the evio event simulator (ESIM model, fixed seed). Every
// grid node of the board is a 3D corner point with a known position, so the true image corners at
// any time are the projections of those points through the camera pose T_w_c(t).
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "evio/calib/camera.h"
#include "evio/calib/geometry.h"
#include "evio/evaluation/corner_evaluation.h"
#include "evio/frontend/efast.h"
#include "evio/sensors/measurements.h"
#include "evio/simulator/simulator.h"

namespace evio::test {

// The scene and the simulation. Defaults: 240 x 180 px, fx = fy = 200 px, a 5 x 4 board of
// 0.2 m squares (intensities 0.15 / 0.9 on a 0.4 background) 1 m in front of the camera, 1.5 s
// of motion with image speeds of about 50-250 px/s. Events are noise-free apart from a fixed,
// seeded per-pixel threshold mismatch (no shot noise, leak, hot pixels, jitter or refractory).
struct CornerSceneOptions {
  int width = 240;                        // px, > 0
  int height = 180;                       // px, > 0
  double focal_px = 200.0;                // fx = fy, px, > 0; principal point at the image centre
  int squares_x = 5;                      // board squares across, >= 1
  int squares_y = 4;                      // board squares down, >= 1
  double square_m = 0.2;                  // square side, m, > 0
  double distance_m = 1.0;                // board distance along the camera's optical axis at rest, m, > 0
  double dark_intensity = 0.15;           // linear intensity of the dark squares, > 0
  double bright_intensity = 0.9;          // linear intensity of the bright squares, > dark
  double background_intensity = 0.4;      // around the board, > 0 (differs from both square values,
                                          // so the board outline and its corners give events too)
  double duration_s = 1.5;                // simulated span, s, > 0
  double motion_scale = 1.0;              // multiplies every motion amplitude (0 = static camera), >= 0
  int supersample = 3;                    // sub-pixel rays per axis (antialiased edges), >= 1
  double max_flow_px_per_step = 0.5;      // simulator step bound, px
  double contrast_threshold = 0.2;        // C+ = C-, log-intensity units, > 0
  double threshold_mismatch_std = 0.03;   // per-pixel threshold sigma, log units, >= 0
  uint64_t seed = 11;                     // event simulator seed (threshold mismatch)
  bool Validate(std::string* why) const;
};

// A simulated sequence with its true corners. Event and pose times share one clock (camera =
// body, no time shift), int64 ns.
class CornerGroundTruthSequence {
 public:
  // Builds the scene and runs the simulator. Throws std::invalid_argument on invalid options.
  explicit CornerGroundTruthSequence(const CornerSceneOptions& options = {});

  const CornerSceneOptions& options() const { return options_; }
  const calib::PinholeCamera& camera() const { return camera_; }
  int width() const { return camera_.width(); }
  int height() const { return camera_.height(); }
  // Simulated events, sorted by time.
  const std::vector<Event>& events() const { return events_; }
  const simulator::SimulationStats& stats() const { return stats_; }
  int64_t t_begin_ns() const { return t_begin_ns_; }
  int64_t t_end_ns() const { return t_end_ns_; }

  // The 3D corner points in the world frame: all (squares_x + 1) x (squares_y + 1) grid nodes of
  // the board, row by row from the top-left: the inner nodes are X-junctions, the nodes on the
  // board's outline are T-junctions (cell edge meets the outline) and its four corners are
  // L-corners (the background differs from both square intensities).
  const std::vector<Eigen::Vector3d>& corners_w() const { return corners_w_; }

  // Camera pose at t_ns (exact, from the continuous trajectory), t in [t_begin_ns, t_end_ns].
  calib::SE3 T_w_c(int64_t t_ns) const;

  // Projections of the corner points visible at t_ns: in front of the camera and with pixel
  // coordinates in [-margin_px, width - 1 + margin_px] x [-margin_px, height - 1 + margin_px]
  // (a negative margin keeps only corners at least -margin_px inside the image). `ids` (if given)
  // receives each projection's index into corners_w(). Pixel (0, 0) is the top-left pixel centre,
  // as in evio::calib and in event coordinates.
  void true_corners_at(int64_t t_ns, double margin_px, std::vector<Eigen::Vector2d>* px,
                       std::vector<int>* ids = nullptr) const;
  std::vector<Eigen::Vector2d> true_corners_at(int64_t t_ns, double margin_px = 0.0) const;

  // Projection of corner `id` at t_ns; false when it is behind the camera.
  bool project_corner(int id, int64_t t_ns, Eigen::Vector2d* px) const;

  // Clean linear-intensity render (CV_32F, width x height) at t_ns, for checking the ground truth
  // against the image.
  cv::Mat render_intensity(int64_t t_ns) const;

  // One line describing scene, motion and simulation (for test logs).
  std::string describe() const;

 private:
  CornerSceneOptions options_;
  calib::PinholeCamera camera_;
  std::vector<Eigen::Vector3d> corners_w_;
  std::unique_ptr<simulator::Simulator> simulator_;
  std::vector<Event> events_;
  simulator::SimulationStats stats_;
  int64_t t_begin_ns_ = 0, t_end_ns_ = 0;
};

// Scoring of per-event corner decisions against a sequence's true corners. A corner event is a
// true positive when a projected true corner lies within kCornerMatchRadiusPx of its pixel at its
// time. Precision; chance level (share of all events within that radius of a true corner: the
// precision of flagging events at random); event recall (share of those near events flagged);
// (corner, 50 ms bin) recall (share of the bins in which a visible, moving corner, at least
// kCornerDetectorBorderPx inside the image, gets a corner event within the radius); reduction
// (events per corner event).
constexpr double kCornerMatchRadiusPx = 2.0;
constexpr int64_t kCornerBinNs = 50'000'000;       // recall bins, ns
constexpr double kMinCornerSpeedPxps = 20;         // a corner "moves" in a bin at this mean image speed, px/s
constexpr int kCornerDetectorBorderPx = 4;         // eFAST never fires within 4 px of the border

// The scoring itself lives in the library (evaluation/corner_evaluation.h), with these constants
// as its defaults.
using CornerMetrics = evaluation::CornerMetrics;

class CornerScorer {
 public:
  // Flags the events near a true corner (once); seq must outlive the scorer.
  explicit CornerScorer(const CornerGroundTruthSequence& seq);
  // Scores any per-event corner decision (called once per event, in time order).
  CornerMetrics evaluate(const std::function<bool(const Event&)>& is_corner) const;
  // eFAST with these options over the sequence's events.
  CornerMetrics evaluate_efast(const frontend::EfastOptions& options) const;

 private:
  const CornerGroundTruthSequence& seq_;
  std::vector<uint8_t> near_;  // per event: a true corner within the radius
};

// The default sequence (CornerSceneOptions{}), simulated once per process (described on stdout
// then), and its scorer.
const CornerGroundTruthSequence& default_corner_sequence();
const CornerScorer& default_corner_scorer();

// One line of figures on stdout.
void print_corner_metrics(const char* name, const CornerMetrics& m);

}  // namespace evio::test
