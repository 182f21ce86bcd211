// evaluation::summarize_image_scores: means and minima of known scores; none: NaN.
#include "evio/evaluation/image_quality_summary.h"

#include <cmath>

#include <gtest/gtest.h>

namespace evio::evaluation {
namespace {

TEST(ImageQualitySummary, MeansAndMinima) {
  const ImageScoreSummary s = summarize_image_scores({{0.1, 20.0, 0.5}, {0.2, 30.0, 0.25}, {0.3, 16.0, 0.75}});
  EXPECT_EQ(s.images, 3u);
  EXPECT_NEAR(s.psnr_db_mean, 22.0, 1e-12);
  EXPECT_NEAR(s.ssim_mean, 0.5, 1e-12);
  EXPECT_EQ(s.psnr_db_min, 16.0);
  EXPECT_EQ(s.ssim_min, 0.25);
}

TEST(ImageQualitySummary, NoImagesIsNaN) {
  const ImageScoreSummary s = summarize_image_scores({});
  EXPECT_EQ(s.images, 0u);
  EXPECT_TRUE(std::isnan(s.psnr_db_mean));
  EXPECT_TRUE(std::isnan(s.ssim_mean));
  EXPECT_TRUE(std::isnan(s.psnr_db_min));
  EXPECT_TRUE(std::isnan(s.ssim_min));
}

}  // namespace
}  // namespace evio::evaluation
