// Pinhole camera with lens distortion, in Kalibr's conventions: radtan (Brown-Conrady as in
// OpenCV / Kalibr "radtan", k1 k2 p1 p2 [k3]) and equidistant (Kannala-Brandt as Kalibr
// "equidistant", k1..k4 on theta = angle from the optical axis). Pixel centres are at integer
// coordinates; (0, 0) is the centre of the top-left pixel.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace evio::calib {

enum class DistortionModel { kNone, kRadtan, kEquidistant };

// "none", "radtan", "equidistant".
const char* distortion_model_name(DistortionModel model);
// Accepts the names above plus Kalibr/ROS aliases: "plumb_bob" -> radtan, "fisheye"/"equi" ->
// equidistant. Case-sensitive, as in Kalibr files.
std::optional<DistortionModel> distortion_model_from_name(const std::string& name);

struct CameraIntrinsics {
  int width = 0;   // px
  int height = 0;  // px
  double fx = 0;   // focal lengths, px
  double fy = 0;
  double cx = 0;   // principal point, px
  double cy = 0;
  DistortionModel model = DistortionModel::kNone;
  // kNone: empty; kRadtan: k1 k2 p1 p2 or k1 k2 p1 p2 k3; kEquidistant: k1 k2 k3 k4.
  std::vector<double> distortion;

  // True when the resolution is positive, fx, fy > 0, all numbers finite and the number of
  // distortion coefficients matches the model; otherwise *why (if given) says what is wrong.
  bool Validate(std::string* why) const;
};

class PinholeCamera {
 public:
  PinholeCamera() = default;
  // Throws std::invalid_argument with the Validate() message if the intrinsics are invalid.
  explicit PinholeCamera(const CameraIntrinsics& intr);

  const CameraIntrinsics& intrinsics() const { return intr_; }
  int width() const { return intr_.width; }
  int height() const { return intr_.height; }

  // p_c: point in the camera frame (any unit). Writes the distorted pixel; returns false when the
  // point is not in front of the camera (z <= 1e-12 |p_c|). J_point = d(px)/d(p_c), 2x3.
  bool project(const Eigen::Vector3d& p_c, Eigen::Vector2d* px,
               Eigen::Matrix<double, 2, 3>* J_point = nullptr) const;
  // Jacobian of the pixel w.r.t. the intrinsics in the order [fx fy cx cy distortion...],
  // 2 x (4 + n). Returns false when project() would.
  bool project_jacobian_intrinsics(const Eigen::Vector3d& p_c, Eigen::MatrixXd* J) const;

  // Unit bearing vector of a distorted pixel. The distortion is inverted iteratively
  // (Gauss-Newton with the analytic Jacobian for radtan, Newton on theta for equidistant) until
  // the reprojection residual is below 1e-12 px or stops decreasing; returns false when it ends
  // above 1e-10 px or on a fold of the distortion (non-positive Jacobian determinant).
  // Equidistant pixels beyond 90 degrees from the axis give bearings with z <= 0.
  bool unproject(const Eigen::Vector2d& px, Eigen::Vector3d* bearing) const;

  // Normalised-plane distortion: xn = (x/z, y/z) -> distorted normalised coordinates, with the
  // 2x2 Jacobian d(xd)/d(xn).
  Eigen::Vector2d distort(const Eigen::Vector2d& xn, Eigen::Matrix2d* J = nullptr) const;
  // Inverse of distort(). Returns false when the iteration does not converge, or, for
  // equidistant, when the ray is 90 degrees or more from the axis (no normalised-plane point).
  bool undistort(const Eigen::Vector2d& xd, Eigen::Vector2d* xn) const;

  // True when border <= x <= width - 1 - border and likewise for y (px).
  bool in_image(const Eigen::Vector2d& px, double border = 0) const;

 private:
  // Equidistant: theta_d(theta) = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8)
  // and its derivative d(theta_d)/d(theta).
  double equidistant_theta_d(double theta, double* dtheta_d = nullptr) const;
  // Equidistant: theta in [0, pi) with theta_d(theta) = rd, by Newton; false if not found.
  bool equidistant_theta(double rd, double* theta) const;
  // Gauss-Newton inverse of the radtan distortion.
  bool radtan_undistort(const Eigen::Vector2d& xd, Eigen::Vector2d* xn) const;

  CameraIntrinsics intr_;
};

// Per-pixel undistortion lookup table for events: the unit bearing of every integer pixel
// (x, y), stored row-major as float to stay cache friendly.
class UndistortionLut {
 public:
  explicit UndistortionLut(const PinholeCamera& cam);

  // Unit bearing of pixel (x, y); NaN where valid() is false. Requires 0 <= x < width, 0 <= y < height.
  const Eigen::Vector3f& bearing(int x, int y) const { return bearings_[index(x, y)]; }
  // bearing.xy / bearing.z: undistorted normalised coordinates; NaN where the pixel is invalid
  // or its ray is not in front of the camera (bearing.z <= 0).
  Eigen::Vector2f normalized(int x, int y) const;
  // False where unproject() failed.
  bool valid(int x, int y) const { return valid_[index(x, y)] != 0; }
  int width() const { return width_; }
  int height() const { return height_; }

 private:
  size_t index(int x, int y) const;

  int width_ = 0;
  int height_ = 0;
  std::vector<Eigen::Vector3f> bearings_;
  std::vector<unsigned char> valid_;
};

}  // namespace evio::calib
