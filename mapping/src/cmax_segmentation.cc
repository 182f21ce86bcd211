// Motion segmentation by contrast maximisation with soft event-cluster associations.
#include "evio/mapping/cmax_segmentation.h"

#include "evio/calib/log.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <memory>
#include <random>
#include <sstream>
#include <stdexcept>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

namespace evio::mapping {

struct MotionSegmenter::State {
  std::vector<SegmentCluster> cl;
  std::vector<std::vector<float>> w;  // w[j][k]: association of event k with cluster j
  std::map<WarpModel, std::unique_ptr<ContrastMaximizer>> cm;  // one per model (level 0 only)
  std::vector<float> support;         // per event: the clusters' blurred IWEs at its warped positions, summed
  std::vector<int> nearest;           // per cluster: the other cluster whose motion is closest on its events
  int alternations = 0;
  int evaluations = 0;
  double self_vote = 1.0;  // what an event's own vote puts at its position after the blur

  ContrastMaximizer& maximizer(WarpModel m, const CmaxOptions& base, int iterations) {
    auto& p = cm[m];
    if (!p) {
      CmaxOptions o = base;
      o.model = m;
      o.pyramid_levels = 1;
      o.max_iterations = iterations;
      p = std::make_unique<ContrastMaximizer>(o);
    }
    return *p;
  }
};

namespace {


// The flow (px/s) a motion gives at point (x, y) at t_ref: the central difference of the warp over
// +-1 ms (for the accelerated models the velocity at t_ref, without the acceleration's term).
Eigen::Vector2d flow_at(WarpModel m, const Eigen::VectorXd& p, const WarpGeometry& g, double x, double y) {
  CmaxEvents probe(0, g);
  probe.push_back(static_cast<float>(x), static_cast<float>(y), 1'000'000, 1);
  probe.push_back(static_cast<float>(x), static_cast<float>(y), -1'000'000, 1);
  Eigen::Vector2d w1, w0;
  if (!warp_event(m, probe, 0, p, &w1) || !warp_event(m, probe, 1, p, &w0)) return Eigen::Vector2d::Zero();
  return (w0 - w1) / 2e-3;
}

// Parameters of model `to` whose flow at (x, y) matches flow v (a starting point for the optimiser).
Eigen::VectorXd params_from_flow(WarpModel to, const Eigen::Vector2d& v, const WarpGeometry& g) {
  Eigen::VectorXd p = Eigen::VectorXd::Zero(warp_dof(to));
  switch (to) {
    case WarpModel::kFlow:
    case WarpModel::kSimilarity:
    case WarpModel::kFlowAccel:
    case WarpModel::kSimilarityAccel: p[0] = v.x(), p[1] = v.y(); break;
    case WarpModel::kRotation: p[0] = v.y() / g.fy, p[1] = -v.x() / g.fx; break;
    case WarpModel::kSixDof: p[3] = v.y() / g.fy, p[4] = -v.x() / g.fx; break;
  }
  return p;
}

// Parameters of model `to` for the motion (from, p): the same velocity part where the models
// share it (flow into similarity), else the same flow at `at`; an acceleration carries over
// between accelerated models and is dropped otherwise.
Eigen::VectorXd convert(WarpModel from, const Eigen::VectorXd& p, WarpModel to, const WarpGeometry& g,
                        const Eigen::Vector2d& at) {
  if (from == to) return p;
  const WarpModel vf = warp_velocity_model(from), vt = warp_velocity_model(to);
  const Eigen::VectorXd pv = p.head(warp_dof(vf));
  Eigen::VectorXd q;
  if (vf == vt) {
    q = pv;
  } else if (vf == WarpModel::kFlow && vt == WarpModel::kSimilarity) {
    q = Eigen::VectorXd::Zero(4);
    q.head<2>() = pv;
  } else {
    q = params_from_flow(vt, flow_at(vf, pv, g, at.x(), at.y()), g);
  }
  if (vt == to) return q;
  Eigen::VectorXd out = Eigen::VectorXd::Zero(warp_dof(to));
  out.head(q.size()) = q;
  if (vf != from) out.tail<2>() = p.tail<2>();
  return out;
}

// k-means (Lloyd) on 2-D points with k-means++ seeding; returns the centres.
std::vector<Eigen::Vector2d> kmeans(const std::vector<Eigen::Vector2d>& pts, int k, uint64_t seed,
                                    std::vector<int>* assignment) {
  std::vector<Eigen::Vector2d> c;
  if (pts.empty() || k <= 0) return c;
  k = std::min<int>(k, static_cast<int>(pts.size()));
  std::mt19937_64 rng(seed);
  c.push_back(pts[std::uniform_int_distribution<size_t>(0, pts.size() - 1)(rng)]);
  std::vector<double> d2(pts.size());
  while (static_cast<int>(c.size()) < k) {
    double sum = 0;
    for (size_t i = 0; i < pts.size(); ++i) {
      double best = std::numeric_limits<double>::infinity();
      for (const auto& q : c) best = std::min(best, (pts[i] - q).squaredNorm());
      d2[i] = best;
      sum += best;
    }
    if (!(sum > 0)) break;  // fewer distinct points than k
    double r = std::uniform_real_distribution<double>(0, sum)(rng);
    size_t pick = 0;
    for (; pick + 1 < pts.size(); ++pick) {
      r -= d2[pick];
      if (r <= 0) break;
    }
    c.push_back(pts[pick]);
  }
  std::vector<int> a(pts.size(), -1);
  for (int it = 0; it < 100; ++it) {
    bool changed = false;
    for (size_t i = 0; i < pts.size(); ++i) {
      int best = 0;
      for (size_t j = 1; j < c.size(); ++j)
        if ((pts[i] - c[j]).squaredNorm() < (pts[i] - c[best]).squaredNorm()) best = static_cast<int>(j);
      if (a[i] != best) a[i] = best, changed = true;
    }
    if (!changed) break;
    std::vector<Eigen::Vector2d> sum(c.size(), Eigen::Vector2d::Zero());
    std::vector<int> cnt(c.size(), 0);
    for (size_t i = 0; i < pts.size(); ++i) sum[a[i]] += pts[i], ++cnt[a[i]];
    for (size_t j = 0; j < c.size(); ++j)
      if (cnt[j] > 0) c[j] = sum[j] / cnt[j];
  }
  *assignment = a;
  return c;
}

// One line per cluster, for debug logs.
std::string describe(const char* stage, const std::vector<SegmentCluster>& cl) {
  std::ostringstream o;
  o.precision(4);
  o << "segmentation " << stage << ":";
  for (const auto& c : cl) {
    o << "\n  id " << c.id << " " << warp_model_name(c.model) << " [" << c.params.transpose() << "] events " << c.events
      << " gain " << c.gain;
  }
  return o.str();
}

}  // namespace

const char* segmentation_init_name(SegmentationInit i) { return i == SegmentationInit::kKmeans ? "kmeans" : "greedy"; }

std::optional<SegmentationInit> segmentation_init_from_name(const std::string& name) {
  if (name == "kmeans") return SegmentationInit::kKmeans;
  if (name == "greedy") return SegmentationInit::kGreedy;
  return std::nullopt;
}

bool SegmentationOptions::Validate(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!cmax.Validate(why)) return false;
  if (clusters < 0 || clusters > 16) return fail("clusters must be in [0, 16] (0 = automatic)");
  if (max_clusters < 1 || max_clusters > 16) return fail("max_clusters must be in [1, 16]");
  if (tile_px < 8) return fail("tile_px must be >= 8 px");
  if (min_tile_events < 5) return fail("min_tile_events must be >= 5");
  if (iterations < 1 || motion_iterations < 1) return fail("iterations and motion_iterations must be >= 1");
  if (!(association_tolerance >= 0 && association_tolerance <= 1)) return fail("association_tolerance must be in [0, 1]");
  if (!(min_cluster_share >= 0 && min_cluster_share < 1)) return fail("min_cluster_share must be in [0, 1)");
  if (!(min_cluster_gain > 0 && std::isfinite(min_cluster_gain))) return fail("min_cluster_gain must be positive");
  if (!(model_gain_per_parameter >= 0 && std::isfinite(model_gain_per_parameter)))
    return fail("model_gain_per_parameter must be >= 0");
  if (!(noise_support >= 0 && std::isfinite(noise_support))) return fail("noise_support must be >= 0");
  if (!(new_motion_px >= 0 && std::isfinite(new_motion_px))) return fail("new_motion_px must be >= 0 px");
  if (split_rounds < 0 || split_rounds > 8) return fail("split_rounds must be in 0..8");
  if (footprint_radius_px < 0 || footprint_radius_px > 100) return fail("footprint_radius_px must be in [0, 100] px");
  return true;
}

