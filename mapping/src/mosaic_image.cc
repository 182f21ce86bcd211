// Display mapping, image files and PSNR / SSIM for log-intensity images. Conventions in
// mosaic_image.h.
#include "evio/mapping/mosaic_image.h"
#include "evio/mapping/option_tables.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "evio/calib/equirectangular.h"
#include "evio/calib/error.h"
#include "evio/sensors/image_io.h"

namespace evio::mapping {
namespace {

void check_mask(const MaskU8* mask, Eigen::Index rows, Eigen::Index cols, const char* what) {
  if (mask && (mask->rows() != rows || mask->cols() != cols))
    throw std::invalid_argument(std::string(what) + ": mask is " + std::to_string(mask->rows()) + "x" +
                                std::to_string(mask->cols()) + ", image " + std::to_string(rows) + "x" +
                                std::to_string(cols));
}

double nearest_rank(std::vector<double>* v, double percent) {
  const auto k = static_cast<size_t>(std::llround(percent / 100.0 * static_cast<double>(v->size() - 1)));
  std::nth_element(v->begin(), v->begin() + static_cast<std::ptrdiff_t>(k), v->end());
  return (*v)[k];
}

// The image file, or an InputError naming it.
void write_image_or_throw(const std::string& path, const cv::Mat& img, const std::vector<int>& params = {}) {
  if (!evio::write_image(path, img, params)) {
    throw InputError(path, 0, "cannot write the image", "a writable path with a .png/.tif extension");
  }
}

}  // namespace

bool LogImageDisplayOptions::Validate(std::string* why) const {
  if (!log_image_display_table().check(*this, why)) return false;
  if (!(high_percentile > low_percentile)) return validation_failed(why, "high_percentile must be > low_percentile");
  return true;
}

bool ImageQualityOptions::Validate(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  if (!(peak >= 0.0 && std::isfinite(peak))) return fail("peak must be >= 0 (0 = reference range)");
  if (!(ssim_sigma > 0.0 && ssim_sigma < 1e3)) return fail("ssim_sigma must be in (0, 1000) px");
  return true;
}

ImageF log_image_to_display(const ImageF& L, const MaskU8* seen, const LogImageDisplayOptions& o) {
  std::string why;
  if (!o.Validate(&why)) throw std::invalid_argument("LogImageDisplayOptions: " + why);
  check_mask(seen, L.rows(), L.cols(), "log_image_to_display");
  const Eigen::Index n = L.size();
  auto usable = [&](Eigen::Index k) { return std::isfinite(L.data()[k]) && (!seen || seen->data()[k] != 0); };
  double max_l = -std::numeric_limits<double>::infinity();
  for (Eigen::Index k = 0; k < n; ++k)
    if (usable(k)) max_l = std::max(max_l, static_cast<double>(L.data()[k]));
  auto value = [&](Eigen::Index k) {
    const double l = L.data()[k];
    return o.linear_intensity ? std::exp(l - max_l) : l;
  };
  std::vector<double> vals;
  vals.reserve(static_cast<size_t>(n));
  for (Eigen::Index k = 0; k < n; ++k)
    if (usable(k)) vals.push_back(value(k));
  ImageF out = ImageF::Zero(L.rows(), L.cols());
  if (vals.empty()) return out;
  const double lo = nearest_rank(&vals, o.low_percentile);
  const double hi = nearest_rank(&vals, o.high_percentile);
  const double inv_gamma = 1.0 / o.gamma;
  for (Eigen::Index k = 0; k < n; ++k) {
    if (!usable(k)) continue;
    const double t = hi > lo ? (value(k) - lo) / (hi - lo) : 0.5;
    out.data()[k] = static_cast<float>(std::clamp(t, 0.0, 1.0));
  }
  if (o.equalize_clip > 0) {
    // CLAHE on 16 bits; unseen pixels at the seen median so they do not pull the tiles' histograms.
    std::vector<float> seen_t;
    for (Eigen::Index k = 0; k < n; ++k)
      if (usable(k)) seen_t.push_back(out.data()[k]);
    std::nth_element(seen_t.begin(), seen_t.begin() + static_cast<std::ptrdiff_t>(seen_t.size() / 2), seen_t.end());
    const float median = seen_t[seen_t.size() / 2];
    const int rows = static_cast<int>(L.rows()), cols = static_cast<int>(L.cols());
    cv::Mat img(rows, cols, CV_16UC1);
    for (int j = 0; j < rows; ++j)
      for (int i = 0; i < cols; ++i) {
        const Eigen::Index k = static_cast<Eigen::Index>(j) * cols + i;
        img.at<uint16_t>(j, i) = static_cast<uint16_t>(std::lround(65535.0 * (usable(k) ? out.data()[k] : median)));
      }
    const int tx = std::max(1, (cols + o.equalize_tile_px - 1) / o.equalize_tile_px);
    const int ty = std::max(1, (rows + o.equalize_tile_px - 1) / o.equalize_tile_px);
    cv::Ptr<cv::CLAHE> clahe = cv::createCLAHE(o.equalize_clip, cv::Size(tx, ty));
    cv::Mat eq;
    clahe->apply(img, eq);
    for (int j = 0; j < rows; ++j)
      for (int i = 0; i < cols; ++i) {
        const Eigen::Index k = static_cast<Eigen::Index>(j) * cols + i;
        if (usable(k)) out.data()[k] = static_cast<float>(eq.at<uint16_t>(j, i) / 65535.0);
      }
  }
  if (o.gamma != 1.0)
    for (Eigen::Index k = 0; k < n; ++k)
      if (usable(k)) out.data()[k] = static_cast<float>(std::pow(static_cast<double>(out.data()[k]), inv_gamma));
  return out;
}

namespace {

// The display mapping as an 8- or 16-bit image (T = uint8_t or uint16_t): one grey channel, or
// grey + alpha (alpha 0 where unseen or non-finite) with transparent_unseen.
template <typename T>
cv::Mat display_image(const ImageF& L, const MaskU8* seen, const LogImageDisplayOptions& options, int depth) {
  const ImageF t = log_image_to_display(L, seen, options);
  const double full = static_cast<double>(std::numeric_limits<T>::max());
  const int rows = static_cast<int>(t.rows()), cols = static_cast<int>(t.cols());
  if (!options.transparent_unseen) {
    cv::Mat img(rows, cols, CV_MAKETYPE(depth, 1));
    for (int j = 0; j < rows; ++j)
      for (int i = 0; i < cols; ++i) img.at<T>(j, i) = static_cast<T>(std::lround(full * t(j, i)));
    return img;
  }
  cv::Mat img(rows, cols, CV_MAKETYPE(depth, 4));
  for (int j = 0; j < rows; ++j)
    for (int i = 0; i < cols; ++i) {
      const bool shown = std::isfinite(L(j, i)) && (!seen || (*seen)(j, i) != 0);
      const T g = static_cast<T>(std::lround(full * t(j, i)));
      img.at<cv::Vec<T, 4>>(j, i) = cv::Vec<T, 4>(g, g, g, shown ? std::numeric_limits<T>::max() : T{0});
    }
  return img;
}

}  // namespace

void write_log_image_png8(const std::string& path, const ImageF& L, const MaskU8* seen,
                          const LogImageDisplayOptions& options) {
  write_image_or_throw(path, display_image<uint8_t>(L, seen, options, CV_8U));
}

void write_log_image_png16(const std::string& path, const ImageF& L, const MaskU8* seen,
                           const LogImageDisplayOptions& options) {
  write_image_or_throw(path, display_image<uint16_t>(L, seen, options, CV_16U));
}

void write_mask_png(const std::string& path, const MaskU8& mask) {
  cv::Mat img(static_cast<int>(mask.rows()), static_cast<int>(mask.cols()), CV_8UC1);
  for (int j = 0; j < img.rows; ++j)
    for (int i = 0; i < img.cols; ++i) img.at<uint8_t>(j, i) = mask(j, i) != 0 ? 255 : 0;
  write_image_or_throw(path, img);
}

void write_log_image_tiff(const std::string& path, const ImageF& L, const MaskU8* seen) {
  check_mask(seen, L.rows(), L.cols(), "write_log_image_tiff");
  cv::Mat img(static_cast<int>(L.rows()), static_cast<int>(L.cols()), CV_32FC1);
  for (int j = 0; j < img.rows; ++j)
    for (int i = 0; i < img.cols; ++i)
      img.at<float>(j, i) = (!seen || (*seen)(j, i)) ? L(j, i) : std::numeric_limits<float>::quiet_NaN();
  write_image_or_throw(path, img);
}

ImageQuality compare_images(const ImageF& est, const ImageF& ref, const MaskU8* mask, const ImageQualityOptions& o) {
  std::string why;
  if (!o.Validate(&why)) throw std::invalid_argument("ImageQualityOptions: " + why);
  if (est.rows() != ref.rows() || est.cols() != ref.cols())
    throw std::invalid_argument("compare_images: estimate and reference differ in size");
  check_mask(mask, ref.rows(), ref.cols(), "compare_images");
  const int H = static_cast<int>(ref.rows()), W = static_cast<int>(ref.cols());
  // Usable pixels, the affine fit and the peak.
  cv::Mat m(H, W, CV_64F), x(H, W, CV_64F), y(H, W, CV_64F);
  int64_t n = 0;
  double sx = 0, sy = 0, rmin = std::numeric_limits<double>::infinity(), rmax = -rmin;
  for (int j = 0; j < H; ++j)
    for (int i = 0; i < W; ++i) {
      const bool ok = std::isfinite(est(j, i)) && std::isfinite(ref(j, i)) && (!mask || (*mask)(j, i) != 0);
      m.at<double>(j, i) = ok ? 1.0 : 0.0;
      x.at<double>(j, i) = ok ? est(j, i) : 0.0;
      y.at<double>(j, i) = ok ? ref(j, i) : 0.0;
      if (!ok) continue;
      ++n;
      sx += est(j, i);
      sy += ref(j, i);
      rmin = std::min(rmin, static_cast<double>(ref(j, i)));
      rmax = std::max(rmax, static_cast<double>(ref(j, i)));
    }
  if (n < 2) throw std::invalid_argument("compare_images: fewer than 2 usable pixels in the mask");
  const double mx = sx / n, my = sy / n;
  double sxx = 0, sxy = 0;
  for (int j = 0; j < H; ++j)
    for (int i = 0; i < W; ++i) {
      if (m.at<double>(j, i) == 0.0) continue;
      const double dx = x.at<double>(j, i) - mx, dy = y.at<double>(j, i) - my;
      sxx += dx * dx;
      sxy += dx * dy;
    }
  ImageQuality q;
  q.pixels = n;
  if (o.fit_scale) {
    if (!(sxx > 0.0)) throw std::invalid_argument("compare_images: constant estimate, the scale fit is undefined");
    q.scale = sxy / sxx;
  }
  q.offset = my - q.scale * mx;
  q.peak = o.peak > 0.0 ? o.peak : rmax - rmin;
  if (!(q.peak > 0.0)) throw std::invalid_argument("compare_images: constant reference and no peak given");
  double se = 0;
  for (int j = 0; j < H; ++j)
    for (int i = 0; i < W; ++i) {
      if (m.at<double>(j, i) == 0.0) continue;
      double& xv = x.at<double>(j, i);
      xv = q.scale * xv + q.offset;  // fitted estimate, used by SSIM below
      const double d = xv - y.at<double>(j, i);
      se += d * d;
    }
  const double mse = se / n;
  q.rmse = std::sqrt(mse);
  q.psnr_db = mse > 0.0 ? 10.0 * std::log10(q.peak * q.peak / mse) : std::numeric_limits<double>::infinity();

  // SSIM with mask-normalised Gaussian statistics.
  const int half = static_cast<int>(std::ceil(3.0 * o.ssim_sigma));
  const cv::Size ks(2 * half + 1, 2 * half + 1);
  auto blur = [&](const cv::Mat& a) {
    cv::Mat b;
    cv::GaussianBlur(a, b, ks, o.ssim_sigma, o.ssim_sigma, cv::BORDER_CONSTANT);
    return b;
  };
  const cv::Mat wsum = blur(m);
  const cv::Mat bx = blur(x), by = blur(y), bxx = blur(x.mul(x)), byy = blur(y.mul(y)), bxy = blur(x.mul(y));
  const double c1 = (0.01 * q.peak) * (0.01 * q.peak), c2 = (0.03 * q.peak) * (0.03 * q.peak);
  double ssum = 0;
  for (int j = 0; j < H; ++j)
    for (int i = 0; i < W; ++i) {
      if (m.at<double>(j, i) == 0.0) continue;
      const double w = wsum.at<double>(j, i);
      const double ux = bx.at<double>(j, i) / w, uy = by.at<double>(j, i) / w;
      const double vx = std::max(bxx.at<double>(j, i) / w - ux * ux, 0.0);
      const double vy = std::max(byy.at<double>(j, i) / w - uy * uy, 0.0);
      const double cxy = bxy.at<double>(j, i) / w - ux * uy;
      ssum += ((2 * ux * uy + c1) * (2 * cxy + c2)) / ((ux * ux + uy * uy + c1) * (vx + vy + c2));
    }
  q.ssim = ssum / n;
  return q;
}

}  // namespace evio::mapping
