// Corner events against true corners (corner_evaluation.h).
#include "evio/evaluation/corner_evaluation.h"

#include <cmath>
#include <stdexcept>
#include <utility>

namespace evio::evaluation {

bool CornerScoringOptions::Validate(std::string* why) const {
  auto fail = [why](const char* m) {
    if (why) *why = m;
    return false;
  };
  if (!(match_radius_px > 0) || !std::isfinite(match_radius_px)) return fail("match_radius_px must be finite and > 0");
  if (bin_ns <= 0) return fail("bin_ns must be > 0");
  if (!(min_speed_pxps >= 0) || !std::isfinite(min_speed_pxps)) return fail("min_speed_pxps must be finite and >= 0");
  if (!(border_px >= 0) || !std::isfinite(border_px)) return fail("border_px must be finite and >= 0");
  return true;
}

CornerEventScorer::CornerEventScorer(int width, int height, int num_corners, std::vector<bool> inner,
                                     CornerProjector project, int64_t t_begin_ns, int64_t t_end_ns,
                                     const CornerScoringOptions& options)
    : width_(width),
      height_(height),
      num_corners_(num_corners),
      inner_(std::move(inner)),
      project_(std::move(project)),
      t_begin_ns_(t_begin_ns),
      t_end_ns_(t_end_ns),
      o_(options) {
  std::string why;
  if (!o_.Validate(&why)) throw std::invalid_argument("CornerScoringOptions: " + why);
  if (width <= 0 || height <= 0 || num_corners < 0) throw std::invalid_argument("CornerEventScorer: bad sizes");
  if (!inner_.empty() && static_cast<int>(inner_.size()) != num_corners)
    throw std::invalid_argument("CornerEventScorer: inner must be empty or hold one flag per corner");
  if (!project_) throw std::invalid_argument("CornerEventScorer: no projector");
  num_bins_ = t_end_ns > t_begin_ns ? static_cast<int>((t_end_ns - t_begin_ns) / o_.bin_ns) : 0;  // whole bins
  hit_.assign(static_cast<size_t>(num_bins_) * static_cast<size_t>(num_corners), 0);
}

const std::vector<Eigen::Vector2d>& CornerEventScorer::corners_at(int64_t t_ns) {
  if (t_ns != cached_t_) {
    project_(t_ns, &cached_);
    if (static_cast<int>(cached_.size()) != num_corners_)
      throw std::invalid_argument("CornerEventScorer: the projector returned a wrong corner count");
    cached_t_ = t_ns;
  }
  return cached_;
}

bool CornerEventScorer::near_true_corner(const Event& e) {
  const Eigen::Vector2d p(e.x, e.y);
  const double r2 = o_.match_radius_px * o_.match_radius_px;
  for (const Eigen::Vector2d& c : corners_at(e.t_ns))
    if ((c - p).squaredNorm() <= r2) return true;  // NaN compares false
  return false;
}

void CornerEventScorer::add(const Event& e, bool is_corner) { add(e, is_corner, near_true_corner(e)); }

void CornerEventScorer::add(const Event& e, bool is_corner, bool near) {
  ++m_.events;
  if (near) {
    ++m_.near_events;
    if (is_corner) ++m_.near_events_flagged;
  }
  if (!is_corner) return;
  ++m_.corner_events;
  const std::vector<Eigen::Vector2d>& px = corners_at(e.t_ns);
  const Eigen::Vector2d p(e.x, e.y);
  const double r2 = o_.match_radius_px * o_.match_radius_px;
  const int64_t bin = e.t_ns >= t_begin_ns_ ? (e.t_ns - t_begin_ns_) / o_.bin_ns : -1;
  bool tp = false;
  for (int k = 0; k < num_corners_; ++k) {
    if (!((px[k] - p).squaredNorm() <= r2)) continue;
    tp = true;
    if (bin >= 0 && bin < num_bins_) hit_[static_cast<size_t>(bin) * num_corners_ + k] = 1;
  }
  if (tp) ++m_.true_positives;
}

CornerMetrics CornerEventScorer::finish() const {
  CornerMetrics m = m_;
  // (corner, bin) pairs: the corner is inside the detectable area (>= border_px from the border)
  // at the bin's start, middle and end, and moves at >= min_speed_pxps on average over the bin.
  const double lo = o_.border_px, x_hi = width_ - 1 - o_.border_px, y_hi = height_ - 1 - o_.border_px;
  auto inside = [&](const Eigen::Vector2d& q) { return q.x() >= lo && q.y() >= lo && q.x() <= x_hi && q.y() <= y_hi; };
  std::vector<Eigen::Vector2d> pa, pm, pb;
  for (int b = 0; b < num_bins_; ++b) {
    const int64_t ta = t_begin_ns_ + b * o_.bin_ns, tb = ta + o_.bin_ns;
    project_(ta, &pa);
    project_(ta + o_.bin_ns / 2, &pm);
    project_(tb, &pb);
    for (int c = 0; c < num_corners_; ++c) {
      if (!inside(pa[c]) || !inside(pm[c]) || !inside(pb[c])) continue;  // NaN: not inside
      if ((pb[c] - pa[c]).norm() / (o_.bin_ns * 1e-9) < o_.min_speed_pxps) continue;
      const bool h = hit_[static_cast<size_t>(b) * num_corners_ + c] != 0;
      ++m.pairs;
      m.pairs_hit += h;
      if (!inner_.empty() && inner_[c]) {
        ++m.inner_pairs;
        m.inner_pairs_hit += h;
      }
    }
  }
  return m;
}

}  // namespace evio::evaluation
