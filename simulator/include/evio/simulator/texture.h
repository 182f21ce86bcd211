// Textures for the event simulator: single-channel linear intensity (irradiance, arbitrary units,
// >= 0) with a mipmap pyramid and trilinear, footprint-aware sampling, so that minified texture
// detail is pre-filtered instead of aliasing into spurious events. Textures come from image files
// (any format OpenCV reads; converted to grey) or from procedural generators (checkerboard,
// random shapes, smooth value noise) so tests need no files.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace evio::simulator {

enum class TextureWrap { kClamp, kRepeat };

class Texture {
 public:
  Texture() = default;
  // `intensity` is CV_32F (copied), finite and >= 0. Builds the mipmap pyramid (2x2 box
  // reduction with the wrap mode at borders; an odd-sized level pairs its last texel with the
  // wrapped neighbour, so level means equal the image mean exactly for power-of-two sizes and
  // approximately otherwise; levels down to 1 x 1). Throws std::invalid_argument otherwise.
  explicit Texture(const cv::Mat& intensity, TextureWrap wrap_u = TextureWrap::kClamp,
                   TextureWrap wrap_v = TextureWrap::kClamp);

  // Loads an image file, converts to grey, maps 8/16-bit values v in [0, max] to
  // min_intensity + (max_intensity - min_intensity) * v / max (max = 255 or 65535; 32-bit float
  // images use max = 1 and must be finite and >= 0). Throws evio::InputError naming the file when
  // it cannot be read, std::invalid_argument when 0 <= min_intensity <= max_intensity is violated.
  static Texture load(const std::string& path, double min_intensity = 0.05, double max_intensity = 1.0,
                      TextureWrap wrap_u = TextureWrap::kClamp, TextureWrap wrap_v = TextureWrap::kClamp);

  bool empty() const { return levels_.empty(); }
  int width() const;   // texels of level 0
  int height() const;
  int num_levels() const { return static_cast<int>(levels_.size()); }
  const cv::Mat& level(int i) const { return levels_.at(i); }
  TextureWrap wrap_u() const { return wrap_u_; }
  TextureWrap wrap_v() const { return wrap_v_; }

  // Sample at continuous texel coordinates of level 0: texel (i, j) covers [i, i+1) x [j, j+1),
  // so its centre is (i + 0.5, j + 0.5). `footprint` is the size of the sampling area in level-0
  // texels (e.g. a camera pixel's extent on the texture); <= 1 gives bilinear sampling of level
  // 0, larger values blend the two mip levels around log2(footprint) (trilinear).
  float sample(double u, double v, double footprint) const;
  // The same sampling with the mip level of detail given directly: lod = log2(footprint)
  // (<= 0: bilinear on level 0). Float coordinates, for the renderers' inner loops.
  // Inline (defined below) so the renderers' loops avoid a call per sample. Requires !empty().
  float sample_lod(float u, float v, float lod) const { return sample_impl(u, v, lod); }
  // Bilinear sample of one mip level at level-0 texel coordinates (level i is addressed through
  // the scale width(i) / width(0), so the whole texture always spans [0, width()) x [0, height())).
  float sample_level(int level, double u, double v) const;

 private:
  // Raw view of one mip level for the sampling loops (points into levels_, whose buffers are
  // shared by copies of the Texture, so the pointers stay valid when the Texture is copied).
  struct LevelView {
    const float* data = nullptr;
    size_t stride = 0;  // floats per row
    int w = 0, h = 0;
    float scale_u = 1, scale_v = 1;  // level texels per level-0 texel
  };
  // Bilinear on one level; u, v are level-0 coordinates already folded into [0, width()] x
  // [0, height()] along repeat axes (wrap_level0), any value along clamp axes.
  template <typename T>
  float bilinear(const LevelView& l, T u, T v) const;
  template <typename T>
  float sample_impl(T u, T v, T lod) const;
  void build_views();

  std::vector<cv::Mat> levels_;
  std::vector<LevelView> views_;
  TextureWrap wrap_u_ = TextureWrap::kClamp, wrap_v_ = TextureWrap::kClamp;
};

enum class ProceduralKind {
  kCheckerboard,  // squares of cell_px texels alternating min/max intensity
  kShapes,        // num_shapes random filled circles, rectangles and triangles (antialiased) on a mid-grey
  kNoise,         // smooth value noise (octaves of bilinear-interpolated random lattices)
  kConstant,      // uniform max_intensity (no texture: a scene that must give no events)
};

struct ProceduralTextureOptions {
  ProceduralKind kind = ProceduralKind::kCheckerboard;
  int width = 1024;              // texels, > 0
  int height = 512;              // texels, > 0
  double cell_px = 64;           // checkerboard cell size, texels
  int num_shapes = 40;           // shapes
  double noise_scale_px = 32;    // lattice spacing of the coarsest noise octave, texels
  int octaves = 4;               // noise octaves (each halves the spacing and the amplitude)
  double min_intensity = 0.05;   // darkest value, intensity units (> 0 keeps log finite)
  double max_intensity = 1.0;    // brightest value, intensity units
  uint64_t seed = 1;
  bool Validate(std::string* why) const;
};

// Deterministic for a given options/seed. Throws std::invalid_argument on invalid options.
Texture make_procedural_texture(const ProceduralTextureOptions& options,
                                TextureWrap wrap_u = TextureWrap::kClamp,
                                TextureWrap wrap_v = TextureWrap::kClamp);

