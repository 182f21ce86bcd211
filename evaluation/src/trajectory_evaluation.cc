// Trajectory evaluation: association, closed-form alignment, ATE, RPE (see the header).
//
// Protocol and its relation to rpg_trajectory_evaluation (Zhang and Scaramuzza, IROS 2018; files
// compute_trajectory_errors.py, trajectory_utils.py, trajectory.py, align_utils.py):
// - Association: for each estimate pose in time order, the nearest not-yet-used ground-truth pose
//   (two-pointer sweep, O(n)); a match needs |t_est + offset - t_gt| <= max_dt. Each
//   ground-truth pose is used at most once. rpg reads pre-associated files; evo/TUM associate
//   greedily over all candidate pairs sorted by |dt| (not monotone in time) -- we keep time order.
// - Alignment (Umeyama 1991): p_gt ~= s R p_est + t on the positions of the chosen pairs, SVD of
//   the cross-covariance with the reflection fix. posyaw: R = Rz(yaw), yaw = atan2(B, A) with
//   A = Sxx + Syy, B = Syx - Sxy of the centred cross-covariance S = sum (p_gt - mu_gt)(p_est -
//   mu_est)^T (the best rotation about z, as rpg's align_posyaw), t = mu_gt - R mu_est. As in
//   rpg, posyaw on a single pair (or on pairs without horizontal spread) takes the yaw from the
//   orientations of the first pair (rpg's align_position_yaw_single) and the translation from its
//   position. Likewise se3/sim3 on two or more positions that do not span a plane (RMS spread
//   under 1 mm, or second singular value under 1e-3 of the first: a still or rotating-in-place
//   camera, a straight line) align the first pair's poses (R = R_gt0 R_est0^T, scale 1), since
//   Umeyama's rotation is undetermined there. first_pose aligns the first pair's poses always (a
//   camera turning in place with a few cm of translation: a fit to positions follows their
//   errors). Aligned orientation: R * R_est (as rpg's align_trajectory).
// - ATE: |p_gt - p_est_aligned| and the angle of R_gt^T R_est_aligned (the same angle as rpg's
//   R_est R_gt^-1), computed from the quaternion with atan2 (rpg: arccos of the trace, which
//   loses precision below ~1e-4 deg; same value otherwise).
// - RPE (rpg's compute_relative_error, method "initial_pose"):
//   * lengths given in %: length = trunc(pct/100 * L, 2 decimals) with L the path length of the
//     whole ground-truth trajectory (rpg: compute_boxplot_distances with truncate(.., 2) on the
//     raw ground truth's length); lengths that come out as 0 m are skipped (no entry), e.g. for a
//     stationary ground truth.
//   * accumulated distance d_k along the matched ground-truth positions (cumulative sum of the
//     consecutive distances, starting at 0).
//   * every pair i is a start; its end j >= i is the first index minimising |d_j - (d_i + len)|
//     among those with |d_j - (d_i + len)| < 0.2 len (rpg: max_dist_diff = 0.2 * len, strict
//     comparison, first minimum wins). rpg scans O(n^2); since d is non-decreasing we find the
//     same index in O(n) with a forward-moving pointer. Starts without such an end are skipped.
//     (Some rpg versions drop the unmatched starts from the list and then index the starts by
//     their position in that shortened list, and skip a length with fewer than 2
//     sub-trajectories; we always use the true start index and keep any count.)
//   * E = (T_gt_i^-1 T_gt_j)^-1 (T_est_i^-1 T_est_j) with the estimate's relative translation
//     multiplied by the alignment scale (1 unless sim3), using the unaligned estimate (the
//     relative motion does not depend on a rigid alignment). E is expressed in the world frame
//     by conjugation with the estimate's rotation at j: E_w = R_est_j E R_est_j^T (rpg's
//     T_error_in_w); its translation norm and angle do not change, its yaw does.
//   * trans_m = |t(E_w)|, trans_percent = 100 trans_m / len, rot_deg = angle(E_w),
//     yaw_deg = |yaw(E_w)| (ZYX, rpg's 'rzyx'), yaw_deg_per_m = yaw_deg / len. Divided by the
//     requested length, not by the distance actually travelled between i and j (as rpg).
// - mean_position_error_percent = 100 mean(ATE trans) / path length of the matched ground truth;
//   final_yaw_error_deg = yaw(R_est_aligned R_gt^T) at the last pair (world-frame yaw error,
//   rpg's abs_e_ypr); yaw_drift_deg_per_m = |final yaw error| / path length. Both are NaN (null
//   in JSON, n/a in tables) when the matched ground truth travels less than 1 um: a percentage of
//   no distance is not a figure (pure rotation; judge those by ate.rot_deg and the RRE).
// - Stats: rmse, mean, median (mean of the two middle values for an even count), population std
//   (divides by n, as numpy.std), min, max.
// Times stay int64 ns; every time difference is taken in int64 before converting to seconds.
#include "evio/evaluation/trajectory_evaluation.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numeric>
#include <sstream>
#include <stdexcept>