MotionSegmenter::MotionSegmenter(const SegmentationOptions& options) : options_(options) {
  std::string why;
  if (!options_.Validate(&why)) throw std::invalid_argument("segmentation options: " + why);
  if (options_.models.empty()) options_.models = {WarpModel::kFlow};
  options_.models = sort_warp_models(options_.models);
  cm_options_ = options_.cmax;
  if (cm_options_.objective == CmaxObjective::kAuto) cm_options_.objective = CmaxObjective::kNormalizedGradientMagnitude;
}

double MotionSegmenter::self_vote() const {
  // A lone, pixel-centred event's own contribution at its position after the blur.
  const double sigma = cm_options_.blur_sigma_px;
  if (!(sigma > 0)) return 1.0;
  const int r = std::max(1, static_cast<int>(std::ceil(3.0 * sigma)));
  double sum = 0;
  for (int i = -r; i <= r; ++i) sum += std::exp(-0.5 * i * i / (sigma * sigma));
  return 1.0 / (sum * sum);
}

void MotionSegmenter::tile_flows(const CmaxEvents& ev, std::vector<Eigen::Vector2d>* flows,
                                 std::vector<Eigen::Vector2d>* centres) {
  flows->clear();
  centres->clear();
  const int T = options_.tile_px, margin = T / 2;
  const int nx = (cm_options_.width + T - 1) / T, ny = (cm_options_.height + T - 1) / T;
  std::vector<std::vector<size_t>> members(static_cast<size_t>(nx) * ny);
  for (size_t k = 0; k < ev.size(); ++k) {
    const int i = static_cast<int>(std::floor(ev.x[k] / T)), j = static_cast<int>(std::floor(ev.y[k] / T));
    if (i >= 0 && j >= 0 && i < nx && j < ny) members[static_cast<size_t>(j) * nx + i].push_back(k);
  }
  CmaxOptions o;
  o.model = WarpModel::kFlow;
  o.objective = CmaxObjective::kVariance;
  o.width = o.height = T + 2 * margin;
  o.blur_sigma_px = cm_options_.blur_sigma_px;
  o.pyramid_levels = 2;
  ContrastMaximizer cm(o);
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const auto& m = members[static_cast<size_t>(j) * nx + i];
      if (static_cast<int>(m.size()) < options_.min_tile_events) continue;
      CmaxEvents t(ev.t_ref_ns(), ev.geometry());
      t.reserve(m.size());
      for (size_t k : m)
        t.push_back(ev.x[k] - static_cast<float>(i * T - margin), ev.y[k] - static_cast<float>(j * T - margin),
                    ev.t_ref_ns() + static_cast<int64_t>(std::llround(static_cast<double>(ev.dt_s[k]) * 1e9)),
                    ev.pol[k] > 0 ? 1 : -1);
      const CmaxResult r = cm.maximize(t);
      if (!(r.objective > r.objective_zero)) continue;  // no texture to focus
      flows->push_back(r.params);
      centres->emplace_back((i + 0.5) * T, (j + 0.5) * T);
    }
  }
}

