// FeatureTracker and ransac_inliers: RANSAC on synthetic two-view geometry with outliers (both
// models, a wrong rotation prior, degenerate input), KLT tracking on a textured image moved by a
// known rigid image motion (accuracy, forward-backward check on a repainted patch, bucketing,
// re-detection), determinism and options validation.
#include "evio/frontend/feature_tracker.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

namespace evio::frontend {
namespace {

// ---------------------------------------------------------------------------------------------
// RANSAC on synthetic two-view geometry.

constexpr double kFocal = 200.0;  // px, for converting angles to pixels in this test

struct TwoView {
  std::vector<Eigen::Vector3d> prev, cur;
  std::vector<bool> is_inlier;
  Eigen::Matrix3d R_cur_prev;
};

Eigen::Vector3d noisy_bearing(const Eigen::Vector3d& p, double sigma_px, std::mt19937_64& rng) {
  std::normal_distribution<double> n(0.0, sigma_px / kFocal);
  Eigen::Vector3d b = p / p.z();
  b.x() += n(rng);
  b.y() += n(rng);
  return b.normalized();
}

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

Eigen::Vector3d random_bearing(std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-0.6, 0.6);  // about +-31 deg
  return Eigen::Vector3d(u(rng), u(rng), 1.0).normalized();
}

// Points 2..10 m in front of the previous camera inside its field of view; the current camera is
// p_cur = R p_prev + t with a rotation of `rot_deg` about a fixed axis and |t| = 0.3 m.
TwoView make_two_view(uint64_t seed, int n, double outlier_fraction, double noise_px,
                      double rot_deg) {
  std::mt19937_64 rng(seed);
  TwoView tv;
  tv.R_cur_prev =
      Eigen::AngleAxisd(rot_deg * M_PI / 180.0, Eigen::Vector3d(0.3, -1.0, 0.2).normalized())
          .toRotationMatrix();
  const Eigen::Vector3d t(0.25, -0.1, 0.13);
  std::uniform_real_distribution<double> depth(2.0, 10.0);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  while (static_cast<int>(tv.prev.size()) < n) {
    const Eigen::Vector3d ray = random_bearing(rng);
    const Eigen::Vector3d p_prev = ray / ray.z() * depth(rng);
    const Eigen::Vector3d p_cur = tv.R_cur_prev * p_prev + t;
    if (p_cur.z() < 0.5 || std::abs(p_cur.x() / p_cur.z()) > 0.7 ||
        std::abs(p_cur.y() / p_cur.z()) > 0.7)
      continue;
    tv.prev.push_back(noisy_bearing(p_prev, noise_px, rng));
    if (u01(rng) < outlier_fraction) {
      // A gross outlier: a random bearing at least 4 px (at f = 200 px) off the epipolar line of
      // the true geometry (one closer to it is indistinguishable from an inlier by any two-view test).
      const Eigen::Matrix3d E = skew(t) * tv.R_cur_prev;
      Eigen::Vector3d b;
      for (;;) {
        b = random_bearing(rng);
        const Eigen::Vector3d l = E * tv.prev.back();
        const double d_px = std::abs(l.dot(b / b.z())) / l.head<2>().norm() * kFocal;
        if (d_px > 4.0) break;
      }
      tv.cur.push_back(b);
      tv.is_inlier.push_back(false);
    } else {
      tv.cur.push_back(noisy_bearing(p_cur, noise_px, rng));
      tv.is_inlier.push_back(true);
    }
  }
  return tv;
}

struct Score {
  double recall = 0, rejection = 0;
};

Score score(const TwoView& tv, const std::vector<bool>& inl) {
  int n_in = 0, n_out = 0, kept_in = 0, rejected_out = 0;
  for (size_t i = 0; i < inl.size(); ++i) {
    if (tv.is_inlier[i]) {
      ++n_in;
      kept_in += inl[i] ? 1 : 0;
    } else {
      ++n_out;
      rejected_out += inl[i] ? 0 : 1;
    }
  }
  return {static_cast<double>(kept_in) / n_in, static_cast<double>(rejected_out) / n_out};
}

// Runs one model over several seeded scenes and returns the worst recall and rejection.
Score worst_over_seeds(RansacModel model, double outliers, double prior_error_deg,
                       const char* label) {
  Score worst{1.0, 1.0};
  const double threshold_rad = std::atan(1.5 / kFocal);
  for (uint64_t s = 1; s <= 10; ++s) {
    const TwoView tv = make_two_view(s, 200, outliers, 0.3, 4.0);
    Eigen::Matrix3d R = tv.R_cur_prev;
    if (prior_error_deg != 0) {
      R = Eigen::AngleAxisd(prior_error_deg * M_PI / 180.0, Eigen::Vector3d(1, 1, 0).normalized())
              .toRotationMatrix() *
          R;
    }
    const std::vector<bool> inl = ransac_inliers(tv.prev, tv.cur, model, &R, threshold_rad, 200, s);
    const Score sc = score(tv, inl);
    worst.recall = std::min(worst.recall, sc.recall);
    worst.rejection = std::min(worst.rejection, sc.rejection);
  }
  std::printf("[ransac] %-40s worst over 10 scenes: inlier recall %.3f, outlier rejection %.3f\n",
              label, worst.recall, worst.rejection);
  return worst;
}

TEST(RansacInliers, TwoPointWithTrueRotation) {
  for (double outliers : {0.2, 0.3}) {
    const Score s = worst_over_seeds(RansacModel::kTwoPoint, outliers, 0.0,
                                     outliers < 0.25 ? "2-point, 20% outliers" : "2-point, 30% outliers");
    EXPECT_GT(s.recall, 0.95);
    EXPECT_GT(s.rejection, 0.95);
  }
}

TEST(RansacInliers, TwoPointKeepsCorrectTracksOverAShortBaseline) {
  // Consecutive 100 Hz event frames: a few mm of translation in front of a scene 2-10 m away, so
  // the rotation-compensated displacement is at the noise level and the translation direction is
  // undetermined. Every correct correspondence must stay (a triangulation-based test put such
  // points at random depths and rejected about half of them), and most gross outliers must still
  // go (a displacement that happens to lie along the chosen epipolar line fits any two-view test).
  for (uint64_t seed = 1; seed <= 10; ++seed) {
    std::mt19937_64 rng(seed);
    const Eigen::Matrix3d R = Eigen::AngleAxisd(0.8 * M_PI / 180.0, Eigen::Vector3d(0.2, 1.0, -0.3).normalized()).toRotationMatrix();
    const Eigen::Vector3d t(0.002, -0.001, 0.001);
    std::uniform_real_distribution<double> depth(2.0, 10.0);
    std::vector<Eigen::Vector3d> prev, cur;
    std::vector<bool> truth;
    for (int i = 0; i < 150; ++i) {
      const Eigen::Vector3d ray = random_bearing(rng);
      const Eigen::Vector3d p = ray / ray.z() * depth(rng);
      prev.push_back(noisy_bearing(p, 0.2, rng));
      if (i % 10 == 0) {  // 10% gross outliers: 5 px off in a random direction
        Eigen::Vector3d q = (R * p + t);
        q = q / q.z();
        const double a = std::uniform_real_distribution<double>(0, 2 * M_PI)(rng);
        q.x() += 5.0 / kFocal * std::cos(a);
        q.y() += 5.0 / kFocal * std::sin(a);
        cur.push_back(q.normalized());
        truth.push_back(false);
      } else {
        cur.push_back(noisy_bearing(R * p + t, 0.2, rng));
        truth.push_back(true);
      }
    }
    const std::vector<bool> inl = ransac_inliers(prev, cur, RansacModel::kTwoPoint, &R, std::atan(1.0 / kFocal), 200, seed);
    int kept = 0, in = 0, rejected = 0, out = 0;
    for (size_t i = 0; i < inl.size(); ++i) {
      (truth[i] ? in : out) += 1;
      if (truth[i] && inl[i]) ++kept;
      if (!truth[i] && !inl[i]) ++rejected;
    }
    EXPECT_GE(kept, in - 1) << "seed " << seed;  // at most one correct track lost (a 3.5-sigma noise draw)
    EXPECT_GE(rejected, out - 3) << "seed " << seed;
  }
}

TEST(RansacInliers, FivePointNister) {
  for (double outliers : {0.2, 0.3}) {
    const Score s = worst_over_seeds(RansacModel::kFivePoint, outliers, 0.0,
                                     outliers < 0.25 ? "5-point, 20% outliers" : "5-point, 30% outliers");
    EXPECT_GT(s.recall, 0.95);
    EXPECT_GT(s.rejection, 0.95);
  }
}

TEST(RansacInliers, TwoPointWithSlightlyWrongRotationPrior) {
  // 0.1 deg of prior error is 0.35 px at f = 200 px.
  const Score s = worst_over_seeds(RansacModel::kTwoPoint, 0.25, 0.1, "2-point, 25% outl., prior off 0.1 deg");
  EXPECT_GT(s.recall, 0.95);
  EXPECT_GT(s.rejection, 0.95);
}

TEST(RansacInliers, IdentityPriorUnderRotationLosesInliers) {
  // The 2-point model relies on the rotation: with a 4 deg rotation and no prior (identity) the
  // true correspondences no longer fit a translation, which shows the prior is actually used.
  const TwoView tv = make_two_view(3, 200, 0.25, 0.3, 4.0);
  const std::vector<bool> inl = ransac_inliers(tv.prev, tv.cur, RansacModel::kTwoPoint, nullptr,
                                               std::atan(1.5 / kFocal), 200, 3);
  const Score s = score(tv, inl);
  std::printf("[ransac] 2-point with identity prior under 4 deg rotation: recall %.3f\n", s.recall);
  EXPECT_LT(s.recall, 0.8);
}

TEST(RansacInliers, NoneKeepsAll) {
  const TwoView tv = make_two_view(5, 50, 0.3, 0.3, 4.0);
  const std::vector<bool> inl =
      ransac_inliers(tv.prev, tv.cur, RansacModel::kNone, nullptr, 0.01, 100, 1);
  ASSERT_EQ(inl.size(), 50u);
  for (bool b : inl) EXPECT_TRUE(b);
}

TEST(RansacInliers, DegenerateInputKeepsAllWithoutCrashing) {
  const TwoView tv = make_two_view(7, 12, 0.0, 0.3, 4.0);
  const Eigen::Matrix3d R = tv.R_cur_prev;
  for (RansacModel m : {RansacModel::kTwoPoint, RansacModel::kFivePoint}) {
    const int min_n = ransac_min_correspondences(m);
    EXPECT_TRUE(ransac_inliers({}, {}, m, &R, 0.01, 100, 1).empty());
    for (int n = 1; n < min_n; ++n) {
      std::vector<Eigen::Vector3d> a(tv.prev.begin(), tv.prev.begin() + n);
      std::vector<Eigen::Vector3d> b(tv.cur.begin(), tv.cur.begin() + n);
      // Make them outliers: the rule is "too few to verify -> all kept", regardless of content.
      for (auto& v : b) v = Eigen::Vector3d(v.y(), -v.x(), v.z());
      const std::vector<bool> inl = ransac_inliers(a, b, m, &R, 0.01, 100, 1);
      ASSERT_EQ(inl.size(), static_cast<size_t>(n));
      for (bool k : inl) EXPECT_TRUE(k) << ransac_model_name(m) << " n=" << n;
    }
  }
  // All-identical bearings (no parallax, every sample degenerate) must not crash.
  std::vector<Eigen::Vector3d> same(20, Eigen::Vector3d(0.1, 0.2, 1.0).normalized());
  for (RansacModel m : {RansacModel::kTwoPoint, RansacModel::kFivePoint}) {
    const std::vector<bool> inl = ransac_inliers(same, same, m, nullptr, 0.01, 50, 1);
    EXPECT_EQ(inl.size(), same.size());
  }
  EXPECT_THROW(ransac_inliers(tv.prev, {}, RansacModel::kTwoPoint, &R, 0.01, 100, 1),
               std::invalid_argument);
  EXPECT_THROW(ransac_inliers(tv.prev, tv.cur, RansacModel::kTwoPoint, &R, 0.0, 100, 1),
               std::invalid_argument);
}

TEST(RansacInliers, SeededAndDeterministic) {
  const TwoView tv = make_two_view(11, 150, 0.3, 0.3, 4.0);
  for (RansacModel m : {RansacModel::kTwoPoint, RansacModel::kFivePoint}) {
    const auto a = ransac_inliers(tv.prev, tv.cur, m, &tv.R_cur_prev, std::atan(1.5 / kFocal), 200, 42);
    const auto b = ransac_inliers(tv.prev, tv.cur, m, &tv.R_cur_prev, std::atan(1.5 / kFocal), 200, 42);
    EXPECT_EQ(a, b);
  }
}

// ---------------------------------------------------------------------------------------------
// Tracking on synthetic images.

constexpr int kW = 240, kH = 180;
constexpr int kMargin = 80;  // the texture extends this far beyond frame 0 on every side (px)

calib::CameraIntrinsics camera() {
  calib::CameraIntrinsics K;
  K.width = kW;
  K.height = kH;
  K.fx = K.fy = kFocal;
  K.cx = 119.5;
  K.cy = 89.5;
  return K;
}

// Grey background with random rectangles and discs of random grey levels, slightly blurred.
cv::Mat make_texture(uint64_t seed, int w, int h) {
  cv::RNG rng(seed);
  cv::Mat img(h, w, CV_8UC1, cv::Scalar(128));
  const int shapes = w * h / 150;
  for (int i = 0; i < shapes; ++i) {
    const cv::Point c(rng.uniform(0, w), rng.uniform(0, h));
    const int g = rng.uniform(0, 256);
    if (rng.uniform(0, 2) == 0) {
      const cv::Size s(rng.uniform(4, 16), rng.uniform(4, 16));
      cv::rectangle(img, cv::Rect(c, s), cv::Scalar(g), -1);
    } else {
      cv::circle(img, c, rng.uniform(2, 8), cv::Scalar(g), -1, cv::LINE_AA);
    }
  }
  cv::GaussianBlur(img, img, cv::Size(0, 0), 1.0);
  return img;
}

// Image motion of one frame step: rotation by `deg` about the principal point, then a shift d
// (px). With fx = fy this is exactly the rigid motion p_cur = Rz(deg) p_prev + (d / f, 0) of a
// fronto-parallel plane at depth 1, so the 2-point model with the Rz prior fits it.
struct Motion {
  double deg = 0, dx = 0, dy = 0;
  Eigen::Matrix3d A() const {  // homogeneous pixel map u_cur = A u_prev
    const double a = deg * M_PI / 180.0, c = std::cos(a), s = std::sin(a);
    const Eigen::Vector2d pp(119.5, 89.5);
    Eigen::Matrix2d R2;
    R2 << c, -s, s, c;
    Eigen::Matrix3d A = Eigen::Matrix3d::Identity();
    A.topLeftCorner<2, 2>() = R2;
    A.topRightCorner<2, 1>() = pp - R2 * pp + Eigen::Vector2d(dx, dy);
    return A;
  }
  Eigen::Matrix3d R_cur_prev() const {
    return Eigen::AngleAxisd(deg * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  }
};

// Frame k shows frame-0 content moved by A_k (frame(A_k p) = texture(p + margin)).
cv::Mat render(const cv::Mat& texture, const Eigen::Matrix3d& A_k) {
  Eigen::Matrix3d T = Eigen::Matrix3d::Identity();
  T(0, 2) = -kMargin;
  T(1, 2) = -kMargin;
  const Eigen::Matrix3d M = A_k * T;  // texture pixel -> frame pixel
  cv::Mat m(2, 3, CV_64F);
  for (int r = 0; r < 2; ++r)
    for (int c = 0; c < 3; ++c) m.at<double>(r, c) = M(r, c);
  cv::Mat out;
  cv::warpAffine(texture, out, m, cv::Size(kW, kH), cv::INTER_LINEAR, cv::BORDER_CONSTANT,
                 cv::Scalar(128));
  return out;
}

cv::Point2f apply(const Eigen::Matrix3d& A, const cv::Point2f& p) {
  const Eigen::Vector3d q = A * Eigen::Vector3d(p.x, p.y, 1.0);
  return cv::Point2f(static_cast<float>(q.x() / q.z()), static_cast<float>(q.y() / q.z()));
}

double dist(const cv::Point2f& a, const cv::Point2f& b) { return std::hypot(a.x - b.x, a.y - b.y); }

TEST(FeatureTracker, TracksKnownMotionAccurately) {
  const cv::Mat tex = make_texture(7, kW + 2 * kMargin, kH + 2 * kMargin);
  FeatureTrackerOptions opt;
  FeatureTracker tracker(camera(), opt);
  const Motion step{0.5, 1.7, -0.9};
  const Eigen::Matrix3d A1 = step.A();
  const Eigen::Matrix3d R1 = step.R_cur_prev();
  // id -> (frame-k pose A_k at birth, position at birth)
  std::map<int64_t, std::pair<Eigen::Matrix3d, cv::Point2f>> birth;
  Eigen::Matrix3d A_k = Eigen::Matrix3d::Identity();
  double sum_err = 0, max_err = 0;
  int n_err = 0;
  const int frames = 10;
  for (int k = 0; k < frames; ++k) {
    if (k > 0) A_k = A1 * A_k;
    const cv::Mat frame = render(tex, A_k);
    const FeatureObservations obs = tracker.track(1000000000LL + k * 10000000LL, frame,
                                                  k > 0 ? &R1 : nullptr);
    EXPECT_EQ(obs.frame_id, k);
    const auto cur = tracker.current();
    ASSERT_EQ(cur.size(), obs.observations.size());
    for (size_t i = 0; i < cur.size(); ++i) {
      const auto& [id, px] = cur[i];
      EXPECT_EQ(obs.observations[i].track_id, id);
      EXPECT_NEAR(obs.observations[i].bearing_c.norm(), 1.0, 1e-12);
      auto it = birth.find(id);
      if (it == birth.end()) {
        birth.emplace(id, std::make_pair(A_k, px));
        continue;
      }
      const cv::Point2f expected = apply(A_k * it->second.first.inverse(), it->second.second);
      const double e = dist(px, expected);
      sum_err += e;
      max_err = std::max(max_err, e);
      ++n_err;
    }
  }
  const FeatureTrackerStats& st = tracker.stats();
  const double mean_err = sum_err / std::max(1, n_err);
  std::printf("[track] %d frames, step 0.5 deg + (1.7, -0.9) px: %d tracked positions, mean error "
              "%.4f px, max %.4f px; detected %lld, lost_klt %lld, lost_fb %lld, ransac %lld\n",
              frames, n_err, mean_err, max_err, static_cast<long long>(st.detected),
              static_cast<long long>(st.lost_klt), static_cast<long long>(st.lost_fb),
              static_cast<long long>(st.rejected_ransac));
  EXPECT_EQ(st.frames, frames);
  EXPECT_GT(n_err, 500);
  EXPECT_LT(mean_err, 0.3);
  EXPECT_LT(max_err, 1.5);
  // Nearly everything survives a clean rigid motion.
  EXPECT_GT(st.tracked, 8 * (st.lost_klt + st.lost_fb + st.rejected_ransac));
}

// Frame 1 = frame 0 moved by a known step, with a 90x80 patch repainted with another texture.
// Counts over three textures, by where a feature should be in frame 1: inside the patch (at least
// 10 px in), far outside it (11 px or more, inside the image minus the border), or in the band
// between, whose 21 px KLT window straddles the edge (reported only).
struct PatchResult {
  int inside = 0, inside_survived = 0, inside_wrong = 0;
  int outside = 0, outside_survived = 0, outside_wrong = 0;
  int band = 0, band_survived = 0, band_wrong = 0;
  int64_t lost_fb = 0, lost_klt = 0, rejected_ransac = 0;
};

PatchResult run_patch(RansacModel model, double fb_max_px) {
  PatchResult r;
  const cv::Rect patch(60, 40, 90, 80);
  auto outside_by = [&](const cv::Point2f& p) {  // Chebyshev distance outside the patch (px)
    return std::max({patch.x - p.x, p.x - (patch.x + patch.width - 1), patch.y - p.y,
                     p.y - (patch.y + patch.height - 1)});
  };
  for (uint64_t seed : {7, 8, 9}) {
    const cv::Mat tex = make_texture(seed, kW + 2 * kMargin, kH + 2 * kMargin);
    const cv::Mat other = make_texture(seed + 100, kW, kH);
    FeatureTrackerOptions opt;
    opt.ransac = model;
    opt.forward_backward_max_px = fb_max_px;
    FeatureTracker tracker(camera(), opt);
    const Motion step{0.3, 1.3, 0.6};
    tracker.track(0, render(tex, Eigen::Matrix3d::Identity()));
    const auto before = tracker.current();
    cv::Mat f1 = render(tex, step.A());
    other(patch).copyTo(f1(patch));
    const Eigen::Matrix3d R = step.R_cur_prev();
    tracker.track(10000000, f1, &R);
    std::map<int64_t, cv::Point2f> after;
    for (const auto& [id, px] : tracker.current()) after[id] = px;
    for (const auto& [id, px0] : before) {
      const cv::Point2f expected = apply(step.A(), px0);
      const auto it = after.find(id);
      const bool survived = it != after.end();
      const int wrong = survived && dist(it->second, expected) > 1.0 ? 1 : 0;
      const float d = outside_by(expected);
      const bool in_image = expected.x >= 4 && expected.y >= 4 && expected.x <= kW - 5 &&
                            expected.y <= kH - 5;
      if (d <= -10) {
        ++r.inside;
        r.inside_survived += survived;
        r.inside_wrong += wrong;
      } else if (d >= 11 && in_image) {
        ++r.outside;
        r.outside_survived += survived;
        r.outside_wrong += wrong;
      } else if (d < 11) {
        ++r.band;
        r.band_survived += survived;
        r.band_wrong += wrong;
      }
    }
    r.lost_fb += tracker.stats().lost_fb;
    r.lost_klt += tracker.stats().lost_klt;
    r.rejected_ransac += tracker.stats().rejected_ransac;
  }
  std::printf("[fb] ransac %-10s fb_max %g px: inside patch %d features, %d survived (%d wrong > 1 px); "
              "far outside %d, %d survived (%d wrong); edge band %d, %d survived (%d wrong); "
              "lost_fb %lld, lost_klt %lld, ransac %lld\n",
              ransac_model_name(model), fb_max_px, r.inside, r.inside_survived, r.inside_wrong,
              r.outside, r.outside_survived, r.outside_wrong, r.band, r.band_survived, r.band_wrong,
              static_cast<long long>(r.lost_fb), static_cast<long long>(r.lost_klt),
              static_cast<long long>(r.rejected_ransac));
  return r;
}

TEST(FeatureTracker, ForwardBackwardRejectsRepaintedPatch) {
  // Without the check (threshold 1e6 px) KLT "tracks" many features into the new content.
  const PatchResult off = run_patch(RansacModel::kNone, 1e6);
  // With the check alone (no RANSAC).
  const PatchResult fb = run_patch(RansacModel::kNone, 1.0);
  ASSERT_GE(fb.inside, 20);
  EXPECT_EQ(off.lost_fb, 0);
  EXPECT_GE(off.inside_wrong, off.inside / 2);
  EXPECT_GT(fb.lost_fb, 0);
  EXPECT_LE(fb.inside_survived, fb.inside / 8);  // measured: see the printed figures
  EXPECT_LE(fb.inside_wrong, fb.inside / 8);
  // Unchanged regions keep their tracks, correctly.
  EXPECT_EQ(fb.outside_wrong, 0);
  EXPECT_GE(fb.outside_survived, fb.outside * 95 / 100);
  // With the 2-point RANSAC after it, never more wrong tracks (a wrong position displaced along its
  // epipolar line is consistent with any two-view model, so RANSAC cannot promise zero).
  const PatchResult both = run_patch(RansacModel::kTwoPoint, 1.0);
  EXPECT_LE(both.inside_wrong, fb.inside_wrong);
  EXPECT_LE(both.band_wrong, fb.band_wrong);
  EXPECT_EQ(both.outside_wrong, 0);
  EXPECT_GE(both.outside_survived, both.outside * 95 / 100);
}

TEST(FeatureTracker, BucketingSpreadsFeatures) {
  // Texture everywhere but with a strong cluster of corners in one cell: bucketing must still put
  // features in every cell and never more than max_per_cell in one.
  cv::Mat frame = make_texture(21, kW, kH);
  cv::Mat dense = frame(cv::Rect(5, 5, 30, 35));
  for (int y = 0; y < dense.rows; y += 5)
    for (int x = 0; x < dense.cols; x += 5)
      cv::rectangle(dense, cv::Rect(x, y, 2, 2), cv::Scalar((x + y) % 2 ? 255 : 0), -1);
  FeatureTrackerOptions opt;
  opt.max_per_cell = 4;
  opt.min_distance_px = 3;
  FeatureTracker tracker(camera(), opt);
  tracker.track(0, frame);
  std::vector<int> cells(static_cast<size_t>(opt.grid_cols * opt.grid_rows), 0);
  for (const auto& [id, px] : tracker.current()) {
    const int c = std::min(opt.grid_cols - 1, static_cast<int>(px.x * opt.grid_cols / kW));
    const int r = std::min(opt.grid_rows - 1, static_cast<int>(px.y * opt.grid_rows / kH));
    ++cells[static_cast<size_t>(r * opt.grid_cols + c)];
  }
  std::printf("[bucket] features per cell (6x4, max 4):");
  for (int c : cells) std::printf(" %d", c);
  std::printf("  total %zu\n", tracker.current().size());
  for (int c : cells) {
    EXPECT_GE(c, 1);
    EXPECT_LE(c, opt.max_per_cell);
  }
  // Untextured cells get nothing: a flat image half.
  cv::Mat half = frame.clone();
  half(cv::Rect(kW / 2, 0, kW / 2, kH)).setTo(cv::Scalar(128));
  FeatureTracker t2(camera(), opt);
  t2.track(0, half);
  int right = 0;
  for (const auto& [id, px] : t2.current()) right += px.x >= kW / 2 ? 1 : 0;
  EXPECT_EQ(right, 0);
  EXPECT_GE(static_cast<int>(t2.current().size()), 3 * 4);  // the 12 textured cells
}

TEST(FeatureTracker, DetectsNewFeaturesWhenTracksDrop) {
  // Pure shift of 9 px per frame: features leave on the left, texture enters on the right.
  const cv::Mat tex = make_texture(5, kW + 2 * kMargin + 200, kH + 2 * kMargin);
  FeatureTrackerOptions opt;
  opt.min_tracks_before_detection = 110;
  FeatureTracker tracker(camera(), opt);
  const Motion step{0.0, -9.0, 0.0};
  const Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d A_k = Eigen::Matrix3d::Identity();
  int64_t max_id = -1;
  int detections = 0;
  for (int k = 0; k < 14; ++k) {
    if (k > 0) A_k = step.A() * A_k;
    const FeatureTrackerStats before = tracker.stats();
    const FeatureObservations obs = tracker.track(k * 10000000LL, render(tex, A_k), k ? &R : nullptr);
    const FeatureTrackerStats& st = tracker.stats();
    const int64_t survived = st.tracked - before.tracked;
    const int64_t added = st.detected - before.detected;
    int64_t new_ids = 0;
    int64_t frame_max = max_id;
    for (const auto& o : obs.observations) {
      if (o.track_id > max_id) ++new_ids;
      frame_max = std::max(frame_max, o.track_id);
    }
    max_id = frame_max;
    EXPECT_EQ(new_ids, added) << "frame " << k;
    EXPECT_EQ(static_cast<int64_t>(obs.observations.size()), survived + added);
    if (k > 0) {
      if (survived < opt.min_tracks_before_detection) {
        EXPECT_GT(added, 0) << "frame " << k << ": " << survived << " tracks left";
        ++detections;
      } else {
        EXPECT_EQ(added, 0) << "frame " << k;
      }
    }
  }
  std::printf("[redetect] 14 frames at 9 px/frame: %d re-detections, %lld features detected, "
              "%lld lost by KLT/border\n",
              detections, static_cast<long long>(tracker.stats().detected),
              static_cast<long long>(tracker.stats().lost_klt));
  EXPECT_GE(detections, 2);
}

std::vector<FeatureObservations> run_sequence(RansacModel model, bool with_prior) {
  const cv::Mat tex = make_texture(13, kW + 2 * kMargin, kH + 2 * kMargin);
  FeatureTrackerOptions opt;
  opt.ransac = model;
  opt.seed = 77;
  FeatureTracker tracker(camera(), opt);
  const Motion step{-0.4, 2.1, 1.2};
  const Eigen::Matrix3d R = step.R_cur_prev();
  std::vector<FeatureObservations> out;
  Eigen::Matrix3d A_k = Eigen::Matrix3d::Identity();
  for (int k = 0; k < 8; ++k) {
    if (k > 0) A_k = step.A() * A_k;
    cv::Mat f = render(tex, A_k);
    if (k == 4) {  // repaint a patch: some tracks go wrong (a local RNG: theRNG() is global state)
      cv::RNG rng(4);
      cv::Mat patch = f(cv::Rect(100, 60, 50, 50));
      rng.fill(patch, cv::RNG::UNIFORM, 0, 256);
    }
    out.push_back(tracker.track(k * 5000000LL, f, (k && with_prior) ? &R : nullptr));
  }
  return out;
}

TEST(FeatureTracker, Deterministic) {
  for (auto [model, prior] : {std::pair{RansacModel::kTwoPoint, true},
                              std::pair{RansacModel::kFivePoint, false}}) {
    const auto a = run_sequence(model, prior);
    const auto b = run_sequence(model, prior);
    ASSERT_EQ(a.size(), b.size());
    size_t total = 0;
    for (size_t k = 0; k < a.size(); ++k) {
      EXPECT_EQ(a[k].t_ns, b[k].t_ns);
      EXPECT_EQ(a[k].frame_id, b[k].frame_id);
      ASSERT_EQ(a[k].observations.size(), b[k].observations.size());
      for (size_t i = 0; i < a[k].observations.size(); ++i) {
        EXPECT_EQ(a[k].observations[i].track_id, b[k].observations[i].track_id);
        EXPECT_EQ(a[k].observations[i].bearing_c, b[k].observations[i].bearing_c);
      }
      total += a[k].observations.size();
    }
    EXPECT_GT(total, 400u);
  }
}

TEST(FeatureTrackerOptions, Validation) {
  std::string why;
  EXPECT_TRUE(FeatureTrackerOptions{}.Validate(&why)) << why;
  auto bad = [](auto mutate) {
    FeatureTrackerOptions o;
    mutate(o);
    std::string w;
    const bool ok = o.Validate(&w);
    return !ok && !w.empty();
  };
  EXPECT_TRUE(bad([](auto& o) { o.grid_cols = 0; }));
  EXPECT_TRUE(bad([](auto& o) { o.grid_rows = -1; }));
  EXPECT_TRUE(bad([](auto& o) { o.max_features = 0; }));
  EXPECT_TRUE(bad([](auto& o) { o.max_per_cell = 0; }));
  EXPECT_TRUE(bad([](auto& o) { o.fast_threshold = 0; }));
  EXPECT_TRUE(bad([](auto& o) { o.fast_threshold = 256; }));
  EXPECT_TRUE(bad([](auto& o) { o.min_distance_px = -1; }));
  EXPECT_TRUE(bad([](auto& o) { o.klt_window_px = 20; }));
  EXPECT_TRUE(bad([](auto& o) { o.klt_window_px = 1; }));
  EXPECT_TRUE(bad([](auto& o) { o.klt_pyramid_levels = -1; }));
  EXPECT_TRUE(bad([](auto& o) { o.klt_max_iterations = 0; }));
  EXPECT_TRUE(bad([](auto& o) { o.forward_backward_max_px = 0; }));
  EXPECT_TRUE(bad([](auto& o) { o.forward_backward_max_px = NAN; }));
  EXPECT_TRUE(bad([](auto& o) { o.ransac = static_cast<RansacModel>(7); }));
  EXPECT_TRUE(bad([](auto& o) { o.ransac_threshold_px = -1; }));
  EXPECT_TRUE(bad([](auto& o) { o.ransac_threshold_px = INFINITY; }));
  EXPECT_TRUE(bad([](auto& o) { o.ransac_max_iterations = 0; }));
  EXPECT_TRUE(bad([](auto& o) { o.min_tracks_before_detection = 151; }));
  EXPECT_TRUE(bad([](auto& o) { o.border_px = -2; }));
  EXPECT_TRUE(FeatureTrackerOptions{}.Validate(nullptr));
  FeatureTrackerOptions no_why;
  no_why.grid_cols = 0;
  EXPECT_FALSE(no_why.Validate(nullptr));

  FeatureTrackerOptions o;
  o.max_features = 0;
  EXPECT_THROW(FeatureTracker(camera(), o), std::invalid_argument);
  calib::CameraIntrinsics K = camera();
  K.model = calib::DistortionModel::kRadtan;
  K.distortion = {0.1, 0, 0, 0};
  EXPECT_THROW(FeatureTracker(K, FeatureTrackerOptions{}), std::invalid_argument);
  FeatureTracker t(camera(), FeatureTrackerOptions{});
  EXPECT_THROW(t.track(0, cv::Mat(kH, kW, CV_8UC3, cv::Scalar(0, 0, 0))), std::invalid_argument);
  EXPECT_THROW(t.track(0, cv::Mat(kH + 1, kW, CV_8UC1, cv::Scalar(0))), std::invalid_argument);
  // A blank frame is valid input: no features, no crash.
  EXPECT_TRUE(t.track(0, cv::Mat(kH, kW, CV_8UC1, cv::Scalar(9))).observations.empty());
}


// Reference templates: on frames with independent noise, chained frame-to-frame KLT accumulates
// each frame's alignment error (a random walk), tracking against a template refreshed every 10
// frames accumulates it once per 10 frames.
double drift_after(int template_max_age_frames, int frames, bool fallback = false) {
  const cv::Mat tex = make_texture(11, kW + 2 * kMargin, kH + 2 * kMargin);
  FeatureTrackerOptions opt;
  opt.template_max_age_frames = template_max_age_frames;
  opt.template_fallback = fallback;
  opt.ransac = RansacModel::kNone;
  opt.forward_backward_max_px = 3.0;
  FeatureTracker tracker(camera(), opt);
  const Motion step{0.0, 0.37, 0.21};
  Eigen::Matrix3d A_k = Eigen::Matrix3d::Identity();
  std::map<int64_t, cv::Point2f> born;  // tracks of frame 0
  cv::RNG rng(3);
  double sum = 0;
  int n = 0;
  for (int k = 0; k < frames; ++k) {
    if (k > 0) A_k = step.A() * A_k;
    cv::Mat frame = render(tex, A_k), noise(frame.size(), CV_16SC1);
    rng.fill(noise, cv::RNG::NORMAL, 0, 12);
    cv::Mat noisy;
    frame.convertTo(noisy, CV_16SC1);
    noisy += noise;
    noisy.convertTo(frame, CV_8UC1);  // saturating
    tracker.track(k * 10000000LL, frame);
    for (const auto& [id, px] : tracker.current()) {
      if (k == 0) born.emplace(id, px);
      if (k == frames - 1 && born.count(id)) {
        sum += dist(px, apply(A_k, born.at(id)));
        ++n;
      }
    }
  }
  EXPECT_GT(n, 50) << "template_max_age_frames " << template_max_age_frames;
  return sum / std::max(1, n);
}

TEST(FeatureTracker, ReferenceTemplatesDriftLessThanChainedTracking) {
  const double chained = drift_after(1, 30), templ = drift_after(10, 30);
  std::printf("[template] mean error after 30 noisy frames: chained %.3f px, template every 10 frames %.3f px\n",
              chained, templ);
  EXPECT_LT(templ, 0.75 * chained);
}

// Template fallback: an in-plane rotation of 3 deg per frame turns a 10-frame-old template by up to
// 27 deg, more than translation-only KLT aligns, while consecutive frames differ by 3 deg. Without
// the fallback those tracks are lost; with it they continue from the previous frame, as chained
// tracks do. Returns how many of frame 0's tracks are alive after `frames` frames. (Where KLT does
// converge on a template turned by 10-15 deg it may be 1.5-2.5 px off and pass the forward-backward
// check: translation-only alignment against a deformed template is biased, which is why templates
// are refreshed.)
size_t survivors(int template_max_age_frames, bool fallback, int frames, int64_t* fallbacks,
                 double max_rotation_deg = 0, double* mean_error_px = nullptr, int64_t* refreshes = nullptr,
                 bool rotation_warp = false) {
  const cv::Mat tex = make_texture(5, kW + 2 * kMargin, kH + 2 * kMargin);
  FeatureTrackerOptions opt;
  opt.klt_warp = rotation_warp ? KltWarp::kRotation : KltWarp::kNone;
  opt.template_max_age_frames = template_max_age_frames;
  opt.template_fallback = fallback;
  opt.template_max_rotation_deg = max_rotation_deg;
  opt.ransac = RansacModel::kNone;
  FeatureTracker tracker(camera(), opt);
  const Motion step{3.0, 0.3, 0.2};
  double error_sum = 0;
  Eigen::Matrix3d A_k = Eigen::Matrix3d::Identity();
  std::map<int64_t, cv::Point2f> born;
  size_t alive = 0;
  for (int k = 0; k < frames; ++k) {
    if (k > 0) A_k = step.A() * A_k;
    const Eigen::Matrix3d R = step.R_cur_prev();
    tracker.track(k * 10000000LL, render(tex, A_k), k > 0 ? &R : nullptr);
    alive = 0;
    error_sum = 0;
    for (const auto& [id, px] : tracker.current()) {
      if (k == 0) born.emplace(id, px);
      if (!born.count(id)) continue;
      ++alive;
      error_sum += dist(px, apply(A_k, born.at(id)));
    }
  }
  *fallbacks = tracker.stats().template_fallbacks;
  if (mean_error_px) *mean_error_px = error_sum / std::max<size_t>(1, alive);
  if (refreshes) *refreshes = tracker.stats().template_rotation_refreshes;
  return alive;
}

TEST(FeatureTracker, TemplateFallbackKeepsTracksTheTemplateLoses) {
  int64_t fb_chained = 0, fb_without = 0, fb_with = 0;
  const size_t chained = survivors(1, false, 12, &fb_chained);
  const size_t without = survivors(10, false, 12, &fb_without);
  const size_t with = survivors(10, true, 12, &fb_with);
  std::printf("[template fallback] frame-0 tracks alive after 12 frames at 3 deg/frame: chained %zu, template "
              "every 10 frames %zu, with fallback %zu (%lld fallbacks)\n",
              chained, without, with, static_cast<long long>(fb_with));
  EXPECT_EQ(fb_chained, 0);
  EXPECT_EQ(fb_without, 0);
  EXPECT_GT(fb_with, 0);
  EXPECT_GT(chained, 50u);
  EXPECT_LT(without, with / 2);
  EXPECT_GE(with, chained * 9 / 10);
}

// A rotation limit on templates: at 3 deg per frame, a 5 deg limit uses no template older than
// the previous frame, so the tracks are not pulled off by turned templates.
TEST(FeatureTracker, TemplatesTurnedTooFarAreNotUsed) {
  int64_t fallbacks = 0, refreshes = 0, refreshes_off = 0;
  double err_off = 0, err_on = 0, err_chained = 0;
  const size_t chained = survivors(1, false, 12, &fallbacks, 0, &err_chained);
  const size_t off = survivors(10, true, 12, &fallbacks, 0, &err_off, &refreshes_off);
  const size_t on = survivors(10, true, 12, &fallbacks, 5.0, &err_on, &refreshes);
  std::printf("[template rotation] after 12 frames at 3 deg/frame, mean error of frame-0 tracks: chained %.3f px (%zu), "
              "templates %.3f px (%zu), templates up to 5 deg %.3f px (%zu, %lld refreshes)\n",
              err_chained, chained, err_off, off, err_on, on, static_cast<long long>(refreshes));
  EXPECT_EQ(refreshes_off, 0);
  EXPECT_GT(refreshes, 0);
  EXPECT_GE(on, chained * 9 / 10);
  // Measured: chained 2.04 px (KLT's translation-only alignment is biased under rotation frame to
  // frame too), templates 3.69 px, with the limit 2.04 px (every template is refreshed after one
  // frame at this rate).
  EXPECT_LT(err_on, 0.65 * err_off);
  EXPECT_LT(err_on, 1.1 * err_chained);
}

// The rotation-warped refinement: the same 12 frames at 3 deg per frame, templates of up to 10
// frames without a rotation limit. Each template is aligned with its turn taken out, so neither
// the templates (turned by up to 30 deg) nor chained tracking (3 deg per step) bias the tracks.
TEST(FeatureTracker, RotationWarpRemovesTheTurnedTemplatesBias) {
  int64_t fallbacks = 0;
  double err_chained = 0, err_chained_warp = 0, err_templates = 0;
  const size_t chained = survivors(1, false, 12, &fallbacks, 0, &err_chained);
  const size_t chained_warp = survivors(1, false, 12, &fallbacks, 0, &err_chained_warp, nullptr, true);
  const size_t templates = survivors(10, true, 12, &fallbacks, 0, &err_templates, nullptr, true);
  std::printf("[rotation warp] after 12 frames at 3 deg/frame, mean error of frame-0 tracks: chained %.3f px (%zu), "
              "chained with the warp %.3f px (%zu), templates of up to 10 frames with the warp %.3f px (%zu)\n",
              err_chained, chained, err_chained_warp, chained_warp, err_templates, templates);
  EXPECT_GE(chained_warp, chained * 9 / 10);
  EXPECT_GE(templates, chained * 9 / 10);
  // Measured: chained 2.04 px, chained with the warp 0.027 px, templates with the warp 0.011 px.
  EXPECT_GT(err_chained, 1.5);
  EXPECT_LT(err_chained_warp, 0.04);
  EXPECT_LT(err_templates, 0.02);
}

// align_warped_patch against a frame turned by 4 deg about the principal point: translation-only
// KLT is off by the turn times the offset of its window's gradient centroid; the warped patch is not.
TEST(AlignWarpedPatch, RemovesTheRotationBiasOfTranslationOnlyKlt) {
  const cv::Mat tex = make_texture(9, kW + 2 * kMargin, kH + 2 * kMargin);
  const Motion turn{4.0, 0.0, 0.0};
  const cv::Mat ref = render(tex, Eigen::Matrix3d::Identity()), cur = render(tex, turn.A());
  std::vector<cv::Point2f> p0;
  for (int y = 40; y <= kH - 40; y += 10)
    for (int x = 40; x <= kW - 40; x += 10) p0.emplace_back(static_cast<float>(x), static_cast<float>(y));
  std::vector<cv::Point2f> p1 = p0;
  std::vector<uchar> st;
  cv::calcOpticalFlowPyrLK(ref, cur, p0, p1, st, cv::noArray(), cv::Size(27, 27), 3,
                           cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 30, 0.01));
  double klt = 0, warped = 0;
  int n = 0, refused = 0;
  for (size_t i = 0; i < p0.size(); ++i) {
    if (!st[i]) continue;
    const cv::Point2f truth = apply(turn.A(), p0[i]);
    cv::Point2f q = p1[i];
    if (!align_warped_patch(ref, p0[i], rotation_homography_jacobian(camera(), turn.R_cur_prev(), p0[i]), cur, 27, 30, 0.001, &q)) {
      ++refused;
      continue;
    }
    klt += dist(p1[i], truth);
    warped += dist(q, truth);
    ++n;
  }
  ASSERT_GT(n, 100);
  EXPECT_LT(refused, n / 20);
  klt /= n;
  warped /= n;
  std::printf("[align_warped_patch] 4 deg turn, %d points (%d refused): KLT mean error %.3f px, warped patch %.3f px\n", n, refused,
              klt, warped);
  // Measured: KLT 0.367 px, the warped patch 0.011 px.
  EXPECT_GT(klt, 0.25);
  EXPECT_LT(warped, 0.02);
}

// With turn_rad, align_warped_patch also estimates an in-plane turn on top of its map: given the
// identity for a frame turned by 4 deg, it finds the turn and the position.
TEST(AlignWarpedPatch, EstimatesTheTurnItIsNotGiven) {
  const cv::Mat tex = make_texture(9, kW + 2 * kMargin, kH + 2 * kMargin);
  const Motion turn{4.0, 0.0, 0.0};
  const cv::Mat ref = render(tex, Eigen::Matrix3d::Identity()), cur = render(tex, turn.A());
  double pos = 0, angle = 0;
  int n = 0, refused = 0;
  for (int y = 40; y <= kH - 40; y += 10)
    for (int x = 40; x <= kW - 40; x += 10) {
      const cv::Point2f p0(static_cast<float>(x), static_cast<float>(y)), truth = apply(turn.A(), p0);
      cv::Point2f q = truth + cv::Point2f(0.4f, -0.3f);
      double phi = 0;
      if (!align_warped_patch(ref, p0, Eigen::Matrix2d::Identity(), cur, 27, 30, 0.001, &q, &phi)) {
        ++refused;
        continue;
      }
      pos += dist(q, truth);
      angle += std::abs(phi * 180.0 / M_PI - 4.0);
      ++n;
    }
  ASSERT_GT(n, 100);
  EXPECT_LT(refused, n / 20);
  pos /= n;
  angle /= n;
  std::printf("[align_warped_patch] turn estimated, %d points (%d refused): mean position error %.3f px, turn error %.3f deg\n", n,
              refused, pos, angle);
  // Measured: 0.018 px, 0.063 deg.
  EXPECT_LT(pos, 0.025);
  EXPECT_LT(angle, 0.08);
}

// With log_scale as well: a frame 6% larger (the camera moving towards a fronto-parallel plane) and
// turned by 3 deg. Translation-only alignment is off by the scale change times the offset of the
// window's gradient centroid; the similarity is not.
TEST(AlignWarpedPatch, EstimatesTheScaleChange) {
  const cv::Mat tex = make_texture(11, kW + 2 * kMargin, kH + 2 * kMargin);
  const double a = 3.0 * M_PI / 180.0, k = 1.06;
  Eigen::Matrix3d A = Eigen::Matrix3d::Identity();
  A.topLeftCorner<2, 2>() << k * std::cos(a), -k * std::sin(a), k * std::sin(a), k * std::cos(a);
  A.topRightCorner<2, 1>() = Eigen::Vector2d(119.5, 89.5) - A.topLeftCorner<2, 2>() * Eigen::Vector2d(119.5, 89.5);
  const cv::Mat ref = render(tex, Eigen::Matrix3d::Identity()), cur = render(tex, A);
  double translation_only = 0, similarity = 0, scale_error = 0;
  int n = 0;
  for (int y = 40; y <= kH - 40; y += 10)
    for (int x = 40; x <= kW - 40; x += 10) {
      const cv::Point2f p0(static_cast<float>(x), static_cast<float>(y)), truth = apply(A, p0);
      cv::Point2f q1 = truth, q2 = truth;
      double phi = 0, sigma = 0;
      if (!align_warped_patch(ref, p0, Eigen::Matrix2d::Identity(), cur, 27, 30, 0.001, &q1) ||
          !align_warped_patch(ref, p0, Eigen::Matrix2d::Identity(), cur, 27, 30, 0.001, &q2, &phi, &sigma))
        continue;
      translation_only += dist(q1, truth);
      similarity += dist(q2, truth);
      scale_error += std::abs(std::exp(sigma) - k);
      ++n;
    }
  ASSERT_GT(n, 150);
  translation_only /= n;
  similarity /= n;
  scale_error /= n;
  std::printf("[align_warped_patch] 6%% larger, 3 deg turn, %d points: translation only %.3f px, similarity %.3f px (scale off by %.4f)\n",
              n, translation_only, similarity, scale_error);
  EXPECT_GT(translation_only, 0.3);
  EXPECT_LT(similarity, 0.03);
  EXPECT_LT(scale_error, 0.003);
}

// The local affine map of the infinite homography against finite differences, for a general turn.
TEST(AlignWarpedPatch, RotationHomographyJacobianMatchesFiniteDifferences) {
  const calib::CameraIntrinsics K = camera();
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitX()) * Eigen::AngleAxisd(-0.15, Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ())).toRotationMatrix();
  const auto map = [&](double x, double y) {
    const Eigen::Vector3d b = R * Eigen::Vector3d((x - K.cx) / K.fx, (y - K.cy) / K.fy, 1.0);
    return Eigen::Vector2d(K.fx * b.x() / b.z() + K.cx, K.fy * b.y() / b.z() + K.cy);
  };
  for (const cv::Point2f p : {cv::Point2f(20, 30), cv::Point2f(119.5, 89.5), cv::Point2f(200, 150)}) {
    const Eigen::Matrix2d J = rotation_homography_jacobian(K, R, p);
    const double h = 1e-4;
    Eigen::Matrix2d N;
    N.col(0) = (map(p.x + h, p.y) - map(p.x - h, p.y)) / (2 * h);
    N.col(1) = (map(p.x, p.y + h) - map(p.x, p.y - h)) / (2 * h);
    EXPECT_LT((J - N).norm(), 1e-6) << p;
  }
  EXPECT_TRUE(rotation_homography_jacobian(K, Eigen::Matrix3d::Identity(), cv::Point2f(5, 7)).isApprox(Eigen::Matrix2d::Identity()));
}

