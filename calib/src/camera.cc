// Pinhole camera with radtan / equidistant distortion (Kalibr conventions) and its per-pixel
// undistortion table. Distortion acts on normalised coordinates xn = (x/z, y/z); pixels are
// u = fx * xd_x + cx, v = fy * xd_y + cy (px).
#include "evio/calib/camera.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include <Eigen/LU>

namespace evio::calib {
namespace {

// Iterative undistortion stops once the reprojection residual is below kStopPx and reports
// success when it ends below kAcceptPx (both in pixels).
constexpr double kStopPx = 1e-12;
constexpr double kAcceptPx = 1e-10;
constexpr int kMaxIterations = 100;

bool all_finite(const std::vector<double>& v) {
  return std::all_of(v.begin(), v.end(), [](double d) { return std::isfinite(d); });
}

double coeff(const std::vector<double>& d, size_t i) { return i < d.size() ? d[i] : 0.0; }

}  // namespace

const char* distortion_model_name(DistortionModel model) {
  switch (model) {
    case DistortionModel::kNone: return "none";
    case DistortionModel::kRadtan: return "radtan";
    case DistortionModel::kEquidistant: return "equidistant";
  }
  return "unknown";
}

std::optional<DistortionModel> distortion_model_from_name(const std::string& name) {
  if (name == "none") return DistortionModel::kNone;
  if (name == "radtan" || name == "plumb_bob") return DistortionModel::kRadtan;
  if (name == "equidistant" || name == "fisheye" || name == "equi") return DistortionModel::kEquidistant;
  return std::nullopt;
}

bool CameraIntrinsics::Validate(std::string* why) const {
  std::ostringstream msg;
  const size_t n = distortion.size();
  if (width <= 0 || height <= 0) {
    msg << "resolution must be positive, got " << width << "x" << height;
  } else if (!std::isfinite(fx) || !std::isfinite(fy) || fx <= 0.0 || fy <= 0.0) {
    msg << "focal lengths must be finite and positive, got fx=" << fx << " fy=" << fy;
  } else if (!std::isfinite(cx) || !std::isfinite(cy)) {
    msg << "principal point must be finite, got cx=" << cx << " cy=" << cy;
  } else if (!all_finite(distortion)) {
    msg << "distortion coefficients must be finite";
  } else if (model == DistortionModel::kNone && n != 0) {
    msg << "distortion model none takes no coefficients, got " << n;
  } else if (model == DistortionModel::kRadtan && n != 4 && n != 5) {
    msg << "distortion model radtan takes 4 or 5 coefficients (k1 k2 p1 p2 [k3]), got " << n;
  } else if (model == DistortionModel::kEquidistant && n != 4) {
    msg << "distortion model equidistant takes 4 coefficients (k1 k2 k3 k4), got " << n;
  } else {
    return true;
  }
  if (why != nullptr) *why = msg.str();
  return false;
}

PinholeCamera::PinholeCamera(const CameraIntrinsics& intr) : intr_(intr) {
  std::string why;
  if (!intr_.Validate(&why)) throw std::invalid_argument("invalid camera intrinsics: " + why);
}

double PinholeCamera::equidistant_theta_d(double theta, double* dtheta_d) const {
  const std::vector<double>& k = intr_.distortion;
  const double t2 = theta * theta;
  // theta_d = theta * (1 + k1 t2 + k2 t2^2 + k3 t2^3 + k4 t2^4), Horner form.
  const double poly = 1.0 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3])));
  if (dtheta_d != nullptr) {
    *dtheta_d = 1.0 + t2 * (3.0 * k[0] + t2 * (5.0 * k[1] + t2 * (7.0 * k[2] + t2 * 9.0 * k[3])));
  }
  return theta * poly;
}

bool PinholeCamera::equidistant_theta(double rd, double* theta) const {
  const double scale = std::max(intr_.fx, intr_.fy);  // px per radian of theta_d, roughly
  double t = std::min(rd, M_PI - 1e-6);
  double best_t = t;
  double best_res = std::numeric_limits<double>::infinity();
  for (int it = 0; it < kMaxIterations; ++it) {
    double d = 0.0;
    const double res = equidistant_theta_d(t, &d) - rd;
    if (std::abs(res) < best_res) {
      best_res = std::abs(res);
      best_t = t;
    }
    if (std::abs(res) * scale < kStopPx) break;
    if (!(d > 0.0)) return false;  // outside the monotone part of theta_d(theta)
    double next = t - res / d;
    // Keep the iterate in [0, pi): halve the distance to the violated bound instead of leaving it.
    if (next < 0.0) next = 0.5 * t;
    if (next >= M_PI) next = 0.5 * (t + M_PI);
    if (next == t) break;
    t = next;
  }
  double d = 0.0;
  equidistant_theta_d(best_t, &d);
  if (best_res * scale > kAcceptPx || !(d > 0.0)) return false;
  *theta = best_t;
  return true;
}