void MotionSegmenter::compute_gains(const CmaxEvents& ev, State* s) {
  // On hard assignments (each event to its most likely cluster): with soft ones, a cluster's IWE
  // also holds fractions of the other clusters' events, which are sharp under their own motions
  // and make every motion look alike.
  const size_t n = ev.size(), N = s->cl.size();
  std::vector<std::vector<uint32_t>> mine(N);
  for (size_t k = 0; k < n; ++k) {
    size_t best = 0;
    for (size_t j = 1; j < N; ++j)
      if (s->w[j][k] > s->w[best][k]) best = j;
    mine[best].push_back(static_cast<uint32_t>(k));
  }
  for (size_t j = 0; j < N; ++j) {
    SegmentCluster& c = s->cl[j];
    const CmaxEvents sub = ev.select(mine[j]);
    auto f = [&](WarpModel m, const Eigen::VectorXd& p) {
      ++s->evaluations;
      return sub.empty() ? 0.0 : s->maximizer(m, cm_options_, options_.motion_iterations).objective(sub, p, 0);
    };
    c.objective = f(c.model, c.params);
    c.objective_other = 0;
    for (size_t i = 0; i < N; ++i)
      if (i != j) {
        const double v = f(s->cl[i].model, s->cl[i].params);
        c.objective_other = std::max(c.objective_other, v);
      }
    c.gain = (N > 1 && c.objective_other > 0) ? c.objective / c.objective_other - 1.0 : 0.0;
  }
  // Where a removed cluster's events go: the cluster whose flow is closest to its own at its
  // events (mean flow difference over up to 256 of them). Not the best-scoring other: under the normalised
  // objective a near-still motion scores about 1 on any events, often above the right motion
  // slightly off, and would take over an object's events (and then its motion).
  s->nearest.assign(N, -1);
  const WarpGeometry& g = cm_options_.geometry;
  for (size_t j = 0; j < N; ++j) {
    const size_t m = mine[j].size(), step = std::max<size_t>(1, m / 256);
    double best = std::numeric_limits<double>::infinity();
    for (size_t i = 0; i < N; ++i) {
      if (i == j) continue;
      double d = 0;
      int cnt = 0;
      for (size_t q = 0; q < m; q += step, ++cnt) {
        const uint32_t k = mine[j][q];
        d += (flow_at(s->cl[i].model, s->cl[i].params, g, ev.x[k], ev.y[k]) -
              flow_at(s->cl[j].model, s->cl[j].params, g, ev.x[k], ev.y[k])).norm();
      }
      if (cnt == 0) {  // no events of its own: compare at the image centre
        d = (flow_at(s->cl[i].model, s->cl[i].params, g, g.cx, g.cy) - flow_at(s->cl[j].model, s->cl[j].params, g, g.cx, g.cy)).norm();
        cnt = 1;
      }
      if (d / cnt < best) best = d / cnt, s->nearest[j] = static_cast<int>(i);
    }
  }
}

