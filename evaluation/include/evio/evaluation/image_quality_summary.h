// Summary of an image reconstruction's quality over a sequence (`evio reconstruct`'s eval.json):
// each image scored against the true view at its time (PSNR in dB and SSIM, e.g. by
// mapping::compare_images), and the sequence by the means and the minima of the two.
#pragma once

#include <cstddef>
#include <vector>

namespace evio::evaluation {

struct ImageScore {
  double t_s = 0;      // the image's time, s
  double psnr_db = 0;  // dB
  double ssim = 0;     // in [-1, 1]
};

struct ImageScoreSummary {
  size_t images = 0;
  double psnr_db_mean = 0, ssim_mean = 0;  // means over the images; NaN when there is none
  double psnr_db_min = 0, ssim_min = 0;    // minima over the images; NaN when there is none
};

ImageScoreSummary summarize_image_scores(const std::vector<ImageScore>& scores);

}  // namespace evio::evaluation
