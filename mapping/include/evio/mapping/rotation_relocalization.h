// Global re-localisation of a rotating camera against an equirectangular log-intensity mosaic
// (calib/equirectangular.h), for a rotational tracker that has lost the map (Kim et al.'s particle
// filter only searches near its estimate). Input: the bearings of a short window of events, each
// already moved to one reference time (e.g. with the window's contrast-maximisation angular
// velocity: the bearings of a sharp image of warped events), and the mosaic. Events fire at
// edges, so the score of a camera rotation R_w_c is the mean gradient magnitude of the mosaic
// (blurred, 0 where unknown) at the events' directions R_w_c b. The search is exhaustive and
// coarse to fine: optical-axis directions on a grid over the known part of the mosaic times roll
// angles over a full turn, scored with a subsample of the events on a more blurred map, then the
// best candidates refined by a pattern search on the rotation vector with more events.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>

namespace evio::mapping {

struct RotationRelocalizationOptions {
  // Optical-axis candidates: a grid of about this spacing on the sphere, kept where the mosaic is
  // known at the grid point, deg.
  double axis_spacing_deg = 3.0;
  // Roll candidates about each axis over a full turn, deg.
  double roll_step_deg = 10.0;
  // Events scored in the coarse search and in the refinement (evenly subsampled), count.
  int coarse_bearings = 300;
  int fine_bearings = 3000;
  // Gradient-magnitude blur of the coarse search and of the refinement, mosaic texels.
  double coarse_blur_texels = 3.0;
  double fine_blur_texels = 1.0;
  // Best coarse candidates (more than max(axis spacing, roll step) apart) refined, count.
  int refine_candidates = 8;
  // Pattern search on the rotation vector: first and last step, deg (last <= first).
  double refine_initial_step_deg = 2.0;
  double refine_final_step_deg = 0.05;
  bool Validate(std::string* why) const;
};

struct RotationRelocalizationResult {
  bool valid = false;          // false without bearings or without a known texel
  Eigen::Matrix3d R_w_c = Eigen::Matrix3d::Identity();  // best rotation, camera -> mosaic frame
  double score = 0;            // its mean gradient magnitude (fine map), log units / texel
  // The best refined candidate more than 5 deg from R_w_c (0 if none): a score close to `score`
  // means the view is ambiguous.
  double runner_up_score = 0;
  int coarse_candidates = 0;   // rotations scored in the coarse search
};

// The gradient-magnitude score maps of a mosaic (width x height row-major log intensities, NaN =
// unknown), built once and reused for several searches or scores.
class RelocalizationMap {
 public:
  RelocalizationMap(const float* log_intensity, int width, int height, const RotationRelocalizationOptions& options);
  // Mean fine-map score of the bearings (camera frame) under R_w_c.
  double score(const Eigen::Matrix3d& R_w_c, const std::vector<Eigen::Vector3f>& bearings) const;
  // The exhaustive search (see the file comment).
  RotationRelocalizationResult search(const std::vector<Eigen::Vector3f>& bearings) const;

 private:
  double score_on(const std::vector<float>& map, const Eigen::Matrix3d& R_w_c, const std::vector<Eigen::Vector3f>& b) const;
  RotationRelocalizationOptions options_;
  int width_, height_;
  std::vector<float> coarse_, fine_;  // blurred gradient magnitude, 0 where unknown
  std::vector<unsigned char> known_;
};

}  // namespace evio::mapping