double MotionSegmenter::cluster_objective(const CmaxEvents& ev, const State& s, int j, WarpModel m,
                                          const Eigen::VectorXd& p) {
  auto& st = const_cast<State&>(s);
  ++st.evaluations;
  return st.maximizer(m, cm_options_, options_.motion_iterations).objective(ev, p, 0, s.w[j].data());
}

void MotionSegmenter::update_associations(const CmaxEvents& ev, State* s) {
  const size_t n = ev.size(), N = s->cl.size();
  std::vector<std::vector<float>> c(N);
  for (size_t j = 0; j < N; ++j) {
    ContrastMaximizer& cm = s->maximizer(s->cl[j].model, cm_options_, options_.motion_iterations);
    const ImageF img = cm.iwe(ev, s->cl[j].params, s->w[j].data(), true);
    sample_at_warped(img, s->cl[j].model, ev, s->cl[j].params, &c[j]);
  }
  s->support.assign(n, 0.0f);
  for (size_t k = 0; k < n; ++k) {
    double sum = 0;
    for (size_t j = 0; j < N; ++j) sum += c[j][k];
    s->support[k] = static_cast<float>(sum);
    for (size_t j = 0; j < N; ++j)
      s->w[j][k] = sum > 0 ? static_cast<float>(c[j][k] / sum) : 1.0f / static_cast<float>(N);
  }
  for (size_t j = 0; j < N; ++j) {
    double e = 0;
    for (size_t k = 0; k < n; ++k) e += s->w[j][k];
    s->cl[j].events = e;
  }
}

void MotionSegmenter::remove_cluster(State* s, int j, int into) {
  // Its associations go to `into` (the cluster whose motion explains its events best) or, with
  // into < 0, to the others in proportion.
  if (into >= 0 && into != j) {
    for (size_t k = 0; k < s->w[j].size(); ++k) s->w[into][k] += s->w[j][k];
  }
  s->cl.erase(s->cl.begin() + j);
  s->w.erase(s->w.begin() + j);
  if (s->cl.empty() || s->w.empty()) return;
  const size_t n = s->w[0].size();
  for (size_t k = 0; k < n; ++k) {
    double sum = 0;
    for (const auto& wj : s->w) sum += wj[k];
    for (auto& wj : s->w) wj[k] = sum > 0 ? static_cast<float>(wj[k] / sum) : 1.0f / static_cast<float>(s->w.size());
  }
}

void MotionSegmenter::alternate(const CmaxEvents& ev, State* s, int iterations) {
  const size_t n = ev.size();
  for (int it = 0; it < iterations && !s->cl.empty(); ++it) {
    ++s->alternations;
    for (size_t j = 0; j < s->cl.size(); ++j) {
      SegmentCluster& c = s->cl[j];
      ContrastMaximizer& cm = s->maximizer(c.model, cm_options_, options_.motion_iterations);
      // Only the events with a say in this cluster (association >= 1e-3) vote in its IWE: the
      // same optimum to within 0.1% of a vote per event, and a small cluster costs little.
      std::vector<uint32_t> idx;
      for (size_t k = 0; k < n; ++k)
        if (s->w[j][k] >= 1e-3f) idx.push_back(static_cast<uint32_t>(k));
      CmaxResult r;
      if (idx.size() * 4 < n * 3) {
        const CmaxEvents sub = ev.select(idx);
        std::vector<float> w(idx.size());
        for (size_t i = 0; i < idx.size(); ++i) w[i] = s->w[j][idx[i]];
        r = sub.empty() ? CmaxResult() : cm.maximize(sub, c.params, w.data());
        if (sub.empty()) r.params = c.params, r.objective = c.objective;
      } else {
        r = cm.maximize(ev, c.params, s->w[j].data());
      }
      s->evaluations += r.evaluations;
      c.params = r.params;
      c.objective = r.objective;
    }
    std::vector<std::vector<float>> before = s->w;
    update_associations(ev, s);
    double change = 0;
    for (size_t j = 0; j < s->cl.size(); ++j)
      for (size_t k = 0; k < n; ++k) change = std::max(change, static_cast<double>(std::abs(s->w[j][k] - before[j][k])));
    // Clusters that lost their events die (smallest first, one at a time, re-normalising).
    bool removed = false;
    while (s->cl.size() > 1) {
      int worst = -1;
      for (size_t j = 0; j < s->cl.size(); ++j)
        if (s->cl[j].events < options_.min_cluster_share * static_cast<double>(n) &&
            (worst < 0 || s->cl[j].events < s->cl[worst].events))
          worst = static_cast<int>(j);
      if (worst < 0) break;
      remove_cluster(s, worst, -1);
      removed = true;
    }
    if (removed) {
      update_associations(ev, s);
      continue;
    }
    if (change < options_.association_tolerance) break;
  }
}

