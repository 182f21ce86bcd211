// Scenes for the event simulator and the per-pixel renderer: each camera pixel casts its ray
// (bearing from the calib camera model, distortion included) into (a) an equirectangular panorama
// at infinity (rotation-only), (b) a set of textured rectangles in 3D (6-DoF, with depth), or
// (c) 2D sprites with their own affine motion composited over a background scene, with labels.
// Renders give linear intensity, z-depth, analytic optical flow and object labels.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "evio/calib/camera.h"
#include "evio/calib/geometry.h"
#include "evio/simulator/texture.h"

namespace evio::simulator {

// Camera pose and velocity at one instant. v_c and omega_c are the camera's linear and angular
// velocity expressed in the camera frame (R_w_c' = R_w_c hat(omega_c), p_w' = R_w_c v_c).
struct CameraState {
  int64_t t_ns = 0;
  calib::SE3 T_w_c;
  Eigen::Vector3d v_c = Eigen::Vector3d::Zero();      // m/s
  Eigen::Vector3d omega_c = Eigen::Vector3d::Zero();  // rad/s
};

// Per-pixel rays of a camera: unit bearings in the camera frame for the pixel centre (integer
// pixel coordinates, as in calib) and for supersample x supersample sub-pixel positions, plus the
// pixel's angular footprint (for mip level selection).
class PixelRays {
 public:
  // Throws std::invalid_argument when supersample < 1 or a pixel centre does not unproject.
  explicit PixelRays(const calib::PinholeCamera& camera, int supersample = 1);
  const calib::PinholeCamera& camera() const { return camera_; }
  int width() const { return camera_.width(); }
  int height() const { return camera_.height(); }
  int supersample() const { return supersample_; }
  int samples_per_pixel() const { return supersample_ * supersample_; }
  const Eigen::Vector3d& centre(int x, int y) const { return centre_[index(x, y)]; }
  // k in [0, samples_per_pixel()).
  const Eigen::Vector3d& sub_ray(int x, int y, int k) const { return sub_[index(x, y) * samples_per_pixel() + k]; }
  // Angle subtended by one sub-sample spacing at this pixel, rad: the square root of the solid
  // angle of a (1/supersample px)^2 cell at the pixel centre, from the projection Jacobian (an
  // isotropic size; distortion and off-axis foreshortening included).
  double sample_angle_rad(int x, int y) const { return angle_[index(x, y)]; }
  size_t index(int x, int y) const { return static_cast<size_t>(y) * camera_.width() + x; }
  // Offset of sub-sample k = ky * supersample + kx from the pixel centre, px:
  // ((kx + 0.5) / supersample - 0.5, (ky + 0.5) / supersample - 0.5).
  Eigen::Vector2d sub_offset(int k) const;
  // The sub-sample at the pixel centre (odd supersample), else -1.
  int centre_sample() const { return supersample_ % 2 == 1 ? (supersample_ / 2) * (supersample_ + 1) : -1; }

  // Flat float copies for the renderers' inner loops: sub-rays at index(x, y) *
  // samples_per_pixel() + k, centres and angles at index(x, y).
  const Eigen::Vector3f* sub_rays_f() const { return sub_f_.data(); }
  // The sub-rays' x, y, z components as separate arrays (same indexing), each padded with 4
  // trailing (0, 0, 1) rays so loops may read groups of 4 past the last sample.
  const float* sub_rays_x() const { return sub_x_.data(); }
  const float* sub_rays_y() const { return sub_y_.data(); }
  const float* sub_rays_z() const { return sub_z_.data(); }
  // log2(sample_angle_rad), per pixel.
  const float* log2_sample_angles_f() const { return log2_angle_f_.data(); }
  const Eigen::Vector3f* centres_f() const { return centre_f_.data(); }
  const float* sample_angles_f() const { return angle_f_.data(); }
  // d(pixel)/d(p_c) of PinholeCamera::project at p_c = the centre bearing (so at range r the
  // Jacobian is this / r); NaN where the centre bearing does not project.
  const Eigen::Matrix<float, 2, 3>* centre_jacobians_f() const { return jac_f_.data(); }

