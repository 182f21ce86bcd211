// Two-view motion-model selection by Torr's Geometric Robust Information Criterion (GRIC; Torr,
// "Geometric motion segmentation and model selection", Phil. Trans. R. Soc. A 1998; Torr, Fitzgibbon
// and Zisserman, "The problem of degeneracy in structure and motion recovery from uncalibrated
// image sequences", IJCV 1999) on the bearings two keyframes share, for a calibrated camera:
//   S  no motion            pi(b1) = pi(b0)                      d = 2, k = 0
//   R  pure rotation        pi(b1) = pi(R b0)  (homography at infinity)   d = 2, k = 3
//   G  general motion       x1^T [t]x R x0 = 0 (essential matrix)         d = 3, k = 5
// with b0, b1 unit-free bearings in the two camera frames (z > 0), x = b / b.z, R = R_c1_c0 and t
// the direction of the camera translation. For each model
//   GRIC = sum_i min(e_i^2 / sigma^2, lambda3 (r - d)) + lambda1 d n + lambda2 k,
//   r = 4 (dimension of a correspondence), lambda1 = log r, lambda2 = log(r n), lambda3 = 2,
// where e_i is the (first-order) distance of the correspondence (x0, x1) from the model's variety
// in the 4-D joint image space, in pixels (both images noisy with sigma per coordinate):
//   S, R: e^2 = f^2 |pi(R b0) - pi(b1)|^2 / 2;   G: the Sampson distance, f^2 (x1^T E x0)^2 /
//   (|(E x0)_{1,2}|^2 + |(E^T x1)_{1,2}|^2).
// The lowest GRIC is the most likely model for its complexity; the capped term makes it robust.
//
// IMU evidence (optional): S and R say that the camera centre does not move between the keyframes,
// so IMU-derived quantities of dimension imu_dof (the caller's: the change of the camera centre's
// velocity, and its predicted displacement when the velocity is observable) are zero up to their
// covariance. Their Mahalanobis square imu_chi2 is added to GRIC_S and GRIC_R as their residual on
// that datum, while G explains it with imu_dof free parameters, penalised as in AIC (2 per
// parameter: a single datum, so GRIC's log(r n) does not apply): GRIC_G += 2 imu_dof.
#pragma once

#include <vector>

#include <Eigen/Core>

namespace evio::backend {

enum class TwoViewModel { kNone, kStatic, kRotation, kGeneral };
const char* two_view_model_name(TwoViewModel m);  // "none", "static", "rotation", "general"

struct TwoViewGric {
  int n = 0;                     // correspondences used
  double gric_static = 0;        // GRIC of S (including the IMU term), dimensionless (-2 log likelihood units)
  double gric_rotation = 0;      // GRIC of R
  double gric_general = 0;       // GRIC of G
  double imu_chi2 = 0;           // chi2 of the static-centre hypothesis on the IMU (0 when not used)
  int imu_dof = 0;               // its degrees of freedom (0: IMU not used)
  TwoViewModel best = TwoViewModel::kNone;  // lowest GRIC; kNone when n < 6
  // Lowest GRIC of the bearings alone (without the IMU terms): what the images say, whatever the
  // velocity estimate (a rotation-dominant motion whose few cm of translation the IMU sees).
  TwoViewModel image_best = TwoViewModel::kNone;
  Eigen::Matrix3d R_c1_c0 = Eigen::Matrix3d::Identity();  // model R's rotation (c0 bearings into c1)
  Eigen::Vector3d t_c1 = Eigen::Vector3d::Zero();          // model G's unit translation direction (c1)
};

// GRIC of S, R and G on the correspondences (b0[i], b1[i]) (bearings with z > 0 in the two cameras).
// R_prior: a prediction of R_c1_c0 (e.g. from the gyro), t_prior: of the translation direction (may
// be zero); both start the fits beside the closed-form ones (Kabsch on the bearings for R, the
// linear epipolar constraint given R for t), which are then refined by Gauss-Newton on the inliers
// of the capped cost. focal_px converts to pixels, sigma_px: observation noise per coordinate, px.
// imu_chi2 >= 0 with imu_dof > 0 degrees of freedom is added as described above (imu_dof = 0: no IMU).
TwoViewGric two_view_gric(const std::vector<Eigen::Vector3d>& b0, const std::vector<Eigen::Vector3d>& b1,
                          const Eigen::Matrix3d& R_prior, const Eigen::Vector3d& t_prior, double focal_px, double sigma_px,
                          int imu_dof = 0, double imu_chi2 = 0);

// Upper quantile of the chi-square distribution: x with P(chi2_dof > x) = p, for dof >= 1 and p in
// (0, 1) (bisection on the regularised lower incomplete gamma function, relative accuracy 1e-10).
// Throws std::invalid_argument otherwise.
double chi2_upper_quantile(int dof, double p);

}  // namespace evio::backend