// A flat patch, a window leaving the image and a singular map are refused, the position untouched.
TEST(AlignWarpedPatch, RefusesFlatPatchesBordersAndSingularMaps) {
  const cv::Mat flat(kH, kW, CV_8UC1, cv::Scalar(90));
  const cv::Mat tex = render(make_texture(3, kW + 2 * kMargin, kH + 2 * kMargin), Eigen::Matrix3d::Identity());
  const Eigen::Matrix2d I = Eigen::Matrix2d::Identity();
  cv::Point2f q(100, 80);
  EXPECT_FALSE(align_warped_patch(flat, cv::Point2f(100, 80), I, flat, 21, 10, 0.01, &q));
  EXPECT_FALSE(align_warped_patch(tex, cv::Point2f(5, 80), I, tex, 21, 10, 0.01, &q));
  EXPECT_FALSE(align_warped_patch(tex, cv::Point2f(100, 80), Eigen::Matrix2d::Zero(), tex, 21, 10, 0.01, &q));
  EXPECT_EQ(q, cv::Point2f(100, 80));
  EXPECT_TRUE(align_warped_patch(tex, cv::Point2f(100, 80), I, tex, 21, 10, 0.01, &q));
  EXPECT_LT(dist(q, cv::Point2f(100, 80)), 1e-3);
  EXPECT_THROW(align_warped_patch(tex, cv::Point2f(100, 80), I, tex, 2, 10, 0.01, &q), std::invalid_argument);
}

