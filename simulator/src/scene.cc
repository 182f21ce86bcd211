// Per-pixel renderer of the simulator's scenes (panorama at infinity, textured planes, image-space
// sprites) with mip-mapped texture sampling, z-depth, labels and analytic optical flow. See
// scene.h for the model. The inner loops work in float on precomputed per-pixel data
// (PixelRays) and make no allocations or virtual calls per pixel.
#include "evio/simulator/scene.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <utility>

namespace evio::simulator {
namespace {

constexpr float kPiF = 3.14159265358979323846f;
constexpr float kInfF = std::numeric_limits<float>::infinity();
constexpr float kNanF = std::numeric_limits<float>::quiet_NaN();
// Lower bound of the cosine that stretches a footprint (latitude on the panorama, incidence on a
// plane), so grazing rays and the poles get a large but finite footprint.
constexpr float kMinStretchCos = 1e-3f;
// Nearest ray parameter accepted as a plane hit, m.
constexpr float kNearHitM = 1e-6f;

// Four-lane float arithmetic through the GCC/Clang vector extension (SSE2 on x86-64, NEON on
// arm64): the per-sample ray math runs in groups of 4 samples, texture fetches stay scalar.
typedef float v4f __attribute__((vector_size(16)));
typedef int32_t v4i __attribute__((vector_size(16)));

inline v4f load4(const float* p) {
  v4f r;
  std::memcpy(&r, p, sizeof r);
  return r;
}
inline void store4(float* p, v4f v) { std::memcpy(p, &v, sizeof v); }
inline void store4(int32_t* p, v4i v) { std::memcpy(p, &v, sizeof v); }
inline v4f splat(float a) { return v4f{a, a, a, a}; }
inline v4f vabs(v4f x) { return reinterpret_cast<v4f>(reinterpret_cast<v4i>(x) & 0x7fffffff); }
inline v4f vmin(v4f a, v4f b) { return a < b ? a : b; }
inline v4f vmax(v4f a, v4f b) { return a > b ? a : b; }
inline v4f vsqrt(v4f x) { return v4f{std::sqrt(x[0]), std::sqrt(x[1]), std::sqrt(x[2]), std::sqrt(x[3])}; }

// Lane-wise atan2 with std::atan2's range (-pi, pi] (atan2(0, 0) = 0). z = min/max(|x|, |y|) in
// [0, 1]; above tan(pi/8) reduced by atan(z) = pi/4 + atan((z - 1) / (z + 1)); then the Taylor
// series to z^15 (alternating, |error| < z^17 / 17 < 2e-8 for |z| <= tan(pi/8)), so the result
// is accurate to float rounding (~1e-7 rad). Branches become selects.
inline v4f atan2_4(v4f y, v4f x) {
  const v4f ax = vabs(x), ay = vabs(y);
  const v4f hi = vmax(ax, ay), lo = vmin(ax, ay);
  v4f z = lo / vmax(hi, splat(1e-30f));  // atan2(0, 0) = 0
  const v4i big = z > 0.41421356f;
  z = big ? (z - 1.0f) / (z + 1.0f) : z;
  const v4f offset = big ? splat(0.25f * kPiF) : splat(0.0f);
  const v4f z2 = z * z;
  v4f p = splat(-1.0f / 15);
  p = p * z2 + 1.0f / 13;
  p = p * z2 - 1.0f / 11;
  p = p * z2 + 1.0f / 9;
  p = p * z2 - 1.0f / 7;
  p = p * z2 + 1.0f / 5;
  p = p * z2 - 1.0f / 3;
  p = p * z2 + 1.0f;
  v4f a = offset + z * p;
  a = ay > ax ? 0.5f * kPiF - a : a;
  a = x < 0.0f ? kPiF - a : a;
  return y < 0.0f ? -a : a;
}

// log2(x) for normal x > 0, lane-wise: exponent plus 2 atanh(s) / ln 2 with s = (m - 1) / (m + 1),
// m in [1, 2), series to s^7 (|error| < 2e-5, continuous across powers of two to that accuracy).
// Used for the mip level of detail, where 1e-3 would do.
inline v4f log2_4(v4f x) {
  const v4i bits = reinterpret_cast<v4i>(x);
  const v4i e = ((bits >> 23) & 0xff) - 127;
  const v4f m = reinterpret_cast<v4f>((bits & 0x007fffff) | 0x3f800000);
  const v4f s = (m - 1.0f) / (m + 1.0f);
  const v4f s2 = s * s;
  const v4f series = s * (1.0f + s2 * (1.0f / 3 + s2 * (1.0f / 5 + s2 * (1.0f / 7))));
  return __builtin_convertvector(e, v4f) + 2.8853900817779268f * series;
}

// Image-plane velocity of the scene point at range 1 / inv_range along the unit centre bearing b:
// J(b) (-omega x b - v inv_range), with J(b) the projection Jacobian at b (J(r b) = J(b) / r).
inline void write_flow(float* f, const Eigen::Matrix<float, 2, 3>& J, const Eigen::Vector3f& b,
                       const Eigen::Vector3f& omega, const Eigen::Vector3f& v, float inv_range) {
  const Eigen::Vector3f d = -omega.cross(b) - v * inv_range;
  f[0] = J.row(0).dot(d);
  f[1] = J.row(1).dot(d);
}

// The rows a request covers, clamped to the image.
std::pair<int, int> row_band(const RenderRequest& request, int h) {
  const int y0 = std::clamp(request.row_begin, 0, h);
  const int y1 = request.row_end < 0 ? h : std::clamp(request.row_end, y0, h);
  return {y0, y1};
}

void prepare_view(const CameraState& camera, const PixelRays& rays, const RenderRequest& request, RenderedView* out) {
  if (out == nullptr) throw std::invalid_argument("render: null output view");
  const int w = rays.width(), h = rays.height();
  const auto [y0, y1] = row_band(request, h);
  if (y0 != 0 || y1 != h) {
    // A band of a view allocated by the caller: check, never reallocate (other bands may be
    // rendering into the same images).
    const auto ok = [&](const cv::Mat& m, int type) { return m.rows == h && m.cols == w && m.type() == type; };
    if (!ok(out->intensity, CV_32F) || !ok(out->depth, CV_32F) || !ok(out->label, CV_16U) ||
        (request.flow && !ok(out->flow, CV_32FC2))) {
      throw std::invalid_argument("render: a row band needs the view's images allocated at full size");
    }
    return;
  }
  out->t_ns = camera.t_ns;
  out->intensity.create(h, w, CV_32F);
  out->depth.create(h, w, CV_32F);
  out->label.create(h, w, CV_16U);
  if (request.flow) {
    out->flow.create(h, w, CV_32FC2);
  } else {
    out->flow.release();
  }
}

std::string texture_size(const Texture& t) { return std::to_string(t.width()) + "x" + std::to_string(t.height()); }

}  // namespace

// ---------------------------------------------------------------------------------------------
// PixelRays

PixelRays::PixelRays(const calib::PinholeCamera& camera, int supersample) : camera_(camera), supersample_(supersample) {
  if (supersample < 1) throw std::invalid_argument("pixel rays: supersample must be >= 1, got " + std::to_string(supersample));
  const int w = camera.width(), h = camera.height();
  if (w <= 0 || h <= 0) throw std::invalid_argument("pixel rays: the camera has no pixels");
  const int spp = samples_per_pixel();
  const size_t n = static_cast<size_t>(w) * h;
  centre_.resize(n);
  sub_.resize(n * spp);
  angle_.resize(n);
  jac_f_.resize(n);
  std::vector<Eigen::Vector2d> offsets(spp);
  for (int k = 0; k < spp; ++k) offsets[k] = sub_offset(k);
  const int kc = centre_sample();
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const size_t i = index(x, y);
      const Eigen::Vector2d px(x, y);
      Eigen::Vector3d b;
      if (!camera.unproject(px, &b))
        throw std::invalid_argument("pixel rays: pixel (" + std::to_string(x) + ", " + std::to_string(y) +
                                    ") does not unproject (distortion not invertible there)");
      centre_[i] = b;
      for (int k = 0; k < spp; ++k) {
        Eigen::Vector3d bs = b;
        // A sub-sample that does not unproject (beyond the distortion's valid region) takes the centre ray.
        if (k != kc && !camera.unproject(px + offsets[k], &bs)) bs = b;
        sub_[i * spp + k] = bs;
      }
      // Solid angle per px^2 at the pixel: with (t1, t2) an orthonormal basis of the tangent plane
      // of the bearing, A = J [t1 t2] maps angles to pixels; one px^2 covers 1 / |det A| sr.
      Eigen::Vector2d p;
      Eigen::Matrix<double, 2, 3> J;
      double angle = std::numeric_limits<double>::quiet_NaN();
      if (camera.project(b, &p, &J)) {
        jac_f_[i] = J.cast<float>();
        const Eigen::Vector3d helper = std::abs(b.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
        const Eigen::Vector3d t1 = b.cross(helper).normalized();
        const Eigen::Vector3d t2 = b.cross(t1);
        Eigen::Matrix2d A;
        A.col(0) = J * t1;
        A.col(1) = J * t2;
        const double det = std::abs(A.determinant());
        if (det > 0) angle = 1.0 / (std::sqrt(det) * supersample);
      } else {
        jac_f_[i].setConstant(kNanF);
      }
      if (!std::isfinite(angle)) {
        // Behind the camera (wide-angle equidistant) or degenerate: angle between neighbour rays.
        Eigen::Vector3d b1;
        const Eigen::Vector2d step(x + 1 < w ? 1.0 : -1.0, 0.0);
        angle = camera.unproject(px + step, &b1) ? std::atan2(b.cross(b1).norm(), b.dot(b1)) / supersample
                                                 : 1.0 / (camera.intrinsics().fx * supersample);
      }
      angle_[i] = angle;
    }
  }
  centre_f_.resize(n);
  sub_f_.resize(n * spp);
  angle_f_.resize(n);
  for (size_t i = 0; i < n; ++i) {
    centre_f_[i] = centre_[i].cast<float>();
    angle_f_[i] = static_cast<float>(angle_[i]);
  }
  for (size_t i = 0; i < sub_.size(); ++i) sub_f_[i] = sub_[i].cast<float>();
  log2_angle_f_.resize(n);
  for (size_t i = 0; i < n; ++i) log2_angle_f_[i] = static_cast<float>(std::log2(angle_[i]));
  sub_x_.assign(sub_.size() + 4, 0.0f);
  sub_y_.assign(sub_.size() + 4, 0.0f);
  sub_z_.assign(sub_.size() + 4, 1.0f);
  for (size_t i = 0; i < sub_.size(); ++i) {
    sub_x_[i] = sub_f_[i].x();
    sub_y_[i] = sub_f_[i].y();
    sub_z_[i] = sub_f_[i].z();
  }
}