#include <Eigen/Geometry>
#include <Eigen/Eigenvalues>
#include <Eigen/SVD>

namespace evio::evaluation {
namespace {

constexpr double kRadToDeg = 180.0 / M_PI;
constexpr double kMinPathLength_m = 1e-6;  // below this the ground truth "does not move"

int64_t seconds_to_ns(double s) { return static_cast<int64_t>(std::llround(s * 1e9)); }

std::string format_seconds(int64_t t_ns) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.9f", static_cast<double>(t_ns) * 1e-9);
  return buf;
}

std::string range_text(const Trajectory& t) {
  return "[" + format_seconds(t.t_begin_ns()) + ", " + format_seconds(t.t_end_ns()) + "] s (" +
         std::to_string(t.size()) + " poses)";
}

// When the two ranges differ by a factor near 1e3/1e6/1e9, a sentence naming the likely units.
std::string unit_hint(const Trajectory& gt, const Trajectory& est) {
  auto magnitude = [](const Trajectory& t) {
    // The larger of |begin| and |end|: an absolute stamp scale.
    return std::max(std::abs(static_cast<double>(t.t_begin_ns())), std::abs(static_cast<double>(t.t_end_ns())));
  };
  auto check = [](double a, double b) -> int {
    if (!(a > 0) || !(b > 0)) return 0;
    const double l = std::log10(a / b);
    for (int k : {3, 6, 9}) {
      if (std::abs(l - k) < 0.5) return k;
      if (std::abs(l + k) < 0.5) return -k;
    }
    return 0;
  };
  int k = check(magnitude(gt), magnitude(est));
  if (k == 0) k = check(static_cast<double>(gt.duration_ns()), static_cast<double>(est.duration_ns()));
  if (k == 0) return "";
  const char* factor = std::abs(k) == 3 ? "1e3" : std::abs(k) == 6 ? "1e6" : "1e9";
  const char* units = std::abs(k) == 3 ? "(e.g. ms vs s, us vs ms, ns vs us)"
                    : std::abs(k) == 6 ? "(e.g. us vs s, ns vs ms)"
                                       : "(e.g. ns vs s)";
  std::string which = k > 0 ? "the ground truth's" : "the estimate's";
  return std::string(" The ranges differ by a factor near ") + factor + ": " + which +
         " stamps look like they are in a smaller time unit than assumed " + units +
         "; give the file's time unit explicitly.";
}

// Angle of a rotation given as a quaternion, rad, in [0, pi].
double quat_angle(const calib::Quat& q) {
  return 2.0 * std::atan2(q.vec().norm(), std::abs(q.w()));
}

void centre(const std::vector<Eigen::Vector3d>& p, Eigen::Vector3d* mean) {
  Eigen::Vector3d m = Eigen::Vector3d::Zero();
  for (const auto& x : p) m += x;
  *mean = m / static_cast<double>(p.size());
}

double path_length(const std::vector<calib::SE3>& poses) {
  double len = 0;
  for (size_t k = 1; k < poses.size(); ++k) len += (poses[k].translation - poses[k - 1].translation).norm();
  return len;
}

// True when positions have no horizontal spread (relative to their magnitude), so that a yaw
// cannot be fitted from them.
bool no_horizontal_spread(const std::vector<Eigen::Vector3d>& p, const Eigen::Vector3d& mean) {
  double horiz = 0, var = 0;
  for (const auto& x : p) {
    horiz += (x - mean).head<2>().squaredNorm();
    var += (x - mean).squaredNorm();
  }
  const double n = static_cast<double>(p.size());
  const double ref = std::max({var / n, mean.squaredNorm(), 1e-300});
  return !(horiz / n > 1e-20 * ref);
}

Eigen::Matrix3d rot_z(double yaw) { return Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix(); }

}  // namespace