TEST(FeatureTracker, TemplateFallbackDriftsLessThanChainedTracking) {
  const double chained = drift_after(1, 30), templ = drift_after(10, 30, true);
  std::printf("[template] mean error after 30 noisy frames: chained %.3f px, template every 10 frames with "
              "fallback %.3f px\n", chained, templ);
  EXPECT_LT(templ, 0.75 * chained);
}

// Long-baseline verification: the scene moves 0.6 px per frame along x (a sideways translation:
// epipolar lines along x); a textured patch in it slides an extra 0.3 px per frame along y. The
// frame-to-frame RANSAC (1 px) keeps the patch's tracks; over 10 frames they are 3 px off their
// epipolar lines and the anchor RANSAC drops them, while the scene's tracks live on.
struct SlideResult {
  size_t slider_tracks = 0, scene_tracks = 0;  // alive at the last frame, born at frame 0
  int64_t rejected_anchor = 0;
};
SlideResult track_with_slider(int anchor_frames) {
  const cv::Mat tex = make_texture(21, kW + 2 * kMargin, kH + 2 * kMargin);
  const cv::Mat patch_tex = make_texture(22, kW + 2 * kMargin, kH + 2 * kMargin);
  const cv::Rect patch(130, 50, 60, 60);  // in frame 0
  FeatureTrackerOptions opt;
  opt.anchor_frames = anchor_frames;
  FeatureTracker tracker(camera(), opt);
  const Motion step{0.0, 0.6, 0.0};
  const Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  std::map<int64_t, bool> born_on_patch;
  SlideResult r;
  Eigen::Matrix3d A_k = Eigen::Matrix3d::Identity();
  const int frames = 16;
  for (int k = 0; k < frames; ++k) {
    if (k > 0) A_k = step.A() * A_k;
    Eigen::Matrix3d S = A_k;
    S(1, 2) += 0.3 * k;  // the patch's extra slide
    cv::Mat frame = render(tex, A_k), slid = render(patch_tex, S), mask(kH + 2 * kMargin, kW + 2 * kMargin, CV_8UC1, cv::Scalar(0));
    mask(cv::Rect(patch.x + kMargin, patch.y + kMargin, patch.width, patch.height)).setTo(255);
    cv::Mat m = render(mask, S);
    slid.copyTo(frame, m > 128);
    tracker.track(k * 10000000LL, frame, k > 0 ? &R : nullptr);
    size_t slider = 0, scene = 0;
    for (const auto& [id, px] : tracker.current()) {
      if (k == 0) born_on_patch[id] = patch.contains(cv::Point(cvRound(px.x), cvRound(px.y)));
      if (!born_on_patch.count(id)) continue;
      // Tracks born near the patch's border see both motions: counted as neither.
      const cv::Point2f p0 = apply(A_k.inverse(), px);
      const bool inner = p0.x > patch.x + 6 && p0.x < patch.br().x - 6 && p0.y > patch.y + 6 + 0.3 * k;
      if (born_on_patch[id] && inner) ++slider;
      if (!born_on_patch[id]) ++scene;
    }
    r.slider_tracks = slider;
    r.scene_tracks = scene;
  }
  r.rejected_anchor = tracker.stats().rejected_anchor;
  return r;
}

