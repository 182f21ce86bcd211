#include "evio/frontend/feature_tracker.h"
#include "evio/frontend/option_tables.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <map>
#include <memory>
#include <set>
#include <random>
#include <sstream>
#include <stdexcept>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include <opengv/relative_pose/CentralRelativeAdapter.hpp>
#include <opengv/sac/Ransac.hpp>
#include <opengv/sac_problems/relative_pose/CentralRelativePoseSacProblem.hpp>
#include <opengv/sac_problems/relative_pose/TranslationOnlySacProblem.hpp>


namespace evio::frontend {
namespace {

// OpenGV's SampleConsensusProblem draws its samples from a protected std::mt19937 seeded either
// from the clock or with a fixed 12345; this wrapper re-seeds it from our seed (both 32-bit
// halves through a seed_seq) and rebuilds the generator functor, which holds a copy of the engine.
template <class Problem>
class SeededProblem : public Problem {
 public:
  template <class... Args>
  explicit SeededProblem(uint64_t seed, Args&&... args)
      : Problem(std::forward<Args>(args)..., /*randomSeed=*/false) {
    std::seed_seq seq{static_cast<uint32_t>(seed & 0xffffffffu), static_cast<uint32_t>(seed >> 32)};
    this->rng_alg_.seed(seq);
    this->rng_gen_.reset(new std::function<int()>(std::bind(*this->rng_dist_, this->rng_alg_)));
  }
};

template <class Problem, class... Args>
bool run_ransac(double threshold, int max_iterations, uint64_t seed, std::vector<int>* inliers,
                Args&&... args) {
  auto problem = std::make_shared<SeededProblem<Problem>>(seed, std::forward<Args>(args)...);
  opengv::sac::Ransac<SeededProblem<Problem>> ransac(max_iterations, threshold, 0.99);
  ransac.sac_model_ = problem;
  if (!ransac.computeModel(0)) return false;
  *inliers = ransac.inliers_;
  return true;
}

// Translation-only two-view RANSAC with the rotation known (Kneip et al., BMVC 2011): with the
// previous bearing rotated into the current camera, m = R_cur_prev b_prev, a static point satisfies
// t . (m x b_cur) = 0 for the translation direction t, so two correspondences give
// t = n_1 x n_2 (n_i = m_i x b_cur_i). A correspondence's error is the angle of b_cur to its
// epipolar plane span(t, m), sin e = |t . n| / |t x m|, or its rotation-compensated displacement
// |n| (the sine of the angle between m and b_cur) when that is smaller: a point that hardly moved
// fits every translation (far away, or a short baseline). This test needs no triangulation: over the
// short baselines of 100 Hz event frames (a few mm), triangulated points come out at random depths
// and a reprojection test rejects correct tracks.
bool two_point_ransac(const std::vector<Eigen::Vector3d>& prev, const std::vector<Eigen::Vector3d>& cur,
                      const Eigen::Matrix3d& R_cur_prev, double threshold_rad, int max_iterations, uint64_t seed,
                      std::vector<bool>* inliers) {
  const size_t n = prev.size();
  const double s_max = std::sin(threshold_rad);
  std::vector<Eigen::Vector3d> m(n), nrm(n);
  size_t moved = 0;
  for (size_t i = 0; i < n; ++i) {
    m[i] = (R_cur_prev * prev[i]).normalized();
    nrm[i] = m[i].cross(cur[i].normalized());
    moved += nrm[i].norm() >= s_max ? 1 : 0;
  }
  inliers->assign(n, true);
  if (moved < 2) return true;  // nothing moved beyond the threshold: every translation fits
  // Cheirality: b_cur ~ lambda m + t with depth lambda > 0 puts b_cur x m along t x m, i.e.
  // n . (t x m) < 0; a point that moved the other way along its epipolar line is behind the camera
  // (a track sliding along an edge, say) and fits only as a point that did not move.
  const auto error = [&](const Eigen::Vector3d& t, size_t i) {
    const double d = nrm[i].norm();
    const Eigen::Vector3d txm = t.cross(m[i]);
    const double across = txm.norm();
    if (!(across > 1e-12) || nrm[i].dot(txm) > 0) return d;
    return std::min(d, std::abs(t.dot(nrm[i])) / across);
  };
  const auto count_of = [&](const Eigen::Vector3d& t) {
    size_t c = 0;
    for (size_t i = 0; i < n; ++i) c += error(t, i) < s_max ? 1 : 0;
    return c;
  };
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<size_t> pick(0, n - 1);
  size_t best_count = 0;
  Eigen::Vector3d best_t = Eigen::Vector3d::Zero();
  int needed = max_iterations;
  for (int it = 0; it < std::min(needed, max_iterations); ++it) {
    const size_t a = pick(rng);
    size_t b = pick(rng);
    if (a == b) b = (b + 1) % n;
    Eigen::Vector3d t = nrm[a].cross(nrm[b]);
    const double tn = t.norm();
    if (!(tn > 1e-12)) continue;
    t /= tn;
    // Both signs of the direction (the sample fixes the line only; cheirality picks the sign).
    size_t count = count_of(t);
    const size_t count_neg = count_of(-t);
    if (count_neg > count) {
      t = -t;
      count = count_neg;
    }
    if (count > best_count) {
      best_count = count;
      best_t = t;
      // Iterations for 99% confidence of one all-inlier sample at this inlier ratio.
      const double w = static_cast<double>(count) / static_cast<double>(n);
      const double p_fail = 1.0 - w * w;
      needed = p_fail <= 1e-12 ? 0 : static_cast<int>(std::ceil(std::log(0.01) / std::log(p_fail)));
    }
  }
  if (best_count == 0) return false;
  // Refinement on the inliers (a minimal sample's direction carries its two points' noise): t is the
  // direction most orthogonal to their epipolar-plane normals, each normal weighed by 1 / |t x m|^2
  // so that its term is the squared error (the smallest eigenvector of sum n n^T / |t x m|^2).
  for (int round = 0; round < 3; ++round) {
    Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
    size_t used = 0;
    for (size_t i = 0; i < n; ++i) {
      if (!(error(best_t, i) < s_max) || nrm[i].norm() < s_max) continue;  // points that did not move say nothing of t
      const double across = best_t.cross(m[i]).norm();
      if (!(across > 1e-6)) continue;
      A += nrm[i] * nrm[i].transpose() / (across * across);
      ++used;
    }
    if (used < 3) break;
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(A);
    Eigen::Vector3d t = es.eigenvectors().col(0);
    if (t.dot(best_t) < 0) t = -t;
    const size_t count = count_of(t);
    if (count < best_count) break;
    best_count = count;
    best_t = t;
  }
  // The zero translation (a rotation, or a baseline too short for any parallax) explains the points
  // that did not move; a translation must also explain at least half of those that did (at least 3),
  // else the moved points are outliers: its two sample points fit by construction, and a gross
  // outlier lies along a chosen epipolar line by chance about once in four (1 px against 5 px).
  const size_t still = n - moved;
  if (best_count < still + std::max<size_t>(3, (moved + 1) / 2)) {
    for (size_t i = 0; i < n; ++i) (*inliers)[i] = nrm[i].norm() < s_max;
    return true;
  }
  // Points that did not move fit any translation, but only at a depth far beyond the others: over
  // a long baseline (the moved inliers' median displacement above kStillRatio thresholds) a point
  // without parallax is a track stuck on the image rather than a point at infinity, and is dropped.
  constexpr double kStillRatio = 5.0;
  std::vector<double> moved_disp;
  for (size_t i = 0; i < n; ++i) {
    if (nrm[i].norm() >= s_max && error(best_t, i) < s_max) moved_disp.push_back(nrm[i].norm());
  }
  std::nth_element(moved_disp.begin(), moved_disp.begin() + static_cast<std::ptrdiff_t>(moved_disp.size() / 2), moved_disp.end());
  const bool long_baseline = moved_disp[moved_disp.size() / 2] > kStillRatio * s_max;
  for (size_t i = 0; i < n; ++i) {
    const bool still = nrm[i].norm() < s_max;
    (*inliers)[i] = still ? !long_baseline : error(best_t, i) < s_max;
  }
  return true;
}

uint64_t splitmix64(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

// Bilinear interpolation of an 8-bit image at (x, y); the caller keeps (x, y) within
// [0, cols - 1) x [0, rows - 1).
inline double bilinear(const cv::Mat& img, double x, double y) {
  const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
  const double ax = x - x0, ay = y - y0;
  const uint8_t* r0 = img.ptr<uint8_t>(y0) + x0;
  const uint8_t* r1 = img.ptr<uint8_t>(std::min(y0 + 1, img.rows - 1)) + x0;
  const int dx = x0 + 1 < img.cols ? 1 : 0;
  return (1 - ay) * ((1 - ax) * r0[0] + ax * r0[dx]) + ay * ((1 - ax) * r1[0] + ax * r1[dx]);
}

}  // namespace

bool align_warped_patch(const cv::Mat& ref, const cv::Point2f& ref_px, const Eigen::Matrix2d& A_cur_ref,
                        const cv::Mat& cur, int window_px, int max_iterations, double epsilon_px, cv::Point2f* cur_px,
                        double* turn_rad, double* log_scale) {
  if (ref.type() != CV_8UC1 || cur.type() != CV_8UC1 || window_px < 3 || window_px % 2 == 0 || !cur_px)
    throw std::invalid_argument("align_warped_patch: 8-bit single-channel images, an odd window >= 3 and an output are required");
  const double det = A_cur_ref.determinant();
  if (!(std::abs(det) > 1e-6) || !A_cur_ref.allFinite() || !std::isfinite(cur_px->x) || !std::isfinite(cur_px->y)) return false;
  const Eigen::Matrix2d A_inv = A_cur_ref.inverse();
  const int half = window_px / 2, n = 2 * half + 1, m = n + 2;  // m: one more ring for the gradients
  // The template, sampled on the current image's integer offsets y in [-half - 1, half + 1]^2 at
  // ref_px + A^-1 y (the reference patch as it looks in the current frame); samples outside the
  // reference image are missing.
  std::vector<double> T(static_cast<size_t>(m * m));
  std::vector<uchar> T_ok(static_cast<size_t>(m * m));
  for (int j = 0; j < m; ++j)
    for (int i = 0; i < m; ++i) {
      const Eigen::Vector2d q = Eigen::Vector2d(ref_px.x, ref_px.y) + A_inv * Eigen::Vector2d(i - half - 1, j - half - 1);
      const size_t k = static_cast<size_t>(j * m + i);
      T_ok[k] = q.x() >= 0 && q.y() >= 0 && q.x() < ref.cols - 1 && q.y() < ref.rows - 1;
      T[k] = T_ok[k] ? bilinear(ref, q.x(), q.y()) : 0.0;
    }
  // Parameters: translation (2), then the log-scale and the turn when asked for. Warp of a
  // template offset y: x = p + exp(sigma) R(phi) y.
  const bool scale = log_scale != nullptr, turn = turn_rad != nullptr;
  std::vector<int> active = {0, 1};
  if (scale) active.push_back(2);
  if (turn) active.push_back(3);
  const int np = static_cast<int>(active.size());
  // The pixels used: a template sample with its 3x3 neighbours (for the gradient), whose
  // current-image position stays inside the image while the alignment moves by up to kReach px
  // from its start.
  constexpr double kReach = 2.0;
  const Eigen::Vector2d start(cur_px->x, cur_px->y);
  std::vector<int> used;
  std::vector<Eigen::Vector4d> sd;  // steepest-descent images: d T / d (p_x, p_y, sigma, phi)
  std::vector<double> t;
  used.reserve(static_cast<size_t>(n * n));
  Eigen::Matrix4d H = Eigen::Matrix4d::Zero();
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const size_t c = static_cast<size_t>((j + 1) * m + i + 1), mm = static_cast<size_t>(m);
      if (!(T_ok[c - mm - 1] && T_ok[c - mm] && T_ok[c - mm + 1] && T_ok[c - 1] && T_ok[c + 1] && T_ok[c + mm - 1] && T_ok[c + mm] &&
            T_ok[c + mm + 1]))
        continue;
      const double x = start.x() + i - half, y = start.y() + j - half;
      if (!(x - kReach >= 0 && y - kReach >= 0 && x + kReach < cur.cols - 1 && y + kReach < cur.rows - 1)) continue;
      used.push_back(j * n + i);
      // Scharr derivatives (as OpenCV's KLT): the fixed point of the alignment weighs each
      // residual by this gradient, and its smoothing across the derivative steadies it on the
      // sparse, spiky event frames.
      const double gx = (3 * (T[c - mm + 1] - T[c - mm - 1]) + 10 * (T[c + 1] - T[c - 1]) + 3 * (T[c + mm + 1] - T[c + mm - 1])) / 32.0;
      const double gy = (3 * (T[c + mm - 1] - T[c - mm - 1]) + 10 * (T[c + mm] - T[c - mm]) + 3 * (T[c + mm + 1] - T[c - mm + 1])) / 32.0;
      const double yx = i - half, yy = j - half;
      sd.emplace_back(gx, gy, gx * yx + gy * yy, -gx * yy + gy * yx);
      t.push_back(T[c]);
      H += sd.back() * sd.back().transpose();
    }
  // At least half the window, with texture in both directions: the smaller eigenvalue of the
  // mean gradient matrix, in grey levels^2 / px^2 (OpenCV's KLT rejects 1e-4 of its own
  // normalisation, about 6.5 here).
  if (2 * used.size() < static_cast<size_t>(n * n)) return false;
  const Eigen::Matrix2d Ht = H.topLeftCorner<2, 2>();
  const double tr = Ht.trace(), dt = Ht.determinant();
  const double min_eig = 0.5 * (tr - std::sqrt(std::max(0.0, tr * tr - 4 * dt))) / static_cast<double>(used.size());
  if (!(min_eig > 1.0)) return false;
  // At most 4 parameters: fixed-capacity Eigen types, no heap allocation per track.
  using Mat = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, 0, 4, 4>;
  using Vec = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, 4, 1>;
  Mat Ha(np, np);
  for (int r = 0; r < np; ++r)
    for (int c = 0; c < np; ++c) Ha(r, c) = H(active[static_cast<size_t>(r)], active[static_cast<size_t>(c)]);
  const Eigen::LDLT<Mat> solver(Ha);
  if (solver.info() != Eigen::Success) return false;
  // Inverse-compositional steps; a step (dp, dsigma, dphi) composes as sigma <- sigma - dsigma,
  // phi <- phi - dphi, p <- p - exp(sigma) R(phi) dp.
  constexpr double kMaxTurnRad = 0.1, kMaxLogScale = 0.1;
  Eigen::Vector2d p = start;
  double sigma = 0, phi = 0;
  const auto in_range = [&] { return (p - start).cwiseAbs().maxCoeff() < kReach && std::abs(phi) < kMaxTurnRad && std::abs(sigma) < kMaxLogScale; };
  for (int it = 0; it < max_iterations; ++it) {
    if (!in_range()) return false;
    Vec b = Vec::Zero(np);
    if (np == 2) {  // translation only: one set of bilinear weights for the whole window
      const double x0 = p.x() - half, y0 = p.y() - half;
      const int ix = static_cast<int>(std::floor(x0)), iy = static_cast<int>(std::floor(y0));
      const double ax = x0 - ix, ay = y0 - iy;
      const double w00 = (1 - ax) * (1 - ay), w01 = ax * (1 - ay), w10 = (1 - ax) * ay, w11 = ax * ay;
      for (size_t k = 0; k < used.size(); ++k) {
        const int j = used[k] / n, i = used[k] % n;
        const uint8_t* r0 = cur.ptr<uint8_t>(iy + j) + ix + i;
        const uint8_t* r1 = cur.ptr<uint8_t>(iy + j + 1) + ix + i;
        const double e = w00 * r0[0] + w01 * r0[1] + w10 * r1[0] + w11 * r1[1] - t[k];
        b(0) += sd[k](0) * e;
        b(1) += sd[k](1) * e;
      }
    } else {
      const double sc = std::exp(sigma), c = sc * std::cos(phi), s = sc * std::sin(phi);
      for (size_t k = 0; k < used.size(); ++k) {
        const double yx = used[k] % n - half, yy = used[k] / n - half;
        const double x = p.x() + c * yx - s * yy, y = p.y() + s * yx + c * yy;
        if (!(x >= 0 && y >= 0 && x < cur.cols - 1 && y < cur.rows - 1)) return false;
        const double e = bilinear(cur, x, y) - t[k];
        for (int r = 0; r < np; ++r) b(r) += sd[k](active[static_cast<size_t>(r)]) * e;
      }
    }
    const Vec d = solver.solve(b);
    double dsigma = 0, dphi = 0;
    for (int r = 2; r < np; ++r) (active[static_cast<size_t>(r)] == 2 ? dsigma : dphi) = d(r);
    sigma -= dsigma;
    phi -= dphi;
    p -= std::exp(sigma) * (Eigen::Rotation2Dd(phi) * d.head<2>());
    if (!p.allFinite() || !std::isfinite(phi) || !std::isfinite(sigma)) return false;
    if (d.head<2>().norm() < epsilon_px && std::abs(dphi) * half < epsilon_px && std::abs(dsigma) * half < epsilon_px) break;
  }
  if (!in_range()) return false;
  *cur_px = cv::Point2f(static_cast<float>(p.x()), static_cast<float>(p.y()));
  if (turn) *turn_rad = phi;
  if (scale) *log_scale = sigma;
  return true;
}

Eigen::Matrix2d rotation_homography_jacobian(const calib::CameraIntrinsics& K, const Eigen::Matrix3d& R_cur_ref,
                                             const cv::Point2f& ref_px) {
  Eigen::Matrix3d Km;
  Km << K.fx, 0, K.cx, 0, K.fy, K.cy, 0, 0, 1;
  Eigen::Matrix3d Ki;
  Ki << 1 / K.fx, 0, -K.cx / K.fx, 0, 1 / K.fy, -K.cy / K.fy, 0, 0, 1;
  const Eigen::Matrix3d H = Km * R_cur_ref * Ki;
  const Eigen::Vector3d h = H * Eigen::Vector3d(ref_px.x, ref_px.y, 1.0);
  if (!(h.z() > 1e-9)) return Eigen::Matrix2d::Identity();
  const double x = h.x() / h.z(), y = h.y() / h.z();
  Eigen::Matrix2d J;
  J << H(0, 0) - x * H(2, 0), H(0, 1) - x * H(2, 1), H(1, 0) - y * H(2, 0), H(1, 1) - y * H(2, 1);
  return J / h.z();
}

const char* klt_warp_name(KltWarp warp) {
  switch (warp) {
    case KltWarp::kNone: return "none";
    case KltWarp::kRotation: return "rotation";
    case KltWarp::kRotationScale: return "rotation_scale";
  }
  return "unknown";
}

const char* ransac_model_name(RansacModel model) {
  switch (model) {
    case RansacModel::kNone: return "none";
    case RansacModel::kTwoPoint: return "two_point";
    case RansacModel::kTwoPointTriangulating: return "two_point_triangulating";
    case RansacModel::kFivePoint: return "five_point";
  }
  return "unknown";
}

int ransac_min_correspondences(RansacModel model) {
  switch (model) {
    case RansacModel::kNone: return 0;
    case RansacModel::kTwoPoint:
    case RansacModel::kTwoPointTriangulating: return 2;
    case RansacModel::kFivePoint: return 8;
  }
  return 0;
}

std::vector<bool> ransac_inliers(const std::vector<Eigen::Vector3d>& bearings_prev,
                                 const std::vector<Eigen::Vector3d>& bearings_cur,
                                 RansacModel model, const Eigen::Matrix3d* R_cur_prev,
                                 double threshold_rad, int max_iterations, uint64_t seed) {
  if (bearings_prev.size() != bearings_cur.size()) {
    std::ostringstream os;
    os << "ransac_inliers: " << bearings_prev.size() << " previous bearings but "
       << bearings_cur.size() << " current ones";
    throw std::invalid_argument(os.str());
  }
  if (!(threshold_rad > 0) || !std::isfinite(threshold_rad) || max_iterations < 1) {
    throw std::invalid_argument("ransac_inliers: threshold_rad must be positive and finite and "
                                "max_iterations >= 1");
  }
  const size_t n = bearings_prev.size();
  std::vector<bool> all(n, true);
  if (model == RansacModel::kNone || n < static_cast<size_t>(ransac_min_correspondences(model))) {
    return all;
  }
  // OpenGV: viewpoint 1 = previous, 2 = current; R12 maps viewpoint-2 coordinates into viewpoint 1
  // (p_1 = R12 p_2 + t12), so R12 = R_cur_prev^T.
  opengv::bearingVectors_t f1(bearings_prev.begin(), bearings_prev.end());
  opengv::bearingVectors_t f2(bearings_cur.begin(), bearings_cur.end());
  for (auto& f : f1) f.normalize();
  for (auto& f : f2) f.normalize();
  const opengv::rotation_t R12 =
      R_cur_prev ? opengv::rotation_t(R_cur_prev->transpose()) : opengv::rotation_t::Identity();
  opengv::relative_pose::CentralRelativeAdapter adapter(f1, f2, R12);
  const double threshold = 1.0 - std::cos(threshold_rad);
  std::vector<int> inliers;
  bool ok = false;
  using opengv::sac_problems::relative_pose::CentralRelativePoseSacProblem;
  if (model == RansacModel::kTwoPointTriangulating) {
    ok = run_ransac<opengv::sac_problems::relative_pose::TranslationOnlySacProblem>(threshold, max_iterations, seed, &inliers, adapter);
  } else if (model == RansacModel::kTwoPoint) {
    std::vector<bool> out;
    if (!two_point_ransac(bearings_prev, bearings_cur, R_cur_prev ? *R_cur_prev : Eigen::Matrix3d::Identity(), threshold_rad,
                          max_iterations, seed, &out)) {
      return all;
    }
    return out;
  } else {
    ok = run_ransac<CentralRelativePoseSacProblem>(threshold, max_iterations, seed, &inliers,
                                                   adapter, CentralRelativePoseSacProblem::NISTER);
  }
  if (!ok) return all;
  std::vector<bool> out(n, false);
  for (int i : inliers) out[static_cast<size_t>(i)] = true;
  return out;
}

bool FeatureTrackerOptions::Validate(std::string* why) const {
  if (!feature_tracker_table().check(*this, why)) return false;
  if (klt_window_px % 2 == 0) return validation_failed(why, "klt_window_px must be odd");
  if (min_tracks_before_detection > max_features)
    return validation_failed(why, "min_tracks_before_detection must be <= max_features");
  return true;
}

FeatureTracker::FeatureTracker(const calib::CameraIntrinsics& ideal_pinhole,
                               const FeatureTrackerOptions& options)
    : K_(ideal_pinhole), options_(options) {
  std::string why;
  if (!K_.Validate(&why)) throw std::invalid_argument("FeatureTracker: camera: " + why);
  if (K_.model != calib::DistortionModel::kNone)
    throw std::invalid_argument("FeatureTracker: the camera must be the ideal pinhole of "
                                "undistorted frames (distortion model none)");
  if (!options_.Validate(&why)) throw std::invalid_argument("FeatureTracker: options: " + why);
  if (2 * options_.border_px >= std::min(K_.width, K_.height))
    throw std::invalid_argument("FeatureTracker: border_px leaves no image");
}

Eigen::Vector3d FeatureTracker::bearing(const cv::Point2f& px) const {
  return Eigen::Vector3d((px.x - K_.cx) / K_.fx, (px.y - K_.cy) / K_.fy, 1.0).normalized();
}

int FeatureTracker::cell_of(const cv::Point2f& px) const {
  int c = static_cast<int>(std::floor(px.x * options_.grid_cols / K_.width));
  int r = static_cast<int>(std::floor(px.y * options_.grid_rows / K_.height));
  c = std::clamp(c, 0, options_.grid_cols - 1);
  r = std::clamp(r, 0, options_.grid_rows - 1);
  return r * options_.grid_cols + c;
}

bool FeatureTracker::inside(const cv::Point2f& px) const {
  const float b = static_cast<float>(options_.border_px);
  if (!(std::isfinite(px.x) && std::isfinite(px.y) && px.x >= b && px.y >= b && px.x <= K_.width - 1 - b &&
        px.y <= K_.height - 1 - b)) {
    return false;
  }
  return valid_.empty() || valid_.at<uint8_t>(cvRound(px.y), cvRound(px.x)) != 0;
}

void FeatureTracker::set_valid_mask(const cv::Mat& mask) {
  if (mask.empty()) {
    valid_.release();
    return;
  }
  if (mask.type() != CV_8UC1 || mask.cols != K_.width || mask.rows != K_.height) {
    throw std::invalid_argument("FeatureTracker::set_valid_mask: a CV_8UC1 mask of the camera's size is required");
  }
  // A feature's whole KLT window must lie on valid pixels.
  const int half = options_.klt_window_px / 2;
  cv::erode(mask, valid_, cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * half + 1, 2 * half + 1)), cv::Point(-1, -1), 1,
            cv::BORDER_CONSTANT, cv::Scalar(255));
}

