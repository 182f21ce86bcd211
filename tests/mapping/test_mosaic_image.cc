// Log-intensity image output and quality (mapping/mosaic_image.h): display mapping (percentiles,
// gamma, unseen pixels, local contrast equalisation), PNG 8/16 and float TIFF files read back, and PSNR / SSIM after the affine
// fit with known answers.
#include <cmath>
#include <cstdio>
#include <random>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "evio/calib/error.h"
#include "evio/mapping/mosaic_image.h"
#include "evio_test/temp_dir.h"

namespace {

using evio::mapping::compare_images;
using evio::mapping::ImageF;
using evio::mapping::ImageQualityOptions;
using evio::mapping::LogImageDisplayOptions;
using evio::mapping::MaskU8;

// 0..n-1 ramp in row-major order (values distinct, easy percentiles).
ImageF ramp(int W, int H) {
  ImageF L(H, W);
  for (int k = 0; k < W * H; ++k) L.data()[k] = static_cast<float>(k);
  return L;
}

ImageF smooth(int W, int H) {
  ImageF L(H, W);
  for (int j = 0; j < H; ++j)
    for (int i = 0; i < W; ++i)
      L(j, i) = static_cast<float>(std::sin(0.07 * i + 0.3) * std::cos(0.05 * j) + 0.5 * std::sin(0.011 * i * j / 4.0));
  return L;
}

TEST(MosaicImage, DisplayMappingPercentilesGammaUnseen) {
  const int W = 10, H = 11;  // 110 values 0..109: 1st percentile rank round(1.09) = 1, 99th round(107.91) = 108
  const ImageF L = ramp(W, H);
  LogImageDisplayOptions o;
  ImageF t = evio::mapping::log_image_to_display(L, nullptr, o);
  EXPECT_FLOAT_EQ(t.data()[0], 0.0f);   // below the 1st percentile: clipped
  EXPECT_FLOAT_EQ(t.data()[1], 0.0f);   // the 1st percentile
  EXPECT_FLOAT_EQ(t.data()[108], 1.0f);
  EXPECT_FLOAT_EQ(t.data()[109], 1.0f);
  EXPECT_NEAR(t.data()[50], (50.0 - 1.0) / 107.0, 1e-6);
  o.gamma = 2.0;
  t = evio::mapping::log_image_to_display(L, nullptr, o);
  EXPECT_NEAR(t.data()[50], std::sqrt((50.0 - 1.0) / 107.0), 1e-6);
  // Unseen pixels: black, and left out of the percentiles.
  MaskU8 seen = MaskU8::Ones(H, W);
  seen.data()[109] = 0;
  seen.data()[108] = 0;
  o.gamma = 1.0;
  o.high_percentile = 100.0;
  t = evio::mapping::log_image_to_display(L, &seen, o);
  EXPECT_EQ(t.data()[109], 0.0f);
  EXPECT_FLOAT_EQ(t.data()[107], 1.0f);
  // Linear intensity: exp(L) percentiles.
  ImageF L2(1, 3);
  L2 << 0.0f, std::log(2.0f), std::log(3.0f);
  LogImageDisplayOptions lin;
  lin.linear_intensity = true;
  lin.low_percentile = 0;
  lin.high_percentile = 100;
  t = evio::mapping::log_image_to_display(L2, nullptr, lin);
  EXPECT_NEAR(t(0, 1), 0.5, 1e-6);  // (2 - 1) / (3 - 1)
  // Flat image: mid grey.
  t = evio::mapping::log_image_to_display(ImageF::Constant(4, 4, 2.0f), nullptr, {});
  EXPECT_FLOAT_EQ(t(2, 2), 0.5f);
  LogImageDisplayOptions bad;
  bad.high_percentile = 0.5;
  EXPECT_THROW(evio::mapping::log_image_to_display(L, nullptr, bad), std::invalid_argument);
}

// Local contrast equalisation (equalize_clip > 0, CLAHE): a dark half and a bright half, each with
// a faint texture. The global mapping spends the range on the step between the halves, so each
// half's texture spans a small part of it; equalised per tile, each half's texture is stretched.
// Unseen pixels stay black and out of the equalisation; bad settings are rejected.
TEST(MosaicImage, LocalContrastEqualisationStretchesEachRegionsTexture) {
  const int W = 256, H = 128;
  ImageF L(H, W);
  for (int j = 0; j < H; ++j)
    for (int i = 0; i < W; ++i)
      L(j, i) = static_cast<float>((i < W / 2 ? -2.0 : 0.0) + 0.1 * std::sin(0.4 * i) * std::cos(0.3 * j));
  MaskU8 seen = MaskU8::Ones(H, W);
  for (int i = 0; i < W; ++i) seen(0, i) = 0;
  auto texture_std = [&](const ImageF& t, int i0, int i1) {  // the texture's spread inside one half
    double s = 0, s2 = 0;
    int n = 0;
    for (int j = 8; j < H - 8; ++j)
      for (int i = i0; i < i1; ++i) {
        s += t(j, i);
        s2 += t(j, i) * t(j, i);
        ++n;
      }
    return std::sqrt(std::max(0.0, s2 / n - (s / n) * (s / n)));
  };
  LogImageDisplayOptions o;
  const ImageF global = evio::mapping::log_image_to_display(L, &seen, o);
  o.equalize_clip = 3.0;
  o.equalize_tile_px = 32;
  const ImageF eq = evio::mapping::log_image_to_display(L, &seen, o);
  const double g_dark = texture_std(global, 8, W / 2 - 8), g_bright = texture_std(global, W / 2 + 8, W - 8);
  const double e_dark = texture_std(eq, 8, W / 2 - 8), e_bright = texture_std(eq, W / 2 + 8, W - 8);
  std::printf("texture std, global / equalised: dark %.4f / %.4f, bright %.4f / %.4f\n", g_dark, e_dark, g_bright, e_bright);
  EXPECT_GT(e_dark, 8 * g_dark);  // measured 11.2x
  EXPECT_GT(e_bright, 8 * g_bright);  // measured 11.2x
  for (int i = 0; i < W; ++i) EXPECT_EQ(eq(0, i), 0.0f);
  EXPECT_GE(eq.minCoeff(), 0.0f);
  EXPECT_LE(eq.maxCoeff(), 1.0f);
  LogImageDisplayOptions bad;
  bad.equalize_clip = -1;
  EXPECT_THROW(evio::mapping::log_image_to_display(L, nullptr, bad), std::invalid_argument);
  bad = {};
  bad.equalize_tile_px = 4;
  EXPECT_THROW(evio::mapping::log_image_to_display(L, nullptr, bad), std::invalid_argument);
}

TEST(MosaicImage, FilesReadBack) {
  evio_test::TempDir dir;
  const int W = 64, H = 32;
  const ImageF L = smooth(W, H);
  MaskU8 seen = MaskU8::Ones(H, W);
  seen.block(0, 0, 4, W).setZero();
  const ImageF t = evio::mapping::log_image_to_display(L, &seen, {});

  evio::mapping::write_log_image_png8(dir.file("m8.png"), L, &seen);
  const cv::Mat p8 = cv::imread(dir.file("m8.png"), cv::IMREAD_UNCHANGED);
  ASSERT_EQ(p8.type(), CV_8UC1);
  ASSERT_EQ(p8.rows, H);
  ASSERT_EQ(p8.cols, W);
  evio::mapping::write_log_image_png16(dir.file("m16.png"), L, &seen);
  const cv::Mat p16 = cv::imread(dir.file("m16.png"), cv::IMREAD_UNCHANGED);
  ASSERT_EQ(p16.type(), CV_16UC1);
  evio::mapping::write_log_image_tiff(dir.file("m.tif"), L, &seen);
  const cv::Mat tf = cv::imread(dir.file("m.tif"), cv::IMREAD_UNCHANGED);
  ASSERT_EQ(tf.type(), CV_32FC1);
  int dark = 0, bright = 0;
  for (int j = 0; j < H; ++j)
    for (int i = 0; i < W; ++i) {
      EXPECT_EQ(p8.at<uint8_t>(j, i), std::lround(255.0 * t(j, i)));
      EXPECT_EQ(p16.at<uint16_t>(j, i), std::lround(65535.0 * t(j, i)));
      if (seen(j, i)) {
        EXPECT_EQ(tf.at<float>(j, i), L(j, i));
        dark += p8.at<uint8_t>(j, i) == 0;
        bright += p8.at<uint8_t>(j, i) == 255;
      } else {
        EXPECT_TRUE(std::isnan(tf.at<float>(j, i)));
        EXPECT_EQ(p8.at<uint8_t>(j, i), 0);
      }
    }
  // ~1 % of the 1792 seen pixels at each end.
  EXPECT_GE(dark, 10);
  EXPECT_LE(dark, 30);
  EXPECT_GE(bright, 10);
  EXPECT_LE(bright, 30);
  EXPECT_THROW(evio::mapping::write_log_image_png8(dir.file("no/such/dir/x.png"), L, &seen), evio::InputError);
}

TEST(MosaicImage, TransparentUnseenPixelsAndCoverageMask) {
  evio_test::TempDir dir;
  const int W = 64, H = 32;
  ImageF L = smooth(W, H);
  MaskU8 seen = MaskU8::Ones(H, W);
  seen.block(0, 0, 4, W).setZero();
  seen.block(10, 20, 5, 7).setZero();
  L(20, 30) = std::nanf("");  // seen but not finite: transparent too
  LogImageDisplayOptions o;
  o.transparent_unseen = true;
  const ImageF t = evio::mapping::log_image_to_display(L, &seen, o);
  evio::mapping::write_log_image_png8(dir.file("rgba8.png"), L, &seen, o);
  evio::mapping::write_log_image_png16(dir.file("rgba16.png"), L, &seen, o);
  evio::mapping::write_mask_png(dir.file("seen.png"), seen);
  const cv::Mat p8 = cv::imread(dir.file("rgba8.png"), cv::IMREAD_UNCHANGED);
  const cv::Mat p16 = cv::imread(dir.file("rgba16.png"), cv::IMREAD_UNCHANGED);
  const cv::Mat m = cv::imread(dir.file("seen.png"), cv::IMREAD_UNCHANGED);
  ASSERT_EQ(p8.type(), CV_8UC4);
  ASSERT_EQ(p16.type(), CV_16UC4);
  ASSERT_EQ(m.type(), CV_8UC1);
  ASSERT_EQ(p8.rows, H);
  ASSERT_EQ(p8.cols, W);
  int transparent = 0, opaque_black = 0;
  for (int j = 0; j < H; ++j)
    for (int i = 0; i < W; ++i) {
      const bool shown = seen(j, i) && std::isfinite(L(j, i));
      const cv::Vec4b c = p8.at<cv::Vec4b>(j, i);
      const cv::Vec<uint16_t, 4> c16 = p16.at<cv::Vec<uint16_t, 4>>(j, i);
      EXPECT_EQ(c[3], shown ? 255 : 0) << j << " " << i;
      EXPECT_EQ(c16[3], shown ? 65535 : 0) << j << " " << i;
      for (int k = 0; k < 3; ++k) {
        EXPECT_EQ(c[k], std::lround(255.0 * t(j, i)));
        EXPECT_EQ(c16[k], std::lround(65535.0 * t(j, i)));
      }
      EXPECT_EQ(m.at<uint8_t>(j, i), seen(j, i) ? 255 : 0);
      transparent += !shown;
      opaque_black += shown && c[0] == 0;
    }
  EXPECT_EQ(transparent, 4 * W + 5 * 7 + 1);
  // The darkest seen pixels (below the low percentile) are black but opaque.
  EXPECT_GE(opaque_black, 10);
}

TEST(MosaicImage, QualityIdenticalAndAffineCopy) {
  const int W = 96, H = 64;
  const ImageF ref = smooth(W, H);
  auto q = compare_images(ref, ref, nullptr);
  std::printf("identical: PSNR %.1f dB, SSIM %.12f\n", q.psnr_db, q.ssim);
  EXPECT_GT(q.psnr_db, 120.0);
  EXPECT_NEAR(q.ssim, 1.0, 1e-9);
  EXPECT_NEAR(q.scale, 1.0, 1e-9);
  EXPECT_NEAR(q.offset, 0.0, 1e-9);
  EXPECT_EQ(q.pixels, W * H);
  // Affine copy (what an unknown C and offset do to log intensity): same answer.
  const ImageF est = (2.5f * ref.array() - 3.0f).matrix();
  q = compare_images(est, ref, nullptr);
  std::printf("affine copy: PSNR %.1f dB, SSIM %.12f, a %.6f, b %.6f\n", q.psnr_db, q.ssim, q.scale, q.offset);
  EXPECT_GT(q.psnr_db, 100.0);
  EXPECT_NEAR(q.ssim, 1.0, 1e-9);
  EXPECT_NEAR(q.scale, 0.4, 1e-6);
  EXPECT_NEAR(q.offset, 1.2, 1e-6);
  // Offset-only fit cannot absorb the scale.
  ImageQualityOptions off;
  off.fit_scale = false;
  q = compare_images(est, ref, nullptr, off);
  EXPECT_LT(q.psnr_db, 20.0);
  EXPECT_LT(q.ssim, 0.9);
  // Offset-only fit with a pure offset: exact again.
  q = compare_images(ImageF((ref.array() + 7.0f).matrix()), ref, nullptr, off);
  EXPECT_GT(q.psnr_db, 100.0);
}

TEST(MosaicImage, QualityNoiseMatchesPsnrFormulaAndMaskIsRespected) {
  const int W = 256, H = 128;
  const ImageF ref = smooth(W, H);
  const double peak = ref.maxCoeff() - ref.minCoeff();
  std::mt19937 rng(4);
  double prev_ssim = 1.0;
  for (double sigma : {0.01, 0.03, 0.1}) {
    std::normal_distribution<float> N(0.0f, static_cast<float>(sigma));
    ImageF est = ref;
    for (int k = 0; k < est.size(); ++k) est.data()[k] += N(rng);
    const auto q = compare_images(est, ref, nullptr);
    const double expected = 20.0 * std::log10(peak / sigma);
    std::printf("noise sigma %.2f: PSNR %.2f dB (20 log10(peak/sigma) = %.2f), SSIM %.4f\n", sigma, q.psnr_db,
                expected, q.ssim);
    EXPECT_NEAR(q.psnr_db, expected, 0.2);
    EXPECT_LT(q.ssim, prev_ssim);
    prev_ssim = q.ssim;
  }
  // Garbage outside the mask changes nothing.
  MaskU8 mask = MaskU8::Ones(H, W);
  mask.block(0, 0, 20, W).setZero();
  ImageF est = (0.5f * ref.array() + 1.0f).matrix();
  const auto clean = compare_images(est, ref, &mask);
  est.block(0, 0, 20, W).setConstant(1e6f);
  est(0, 0) = NAN;
  const auto dirty = compare_images(est, ref, &mask);
  EXPECT_EQ(clean.pixels, (H - 20) * W);
  EXPECT_EQ(dirty.pixels, clean.pixels);
  EXPECT_DOUBLE_EQ(dirty.ssim, clean.ssim);
  EXPECT_NEAR(dirty.ssim, 1.0, 1e-9);
  // Unmasked, the garbage is seen.
  est(0, 0) = 0.0f;
  EXPECT_LT(compare_images(est, ref, nullptr).ssim, 0.95);
  EXPECT_THROW(compare_images(ImageF::Zero(H, W), ref, nullptr), std::invalid_argument);
  EXPECT_THROW(compare_images(ref, ImageF::Zero(H, W + 1), nullptr), std::invalid_argument);
}

}  // namespace

