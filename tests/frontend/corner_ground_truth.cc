// Simulated corner ground truth: see corner_ground_truth.h.
#include "corner_ground_truth.h"

#include <cmath>
#include <cstdio>
#include <sstream>
#include <stdexcept>

#include "evio/simulator/scene.h"
#include "evio/simulator/texture.h"
#include "evio/simulator/trajectory.h"

namespace evio::test {
namespace {

// Texels per board square of the procedural texture (the box-filtered checkerboard puts cell
// edges exactly on texel boundaries, so node (i, j) is texel (i, j) * kCellTexels).
constexpr int kCellTexels = 64;

// Collects the simulator's event packets.
struct EventCollector final : simulator::SimulationSink {
  std::vector<Event>* out = nullptr;
  void on_events(const std::vector<Event>& events, const std::vector<uint16_t>*) override {
    out->insert(out->end(), events.begin(), events.end());
  }
};

}  // namespace

bool CornerSceneOptions::Validate(std::string* why) const {
  auto fail = [why](const char* msg) {
    if (why) *why = msg;
    return false;
  };
  if (width <= 0 || height <= 0) return fail("width and height must be > 0 px");
  if (!(focal_px > 0) || !std::isfinite(focal_px)) return fail("focal_px must be finite and > 0");
  if (squares_x < 1 || squares_y < 1) return fail("squares_x and squares_y must be >= 1");
  if (!(square_m > 0) || !std::isfinite(square_m)) return fail("square_m must be finite and > 0");
  if (!(distance_m > 0) || !std::isfinite(distance_m)) return fail("distance_m must be finite and > 0");
  if (!(dark_intensity > 0) || !(bright_intensity > dark_intensity) || !std::isfinite(bright_intensity))
    return fail("need 0 < dark_intensity < bright_intensity (finite)");
  if (!(background_intensity > 0) || !std::isfinite(background_intensity))
    return fail("background_intensity must be finite and > 0");
  if (!(duration_s > 0) || !std::isfinite(duration_s)) return fail("duration_s must be finite and > 0");
  if (!(motion_scale >= 0) || !std::isfinite(motion_scale)) return fail("motion_scale must be finite and >= 0");
  if (supersample < 1) return fail("supersample must be >= 1");
  if (!(max_flow_px_per_step > 0)) return fail("max_flow_px_per_step must be > 0");
  if (!(contrast_threshold > 0)) return fail("contrast_threshold must be > 0");
  if (!(threshold_mismatch_std >= 0)) return fail("threshold_mismatch_std must be >= 0");
  return true;
}

CornerGroundTruthSequence::CornerGroundTruthSequence(const CornerSceneOptions& options) : options_(options) {
  std::string why;
  if (!options_.Validate(&why)) throw std::invalid_argument("CornerSceneOptions: " + why);
  const CornerSceneOptions& o = options_;

  calib::CameraIntrinsics in;
  in.width = o.width;
  in.height = o.height;
  in.fx = in.fy = o.focal_px;
  in.cx = (o.width - 1) / 2.0;
  in.cy = (o.height - 1) / 2.0;
  in.model = calib::DistortionModel::kNone;
  camera_ = calib::PinholeCamera(in);

  // Board: a plane facing the camera at rest (camera z forward, x right, y down = world axes),
  // texture u along world +x, texture rows growing downwards (axis_v = world -y, "up").
  simulator::ProceduralTextureOptions t;
  t.kind = simulator::ProceduralKind::kCheckerboard;
  t.cell_px = kCellTexels;
  t.width = o.squares_x * kCellTexels;
  t.height = o.squares_y * kCellTexels;
  t.min_intensity = o.dark_intensity;
  t.max_intensity = o.bright_intensity;
  simulator::TexturedPlane board;
  board.center_w = Eigen::Vector3d(0, 0, o.distance_m);
  board.axis_u_w = Eigen::Vector3d::UnitX();
  board.axis_v_w = -Eigen::Vector3d::UnitY();
  board.width_m = o.squares_x * o.square_m;
  board.height_m = o.squares_y * o.square_m;
  board.texture = std::make_shared<simulator::Texture>(simulator::make_procedural_texture(t));
  auto scene = std::make_shared<simulator::PlanarScene>(std::vector<simulator::TexturedPlane>{board}, o.background_intensity);

  // Texel (u, v) of the plane is the point center + a axis_u + b axis_v with
  // a = u / texels_per_m - width / 2 and b = height / 2 - v / texels_per_m (simulator/scene.h).
  for (int j = 0; j <= o.squares_y; ++j)
    for (int i = 0; i <= o.squares_x; ++i) {
      const double a = i * o.square_m - 0.5 * board.width_m;
      const double b = 0.5 * board.height_m - j * o.square_m;
      corners_w_.push_back(board.center_w + a * board.axis_u_w + b * board.axis_v_w);
    }

  // Smooth 6-DoF motion: translation sinusoids (x, y in the image plane, z towards the board) and
  // tilt (about x), pan (about y) and in-plane rotation (about the optical axis z), with
  // different frequencies and phases so the image never stops moving as a whole.
  simulator::SinusoidTrajectoryOptions m;
  m.t_begin_ns = 0;
  m.duration_s = o.duration_s;
  const double k = o.motion_scale;
  m.amplitude_m = Eigen::Vector3d(0.075, 0.06, 0.15) * k;
  m.frequency_hz = Eigen::Vector3d(0.6, 0.8, 0.4);
  m.phase_rad = Eigen::Vector3d(0.0, 1.2, 2.0);
  m.angle_amplitude_rad = Eigen::Vector3d(0.075, 0.105, 0.375) * k;
  m.angle_frequency_hz = Eigen::Vector3d(0.9, 0.7, 0.5);
  m.angle_phase_rad = Eigen::Vector3d(0.5, 2.5, 0.0);
  auto trajectory = std::make_shared<simulator::SinusoidTrajectory>(m);

  simulator::SimulatorOptions so;
  so.camera = camera_;
  so.T_c_b = calib::SE3();  // body = camera
  so.supersample = o.supersample;
  so.threads = 1;
  so.stepping.max_flow_px = o.max_flow_px_per_step;
  so.stepping.max_log_change = 0;
  so.events.contrast_threshold_pos = o.contrast_threshold;
  so.events.contrast_threshold_neg = o.contrast_threshold;
  so.events.threshold_mismatch_std = o.threshold_mismatch_std;
  so.events.refractory_ns = 0;
  so.events.shot_noise_rate_hz = 0;
  so.events.leak_rate_hz = 0;
  so.events.hot_pixel_fraction = 0;
  so.events.timestamp_jitter_ns = 0;
  so.events.seed = o.seed;
  so.ground_truth_flow = false;
  simulator_ = std::make_unique<simulator::Simulator>(scene, trajectory, so);
  t_begin_ns_ = simulator_->t_begin_ns();
  t_end_ns_ = simulator_->t_end_ns();

  EventCollector sink;
  sink.out = &events_;
  stats_ = simulator_->run(&sink);
}

calib::SE3 CornerGroundTruthSequence::T_w_c(int64_t t_ns) const { return simulator_->camera_state(t_ns).T_w_c; }

bool CornerGroundTruthSequence::project_corner(int id, int64_t t_ns, Eigen::Vector2d* px) const {
  const calib::SE3 T_c_w = T_w_c(t_ns).inverse();
  return camera_.project(T_c_w * corners_w_.at(id), px);
}

void CornerGroundTruthSequence::true_corners_at(int64_t t_ns, double margin_px, std::vector<Eigen::Vector2d>* px,
                                                std::vector<int>* ids) const {
  px->clear();
  if (ids) ids->clear();
  const calib::SE3 T_c_w = T_w_c(t_ns).inverse();
  const double x_hi = camera_.width() - 1 + margin_px, y_hi = camera_.height() - 1 + margin_px;
  for (size_t i = 0; i < corners_w_.size(); ++i) {
    Eigen::Vector2d p;
    if (!camera_.project(T_c_w * corners_w_[i], &p)) continue;
    if (p.x() < -margin_px || p.y() < -margin_px || p.x() > x_hi || p.y() > y_hi) continue;
    px->push_back(p);
    if (ids) ids->push_back(static_cast<int>(i));
  }
}

std::vector<Eigen::Vector2d> CornerGroundTruthSequence::true_corners_at(int64_t t_ns, double margin_px) const {
  std::vector<Eigen::Vector2d> px;
  true_corners_at(t_ns, margin_px, &px);
  return px;
}

cv::Mat CornerGroundTruthSequence::render_intensity(int64_t t_ns) const {
  return simulator_->render(t_ns, false).intensity;
}

std::string CornerGroundTruthSequence::describe() const {
  const CornerSceneOptions& o = options_;
  char buf[512];
  std::snprintf(buf, sizeof(buf),
                "%dx%d px, f %.0f px; %dx%d board of %.2f m squares at %.2f m (%zu corner points); %.2f s, "
                "motion x%.2f; C %.2f, mismatch %.3f, seed %llu: %llu events, %llu steps, max image speed %.0f px/s",
                o.width, o.height, o.focal_px, o.squares_x, o.squares_y, o.square_m, o.distance_m, corners_w_.size(),
                o.duration_s, o.motion_scale, o.contrast_threshold, o.threshold_mismatch_std,
                static_cast<unsigned long long>(o.seed), static_cast<unsigned long long>(stats_.events),
                static_cast<unsigned long long>(stats_.steps), stats_.max_flow_pxps);
  return buf;
}

CornerScorer::CornerScorer(const CornerGroundTruthSequence& seq) : seq_(seq), near_(seq.events().size(), 0) {
  std::vector<Eigen::Vector2d> px;
  for (size_t i = 0; i < seq.events().size(); ++i) {
    const Event& e = seq.events()[i];
    seq.true_corners_at(e.t_ns, kCornerMatchRadiusPx, &px);
    const Eigen::Vector2d p(e.x, e.y);
    for (const Eigen::Vector2d& c : px)
      if ((c - p).squaredNorm() <= kCornerMatchRadiusPx * kCornerMatchRadiusPx) {
        near_[i] = 1;
        break;
      }
  }
}

CornerMetrics CornerScorer::evaluate(const std::function<bool(const Event&)>& is_corner) const {
  const CornerGroundTruthSequence& seq = seq_;
  const CornerSceneOptions& so = seq.options();
  const int num_corners = static_cast<int>(seq.corners_w().size());
  std::vector<bool> inner(num_corners);
  for (int c = 0; c < num_corners; ++c) {
    const int gi = c % (so.squares_x + 1), gj = c / (so.squares_x + 1);
    inner[c] = gi > 0 && gi < so.squares_x && gj > 0 && gj < so.squares_y;
  }
  evaluation::CornerScoringOptions o;
  o.match_radius_px = kCornerMatchRadiusPx;
  o.bin_ns = kCornerBinNs;
  o.min_speed_pxps = kMinCornerSpeedPxps;
  o.border_px = kCornerDetectorBorderPx;
  evaluation::CornerEventScorer scorer(
      seq.width(), seq.height(), num_corners, inner,
      [&seq, num_corners](int64_t t_ns, std::vector<Eigen::Vector2d>* px) {
        px->assign(num_corners, Eigen::Vector2d::Constant(NAN));
        const calib::SE3 T_c_w = seq.T_w_c(t_ns).inverse();
        for (int c = 0; c < num_corners; ++c) {
          Eigen::Vector2d p;
          if (seq.camera().project(T_c_w * seq.corners_w()[c], &p)) (*px)[c] = p;
        }
      },
      seq.t_begin_ns(), seq.t_end_ns(), o);
  for (size_t i = 0; i < seq.events().size(); ++i) {
    const Event& e = seq.events()[i];
    scorer.add(e, is_corner(e), near_[i] != 0);
  }
  return scorer.finish();
}

CornerMetrics CornerScorer::evaluate_efast(const frontend::EfastOptions& options) const {
  frontend::EfastDetector detector(seq_.width(), seq_.height(), options);
  return evaluate([&detector](const Event& e) { return detector.process(e); });
}

const CornerGroundTruthSequence& default_corner_sequence() {
  static const std::unique_ptr<CornerGroundTruthSequence> seq = [] {
    auto s = std::make_unique<CornerGroundTruthSequence>(CornerSceneOptions{});
    std::printf("scene: %s\n", s->describe().c_str());
    return s;
  }();
  return *seq;
}

const CornerScorer& default_corner_scorer() {
  static const CornerScorer s(default_corner_sequence());
  return s;
}

void print_corner_metrics(const char* name, const CornerMetrics& m) {
  std::printf(
      "%s: %lld events, %lld corner events (reduction %.1fx); precision %.4f (TP %lld) vs chance %.4f "
      "(%lld events within %.0f px of a true corner); event recall %.4f (%lld flagged); (corner, %lld ms bin) "
      "recall %.4f (%lld of %lld pairs), inner X-junctions only %.4f (%lld of %lld)\n",
      name, (long long)m.events, (long long)m.corner_events, m.reduction(), m.precision(),
      (long long)m.true_positives, m.chance(), (long long)m.near_events, kCornerMatchRadiusPx, m.event_recall(),
      (long long)m.near_events_flagged, (long long)(kCornerBinNs / 1'000'000), m.pair_recall(), (long long)m.pairs_hit,
      (long long)m.pairs, m.inner_pair_recall(), (long long)m.inner_pairs_hit, (long long)m.inner_pairs);
}

}  // namespace evio::test