Eigen::Vector2d PinholeCamera::distort(const Eigen::Vector2d& xn, Eigen::Matrix2d* J) const {
  const std::vector<double>& k = intr_.distortion;
  switch (intr_.model) {
    case DistortionModel::kNone:
      if (J != nullptr) J->setIdentity();
      return xn;

    case DistortionModel::kRadtan: {
      const double k1 = k[0], k2 = k[1], p1 = k[2], p2 = k[3], k3 = coeff(k, 4);
      const double x = xn.x(), y = xn.y();
      const double xx = x * x, yy = y * y, xy = x * y, r2 = xx + yy;
      const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
      const Eigen::Vector2d xd(x * radial + 2.0 * p1 * xy + p2 * (r2 + 2.0 * xx),
                               y * radial + p1 * (r2 + 2.0 * yy) + 2.0 * p2 * xy);
      if (J != nullptr) {
        const double dradial = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2);  // d(radial)/d(r2)
        const double off = 2.0 * xy * dradial + 2.0 * p1 * x + 2.0 * p2 * y;
        (*J)(0, 0) = radial + 2.0 * xx * dradial + 2.0 * p1 * y + 6.0 * p2 * x;
        (*J)(0, 1) = off;
        (*J)(1, 0) = off;
        (*J)(1, 1) = radial + 2.0 * yy * dradial + 6.0 * p1 * y + 2.0 * p2 * x;
      }
      return xd;
    }

    case DistortionModel::kEquidistant: {
      const double r = xn.norm();
      if (r == 0.0) {
        if (J != nullptr) J->setIdentity();
        return xn;
      }
      const double theta = std::atan(r);
      double dtheta_d = 0.0;
      const double theta_d = equidistant_theta_d(theta, &dtheta_d);
      const double s = theta_d / r;
      if (J != nullptr) {
        // xd = theta_d(r) u with u = xn / r: radial derivative along u, scale s across it.
        const Eigen::Vector2d u = xn / r;
        const double radial_slope = dtheta_d / (1.0 + r * r);
        *J = radial_slope * (u * u.transpose()) + s * (Eigen::Matrix2d::Identity() - u * u.transpose());
      }
      return s * xn;
    }
  }
  return xn;
}

bool PinholeCamera::radtan_undistort(const Eigen::Vector2d& xd, Eigen::Vector2d* xn) const {
  const Eigen::Vector2d f(intr_.fx, intr_.fy);
  auto residual_px = [&](const Eigen::Vector2d& r) { return r.cwiseProduct(f).norm(); };

  Eigen::Vector2d x = xd;
  Eigen::Matrix2d J;
  Eigen::Vector2d r = distort(x, &J) - xd;
  double res = residual_px(r);
  for (int it = 0; it < kMaxIterations && res >= kStopPx; ++it) {
    const double det = J.determinant();
    if (!(std::abs(det) > 1e-12)) return false;
    const Eigen::Vector2d step = J.inverse() * r;
    // Gauss-Newton step with backtracking: halve it until the residual decreases.
    double alpha = 1.0;
    bool improved = false;
    for (int ls = 0; ls < 30; ++ls) {
      const Eigen::Vector2d cand = x - alpha * step;
      Eigen::Matrix2d Jc;
      const Eigen::Vector2d rc = distort(cand, &Jc) - xd;
      const double res_c = residual_px(rc);
      if (res_c < res) {
        x = cand;
        r = rc;
        J = Jc;
        res = res_c;
        improved = true;
        break;
      }
      alpha *= 0.5;
    }
    if (!improved) break;  // at the rounding floor
  }
  // Accept only converged solutions on the locally orientation-preserving branch.
  if (!(res <= kAcceptPx) || !(J.determinant() > 0.0)) return false;
  *xn = x;
  return true;
}

bool PinholeCamera::undistort(const Eigen::Vector2d& xd, Eigen::Vector2d* xn) const {
  switch (intr_.model) {
    case DistortionModel::kNone:
      *xn = xd;
      return true;
    case DistortionModel::kRadtan:
      return radtan_undistort(xd, xn);
    case DistortionModel::kEquidistant: {
      const double rd = xd.norm();
      if (rd == 0.0) {
        *xn = xd;
        return true;
      }
      double theta = 0.0;
      if (!equidistant_theta(rd, &theta) || theta >= 0.5 * M_PI) return false;
      *xn = (std::tan(theta) / rd) * xd;
      return true;
    }
  }
  return false;
}

bool PinholeCamera::project(const Eigen::Vector3d& p_c, Eigen::Vector2d* px,
                            Eigen::Matrix<double, 2, 3>* J_point) const {
  const double z = p_c.z();
  if (!(z > 1e-12 * p_c.norm())) return false;
  const double inv_z = 1.0 / z;
  const Eigen::Vector2d xn(p_c.x() * inv_z, p_c.y() * inv_z);
  Eigen::Matrix2d Jd;
  const Eigen::Vector2d xd = distort(xn, J_point != nullptr ? &Jd : nullptr);
  *px = Eigen::Vector2d(intr_.fx * xd.x() + intr_.cx, intr_.fy * xd.y() + intr_.cy);
  if (J_point != nullptr) {
    Eigen::Matrix<double, 2, 3> Jn;  // d(xn)/d(p_c)
    Jn << inv_z, 0.0, -xn.x() * inv_z,
          0.0, inv_z, -xn.y() * inv_z;
    *J_point = Eigen::Vector2d(intr_.fx, intr_.fy).asDiagonal() * (Jd * Jn);
  }
  return true;
}