const char* alignment_name(Alignment a) {
  switch (a) {
    case Alignment::kNone: return "none";
    case Alignment::kSE3: return "se3";
    case Alignment::kSim3: return "sim3";
    case Alignment::kPosYaw: return "posyaw";
    case Alignment::kFirstPose: return "first_pose";
  }
  return "none";
}

std::optional<Alignment> alignment_from_name(const std::string& name) {
  for (Alignment a : {Alignment::kNone, Alignment::kSE3, Alignment::kSim3, Alignment::kPosYaw, Alignment::kFirstPose}) {
    if (name == alignment_name(a)) return a;
  }
  return std::nullopt;
}

bool AssociationOptions::Validate(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!std::isfinite(max_dt_s) || max_dt_s <= 0) return fail("association max_dt_s must be finite and > 0 s");
  if (max_dt_s > 1e6) return fail("association max_dt_s must be at most 1e6 s");
  if (!std::isfinite(time_offset_s) || std::abs(time_offset_s) > 1e9)
    return fail("association time_offset_s must be finite and within +-1e9 s");
  return true;
}

bool AlignmentOptions::Validate(std::string* why) const {
  if (!std::isfinite(first_s) || first_s < 0 || first_s > 1e9) {
    if (why) *why = "alignment first_s must be finite and in [0, 1e9] s (0: all pairs)";
    return false;
  }
  return true;
}

bool RelativeErrorOptions::Validate(std::string* why) const {
  for (double l : lengths) {
    if (!std::isfinite(l) || l <= 0) {
      if (why) *why = "relative error lengths must be finite and > 0 (" + std::string(lengths_in_percent ? "%" : "m") + ")";
      return false;
    }
    if (lengths_in_percent && l > 100) {
      if (why) *why = "relative error lengths in percent must be at most 100";
      return false;
    }
  }
  return true;
}

bool EvaluationOptions::Validate(std::string* why) const {
  return association.Validate(why) && alignment.Validate(why) && rpe.Validate(why);
}