TEST(FeatureTracker, AnchorRansacDropsTracksThatSlideSlowly) {
  const SlideResult off = track_with_slider(0), on = track_with_slider(10);
  std::printf("[anchor] after 16 frames: without anchor %zu sliding and %zu scene tracks; anchor every 10 frames %zu "
              "and %zu (%lld rejected)\n", off.slider_tracks, off.scene_tracks, on.slider_tracks, on.scene_tracks,
              static_cast<long long>(on.rejected_anchor));
  EXPECT_EQ(off.rejected_anchor, 0);
  EXPECT_GE(off.slider_tracks, 3u);
  EXPECT_EQ(on.slider_tracks, 0u);
  EXPECT_GT(on.rejected_anchor, 0);
  EXPECT_GE(on.scene_tracks, off.scene_tracks * 9 / 10);
}

TEST(FeatureTrackerOptions, TemplateAgeMustBePositive) {
  FeatureTrackerOptions o;
  o.template_max_age_frames = 0;
  std::string why;
  EXPECT_FALSE(o.Validate(&why));
  EXPECT_NE(why.find("template_max_age_frames"), std::string::npos);
  for (auto bad : {+[](FeatureTrackerOptions* b) { b->template_max_rotation_deg = -1; },
                   +[](FeatureTrackerOptions* b) { b->template_max_rotation_deg = std::nan(""); },
                   +[](FeatureTrackerOptions* b) { b->anchor_frames = -1; },
                   +[](FeatureTrackerOptions* b) { b->anchor_ransac_threshold_px = 0; }}) {
    FeatureTrackerOptions b;
    bad(&b);
    EXPECT_FALSE(b.Validate(&why));
  }
}

}  // namespace
}  // namespace evio::frontend
