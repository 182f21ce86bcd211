#include "evio/backend/marginalization.h"

#include <algorithm>
#include <stdexcept>
#include <unordered_map>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include "evio/backend/pose_manifold.h"
#include "evio/calib/geometry.h"

namespace evio::backend {

LinearPrior::LinearPrior(std::vector<PriorBlock> blocks, Eigen::MatrixXd J, Eigen::VectorXd r0)
    : blocks_(std::move(blocks)), J_(std::move(J)), r0_(std::move(r0)) {
  int cols = 0;
  for (const PriorBlock& b : blocks_) {
    if (b.parameters == nullptr || static_cast<int>(b.x0.size()) != b.size || (b.is_pose && b.size != 7) || b.size <= 0) {
      throw std::invalid_argument("linear prior: a block has an inconsistent size");
    }
    cols += b.tangent_size();
    mutable_parameter_block_sizes()->push_back(b.size);
  }
  if (J_.cols() != cols || J_.rows() != r0_.size() || J_.rows() == 0) {
    throw std::invalid_argument("linear prior: J is " + std::to_string(J_.rows()) + "x" + std::to_string(J_.cols()) +
                                ", expected " + std::to_string(r0_.size()) + "x" + std::to_string(cols));
  }
  set_num_residuals(static_cast<int>(J_.rows()));
}

bool LinearPrior::Evaluate(double const* const* parameters, double* residuals, double** jacobians) const {
  const int n = static_cast<int>(J_.cols());
  Eigen::VectorXd dx(n);
  std::vector<Eigen::Matrix3d> jr_inv(blocks_.size());
  int col = 0;
  for (size_t i = 0; i < blocks_.size(); ++i) {
    const PriorBlock& b = blocks_[i];
    const double* x = parameters[i];
    if (b.is_pose) {
      const Eigen::Map<const Eigen::Quaterniond> q(x), q0(b.x0.data());
      const Eigen::Vector3d phi = calib::so3_log((q0.conjugate() * q).normalized());
      dx.segment<3>(col) = phi;
      dx.segment<3>(col + 3) = Eigen::Map<const Eigen::Vector3d>(x + 4) - Eigen::Map<const Eigen::Vector3d>(b.x0.data() + 4);
      jr_inv[i] = calib::so3_right_jacobian_inv(phi);
    } else {
      for (int k = 0; k < b.size; ++k) dx(col + k) = x[k] - b.x0[static_cast<size_t>(k)];
    }
    col += b.tangent_size();
  }
  Eigen::Map<Eigen::VectorXd>(residuals, J_.rows()) = r0_ + J_ * dx;
  if (jacobians == nullptr) return true;
  col = 0;
  for (size_t i = 0; i < blocks_.size(); ++i) {
    const PriorBlock& b = blocks_[i];
    if (jacobians[i] != nullptr) {
      Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> out(jacobians[i], J_.rows(), b.size);
      if (b.is_pose) {
        Eigen::MatrixXd Jt = J_.middleCols(col, 6);
        Jt.leftCols(3) = Jt.leftCols(3) * jr_inv[i];  // d Log(q0^-1 q Exp(d)) / dd = Jr^-1
        out = Jt * PoseManifold::minus_jacobian(parameters[i]);
      } else {
        out = J_.middleCols(col, b.size);
      }
    }
    col += b.tangent_size();
  }
  return true;
}

std::unique_ptr<LinearPrior> LinearPrior::anchor(std::vector<PriorBlock> blocks, const std::vector<Eigen::MatrixXd>& sqrt_info) {
  if (sqrt_info.size() != blocks.size()) throw std::invalid_argument("linear prior anchor: one sqrt_info per block");
  int n = 0;
  for (const PriorBlock& b : blocks) n += b.tangent_size();
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(n, n);
  int col = 0;
  for (size_t i = 0; i < blocks.size(); ++i) {
    const int t = blocks[i].tangent_size();
    if (sqrt_info[i].rows() != t || sqrt_info[i].cols() != t) throw std::invalid_argument("linear prior anchor: sqrt_info size");
    J.block(col, col, t, t) = sqrt_info[i];
    col += t;
  }
  return std::make_unique<LinearPrior>(std::move(blocks), std::move(J), Eigen::VectorXd::Zero(n));
}

std::unique_ptr<LinearPrior> marginalize(ceres::Problem* problem, const std::vector<ceres::ResidualBlockId>& residual_blocks,
                                         const std::vector<const double*>& removed,
                                         const std::function<bool(const double*)>& is_pose, MarginalizationStats* stats,
                                         double eps) {
  // Column layout: removed blocks first, then kept blocks in first-seen order.
  struct Col {
    int offset = 0;
    int tangent = 0;
    int size = 0;
  };
  std::unordered_map<const double*, Col> cols;
  std::vector<const double*> kept;
  int m = 0;
  for (const double* p : removed) {
    const int size = problem->ParameterBlockSize(p);
    const int t = problem->ParameterBlockTangentSize(p);
    cols[p] = {m, t, size};
    m += t;
  }
  int n = m;
  int rows = 0;
  for (ceres::ResidualBlockId id : residual_blocks) {
    std::vector<double*> params;
    problem->GetParameterBlocksForResidualBlock(id, &params);
    for (double* p : params) {
      if (cols.count(p)) continue;
      const int size = problem->ParameterBlockSize(p);
      const int t = problem->ParameterBlockTangentSize(p);
      cols[p] = {n, t, size};
      n += t;
      kept.push_back(p);
    }
    rows += problem->GetCostFunctionForResidualBlock(id)->num_residuals();
  }
  if (kept.empty()) return nullptr;
  // Stacked Jacobian and residual.
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(rows, n);
  Eigen::VectorXd r = Eigen::VectorXd::Zero(rows);
  int row = 0;
  for (ceres::ResidualBlockId id : residual_blocks) {
    std::vector<double*> params;
    problem->GetParameterBlocksForResidualBlock(id, &params);
    const int nr = problem->GetCostFunctionForResidualBlock(id)->num_residuals();
    std::vector<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> jac(params.size());
    std::vector<double*> jp(params.size());
    for (size_t i = 0; i < params.size(); ++i) {
      jac[i].resize(nr, cols[params[i]].tangent);
      jp[i] = jac[i].data();
    }
    double cost = 0;
    Eigen::VectorXd res(nr);
    if (!problem->EvaluateResidualBlock(id, true, &cost, res.data(), jp.data())) {
      throw std::runtime_error("marginalisation: a residual block failed to evaluate");
    }
    r.segment(row, nr) = res;
    for (size_t i = 0; i < params.size(); ++i) J.block(row, cols[params[i]].offset, nr, cols[params[i]].tangent) += jac[i];
    row += nr;
  }
  const Eigen::MatrixXd H = J.transpose() * J;
  const Eigen::VectorXd g = J.transpose() * r;
  const int k = n - m;
  Eigen::MatrixXd Hs = H.bottomRightCorner(k, k);
  Eigen::VectorXd gs = g.tail(k);
  if (m > 0) {
    // Pseudo-inverse of H_mm by eigen-decomposition (unobserved directions contribute nothing).
    const Eigen::MatrixXd Hmm = 0.5 * (H.topLeftCorner(m, m) + H.topLeftCorner(m, m).transpose());
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(Hmm);
    const double tol = eps * std::max(1.0, es.eigenvalues().cwiseAbs().maxCoeff());
    Eigen::VectorXd inv = es.eigenvalues();
    for (int i = 0; i < m; ++i) inv(i) = inv(i) > tol ? 1.0 / inv(i) : 0.0;
    const Eigen::MatrixXd Hmm_inv = es.eigenvectors() * inv.asDiagonal() * es.eigenvectors().transpose();
    const Eigen::MatrixXd Hkm = H.bottomLeftCorner(k, m);
    Hs -= Hkm * Hmm_inv * Hkm.transpose();
    gs -= Hkm * Hmm_inv * g.head(m);
  }
  Hs = 0.5 * (Hs + Hs.transpose());
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(Hs);
  const double tol = eps * std::max(1.0, es.eigenvalues().cwiseAbs().maxCoeff());
  Eigen::VectorXd s = es.eigenvalues(), s_inv = es.eigenvalues();
  int rank = 0;
  for (int i = 0; i < k; ++i) {
    if (s(i) > tol) {
      s(i) = std::sqrt(s(i));
      s_inv(i) = 1.0 / s(i);
      ++rank;
    } else {
      s(i) = s_inv(i) = 0.0;
    }
  }
  const Eigen::MatrixXd Jstar = s.asDiagonal() * es.eigenvectors().transpose();
  const Eigen::VectorXd rstar = s_inv.asDiagonal() * es.eigenvectors().transpose() * gs;
  std::vector<PriorBlock> blocks;
  for (const double* p : kept) {
    PriorBlock b;
    b.parameters = p;
    b.size = cols[p].size;
    b.is_pose = is_pose(p);
    b.x0.assign(p, p + b.size);
    blocks.push_back(std::move(b));
  }
  if (stats) {
    stats->removed_dims = m;
    stats->kept_dims = k;
    stats->residual_blocks = static_cast<int>(residual_blocks.size());
    stats->rank = rank;
  }
  return std::make_unique<LinearPrior>(std::move(blocks), Jstar, rstar);
}

}  // namespace evio::backend
