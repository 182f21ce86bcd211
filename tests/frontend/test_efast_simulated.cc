// eFAST against simulated ground truth: a checkerboard plane seen by a moving 240x180 camera
// (corner_ground_truth.h), every board grid node a known 3D corner. A corner event is a true
// positive when a projected true corner lies within 2 px of its pixel at its time. Reported, for
// the plain and the filtered SAE: precision, the chance level (share of all events within 2 px of
// a true corner: the precision of flagging events at random), event recall (share of the events
// within 2 px of a true corner that are flagged), (corner, 50 ms bin) recall (share of the bins in
// which a visible, moving corner gets at least one corner event within 2 px) and the event
// reduction rate (events per corner event). The ground truth itself is checked against renders.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <memory>
#include <vector>

#include <gtest/gtest.h>

#include "corner_ground_truth.h"
#include "evio/frontend/efast.h"

namespace evio::test {
namespace {

const CornerGroundTruthSequence& sequence() { return default_corner_sequence(); }

CornerMetrics evaluate(const std::function<bool(const Event&)>& is_corner) {
  return default_corner_scorer().evaluate(is_corner);
}

CornerMetrics evaluate_efast(const frontend::EfastOptions& options) { return default_corner_scorer().evaluate_efast(options); }

// Bilinear sample of a CV_32F image at pixel coordinates (pixel centres at integers).
double bilinear(const cv::Mat& img, const Eigen::Vector2d& p) {
  const int x0 = static_cast<int>(std::floor(p.x())), y0 = static_cast<int>(std::floor(p.y()));
  const double fx = p.x() - x0, fy = p.y() - y0;
  auto at = [&](int x, int y) {
    return static_cast<double>(img.at<float>(std::clamp(y, 0, img.rows - 1), std::clamp(x, 0, img.cols - 1)));
  };
  return (1 - fy) * ((1 - fx) * at(x0, y0) + fx * at(x0 + 1, y0)) + fy * ((1 - fx) * at(x0, y0 + 1) + fx * at(x0 + 1, y0 + 1));
}

// ------------------------------------------------------------------------------------------
TEST(CornerGroundTruth, SceneMovesAtTheIntendedImageSpeeds) {
  const CornerGroundTruthSequence& seq = sequence();
  EXPECT_EQ(seq.width(), 240);
  EXPECT_EQ(seq.height(), 180);
  EXPECT_EQ(seq.corners_w().size(), 30u);
  EXPECT_GT(seq.events().size(), 100'000u);
  EXPECT_TRUE(std::is_sorted(seq.events().begin(), seq.events().end(),
                             [](const Event& a, const Event& b) { return a.t_ns < b.t_ns; }));
  // Image speeds of the corners (finite differences over 10 ms): about 50-300 px/s.
  double sum = 0, max_speed = 0;
  int n = 0;
  for (int64_t t = seq.t_begin_ns(); t + 10'000'000 <= seq.t_end_ns(); t += 10'000'000)
    for (int c = 0; c < static_cast<int>(seq.corners_w().size()); ++c) {
      Eigen::Vector2d a, b;
      ASSERT_TRUE(seq.project_corner(c, t, &a));
      ASSERT_TRUE(seq.project_corner(c, t + 10'000'000, &b));
      const double v = (b - a).norm() / 0.01;
      sum += v;
      max_speed = std::max(max_speed, v);
      ++n;
    }
  std::printf("corner image speed: mean %.1f px/s, max %.1f px/s; simulator max flow %.1f px/s\n", sum / n,
              max_speed, seq.stats().max_flow_pxps);
  EXPECT_GT(sum / n, 50.0);
  EXPECT_LT(max_speed, 400.0);
  // Most corners stay in view: mean number of visible corners over the same time grid.
  double visible = 0;
  int samples = 0;
  for (int64_t t = seq.t_begin_ns(); t <= seq.t_end_ns(); t += 10'000'000, ++samples)
    visible += static_cast<double>(seq.true_corners_at(t).size());
  std::printf("visible corners: %.1f of %zu on average\n", visible / samples, seq.corners_w().size());
  EXPECT_GT(visible / samples, 15.0);
}

// The projected corners sit where the rendered image has its junctions: 15 mm (about 3 px per
// axis) from each visible corner into each of its four quadrants, the render shows the expected
// square (dark or bright) or the background, so a corner misplaced by ~3 px would fail.
TEST(CornerGroundTruth, ProjectedCornersMatchTheRenderedJunctions) {
  const CornerGroundTruthSequence& seq = sequence();
  const CornerSceneOptions& o = seq.options();
  const Eigen::Vector3d u = Eigen::Vector3d::UnitX(), down = Eigen::Vector3d::UnitY();  // board axes (world)
  const double offset_m = 0.015;  // about 3 px per axis at 1 m and f = 200 px
  int checked = 0, wrong = 0;
  double worst = 0;
  for (int64_t t : {int64_t(100'000'000), int64_t(500'000'000), int64_t(900'000'000), int64_t(1'300'000'000)}) {
    const cv::Mat img = seq.render_intensity(t);
    const calib::SE3 T_c_w = seq.T_w_c(t).inverse();
    for (int c = 0; c < static_cast<int>(seq.corners_w().size()); ++c) {
      const int gi = c % (o.squares_x + 1), gj = c / (o.squares_x + 1);
      for (int di : {-1, 1})
        for (int dj : {-1, 1}) {
          const Eigen::Vector3d p_w = seq.corners_w()[c] + offset_m * (di * u + dj * down);
          Eigen::Vector2d px;
          if (!seq.camera().project(T_c_w * p_w, &px) || !seq.camera().in_image(px, 1.0)) continue;
          const int ci = gi + (di < 0 ? -1 : 0), cj = gj + (dj < 0 ? -1 : 0);  // square of the sample
          double expected = o.background_intensity;
          if (ci >= 0 && cj >= 0 && ci < o.squares_x && cj < o.squares_y)
            expected = (ci + cj) % 2 == 0 ? o.dark_intensity : o.bright_intensity;  // square (0, 0) is dark
          const double err = std::abs(bilinear(img, px) - expected);
          worst = std::max(worst, err);
          ++checked;
          wrong += err > 0.03;
        }
    }
  }
  std::printf("junction quadrants checked: %d, wrong: %d, worst |I - expected| %.4f\n", checked, wrong, worst);
  EXPECT_GT(checked, 300);
  EXPECT_EQ(wrong, 0);
}

TEST(EfastSimulated, PrecisionAndRecallAgainstProjectedCorners) {
  const CornerMetrics plain = evaluate_efast(frontend::EfastOptions{});
  frontend::EfastOptions fo;
  fo.filter_sae = true;
  const CornerMetrics filtered = evaluate_efast(fo);
  print_corner_metrics("eFAST, plain SAE   ", plain);
  print_corner_metrics("eFAST, filtered SAE", filtered);

  for (const CornerMetrics* m : {&plain, &filtered}) {
    ASSERT_GT(m->corner_events, 1000);
    EXPECT_LT(m->chance(), 0.12);  // measured 0.084: corners are a small part of the event stream
    // Far above chance (flagging events at random gives the chance level; measured ratio >= 8).
    EXPECT_GT(m->precision(), 5.0 * m->chance());
  }
  // Floors: the figures measured at the default seed 11 (and seeds 12-15: within 0.01) minus a
  // margin. Seed 11: plain 0.7635 / 0.3900 / 0.9054 / 23.3x, filtered 0.6754 / 0.0932 / 0.9040 / 86.4x
  // (precision / event recall / (corner, bin) recall / reduction).
  EXPECT_GT(plain.precision(), 0.70);
  EXPECT_GT(plain.event_recall(), 0.35);
  EXPECT_GT(plain.pair_recall(), 0.85);
  EXPECT_GT(filtered.precision(), 0.62);
  EXPECT_GT(filtered.event_recall(), 0.08);
  EXPECT_GT(filtered.pair_recall(), 0.84);
  EXPECT_GT(plain.reduction(), 15.0);
  EXPECT_LT(plain.reduction(), 35.0);
  // The filtered SAE drops most repeated events of a pixel: several times fewer corner events,
  // at nearly the same per-corner recall.
  EXPECT_GT(filtered.reduction(), 2.5 * plain.reduction());
  EXPECT_GT(filtered.pair_recall(), plain.pair_recall() - 0.05);
}

// Control for the scoring: flagging every k-th event (as many as eFAST flags) scores at the chance
// level, far below eFAST, so the precision above reflects where eFAST fires, not the matching rule.
// Its (corner, 50 ms bin) recall is high (measured 0.958, above eFAST's 0.905): at ~800 k events/s a
// 50 ms bin puts dozens of strided picks on the edges through every moving corner, so that recall
// only means something next to the precision; it is printed, not asserted, here.
TEST(EfastSimulated, UninformedSelectionScoresAtChance) {
  const CornerMetrics efast = evaluate_efast(frontend::EfastOptions{});
  const int64_t stride = std::max<int64_t>(1, efast.events / efast.corner_events);
  int64_t n = 0;
  const CornerMetrics strided = evaluate([&n, stride](const Event&) { return n++ % stride == 0; });
  print_corner_metrics("every k-th event    ", strided);
  EXPECT_NEAR(strided.precision(), strided.chance(), 0.02);
  EXPECT_NEAR(strided.event_recall(), 1.0 / stride, 0.02);
  EXPECT_LT(strided.precision(), 0.3 * efast.precision());
}

}  // namespace
}  // namespace evio::test