void MotionSegmenter::decide_count(const CmaxEvents& ev, State* sp, SegmentationResult* out) {
  // Remove the least useful cluster while it is not useful enough.
  State& s = *sp;
  const bool debug = log_level() == LogLevel::kDebug;
  while (true) {
    compute_gains(ev, &s);
    CountStep step;
    step.clusters = static_cast<int>(s.cl.size());
    for (const auto& c : s.cl) step.sum_objective += c.objective;
    if (s.cl.size() <= 1) {
      out->count_steps.push_back(step);
      break;
    }
    // Below the bar, a new proposal goes before a cluster that lives on from the last window
    // (near-duplicates of a live cluster must not take its label).
    int worst = 0;
    auto below = [&](size_t j) { return s.cl[j].gain < options_.min_cluster_gain; };
    for (size_t j = 1; j < s.cl.size(); ++j) {
      const bool jp = s.cl[j].id < 0 && below(j), wp = s.cl[worst].id < 0 && below(worst);
      if ((jp && !wp) || (jp == wp && s.cl[j].gain < s.cl[worst].gain)) worst = static_cast<int>(j);
    }
    step.smallest_gain = s.cl[worst].gain;
    if (!below(worst)) {
      out->count_steps.push_back(step);
      break;
    }
    step.removed = true;
    step.removed_id = s.cl[worst].id;
    step.removed_model = s.cl[worst].model;
    step.removed_params = s.cl[worst].params;
    out->count_steps.push_back(step);
    if (debug) log_debug(describe("gains before a removal", s.cl));
    // A proposal that absorbs a live cluster takes over its label (it is the same object).
    const int into = s.nearest[worst];
    if (into >= 0 && s.cl[into].id < 0 && s.cl[worst].id >= 0) s.cl[into].id = s.cl[worst].id;
    remove_cluster(&s, worst, into);
    update_associations(ev, &s);
    alternate(ev, &s, std::max(2, options_.iterations / 2));
  }
}