Eigen::Vector2d PixelRays::sub_offset(int k) const {
  const int s = supersample_;
  return Eigen::Vector2d((k % s + 0.5) / s - 0.5, (k / s + 0.5) / s - 0.5);
}

// ---------------------------------------------------------------------------------------------
// Flow of a static point

Eigen::Vector2d static_point_flow(const calib::PinholeCamera& camera, const Eigen::Vector3d& bearing, double depth,
                                  const CameraState& state) {
  const Eigen::Vector2d nan2 = Eigen::Vector2d::Constant(std::numeric_limits<double>::quiet_NaN());
  Eigen::Vector3d X, dX;
  if (std::isinf(depth) && depth > 0) {
    // At infinity only the rotation moves the point's direction: d(b)/dt = -omega x b.
    X = bearing.normalized();
    dX = -state.omega_c.cross(X);
  } else {
    if (!(depth > 0) || !(bearing.z() > 0)) return nan2;
    X = bearing * (depth / bearing.z());
    dX = -state.omega_c.cross(X) - state.v_c;
  }
  Eigen::Vector2d px;
  Eigen::Matrix<double, 2, 3> J;
  if (!camera.project(X, &px, &J)) return nan2;
  return J * dX;
}

// ---------------------------------------------------------------------------------------------
// PanoramaScene