AssociatedPoses associate(const Trajectory& groundtruth, const Trajectory& estimate, const AssociationOptions& options) {
  std::string why;
  if (!options.Validate(&why)) throw std::invalid_argument(why);
  if (groundtruth.empty()) throw std::invalid_argument("association: the ground-truth trajectory is empty");
  if (estimate.empty()) throw std::invalid_argument("association: the estimate trajectory is empty");

  const int64_t offset_ns = seconds_to_ns(options.time_offset_s);
  const int64_t max_dt_ns = seconds_to_ns(options.max_dt_s);
  const auto& gt = groundtruth.poses();
  const auto& est = estimate.poses();
  const size_t n_gt = gt.size();

  AssociatedPoses out;
  const size_t reserve = std::min(n_gt, est.size());
  out.t_ns.reserve(reserve);
  out.groundtruth.reserve(reserve);
  out.estimate.reserve(reserve);
  out.estimate_index.reserve(reserve);

  // Smallest |dt| seen, for the error message when nothing associates.
  int64_t closest_ns = std::numeric_limits<int64_t>::max();
  size_t j = 0;  // gt[j] is the last ground-truth pose with t <= t (or 0)
  size_t next_free = 0;
  for (size_t e = 0; e < est.size(); ++e) {
    const int64_t t = est[e].t_ns + offset_ns;
    while (j + 1 < n_gt && gt[j + 1].t_ns <= t) ++j;
    if (!options.interpolate_groundtruth) {
      // Candidates: j (at or before t) and j + 1 (after t), both not used yet.
      size_t best = n_gt;
      int64_t best_dt = std::numeric_limits<int64_t>::max();
      for (size_t c = std::max(j, next_free); c <= j + 1 && c < n_gt; ++c) {
        const int64_t dt = t >= gt[c].t_ns ? t - gt[c].t_ns : gt[c].t_ns - t;
        if (dt < best_dt) {
          best_dt = dt;
          best = c;
        }
      }
      if (best == n_gt) continue;
      closest_ns = std::min(closest_ns, best_dt);
      if (best_dt > max_dt_ns) continue;
      out.t_ns.push_back(t);
      out.groundtruth.push_back(gt[best].T_w_b);
      out.estimate.push_back(est[e].T_w_b);
      out.estimate_index.push_back(e);
      next_free = best + 1;
    } else {
      if (t < gt.front().t_ns || t > gt.back().t_ns) {
        const int64_t dt = t < gt.front().t_ns ? gt.front().t_ns - t : t - gt.back().t_ns;
        closest_ns = std::min(closest_ns, dt);
        continue;
      }
      calib::SE3 T;
      if (gt[j].t_ns == t) {
        T = gt[j].T_w_b;
        closest_ns = 0;
      } else {
        // gt[j].t < t < gt[j + 1].t
        const int64_t gap = gt[j + 1].t_ns - gt[j].t_ns;
        closest_ns = std::min(closest_ns, std::min(t - gt[j].t_ns, gt[j + 1].t_ns - t));
        if (gap > 2 * max_dt_ns) continue;
        const double s = static_cast<double>(t - gt[j].t_ns) / static_cast<double>(gap);
        T = calib::se3_interpolate(gt[j].T_w_b, gt[j + 1].T_w_b, s);
      }
      out.t_ns.push_back(t);
      out.groundtruth.push_back(T);
      out.estimate.push_back(est[e].T_w_b);
      out.estimate_index.push_back(e);
    }
  }

  if (out.size() == 0) {
    std::ostringstream msg;
    msg << "association: no estimate pose has a ground-truth pose within max_dt = " << options.max_dt_s << " s";
    if (options.interpolate_groundtruth) msg << " (interpolation: inside the ground truth's range, neighbours at most 2 max_dt apart)";
    msg << ". Ground truth " << range_text(groundtruth) << ", estimate " << range_text(estimate);
    if (offset_ns != 0) msg << ", time offset " << options.time_offset_s << " s added to the estimate";
    msg << ".";
    const int64_t est_lo = estimate.t_begin_ns() + offset_ns, est_hi = estimate.t_end_ns() + offset_ns;
    if (est_hi < groundtruth.t_begin_ns() || est_lo > groundtruth.t_end_ns()) {
      msg << " The time ranges do not overlap.";
    } else if (closest_ns != std::numeric_limits<int64_t>::max()) {
      msg << " The closest stamps are " << static_cast<double>(closest_ns) * 1e-9
          << " s apart: increase max_dt or check the time offset.";
    }
    msg << unit_hint(groundtruth, estimate);
    throw std::invalid_argument(msg.str());
  }
  return out;
}