int MotionSegmenter::add_proposals(const CmaxEvents& ev, State* s, int room, const std::vector<Eigen::Vector2d>& flows,
                                   const std::vector<Eigen::Vector2d>& centres, WarpModel base, int* evaluations) {
  const size_t n = ev.size();
  const WarpGeometry& g = ev.geometry();
  std::vector<Eigen::Vector2d> starts;
  std::vector<std::vector<float>> start_votes;
  if (s->cl.empty() && options_.init == SegmentationInit::kGreedy) {
    // Greedy: fit a flow to the events the previous fits leave out of focus.
    std::vector<float> rest(n, 1.0f), c;
    CmaxOptions o = cm_options_;
    o.model = WarpModel::kFlow;
    ContrastMaximizer cm(o);
    for (int j = 0; j < room; ++j) {
      const CmaxResult r = cm.maximize(ev, Eigen::VectorXd(), rest.data());
      *evaluations += r.evaluations;
      starts.push_back(r.params);
      start_votes.push_back(rest);
      const ImageF img = cm.iwe(ev, r.params, rest.data(), true);
      sample_at_warped(img, WarpModel::kFlow, ev, r.params, &c);
      double mean = 0, wsum = 0;
      for (size_t k = 0; k < n; ++k) mean += rest[k] * c[k], wsum += rest[k];
      mean = wsum > 0 ? mean / wsum : 0;
      for (size_t k = 0; k < n; ++k) rest[k] *= static_cast<float>(1.0 - c[k] / (c[k] + mean + 1e-12));
    }
  } else {
    // k-means on the local flows of the tiles the clusters leave unexplained (all tiles when
    // there are none): a tile is explained when its flow is within new_motion_px over the window
    // of the flow of the cluster that holds most of its events.
    const int T = options_.tile_px;
    const int nx = (cm_options_.width + T - 1) / T, ny = (cm_options_.height + T - 1) / T;
    auto tile_of = [&](double x, double y) {
      const int i = static_cast<int>(std::floor(x / T)), j = static_cast<int>(std::floor(y / T));
      return (i >= 0 && j >= 0 && i < nx && j < ny) ? j * nx + i : -1;
    };
    std::vector<int> index(static_cast<size_t>(nx) * ny, -1);  // tile -> entry of flows
    for (size_t i = 0; i < centres.size(); ++i) index[static_cast<size_t>(tile_of(centres[i].x(), centres[i].y()))] = static_cast<int>(i);
    std::vector<char> unexplained(flows.size(), 1);
    if (!s->cl.empty()) {
      const size_t N = s->cl.size();
      std::vector<std::vector<int>> held(flows.size(), std::vector<int>(N, 0));
      for (size_t k = 0; k < n; ++k) {
        const int t = tile_of(ev.x[k], ev.y[k]);
        if (t < 0 || index[static_cast<size_t>(t)] < 0) continue;
        size_t best = 0;
        for (size_t j = 1; j < N; ++j)
          if (s->w[j][k] > s->w[best][k]) best = j;
        ++held[static_cast<size_t>(index[static_cast<size_t>(t)])][best];
      }
      const double span = ev.dt_max_s() - ev.dt_min_s();
      for (size_t i = 0; i < flows.size(); ++i) {
        const size_t j = static_cast<size_t>(std::max_element(held[i].begin(), held[i].end()) - held[i].begin());
        const SegmentCluster& c = s->cl[j];
        unexplained[i] = (flows[i] - flow_at(c.model, c.params, g, centres[i].x(), centres[i].y())).norm() * span >=
                         options_.new_motion_px;
      }
    }
    std::vector<Eigen::Vector2d> f2;
    std::vector<int> entry;  // f2 -> flows
    for (size_t i = 0; i < flows.size(); ++i)
      if (unexplained[i]) f2.push_back(flows[i]), entry.push_back(static_cast<int>(i));
    if (f2.empty()) return 0;
    std::vector<int> assignment;
    starts = kmeans(f2, std::min<int>(room, static_cast<int>(f2.size())), options_.seed, &assignment);
    std::vector<int> proposal_of(flows.size(), -1);
    for (size_t q = 0; q < f2.size(); ++q) proposal_of[static_cast<size_t>(entry[q])] = assignment[q];
    start_votes.assign(starts.size(), std::vector<float>(n, 0.0f));
    for (size_t k = 0; k < n; ++k) {
      const int t = tile_of(ev.x[k], ev.y[k]);
      if (t < 0 || index[static_cast<size_t>(t)] < 0) continue;
      const int p = proposal_of[static_cast<size_t>(index[static_cast<size_t>(t)])];
      if (p >= 0) start_votes[static_cast<size_t>(p)][k] = 1.0f;
    }
  }
  for (size_t i = 0; i < starts.size(); ++i) {
    SegmentCluster c;
    c.id = -1;  // an id only if it survives
    c.model = base;
    c.params = params_from_flow(base, starts[i], g);
    s->cl.push_back(c);
    s->w.push_back(start_votes[i]);
  }
  return static_cast<int>(starts.size());
}

