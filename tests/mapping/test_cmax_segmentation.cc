// Motion segmentation by contrast maximisation on the simulator's dynamic_3objects scene (three
// independently moving sprites over a moving background, every event labelled with its object):
// per-event label accuracy at windows where the objects move >= 4 px, the automatic cluster
// count, and labels that persist across windows. Also synthetic two-motion windows and the
// extremes. Instrument knobs (environment, for exploring; the defaults are what is asserted):
// SEG_WINDOW=N events per window, SEG_MS=ms time windows, SEG_TRACE=1 debug log of every stage,
// SEG_NOISE / SEG_GAIN / SEG_NEWPX / SEG_SPLIT / SEG_MGAIN: noise_support / min_cluster_gain /
// new_motion_px / split_rounds / model_gain_per_parameter; SEG_MODELS=flow,similarity,...: the
// candidate models; SEG_SEED / SEG_DURATION: another realisation or a longer stretch of the scene.
#include "evio/mapping/cmax_segmentation.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <random>
#include <set>

#include <gtest/gtest.h>

#include "evio/calib/log.h"
#include "evio/evaluation/label_evaluation.h"
#include "evio/simulator/scene_config.h"
#include "evio/simulator/simulator.h"
#include "evio_test/moving_patches.h"

namespace {

using evio::mapping::CmaxEvents;
using evio::mapping::MotionSegmenter;
using evio::mapping::SegmentationOptions;
using evio::mapping::WarpGeometry;
using evio::mapping::WarpModel;

struct Recording {
  std::vector<evio::Event> events;
  std::vector<uint16_t> labels;
  evio::calib::CameraIntrinsics camera;
  std::shared_ptr<evio::simulator::Simulator> sim;
};

class Collect : public evio::simulator::SimulationSink {
 public:
  explicit Collect(Recording* r) : r_(r) {}
  void on_events(const std::vector<evio::Event>& events, const std::vector<uint16_t>* labels) override {
    r_->events.insert(r_->events.end(), events.begin(), events.end());
    if (labels) r_->labels.insert(r_->labels.end(), labels->begin(), labels->end());
  }