std::vector<std::pair<int64_t, cv::Point2f>> FeatureTracker::current() const {
  std::vector<std::pair<int64_t, cv::Point2f>> out;
  out.reserve(tracks_.size());
  for (const Track& t : tracks_) out.emplace_back(t.id, t.px);
  return out;
}

void FeatureTracker::detect(const cv::Mat& frame) {
  const int budget = options_.max_features - static_cast<int>(tracks_.size());
  if (budget <= 0) return;
  std::vector<cv::KeyPoint> corners;
  cv::FAST(frame, corners, options_.fast_threshold, /*nonmaxSuppression=*/true);
  // Strongest first; ties broken by position so the order never depends on the detector's.
  std::sort(corners.begin(), corners.end(), [](const cv::KeyPoint& a, const cv::KeyPoint& b) {
    if (a.response != b.response) return a.response > b.response;
    if (a.pt.y != b.pt.y) return a.pt.y < b.pt.y;
    return a.pt.x < b.pt.x;
  });
  std::vector<int> per_cell(static_cast<size_t>(options_.grid_cols * options_.grid_rows), 0);
  cv::Mat occupied(frame.size(), CV_8UC1, cv::Scalar(0));
  const int r = options_.min_distance_px;
  for (const Track& t : tracks_) {
    ++per_cell[static_cast<size_t>(cell_of(t.px))];
    if (r > 0) cv::circle(occupied, cv::Point(cvRound(t.px.x), cvRound(t.px.y)), r, 255, -1);
  }
  int added = 0;
  for (const cv::KeyPoint& kp : corners) {
    if (added >= budget) break;
    if (!inside(kp.pt)) continue;
    const int cell = cell_of(kp.pt);
    if (per_cell[static_cast<size_t>(cell)] >= options_.max_per_cell) continue;
    const cv::Point ip(cvRound(kp.pt.x), cvRound(kp.pt.y));
    if (occupied.at<uint8_t>(ip) != 0) continue;
    tracks_.push_back({next_id_++, kp.pt, frame_id_, kp.pt, false, kp.pt});
    ++per_cell[static_cast<size_t>(cell)];
    if (r > 0) cv::circle(occupied, ip, r, 255, -1);
    ++added;
  }
  stats_.detected += added;
}