SegmentationResult MotionSegmenter::segment(const CmaxEvents& ev, const std::vector<SegmentCluster>* previous,
                                            int* next_id) {
  SegmentationResult out;
  int local_next = 0;
  if (!next_id) next_id = &local_next;
  const size_t n = ev.size();
  if (n == 0) return out;
  const WarpGeometry& g = ev.geometry();
  // The count is decided with the richest candidate model (a rotating object is one similarity
  // cluster, but would need several flow clusters); each cluster's model is chosen afterwards.
  const WarpModel base = options_.models.back();
  State s;
  s.self_vote = self_vote();

  const int target = options_.clusters > 0 ? options_.clusters : options_.max_clusters;
  // Starting clusters: the previous window's, then proposals up to the target count.
  if (previous) {
    // Largest first, so a fixed count keeps the clusters that matter.
    std::vector<const SegmentCluster*> order;
    for (const SegmentCluster& c : *previous) order.push_back(&c);
    std::stable_sort(order.begin(), order.end(), [](auto* a, auto* b) { return a->events > b->events; });
    for (const SegmentCluster* pc : order) {
      if (static_cast<int>(s.cl.size()) >= target) break;
      SegmentCluster k = *pc;
      k.models.clear();
      // First votes: the events inside its footprint, moved by its flow since that window.
      std::vector<float> votes(n, 1.0f);
      if (k.footprint.size() > 0) {
        // Moved by its motion since that window: the flow there times the time, plus an
        // accelerated model's a dt^2 / 2; an accelerated model's velocity is carried forward.
        const double since = static_cast<double>(ev.t_ref_ns() - k.footprint_t_ns) * 1e-9;
        Eigen::Vector2d shift = flow_at(k.model, k.params, g, k.centroid.x(), k.centroid.y()) * since;
        if (warp_velocity_model(k.model) != k.model) shift += 0.5 * since * since * k.params.tail<2>();
        k.params = warp_params_at(k.model, k.params, since);
        const long fw = k.footprint.cols(), fh = k.footprint.rows();
        for (size_t e = 0; e < n; ++e) {
          const long x = std::lround(ev.x[e] - shift.x()), y = std::lround(ev.y[e] - shift.y());
          votes[e] = (x >= 0 && y >= 0 && x < fw && y < fh && k.footprint(y, x)) ? 1.0f : 0.0f;
        }
      }
      k.params = convert(k.model, k.params, base, g, k.centroid);
      k.model = base;
      s.cl.push_back(k);
      s.w.push_back(votes);
    }
  }
  if (!s.cl.empty()) {
    // Refit the live clusters to this window before asking which tiles they leave unexplained
    // (an accelerating object's tiles would otherwise all look new).
    update_associations(ev, &s);
    alternate(ev, &s, std::max(2, options_.iterations / 2));
  }
  const bool debug = log_level() == LogLevel::kDebug;
  // Local flows per tile, once per window: the k-means proposals come from them.
  std::vector<Eigen::Vector2d> flows, centres;
  if (options_.init == SegmentationInit::kKmeans || !s.cl.empty() || options_.split_rounds > 0)
    tile_flows(ev, &flows, &centres);
  // Split and merge: propose clusters for what the clusters leave unexplained, alternate, and
  // (automatic count) merge the clusters that do not pay; again while new proposals survive.
  for (int round = 0;; ++round) {
    const int room = target - static_cast<int>(s.cl.size());
    auto unnamed = [&] { return std::count_if(s.cl.begin(), s.cl.end(), [](const SegmentCluster& c) { return c.id < 0; }); };
    const auto unnamed_before = unnamed();
    const int added = room > 0 ? add_proposals(ev, &s, room, flows, centres, base, &out.evaluations) : 0;
    if (round > 0 && added == 0) break;
    if (s.cl.empty()) {  // no texture anywhere: one still cluster
      SegmentCluster c;
      c.model = base;
      c.params = Eigen::VectorXd::Zero(warp_dof(base));
      s.cl.push_back(c);
      s.w.push_back(std::vector<float>(n, 1.0f));
    }
    if (debug) log_debug(describe(round == 0 ? "start" : "split proposals", s.cl));
    // First associations: each new cluster's IWE from its own votes.
    update_associations(ev, &s);
    if (debug) log_debug(describe("first associations", s.cl));
    alternate(ev, &s, options_.iterations);
    if (debug) log_debug(describe("alternated", s.cl));
    if (options_.clusters == 0) decide_count(ev, &s, &out);
    if (options_.clusters > 0 || round >= options_.split_rounds) break;
    // A round whose proposals all merged away changes nothing more.
    if (round > 0 && unnamed() <= unnamed_before) break;
  }

  // The warp model of each cluster: the simplest whose objective is not beaten by a richer one
  // by more than the per-parameter penalty.
  if (options_.models.size() > 1) {
    bool changed = false;
    for (size_t j = 0; j < s.cl.size(); ++j) {
      SegmentCluster& c = s.cl[j];
      // The cluster's centroid, where model conversions match flows.
      Eigen::Vector2d at = Eigen::Vector2d::Zero();
      double ws = 0;
      for (size_t k = 0; k < n; ++k) at += s.w[j][k] * Eigen::Vector2d(ev.x[k], ev.y[k]), ws += s.w[j][k];
      at = ws > 0 ? Eigen::Vector2d(at / ws) : Eigen::Vector2d(g.cx, g.cy);
      std::vector<ModelTrial> trials;
      for (WarpModel m : options_.models) {
        ModelTrial t;
        t.model = m;
        ContrastMaximizer& cm = s.maximizer(m, cm_options_, options_.motion_iterations);
        const Eigen::VectorXd init = convert(c.model, c.params, m, g, at);
        if (m == c.model) {
          t.params = c.params;
          t.objective = cluster_objective(ev, s, static_cast<int>(j), m, c.params);
        } else {
          // Richer models get the iterations their extra parameters need.
          CmaxResult r = cm.maximize(ev, init, s.w[j].data());
          r = cm.maximize(ev, r.params, s.w[j].data());
          s.evaluations += r.evaluations;
          t.params = r.params;
          t.objective = r.objective;
        }
        trials.push_back(t);
      }
      // Score against the simplest model: the rule of warp_model_selection.h.
      const size_t best = choose_warp_model(&trials, options_.model_gain_per_parameter);
      if (trials[best].model != c.model) changed = true;
      c.model = trials[best].model;
      c.params = trials[best].params;
      c.models = trials;
    }
    if (changed) {
      update_associations(ev, &s);
      alternate(ev, &s, 2);
    }
  }

  SegmentationResult f = finish(ev, &s, next_id);
  f.count_steps = out.count_steps;
  f.evaluations += out.evaluations;
  return f;
}