PanoramaScene::PanoramaScene(std::shared_ptr<const Texture> texture, double gain) : texture_(std::move(texture)), gain_(gain) {
  if (!texture_ || texture_->empty()) throw std::invalid_argument("panorama scene: missing texture");
  if (!std::isfinite(gain) || gain < 0) throw std::invalid_argument("panorama scene: gain must be finite and >= 0");
  // Longitude wraps and latitude clamps; rebuild the pyramid when the texture was made otherwise.
  if (texture_->wrap_u() != TextureWrap::kRepeat || texture_->wrap_v() != TextureWrap::kClamp)
    texture_ = std::make_shared<const Texture>(texture_->level(0), TextureWrap::kRepeat, TextureWrap::kClamp);
}

std::string PanoramaScene::describe() const {
  std::ostringstream s;
  s << "panorama " << texture_size(*texture_) << " texels, gain " << gain_;
  return s.str();
}

void PanoramaScene::render(const CameraState& camera, const PixelRays& rays, const RenderRequest& request,
                           RenderedView* out) const {
  prepare_view(camera, rays, request, out);
  const Texture& tex = *texture_;
  const Eigen::Matrix3f R = camera.T_w_c.rotation_matrix().cast<float>();  // R_w_c
  const Eigen::Vector3f omega = camera.omega_c.cast<float>();
  const Eigen::Vector3f zero = Eigen::Vector3f::Zero();
  const float ku = static_cast<float>(tex.width() / (2 * M_PI));  // texels per rad of longitude
  const float kv = static_cast<float>(tex.height() / M_PI);       // texels per rad of latitude
  // Footprint: one sample spans angle * kv texels vertically and angle * ku / cos(lat)
  // horizontally; the isotropic footprint is their geometric mean (same area), so
  // lod = log2(angle) + log2(ku kv) / 2 - log2(cos(lat)) / 2.
  const float half_log2_density = 0.5f * std::log2(ku * kv);
  const int w = rays.width(), h = rays.height(), spp = rays.samples_per_pixel();
  const int row_samples = w * spp;
  const float scale = static_cast<float>(gain_) / static_cast<float>(spp);
  std::vector<float> ubuf(row_samples + 4), vbuf(row_samples + 4), lbuf(row_samples + 4);
  const float* bx = rays.sub_rays_x();
  const float* by = rays.sub_rays_y();
  const float* bz = rays.sub_rays_z();
  const float* log2_angle = rays.log2_sample_angles_f();
  const Eigen::Matrix<float, 2, 3>* jac = rays.centre_jacobians_f();
  const Eigen::Vector3f* centres = rays.centres_f();
  const auto [y_begin, y_end] = row_band(request, h);
  for (int y = y_begin; y < y_end; ++y) {
    // Pass 1, four samples at a time: world direction -> texel coordinates and the latitude term.
    const size_t base = rays.index(0, y) * spp;
    for (int j = 0; j < row_samples; j += 4) {
      const v4f x0 = load4(bx + base + j), x1 = load4(by + base + j), x2 = load4(bz + base + j);
      const v4f dx = R(0, 0) * x0 + R(0, 1) * x1 + R(0, 2) * x2;
      const v4f dy = R(1, 0) * x0 + R(1, 1) * x1 + R(1, 2) * x2;
      const v4f dz = R(2, 0) * x0 + R(2, 1) * x1 + R(2, 2) * x2;
      const v4f cos_lat = vsqrt(dx * dx + dy * dy);
      store4(ubuf.data() + j, (atan2_4(dy, dx) + kPiF) * ku);
      store4(vbuf.data() + j, (0.5f * kPiF - atan2_4(dz, cos_lat)) * kv);
      store4(lbuf.data() + j, -0.5f * log2_4(vmax(cos_lat, splat(kMinStretchCos))));
    }
    // Pass 2: texture fetches and the per-pixel outputs.
    float* I = out->intensity.ptr<float>(y);
    float* D = out->depth.ptr<float>(y);
    uint16_t* L = out->label.ptr<uint16_t>(y);
    float* F = request.flow ? out->flow.ptr<float>(y) : nullptr;
    for (int x = 0; x < w; ++x) {
      const size_t i = rays.index(x, y);
      const float lod0 = log2_angle[i] + half_log2_density;
      const int j0 = x * spp;
      float sum = 0;
      for (int k = 0; k < spp; ++k) sum += tex.sample_lod(ubuf[j0 + k], vbuf[j0 + k], lod0 + lbuf[j0 + k]);
      I[x] = sum * scale;
      D[x] = kInfF;
      L[x] = 0;
      if (F) write_flow(F + 2 * x, jac[i], centres[i], omega, zero, 0.0f);
    }
  }
}

