#include "evio/mapping/contrast_maximization.h"
#include "evio/mapping/option_tables.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

namespace evio::mapping {

bool RotationalCmaxOptions::Validate(std::string* why) const {
  if (!rotational_cmax_table().check(*this, why)) return false;
  if (min_step_radps > initial_step_radps) return validation_failed(why, "min_step_radps must be <= initial_step_radps");
  return true;
}

double rotational_iwe_variance(const std::vector<Eigen::Vector3f>& bearings, const std::vector<int64_t>& t_ns,
                               int64_t t_ref_ns, const Eigen::Vector3d& omega, const RotationalCmaxOptions& o,
                               double sigma_px, int* in_image) {
  if (bearings.size() != t_ns.size()) throw std::invalid_argument("rotational_iwe_variance: bearings and times differ in size");
  cv::Mat iwe(o.height, o.width, CV_32F, cv::Scalar(0));
  const float cx = 0.5f * static_cast<float>(o.width), cy = 0.5f * static_cast<float>(o.height);
  const float f = static_cast<float>(o.focal_px);
  const Eigen::Vector3f w = omega.cast<float>();
  int inside = 0;
  for (size_t k = 0; k < bearings.size(); ++k) {
    // Small differences of int64 times are exact in double, then float is enough.
    const float dt = static_cast<float>(static_cast<double>(t_ns[k] - t_ref_ns) * 1e-9);
    const Eigen::Vector3f& b = bearings[k];
    const Eigen::Vector3f wb = w.cross(b);
    const Eigen::Vector3f d = b + dt * wb + (0.5f * dt * dt) * w.cross(wb);
    if (!(d.z() > 1e-6f)) continue;
    const float x = f * d.x() / d.z() + cx - 0.5f, y = f * d.y() / d.z() + cy - 0.5f;  // pixel centres at +0.5
    const float fx = std::floor(x), fy = std::floor(y);
    const int ix = static_cast<int>(fx), iy = static_cast<int>(fy);
    if (ix < 0 || iy < 0 || ix + 1 >= o.width || iy + 1 >= o.height) continue;
    const float ax = x - fx, ay = y - fy;
    float* r0 = iwe.ptr<float>(iy);
    float* r1 = iwe.ptr<float>(iy + 1);
    r0[ix] += (1 - ax) * (1 - ay);
    r0[ix + 1] += ax * (1 - ay);
    r1[ix] += (1 - ax) * ay;
    r1[ix + 1] += ax * ay;
    ++inside;
  }
  if (in_image) *in_image = inside;
  cv::GaussianBlur(iwe, iwe, cv::Size(0, 0), sigma_px, sigma_px, cv::BORDER_CONSTANT);
  cv::Scalar mean, stddev;
  cv::meanStdDev(iwe, mean, stddev);
  return stddev[0] * stddev[0];
}

RotationalCmaxResult estimate_angular_velocity(const std::vector<Eigen::Vector3f>& bearings,
                                               const std::vector<int64_t>& t_ns, int64_t t_ref_ns,
                                               const Eigen::Vector3d& omega_init, const RotationalCmaxOptions& o) {
  std::string why;
  if (!o.Validate(&why)) throw std::invalid_argument("estimate_angular_velocity: " + why);
  if (bearings.size() != t_ns.size()) throw std::invalid_argument("estimate_angular_velocity: bearings and times differ in size");
  RotationalCmaxResult r;
  r.omega_c = omega_init;
  if (bearings.empty()) return r;
  int evals = 0;
  auto search = [&](double sigma, double step, Eigen::Vector3d* omega, int budget) {
    double best = rotational_iwe_variance(bearings, t_ns, t_ref_ns, *omega, o, sigma);
    ++evals;
    while (step >= o.min_step_radps && evals < budget) {
      bool improved = false;
      for (int axis = 0; axis < 3 && evals < budget; ++axis) {
        for (double sgn : {1.0, -1.0}) {
          Eigen::Vector3d c = *omega;
          c[axis] += sgn * step;
          const double v = rotational_iwe_variance(bearings, t_ns, t_ref_ns, c, o, sigma);
          ++evals;
          if (v > best) {
            best = v;
            *omega = c;
            improved = true;
            break;  // keep this axis' direction; next axis
          }
        }
      }
      if (!improved) step *= 0.5;
    }
    return best;
  };
  Eigen::Vector3d omega = omega_init;
  const double coarse_sigma = o.blur_sigma_px * o.coarse_blur_factor;
  if (o.coarse_blur_factor > 1) {
    search(coarse_sigma, o.initial_step_radps, &omega, o.max_evaluations / 2);
    r.contrast = search(o.blur_sigma_px, o.initial_step_radps / 4, &omega, o.max_evaluations);
  } else {
    r.contrast = search(o.blur_sigma_px, o.initial_step_radps, &omega, o.max_evaluations);
  }
  r.omega_c = omega;
  r.evaluations = evals;
  r.contrast_zero = rotational_iwe_variance(bearings, t_ns, t_ref_ns, Eigen::Vector3d::Zero(), o, o.blur_sigma_px);
  rotational_iwe_variance(bearings, t_ns, t_ref_ns, omega, o, o.blur_sigma_px, &r.events);
  return r;
}

}  // namespace evio::mapping
