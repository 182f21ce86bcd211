// Output and quality of reconstructed log-intensity images (the mosaic from gradient_mosaic.h or
// any other): display mapping to 8/16-bit PNG, raw float TIFF, and PSNR / SSIM (Wang et al., IEEE
// TIP 2004) against a reference after a global affine intensity fit.
//
// File formats: PNG 8 and 16 bit (display-mapped) and 32-bit float TIFF (raw log intensity, unseen
// pixels NaN). OpenEXR is not offered: Debian 12's OpenCV 4.6 has it compiled in but refuses to
// use it unless the process sets OPENCV_IO_ENABLE_OPENEXR, which a library must not do.
#pragma once

#include <cstdint>
#include <string>

#include <Eigen/Core>

#include "evio/mapping/image.h"

namespace evio::mapping {

// Display mapping of a log-intensity image L: x = L (or exp(L - max) with linear_intensity) is
// mapped affinely so that the low/high percentiles of x over the seen, finite pixels become 0 and
// 1, clipped to [0, 1], then t -> t^(1/gamma). Unseen or non-finite pixels become 0 (black).
// Percentiles use the nearest rank, index round(p / 100 * (n - 1)) of the sorted values. When the
// two percentiles coincide (a flat image) every seen pixel maps to 0.5.
struct LogImageDisplayOptions {
  double low_percentile = 1.0;    // %, mapped to black
  double high_percentile = 99.0;  // %, above low_percentile, mapped to white
  double gamma = 1.0;             // display gamma: value = t^(1/gamma); 2.2 for linear_intensity
  bool linear_intensity = false;  // map linear intensity exp(L) instead of log intensity
  // Local contrast equalisation after the global mapping (before gamma): contrast-limited adaptive
  // histogram equalisation (CLAHE, Zuiderveld 1994; OpenCV) over tiles of equalize_tile_px
  // (px, >= 8) with this clip limit (>= 0; 0 = off; 2-4 typical: the higher, the stronger). Unseen
  // pixels take the seen ones' median for it. Off by default: it sharpens texture a person looks
  // for and departs from the intensities (docs/results/mosaic.md measures both).
  double equalize_clip = 0.0;
  int equalize_tile_px = 64;
  // PNG writers: grey plus alpha (4 channels, R = G = B = the display value) with alpha 0 where a
  // pixel is unseen or non-finite and full alpha elsewhere, so unseen pixels stand apart from dark
  // seen ones in any viewer; false: one grey channel, unseen pixels black.
  bool transparent_unseen = false;
  bool Validate(std::string* why) const;
};

// Display values in [0, 1] (H x W). seen may be null (every finite pixel is seen). Throws
// std::invalid_argument for invalid options or a mask of another size.
ImageF log_image_to_display(const ImageF& log_intensity, const MaskU8* seen, const LogImageDisplayOptions& options = {});

// 8-bit PNG (round(255 t)) and 16-bit PNG (round(65535 t)) of the display mapping: grey, or
// grey + alpha with options.transparent_unseen (then BGRA as OpenCV writes it: RGBA in the file).
// Throw evio::InputError when the file cannot be written, std::invalid_argument as above.
void write_log_image_png8(const std::string& path, const ImageF& log_intensity, const MaskU8* seen,
                          const LogImageDisplayOptions& options = {});
void write_log_image_png16(const std::string& path, const ImageF& log_intensity, const MaskU8* seen,
                           const LogImageDisplayOptions& options = {});
// 8-bit grey PNG of a mask: 255 where the mask is non-zero, 0 elsewhere (e.g. the mosaic's
// seen coverage). Throws evio::InputError when the file cannot be written.
void write_mask_png(const std::string& path, const MaskU8& mask);
// 32-bit float single-channel TIFF of the log intensity itself, NaN where seen is 0.
void write_log_image_tiff(const std::string& path, const ImageF& log_intensity, const MaskU8* seen);

// Quality of an estimate against a reference over a mask, after the least-squares affine fit
// y ~ a x + b of the estimate x onto the reference y over the mask (a = 1 when !fit_scale). Meant
// for log intensities on both sides: the mosaic knows log intensity up to an offset, and up to a
// scale when the contrast threshold C is uncertain; for linear intensities, pass those instead.
//   PSNR = 10 log10(peak^2 / MSE) dB, MSE over the mask after the fit (+inf when MSE is exactly 0);
//   SSIM: Gaussian window (ssim_sigma, truncated at 3 sigma), K1 = 0.01, K2 = 0.03, dynamic range
//   = peak; local statistics are mask-normalised (pixels outside the mask never enter a window),
//   and the SSIM map is averaged over the mask. peak = max - min of the reference over the mask
//   unless options.peak > 0.
struct ImageQualityOptions {
  bool fit_scale = true;    // fit a and b (true) or the offset b only (a = 1)
  double peak = 0.0;        // dynamic range for PSNR and SSIM, reference units; 0 = reference range
  double ssim_sigma = 1.5;  // px, Gaussian window std (> 0)
  bool Validate(std::string* why) const;
};

struct ImageQuality {
  double psnr_db = 0.0;
  double ssim = 0.0;
  double rmse = 0.0;    // reference units, after the fit
  double scale = 1.0;   // a
  double offset = 0.0;  // b
  double peak = 0.0;    // the dynamic range used
  int64_t pixels = 0;   // pixels in the mask (finite in both images)
};

// mask may be null (all pixels); pixels non-finite in either image are left out. Throws
// std::invalid_argument on size mismatches, invalid options, fewer than 2 usable pixels, or a
// constant estimate with fit_scale (the fit is undefined).
ImageQuality compare_images(const ImageF& estimate, const ImageF& reference, const MaskU8* mask,
                            const ImageQualityOptions& options = {});

}  // namespace evio::mapping