// ---------------------------------------------------------------------------------------------
// PlanarScene

namespace {

// A plane in the camera frame, set up so a ray t b (b unit) hits it at t = nd / (n . b) and
// lands on texel (t (b . tu) + ou, t (b . tv) + ov).
struct CameraPlane {
  Eigen::Vector3f n, tu, tv;
  float nd = 0, ou = 0, ov = 0;
  float u_max = 0, v_max = 0;  // texture size, texels
  float half_log2_density = 0;  // log2(texels per m along u times along v) / 2
  float gain = 1;
  const Texture* texture = nullptr;
};

struct Hit {
  int plane = -1;
  float t = kInfF;  // range along the unit ray, m
  float u = 0, v = 0, cos_inc = 1;
};

inline Hit cast_ray(const std::vector<CameraPlane>& planes, const Eigen::Vector3f& b) {
  Hit hit;
  for (size_t p = 0; p < planes.size(); ++p) {
    const CameraPlane& pl = planes[p];
    const float nb = pl.n.dot(b);
    if (nb == 0) continue;
    const float t = pl.nd / nb;
    if (!(t > kNearHitM && t < hit.t)) continue;
    const float u = t * b.dot(pl.tu) + pl.ou;
    if (!(u >= 0 && u <= pl.u_max)) continue;
    const float v = t * b.dot(pl.tv) + pl.ov;
    if (!(v >= 0 && v <= pl.v_max)) continue;
    hit.plane = static_cast<int>(p);
    hit.t = t;
    hit.u = u;
    hit.v = v;
    hit.cos_inc = std::abs(nb);
  }
  return hit;
}

}  // namespace

