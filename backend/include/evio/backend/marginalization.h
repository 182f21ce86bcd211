// Marginalisation into a linear prior (the Schur complement of the Gauss-Newton system, as in
// OKVIS / VINS-Mono): the residual blocks connected to the variables being removed are linearised
// at the current estimate, H = J^T J and g = J^T r are formed (block by block) over [removed | kept]
// tangent coordinates, the removed part is eliminated (H* = H_kk - H_km H_mm^+ H_mk, g* likewise), and
// H*, g* are factored back into a residual r(x) = r* + J* dx with J*^T J* = H*, J*^T r* = g*.
// dx is the tangent difference of each kept block from its value at marginalisation time:
// poses Minus(x, x0) (PoseManifold), Euclidean blocks x - x0.
#pragma once

#include <functional>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "ceres/cost_function.h"
#include "ceres/problem.h"

namespace evio::backend {

// A parameter block of a prior: 7-double pose (PoseManifold) or Euclidean of `size` doubles.
struct PriorBlock {
  const double* parameters = nullptr;  // the live block (the prior's cost is added on it)
  int size = 0;                        // ambient size (7 for poses)
  bool is_pose = false;
  std::vector<double> x0;              // linearisation point (ambient)
  int tangent_size() const { return is_pose ? 6 : size; }
};

// Residual r(x) = r0 + J dx(x) over the blocks in order; Jacobians exact in dx (for poses the
// rotation part uses the inverse right Jacobian of Log(q0^-1 q)), lifted to ambient pose columns
// with PoseManifold::minus_jacobian.
class LinearPrior final : public ceres::CostFunction {
 public:
  // J: m x sum(tangent sizes), r0: m. Throws std::invalid_argument on size mismatches.
  LinearPrior(std::vector<PriorBlock> blocks, Eigen::MatrixXd J, Eigen::VectorXd r0);
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override;
  const std::vector<PriorBlock>& blocks() const { return blocks_; }
  const Eigen::MatrixXd& jacobian() const { return J_; }
  const Eigen::VectorXd& residual0() const { return r0_; }

  // A prior pinning blocks to values with the given square-root information per block (each
  // sqrt_info tangent x tangent): r = S (x [-] x0).
  static std::unique_ptr<LinearPrior> anchor(std::vector<PriorBlock> blocks, const std::vector<Eigen::MatrixXd>& sqrt_info);

 private:
  std::vector<PriorBlock> blocks_;
  Eigen::MatrixXd J_;
  Eigen::VectorXd r0_;
};

struct MarginalizationStats {
  int removed_dims = 0;
  int kept_dims = 0;
  int residual_blocks = 0;
  int rank = 0;  // rank of the prior (H* eigenvalues above the threshold)
};

// Linearises `residual_blocks` (all must be in `problem`, with loss functions applied) at the
// current parameter values, eliminates the blocks in `removed` and returns the prior on every
// other block those residuals touch (kept blocks in first-seen order; `is_pose(block)` says which
// blocks are 7-double poses). Removed blocks that share no residual with each other (landmarks
// of finished tracks) are eliminated first, each with the pseudo-inverse of its own diagonal block,
// then the other removed blocks from the reduced system (the same Schur complement as one
// pseudo-inverse of H_mm when H_mm is invertible). Eigenvalues below eps * max of the matrix being
// inverted (each such block, the rest of H_mm, H*) are treated as zero.
// Returns null when no kept block remains.
std::unique_ptr<LinearPrior> marginalize(ceres::Problem* problem,
                                         const std::vector<ceres::ResidualBlockId>& residual_blocks,
                                         const std::vector<const double*>& removed,
                                         const std::function<bool(const double*)>& is_pose,
                                         MarginalizationStats* stats = nullptr, double eps = 1e-10);

}  // namespace evio::backend
