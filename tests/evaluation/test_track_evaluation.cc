// Feature-track evaluation against ground truth: exact tracks score zero, a known per-frame drift
// shows up as an error growing linearly with age (anchored) and is partly absorbed when
// triangulated, gross errors are counted apart, tracks that end with their landmark in view are
// counted as lost while visible, and tracks that leave the view are not.
#include "evio/evaluation/track_evaluation.h"
#include "evio/evaluation/track_oracle.h"

#include <cmath>
#include <map>
#include <algorithm>
#include <random>
#include <set>
#include <vector>

#include <gtest/gtest.h>

namespace evio::evaluation {
namespace {

// A wall x = 2 m (world), camera looking along +x (camera z = world x, camera x = -world y,
// camera y = -world z), body = camera, moving sideways along world y at 0.5 m/s; 50 frames at
// 20 Hz.
struct Scenario {
  calib::CameraCalibration camera;
  Trajectory gt;
  std::vector<Eigen::Vector3d> points;
  RayCaster cast = [](const Eigen::Vector3d& o, const Eigen::Vector3d& d) -> std::optional<double> {
    if (!(d.x() > 1e-12)) return std::nullopt;
    return (2.0 - o.x()) / d.x();
  };
  Scenario() {
    calib::CameraIntrinsics K;
    K.width = 240;
    K.height = 180;
    K.fx = K.fy = 200;
    K.cx = 120;
    K.cy = 90;
    camera.camera = calib::PinholeCamera(K);
    camera.has_T_c_b = true;
    Eigen::Matrix3d R_w_c;
    R_w_c << 0, 0, 1, -1, 0, 0, 0, -1, 0;
    std::vector<StampedPose> poses;
    for (int i = 0; i <= 300; ++i) {
      const int64_t t = static_cast<int64_t>(i) * 10'000'000;
      poses.push_back({t, calib::SE3(R_w_c, Eigen::Vector3d(0, 0.5 * 1e-9 * static_cast<double>(t), 0))});
    }
    gt = Trajectory(poses);
    std::mt19937 rng(5);
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    for (int i = 0; i < 200; ++i) points.push_back({2.0, 0.6 + 1.2 * u(rng), 0.8 * u(rng)});
  }
  // Observations of every point in view at frames 0..n-1 (50 ms apart); drift_px per frame of age
  // added along the image y axis (across the motion: no depth explains it); a track ends after max_len frames (new id when re-observed).
  std::vector<FeatureObservations> frames(int n, double drift_px, int max_len) const {
    std::vector<FeatureObservations> out;
    std::vector<int> age(points.size(), -1);
    std::vector<int64_t> id(points.size(), 0);
    int64_t next_id = 0;
    for (int k = 0; k < n; ++k) {
      FeatureObservations f;
      f.t_ns = k * 50'000'000LL;
      f.frame_id = k;
      const calib::SE3 T_c_w = gt.interpolate(f.t_ns)->inverse();
      for (size_t i = 0; i < points.size(); ++i) {
        const Eigen::Vector3d p = T_c_w * points[i];
        Eigen::Vector2d px;
        const bool in = p.z() > 0 && camera.camera.project(p, &px) && px.x() > 8 && px.x() < 231 && px.y() > 8 && px.y() < 171;
        if (!in || age[i] + 1 >= max_len) {
          age[i] = in ? -2 : -1;  // -2: waits one frame out of the tracker before a new track
          continue;
        }
        if (age[i] < 0) {
          if (age[i] == -2) {
            age[i] = -1;
            continue;
          }
          id[i] = next_id++;
        }
        ++age[i];
        px.y() += drift_px * age[i];
        Eigen::Vector3d b;
        EXPECT_TRUE(camera.camera.unproject(px, &b));
        f.observations.push_back({id[i], b});
      }
      out.push_back(f);
    }
    return out;
  }
};

TEST(TrackEvaluation, ExactTracksScoreZero) {
  const Scenario s;
  const auto frames = s.frames(40, 0.0, 1000);
  const TrackEvaluation e = evaluate_tracks(frames, s.gt, s.camera, s.cast);
  EXPECT_EQ(e.frames, 40);
  EXPECT_GT(e.tracks, 50);
  EXPECT_EQ(e.tracks_scored, e.tracks);
  EXPECT_LT(e.median_px, 1e-6);
  EXPECT_LT(e.p90_px, 1e-6);
  EXPECT_EQ(e.gross_errors, 0);
  // Points leave the view through the side: none of them is lost while visible.
  EXPECT_GT(e.ended, 10);
  EXPECT_EQ(e.lost_while_visible, 0);
  TrackEvaluationOptions tri;
  tri.reference = TrackReference::kTriangulated;
  const TrackEvaluation t = evaluate_tracks(frames, s.gt, s.camera, {}, tri);
  EXPECT_GT(t.tracks_scored, 0.8 * t.tracks);
  EXPECT_LT(t.median_px, 1e-6);
}

TEST(TrackEvaluation, DriftGrowsWithAgeWhenAnchored) {
  const Scenario s;
  const double drift = 0.1;  // px per frame
  const TrackEvaluation e = evaluate_tracks(s.frames(40, drift, 1000), s.gt, s.camera, s.cast);
  for (int a : {1, 2, 5, 10, 20}) {
    const TrackAgeBin& b = e.by_age[static_cast<size_t>(a - 1)];
    ASSERT_GT(b.count, 10) << a;
    EXPECT_NEAR(b.median_px, drift * a, 1e-6) << a;
  }
  // Triangulated: the point absorbs the mean of the drift, so the error stays below the anchored one.
  TrackEvaluationOptions tri;
  tri.reference = TrackReference::kTriangulated;
  const TrackEvaluation t = evaluate_tracks(s.frames(40, drift, 1000), s.gt, s.camera, {}, tri);
  EXPECT_GT(t.median_px, 0.01);
  EXPECT_LT(t.by_age[19].median_px, 0.8 * e.by_age[19].median_px);
}

TEST(TrackEvaluation, GrossErrorsAndLostWhileVisible) {
  const Scenario s;
  TrackEvaluationOptions o;
  o.gross_error_px = 1.0;
  // Drift 0.3 px/frame: ages >= 4 are gross errors (> 1 px). Tracks cut after 5 observations
  // while the point is still in view are lost while visible.
  const TrackEvaluation e = evaluate_tracks(s.frames(30, 0.3, 5), s.gt, s.camera, s.cast, o);
  EXPECT_GT(e.gross_errors, 0);
  EXPECT_EQ(e.by_age[3].count, 0);
  EXPECT_GT(e.by_age[2].count, 0);
  EXPECT_GT(e.lost_while_visible, 0.5 * e.ended);
  EXPECT_NEAR(e.median_lifetime_frames, 5, 1e-9);
  EXPECT_NEAR(e.lost_fraction, static_cast<double>(e.lost_while_visible) / static_cast<double>(e.ended), 1e-12);
}

TEST(TrackEvaluation, BadOptionsAndMissingRayCaster) {
  const Scenario s;
  TrackEvaluationOptions o;
  o.min_observations = 1;
  std::string why;
  EXPECT_FALSE(o.Validate(&why));
  EXPECT_NE(why.find("min_observations"), std::string::npos);
  EXPECT_THROW(evaluate_tracks({}, s.gt, s.camera, s.cast, o), std::invalid_argument);
  EXPECT_THROW(evaluate_tracks({}, s.gt, s.camera, {}), std::invalid_argument);
  const TrackEvaluation empty = evaluate_tracks({}, s.gt, s.camera, s.cast);
  EXPECT_EQ(empty.frames, 0);
  EXPECT_TRUE(std::isnan(empty.median_px));
  EXPECT_FALSE(track_evaluation_json(empty).empty());
}

// TrackOracle: the front-end's tracks (here drifting 0.3 px per frame) become the exact
// projections of their landmarks (anchored error 0 at every age), with the same topology; a
// random-walk drift added back grows like sqrt(age); a track whose first ray hits nothing is
// dropped.
std::vector<FeatureObservations> through_oracle(const Scenario& s, std::vector<FeatureObservations> frames,
                                                const TrackOracleOptions& o, RayCaster cast, TrackOracleStats* stats) {
  TrackOracle oracle(s.gt, s.camera, std::move(cast), o);
  for (auto& f : frames) oracle.apply(&f);
  *stats = oracle.stats();
  return frames;
}

TEST(TrackOracle, ReplacesTracksByTrueProjectionsKeepingTopology) {
  const Scenario s;
  const auto real = s.frames(40, 0.3, 15);
  TrackOracleStats st;
  const auto exact = through_oracle(s, real, {}, s.cast, &st);
  ASSERT_EQ(exact.size(), real.size());
  int64_t n = 0;
  for (size_t k = 0; k < real.size(); ++k) {
    ASSERT_EQ(exact[k].observations.size(), real[k].observations.size());
    for (size_t i = 0; i < real[k].observations.size(); ++i)
      EXPECT_EQ(exact[k].observations[i].track_id, real[k].observations[i].track_id);
    n += static_cast<int64_t>(real[k].observations.size());
  }
  EXPECT_EQ(st.replaced, n);
  EXPECT_EQ(st.dropped, 0);
  const TrackEvaluation before = evaluate_tracks(real, s.gt, s.camera, s.cast);
  const TrackEvaluation after = evaluate_tracks(exact, s.gt, s.camera, s.cast);
  EXPECT_GT(before.by_age[9].median_px, 2.5);  // 0.3 px x 10 frames
  EXPECT_LT(after.by_age[9].median_px, 1e-6);
  EXPECT_LT(after.p90_px, 1e-6);
  EXPECT_EQ(after.tracks, before.tracks);
}

TEST(TrackOracle, RandomWalkDriftGrowsLikeTheSquareRootOfAge) {
  const Scenario s;
  TrackOracleOptions o;
  o.drift_px_per_frame = 0.5;
  TrackOracleStats st;
  const auto drifting = through_oracle(s, s.frames(40, 0.0, 1000), o, s.cast, &st);
  const TrackEvaluation e = evaluate_tracks(drifting, s.gt, s.camera, s.cast);
  // 2-D Gaussian with sigma 0.5 sqrt(age) per axis: median radius 1.1774 sigma.
  for (int age : {4, 16}) {
    const double expected = 1.1774 * 0.5 * std::sqrt(age);
    EXPECT_NEAR(e.by_age[static_cast<size_t>(age - 1)].median_px, expected, 0.2 * expected) << "age " << age;
  }
}

// The oracle's error by track age: tracks drifting 0.1 px per frame of age (along image y) have an
// error of exactly 0.1 x age against their first observation's landmark; the rms of a bucket is
// 0.1 x the rms of its ages.
TEST(TrackOracle, ErrorByTrackAgeGrowsWithTheDrift) {
  const Scenario s;
  const auto frames = s.frames(40, 0.1, 1000);
  TrackOracleOptions o;
  o.keep_error = OracleError::kReal;
  TrackOracleStats st;
  through_oracle(s, frames, o, s.cast, &st);
  // Expected per bucket from the input's own ages.
  std::map<int64_t, int> age_of;
  double sq[TrackOracleStats::kAgeBuckets] = {};
  int64_t count[TrackOracleStats::kAgeBuckets] = {};
  for (const auto& f : frames) {
    for (const auto& ob : f.observations) {
      const auto [it, first] = age_of.emplace(ob.track_id, 0);
      if (first) continue;
      const int a = ++it->second;
      int k = TrackOracleStats::kAgeBuckets - 1;
      while (k > 0 && a < TrackOracleStats::kAgeBucketStart[k]) --k;
      sq[k] += 0.01 * a * a;
      ++count[k];
    }
  }
  for (int k = 0; k < TrackOracleStats::kAgeBuckets; ++k) {
    EXPECT_EQ(st.by_age[k].count, count[k]) << k;
    if (count[k] == 0) continue;
    EXPECT_NEAR(st.by_age[k].error_rms_px, std::sqrt(sq[k] / static_cast<double>(count[k])), 1e-6) << k;
  }
  EXPECT_NEAR(st.by_age[0].error_rms_px, 0.1, 1e-6);
  // Quantiles of |e - c| (c: the frame's median drift) within a bin of the exact ones.
  TrackOracleStats::AgeBucket one;
  for (double v : {0.05, 0.15, 0.25, 0.35, 1.05}) {
    one.independent_hist[static_cast<size_t>(v / TrackOracleStats::kBinPx)] += 1;
    ++one.count;
  }
  EXPECT_NEAR(one.independent_quantile_px(0.5), 0.25, TrackOracleStats::kBinPx);
  EXPECT_NEAR(one.independent_quantile_px(0.9), 1.05, TrackOracleStats::kBinPx);
  EXPECT_EQ(TrackOracleStats::AgeBucket().independent_quantile_px(0.5), 0.0);
  EXPECT_GT(count[5], 0);   // ages 32..39
  EXPECT_EQ(count[6], 0);   // no track reaches 64 frames
}

// The observation sink gets every observation the oracle measures: its error (the drift along y),
// its age, its frame's common mode (the per-axis median of the frame's errors), the true projection,
// its image velocity (50 px/s along x: 0.5 m/s sideways at 2 m with f = 200 px), the depth (2 m)
// and the camera orientation.
TEST(TrackOracle, ObservationSinkGetsEachObservationsErrorAndTruth) {
  const Scenario s;
  std::vector<FeatureObservations> frames = s.frames(20, 0.1, 1000);
  TrackOracleOptions o;
  o.keep_error = OracleError::kReal;
  TrackOracle oracle(s.gt, s.camera, s.cast, o);
  std::vector<OracleObservation> got;
  oracle.set_observation_sink([&](const OracleObservation& m) { got.push_back(m); });
  std::vector<FeatureObservations> before = frames;
  size_t n = 0;
  for (auto& f : frames) {
    n += f.observations.size();
    oracle.apply(&f);
  }
  ASSERT_EQ(got.size(), n);
  ASSERT_GT(n, 500u);
  std::map<int64_t, std::vector<double>> frame_errors;
  for (const OracleObservation& m : got) frame_errors[m.t_ns].push_back(m.error_px.y());
  size_t k = 0, i = 0;
  std::map<int64_t, int64_t> age_of;
  for (const OracleObservation& m : got) {
    while (i >= before[k].observations.size()) {
      ++k;
      i = 0;
    }
    const FeatureObservation& ob = before[k].observations[i++];
    EXPECT_EQ(m.t_ns, before[k].t_ns);
    EXPECT_EQ(m.track_id, ob.track_id);
    const auto [it, first] = age_of.emplace(ob.track_id, 0);
    if (!first) ++it->second;
    EXPECT_EQ(m.age, it->second);
    EXPECT_NEAR(m.error_px.x(), 0.0, 1e-6);
    EXPECT_NEAR(m.error_px.y(), 0.1 * static_cast<double>(m.age), 1e-6);
    std::vector<double> v = frame_errors[m.t_ns];
    std::nth_element(v.begin(), v.begin() + static_cast<long>(v.size() / 2), v.end());
    EXPECT_NEAR(m.common_mode_px.y(), v[v.size() / 2], 1e-9);
    Eigen::Vector2d observed;
    ASSERT_TRUE(s.camera.camera.project(ob.bearing_c, &observed));
    EXPECT_LT((m.true_px + m.error_px - observed).norm(), 1e-6);
    // Zero where the ground truth does not cover t - 2 ms (the first frame, at t = 0).
    EXPECT_NEAR(m.true_flow_px_s.x(), m.t_ns < 2'000'000 ? 0.0 : 50.0, 1e-3);
    EXPECT_NEAR(m.true_flow_px_s.y(), 0.0, 1e-3);
    EXPECT_NEAR(m.depth_m, 2.0, 1e-9);
    EXPECT_TRUE(m.q_c_w.isApprox(s.gt.interpolate(m.t_ns)->inverse().rotation, 1e-12));
  }
}

// keep_error splits the front-end's own error per frame: every observation after a track's first
// is moved by a frame-wide shift c_k plus its own noise; `real` keeps the observations as they
// are, `common_mode` gives every track the frame's median error (c_k up to the noise), and
// `independent` the rest (median 0).
TEST(TrackOracle, KeepsTheRealErrorItsCommonModeOrTheRest) {
  const Scenario s;
  std::vector<FeatureObservations> frames = s.frames(30, 0.0, 1000);
  std::mt19937 rng(9);
  std::normal_distribution<double> noise(0.0, 0.2);
  std::vector<Eigen::Vector2d> shift;
  std::set<int64_t> seen;
  for (size_t k = 0; k < frames.size(); ++k) {
    shift.emplace_back(0.8 * std::sin(0.7 * static_cast<double>(k)), 0.5 * std::cos(0.4 * static_cast<double>(k)));
    for (FeatureObservation& o : frames[k].observations) {
      if (seen.insert(o.track_id).second) continue;  // first observation: exact (the anchor)
      Eigen::Vector2d px;
      ASSERT_TRUE(s.camera.camera.project(o.bearing_c, &px));
      px += shift.back() + Eigen::Vector2d(noise(rng), noise(rng));
      ASSERT_TRUE(s.camera.camera.unproject(px, &o.bearing_c));
    }
  }
  TrackOracleStats st_none, st;
  const auto exact = through_oracle(s, frames, {}, s.cast, &st_none);
  // Pixel error of each observation of `out` against the exact projections, per frame.
  auto errors = [&](const std::vector<FeatureObservations>& out) {
    std::vector<std::vector<Eigen::Vector2d>> e(out.size());
    for (size_t k = 0; k < out.size(); ++k) {
      EXPECT_EQ(out[k].observations.size(), exact[k].observations.size());
      for (size_t i = 0; i < out[k].observations.size(); ++i) {
        Eigen::Vector2d a, b;
        EXPECT_TRUE(s.camera.camera.project(out[k].observations[i].bearing_c, &a));
        EXPECT_TRUE(s.camera.camera.project(exact[k].observations[i].bearing_c, &b));
        e[k].push_back(a - b);
      }
    }
    return e;
  };
  auto median_x = [](std::vector<Eigen::Vector2d> v) {
    std::vector<double> x;
    for (const auto& p : v) x.push_back(p.x());
    std::nth_element(x.begin(), x.begin() + static_cast<long>(x.size() / 2), x.end());
    return x[x.size() / 2];
  };
  TrackOracleOptions o;
  o.keep_error = OracleError::kReal;
  const auto real = errors(through_oracle(s, frames, o, s.cast, &st));
  double ms = 0;
  for (size_t k = 1; k < frames.size(); ++k) ms += shift[k].squaredNorm();
  EXPECT_NEAR(st.common_mode_rms_px, std::sqrt(ms / static_cast<double>(frames.size())), 0.05);
  o.keep_error = OracleError::kCommonMode;
  const auto common = errors(through_oracle(s, frames, o, s.cast, &st));
  o.keep_error = OracleError::kIndependent;
  const auto rest = errors(through_oracle(s, frames, o, s.cast, &st));
  for (size_t k = 1; k < frames.size(); ++k) {
    ASSERT_GT(real[k].size(), 50u);
    for (size_t i = 0; i < real[k].size(); ++i) {
      EXPECT_NEAR(common[k][i].x(), common[k][0].x(), 1e-6);  // one shift for the whole frame
      EXPECT_NEAR(common[k][i].x() + rest[k][i].x(), real[k][i].x(), 1e-6);
      EXPECT_NEAR(common[k][i].y() + rest[k][i].y(), real[k][i].y(), 1e-6);
    }
    EXPECT_NEAR(common[k][0].x(), shift[k].x(), 0.06) << k;
    EXPECT_NEAR(common[k][0].y(), shift[k].y(), 0.06) << k;
    EXPECT_NEAR(median_x(rest[k]), 0.0, 1e-6) << k;
  }
  EXPECT_STREQ(to_string(OracleError::kCommonMode), "common_mode");
  // max_error_px drops the observations whose own error is larger.
  o.keep_error = OracleError::kReal;
  o.max_error_px = 0.9;
  const auto kept = through_oracle(s, frames, o, s.cast, &st);
  size_t n_in = 0, n_out = 0;
  for (size_t k = 0; k < frames.size(); ++k) {
    n_in += frames[k].observations.size();
    n_out += kept[k].observations.size();
  }
  EXPECT_GT(st.dropped_gross, 0);
  EXPECT_EQ(n_out + static_cast<size_t>(st.dropped_gross), n_in);
}

// true_frame_motion: the camera moves 0.5 m/s along world y, looking along world x at the plane
// x = 2 m: camera-frame velocity (-0.5, 0, 0) m/s (camera x is world -y), every track 2 m deep.
TEST(TrackOracle, TrueFrameMotionGivesTheCameraVelocityAndTheTracksMedianDepth) {
  const Scenario s;
  const auto frames = s.frames(5, 0.0, 1000);
  ASSERT_GT(frames[2].observations.size(), 10u);
  Eigen::Vector3d v_c;
  double depth = 0;
  ASSERT_TRUE(true_frame_motion(s.gt, s.camera.T_c_b, s.cast, frames[2], &v_c, &depth));
  EXPECT_NEAR((v_c - Eigen::Vector3d(-0.5, 0, 0)).norm(), 0.0, 1e-9) << v_c.transpose();
  EXPECT_NEAR(depth, 2.0, 1e-9);
  // The plane x = 2 m (world) is z = 2 m in the camera frame.
  Eigen::Vector4d plane;
  ASSERT_TRUE(true_frame_motion(s.gt, s.camera.T_c_b, s.cast, frames[2], &v_c, &depth, &plane));
  EXPECT_NEAR((plane - Eigen::Vector4d(0, 0, 1, 2)).norm(), 0.0, 1e-9) << plane.transpose();
  const RayCaster nothing = [](const Eigen::Vector3d&, const Eigen::Vector3d&) { return std::optional<double>(); };
  EXPECT_FALSE(true_frame_motion(s.gt, s.camera.T_c_b, nothing, frames[2], &v_c, &depth));
  FeatureObservations late = frames[2];
  late.t_ns = 10'000'000'000;  // after the ground truth
  EXPECT_FALSE(true_frame_motion(s.gt, s.camera.T_c_b, s.cast, late, &v_c, &depth));
}

TEST(TrackOracle, TracksWithoutALandmarkAreDroppedAndOptionsAreChecked) {
  const Scenario s;
  TrackOracleStats st;
  const auto none = through_oracle(s, s.frames(5, 0.0, 1000), {},
                                   [](const Eigen::Vector3d&, const Eigen::Vector3d&) { return std::optional<double>(); }, &st);
  for (const auto& f : none) EXPECT_TRUE(f.observations.empty());
  EXPECT_GT(st.dropped, 0);
  EXPECT_EQ(st.replaced, 0);
  TrackOracleOptions bad;
  bad.white_noise_px = -1;
  EXPECT_THROW(TrackOracle(s.gt, s.camera, s.cast, bad), std::invalid_argument);
  TrackOracleOptions bad_max;
  bad_max.max_error_px = -1;
  EXPECT_THROW(TrackOracle(s.gt, s.camera, s.cast, bad_max), std::invalid_argument);
  EXPECT_THROW(TrackOracle(s.gt, s.camera, RayCaster(), {}), std::invalid_argument);
}

}  // namespace
}  // namespace evio::evaluation