PlanarScene::PlanarScene(std::vector<TexturedPlane> planes, double background_intensity)
    : planes_(std::move(planes)), background_(background_intensity) {
  if (!std::isfinite(background_intensity) || background_intensity < 0)
    throw std::invalid_argument("planar scene: background intensity must be finite and >= 0");
  if (planes_.size() >= 65535) throw std::invalid_argument("planar scene: at most 65534 planes (16-bit labels)");
  for (size_t i = 0; i < planes_.size(); ++i) {
    const TexturedPlane& p = planes_[i];
    const std::string where = "planar scene: plane " + std::to_string(i) + ": ";
    if (!p.texture || p.texture->empty()) throw std::invalid_argument(where + "missing texture");
    if (!(p.width_m > 0) || !(p.height_m > 0) || !std::isfinite(p.width_m) || !std::isfinite(p.height_m))
      throw std::invalid_argument(where + "width_m and height_m must be finite and > 0");
    if (!p.center_w.allFinite() || !std::isfinite(p.gain) || p.gain < 0)
      throw std::invalid_argument(where + "centre must be finite and gain finite and >= 0");
    if (std::abs(p.axis_u_w.norm() - 1) > 1e-6 || std::abs(p.axis_v_w.norm() - 1) > 1e-6 ||
        std::abs(p.axis_u_w.dot(p.axis_v_w)) > 1e-6)
      throw std::invalid_argument(where + "axis_u_w and axis_v_w must be orthonormal (|a| = 1, a . b = 0 to 1e-6)");
  }
}

std::string PlanarScene::describe() const {
  std::ostringstream s;
  s << "planar scene: " << planes_.size() << " textured plane(s), background " << background_;
  for (size_t i = 0; i < planes_.size(); ++i) {
    const TexturedPlane& p = planes_[i];
    s << "; [" << i + 1 << "] " << p.width_m << "x" << p.height_m << " m at (" << p.center_w.transpose() << "), "
      << texture_size(*p.texture) << " texels";
  }
  return s.str();
}

std::optional<double> PlanarScene::intersect(const Eigen::Vector3d& origin_w, const Eigen::Vector3d& dir_w) const {
  std::optional<double> best;
  if (!origin_w.allFinite() || !dir_w.allFinite() || dir_w.squaredNorm() == 0) return best;
  for (const TexturedPlane& p : planes_) {
    const Eigen::Vector3d n = p.axis_u_w.cross(p.axis_v_w);
    const double den = n.dot(dir_w);
    if (std::abs(den) < 1e-12 * dir_w.norm()) continue;  // parallel to the plane
    const double s = n.dot(p.center_w - origin_w) / den;
    if (!(s > 0) || (best && s >= *best)) continue;
    const Eigen::Vector3d d = origin_w + s * dir_w - p.center_w;
    if (std::abs(d.dot(p.axis_u_w)) <= 0.5 * p.width_m && std::abs(d.dot(p.axis_v_w)) <= 0.5 * p.height_m) best = s;
  }
  return best;
}

