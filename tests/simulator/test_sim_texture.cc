#include "evio/simulator/texture.h"

#include <cmath>
#include <cstdint>
#include <random>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "evio/calib/error.h"
#include "evio_test/temp_dir.h"

namespace evio::simulator {
namespace {

cv::Mat random_image(int w, int h, uint64_t seed) {
  std::mt19937_64 rng(seed);
  cv::Mat m(h, w, CV_32F);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) m.at<float>(y, x) = static_cast<float>((rng() >> 11) * 0x1.0p-53);
  return m;
}

double level_mean(const Texture& t, int i) { return cv::mean(t.level(i))[0]; }

TEST(SimTexture, ExactAtTexelCentres) {
  const cv::Mat img = random_image(17, 9, 3);
  for (TextureWrap wrap : {TextureWrap::kClamp, TextureWrap::kRepeat}) {
    const Texture t(img, wrap, wrap);
    for (int y = 0; y < img.rows; ++y) {
      for (int x = 0; x < img.cols; ++x) {
        EXPECT_EQ(t.sample(x + 0.5, y + 0.5, 1.0), img.at<float>(y, x)) << x << " " << y;
        EXPECT_EQ(t.sample_lod(x + 0.5f, y + 0.5f, 0.0f), img.at<float>(y, x));
      }
    }
  }
}

TEST(SimTexture, BilinearBetweenCentresAndWrapModes) {
  const cv::Mat img = random_image(8, 6, 4);
  const Texture clamp(img, TextureWrap::kClamp, TextureWrap::kClamp);
  const Texture repeat(img, TextureWrap::kRepeat, TextureWrap::kRepeat);
  // Halfway between texels (2, 3) and (3, 3).
  EXPECT_NEAR(clamp.sample(3.0, 3.5, 1), 0.5 * (img.at<float>(3, 2) + img.at<float>(3, 3)), 1e-6);
  // A quarter of the way towards the lower-right neighbour in both directions.
  const double q = 0.25;
  const double expected = (1 - q) * (1 - q) * img.at<float>(1, 4) + q * (1 - q) * img.at<float>(1, 5) +
                          (1 - q) * q * img.at<float>(2, 4) + q * q * img.at<float>(2, 5);
  EXPECT_NEAR(repeat.sample(4.5 + q, 1.5 + q, 0.5), expected, 1e-6);
  // At the left border: repeat blends the last and first column, clamp holds the first column.
  EXPECT_NEAR(repeat.sample(0.0, 2.5, 1), 0.5 * (img.at<float>(2, 0) + img.at<float>(2, 7)), 1e-6);
  EXPECT_NEAR(clamp.sample(0.0, 2.5, 1), img.at<float>(2, 0), 1e-6);
  EXPECT_NEAR(clamp.sample(-5.0, 2.5, 1), img.at<float>(2, 0), 1e-6);
  // Repeat is periodic with the texture size, far away too.
  EXPECT_NEAR(repeat.sample(3.3 + 8 * 1000, 2.7 - 6 * 50, 1), repeat.sample(3.3, 2.7, 1), 1e-5);
  EXPECT_NEAR(clamp.sample(3.3, 100.0, 1), clamp.sample(3.3, 5.5, 1), 1e-6);
}

TEST(SimTexture, MipLevelMeansEqualImageMean) {
  ProceduralTextureOptions o;
  o.kind = ProceduralKind::kNoise;
  o.width = 256;
  o.height = 128;
  for (TextureWrap wrap : {TextureWrap::kClamp, TextureWrap::kRepeat}) {
    const Texture t = make_procedural_texture(o, wrap, wrap);
    ASSERT_EQ(t.num_levels(), 9);  // 256x128 ... 2x1, 1x1
    EXPECT_EQ(t.level(1).cols, 128);
    EXPECT_EQ(t.level(1).rows, 64);
    EXPECT_EQ(t.level(8).cols, 1);
    EXPECT_EQ(t.level(8).rows, 1);
    const double mean0 = level_mean(t, 0);
    for (int i = 1; i < t.num_levels(); ++i) EXPECT_NEAR(level_mean(t, i), mean0, 1e-5 * mean0) << "level " << i;
    // Level 1 texel = mean of its 2x2 parents.
    const cv::Mat& l0 = t.level(0);
    EXPECT_NEAR(t.level(1).at<float>(5, 7),
                0.25 * (l0.at<float>(10, 14) + l0.at<float>(10, 15) + l0.at<float>(11, 14) + l0.at<float>(11, 15)), 1e-6);
  }
  // Odd sizes still end at 1x1; the last texel pairs with its wrapped neighbour.
  const cv::Mat odd = random_image(5, 3, 9);
  const Texture t(odd, TextureWrap::kRepeat, TextureWrap::kClamp);
  EXPECT_EQ(t.num_levels(), 4);  // 5x3, 3x2, 2x1, 1x1
  EXPECT_NEAR(t.level(1).at<float>(1, 2),
              0.25 * (2 * odd.at<float>(2, 4) + 2 * odd.at<float>(2, 0)), 1e-6);  // column 4 + wrap to 0, row 2 clamped
}

TEST(SimTexture, TrilinearFootprintSelectsAndBlendsLevels) {
  ProceduralTextureOptions o;
  o.kind = ProceduralKind::kNoise;
  o.width = 64;
  o.height = 64;
  const Texture t = make_procedural_texture(o, TextureWrap::kRepeat, TextureWrap::kRepeat);
  const double u = 21.3, v = 40.8;
  for (int l = 0; l < 5; ++l) EXPECT_NEAR(t.sample(u, v, std::ldexp(1.0, l)), t.sample_level(l, u, v), 1e-6);
  // Footprint 2^1.25 blends levels 1 and 2 with weights 0.75 / 0.25.
  EXPECT_NEAR(t.sample(u, v, std::pow(2.0, 1.25)), 0.75 * t.sample_level(1, u, v) + 0.25 * t.sample_level(2, u, v),
              1e-6);
  EXPECT_NEAR(t.sample_lod(static_cast<float>(u), static_cast<float>(v), 1.25f), t.sample(u, v, std::pow(2.0, 1.25)),
              1e-5);
  // A footprint larger than the texture gives the mean.
  EXPECT_NEAR(t.sample(u, v, 1e6), level_mean(t, 0), 1e-5);
  // Footprints <= 1 are plain bilinear on level 0.
  EXPECT_EQ(t.sample(u, v, 0.3), t.sample_level(0, u, v));
}

TEST(SimTexture, CheckerboardIsBoxFiltered) {
  ProceduralTextureOptions o;
  o.kind = ProceduralKind::kCheckerboard;
  o.width = 64;
  o.height = 32;
  o.cell_px = 8;
  o.min_intensity = 0.1;
  o.max_intensity = 0.9;
  const Texture t = make_procedural_texture(o);
  const cv::Mat& img = t.level(0);
  EXPECT_FLOAT_EQ(img.at<float>(0, 0), 0.1f);  // cell (0, 0) is dark
  EXPECT_FLOAT_EQ(img.at<float>(0, 8), 0.9f);
  EXPECT_FLOAT_EQ(img.at<float>(8, 0), 0.9f);
  EXPECT_FLOAT_EQ(img.at<float>(9, 9), 0.1f);
  EXPECT_NEAR(level_mean(t, 0), 0.5, 1e-6);
  // A cell edge inside a texel: column 4 of a 4.5-texel checkerboard is half dark, half bright.
  o.cell_px = 4.5;
  const Texture half = make_procedural_texture(o);
  EXPECT_NEAR(half.level(0).at<float>(0, 4), 0.5, 1e-6);
  EXPECT_NEAR(half.level(0).at<float>(0, 3), 0.1, 1e-6);
}

TEST(SimTexture, ProceduralDeterministicBySeed) {
  for (ProceduralKind kind : {ProceduralKind::kShapes, ProceduralKind::kNoise}) {
    ProceduralTextureOptions o;
    o.kind = kind;
    o.width = 128;
    o.height = 64;
    o.seed = 7;
    const Texture a = make_procedural_texture(o), b = make_procedural_texture(o);
    EXPECT_EQ(cv::norm(a.level(0), b.level(0), cv::NORM_INF), 0.0) << procedural_kind_name(kind);
    o.seed = 8;
    const Texture c = make_procedural_texture(o);
    EXPECT_GT(cv::norm(a.level(0), c.level(0), cv::NORM_INF), 0.1) << procedural_kind_name(kind);
    double lo = 0, hi = 0;
    cv::minMaxLoc(a.level(0), &lo, &hi);
    EXPECT_GE(lo, o.min_intensity - 1e-6);
    EXPECT_LE(hi, o.max_intensity + 1e-6);
  }
}

TEST(SimTexture, ShapesHaveAntialiasedEdges) {
  ProceduralTextureOptions o;
  o.kind = ProceduralKind::kShapes;
  o.width = 256;
  o.height = 256;
  o.num_shapes = 10;
  o.min_intensity = 0.0;
  o.max_intensity = 1.0;
  const Texture t = make_procedural_texture(o);
  const cv::Mat& img = t.level(0);
  // Count texels that differ from all 4-neighbours' common values: edge texels take partial coverage,
  // so they lie strictly between their left and right neighbours where the two differ clearly.
  int steps = 0, intermediate = 0;
  for (int y = 0; y < img.rows; ++y) {
    for (int x = 1; x + 1 < img.cols; ++x) {
      const float a = img.at<float>(y, x - 1), b = img.at<float>(y, x), c = img.at<float>(y, x + 1);
      if (std::abs(a - c) < 0.2f) continue;
      ++steps;
      if (b > std::min(a, c) + 0.02f && b < std::max(a, c) - 0.02f) ++intermediate;
    }
  }
  ASSERT_GT(steps, 50);
  EXPECT_GT(intermediate, steps / 3) << "edges are not antialiased";
}

TEST(SimTexture, NoiseIsSmoothAndSpansTheRange) {
  ProceduralTextureOptions o;
  o.kind = ProceduralKind::kNoise;
  o.width = 256;
  o.height = 128;
  o.noise_scale_px = 32;
  o.octaves = 3;
  o.min_intensity = 0.2;
  o.max_intensity = 0.8;
  const Texture t = make_procedural_texture(o, TextureWrap::kRepeat, TextureWrap::kRepeat);
  const cv::Mat& img = t.level(0);
  double lo = 0, hi = 0;
  cv::minMaxLoc(img, &lo, &hi);
  EXPECT_NEAR(lo, 0.2, 1e-6);
  EXPECT_NEAR(hi, 0.8, 1e-6);
  // Finest octave spacing is 8 texels: neighbouring texels differ by a small fraction of the range,
  // also across the (seamless) repeat border.
  float max_step = 0;
  for (int y = 0; y < img.rows; ++y)
    for (int x = 0; x < img.cols; ++x)
      max_step = std::max(max_step, std::abs(img.at<float>(y, x) - img.at<float>(y, (x + 1) % img.cols)));
  EXPECT_LT(max_step, 0.15f);
  EXPECT_GT(max_step, 0.005f);
}

TEST(SimTexture, ConstantAndNames) {
  ProceduralTextureOptions o;
  o.kind = ProceduralKind::kConstant;
  o.width = 16;
  o.height = 8;
  o.max_intensity = 0.7;
  const Texture t = make_procedural_texture(o);
  EXPECT_FLOAT_EQ(t.sample(3.2, 7.9, 1), 0.7f);
  for (ProceduralKind k : {ProceduralKind::kCheckerboard, ProceduralKind::kShapes, ProceduralKind::kNoise,
                           ProceduralKind::kConstant}) {
    ProceduralKind back = ProceduralKind::kConstant;
    ASSERT_TRUE(procedural_kind_from_name(procedural_kind_name(k), &back));
    EXPECT_EQ(back, k);
  }
  EXPECT_FALSE(procedural_kind_from_name("Checkerboard", nullptr));
}

TEST(SimTexture, ValidationRejectsBadInput) {
  std::string why;
  ProceduralTextureOptions o;
  EXPECT_TRUE(o.Validate(&why)) << why;
  o.width = 0;
  EXPECT_FALSE(o.Validate(&why));
  EXPECT_NE(why.find("width"), std::string::npos);
  EXPECT_THROW(make_procedural_texture(o), std::invalid_argument);
  o = ProceduralTextureOptions();
  o.min_intensity = 2;
  o.max_intensity = 1;
  EXPECT_FALSE(o.Validate(&why));
  o = ProceduralTextureOptions();
  o.octaves = 0;
  EXPECT_FALSE(o.Validate(&why));

  cv::Mat bad = random_image(4, 4, 1);
  bad.at<float>(2, 1) = -0.5f;
  EXPECT_THROW(Texture{bad}, std::invalid_argument);
  bad.at<float>(2, 1) = std::nanf("");
  EXPECT_THROW(Texture{bad}, std::invalid_argument);
  EXPECT_THROW(Texture{cv::Mat(4, 4, CV_8U, cv::Scalar(1))}, std::invalid_argument);
  EXPECT_THROW(Texture{cv::Mat()}, std::invalid_argument);
  const Texture empty;
  EXPECT_TRUE(empty.empty());
  EXPECT_THROW(empty.sample(0, 0, 1), std::logic_error);
}

TEST(SimTexture, LoadMapsBitDepthsToIntensity) {
  evio_test::TempDir dir;
  cv::Mat g8(4, 6, CV_8U);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 6; ++x) g8.at<uint8_t>(y, x) = static_cast<uint8_t>(10 * x + 60 * y);
  ASSERT_TRUE(cv::imwrite(dir.file("g8.png"), g8));
  const Texture t8 = Texture::load(dir.file("g8.png"), 0.1, 0.9);
  ASSERT_EQ(t8.width(), 6);
  ASSERT_EQ(t8.height(), 4);
  EXPECT_NEAR(t8.level(0).at<float>(2, 3), 0.1 + 0.8 * 150 / 255.0, 1e-6);
  EXPECT_NEAR(t8.level(0).at<float>(0, 0), 0.1, 1e-6);