 private:
  calib::PinholeCamera camera_;
  int supersample_ = 1;
  std::vector<Eigen::Vector3d> centre_, sub_;
  std::vector<double> angle_;
  std::vector<Eigen::Vector3f> centre_f_, sub_f_;
  std::vector<float> angle_f_, log2_angle_f_, sub_x_, sub_y_, sub_z_;
  std::vector<Eigen::Matrix<float, 2, 3>> jac_f_;
};

struct RenderedView {
  int64_t t_ns = 0;
  cv::Mat intensity;  // CV_32F linear intensity (mean over the sub-pixel samples)
  cv::Mat depth;      // CV_32F z-depth in the camera frame of the centre ray, m; +inf when nothing is hit
  cv::Mat flow;       // CV_32FC2 image-plane velocity of the centre ray's scene point, px/s (only when asked)
  cv::Mat label;      // CV_16U object id of the centre ray (0 = background / static scene)
};

struct RenderRequest {
  bool flow = false;  // compute the flow image (a little slower)
  // Rows [row_begin, row_end) only (row_end < 0: to the last row). A partial band writes into
  // images the caller has already allocated at full size (with flow when asked), so several
  // threads can render disjoint bands of one view; every pixel depends only on its own ray,
  // so a banded render is bit-identical to a whole one.
  int row_begin = 0;
  int row_end = -1;
};

class Scene {
 public:
  virtual ~Scene() = default;
  // Fills *out (allocating the images) for the camera state; thread-compatible (const).
  virtual void render(const CameraState& camera, const PixelRays& rays, const RenderRequest& request,
                      RenderedView* out) const = 0;
  virtual std::string describe() const = 0;
  // True when nothing in the scene moves by itself (the image changes only with the camera).
  virtual bool is_static() const { return true; }
};

// (a) Equirectangular panorama at infinity in the world frame. A world direction d = (dx, dy, dz)
// has longitude atan2(dy, dx) in (-pi, pi] and latitude asin(dz) in [-pi/2, pi/2]; texel
// coordinates u = (lon + pi) / (2 pi) * W, v = (pi/2 - lat) / pi * H (row 0 is up, +z).
// Depth is +inf, flow from rotation only, label 0. Mip footprint of a sample of angle a: a * H / pi
// texels vertically and a * W / (2 pi cos(lat)) horizontally; the isotropic footprint used is
// their geometric mean (same area; cos(lat) floored at 1e-3 near the poles).
class PanoramaScene final : public Scene {
 public:
  // The texture should be about 2:1; u wraps (repeat), v clamps.
  explicit PanoramaScene(std::shared_ptr<const Texture> texture, double gain = 1.0);
  void render(const CameraState& camera, const PixelRays& rays, const RenderRequest& request,
              RenderedView* out) const override;
  std::string describe() const override;
  const Texture& texture() const { return *texture_; }