void PlanarScene::render(const CameraState& camera, const PixelRays& rays, const RenderRequest& request,
                         RenderedView* out) const {
  prepare_view(camera, rays, request, out);
  const calib::SE3 T_c_w = camera.T_w_c.inverse();
  const Eigen::Matrix3d R_c_w = T_c_w.rotation_matrix();
  std::vector<CameraPlane> planes(planes_.size());
  for (size_t i = 0; i < planes_.size(); ++i) {
    const TexturedPlane& p = planes_[i];
    const Eigen::Vector3d c = T_c_w * p.center_w;
    const Eigen::Vector3d u = R_c_w * p.axis_u_w, v = R_c_w * p.axis_v_w;
    const Eigen::Vector3d n = u.cross(v);
    const double su = p.texture->width() / p.width_m, sv = p.texture->height() / p.height_m;  // texels per m
    CameraPlane& q = planes[i];
    q.n = n.cast<float>();
    q.nd = static_cast<float>(n.dot(c));
    // texel u = (a + width / 2) su with a = (t b - c) . u; texel v = (height / 2 - b_coord) sv.
    q.tu = (u * su).cast<float>();
    q.ou = static_cast<float>((0.5 * p.width_m - c.dot(u)) * su);
    q.tv = (-v * sv).cast<float>();
    q.ov = static_cast<float>((0.5 * p.height_m + c.dot(v)) * sv);
    q.u_max = static_cast<float>(p.texture->width());
    q.v_max = static_cast<float>(p.texture->height());
    q.half_log2_density = static_cast<float>(0.5 * std::log2(su * sv));
    q.gain = static_cast<float>(p.gain);
    q.texture = p.texture.get();
  }
  const Eigen::Vector3f omega = camera.omega_c.cast<float>();
  const Eigen::Vector3f vel = camera.v_c.cast<float>();
  const int w = rays.width(), h = rays.height(), spp = rays.samples_per_pixel(), kc = rays.centre_sample();
  const int row_samples = w * spp;
  const float inv_spp = 1.0f / static_cast<float>(spp);
  const float background = static_cast<float>(background_);
  std::vector<int32_t> pbuf(row_samples + 4);
  std::vector<float> tbuf(row_samples + 4), ubuf(row_samples + 4), vbuf(row_samples + 4), lbuf(row_samples + 4);
  const float* bx = rays.sub_rays_x();
  const float* by = rays.sub_rays_y();
  const float* bz = rays.sub_rays_z();
  const float* log2_angle = rays.log2_sample_angles_f();
  const Eigen::Vector3f* centres = rays.centres_f();
  const Eigen::Matrix<float, 2, 3>* jac = rays.centre_jacobians_f();
  const int num_planes = static_cast<int>(planes.size());
  const auto [y_begin, y_end] = row_band(request, h);
  for (int y = y_begin; y < y_end; ++y) {
    // Pass 1, four rays at a time against every plane: nearest hit, its texel and lod term.
    const size_t base = rays.index(0, y) * spp;
    for (int j = 0; j < row_samples; j += 4) {
      const v4f x0 = load4(bx + base + j), x1 = load4(by + base + j), x2 = load4(bz + base + j);
      v4f best_t = splat(kInfF), best_u = splat(0), best_v = splat(0), best_cos = splat(1), best_hld = splat(0);
      v4i best = v4i{-1, -1, -1, -1};
      for (int p = 0; p < num_planes; ++p) {
        const CameraPlane& pl = planes[p];
        const v4f nb = pl.n.x() * x0 + pl.n.y() * x1 + pl.n.z() * x2;
        const v4f t = pl.nd / nb;  // inf / NaN when parallel: rejected by the comparisons
        const v4f u = t * (pl.tu.x() * x0 + pl.tu.y() * x1 + pl.tu.z() * x2) + pl.ou;
        const v4f v = t * (pl.tv.x() * x0 + pl.tv.y() * x1 + pl.tv.z() * x2) + pl.ov;
        const v4i ok = (t > kNearHitM) & (t < best_t) & (u >= 0.0f) & (u <= pl.u_max) & (v >= 0.0f) & (v <= pl.v_max);
        best_t = ok ? t : best_t;
        best_u = ok ? u : best_u;
        best_v = ok ? v : best_v;
        best_cos = ok ? vabs(nb) : best_cos;
        best_hld = ok ? splat(pl.half_log2_density) : best_hld;
        best = ok ? v4i{p, p, p, p} : best;
      }
      // Footprint: one sample spans t * angle metres across the ray, stretched by 1 / cos(incidence)
      // along the plane's tilt; the isotropic footprint is the geometric mean (same area), so
      // lod = log2(angle) + log2(t) + log2(texels per m^2) / 2 - log2(cos) / 2.
      const v4f t_safe = best_t < kInfF ? best_t : splat(1.0f);
      store4(lbuf.data() + j, best_hld + log2_4(t_safe) - 0.5f * log2_4(vmax(best_cos, splat(kMinStretchCos))));
      store4(pbuf.data() + j, best);
      store4(tbuf.data() + j, best_t);
      store4(ubuf.data() + j, best_u);
      store4(vbuf.data() + j, best_v);
    }
    // Pass 2: texture fetches and the per-pixel outputs.
    float* I = out->intensity.ptr<float>(y);
    float* D = out->depth.ptr<float>(y);
    uint16_t* L = out->label.ptr<uint16_t>(y);
    float* F = request.flow ? out->flow.ptr<float>(y) : nullptr;
    for (int x = 0; x < w; ++x) {
      const size_t i = rays.index(x, y);
      const int j0 = x * spp;
      const float la = log2_angle[i];
      float sum = 0;
      for (int k = 0; k < spp; ++k) {
        const int p = pbuf[j0 + k];
        if (p < 0) {
          sum += background;
        } else {
          const CameraPlane& pl = planes[p];
          sum += pl.gain * pl.texture->sample_lod(ubuf[j0 + k], vbuf[j0 + k], la + lbuf[j0 + k]);
        }
      }
      I[x] = sum * inv_spp;
      int centre_plane;
      float centre_t;
      if (kc >= 0) {
        centre_plane = pbuf[j0 + kc];
        centre_t = tbuf[j0 + kc];
      } else {
        const Hit hit = cast_ray(planes, centres[i]);
        centre_plane = hit.plane;
        centre_t = hit.t;
      }
      if (centre_plane >= 0) {
        D[x] = centre_t * centres[i].z();
        L[x] = static_cast<uint16_t>(centre_plane + 1);
        if (F) write_flow(F + 2 * x, jac[i], centres[i], omega, vel, 1.0f / centre_t);
      } else {
        D[x] = kInfF;
        L[x] = 0;
        if (F) write_flow(F + 2 * x, jac[i], centres[i], omega, vel, 0.0f);
      }
    }
  }
}

// ---------------------------------------------------------------------------------------------
// SpriteScene