  cv::Mat g16(3, 3, CV_16U, cv::Scalar(65535));
  g16.at<uint16_t>(1, 1) = 32768;
  ASSERT_TRUE(cv::imwrite(dir.file("g16.png"), g16));
  const Texture t16 = Texture::load(dir.file("g16.png"), 0.0, 2.0, TextureWrap::kRepeat, TextureWrap::kClamp);
  EXPECT_NEAR(t16.level(0).at<float>(1, 1), 2.0 * 32768 / 65535.0, 1e-6);
  EXPECT_NEAR(t16.level(0).at<float>(0, 2), 2.0, 1e-6);
  EXPECT_EQ(t16.wrap_u(), TextureWrap::kRepeat);

  // Colour images are converted to grey.
  cv::Mat colour(2, 2, CV_8UC3, cv::Scalar(255, 255, 255));
  ASSERT_TRUE(cv::imwrite(dir.file("c.png"), colour));
  EXPECT_NEAR(Texture::load(dir.file("c.png"), 0.05, 1.0).level(0).at<float>(1, 1), 1.0, 1e-6);

  const std::string missing = dir.file("missing.png");
  try {
    Texture::load(missing);
    FAIL() << "no exception";
  } catch (const evio::InputError& e) {
    EXPECT_EQ(e.file(), missing);
  }
  const std::string garbage = dir.write("garbage.png", "not an image");
  EXPECT_THROW(Texture::load(garbage), evio::InputError);
  EXPECT_THROW(Texture::load(dir.file("g8.png"), 0.5, 0.1), std::invalid_argument);
}

}  // namespace
// The true panorama's log intensity on the mosaic grid: with R_w_m = I the mosaic and the texture
// share the equirectangular convention, so texel (i, j) of a W x H mosaic samples the texture at
// ((i + 0.5) Wt / W, (j + 0.5) Ht / H); a 90 deg turn about z shifts longitude by a quarter turn.
TEST(SimTexture, PanoramaReferenceSamplesTheTextureAlongEachTexelsDirection) {
  const int Wt = 256, Ht = 128, W = 64, H = 32;
  cv::Mat img(Ht, Wt, CV_32F);
  for (int j = 0; j < Ht; ++j)
    for (int i = 0; i < Wt; ++i) img.at<float>(j, i) = 0.1f + 0.8f * static_cast<float>(i) / Wt;  // ramp in longitude
  const Texture tex(img, TextureWrap::kRepeat, TextureWrap::kClamp);
  const auto ref = panorama_log_reference(tex, Eigen::Matrix3d::Identity(), W, H);
  ASSERT_EQ(ref.rows(), H);
  ASSERT_EQ(ref.cols(), W);
  // Away from the seam (where the repeat wrap blends both ends), the ramp's mean over the footprint.
  for (int i = 4; i < W - 4; i += 7) {
    const double u_tex = (i + 0.5) * Wt / W;
    EXPECT_NEAR(ref(H / 2, i), std::log(0.1 + 0.8 * (u_tex - 0.5) / Wt), 0.01) << i;
  }
  Eigen::Matrix3d Rz;  // +90 deg about z: mosaic longitude l looks along texture longitude l + 90 deg
  Rz << 0, -1, 0, 1, 0, 0, 0, 0, 1;
  const auto turned = panorama_log_reference(tex, Rz, W, H);
  EXPECT_NEAR(turned(H / 2, 10), ref(H / 2, 10 + W / 4), 1e-4);
  EXPECT_THROW(panorama_log_reference(Texture(), Rz, W, H), std::invalid_argument);
  EXPECT_THROW(panorama_log_reference(tex, Rz, 1, H), std::invalid_argument);
}

}  // namespace evio::simulator