void FeatureTracker::verify_against_anchor(std::vector<Track>* tracks, const Eigen::Matrix3d* R_cur_prev) {
  if (anchor_frame_ < 0) return;
  if (!R_cur_prev) {  // the rotation since the anchor is unknown: restart it at this frame
    anchor_frame_ = -1;
    for (Track& t : *tracks) t.anchored = false;
    return;
  }
  R_cur_anchor_ = *R_cur_prev * R_cur_anchor_;
  std::vector<size_t> idx;
  std::vector<Eigen::Vector3d> b0, b1;
  for (size_t i = 0; i < tracks->size(); ++i) {
    const Track& t = (*tracks)[i];
    if (!t.anchored) continue;
    idx.push_back(i);
    b0.push_back(bearing(t.anchor_px));
    b1.push_back(bearing(t.px));
  }
  if (idx.size() < static_cast<size_t>(ransac_min_correspondences(RansacModel::kTwoPoint))) return;
  const double f = std::sqrt(K_.fx * K_.fy);
  const std::vector<bool> inlier =
      ransac_inliers(b0, b1, RansacModel::kTwoPoint, &R_cur_anchor_, std::atan(options_.anchor_ransac_threshold_px / f),
                     options_.ransac_max_iterations,
                     splitmix64(~options_.seed ^ splitmix64(static_cast<uint64_t>(frame_id_))));
  std::vector<bool> drop(tracks->size(), false);
  for (size_t k = 0; k < idx.size(); ++k) drop[idx[k]] = !inlier[k];
  std::vector<Track> kept;
  kept.reserve(tracks->size());
  for (size_t i = 0; i < tracks->size(); ++i) {
    if (drop[i]) {
      ++stats_.rejected_anchor;
    } else {
      kept.push_back((*tracks)[i]);
    }
  }
  *tracks = std::move(kept);
}