bool PinholeCamera::project_jacobian_intrinsics(const Eigen::Vector3d& p_c, Eigen::MatrixXd* J) const {
  const double z = p_c.z();
  if (!(z > 1e-12 * p_c.norm())) return false;
  const Eigen::Vector2d xn(p_c.x() / z, p_c.y() / z);
  const Eigen::Vector2d xd = distort(xn);
  const std::vector<double>& k = intr_.distortion;
  const int n = static_cast<int>(k.size());
  J->setZero(2, 4 + n);
  (*J)(0, 0) = xd.x();
  (*J)(1, 1) = xd.y();
  (*J)(0, 2) = 1.0;
  (*J)(1, 3) = 1.0;

  const double x = xn.x(), y = xn.y();
  Eigen::Matrix2Xd Jk(2, n);  // d(xd)/d(distortion)
  switch (intr_.model) {
    case DistortionModel::kNone:
      break;
    case DistortionModel::kRadtan: {
      const double r2 = x * x + y * y;
      Jk.col(0) << x * r2, y * r2;
      Jk.col(1) << x * r2 * r2, y * r2 * r2;
      Jk.col(2) << 2.0 * x * y, r2 + 2.0 * y * y;
      Jk.col(3) << r2 + 2.0 * x * x, 2.0 * x * y;
      if (n == 5) Jk.col(4) << x * r2 * r2 * r2, y * r2 * r2 * r2;
      break;
    }
    case DistortionModel::kEquidistant: {
      // xd = theta_d / r * xn; d(theta_d)/d(k_i) = theta^(2i+1), so d(xd)/d(k_i) = theta^(2i) (theta/r) xn.
      const double r = xn.norm();
      const double theta = std::atan(r);
      const double theta_over_r = r > 0.0 ? theta / r : 1.0;
      const double t2 = theta * theta;
      double t_pow = t2;
      for (int i = 0; i < n; ++i) {
        Jk.col(i) = (t_pow * theta_over_r) * xn;
        t_pow *= t2;
      }
      break;
    }
  }
  if (n > 0) J->rightCols(n) = Eigen::Vector2d(intr_.fx, intr_.fy).asDiagonal() * Jk;
  return true;
}

bool PinholeCamera::unproject(const Eigen::Vector2d& px, Eigen::Vector3d* bearing) const {
  const Eigen::Vector2d xd((px.x() - intr_.cx) / intr_.fx, (px.y() - intr_.cy) / intr_.fy);
  if (intr_.model == DistortionModel::kEquidistant) {
    // Work on the angle directly so that rays at or beyond 90 degrees are representable.
    const double rd = xd.norm();
    if (rd == 0.0) {
      *bearing = Eigen::Vector3d::UnitZ();
      return true;
    }
    double theta = 0.0;
    if (!equidistant_theta(rd, &theta)) return false;
    const double s = std::sin(theta) / rd;
    *bearing = Eigen::Vector3d(s * xd.x(), s * xd.y(), std::cos(theta));
    return true;
  }
  Eigen::Vector2d xn;
  if (!undistort(xd, &xn)) return false;
  *bearing = Eigen::Vector3d(xn.x(), xn.y(), 1.0).normalized();
  return true;
}

bool PinholeCamera::in_image(const Eigen::Vector2d& px, double border) const {
  return px.x() >= border && px.y() >= border && px.x() <= intr_.width - 1 - border &&
         px.y() <= intr_.height - 1 - border;
}

UndistortionLut::UndistortionLut(const PinholeCamera& cam) : width_(cam.width()), height_(cam.height()) {
  const size_t n = static_cast<size_t>(std::max(width_, 0)) * static_cast<size_t>(std::max(height_, 0));
  const float nan = std::numeric_limits<float>::quiet_NaN();
  bearings_.assign(n, Eigen::Vector3f(nan, nan, nan));
  valid_.assign(n, 0);
  for (int y = 0; y < height_; ++y) {
    for (int x = 0; x < width_; ++x) {
      Eigen::Vector3d b;
      if (!cam.unproject(Eigen::Vector2d(x, y), &b)) continue;
      bearings_[index(x, y)] = b.cast<float>();
      valid_[index(x, y)] = 1;
    }
  }
}

Eigen::Vector2f UndistortionLut::normalized(int x, int y) const {
  const Eigen::Vector3f& b = bearings_[index(x, y)];
  if (!(b.z() > 0.0f)) {
    const float nan = std::numeric_limits<float>::quiet_NaN();
    return Eigen::Vector2f(nan, nan);
  }
  return b.head<2>() / b.z();
}

size_t UndistortionLut::index(int x, int y) const {
  assert(x >= 0 && x < width_ && y >= 0 && y < height_ && "UndistortionLut pixel out of range");
  return static_cast<size_t>(y) * static_cast<size_t>(width_) + static_cast<size_t>(x);
}

}  // namespace evio::calib