AlignmentResult align_positions(const std::vector<Eigen::Vector3d>& p_groundtruth,
                                const std::vector<Eigen::Vector3d>& p_estimate, Alignment method) {
  if (p_groundtruth.size() != p_estimate.size()) {
    throw std::invalid_argument("alignment: " + std::to_string(p_groundtruth.size()) + " ground-truth positions but " +
                                std::to_string(p_estimate.size()) + " estimate positions");
  }
  AlignmentResult r;
  r.method = method;
  r.pairs_used = p_groundtruth.size();
  if (method == Alignment::kNone) return r;
  if (method == Alignment::kFirstPose)
    throw std::invalid_argument("alignment first_pose needs the poses' orientations, not positions alone");
  const size_t n = p_groundtruth.size();
  const std::string name = alignment_name(method);
  if (n == 0) throw std::invalid_argument("alignment " + name + ": no pairs to align");
  for (size_t k = 0; k < n; ++k) {
    if (!p_groundtruth[k].allFinite() || !p_estimate[k].allFinite())
      throw std::invalid_argument("alignment " + name + ": non-finite position in pair " + std::to_string(k));
  }

  Eigen::Vector3d mu_gt, mu_est;
  centre(p_groundtruth, &mu_gt);
  centre(p_estimate, &mu_est);
  if (n == 1) {
    if (method == Alignment::kPosYaw) {
      r.translation = mu_gt - mu_est;
      return r;
    }
    throw std::invalid_argument("alignment " + name +
                                ": a single pair does not determine a rotation (needs at least 3 non-collinear "
                                "positions); use --align none or posyaw, or align on more poses");
  }
  // Cross-covariance S = 1/n sum (p_gt - mu_gt)(p_est - mu_est)^T and the estimate's variance.
  Eigen::Matrix3d S = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d C_est = Eigen::Matrix3d::Zero();
  double var_est = 0;
  for (size_t k = 0; k < n; ++k) {
    const Eigen::Vector3d g = p_groundtruth[k] - mu_gt;
    const Eigen::Vector3d e = p_estimate[k] - mu_est;
    S.noalias() += g * e.transpose();
    C_est.noalias() += e * e.transpose();
    var_est += e.squaredNorm();
  }
  const double inv_n = 1.0 / static_cast<double>(n);
  S *= inv_n;
  C_est *= inv_n;
  var_est *= inv_n;

  if (method == Alignment::kPosYaw) {
    const double A = S(0, 0) + S(1, 1);
    const double B = S(1, 0) - S(0, 1);
    if (no_horizontal_spread(p_estimate, mu_est) || (A == 0 && B == 0)) {
      throw std::invalid_argument("alignment posyaw: the estimate positions have no horizontal spread, so the yaw is "
                                  "undetermined; align on more poses");
    }
    r.rotation = rot_z(std::atan2(B, A));
    r.translation = mu_gt - r.rotation * mu_est;
    return r;
  }

  // se3 / sim3 need a rank >= 2 configuration (3 non-collinear points).
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(C_est);
  const Eigen::Vector3d ev = eig.eigenvalues();  // ascending
  if (!(ev(2) > 0) || !(ev(1) > 1e-18 * ev(2))) {
    throw std::invalid_argument("alignment " + name + ": the " + std::to_string(n) +
                                " estimate positions are collinear or identical, so the rotation about their line "
                                "is undetermined (needs at least 3 non-collinear positions); align on more poses "
                                "or use posyaw");
  }
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(S, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Matrix3d U = svd.matrixU();
  const Eigen::Matrix3d V = svd.matrixV();
  Eigen::Vector3d s_diag(1, 1, 1);
  if (U.determinant() * V.determinant() < 0) s_diag(2) = -1;  // reflection fix
  r.rotation = U * s_diag.asDiagonal() * V.transpose();
  if (method == Alignment::kSim3) {
    r.scale = svd.singularValues().dot(s_diag) / var_est;
    if (!(r.scale > 0) || !std::isfinite(r.scale))
      throw std::invalid_argument("alignment sim3: degenerate scale " + std::to_string(r.scale));
  }
  r.translation = mu_gt - r.scale * r.rotation * mu_est;
  return r;
}

namespace {
// True when the positions span a plane: RMS spread >= 1 mm and the second singular value of the
// centred positions at least 1e-3 of the first.
bool has_3d_spread(const std::vector<Eigen::Vector3d>& p) {
  if (p.size() < 3) return false;
  Eigen::Vector3d mu = Eigen::Vector3d::Zero();
  for (const auto& x : p) mu += x;
  mu /= static_cast<double>(p.size());
  Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
  for (const auto& x : p) C += (x - mu) * (x - mu).transpose();
  C /= static_cast<double>(p.size());
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(C);  // ascending eigenvalues
  const double s1 = std::sqrt(std::max(0.0, es.eigenvalues()(2))), s2 = std::sqrt(std::max(0.0, es.eigenvalues()(1)));
  return s1 >= 1e-3 && s2 >= 1e-3 * s1;
}
}  // namespace

AlignmentResult align(const AssociatedPoses& pairs, const AlignmentOptions& options) {
  std::string why;
  if (!options.Validate(&why)) throw std::invalid_argument(why);
  size_t n = pairs.size();
  if (options.first_poses > 0) n = std::min(n, options.first_poses);
  if (options.first_s > 0 && n > 0) {
    const int64_t limit_ns = seconds_to_ns(options.first_s);
    size_t m = 0;
    while (m < n && pairs.t_ns[m] - pairs.t_ns[0] <= limit_ns) ++m;
    n = m;
  }
  if (options.method == Alignment::kNone) {
    AlignmentResult r;
    r.pairs_used = n;
    return r;
  }
  std::vector<Eigen::Vector3d> p_gt(n), p_est(n);
  for (size_t k = 0; k < n; ++k) {
    p_gt[k] = pairs.groundtruth[k].translation;
    p_est[k] = pairs.estimate[k].translation;
  }
  if (options.method == Alignment::kPosYaw && n >= 1) {
    // Single pair, or no horizontal spread: yaw from the first pair's orientations (as rpg's
    // align_position_yaw_single), translation from its position.
    Eigen::Vector3d mu;
    centre(p_est, &mu);
    if (n == 1 || no_horizontal_spread(p_est, mu)) {
      const Eigen::Matrix3d C = pairs.estimate[0].rotation_matrix() * pairs.groundtruth[0].rotation_matrix().transpose();
      AlignmentResult r;
      r.method = Alignment::kPosYaw;
      r.pairs_used = n;
      r.rotation = rot_z(std::atan2(C(0, 1) - C(1, 0), C(0, 0) + C(1, 1)));
      r.translation = p_gt[0] - r.rotation * p_est[0];
      return r;
    }
  }
  if (n == 0) {
    throw std::invalid_argument(std::string("alignment ") + alignment_name(options.method) +
                                ": no pairs within the alignment window (first_s / first_poses)");
  }
  if (options.method == Alignment::kFirstPose ||
      ((options.method == Alignment::kSE3 || options.method == Alignment::kSim3) && n >= 2 &&
       (!has_3d_spread(p_gt) || !has_3d_spread(p_est)))) {
    // first_pose, or positions that do not span a plane (a still or rotating-in-place camera, a
    // straight line), which leave the Umeyama rotation undetermined: the first pair's poses
    // (rotation R_gt0 R_est0^T, translation from its positions, scale 1).
    AlignmentResult r;
    r.method = options.method;
    r.pairs_used = options.method == Alignment::kFirstPose ? 1 : n;
    r.rotation = pairs.groundtruth[0].rotation_matrix() * pairs.estimate[0].rotation_matrix().transpose();
    r.translation = p_gt[0] - r.rotation * p_est[0];
    return r;
  }
  return align_positions(p_gt, p_est, options.method);
}

calib::SE3 apply_alignment(const AlignmentResult& a, const calib::SE3& T_w_b) {
  const calib::Quat q_align(a.rotation);
  return calib::SE3(q_align * T_w_b.rotation, a.scale * (a.rotation * T_w_b.translation) + a.translation);
}

Stats compute_stats(std::vector<double> values) {
  Stats s;
  s.count = values.size();
  if (values.empty()) return s;
  const double n = static_cast<double>(values.size());
  double sum = 0, sum_sq = 0;
  s.min = values[0];
  s.max = values[0];
  for (double v : values) {
    sum += v;
    sum_sq += v * v;
    s.min = std::min(s.min, v);
    s.max = std::max(s.max, v);
  }
  s.mean = sum / n;
  s.rmse = std::sqrt(sum_sq / n);
  double var = 0;
  for (double v : values) var += (v - s.mean) * (v - s.mean);
  s.std = std::sqrt(var / n);
  const size_t mid = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(mid), values.end());
  const double upper = values[mid];
  if (values.size() % 2 == 1) {
    s.median = upper;
  } else {
    const double lower = *std::max_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(mid));
    s.median = 0.5 * (lower + upper);
  }
  return s;
}

