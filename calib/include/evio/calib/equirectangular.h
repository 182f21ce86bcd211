// Equirectangular (longitude-latitude) image geometry for panoramas and mosaics. Same convention
// as the simulator's PanoramaScene, so a mosaic and a rendered panorama compare texel for texel:
// a unit direction d = (dx, dy, dz) in the mosaic's frame has longitude atan2(dy, dx) in (-pi, pi]
// and latitude asin(dz) in [-pi/2, pi/2]; its continuous image coordinates are
//   u = (lon + pi) / (2 pi) * W,   v = (pi/2 - lat) / pi * H     (row 0 is up, +z),
// and pixel (i, j) covers [i, i+1) x [j, j+1) with its centre at (i + 0.5, j + 0.5). u wraps
// around (period W); v is clamped to [0, H).
#pragma once

#include <Eigen/Core>
#include <cmath>

namespace evio::calib {

class Equirectangular {
 public:
  Equirectangular(int width, int height) : width_(width), height_(height) {}
  int width() const { return width_; }
  int height() const { return height_; }
  // Texels per radian along u (longitude) and v (latitude).
  double pixels_per_rad_u() const { return width_ / (2.0 * kPi); }
  double pixels_per_rad_v() const { return height_ / kPi; }

  // Direction (need not be unit; must be non-zero) -> continuous (u, v), u in [0, W), v in [0, H].
  Eigen::Vector2d project(const Eigen::Vector3d& d) const {
    const double lon = std::atan2(d.y(), d.x());
    const double lat = std::atan2(d.z(), std::hypot(d.x(), d.y()));
    double u = (lon + kPi) * pixels_per_rad_u();
    if (u >= width_) u -= width_;
    if (u < 0) u += width_;
    return {u, (0.5 * kPi - lat) * pixels_per_rad_v()};
  }
  // Same, with the 2x3 Jacobian d(u, v)/d(d) at d. Near the poles (|cos lat| < 1e-9) the
  // longitude derivative is undefined; its row is set to zero there.
  Eigen::Vector2d project(const Eigen::Vector3d& d, Eigen::Matrix<double, 2, 3>* J) const {
    Eigen::Vector2d uv = project(d);
    const double rxy2 = d.x() * d.x() + d.y() * d.y();
    const double rxy = std::sqrt(rxy2);
    const double r2 = rxy2 + d.z() * d.z();
    if (rxy < 1e-9 * std::sqrt(r2)) {
      J->row(0).setZero();
    } else {
      // d lon / d d = (-dy, dx, 0) / rxy^2
      J->row(0) << -d.y() / rxy2, d.x() / rxy2, 0.0;
      J->row(0) *= pixels_per_rad_u();
    }
    // d lat / d d = (-dx dz / rxy, -dy dz / rxy, rxy) / r^2; v = (pi/2 - lat) * kv
    if (rxy < 1e-12) {
      J->row(1).setZero();
    } else {
      J->row(1) << d.x() * d.z() / (rxy * r2), d.y() * d.z() / (rxy * r2), -rxy / r2;
      J->row(1) *= pixels_per_rad_v();
    }
    return uv;
  }
  // Continuous (u, v) -> unit direction.
  Eigen::Vector3d unproject(double u, double v) const {
    const double lon = u / pixels_per_rad_u() - kPi;
    const double lat = 0.5 * kPi - v / pixels_per_rad_v();
    const double c = std::cos(lat);
    return {c * std::cos(lon), c * std::sin(lon), std::sin(lat)};
  }
  // Unit direction through the centre of pixel (i, j).
  Eigen::Vector3d pixel_direction(int i, int j) const { return unproject(i + 0.5, j + 0.5); }

 private:
  static constexpr double kPi = 3.14159265358979323846;
  int width_;
  int height_;
};

}  // namespace evio::calib