SegmentationResult MotionSegmenter::finish(const CmaxEvents& ev, State* sp, int* next_id) {
  State& s = *sp;
  const size_t n = ev.size();
  SegmentationResult out;
  compute_gains(ev, &s);
  for (auto& c : s.cl)
    if (c.id < 0) c.id = (*next_id)++;
  std::vector<size_t> order(s.cl.size());
  for (size_t j = 0; j < order.size(); ++j) order[j] = j;
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) { return s.cl[a].id < s.cl[b].id; });
  out.associations.resize(static_cast<Eigen::Index>(n), static_cast<Eigen::Index>(s.cl.size()));
  for (size_t jj = 0; jj < order.size(); ++jj) {
    out.clusters.push_back(s.cl[order[jj]]);
    for (size_t k = 0; k < n; ++k) out.associations(static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(jj)) = s.w[order[jj]][k];
  }
  out.labels.assign(n, -1);
  for (size_t k = 0; k < n; ++k) {
    if (s.support.empty() || s.support[k] < options_.noise_support * s.self_vote) continue;
    Eigen::Index best = 0;
    out.associations.row(static_cast<Eigen::Index>(k)).maxCoeff(&best);
    out.labels[k] = out.clusters[static_cast<size_t>(best)].id;
  }
  for (const auto& c : out.clusters) out.sum_objective += c.objective;
  // Footprints and centroids for the next window.
  const int W = cm_options_.width, H = cm_options_.height, R = options_.footprint_radius_px;
  for (size_t jj = 0; jj < out.clusters.size(); ++jj) {
    SegmentCluster& c = out.clusters[jj];
    MaskU8 m = MaskU8::Zero(H, W);
    Eigen::Vector2d sum = Eigen::Vector2d::Zero();
    int cnt = 0;
    for (size_t k = 0; k < n; ++k) {
      if (out.labels[k] != c.id) continue;
      const long x = std::lround(ev.x[k]), y = std::lround(ev.y[k]);
      if (x < 0 || y < 0 || x >= W || y >= H) continue;
      m(y, x) = 1;
      sum += Eigen::Vector2d(ev.x[k], ev.y[k]);
      ++cnt;
    }
    c.centroid = cnt > 0 ? Eigen::Vector2d(sum / cnt) : Eigen::Vector2d(ev.geometry().cx, ev.geometry().cy);
    if (R > 0) {
      cv::Mat src(H, W, CV_8U, m.data());
      cv::dilate(src, src, cv::getStructuringElement(cv::MORPH_ELLIPSE, cv::Size(2 * R + 1, 2 * R + 1)));
    }
    c.footprint = std::move(m);
    c.footprint_t_ns = ev.t_ref_ns();
  }
  out.alternations = s.alternations;
  out.evaluations += s.evaluations;
  return out;
}

SegmentationResult MotionSegmenter::refine(const CmaxEvents& ev, const std::vector<SegmentCluster>& clusters,
                                           const std::vector<std::vector<float>>& weights, int iterations) {
  if (clusters.empty() || weights.size() != clusters.size())
    throw std::invalid_argument("refine: one weight vector per cluster is needed");
  const size_t n = ev.size();
  State s;
  s.self_vote = self_vote();
  s.cl = clusters;
  s.w = weights;
  for (auto& w : s.w)
    if (w.size() != n) throw std::invalid_argument("refine: each weight vector needs one value per event");
  for (size_t k = 0; k < n; ++k) {
    double sum = 0;
    for (const auto& w : s.w) sum += w[k];
    for (auto& w : s.w) w[k] = sum > 0 ? static_cast<float>(w[k] / sum) : 1.0f / static_cast<float>(s.w.size());
  }
  if (iterations > 0) alternate(ev, &s, iterations);
  if (s.support.empty()) update_associations(ev, &s);
  int next = 0;
  for (const auto& c : s.cl) next = std::max(next, c.id + 1);
  return finish(ev, &s, &next);
}

}  // namespace evio::mapping