 private:
  std::shared_ptr<const Texture> texture_;
  double gain_;
};

// A textured rectangle in the world: points center + a * axis_u + b * axis_v with
// |a| <= width/2, |b| <= height/2; the texture is stretched over it (texel u grows with a,
// v grows with -b, so the texture's top row is at +axis_v). Visible from both sides.
struct TexturedPlane {
  Eigen::Vector3d center_w = Eigen::Vector3d::Zero();
  Eigen::Vector3d axis_u_w = Eigen::Vector3d::UnitX();  // unit, orthogonal to axis_v_w
  Eigen::Vector3d axis_v_w = Eigen::Vector3d::UnitY();
  double width_m = 1.0;
  double height_m = 1.0;
  std::shared_ptr<const Texture> texture;
  double gain = 1.0;  // intensity multiplier (HDR scenes: planes of very different brightness)
};

// (b) Nearest-hit ray casting against the planes; label = plane index + 1, 0 and
// background_intensity where no plane is hit (depth +inf, flow from rotation only). Mip
// footprint of a sample of angle a hitting at range t with incidence cosine c: t a texels-per-metre
// across, stretched by 1 / c along the tilt; the isotropic footprint is the geometric mean
// t a sqrt(texels_per_m_u texels_per_m_v / c) (same area; c floored at 1e-3).
class PlanarScene final : public Scene {
 public:
  // Throws std::invalid_argument for non-orthonormal axes, non-positive sizes or a missing texture.
  PlanarScene(std::vector<TexturedPlane> planes, double background_intensity = 0.1);
  void render(const CameraState& camera, const PixelRays& rays, const RenderRequest& request,
              RenderedView* out) const override;
  std::string describe() const override;
  const std::vector<TexturedPlane>& planes() const { return planes_; }
  // Nearest hit of the ray origin_w + s dir_w (s > 0, dir_w need not be unit) with a plane's
  // rectangle, in double precision: the ray parameter s of the hit (the point is origin_w + s
  // dir_w), nullopt when no plane is hit. Ground truth for feature-track evaluation.
  std::optional<double> intersect(const Eigen::Vector3d& origin_w, const Eigen::Vector3d& dir_w) const;

 private:
  std::vector<TexturedPlane> planes_;
  double background_;
};

// Image-space motion of a sprite, t in seconds since the scene's t0:
// centre(t) = centre + velocity t + amplitude .* sin(2 pi f t + phase) (px),
// angle(t) = angle + angular_rate t (rad, counter-clockwise in the image: x right, y down, so a
// positive rate turns +x towards +y), scale(t) = scale * exp(scale_rate t).
struct SpriteMotion {
  Eigen::Vector2d centre_px = Eigen::Vector2d::Zero();
  Eigen::Vector2d velocity_pxps = Eigen::Vector2d::Zero();
  Eigen::Vector2d amplitude_px = Eigen::Vector2d::Zero();
  Eigen::Vector2d frequency_hz = Eigen::Vector2d::Zero();
  Eigen::Vector2d phase_rad = Eigen::Vector2d::Zero();
  double angle_rad = 0;
  double angular_rate_radps = 0;
  double scale = 1.0;
  double scale_rate_per_s = 0;
};

enum class SpriteShape { kRectangle, kEllipse };

// A textured object: at scale 1 it covers width_px x height_px image pixels with the whole
// texture, clipped to its shape (antialiased edge by supersampling).
struct Sprite {
  std::shared_ptr<const Texture> texture;
  SpriteShape shape = SpriteShape::kRectangle;
  double width_px = 40;
  double height_px = 40;
  double gain = 1.0;
  SpriteMotion motion;
};

// (c) Sprites drawn in order (later on top) over a background scene rendered for the camera.
// Label = sprite index + 1 where a sprite covers the centre ray, else 0. Sprite depth is the
// background's depth (sprites have no 3D position); sprite flow is the derivative of its motion.
class SpriteScene final : public Scene {
 public:
  SpriteScene(std::shared_ptr<const Scene> background, std::vector<Sprite> sprites, int64_t t0_ns = 0);
  void render(const CameraState& camera, const PixelRays& rays, const RenderRequest& request,
              RenderedView* out) const override;
  std::string describe() const override;
  bool is_static() const override { return sprites_.empty() && background_->is_static(); }

 private:
  std::shared_ptr<const Scene> background_;
  std::vector<Sprite> sprites_;
  int64_t t0_ns_;
};

// Flow of a static scene point seen along `bearing` at z-depth `depth` (+inf: at infinity), for
// the camera velocity; px/s. Shared by the scenes; exposed for tests.
Eigen::Vector2d static_point_flow(const calib::PinholeCamera& camera, const Eigen::Vector3d& bearing, double depth,
                                  const CameraState& state);

}  // namespace evio::simulator