namespace {

// A sprite's pose at the render time: image point p maps to sprite coordinates
// l = R(-angle) (p - centre) / scale (px at scale 1, origin at the sprite centre).
struct PosedSprite {
  const Sprite* sprite = nullptr;
  double cx = 0, cy = 0;      // centre, px
  double vx = 0, vy = 0;      // centre velocity, px/s
  double m00 = 1, m01 = 0, m10 = 0, m11 = 1;  // R(-angle) / scale
  double angular_rate = 0, scale_rate = 0;     // rad/s, 1/s
  double half_w = 0, half_h = 0;               // px at scale 1
  double tex_su = 0, tex_sv = 0;               // texels per sprite px
  float lod = 0;
  int x0 = 0, x1 = -1, y0 = 0, y1 = -1;        // pixel bounding box (inclusive)

  // True when the image point is on the sprite; *value is its intensity then.
  bool sample(double px, double py, float* value) const {
    const double dx = px - cx, dy = py - cy;
    const double lx = m00 * dx + m01 * dy, ly = m10 * dx + m11 * dy;
    if (sprite->shape == SpriteShape::kRectangle) {
      if (std::abs(lx) > half_w || std::abs(ly) > half_h) return false;
    } else {
      const double ex = lx / half_w, ey = ly / half_h;
      if (ex * ex + ey * ey > 1) return false;
    }
    if (value) {
      *value = static_cast<float>(sprite->gain) *
               sprite->texture->sample_lod(static_cast<float>((lx + half_w) * tex_su),
                                           static_cast<float>((ly + half_h) * tex_sv), lod);
    }
    return true;
  }
  // d/dt of the image position of the sprite point currently at (px, py), px/s.
  void flow(double px, double py, float* f) const {
    const double dx = px - cx, dy = py - cy;
    f[0] = static_cast<float>(vx + scale_rate * dx - angular_rate * dy);
    f[1] = static_cast<float>(vy + scale_rate * dy + angular_rate * dx);
  }
};

}  // namespace

SpriteScene::SpriteScene(std::shared_ptr<const Scene> background, std::vector<Sprite> sprites, int64_t t0_ns)
    : background_(std::move(background)), sprites_(std::move(sprites)), t0_ns_(t0_ns) {
  if (!background_) throw std::invalid_argument("sprite scene: missing background scene");
  if (sprites_.size() >= 65535) throw std::invalid_argument("sprite scene: at most 65534 sprites (16-bit labels)");
  for (size_t i = 0; i < sprites_.size(); ++i) {
    const Sprite& s = sprites_[i];
    const SpriteMotion& m = s.motion;
    const std::string where = "sprite scene: sprite " + std::to_string(i) + ": ";
    if (!s.texture || s.texture->empty()) throw std::invalid_argument(where + "missing texture");
    if (!(s.width_px > 0) || !(s.height_px > 0) || !std::isfinite(s.width_px) || !std::isfinite(s.height_px))
      throw std::invalid_argument(where + "width_px and height_px must be finite and > 0");
    if (!std::isfinite(s.gain) || s.gain < 0) throw std::invalid_argument(where + "gain must be finite and >= 0");
    if (!(m.scale > 0) || !std::isfinite(m.scale) || !std::isfinite(m.scale_rate_per_s) || !std::isfinite(m.angle_rad) ||
        !std::isfinite(m.angular_rate_radps) || !m.centre_px.allFinite() || !m.velocity_pxps.allFinite() ||
        !m.amplitude_px.allFinite() || !m.frequency_hz.allFinite() || !m.phase_rad.allFinite())
      throw std::invalid_argument(where + "motion must be finite with scale > 0");
  }
}

std::string SpriteScene::describe() const {
  std::ostringstream s;
  s << sprites_.size() << " sprite(s) over [" << background_->describe() << "]";
  return s.str();
}