std::vector<int64_t> FeatureTracker::lost_track_ids() const {
  std::vector<int64_t> ids;
  ids.reserve(lost_.size());
  for (const auto& [id, l] : lost_) ids.push_back(id);
  return ids;
}

void FeatureTracker::reacquire(int64_t t_ns, const std::vector<cv::Mat>& pyramid, int levels,
                               const std::vector<TrackPrediction>& predictions) {
  const cv::Size win(options_.klt_window_px, options_.klt_window_px);
  const cv::TermCriteria term(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, options_.klt_max_iterations, options_.klt_epsilon_px);
  std::set<int64_t> live;
  for (const Track& t : tracks_) live.insert(t.id);
  // Candidates grouped by their template's frame (one KLT call per reference pyramid).
  std::map<int64_t, std::vector<std::pair<int64_t, cv::Point2f>>> by_ref;
  for (const TrackPrediction& p : predictions) {
    const auto it = lost_.find(p.track_id);
    if (it == lost_.end() || live.count(p.track_id) || !p.px.allFinite()) continue;
    const cv::Point2f q(static_cast<float>(p.px.x()), static_cast<float>(p.px.y()));
    if (!inside(q)) continue;
    by_ref[it->second.ref_frame].emplace_back(p.track_id, q);
  }
  const double fb2 = options_.forward_backward_max_px * options_.forward_backward_max_px;
  const double max2 = options_.reacquire_max_px * options_.reacquire_max_px;
  for (auto& [ref, cands] : by_ref) {
    const RefFrame* rf = nullptr;
    for (const RefFrame& r : ref_frames_)
      if (r.frame == ref) rf = &r;
    if (!rf) continue;
    if (options_.template_max_rotation_deg > 0 &&
        (!rf->rotation_known || Eigen::AngleAxisd(rf->R_cur_ref).angle() > 2 * options_.template_max_rotation_deg * M_PI / 180.0)) {
      continue;
    }
    std::vector<cv::Point2f> q0, q1, qb;
    for (const auto& [id, q] : cands) {
      q0.push_back(lost_.at(id).ref_px);
      q1.push_back(q);
    }
    const std::vector<cv::Point2f> predicted = q1;
    std::vector<uchar> sf, sb;
    cv::calcOpticalFlowPyrLK(rf->pyramid, pyramid, q0, q1, sf, cv::noArray(), win, levels, term, cv::OPTFLOW_USE_INITIAL_FLOW);
    qb = q0;
    cv::calcOpticalFlowPyrLK(pyramid, rf->pyramid, q1, qb, sb, cv::noArray(), win, levels, term, cv::OPTFLOW_USE_INITIAL_FLOW);
    for (size_t k = 0; k < cands.size(); ++k) {
      const cv::Point2f d = q1[k] - predicted[k], e = qb[k] - q0[k];
      if (!sf[k] || !sb[k] || !inside(q1[k]) || e.dot(e) > fb2 || d.dot(d) > max2) continue;
      Track t;
      t.id = cands[k].first;
      t.px = q1[k];
      t.ref_frame = ref;
      t.ref_px = q0[k];
      tracks_.push_back(t);
      lost_.erase(t.id);
      ++stats_.reacquired;
    }
  }
  (void)t_ns;
}