double yaw_of(const Eigen::Matrix3d& R) { return std::atan2(R(1, 0), R(0, 0)); }

namespace {

// rpg's sub-trajectory ends: for each start i, the first j >= i minimising |d_j - (d_i + len)|
// among |.| < 0.2 len, or -1. d non-decreasing.
std::vector<long> sub_trajectory_ends(const std::vector<double>& d, double len) {
  const size_t n = d.size();
  std::vector<long> ends(n, -1);
  // first_of_plateau[k]: smallest index with the same distance as k.
  std::vector<size_t> first_of_plateau(n);
  for (size_t k = 0; k < n; ++k) first_of_plateau[k] = (k > 0 && d[k] == d[k - 1]) ? first_of_plateau[k - 1] : k;
  const double max_diff = 0.2 * len;
  size_t lo = 0;  // first index with d[lo] >= target (targets increase with i)
  for (size_t i = 0; i < n; ++i) {
    const double target = d[i] + len;
    if (lo < i) lo = i;
    while (lo < n && d[lo] < target) ++lo;
    long best = -1;
    double best_err = max_diff;
    // Below the target: the first index of the plateau just before lo (earliest wins ties).
    if (lo > i) {
      const size_t b = std::max(first_of_plateau[lo - 1], i);
      const double err = std::abs(d[b] - target);
      if (err < best_err) {
        best_err = err;
        best = static_cast<long>(b);
      }
    }
    if (lo < n) {
      const double err = std::abs(d[lo] - target);
      if (err < best_err) {
        best_err = err;
        best = static_cast<long>(lo);
      }
    }
    ends[i] = best;
  }
  return ends;
}

}  // namespace

