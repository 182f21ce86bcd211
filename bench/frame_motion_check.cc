// frame_motion_check: instruments for the event frames' translation compensation on a simulated
// planes sequence (SEQ = an `evio simulate` folder, SCENE = its scene_resolved.yaml).
//   frame_motion_check SEQ SCENE 0 [f]  : per window of 15000 events, the accumulator variance
//       against a scale of the true velocity (contrast maximisation: where is the sharpest frame),
//       and the shift of 32-px patches of the compensated frame against the edge map the simulator
//       renders at the frame's stamp (phase correlation; along / across the local flow).
//   frame_motion_check SEQ SCENE N [f]  : OpenCV KLT of Shi-Tomasi (FASTDET=1: FAST) corners over N
//       frames built with the true motion, error against the true displacement of each corner's
//       scene point, binned by displacement (R=k: template refreshed every k frames).
//   frame_motion_check SEQ SCENE -1 [f] : the VIO tracker (frontend::FeatureTracker with
//       VioPipelineOptions' tracker) on frames built with the true motion, the same bins. Env:
//       EXACT=1 the velocity at each frame's stamp (else the last tracked frame's, as the pipeline
//       fed it back), STALE=1 / STALEV=1 / STALER=1 the window's first event's velocity / world
//       velocity / rotation, AGE, ROT, NOFB, WIN, EPS, LEVELS tracker options.
//   frame_motion_check SEQ SCENE -2 [f] : frames streamed as the pipeline builds them (add_events),
//       compensated with the true motion at each frame's stamp (set_motion_provider), every 10th
//       after 1 s against the rendered edges; LAG=px sets event_lag_px, VERBOSE=1 per frame.
// A fourth argument applies the pipeline's refractory and background-activity filters first.
#include <cstdio>
#include <iostream>
#include <vector>
#include "evio/evaluation/track_oracle.h"
#include "evio/frontend/event_frame.h"
#include "evio/sensors/dataset.h"
#include "evio/simulator/scene.h"
#include "evio/sensors/dataset_calibration.h"
#include "evio/sensors/trajectory.h"
#include "evio/simulator/scene_config.h"
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>
#include "evio/calib/geometry.h"
#include "evio/simulator/simulator.h"
#include "evio/frontend/event_filters.h"
#include "evio/frontend/feature_tracker.h"
#include "evio/pipeline/vio_pipeline.h"
#include <map>
#include <opencv2/features2d.hpp>
using namespace evio;
// Mean shift (px) of 32-px patches of a compensated accumulator against the edge density
// |grad log I . flow| the simulator renders at t_ref (camera clock), along and across the local
// flow; patches with too few events, a weak correlation or shifts over 5 px are skipped.
struct Shift { double along = 0, across = 0, flow = 0; int n = 0; };
Shift edge_shift(const calib::CameraCalibration& cal, const simulator::Simulator& sim, const cv::Mat& acc, int64_t t_ref) {
  const calib::CameraIntrinsics& in = cal.camera.intrinsics();
  const simulator::RenderedView rv = sim.render(t_ref + cal.time_shift_ns, true);
  cv::Mat dd(rv.intensity.size(), CV_32F, cv::Scalar(0));
  for (int y = 1; y + 1 < dd.rows; ++y)
    for (int x = 1; x + 1 < dd.cols; ++x) {
      auto L = [&](int xx, int yy) { return std::log(rv.intensity.at<float>(yy, xx) + 1e-3f); };
      const float gx = 0.5f * (L(x + 1, y) - L(x - 1, y)), gy = 0.5f * (L(x, y + 1) - L(x, y - 1));
      const cv::Vec2f fl = rv.flow.at<cv::Vec2f>(y, x);
      dd.at<float>(y, x) = std::abs(gx * fl[0] + gy * fl[1]);
    }
  cv::Mat P(dd.size(), CV_32F, cv::Scalar(0)), FX(dd.size(), CV_32F, cv::Scalar(0)), FY(dd.size(), CV_32F, cv::Scalar(0));
  for (int y = 0; y < P.rows; ++y)
    for (int x = 0; x < P.cols; ++x) {
      Eigen::Vector2d px;
      if (!cal.camera.project(Eigen::Vector3d((x - in.cx) / in.fx, (y - in.cy) / in.fy, 1.0), &px)) continue;
      const int x0 = (int)std::floor(px.x()), y0 = (int)std::floor(px.y());
      if (x0 < 0 || y0 < 0 || x0 + 1 >= dd.cols || y0 + 1 >= dd.rows) continue;
      const float ax = px.x() - x0, ay = px.y() - y0;
      P.at<float>(y, x) = (1 - ax) * (1 - ay) * dd.at<float>(y0, x0) + ax * (1 - ay) * dd.at<float>(y0, x0 + 1) + (1 - ax) * ay * dd.at<float>(y0 + 1, x0) + ax * ay * dd.at<float>(y0 + 1, x0 + 1);
      FX.at<float>(y, x) = rv.flow.at<cv::Vec2f>(y0, x0)[0];
      FY.at<float>(y, x) = rv.flow.at<cv::Vec2f>(y0, x0)[1];
    }
  Shift r;
  const int S = 32;
  for (int y = 8; y + S <= P.rows - 8; y += S)
    for (int x = 8; x + S <= P.cols - 8; x += S) {
      cv::Rect q(x, y, S, S);
      cv::Mat a = acc(q).clone(), p = P(q).clone();
      if (cv::sum(a)[0] < 50 || cv::sum(p)[0] <= 0) continue;
      double resp = 0;
      cv::Point2d sh = cv::phaseCorrelate(p, a, cv::noArray(), &resp);
      if (resp < 0.1 || std::hypot(sh.x, sh.y) > 5) continue;
      const double fx = cv::mean(FX(q))[0], fy = cv::mean(FY(q))[0], fn = std::hypot(fx, fy);
      if (fn < 1) continue;
      r.along += (sh.x * fx + sh.y * fy) / fn;
      r.across += (-sh.x * fy + sh.y * fx) / fn;
      r.flow += fn;
      ++r.n;
    }
  return r;
}

