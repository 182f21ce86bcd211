// Means and minima of per-image PSNR and SSIM (image_quality_summary.h).
#include "evio/evaluation/image_quality_summary.h"

#include <algorithm>
#include <cmath>

namespace evio::evaluation {

ImageScoreSummary summarize_image_scores(const std::vector<ImageScore>& scores) {
  ImageScoreSummary s;
  s.images = scores.size();
  if (scores.empty()) {
    s.psnr_db_mean = s.ssim_mean = s.psnr_db_min = s.ssim_min = NAN;
    return s;
  }
  const double n = static_cast<double>(scores.size());
  s.psnr_db_min = s.ssim_min = INFINITY;
  for (const ImageScore& q : scores) {
    s.psnr_db_mean += q.psnr_db / n;
    s.ssim_mean += q.ssim / n;
    s.psnr_db_min = std::min(s.psnr_db_min, q.psnr_db);
    s.ssim_min = std::min(s.ssim_min, q.ssim);
  }
  return s;
}

}  // namespace evio::evaluation