// "checkerboard", "shapes", "noise", "constant".
const char* procedural_kind_name(ProceduralKind kind);
bool procedural_kind_from_name(const std::string& name, ProceduralKind* kind);

// ---------------------------------------------------------------------------------------------
// Inline sampling (hot path of the renderers).

// The sampling helpers are small but GCC does not inline them into the renderers' loops on its
// own at -O2, and a call per sample is a large share of a render.
#if defined(__GNUC__)
#define EVIO_SIM_ALWAYS_INLINE inline __attribute__((always_inline))
#else
#define EVIO_SIM_ALWAYS_INLINE inline
#endif

namespace internal {

// floor() for the sampling loops: the release build targets baseline x86-64 (no SSE4.1 round
// instruction), where std::floor is a library call.
template <typename T>
inline int fast_floor(T x) {
  const int i = static_cast<int>(x);
  return (x < static_cast<T>(i)) ? i - 1 : i;
}

// Level-0 coordinates this far out are folded by std::floor first (fast_floor would overflow).
constexpr double kFastFloorLimit = 1e9;

// Folds a level-0 coordinate of a repeat axis into [0, n] (n itself only by rounding).
template <typename T>
inline T wrap_level0(T u, int n) {
  const T fn = static_cast<T>(n);
  if (std::abs(u) > kFastFloorLimit) u -= fn * std::floor(u / fn);
  return u - fn * static_cast<T>(fast_floor(u * (static_cast<T>(1) / fn)));
}

}  // namespace internal

template <typename T>
EVIO_SIM_ALWAYS_INLINE float Texture::bilinear(const LevelView& l, T u, T v) const {
  T x = u * static_cast<T>(l.scale_u) - static_cast<T>(0.5);
  T y = v * static_cast<T>(l.scale_v) - static_cast<T>(0.5);
  int x0, x1, y0, y1;
  if (wrap_u_ == TextureWrap::kRepeat) {
    if (x < 0) x += static_cast<T>(l.w);  // u in [0, width()] puts x in [-0.5, w - 0.5]
    x0 = static_cast<int>(x);
    // x == w by rounding, or NaN input: stay in bounds (the weight then reaches texel 0).
    if (static_cast<unsigned>(x0) >= static_cast<unsigned>(l.w)) x0 = l.w - 1;
    x1 = x0 + 1 == l.w ? 0 : x0 + 1;
  } else {
    x = std::min(static_cast<T>(l.w - 1), std::max(static_cast<T>(0), x));  // this order maps NaN to 0
    x0 = static_cast<int>(x);
    x1 = std::min(x0 + 1, l.w - 1);
  }
  if (wrap_v_ == TextureWrap::kRepeat) {
    if (y < 0) y += static_cast<T>(l.h);
    y0 = static_cast<int>(y);
    if (static_cast<unsigned>(y0) >= static_cast<unsigned>(l.h)) y0 = l.h - 1;
    y1 = y0 + 1 == l.h ? 0 : y0 + 1;
  } else {
    y = std::min(static_cast<T>(l.h - 1), std::max(static_cast<T>(0), y));
    y0 = static_cast<int>(y);
    y1 = std::min(y0 + 1, l.h - 1);
  }
  const float fx = static_cast<float>(x - static_cast<T>(x0)), fy = static_cast<float>(y - static_cast<T>(y0));
  const float* r0 = l.data + static_cast<size_t>(y0) * l.stride;
  const float* r1 = l.data + static_cast<size_t>(y1) * l.stride;
  const float top = r0[x0] + fx * (r0[x1] - r0[x0]);
  const float bottom = r1[x0] + fx * (r1[x1] - r1[x0]);
  return top + fy * (bottom - top);
}

template <typename T>
EVIO_SIM_ALWAYS_INLINE float Texture::sample_impl(T u, T v, T lod) const {
  if (wrap_u_ == TextureWrap::kRepeat) u = internal::wrap_level0(u, views_[0].w);
  if (wrap_v_ == TextureWrap::kRepeat) v = internal::wrap_level0(v, views_[0].h);
  const int n = static_cast<int>(views_.size());
  if (!(lod > 0)) return bilinear(views_[0], u, v);
  if (lod >= static_cast<T>(n - 1)) return bilinear(views_[n - 1], u, v);
  const int l = static_cast<int>(lod);
  const float f = static_cast<float>(lod - static_cast<T>(l));
  const float a = bilinear(views_[l], u, v);
  const float b = bilinear(views_[l + 1], u, v);
  return a + f * (b - a);
}

// The true log intensity of an equirectangular mosaic (width x height texels, calib/equirectangular.h)
// of a panorama texture at infinity (PanoramaScene, scene.h): texel (i, j) looks along
// d_m = pixel_direction(i, j) in the mosaic frame, R_w_m d_m in the texture's world frame; its value
// is log(max(min_intensity, texture sampled there)) with the mosaic texel's footprint (texture height
// / mosaic height texels). The reference mapping::compare_images takes for a mosaic built from a
// simulated sequence (R_w_m from aligning the first pose, as `evio mosaic --gt` does). H x W,
// row-major (mapping::ImageF). Throws std::invalid_argument for an empty texture, a size below
// 2 x 2 or min_intensity <= 0.
Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> panorama_log_reference(
    const Texture& texture, const Eigen::Matrix3d& R_w_m, int width, int height, double min_intensity = 1e-4);

}  // namespace evio::simulator
