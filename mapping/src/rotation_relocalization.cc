#include "evio/mapping/rotation_relocalization.h"
#include "evio/mapping/option_tables.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "evio/calib/fast_math.h"
#include "evio/calib/geometry.h"

namespace evio::mapping {

bool RotationRelocalizationOptions::Validate(std::string* why) const {
  if (!relocalization_table().check(*this, why)) return false;
  if (refine_final_step_deg > refine_initial_step_deg)
    return validation_failed(why, "refine_final_step_deg must be <= refine_initial_step_deg");
  return true;
}

namespace {

constexpr double kDeg = M_PI / 180.0;

// Separable Gaussian blur, u periodic, v clamped.
void blur(std::vector<float>* img, int W, int H, double sigma) {
  if (sigma <= 0) return;
  const int r = std::max(1, static_cast<int>(std::ceil(3 * sigma)));
  std::vector<float> k(2 * r + 1);
  float sum = 0;
  for (int i = -r; i <= r; ++i) sum += k[i + r] = static_cast<float>(std::exp(-0.5 * i * i / (sigma * sigma)));
  for (float& v : k) v /= sum;
  std::vector<float> tmp(img->size());
  const std::vector<float>& a = *img;
  for (int j = 0; j < H; ++j) {
    const float* row = a.data() + static_cast<size_t>(j) * W;
    float* out = tmp.data() + static_cast<size_t>(j) * W;
    for (int i = 0; i < W; ++i) {
      float s = 0;
      for (int d = -r; d <= r; ++d) s += k[d + r] * row[((i + d) % W + W) % W];
      out[i] = s;
    }
  }
  for (int j = 0; j < H; ++j)
    for (int i = 0; i < W; ++i) {
      float s = 0;
      for (int d = -r; d <= r; ++d) s += k[d + r] * tmp[static_cast<size_t>(std::clamp(j + d, 0, H - 1)) * W + i];
      (*img)[static_cast<size_t>(j) * W + i] = s;
    }
}

// Camera rotation whose optical axis (+z) looks along unit d, rolled by phi about it.
Eigen::Matrix3d axis_roll_rotation(const Eigen::Vector3d& d, double phi) {
  const Eigen::Vector3d ref = std::abs(d.z()) < 0.99 ? Eigen::Vector3d::UnitZ() : Eigen::Vector3d::UnitX();
  const Eigen::Vector3d e1 = ref.cross(d).normalized();
  const Eigen::Vector3d e2 = d.cross(e1);
  Eigen::Matrix3d R;
  R.col(0) = std::cos(phi) * e1 + std::sin(phi) * e2;
  R.col(1) = d.cross(R.col(0));
  R.col(2) = d;
  return R;
}

double angle_between(const Eigen::Matrix3d& A, const Eigen::Matrix3d& B) {
  return calib::so3_log(A.transpose() * B).norm();
}

}  // namespace

RelocalizationMap::RelocalizationMap(const float* log_intensity, int width, int height,
                                     const RotationRelocalizationOptions& options)
    : options_(options), width_(width), height_(height) {
  std::string why;
  if (!options_.Validate(&why)) throw std::invalid_argument("RotationRelocalizationOptions: " + why);
  if (width < 3 || height < 3 || !log_intensity) throw std::invalid_argument("RelocalizationMap: a map of at least 3 x 3 texels");
  const size_t n = static_cast<size_t>(width) * static_cast<size_t>(height);
  fine_.assign(n, 0.0f);
  known_.assign(n, 0);
  auto at = [&](int i, int j) { return log_intensity[static_cast<size_t>(j) * width + ((i % width) + width) % width]; };
  for (int j = 0; j < height; ++j)
    for (int i = 0; i < width; ++i) {
      const float c = at(i, j);
      if (std::isnan(c)) continue;
      known_[static_cast<size_t>(j) * width + i] = 1;
      const float l = at(i - 1, j), r = at(i + 1, j), u = at(i, std::max(j - 1, 0)), d = at(i, std::min(j + 1, height - 1));
      if (std::isnan(l) || std::isnan(r) || std::isnan(u) || std::isnan(d)) continue;
      const float gx = 0.5f * (r - l), gy = 0.5f * (d - u);
      fine_[static_cast<size_t>(j) * width + i] = std::sqrt(gx * gx + gy * gy);
    }
  coarse_ = fine_;
  blur(&fine_, width, height, options_.fine_blur_texels);
  blur(&coarse_, width, height, options_.coarse_blur_texels);
}

double RelocalizationMap::score_on(const std::vector<float>& map, const Eigen::Matrix3d& R_w_c,
                                   const std::vector<Eigen::Vector3f>& b) const {
  if (b.empty()) return 0.0;
  const Eigen::Matrix3f R = R_w_c.cast<float>();
  double s = 0;
  for (const Eigen::Vector3f& x : b) {
    const Eigen::Vector2f uv = calib::fast_equirectangular_project(R * x, width_, height_);
    const float u = uv.x() - 0.5f, v = std::clamp(uv.y() - 0.5f, 0.0f, static_cast<float>(height_ - 1));
    const float fu = std::floor(u), fv = std::floor(v);
    const int i0 = ((static_cast<int>(fu) % width_) + width_) % width_, i1 = (i0 + 1) % width_;
    const int j0 = static_cast<int>(fv), j1 = std::min(j0 + 1, height_ - 1);
    const float au = u - fu, av = v - fv;
    const float* r0 = map.data() + static_cast<size_t>(j0) * width_;
    const float* r1 = map.data() + static_cast<size_t>(j1) * width_;
    s += (1 - av) * ((1 - au) * r0[i0] + au * r0[i1]) + av * ((1 - au) * r1[i0] + au * r1[i1]);
  }
  return s / static_cast<double>(b.size());
}

double RelocalizationMap::score(const Eigen::Matrix3d& R_w_c, const std::vector<Eigen::Vector3f>& bearings) const {
  return score_on(fine_, R_w_c, bearings);
}

RotationRelocalizationResult RelocalizationMap::search(const std::vector<Eigen::Vector3f>& bearings) const {
  RotationRelocalizationResult res;
  if (bearings.empty()) return res;
  auto subsample = [&bearings](int count) {
    std::vector<Eigen::Vector3f> sub;
    const size_t m = std::min(bearings.size(), static_cast<size_t>(count));
    for (size_t k = 0; k < m; ++k) sub.push_back(bearings[k * bearings.size() / m]);
    return sub;
  };
  const std::vector<Eigen::Vector3f> sub = subsample(options_.coarse_bearings), fine = subsample(options_.fine_bearings);

  // Coarse: axis grid over the known mosaic x rolls.
  struct Candidate {
    double score;
    Eigen::Matrix3d R;
  };
  std::vector<Candidate> coarse;
  const double s = options_.axis_spacing_deg * kDeg;
  const int rolls = std::max(1, static_cast<int>(std::lround(360.0 / options_.roll_step_deg)));
  for (double polar = 0.5 * s; polar < M_PI; polar += s) {
    const int n_lon = std::max(1, static_cast<int>(std::lround(2 * M_PI * std::sin(polar) / s)));
    for (int k = 0; k < n_lon; ++k) {
      const double lon = -M_PI + (k + 0.5) * 2 * M_PI / n_lon;
      const Eigen::Vector3d d(std::sin(polar) * std::cos(lon), std::sin(polar) * std::sin(lon), std::cos(polar));
      const Eigen::Vector2f uv = calib::fast_equirectangular_project(d.cast<float>(), width_, height_);
      const int i = std::clamp(static_cast<int>(uv.x()), 0, width_ - 1), j = std::clamp(static_cast<int>(uv.y()), 0, height_ - 1);
      if (!known_[static_cast<size_t>(j) * width_ + i]) continue;
      for (int r = 0; r < rolls; ++r) {
        const Eigen::Matrix3d R = axis_roll_rotation(d, r * 2 * M_PI / rolls);
        coarse.push_back({score_on(coarse_, R, sub), R});
      }
    }
  }
  res.coarse_candidates = static_cast<int>(coarse.size());
  if (coarse.empty()) return res;
  std::sort(coarse.begin(), coarse.end(), [](const Candidate& a, const Candidate& b) { return a.score > b.score; });
  const double sep = std::max(options_.axis_spacing_deg, options_.roll_step_deg) * kDeg;
  std::vector<Candidate> picked;
  for (const Candidate& c : coarse) {
    if (static_cast<int>(picked.size()) >= options_.refine_candidates) break;
    bool far = true;
    for (const Candidate& p : picked) far = far && angle_between(p.R, c.R) > sep;
    if (far) picked.push_back(c);
  }

  // Refine: pattern search on R Exp(delta) with fine_bearings events on the fine map.
  for (Candidate& c : picked) {
    double best = score_on(fine_, c.R, fine);
    int evaluations = 0;
    for (double step = options_.refine_initial_step_deg * kDeg;
         step >= options_.refine_final_step_deg * kDeg * 0.999 && evaluations < 600;) {
      bool improved = false;
      for (int a = 0; a < 3 && !improved; ++a)
        for (int sg = -1; sg <= 1 && !improved; sg += 2) {
          Eigen::Vector3d delta = Eigen::Vector3d::Zero();
          delta[a] = sg * step;
          const Eigen::Matrix3d R = c.R * calib::so3_exp(delta);
          const double v = score_on(fine_, R, fine);
          ++evaluations;
          if (v > best) {
            best = v;
            c.R = R;
            improved = true;
          }
        }
      if (!improved) step *= 0.5;
    }
    c.score = best;
  }
  std::sort(picked.begin(), picked.end(), [](const Candidate& a, const Candidate& b) { return a.score > b.score; });
  res.valid = true;
  res.R_w_c = picked.front().R;
  res.score = picked.front().score;
  for (size_t k = 1; k < picked.size(); ++k)
    if (angle_between(picked[k].R, res.R_w_c) > 5 * kDeg) {
      res.runner_up_score = picked[k].score;
      break;
    }
  return res;
}

}  // namespace evio::mapping