void SpriteScene::render(const CameraState& camera, const PixelRays& rays, const RenderRequest& request,
                         RenderedView* out) const {
  background_->render(camera, rays, request, out);
  if (sprites_.empty()) return;
  const int w = rays.width(), h = rays.height(), spp = rays.samples_per_pixel(), kc = rays.centre_sample();
  const auto [y_begin, y_end] = row_band(request, h);
  // Labels name sprites only; the background (whatever its own labels) is 0.
  out->label.rowRange(y_begin, y_end).setTo(0);
  const double t = static_cast<double>(camera.t_ns - t0_ns_) * 1e-9;
  std::vector<PosedSprite> posed(sprites_.size());
  int ux0 = w, ux1 = -1, uy0 = h, uy1 = -1;  // union of the bounding boxes
  for (size_t i = 0; i < sprites_.size(); ++i) {
    const Sprite& s = sprites_[i];
    const SpriteMotion& m = s.motion;
    PosedSprite& p = posed[i];
    p.sprite = &s;
    const Eigen::Vector2d arg = 2 * M_PI * m.frequency_hz * t + m.phase_rad;
    p.cx = m.centre_px.x() + m.velocity_pxps.x() * t + m.amplitude_px.x() * std::sin(arg.x());
    p.cy = m.centre_px.y() + m.velocity_pxps.y() * t + m.amplitude_px.y() * std::sin(arg.y());
    p.vx = m.velocity_pxps.x() + m.amplitude_px.x() * 2 * M_PI * m.frequency_hz.x() * std::cos(arg.x());
    p.vy = m.velocity_pxps.y() + m.amplitude_px.y() * 2 * M_PI * m.frequency_hz.y() * std::cos(arg.y());
    const double angle = m.angle_rad + m.angular_rate_radps * t;
    const double scale = m.scale * std::exp(m.scale_rate_per_s * t);
    const double c = std::cos(angle), sn = std::sin(angle);
    // R(angle) = [c -s; s c] turns +x towards +y (y down); its inverse is the transpose.
    p.m00 = c / scale;
    p.m01 = sn / scale;
    p.m10 = -sn / scale;
    p.m11 = c / scale;
    p.angular_rate = m.angular_rate_radps;
    p.scale_rate = m.scale_rate_per_s;
    p.half_w = 0.5 * s.width_px;
    p.half_h = 0.5 * s.height_px;
    p.tex_su = s.texture->width() / s.width_px;
    p.tex_sv = s.texture->height() / s.height_px;
    // One sample spacing (1 / supersample px) covers tex_su / scale texels along u (tex_sv along v).
    const double fp2 = p.tex_su * p.tex_sv / (scale * scale * spp);
    p.lod = fp2 > 1 ? static_cast<float>(0.5 * std::log2(fp2)) : 0.0f;
    const double ex = scale * (std::abs(c) * p.half_w + std::abs(sn) * p.half_h);
    const double ey = scale * (std::abs(sn) * p.half_w + std::abs(c) * p.half_h);
    // Pixel x covers [x - 0.5, x + 0.5].
    p.x0 = static_cast<int>(std::max(0.0, std::ceil(p.cx - ex - 0.5)));
    p.x1 = static_cast<int>(std::min(w - 1.0, std::floor(p.cx + ex + 0.5)));
    p.y0 = static_cast<int>(std::max(0.0, std::ceil(p.cy - ey - 0.5)));
    p.y1 = static_cast<int>(std::min(h - 1.0, std::floor(p.cy + ey + 0.5)));
    if (p.x0 > p.x1 || p.y0 > p.y1) continue;
    ux0 = std::min(ux0, p.x0);
    ux1 = std::max(ux1, p.x1);
    uy0 = std::min(uy0, p.y0);
    uy1 = std::max(uy1, p.y1);
  }
  std::vector<Eigen::Vector2d> offsets(spp);
  for (int k = 0; k < spp; ++k) offsets[k] = rays.sub_offset(k);
  std::vector<int> active;
  active.reserve(posed.size());
  for (int y = std::max(uy0, y_begin); y <= std::min(uy1, y_end - 1); ++y) {
    float* I = out->intensity.ptr<float>(y);
    uint16_t* L = out->label.ptr<uint16_t>(y);
    float* F = request.flow ? out->flow.ptr<float>(y) : nullptr;
    for (int x = ux0; x <= ux1; ++x) {
      active.clear();
      for (int j = static_cast<int>(posed.size()) - 1; j >= 0; --j) {  // topmost first
        const PosedSprite& p = posed[j];
        if (x >= p.x0 && x <= p.x1 && y >= p.y0 && y <= p.y1) active.push_back(j);
      }
      if (active.empty()) continue;
      // Each sub-sample shows the topmost sprite covering it, else the background; the background's
      // own sub-samples are not kept, so uncovered samples take its pixel mean.
      float sum = 0;
      int covered = 0, centre_owner = -1;
      for (int k = 0; k < spp; ++k) {
        const double px = x + offsets[k].x(), py = y + offsets[k].y();
        for (int j : active) {
          float value;
          if (posed[j].sample(px, py, &value)) {
            sum += value;
            ++covered;
            if (k == kc) centre_owner = j;
            break;
          }
        }
      }
      if (covered == 0 && kc >= 0) continue;
      if (kc < 0) {
        for (int j : active) {
          if (posed[j].sample(x, y, nullptr)) {
            centre_owner = j;
            break;
          }
        }
      }
      I[x] = (sum + static_cast<float>(spp - covered) * I[x]) / static_cast<float>(spp);
      if (centre_owner >= 0) {
        L[x] = static_cast<uint16_t>(centre_owner + 1);
        if (F) posed[centre_owner].flow(x, y, F + 2 * x);
      }
    }
  }
}

}  // namespace evio::simulator
