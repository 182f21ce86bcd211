// Textures for the event simulator: mipmap pyramid (2x2 box with the wrap mode), bilinear and
// trilinear sampling in level-0 texel coordinates, image loading and seeded procedural generators.
// See texture.h for the conventions.
#include "evio/simulator/texture.h"

#include "evio/calib/equirectangular.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>


#include "evio/calib/error.h"
#include "evio/sensors/image_io.h"

namespace evio::simulator {
namespace {

inline int wrap_index(int i, int n, TextureWrap wrap) {
  if (i >= 0 && i < n) return i;
  if (wrap == TextureWrap::kClamp) return std::clamp(i, 0, n - 1);
  const int m = i % n;
  return m < 0 ? m + n : m;
}

// One 2x2 box reduction: (w, h) -> ((w + 1) / 2, (h + 1) / 2); an odd level's last texel pairs
// with its wrapped neighbour (itself under clamp, texel 0 under repeat).
cv::Mat reduce_level(const cv::Mat& src, TextureWrap wrap_u, TextureWrap wrap_v) {
  const int w = src.cols, h = src.rows;
  const int w2 = (w + 1) / 2, h2 = (h + 1) / 2;
  cv::Mat dst(h2, w2, CV_32F);
  for (int y = 0; y < h2; ++y) {
    const float* r0 = src.ptr<float>(wrap_index(2 * y, h, wrap_v));
    const float* r1 = src.ptr<float>(wrap_index(2 * y + 1, h, wrap_v));
    float* out = dst.ptr<float>(y);
    for (int x = 0; x < w2; ++x) {
      const int x0 = wrap_index(2 * x, w, wrap_u), x1 = wrap_index(2 * x + 1, w, wrap_u);
      // Sum in double so a level's mean is the exact mean of its parent up to float rounding.
      out[x] = static_cast<float>(0.25 * (static_cast<double>(r0[x0]) + r0[x1] + r1[x0] + r1[x1]));
    }
  }
  return dst;
}

// Uniform double in [0, 1) from the top 53 bits: same numbers on every standard library
// (std::uniform_real_distribution's algorithm is implementation-defined).
inline double uniform01(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

// Integral over [0, x] of the checkerboard parity p(s) = floor(s / c) mod 2.
double parity_integral(double x, double c) {
  const double q = std::floor(x / (2 * c));
  const double r = x - 2 * c * q;
  return q * c + std::max(0.0, r - c);
}

// Box-filtered checkerboard: texel value = exact area fraction of the texel in "odd" cells
// (cell (0, 0), top-left, is min_intensity).
cv::Mat make_checkerboard(const ProceduralTextureOptions& o) {
  std::vector<double> ex(o.width), ey(o.height);
  for (int i = 0; i < o.width; ++i) ex[i] = parity_integral(i + 1.0, o.cell_px) - parity_integral(i, o.cell_px);
  for (int j = 0; j < o.height; ++j) ey[j] = parity_integral(j + 1.0, o.cell_px) - parity_integral(j, o.cell_px);
  cv::Mat img(o.height, o.width, CV_32F);
  for (int j = 0; j < o.height; ++j) {
    float* row = img.ptr<float>(j);
    for (int i = 0; i < o.width; ++i) {
      const double odd = ex[i] * (1 - ey[j]) + (1 - ex[i]) * ey[j];
      row[i] = static_cast<float>(o.min_intensity + (o.max_intensity - o.min_intensity) * odd);
    }
  }
  return img;
}

struct Shape {
  int kind = 0;  // 0 circle, 1 rectangle, 2 triangle
  double cx = 0, cy = 0;
  double r = 0;           // circle radius / bounding radius
  double hx = 0, hy = 0;  // rectangle half sizes
  double ca = 1, sa = 0;  // rectangle orientation
  std::array<double, 6> tri{};  // triangle vertices (x0 y0 x1 y1 x2 y2), counter-clockwise
  double value = 0;

  bool inside(double x, double y) const {
    const double dx = x - cx, dy = y - cy;
    switch (kind) {
      case 0:
        return dx * dx + dy * dy <= r * r;
      case 1: {
        const double lx = ca * dx + sa * dy, ly = -sa * dx + ca * dy;
        return std::abs(lx) <= hx && std::abs(ly) <= hy;
      }
      default: {
        for (int e = 0; e < 3; ++e) {
          const double ax = tri[2 * e], ay = tri[2 * e + 1];
          const double bx = tri[(2 * e + 2) % 6], by = tri[(2 * e + 3) % 6];
          if ((bx - ax) * (y - ay) - (by - ay) * (x - ax) < 0) return false;
        }
        return true;
      }
    }
  }
};

// Random filled shapes on mid-grey, composited in order; each texel's coverage is estimated
// with kAa x kAa sub-samples (antialiased edges). Under repeat wrap a shape is also drawn shifted
// by one period so it continues across the border.
cv::Mat make_shapes(const ProceduralTextureOptions& o, TextureWrap wrap_u, TextureWrap wrap_v) {
  constexpr int kAa = 4;
  std::mt19937_64 rng(o.seed);
  cv::Mat img(o.height, o.width, CV_32F, cv::Scalar(0.5 * (o.min_intensity + o.max_intensity)));
  const double base = std::min(o.width, o.height);
  for (int s = 0; s < o.num_shapes; ++s) {
    Shape sh;
    sh.kind = static_cast<int>(uniform01(rng) * 3);
    sh.cx = uniform01(rng) * o.width;
    sh.cy = uniform01(rng) * o.height;
    sh.r = base * (0.03 + 0.12 * uniform01(rng));
    const double angle = 2 * M_PI * uniform01(rng);
    sh.value = o.min_intensity + (o.max_intensity - o.min_intensity) * uniform01(rng);
    sh.ca = std::cos(angle);
    sh.sa = std::sin(angle);
    sh.hx = sh.r * (0.4 + 0.6 * uniform01(rng));
    sh.hy = sh.r * (0.4 + 0.6 * uniform01(rng));
    for (int k = 0; k < 3; ++k) {
      const double a = angle + 2 * M_PI * k / 3 + 0.6 * (uniform01(rng) - 0.5);
      sh.tri[2 * k] = sh.cx + sh.r * std::cos(a);
      sh.tri[2 * k + 1] = sh.cy + sh.r * std::sin(a);
    }
    const double reach = sh.r * std::sqrt(2.0) + 1;
    std::vector<double> shifts_u{0}, shifts_v{0};
    if (wrap_u == TextureWrap::kRepeat) shifts_u = {-static_cast<double>(o.width), 0, static_cast<double>(o.width)};
    if (wrap_v == TextureWrap::kRepeat) shifts_v = {-static_cast<double>(o.height), 0, static_cast<double>(o.height)};
    for (double su : shifts_u) {
      for (double sv : shifts_v) {
        const int x0 = std::max(0, static_cast<int>(std::floor(sh.cx + su - reach)));
        const int x1 = std::min(o.width - 1, static_cast<int>(std::ceil(sh.cx + su + reach)));
        const int y0 = std::max(0, static_cast<int>(std::floor(sh.cy + sv - reach)));
        const int y1 = std::min(o.height - 1, static_cast<int>(std::ceil(sh.cy + sv + reach)));
        for (int y = y0; y <= y1; ++y) {
          float* row = img.ptr<float>(y);
          for (int x = x0; x <= x1; ++x) {
            int hits = 0;
            for (int b = 0; b < kAa; ++b) {
              for (int a = 0; a < kAa; ++a) {
                hits += sh.inside(x + (a + 0.5) / kAa - su, y + (b + 0.5) / kAa - sv) ? 1 : 0;
              }
            }
            if (hits == 0) continue;
            const double cov = static_cast<double>(hits) / (kAa * kAa);
            row[x] = static_cast<float>(row[x] + cov * (sh.value - row[x]));
          }
        }
      }
    }
  }
  return img;
}

inline double smoothstep(double t) { return t * t * (3 - 2 * t); }

// Value noise: octave o has a lattice of uniform random values with spacing noise_scale_px / 2^o
// (adjusted to divide the texture size under repeat wrap, so the noise tiles) and amplitude 2^-o,
// interpolated bilinearly with smoothstep weights (C1). The sum is stretched to [min, max].
cv::Mat make_noise(const ProceduralTextureOptions& o, TextureWrap wrap_u, TextureWrap wrap_v) {
  std::mt19937_64 rng(o.seed);
  cv::Mat acc(o.height, o.width, CV_64F, cv::Scalar(0));
  double amplitude = 1;
  for (int oct = 0; oct < o.octaves; ++oct, amplitude *= 0.5) {
    const double spacing = o.noise_scale_px / std::ldexp(1.0, oct);
    auto lattice = [&](int size, TextureWrap wrap, int* n, double* step) {
      if (wrap == TextureWrap::kRepeat) {
        *n = std::max(1, static_cast<int>(std::lround(size / spacing)));
        *step = static_cast<double>(size) / *n;
      } else {
        *n = static_cast<int>(std::ceil(size / spacing)) + 2;
        *step = spacing;
      }
    };
    int nx = 0, ny = 0;
    double sx = 1, sy = 1;
    lattice(o.width, wrap_u, &nx, &sx);
    lattice(o.height, wrap_v, &ny, &sy);
    std::vector<double> values(static_cast<size_t>(nx) * ny);
    for (double& v : values) v = uniform01(rng);
    auto at = [&](int i, int j) {
      i = wrap_u == TextureWrap::kRepeat ? i % nx : std::min(i, nx - 1);
      j = wrap_v == TextureWrap::kRepeat ? j % ny : std::min(j, ny - 1);
      return values[static_cast<size_t>(j) * nx + i];
    };
    for (int y = 0; y < o.height; ++y) {
      const double gy = (y + 0.5) / sy;
      const int iy = static_cast<int>(gy);
      const double fy = smoothstep(gy - iy);
      double* row = acc.ptr<double>(y);
      for (int x = 0; x < o.width; ++x) {
        const double gx = (x + 0.5) / sx;
        const int ix = static_cast<int>(gx);
        const double fx = smoothstep(gx - ix);
        const double top = at(ix, iy) + fx * (at(ix + 1, iy) - at(ix, iy));
        const double bottom = at(ix, iy + 1) + fx * (at(ix + 1, iy + 1) - at(ix, iy + 1));
        row[x] += amplitude * (top + fy * (bottom - top));
      }
    }
  }
  double lo = 0, hi = 0;
  cv::minMaxLoc(acc, &lo, &hi);
  cv::Mat img(o.height, o.width, CV_32F);
  for (int y = 0; y < o.height; ++y) {
    const double* a = acc.ptr<double>(y);
    float* row = img.ptr<float>(y);
    for (int x = 0; x < o.width; ++x) {
      const double t = hi > lo ? (a[x] - lo) / (hi - lo) : 0.5;
      row[x] = static_cast<float>(o.min_intensity + (o.max_intensity - o.min_intensity) * t);
    }
  }
  return img;
}

}  // namespace

Texture::Texture(const cv::Mat& intensity, TextureWrap wrap_u, TextureWrap wrap_v) : wrap_u_(wrap_u), wrap_v_(wrap_v) {
  if (intensity.empty() || intensity.type() != CV_32FC1 || intensity.dims != 2)
    throw std::invalid_argument("texture: intensity must be a non-empty single-channel CV_32F image");
  for (int y = 0; y < intensity.rows; ++y) {
    const float* row = intensity.ptr<float>(y);
    for (int x = 0; x < intensity.cols; ++x) {
      if (!std::isfinite(row[x]) || row[x] < 0)
        throw std::invalid_argument("texture: intensity at (" + std::to_string(x) + ", " + std::to_string(y) +
                                    ") is " + std::to_string(row[x]) + " (expected finite and >= 0)");
    }
  }
  levels_.push_back(intensity.clone());
  while (levels_.back().cols > 1 || levels_.back().rows > 1) levels_.push_back(reduce_level(levels_.back(), wrap_u, wrap_v));
  build_views();
}

void Texture::build_views() {
  views_.clear();
  const double w0 = levels_.front().cols, h0 = levels_.front().rows;
  for (const cv::Mat& m : levels_) {
    LevelView v;
    v.data = m.ptr<float>(0);
    v.stride = m.step1();
    v.w = m.cols;
    v.h = m.rows;
    v.scale_u = static_cast<float>(m.cols / w0);
    v.scale_v = static_cast<float>(m.rows / h0);
    views_.push_back(v);
  }
}

int Texture::width() const { return levels_.empty() ? 0 : levels_.front().cols; }
int Texture::height() const { return levels_.empty() ? 0 : levels_.front().rows; }

float Texture::sample_level(int level, double u, double v) const {
  if (levels_.empty()) throw std::logic_error("texture: sample of an empty texture");
  if (level < 0 || level >= num_levels()) throw std::out_of_range("texture: mip level " + std::to_string(level));
  if (!std::isfinite(u) || !std::isfinite(v)) return std::numeric_limits<float>::quiet_NaN();
  if (wrap_u_ == TextureWrap::kRepeat) u = internal::wrap_level0(u, views_[0].w);
  if (wrap_v_ == TextureWrap::kRepeat) v = internal::wrap_level0(v, views_[0].h);
  return bilinear(views_[level], u, v);
}

float Texture::sample(double u, double v, double footprint) const {
  if (levels_.empty()) throw std::logic_error("texture: sample of an empty texture");
  if (!std::isfinite(u) || !std::isfinite(v)) return std::numeric_limits<float>::quiet_NaN();
  return sample_impl(u, v, footprint > 1 ? std::log2(footprint) : 0.0);
}

Texture Texture::load(const std::string& path, double min_intensity, double max_intensity, TextureWrap wrap_u,
                      TextureWrap wrap_v) {
  if (!(min_intensity >= 0) || !(max_intensity >= min_intensity) || !std::isfinite(max_intensity))
    throw std::invalid_argument("texture: need 0 <= min_intensity <= max_intensity (finite), got " +
                                std::to_string(min_intensity) + ", " + std::to_string(max_intensity));
  cv::Mat img;
  try {
    img = read_image(path, cv::IMREAD_ANYDEPTH | cv::IMREAD_GRAYSCALE);
  } catch (const cv::Exception& e) {
    throw InputError(path, 0, std::string("cannot decode the image: ") + e.what(),
                     "an image file OpenCV can read (PNG, JPEG, TIFF, ...)");
  }
  if (img.empty())
    throw InputError(path, 0, "cannot read the image (missing file or unsupported format)",
                     "an image file OpenCV can read (PNG, JPEG, TIFF, ...)");
  double max_value = 1;
  switch (img.depth()) {
    case CV_8U: max_value = 255; break;
    case CV_16U: max_value = 65535; break;
    case CV_32F: max_value = 1; break;
    default:
      throw InputError(path, 0, "unsupported pixel depth " + std::to_string(img.depth()), "8-bit, 16-bit or float pixels");
  }
  cv::Mat f;
  img.convertTo(f, CV_32F);
  if (img.depth() == CV_32F) {
    for (int y = 0; y < f.rows; ++y) {
      const float* row = f.ptr<float>(y);
      for (int x = 0; x < f.cols; ++x) {
        if (!std::isfinite(row[x]) || row[x] < 0)
          throw InputError(path, 0,
                           "float pixel (" + std::to_string(x) + ", " + std::to_string(y) + ") is " +
                               std::to_string(row[x]),
                           "finite values >= 0");
      }
    }
  }
  f.convertTo(f, CV_32F, (max_intensity - min_intensity) / max_value, min_intensity);
  return Texture(f, wrap_u, wrap_v);
}

bool ProceduralTextureOptions::Validate(std::string* why) const {
  constexpr int kMaxSide = 1 << 15;
  if (width <= 0 || height <= 0 || width > kMaxSide || height > kMaxSide)
    return validation_failed(why, "width and height must be in [1, " + std::to_string(kMaxSide) + "] texels, got " +
                         std::to_string(width) + " x " + std::to_string(height));
  if (!(cell_px > 0) || !std::isfinite(cell_px)) return validation_failed(why, "cell_px must be > 0 texels");
  if (num_shapes < 0) return validation_failed(why, "num_shapes must be >= 0");
  if (!(noise_scale_px > 0) || !std::isfinite(noise_scale_px)) return validation_failed(why, "noise_scale_px must be > 0 texels");
  if (octaves < 1 || octaves > 16) return validation_failed(why, "octaves must be in [1, 16]");
  if (!(min_intensity >= 0) || !std::isfinite(max_intensity) || !(max_intensity >= min_intensity))
    return validation_failed(why, "need 0 <= min_intensity <= max_intensity (finite)");
  return true;
}

Texture make_procedural_texture(const ProceduralTextureOptions& options, TextureWrap wrap_u, TextureWrap wrap_v) {
  std::string why;
  if (!options.Validate(&why)) throw std::invalid_argument("procedural texture: " + why);
  switch (options.kind) {
    case ProceduralKind::kCheckerboard:
      return Texture(make_checkerboard(options), wrap_u, wrap_v);
    case ProceduralKind::kShapes:
      return Texture(make_shapes(options, wrap_u, wrap_v), wrap_u, wrap_v);
    case ProceduralKind::kNoise:
      return Texture(make_noise(options, wrap_u, wrap_v), wrap_u, wrap_v);
    case ProceduralKind::kConstant:
      break;
  }
  return Texture(cv::Mat(options.height, options.width, CV_32F, cv::Scalar(options.max_intensity)), wrap_u, wrap_v);
}

const char* procedural_kind_name(ProceduralKind kind) {
  switch (kind) {
    case ProceduralKind::kCheckerboard: return "checkerboard";
    case ProceduralKind::kShapes: return "shapes";
    case ProceduralKind::kNoise: return "noise";
    case ProceduralKind::kConstant: return "constant";
  }
  return "unknown";
}

bool procedural_kind_from_name(const std::string& name, ProceduralKind* kind) {
  for (ProceduralKind k : {ProceduralKind::kCheckerboard, ProceduralKind::kShapes, ProceduralKind::kNoise,
                           ProceduralKind::kConstant}) {
    if (name == procedural_kind_name(k)) {
      if (kind) *kind = k;
      return true;
    }
  }
  return false;
}

Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> panorama_log_reference(
    const Texture& texture, const Eigen::Matrix3d& R_w_m, int width, int height, double min_intensity) {
  if (texture.empty()) throw std::invalid_argument("panorama_log_reference: empty texture");
  if (width < 2 || height < 2) throw std::invalid_argument("panorama_log_reference: size below 2 x 2");
  if (!(min_intensity > 0)) throw std::invalid_argument("panorama_log_reference: min_intensity must be > 0");
  const calib::Equirectangular mosaic(width, height);
  const calib::Equirectangular tex(texture.width(), texture.height());
  const double footprint = static_cast<double>(texture.height()) / height;
  Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> ref(height, width);
  for (int v = 0; v < height; ++v)
    for (int u = 0; u < width; ++u) {
      const Eigen::Vector2d t = tex.project(R_w_m * mosaic.pixel_direction(u, v));
      ref(v, u) = static_cast<float>(
          std::log(std::max(min_intensity, static_cast<double>(texture.sample(t.x(), t.y(), footprint)))));
    }
  return ref;
}

}  // namespace evio::simulator
