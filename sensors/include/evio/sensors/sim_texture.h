// Textures for the event simulator: single-channel linear intensity (irradiance, arbitrary units,
// >= 0) with a mipmap pyramid and trilinear, footprint-aware sampling, so that minified texture
// detail is pre-filtered instead of aliasing into spurious events. Textures come from image files
// (any format OpenCV reads; converted to grey) or from procedural generators (checkerboard,
// random shapes, smooth value noise) so tests need no files.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace evio::sim {

enum class TextureWrap { kClamp, kRepeat };

class Texture {
 public:
  Texture() = default;
  // `intensity` is CV_32F (copied), finite and >= 0. Builds the mipmap pyramid (2x2 box
  // reduction with the wrap mode at borders). Throws std::invalid_argument otherwise.
  explicit Texture(const cv::Mat& intensity, TextureWrap wrap_u = TextureWrap::kClamp,
                   TextureWrap wrap_v = TextureWrap::kClamp);

  // Loads an image file, converts to grey, maps 8/16-bit values v in [0, max] to
  // min_intensity + (max_intensity - min_intensity) * v / max. Throws evio::InputError naming
  // the file when it cannot be read.
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

 private:
  std::vector<cv::Mat> levels_;
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

}  // namespace evio::sim