FeatureObservations FeatureTracker::track(int64_t t_ns, const cv::Mat& frame,
                                          const Eigen::Matrix3d* R_cur_prev,
                                          const std::vector<TrackPrediction>* predictions) {
  if (frame.empty() || frame.type() != CV_8UC1 || frame.cols != K_.width ||
      frame.rows != K_.height) {
    std::ostringstream os;
    os << "FeatureTracker::track: expected an 8-bit single-channel " << K_.width << "x"
       << K_.height << " frame, got type " << frame.type() << " " << frame.cols << "x"
       << frame.rows;
    throw std::invalid_argument(os.str());
  }
  const cv::Size win(options_.klt_window_px, options_.klt_window_px);
  std::vector<cv::Mat> pyramid;
  const int levels = cv::buildOpticalFlowPyramid(frame, pyramid, win, options_.klt_pyramid_levels,
                                                 /*withDerivatives=*/true, cv::BORDER_REFLECT_101,
                                                 cv::BORDER_CONSTANT, /*tryReuseInputImage=*/false);
  const cv::TermCriteria term(cv::TermCriteria::COUNT | cv::TermCriteria::EPS,
                              options_.klt_max_iterations, options_.klt_epsilon_px);

  if (!tracks_.empty() && !prev_pyramid_.empty()) {
    const size_t n = tracks_.size();
    std::vector<cv::Point2f> p0(n), p1(n), back(n);
    for (size_t i = 0; i < n; ++i) {
      p0[i] = tracks_[i].px;
      p1[i] = p0[i];
      if (R_cur_prev) {  // rotate the bearing (points at infinity) and project
        const Eigen::Vector3d b =
            *R_cur_prev * Eigen::Vector3d((p0[i].x - K_.cx) / K_.fx, (p0[i].y - K_.cy) / K_.fy, 1);
        if (b.z() > 1e-6) {
          const cv::Point2f q(static_cast<float>(K_.fx * b.x() / b.z() + K_.cx),
                              static_cast<float>(K_.fy * b.y() / b.z() + K_.cy));
          if (inside(q)) p1[i] = q;
        }
      }
    }
    const std::vector<cv::Point2f> guess = p1;  // KLT's initial positions (rotation prior)
    std::vector<uchar> st_f(n, 0), st_b(n, 0);
    std::vector<cv::Point2f> ref_px(n);
    // One KLT call per reference frame (with template_max_age_frames = 1 that is the previous
    // frame for every track).
    const bool chained = options_.template_max_age_frames == 1;
    // Templates turned by more than template_max_rotation_deg since their frame (or by an unknown
    // rotation) are not used: such tracks go from the previous frame and their template restarts.
    for (RefFrame& rf : ref_frames_) {
      if (R_cur_prev) {
        rf.R_cur_ref = *R_cur_prev * rf.R_cur_ref;
      } else {
        rf.rotation_known = false;
      }
    }
    auto too_rotated = [&](int64_t ref) {
      if (options_.template_max_rotation_deg <= 0) return false;
      for (const RefFrame& rf : ref_frames_) {
        if (rf.frame != ref) continue;
        if (!rf.rotation_known) return true;
        return Eigen::AngleAxisd(rf.R_cur_ref).angle() > options_.template_max_rotation_deg * M_PI / 180.0;
      }
      return true;
    };
    // refs: the frame each track's KLT aligns from; templ: its template's frame. With
    // klt_warp every track's KLT goes from the previous frame (a small turn, so a small bias and a
    // sure convergence) and the warped refinement below aligns it to its template.
    const bool warp = options_.klt_warp != KltWarp::kNone;
    std::vector<int64_t> refs, templ;
    std::vector<uchar> refresh(n, 0);
    for (size_t i = 0; i < n; ++i) {
      const Track& t = tracks_[i];
      if (chained || t.ref_frame == frame_id_ - 1) {
        templ.push_back(frame_id_ - 1);
      } else if (too_rotated(t.ref_frame)) {
        templ.push_back(frame_id_ - 1);
        refresh[i] = 1;
        ++stats_.template_rotation_refreshes;
      } else {
        templ.push_back(t.ref_frame);
      }
      refs.push_back(warp ? frame_id_ - 1 : templ.back());
    }
    std::vector<int64_t> groups = refs;
    std::sort(groups.begin(), groups.end());
    groups.erase(std::unique(groups.begin(), groups.end()), groups.end());
    for (int64_t g : groups) {
      const std::vector<cv::Mat>* ref_pyr = &prev_pyramid_;
      if (g != frame_id_ - 1) {
        ref_pyr = nullptr;
        for (const RefFrame& rf : ref_frames_)
          if (rf.frame == g) ref_pyr = &rf.pyramid;
        if (!ref_pyr) continue;  // cannot happen: every referenced pyramid is kept
      }
      std::vector<size_t> idx;
      std::vector<cv::Point2f> q0, q1, qb;
      for (size_t i = 0; i < n; ++i) {
        if (refs[i] != g) continue;
        idx.push_back(i);
        ref_px[i] = g == frame_id_ - 1 ? p0[i] : tracks_[i].ref_px;
        q0.push_back(ref_px[i]);
        q1.push_back(p1[i]);
      }
      std::vector<uchar> sf, sb;
      // No error output: OpenCV then skips its per-point residual pass (the status is the same).
      cv::calcOpticalFlowPyrLK(*ref_pyr, pyramid, q0, q1, sf, cv::noArray(), win, levels, term,
                               cv::OPTFLOW_USE_INITIAL_FLOW);
      qb = q0;
      cv::calcOpticalFlowPyrLK(pyramid, *ref_pyr, q1, qb, sb, cv::noArray(), win, levels, term,
                               cv::OPTFLOW_USE_INITIAL_FLOW);
      for (size_t k = 0; k < idx.size(); ++k) {
        p1[idx[k]] = q1[k];
        back[idx[k]] = qb[k];
        st_f[idx[k]] = sf[k];
        st_b[idx[k]] = sb[k];
      }
    }
    const double fb2 = options_.forward_backward_max_px * options_.forward_backward_max_px;
    auto passed = [&](size_t i) {
      const double dx = back[i].x - ref_px[i].x, dy = back[i].y - ref_px[i].y;
      return st_f[i] && inside(p1[i]) && st_b[i] && dx * dx + dy * dy <= fb2;
    };
    // Template fallback: a track that fails against an older reference is tracked from the
    // previous frame instead (chained) and its reference restarts at this frame.
    std::vector<uchar> fell_back(n, 0);
    if (!chained && options_.template_fallback) {
      std::vector<size_t> idx;
      std::vector<cv::Point2f> q0, q1, qb;
      for (size_t i = 0; i < n; ++i) {
        if (refs[i] == frame_id_ - 1 || passed(i)) continue;
        idx.push_back(i);
        q0.push_back(p0[i]);
        q1.push_back(guess[i]);
      }
      if (!idx.empty()) {
        std::vector<uchar> sf, sb;
        cv::calcOpticalFlowPyrLK(prev_pyramid_, pyramid, q0, q1, sf, cv::noArray(), win, levels, term,
                                 cv::OPTFLOW_USE_INITIAL_FLOW);
        qb = q0;
        cv::calcOpticalFlowPyrLK(pyramid, prev_pyramid_, q1, qb, sb, cv::noArray(), win, levels, term,
                                 cv::OPTFLOW_USE_INITIAL_FLOW);
        for (size_t k = 0; k < idx.size(); ++k) {
          const size_t i = idx[k];
          p1[i] = q1[k];
          back[i] = qb[k];
          ref_px[i] = p0[i];
          st_f[i] = sf[k];
          st_b[i] = sb[k];
          fell_back[i] = 1;
        }
        stats_.template_fallbacks += static_cast<int64_t>(idx.size());
      }
    }
    // Warped refinement (klt_warp) of the tracks KLT and the forward-backward
    // check kept: against the track's template, or the previous frame when the template is that
    // frame, cannot be warped (rotation unknown) or fails (template_fallback; its template then
    // restarts); without the IMU rotation to the previous frame the KLT result stays.
    std::vector<uchar> warp_failed(n, 0);
    if (warp) {
      const auto refine = [&](const cv::Mat& ref_img, const cv::Point2f& ref_pt, const Eigen::Matrix3d& R_cur_ref, size_t i) {
        cv::Point2f q = p1[i];
        double log_scale = 0;
        if (!align_warped_patch(ref_img, ref_pt, rotation_homography_jacobian(K_, R_cur_ref, ref_pt), pyramid[0], options_.klt_window_px,
                                options_.klt_max_iterations, options_.klt_epsilon_px, &q, nullptr,
                                options_.klt_warp == KltWarp::kRotationScale ? &log_scale : nullptr))
          return false;
        const cv::Point2f d = q - p1[i];
        if (d.dot(d) > fb2 || !inside(q)) return false;
        p1[i] = q;
        return true;
      };
      for (size_t i = 0; i < n; ++i) {
        if (!passed(i)) continue;
        if (templ[i] != frame_id_ - 1) {
          const RefFrame* rf = nullptr;
          for (const RefFrame& r : ref_frames_)
            if (r.frame == templ[i]) rf = &r;
          if (rf && rf->rotation_known && refine(rf->pyramid[0], tracks_[i].ref_px, rf->R_cur_ref, i)) continue;
          if (!options_.template_fallback) {
            warp_failed[i] = 1;
            continue;
          }
          fell_back[i] = 1;
          ++stats_.template_fallbacks;
        }
        if (R_cur_prev && !refine(prev_pyramid_[0], p0[i], *R_cur_prev, i)) warp_failed[i] = 1;
      }
    }
    std::vector<size_t> kept;
    kept.reserve(n);
    // A lost track keeps its template for re-acquisition (the reference it was last aligned
    // against: its own patch, not a position that failed).
    const auto remember = [&](const Track& t) {
      if (options_.reacquire_max_age_s > 0 && options_.template_max_age_frames > 1) lost_[t.id] = {t.ref_frame, t.ref_px, t_ns};
    };
    for (size_t i = 0; i < n; ++i) {
      if (!st_f[i] || !inside(p1[i])) {
        ++stats_.lost_klt;
        remember(tracks_[i]);
        continue;
      }
      const double dx = back[i].x - ref_px[i].x, dy = back[i].y - ref_px[i].y;
      if (!st_b[i] || !(dx * dx + dy * dy <= fb2)) {
        ++stats_.lost_fb;
        remember(tracks_[i]);
        continue;
      }
      if (warp_failed[i]) {
        ++stats_.lost_warp;
        remember(tracks_[i]);
        continue;
      }
      kept.push_back(i);
    }
    RansacModel model = options_.ransac;
    if ((model == RansacModel::kTwoPoint || model == RansacModel::kTwoPointTriangulating) && !R_cur_prev) model = RansacModel::kFivePoint;
    std::vector<bool> inlier(kept.size(), true);
    if (model != RansacModel::kNone) {
      std::vector<Eigen::Vector3d> b0, b1;
      b0.reserve(kept.size());
      b1.reserve(kept.size());
      for (size_t i : kept) {
        b0.push_back(bearing(p0[i]));
        b1.push_back(bearing(p1[i]));
      }
      const double f = std::sqrt(K_.fx * K_.fy);
      inlier = ransac_inliers(b0, b1, model, R_cur_prev, std::atan(options_.ransac_threshold_px / f),
                              options_.ransac_max_iterations,
                              splitmix64(options_.seed ^ splitmix64(static_cast<uint64_t>(frame_id_))));
    }
    std::vector<Track> survivors;
    survivors.reserve(kept.size());
    for (size_t k = 0; k < kept.size(); ++k) {
      if (!inlier[k]) {
        ++stats_.rejected_ransac;
        remember(tracks_[kept[k]]);
        continue;
      }
      Track t = tracks_[kept[k]];
      t.px = p1[kept[k]];
      // The template is refreshed once it is template_max_age_frames old (or after a fallback).
      if (fell_back[kept[k]] || refresh[kept[k]] || frame_id_ - t.ref_frame >= options_.template_max_age_frames) {
        t.ref_frame = frame_id_;
        t.ref_px = t.px;
      }
      survivors.push_back(t);
    }
    if (options_.anchor_frames > 0) verify_against_anchor(&survivors, R_cur_prev);
    stats_.tracked += static_cast<int64_t>(survivors.size());
    tracks_ = std::move(survivors);
  } else {
    tracks_.clear();
  }

  // Lost templates expire after reacquire_max_age_s; the rest are looked for at their predictions.
  for (auto it = lost_.begin(); it != lost_.end();) {
    it = 1e-9 * static_cast<double>(t_ns - it->second.lost_t_ns) > options_.reacquire_max_age_s ? lost_.erase(it) : std::next(it);
  }
  if (predictions && !predictions->empty() && !lost_.empty() && !prev_pyramid_.empty()) reacquire(t_ns, pyramid, levels, *predictions);
  if (stats_.frames == 0 ||
      static_cast<int>(tracks_.size()) < options_.min_tracks_before_detection) {
    detect(frame);
  }
  if (options_.template_max_age_frames > 1) {
    // Keep the pyramids still referenced (this frame's is referenced by new and refreshed tracks),
    // also by the templates of lost tracks.
    std::vector<RefFrame> keep;
    for (RefFrame& rf : ref_frames_) {
      const bool used = std::any_of(tracks_.begin(), tracks_.end(), [&](const Track& t) { return t.ref_frame == rf.frame; }) ||
                        std::any_of(lost_.begin(), lost_.end(), [&](const auto& l) { return l.second.ref_frame == rf.frame; });
      if (used) keep.push_back(std::move(rf));
    }
    keep.push_back({frame_id_, pyramid, Eigen::Matrix3d::Identity(), true});
    ref_frames_ = std::move(keep);
  }
  prev_pyramid_ = std::move(pyramid);
  if (options_.anchor_frames > 0 &&
      (anchor_frame_ < 0 || frame_id_ - anchor_frame_ >= options_.anchor_frames)) {
    anchor_frame_ = frame_id_;
    R_cur_anchor_.setIdentity();
    for (Track& t : tracks_) {
      t.anchored = true;
      t.anchor_px = t.px;
    }
  }

  FeatureObservations out;
  out.t_ns = t_ns;
  out.frame_id = frame_id_++;
  out.observations.reserve(tracks_.size());
  for (const Track& t : tracks_) out.observations.push_back({t.id, bearing(t.px)});
  ++stats_.frames;
  return out;
}

}  // namespace evio::frontend