EvaluationResult evaluate(const Trajectory& groundtruth, const Trajectory& estimate, const EvaluationOptions& options) {
  std::string why;
  if (!options.Validate(&why)) throw std::invalid_argument("evaluation options: " + why);
  EvaluationResult r;
  r.pairs = associate(groundtruth, estimate, options.association);
  const AssociatedPoses& P = r.pairs;
  const size_t n = P.size();
  r.matched_poses = n;
  r.alignment = align(P, options.alignment);
  r.groundtruth_length_m = path_length(P.groundtruth);

  // Absolute errors.
  r.aligned_estimate.resize(n);
  r.ate.trans_errors_m.resize(n);
  r.ate.rot_errors_deg.resize(n);
  for (size_t k = 0; k < n; ++k) {
    r.aligned_estimate[k] = apply_alignment(r.alignment, P.estimate[k]);
    r.ate.trans_errors_m[k] = (P.groundtruth[k].translation - r.aligned_estimate[k].translation).norm();
    r.ate.rot_errors_deg[k] = quat_angle(P.groundtruth[k].rotation.conjugate() * r.aligned_estimate[k].rotation) * kRadToDeg;
  }
  r.ate.trans_m = compute_stats(r.ate.trans_errors_m);
  r.ate.rot_deg = compute_stats(r.ate.rot_errors_deg);
  if (r.groundtruth_length_m > kMinPathLength_m) r.mean_position_error_percent = 100.0 * r.ate.trans_m.mean / r.groundtruth_length_m;
  {
    const Eigen::Matrix3d E = r.aligned_estimate[n - 1].rotation_matrix() * P.groundtruth[n - 1].rotation_matrix().transpose();
    r.final_yaw_error_deg = yaw_of(E) * kRadToDeg;
    if (r.groundtruth_length_m > kMinPathLength_m) r.yaw_drift_deg_per_m = std::abs(r.final_yaw_error_deg) / r.groundtruth_length_m;
  }

  // Relative errors.
  if (!options.rpe.lengths.empty()) {
    const double total_length = groundtruth.path_length_m();
    std::vector<double> d(n, 0.0);
    for (size_t k = 1; k < n; ++k) d[k] = d[k - 1] + (P.groundtruth[k].translation - P.groundtruth[k - 1].translation).norm();
    const double scale = r.alignment.scale;
    std::vector<double> e_trans, e_trans_pct, e_rot, e_yaw, e_yaw_per_m;
    for (double l : options.rpe.lengths) {
      double len = l;
      if (options.rpe.lengths_in_percent) len = std::trunc(l / 100.0 * total_length * 100.0) / 100.0;
      if (!(len > 0)) continue;  // e.g. a ground truth that does not move: no sub-trajectories
      const std::vector<long> ends = sub_trajectory_ends(d, len);
      e_trans.clear();
      e_trans_pct.clear();
      e_rot.clear();
      e_yaw.clear();
      e_yaw_per_m.clear();
      for (size_t i = 0; i < n; ++i) {
        if (ends[i] < 0) continue;
        const size_t j = static_cast<size_t>(ends[i]);
        const calib::SE3& gi = P.groundtruth[i];
        const calib::SE3& gj = P.groundtruth[j];
        const calib::SE3& ei = P.estimate[i];
        const calib::SE3& ej = P.estimate[j];
        // Relative motions i -> j.
        const calib::Quat q_gt_rel = gi.rotation.conjugate() * gj.rotation;
        const Eigen::Vector3d t_gt_rel = gi.rotation.conjugate() * (gj.translation - gi.translation);
        const calib::Quat q_est_rel = ei.rotation.conjugate() * ej.rotation;
        const Eigen::Vector3d t_est_rel = scale * (ei.rotation.conjugate() * (ej.translation - ei.translation));
        // E = T_gt_rel^-1 T_est_rel.
        const calib::Quat q_gt_rel_inv = q_gt_rel.conjugate();
        const calib::Quat q_E = q_gt_rel_inv * q_est_rel;
        const Eigen::Vector3d t_E = q_gt_rel_inv * (t_est_rel - t_gt_rel);
        // In the world frame: R_est_j E R_est_j^T (translation norm and angle unchanged).
        const calib::Quat q_Ew = ej.rotation * q_E * ej.rotation.conjugate();
        const double tn = t_E.norm();
        const double yaw = std::abs(yaw_of(q_Ew.toRotationMatrix())) * kRadToDeg;
        e_trans.push_back(tn);
        e_trans_pct.push_back(100.0 * tn / len);
        e_rot.push_back(quat_angle(q_E) * kRadToDeg);
        e_yaw.push_back(yaw);
        e_yaw_per_m.push_back(yaw / len);
      }
      RelativeError re;
      re.length_m = len;
      re.count = e_trans.size();
      re.trans_m = compute_stats(e_trans);
      re.trans_percent = compute_stats(e_trans_pct);
      re.rot_deg = compute_stats(e_rot);
      re.yaw_deg = compute_stats(e_yaw);
      re.yaw_deg_per_m = compute_stats(e_yaw_per_m);
      r.rpe.push_back(re);
    }
  }
  return r;
}

}  // namespace evio::evaluation