 private:
  Recording* r_;
};

const Recording& dynamic_3objects() {
  static Recording rec = [] {
    Recording r;
    evio::set_log_sink([](evio::LogLevel, const std::string&) {});
    evio::simulator::SimulateOverrides o;
    o.duration_s = getenv("SEG_DURATION") ? std::stod(getenv("SEG_DURATION")) : 1.6;
    if (getenv("SEG_SEED")) o.seed = std::stoull(getenv("SEG_SEED"));
    const auto c = evio::simulator::load_simulation_config(std::string(EVIO_SOURCE_DIR) + "/datasets/dynamic_3objects.yaml", o);
    r.camera = c.simulator.camera.intrinsics();
    r.sim = std::make_shared<evio::simulator::Simulator>(c.scene, c.trajectory, c.simulator);
    Collect sink(&r);
    r.sim->run(&sink);
    evio::set_log_sink({});
    return r;
  }();
  return rec;
}

// "flow,similarity" -> the models.
std::vector<WarpModel> models_from(const std::string& list) {
  std::vector<WarpModel> out;
  std::string word;
  for (char c : list + ",") {
    if (c != ',') {
      word += c;
    } else if (!word.empty()) {
      out.push_back(evio::mapping::warp_model_from_name(word).value());
      word.clear();
    }
  }
  return out;
}

// Integer pixels with their dither, as the CMax pipelines add them.
void push_dithered(CmaxEvents* ev, const evio::Event& e) {
  float ox, oy;
  evio::mapping::pixel_dither(e.t_ns, e.x, e.y, &ox, &oy);
  ev->push_back(e.x + ox, e.y + oy, e.t_ns, e.polarity);
}

struct WindowScore {
  double accuracy = 0;     // share of labelled (non-noise) events whose cluster maps to their object
  int true_objects = 0;    // objects (incl. background) with >= 1% of the window's events
  int clusters = 0;
  double min_motion_px = 0;  // smallest object displacement over the window (ground-truth flow)
};

// Two textured patches (short random edges) moving with different flows over a still textured
// background; labels 0 (background), 1, 2.
struct Synthetic {
  CmaxEvents ev;
  std::vector<uint16_t> truth;
};
Synthetic two_objects(int n, uint64_t seed, int64_t t0 = 1'000'000'000, double span = 0.03) {
  WarpGeometry g;
  g.fx = g.fy = 200, g.cx = 119.5, g.cy = 89.5;
  const double v1[2] = {250, -120}, v2[2] = {-180, -200};
  Synthetic s{CmaxEvents(t0 + static_cast<int64_t>(span * 0.5e9), g), {}};
  int k = 0;
  for (const evio_test::PatchEvent& e : evio_test::moving_patches(n, seed, v1, v2, t0, span)) {
    s.ev.push_back(static_cast<float>(e.x), static_cast<float>(e.y), e.t_ns, k++ % 2 ? 1 : -1);
    s.truth.push_back(static_cast<uint16_t>(e.label));
  }
  return s;
}

// Majority mapping cluster -> true label; accuracy over events with a true label (not noise)
// (evaluation::score_labels). per_object (optional): accuracy per true label.
double label_accuracy(const std::vector<int>& pred, const uint16_t* truth, size_t n,
                      std::map<int, double>* per_object = nullptr) {
  const evio::evaluation::LabelAgreement a = evio::evaluation::score_labels(pred.data(), truth, n);
  if (per_object)
    for (const auto& [l, c] : a.scored_per_label) {
      const auto it = a.correct_per_label.find(l);
      (*per_object)[l] = static_cast<double>(it == a.correct_per_label.end() ? 0 : it->second) / static_cast<double>(c);
    }
  return a.accuracy();
}

TEST(CmaxSegmentation, DynamicThreeObjects) {
  const Recording& rec = dynamic_3objects();
  ASSERT_GT(rec.events.size(), 100000u);
  ASSERT_EQ(rec.labels.size(), rec.events.size());
  WarpGeometry g;
  g.fx = rec.camera.fx, g.fy = rec.camera.fy, g.cx = rec.camera.cx, g.cy = rec.camera.cy;
  SegmentationOptions o;
  o.cmax.width = rec.camera.width, o.cmax.height = rec.camera.height, o.cmax.geometry = g;
  if (getenv("SEG_NOISE")) o.noise_support = std::stod(getenv("SEG_NOISE"));
  if (getenv("SEG_GREEDY")) o.init = evio::mapping::SegmentationInit::kGreedy;
  if (getenv("SEG_MAXC")) o.max_clusters = std::stoi(getenv("SEG_MAXC"));
  if (getenv("SEG_GAIN")) o.min_cluster_gain = std::stod(getenv("SEG_GAIN"));
  if (getenv("SEG_NEWPX")) o.new_motion_px = std::stod(getenv("SEG_NEWPX"));
  if (getenv("SEG_SPLIT")) o.split_rounds = std::stoi(getenv("SEG_SPLIT"));
  if (getenv("SEG_MODELS")) o.models = models_from(getenv("SEG_MODELS"));
  if (getenv("SEG_MGAIN")) o.model_gain_per_parameter = std::stod(getenv("SEG_MGAIN"));
  MotionSegmenter seg(o);
  // ~0.1 s windows: long enough for the slow objects to move 2-5 px; the sinusoidally moving ones
  // depart from a constant velocity by about a pixel there (~2 px in 0.2 s windows: similarity_accel).
  const size_t window0 = getenv("SEG_WINDOW") ? std::stoul(getenv("SEG_WINDOW")) : 70000;
  if (getenv("SEG_TRACE")) {
    evio::set_log_level(evio::LogLevel::kDebug);
    evio::set_log_sink([](evio::LogLevel, const std::string& m) { std::printf("%s\n", m.c_str()); });
  }
  std::vector<evio::mapping::SegmentCluster> prev;
  int next_id = 0;
  int scored = 0, count_right = 0, windows = 0, count_right_all = 0;
  double acc_sum = 0, acc_min = 1, all_sum = 0, all_min = 1;
  std::map<int, int> last_id, switches;
  const int64_t window_ns = getenv("SEG_MS") ? static_cast<int64_t>(std::stod(getenv("SEG_MS")) * 1e6) : 0;
  for (size_t first = 0, window = window0; first < rec.events.size(); first += window) {
    if (window_ns > 0) {
      size_t last = first;
      while (last < rec.events.size() && rec.events[last].t_ns < rec.events[first].t_ns + window_ns) ++last;
      if (last == rec.events.size()) break;
      window = last - first;
    } else if (first + window > rec.events.size()) {
      break;
    }
    const int64_t t0 = rec.events[first].t_ns, t1 = rec.events[first + window - 1].t_ns;
    CmaxEvents ev((t0 + t1) / 2, g);
    ev.reserve(window);
    for (size_t k = first; k < first + window; ++k) push_dithered(&ev, rec.events[k]);
    const auto start = std::chrono::steady_clock::now();
    const auto r = seg.segment(ev, prev.empty() ? nullptr : &prev, &next_id);
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    prev = r.clusters;
    // Ground truth: objects present, and how far each moves over the window (flow at mid-time).
    std::map<int, int> count;
    for (size_t k = first; k < first + window; ++k)
      if (rec.labels[k] != 65535) ++count[rec.labels[k]];
    const auto view = rec.sim->render((t0 + t1) / 2, true);
    std::map<int, double> speed_sum;
    std::map<int, int> speed_n;
    for (int y = 0; y < view.label.rows; ++y)
      for (int x = 0; x < view.label.cols; ++x) {
        const int l = view.label.at<uint16_t>(y, x);
        const cv::Vec2f f = view.flow.at<cv::Vec2f>(y, x);
        speed_sum[l] += std::hypot(f[0], f[1]);
        ++speed_n[l];
      }
    WindowScore s;
    s.min_motion_px = 1e9;
    for (const auto& [l, c] : count) {
      if (c < 0.01 * window) continue;
      ++s.true_objects;
      if (l != 0 && speed_n[l] > 0) s.min_motion_px = std::min(s.min_motion_px, speed_sum[l] / speed_n[l] * (t1 - t0) * 1e-9);
    }
    s.clusters = static_cast<int>(r.clusters.size());
    std::map<int, double> per;
    s.accuracy = label_accuracy(r.labels, rec.labels.data() + first, window, &per);
    std::printf("window %.3f-%.3f s: %d clusters (true %d), accuracy %.3f, slowest object %.1f px, %.0f ms, %d alternations, %d evaluations; ids",
                t0 * 1e-9, t1 * 1e-9, s.clusters, s.true_objects, s.accuracy, s.min_motion_px, ms, r.alternations, r.evaluations);
    for (const auto& c : r.clusters) std::printf(" %d:%s(%.0f ev, gain %.3f)", c.id, evio::mapping::warp_model_name(c.model), c.events, c.gain);
    std::map<int, int> noise_by;
    for (size_t k = 0; k < window; ++k)
      if (r.labels[k] < 0) ++noise_by[rec.labels[first + k]];
    std::printf("\n   per object:");
    for (const auto& [l, a] : per) std::printf(" %d: %.3f (%d ev, %d as noise, %.1f px)", l, a, count[l], noise_by[l], speed_n[l] ? speed_sum[l] / speed_n[l] * (t1 - t0) * 1e-9 : 0.0);
    int true_noise = 0;
    for (size_t k = first; k < first + window; ++k) true_noise += rec.labels[k] == 65535;
    std::printf(" noise: %d of %d found", noise_by[65535], true_noise);
    if (getenv("SEG_WHERE")) {  // where each cluster's events are: mean and spread of t, x, y
      for (const auto& c : r.clusters) {
        double st = 0, sx = 0, sy = 0, stt = 0, sxx = 0, syy = 0;
        int m = 0;
        for (size_t k = 0; k < window; ++k)
          if (r.labels[k] == c.id) {
            const double t = (rec.events[first + k].t_ns - t0) * 1e-9, x = rec.events[first + k].x, y = rec.events[first + k].y;
            st += t, sx += x, sy += y, stt += t * t, sxx += x * x, syy += y * y, ++m;
          }
        if (m == 0) continue;
        auto sd = [&](double a, double aa) { return std::sqrt(std::max(0.0, aa / m - (a / m) * (a / m))); };
        std::printf("\n   cluster %d: %d events, t %.3f+-%.3f s, x %.0f+-%.0f, y %.0f+-%.0f, params %s", c.id, m, st / m, sd(st, stt), sx / m,
                    sd(sx, sxx), sy / m, sd(sy, syy), ::testing::PrintToString(c.params.transpose().eval()).c_str());
        std::map<int, int> of;  // its events by true object
        for (size_t k = 0; k < window; ++k)
          if (r.labels[k] == c.id) ++of[rec.labels[first + k]];
        std::printf(", objects");
        for (const auto& [l, cnt] : of) std::printf(" %d:%d", l == 65535 ? -1 : l, cnt);
      }
    }
    std::printf("\n   count steps:");
    for (const auto& st : r.count_steps) std::printf(" [%d clusters, smallest gain %.3f%s]", st.clusters, st.smallest_gain, st.removed ? ", removed" : "");
    std::printf("\n");
    ++windows;
    all_sum += s.accuracy;
    all_min = std::min(all_min, s.accuracy);
    if (s.clusters == s.true_objects) ++count_right_all;
    // The cluster id each object's events mostly got: a change is a label switch.
    for (const auto& [l, c] : count) {
      if (l == 65535 || c < 0.01 * window) continue;
      std::map<int, int> ids;
      for (size_t k = 0; k < window; ++k)
        if (rec.labels[first + k] == l && r.labels[k] >= 0) ++ids[r.labels[k]];
      if (ids.empty()) continue;
      const int id = std::max_element(ids.begin(), ids.end(), [](auto& a, auto& b) { return a.second < b.second; })->first;
      if (last_id.count(l) && last_id[l] != id) ++switches[l];
      last_id[l] = id;
    }
    if (s.min_motion_px >= 4.0) {
      ++scored;
      acc_sum += s.accuracy;
      acc_min = std::min(acc_min, s.accuracy);
      if (s.clusters == s.true_objects) ++count_right;
    }
  }
  std::printf("all %d windows: mean accuracy %.4f, worst %.4f, cluster count right in %d\n", windows, all_sum / windows, all_min, count_right_all);
  std::printf("windows where every object moves >= 4 px: %d, mean accuracy %.4f, worst %.4f, cluster count right in %d\n", scored,
              scored ? acc_sum / scored : 0.0, acc_min, count_right);
  std::printf("label switches per object:");
  for (const auto& [l, n] : last_id) std::printf(" %d: %d", l, switches[l]);
  std::printf("\n");
  ASSERT_GT(windows, 5);
  // Measured (1.6 s, 70k-event windows, default models flow,similarity): 0.962 over all windows
  // (the dither alone moves it by about 1.5 points), count right in 6 of 11.
  EXPECT_GE(all_sum / windows, 0.95);
  if (scored > 0) {
    EXPECT_GE(acc_sum / scored, 0.95);  // measured 0.958 (2 windows; 0.972 with similarity_accel added)
  }
  // Labels persist: the two large objects keep theirs (measured: 0 switches over 11 windows).
  EXPECT_LE(switches[1] + switches[3], 2);
}

TEST(CmaxSegmentation, TwoMovingPatchesOverAStillBackground) {
  const Synthetic s = two_objects(30000, 3);
  SegmentationOptions o;
  o.cmax.geometry = s.ev.geometry();
  MotionSegmenter seg(o);
  if (getenv("SEG_TRACE")) {
    evio::set_log_level(evio::LogLevel::kDebug);
    evio::set_log_sink([](evio::LogLevel, const std::string& m) { std::printf("%s\n", m.c_str()); });
  }
  int next = 0;
  const auto r = seg.segment(s.ev, nullptr, &next);
  std::map<int, double> per;
  const double acc = label_accuracy(r.labels, s.truth.data(), s.truth.size(), &per);
  std::printf("two patches: %zu clusters, accuracy %.4f (background %.3f, patches %.3f %.3f)\n", r.clusters.size(), acc, per[0], per[1], per[2]);
  for (const auto& c : r.clusters)
    std::printf("  id %d %s %s, %.0f events, gain %.3f\n", c.id, evio::mapping::warp_model_name(c.model),
                ::testing::PrintToString(c.params.transpose().eval()).c_str(), c.events, c.gain);
  // Measured: 3 clusters, accuracy 0.969 (background 0.972, patches 0.998 and 0.900).
  EXPECT_EQ(r.clusters.size(), 3u);
  EXPECT_GE(acc, 0.96);
  // Flow explains translating patches: no cluster needs the similarity model.
  for (const auto& c : r.clusters) EXPECT_EQ(c.model, WarpModel::kFlow) << c.id;
  // A fixed count of 3 gives the same partition; a fixed count of 1 labels everything alike.
  o.clusters = 3;
  const auto r3 = MotionSegmenter(o).segment(s.ev, nullptr, &next);
  EXPECT_GE(label_accuracy(r3.labels, s.truth.data(), s.truth.size()), 0.95);  // measured 0.958
  o.clusters = 1;
  const auto r1 = MotionSegmenter(o).segment(s.ev, nullptr, &next);
  ASSERT_EQ(r1.clusters.size(), 1u);
}

TEST(CmaxSegmentation, Extremes) {
  WarpGeometry g;
  SegmentationOptions o;
  MotionSegmenter seg(o);
  int next = 0;
  const int64_t big = 1'700'000'000'000'000'000LL;
  CmaxEvents none(big, g), one(big, g), pixel(big, g), instant(big, g);
  auto r = seg.segment(none, nullptr, &next);
  EXPECT_TRUE(r.clusters.empty());
  EXPECT_TRUE(r.labels.empty());
  one.push_back(10, 20, big + 5, 1);
  for (int k = 0; k < 3000; ++k) {
    pixel.push_back(57, 33, big + k * 1000, k % 2 ? 1 : -1);
    instant.push_back(static_cast<float>(k % 240), static_cast<float>((k * 7) % 180), big, 1);
  }
  for (const CmaxEvents* e : {&one, &pixel, &instant}) {
    r = seg.segment(*e, nullptr, &next);
    ASSERT_EQ(r.labels.size(), e->size());
    ASSERT_GE(r.clusters.size(), 1u);
    for (const auto& c : r.clusters) EXPECT_TRUE(c.params.allFinite());
    EXPECT_TRUE(r.associations.allFinite());
  }
  // A 10x burst of the same scene: the same partition.
  const Synthetic s = two_objects(300000, 3);
  o.cmax.geometry = s.ev.geometry();
  const auto rb = MotionSegmenter(o).segment(s.ev, nullptr, &next);
  EXPECT_GE(label_accuracy(rb.labels, s.truth.data(), s.truth.size()), 0.97);
  EXPECT_THROW(MotionSegmenter([] { SegmentationOptions b; b.max_clusters = 0; return b; }()), std::invalid_argument);
}

// The instrument: with the true associations, fit each object's motion, then (a) one
// association update from those motions, (b) the alternation started there. (a) bounds what the
// model and association rule can reach; (b) says whether the truth is a stable fixed point.
TEST(CmaxSegmentation, OracleAssociations) {
  const Recording& rec = dynamic_3objects();
  WarpGeometry g;
  g.fx = rec.camera.fx, g.fy = rec.camera.fy, g.cx = rec.camera.cx, g.cy = rec.camera.cy;
  SegmentationOptions o;
  o.cmax.width = rec.camera.width, o.cmax.height = rec.camera.height, o.cmax.geometry = g;
  MotionSegmenter seg(o);
  const size_t window = getenv("SEG_WINDOW") ? std::stoul(getenv("SEG_WINDOW")) : 40000;
  const WarpModel model = WarpModel::kSimilarity;
  for (size_t first = 0; first + window <= rec.events.size(); first += 4 * window) {
    const int64_t t0 = rec.events[first].t_ns, t1 = rec.events[first + window - 1].t_ns;
    CmaxEvents ev((t0 + t1) / 2, g);
    for (size_t k = first; k < first + window; ++k) push_dithered(&ev, rec.events[k]);
    std::map<int, int> count;
    for (size_t k = first; k < first + window; ++k) ++count[rec.labels[k]];
    std::vector<evio::mapping::SegmentCluster> cl;
    std::vector<std::vector<float>> w;
    evio::mapping::CmaxOptions co = o.cmax;
    co.model = model;
    co.objective = evio::mapping::CmaxObjective::kNormalizedGradientMagnitude;
    evio::mapping::ContrastMaximizer cm(co);
    for (const auto& [l, c] : count) {
      if (l == 65535) continue;
      std::vector<float> wl(window);
      for (size_t k = 0; k < window; ++k) wl[k] = rec.labels[first + k] == l ? 1.0f : (rec.labels[first + k] == 65535 ? 0.25f : 0.0f);
      const auto r = cm.maximize(ev, Eigen::VectorXd(), wl.data());
      evio::mapping::SegmentCluster sc;
      sc.id = l, sc.model = model, sc.params = r.params;
      cl.push_back(sc);
      w.push_back(wl);
      std::printf("  object %d: %d events, params %s\n", l, c, ::testing::PrintToString(r.params.transpose().eval()).c_str());
    }
    {  // least-squares similarity field of the true flow per object: flow = v + s r + w J r, r = x - c
      const auto view = rec.sim->render((t0 + t1) / 2, true);
      std::map<int, Eigen::Matrix4d> A;
      std::map<int, Eigen::Vector4d> B;
      for (int y = 0; y < view.label.rows; ++y)
        for (int x = 0; x < view.label.cols; ++x) {
          const int l = view.label.at<uint16_t>(y, x);
          const cv::Vec2f f = view.flow.at<cv::Vec2f>(y, x);
          const double rx = x - g.cx, ry = y - g.cy;
          Eigen::Matrix<double, 2, 4> J;
          J << 1, 0, rx, -ry, 0, 1, ry, rx;
          if (!A.count(l)) A[l].setZero(), B[l].setZero();
          A[l] += J.transpose() * J;
          B[l] += J.transpose() * Eigen::Vector2d(f[0], f[1]);
        }
      for (auto& [l, a] : A) {
        const Eigen::Vector4d truth = a.ldlt().solve(B[l]);
        std::printf("  true similarity field of %d: %s", l, ::testing::PrintToString(truth.transpose().eval()).c_str());
        for (size_t i = 0; i < cl.size(); ++i)
          if (cl[i].id == l && model == WarpModel::kSimilarity)
            std::printf("  objective at truth %.5g, at estimate %.5g", cm.objective(ev, truth, 0, w[i].data()), cm.objective(ev, cl[i].params, 0, w[i].data()));
        std::printf("\n");
      }
    }
    const auto one = seg.refine(ev, cl, w, 0);
    // one association update from the oracle motions:
    auto a = seg.refine(ev, cl, w, 0);
    const double acc_truth_assoc = label_accuracy(a.labels, rec.labels.data() + first, window);
    const auto b = seg.refine(ev, cl, w, 8);
    const double acc_alt = label_accuracy(b.labels, rec.labels.data() + first, window);
    std::printf("window %.3f s: labels from oracle weights %.3f; after 8 alternations %.3f (%zu clusters left); gains", t0 * 1e-9, acc_truth_assoc, acc_alt, b.clusters.size());
    // Measured 0.987-0.993 and 0.963-0.989 (40k-event windows).
    EXPECT_GE(acc_truth_assoc, 0.98);
    EXPECT_GE(acc_alt, 0.95);
    for (const auto& c : one.clusters) std::printf(" %d:%.3f", c.id, c.gain);
    std::printf("\n");
  }
}

}  // namespace