int main(int argc, char** argv) {
  const std::string seq = argv[1], scene = argv[2];
  auto reader = open_dataset(seq);
  auto cal = *find_dataset_calibration(seq, "", *reader).camera;
  std::vector<ImuSample> imu = reader->read_imu();
  std::vector<Event> ev; EventBuffer chunk;
  while (reader->read_events(&chunk, size_t{1} << 20) > 0) { ev.insert(ev.end(), chunk.begin(), chunk.end()); chunk.clear(); }
  if (argc > 4) {
    frontend::RefractoryFilter rf(cal.camera.width(), cal.camera.height());
    frontend::BackgroundActivityFilter bf(cal.camera.width(), cal.camera.height());
    std::vector<Event> kept;
    for (const Event& e : ev) if (rf.accept(e) && bf.accept(e)) kept.push_back(e);
    printf("filters keep %zu of %zu\n", kept.size(), ev.size());
    ev.swap(kept);
  }
  const auto gt = read_trajectory(seq + "/groundtruth.txt");
  const auto sc = simulator::load_simulation_config(scene);
  auto planes = std::dynamic_pointer_cast<const simulator::PlanarScene>(sc.scene);
  evaluation::RayCaster cast = [planes](const Eigen::Vector3d& o, const Eigen::Vector3d& d) { return planes->intersect(o, d); };
  simulator::Simulator sim(sc.scene, sc.trajectory, sc.simulator);
  frontend::EventFrameOptions o;
  o.use_depth = true;
  frontend::EventFrameBuilder b(cal, o);
  const int N = 15000;
  for (auto& s : imu) b.add_imu(s);
  


  if (argc > 3 && std::atoi(argv[3]) == -2) {
    // Frames as the pipeline streams them (add_events), compensated with the true motion at each
    // frame's stamp, LAG=px for event_lag_px: their shift against the rendered edges.
    const auto K0 = b.K();
    frontend::EventFrameOptions lo = o;
    lo.min_window_ns = 10'000'000;
    if (getenv("LAG")) lo.event_lag_px = std::atof(getenv("LAG"));
    frontend::EventFrameBuilder fb(cal, lo);
    for (auto& x : imu) fb.add_imu(x);
    fb.set_motion_provider([&](int64_t t_ref, frontend::FrameMotion* m) {
      FeatureObservations g;
      g.t_ns = t_ref + cal.time_shift_ns;
      for (int y = 20; y < 180; y += 20)
        for (int x = 20; x < 240; x += 20)
          g.observations.push_back({y * 1000 + x, Eigen::Vector3d((x - K0(0, 2)) / K0(0, 0), (y - K0(1, 2)) / K0(1, 1), 1).normalized()});
      Eigen::Vector4d pl;
      if (!evaluation::true_frame_motion(gt, cal.T_c_b, cast, g, &m->v_c, &m->depth_m, &pl)) return false;
      if (pl.w() > 0) { m->plane_n_c = pl.head<3>(); m->plane_d_m = pl.w(); }
      return true;
    });
    std::vector<frontend::EventFrame> out;
    Shift sum;
    int frames = 0;
    for (size_t i = 0; i < ev.size(); i += 3750) {
      out.clear();
      fb.add_events(EventSpan(ev.data() + i, std::min<size_t>(3750, ev.size() - i)), &out);
      for (auto& ef : out) {
        if (ef.t_ns < 1'000'000'000 || (frames++ % 10) != 0) continue;
        const Shift r = edge_shift(cal, sim, ef.accumulator, ef.t_ns);
        if (r.n == 0) continue;
        sum.along += r.along / r.n; sum.across += r.across / r.n; sum.flow += r.flow / r.n; ++sum.n;
        if (getenv("VERBOSE")) printf("  frame at %.2f s: along %+.3f px, flow %.0f px/s, window %.1f ms\n", ef.t_ns * 1e-9, r.along / r.n, r.flow / r.n, (ef.t_end_ns - ef.t_begin_ns) * 1e-6);
      }
    }
    printf("LAG %s: %d frames, mean shift against the rendered edges along the flow %+.3f px, across %+.3f px (flow %.0f px/s)\n",
           getenv("LAG") ? getenv("LAG") : "0", sum.n, sum.along / sum.n, sum.across / sum.n, sum.flow / sum.n);
    return 0;
  }
  if (argc > 3 && std::atoi(argv[3]) == -1) {
    // the pipeline's tracker on frames built like the pipeline's, with the true motion fed back
    const auto K0 = b.K();
    pipeline::VioPipelineOptions po;
    if (getenv("LEVELS")) po.tracker.klt_pyramid_levels = atoi(getenv("LEVELS"));
    if (getenv("AGE")) po.tracker.template_max_age_frames = atoi(getenv("AGE"));
    if (getenv("WIN")) po.tracker.klt_window_px = atoi(getenv("WIN"));
    if (getenv("ROT")) po.tracker.template_max_rotation_deg = atof(getenv("ROT"));
    if (getenv("NOFB")) po.tracker.template_fallback = false;
    if (getenv("EPS")) po.tracker.klt_epsilon_px = atof(getenv("EPS"));
    calib::CameraIntrinsics ideal = cal.camera.intrinsics();
    ideal.model = calib::DistortionModel::kNone; ideal.distortion.clear();
    for (double sc : {0.0, 1.0}) {
      frontend::EventFrameBuilder fb(cal, o);
      for (auto& s : imu) fb.add_imu(s);
      frontend::FeatureTracker tr(ideal, po.tracker);
      auto T_w_c = [&](int64_t t_cam) { return evaluation::groundtruth_state(gt, t_cam + cal.time_shift_ns)->T_w_b * cal.T_c_b.inverse(); };
      std::map<int64_t, Eigen::Vector3d> X;  // anchored landmark per track
      std::map<int64_t, Eigen::Vector2d> first;
      std::vector<double> ba(6, 0), bc(6, 0); std::vector<int> bn(6, 0);
      int64_t prev_t = -1;
      std::vector<frontend::EventFrame> out;
      for (size_t i = 0; i < ev.size(); i += 3750) {
        out.clear();
        if (getenv("EXACT")) {
          if (i % N != 0 || i + N > ev.size()) continue;
          EventSpan w(ev.data() + i, N);
          FeatureObservations g; g.t_ns = getenv("STALE") ? w.front().t_ns : w.back().t_ns;
          for (int y = 20; y < 180; y += 20) for (int x = 20; x < 240; x += 20)
            g.observations.push_back({y * 1000 + x, Eigen::Vector3d((x - K0(0, 2)) / K0(0, 0), (y - K0(1, 2)) / K0(1, 1), 1).normalized()});
          Eigen::Vector3d v; double d; Eigen::Vector4d pl;
          if (evaluation::true_frame_motion(gt, cal.T_c_b, cast, g, &v, &d, &pl)) {
            if (getenv("STALEV")) {
              const auto s0 = evaluation::groundtruth_state(gt, w.front().t_ns), s1 = evaluation::groundtruth_state(gt, w.back().t_ns);
              v = cal.T_c_b.rotation * (s1->T_w_b.rotation.conjugate() * s0->v_w);
            }
            if (getenv("STALER")) {
              const auto s0 = evaluation::groundtruth_state(gt, w.front().t_ns), s1 = evaluation::groundtruth_state(gt, w.back().t_ns);
              v = cal.T_c_b.rotation * (s0->T_w_b.rotation.conjugate() * s1->v_w);
            }
          }
          if (true) fb.set_motion_plane(v * sc + Eigen::Vector3d(1e-12, 0, 0), pl.head<3>(), pl.w());
          out.push_back(fb.build_frame(w, w.back().t_ns));
        } else {
        fb.add_events(EventSpan(ev.data() + i, std::min<size_t>(3750, ev.size() - i)), &out);
        }
        for (auto& ef : out) {
          if (ef.t_ns < 2'000'000'000) { prev_t = ef.t_ns; continue; }
          const calib::SE3 Twc = T_w_c(ef.t_ns);
          Eigen::Matrix3d R;
          if (prev_t >= 0) R = (Twc.inverse() * T_w_c(prev_t)).rotation_matrix();
          FeatureObservations f = tr.track(ef.t_ns, ef.image, prev_t >= 0 ? &R : nullptr);
          prev_t = ef.t_ns;
          for (auto& ob : f.observations) {
            const Eigen::Vector2d px(K0(0, 0) * ob.bearing_c.x() / ob.bearing_c.z() + K0(0, 2), K0(1, 1) * ob.bearing_c.y() / ob.bearing_c.z() + K0(1, 2));
            auto it = X.find(ob.track_id);
            if (it == X.end()) {
              const Eigen::Vector3d d = Twc.rotation * ob.bearing_c.normalized();
              if (auto r = cast(Twc.translation, d)) { X[ob.track_id] = Twc.translation + *r * d; first[ob.track_id] = px; }
              continue;
            }
            const Eigen::Vector3d q = Twc.inverse() * it->second;
            const Eigen::Vector2d pt(K0(0, 0) * q.x() / q.z() + K0(0, 2), K0(1, 1) * q.y() / q.z() + K0(1, 2));
            const Eigen::Vector2d D = pt - first[ob.track_id], e = px - pt;
            if (e.norm() > 10 || D.norm() < 1) continue;
            const Eigen::Vector2d u = D.normalized();
            const int bin = std::min(5, (int)(D.norm() / 10));
            ba[bin] += e.dot(u); bc[bin] += u.x() * e.y() - u.y() * e.x(); ++bn[bin];
          }
          Eigen::Vector3d v; double d; Eigen::Vector4d pl;
          if (!getenv("EXACT") && evaluation::true_frame_motion(gt, cal.T_c_b, cast, f, &v, &d, &pl)) fb.set_motion_plane(v * sc + Eigen::Vector3d(1e-12, 0, 0), pl.head<3>(), pl.w());
        }
      }
      printf("tracker, scale %.0f: fallbacks %lld rotation refreshes %lld tracked %lld;", sc, (long long)tr.stats().template_fallbacks, (long long)tr.stats().template_rotation_refreshes, (long long)tr.stats().tracked);
      for (int i = 0; i < 6; ++i) if (bn[i]) printf(" [%d] %+.3f/%+.3f (n %d)", i * 10, ba[i] / bn[i], bc[i] / bn[i], bn[i]);
      printf("\n");
    }
    return 0;
  }
  if (argc > 3 && std::atoi(argv[3]) > 0) {
    const int M = std::atoi(argv[3]); const int R = getenv("R") ? atoi(getenv("R")) : 10;
    const auto K0 = b.K();
    auto motion_at = [&](int64_t t_ref, Eigen::Vector3d* v, Eigen::Vector4d* pl) {
      FeatureObservations f;
      f.t_ns = t_ref + cal.time_shift_ns;
      for (int y = 20; y < 180; y += 20)
        for (int x = 20; x < 240; x += 20)
          f.observations.push_back({y * 1000 + x, Eigen::Vector3d((x - K0(0, 2)) / K0(0, 0), (y - K0(1, 2)) / K0(1, 1), 1).normalized()});
      double d;
      return evaluation::true_frame_motion(gt, cal.T_c_b, cast, f, v, &d, pl);
    };
    auto T_w_c = [&](int64_t t_cam) { return evaluation::groundtruth_state(gt, t_cam + cal.time_shift_ns)->T_w_b * cal.T_c_b.inverse(); };
    for (int mode : {0, 1}) for (double sc : {0.0, 1.0}) {
      std::vector<double> bins_along(6, 0), bins_across(6, 0); std::vector<int> bins_n(6, 0);
      for (size_t start = 1500000; start + (M + 1) * N < ev.size(); start += 300000) {
        std::vector<frontend::EventFrame> fr;
        bool ok = true;
        for (int k = 0; k <= M; ++k) {
          EventSpan w(ev.data() + start + k * N, N);
          Eigen::Vector3d v; Eigen::Vector4d pl;
          if (!motion_at(w.back().t_ns, &v, &pl)) { ok = false; break; }
          b.set_motion_plane(v * sc + Eigen::Vector3d(1e-12, 0, 0), pl.head<3>(), pl.w());
          fr.push_back(b.build_frame(w, w.back().t_ns));
        }
        if (!ok) continue;
        std::vector<cv::Point2f> p0;
        if (getenv("FASTDET")) {
          std::vector<cv::KeyPoint> kp;
          cv::FAST(fr[0].image, kp, 20, true);
          std::sort(kp.begin(), kp.end(), [](const cv::KeyPoint& a, const cv::KeyPoint& b) { return a.response > b.response; });
          for (size_t i = 0; i < kp.size() && i < 60; ++i) if (kp[i].pt.x > 15 && kp[i].pt.y > 15 && kp[i].pt.x < 225 && kp[i].pt.y < 165) p0.push_back(kp[i].pt);
        } else {
          cv::goodFeaturesToTrack(fr[0].image, p0, 60, 0.05, 10);
        }
        if (p0.empty()) continue;
        const calib::SE3 Tw0 = T_w_c(fr[0].t_ns);
        std::vector<Eigen::Vector3d> X(p0.size());
        std::vector<bool> hit(p0.size(), false);
        for (size_t i = 0; i < p0.size(); ++i) {
          Eigen::Vector3d d = Tw0.rotation * Eigen::Vector3d((p0[i].x - K0(0, 2)) / K0(0, 0), (p0[i].y - K0(1, 2)) / K0(1, 1), 1).normalized();
          auto r = cast(Tw0.translation, d);
          if (r) { X[i] = Tw0.translation + *r * d; hit[i] = true; }
        }
        std::vector<cv::Point2f> ref = p0, cur = p0;
        std::vector<uchar> alive(p0.size(), 1);
        int ref_k = 0;
        for (int k = 1; k <= M; ++k) {
          const calib::SE3 Tck = T_w_c(fr[k].t_ns).inverse();
          std::vector<cv::Point2f> pt(p0.size()), p1;
          for (size_t i = 0; i < p0.size(); ++i) {
            const Eigen::Vector3d q = Tck * X[i];
            pt[i] = cv::Point2f(K0(0, 0) * q.x() / q.z() + K0(0, 2), K0(1, 1) * q.y() / q.z() + K0(1, 2));
          }
          p1 = pt;
          if (mode == 1) {  // prior: previous position rotated by the true rotation
            const Eigen::Matrix3d R = (Tck * T_w_c(fr[k - 1].t_ns)).rotation_matrix();
            for (size_t i = 0; i < p0.size(); ++i) {
              Eigen::Vector3d q = R * Eigen::Vector3d((cur[i].x - K0(0, 2)) / K0(0, 0), (cur[i].y - K0(1, 2)) / K0(1, 1), 1);
              p1[i] = cv::Point2f(K0(0, 0) * q.x() / q.z() + K0(0, 2), K0(1, 1) * q.y() / q.z() + K0(1, 2));
            }
          }
          std::vector<uchar> st; std::vector<float> er;
          cv::calcOpticalFlowPyrLK(fr[ref_k].image, fr[k].image, ref, p1, st, er, cv::Size(27, 27), 2,
                                   cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 30, 0.01), cv::OPTFLOW_USE_INITIAL_FLOW);
          for (size_t i = 0; i < p0.size(); ++i) {
            if (!st[i]) alive[i] = 0;
            if (!alive[i] || !hit[i]) continue;
            const Eigen::Vector2d D(pt[i].x - p0[i].x, pt[i].y - p0[i].y);
            const Eigen::Vector2d e(p1[i].x - pt[i].x, p1[i].y - pt[i].y);
            if (e.norm() > 5) { alive[i] = 0; continue; }
            if (D.norm() < 1) continue;
            const Eigen::Vector2d u = D.normalized();
            const int bin = std::min(5, (int)(D.norm() / 10));
            bins_along[bin] += e.dot(u); bins_across[bin] += u.x() * e.y() - u.y() * e.x(); ++bins_n[bin];
          }
          cur = p1;
          if (k % R == 0) { ref = p1; ref_k = k; }
        }
      }
      printf("init %s scale %.0f: KLT error vs true displacement, by displacement (10 px bins): ", mode ? "rotation" : "true", sc);
      for (int i = 0; i < 6; ++i) if (bins_n[i]) printf(" [%d] %+.3f/%+.3f (n %d)", i * 10, bins_along[i] / bins_n[i], bins_across[i] / bins_n[i], bins_n[i]);
      printf("\n");
    }
    return 0;
  }
  const double scales[] = {0, 0.5, 0.75, 0.9, 1.0, 1.1, 1.25, 1.5, 2.0};
  std::vector<double> sum(9, 0);
  int n = 0;
  const auto K = b.K();
  for (size_t start = 2000000; start + N < ev.size(); start += 400000) {
    EventSpan w(ev.data() + start, N);
    const int64_t t_ref = w.back().t_ns;
    FeatureObservations f;
    f.t_ns = t_ref + cal.time_shift_ns;
    for (int y = 20; y < 180; y += 20)
      for (int x = 20; x < 240; x += 20)
        f.observations.push_back({y * 1000 + x, Eigen::Vector3d((x - K(0, 2)) / K(0, 0), (y - K(1, 2)) / K(1, 1), 1).normalized()});
    Eigen::Vector3d v; double d; Eigen::Vector4d pl;
    if (!evaluation::true_frame_motion(gt, cal.T_c_b, cast, f, &v, &d, &pl)) continue;
    std::vector<double> var;
    for (double s : scales) {
      b.set_motion_plane(v * s + Eigen::Vector3d(1e-12, 0, 0), pl.head<3>(), pl.w());
      auto fr = b.build_frame(w, t_ref);
      cv::Scalar m, sd; cv::meanStdDev(fr.accumulator, m, sd);
      var.push_back(sd[0] * sd[0]);
    }
    // Position against the predicted edge density at t_ref, rotation only and with the true translation.
    for (double sc : {0.0, 1.0}) {
      b.set_motion_plane(v * sc + Eigen::Vector3d(1e-12, 0, 0), pl.head<3>(), pl.w());
      const Shift r = edge_shift(cal, sim, b.build_frame(w, t_ref).accumulator, t_ref);
      if (r.n == 0) continue;
      printf("  scale %.0f: %d patches, shift along flow %+.3f px, across %+.3f px, mean flow %.0f px/s (x window %.1f px)\n", sc, r.n,
             r.along / r.n, r.across / r.n, r.flow / r.n, r.flow / r.n * (w.back().t_ns - w.front().t_ns) * 1e-9);
    }
    printf("t %.2f |v| %.2f d %.2f win %.1f ms:", t_ref * 1e-9, v.norm(), pl.w(), (w.back().t_ns - w.front().t_ns) * 1e-6);
    for (size_t i = 0; i < var.size(); ++i) { printf(" %.4f", var[i] / var[4]); sum[i] += var[i] / var[4]; }
    printf("\n"); ++n;
  }
  printf("mean:"); for (double s : sum) printf(" %.4f", s / n); printf("\n");
}
