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

namespace {

// Pseudo-inverse of a symmetric positive semi-definite matrix by eigen-decomposition: eigenvalues
// below eps * max(1, |largest|) count as zero (unobserved directions contribute nothing).
Eigen::MatrixXd psd_pseudo_inverse(const Eigen::MatrixXd& A, double eps) {
  const Eigen::MatrixXd S = 0.5 * (A + A.transpose());
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(S);
  const double tol = eps * std::max(1.0, es.eigenvalues().cwiseAbs().maxCoeff());
  Eigen::VectorXd inv = es.eigenvalues();
  for (int i = 0; i < inv.size(); ++i) inv(i) = inv(i) > tol ? 1.0 / inv(i) : 0.0;
  return es.eigenvectors() * inv.asDiagonal() * es.eigenvectors().transpose();
}

}  // namespace

std::unique_ptr<LinearPrior> marginalize(ceres::Problem* problem, const std::vector<ceres::ResidualBlockId>& residual_blocks,
                                         const std::vector<const double*>& removed,
                                         const std::function<bool(const double*)>& is_pose, MarginalizationStats* stats,
                                         double eps) {
  // Every parameter block the residuals touch, and per residual the blocks it touches.
  struct Block {
    const double* p = nullptr;
    int tangent = 0;
    int size = 0;
    bool removed = false;
    bool first_stage = false;  // removed and eliminated on its own (see below)
    int offset = -1;           // column in the reduced system [second-stage removed | kept]
  };
  std::vector<Block> blocks;
  std::unordered_map<const double*, int> index;
  auto block_of = [&](const double* p, bool is_removed) {
    const auto it = index.find(p);
    if (it != index.end()) return it->second;
    Block b;
    b.p = p;
    b.size = problem->ParameterBlockSize(p);
    b.tangent = problem->ParameterBlockTangentSize(p);
    b.removed = is_removed;
    blocks.push_back(b);
    index.emplace(p, static_cast<int>(blocks.size()) - 1);
    return static_cast<int>(blocks.size()) - 1;
  };
  for (const double* p : removed) block_of(p, true);
  const size_t n_removed = blocks.size();
  std::vector<std::vector<int>> touches(residual_blocks.size());
  std::vector<const double*> kept;
  for (size_t r = 0; r < residual_blocks.size(); ++r) {
    std::vector<double*> params;
    problem->GetParameterBlocksForResidualBlock(residual_blocks[r], &params);
    for (double* p : params) {
      const size_t before = blocks.size();
      touches[r].push_back(block_of(p, false));
      if (blocks.size() > before) kept.push_back(p);
    }
  }
  if (kept.empty()) return nullptr;

  // Two-stage elimination. Removed blocks that share no residual with another removed block of the
  // first stage (typically the landmarks of finished tracks, coupled only to poses) form the first
  // stage: H_mm is block diagonal over them, so each is eliminated on its own with the
  // pseudo-inverse of its diagonal block. The remaining removed blocks (the oldest keyframe's pose)
  // are eliminated from the reduced system next. With an invertible H_mm this is the same Schur
  // complement as one pseudo-inverse of the whole H_mm, at a fraction of the cost.
  {
    std::vector<size_t> order(n_removed);
    for (size_t i = 0; i < n_removed; ++i) order[i] = i;
    std::stable_sort(order.begin(), order.end(), [&](size_t a, size_t b) { return blocks[a].tangent < blocks[b].tangent; });
    std::vector<std::vector<int>> removed_neighbours(n_removed);
    for (const auto& t : touches)
      for (int a : t)
        for (int b : t)
          if (a != b && blocks[static_cast<size_t>(a)].removed && blocks[static_cast<size_t>(b)].removed)
            removed_neighbours[static_cast<size_t>(a)].push_back(b);
    for (size_t i : order) {
      bool free = true;
      for (int nb : removed_neighbours[i]) free = free && !blocks[static_cast<size_t>(nb)].first_stage;
      blocks[i].first_stage = free;
    }
  }
  int m = 0, m2 = 0, n = 0;  // removed dims, second-stage removed dims, reduced system dims
  for (Block& b : blocks) {
    if (b.removed) m += b.tangent;
    if (b.removed && !b.first_stage) {
      b.offset = n;
      n += b.tangent;
      m2 += b.tangent;
    }
  }
  for (Block& b : blocks) {
    if (!b.removed) {
      b.offset = n;
      n += b.tangent;
    }
  }
  const int k = n - m2;

  // H = J^T J and g = J^T r, accumulated per residual block: the reduced system over
  // [second-stage removed | kept], and per first-stage block its diagonal block, gradient and
  // couplings to the reduced blocks.
  struct FirstStage {
    Eigen::MatrixXd D;
    Eigen::VectorXd g;
    std::vector<std::pair<int, Eigen::MatrixXd>> couple;  // (block, t_first x t_block)
  };
  std::vector<FirstStage> first(blocks.size());  // used at the first-stage blocks
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(n, n);
  Eigen::VectorXd g = Eigen::VectorXd::Zero(n);
  using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  std::vector<RowMajor> jac;
  std::vector<double*> jp;
  Eigen::VectorXd res;
  for (size_t r = 0; r < residual_blocks.size(); ++r) {
    const ceres::ResidualBlockId id = residual_blocks[r];
    const std::vector<int>& t = touches[r];
    const int nr = problem->GetCostFunctionForResidualBlock(id)->num_residuals();
    jac.resize(t.size());
    jp.resize(t.size());
    for (size_t i = 0; i < t.size(); ++i) {
      jac[i].resize(nr, blocks[static_cast<size_t>(t[i])].tangent);
      jp[i] = jac[i].data();
    }
    res.resize(nr);
    double cost = 0;
    if (!problem->EvaluateResidualBlock(id, true, &cost, res.data(), jp.data())) {
      throw std::runtime_error("marginalisation: a residual block failed to evaluate");
    }
    for (size_t i = 0; i < t.size(); ++i) {
      const Block& bi = blocks[static_cast<size_t>(t[i])];
      if (bi.first_stage) {
        FirstStage& f = first[t[i]];
        if (f.D.size() == 0) {
          f.D = Eigen::MatrixXd::Zero(bi.tangent, bi.tangent);
          f.g = Eigen::VectorXd::Zero(bi.tangent);
        }
        f.g += jac[i].transpose() * res;
        for (size_t j = 0; j < t.size(); ++j) {
          const Block& bj = blocks[static_cast<size_t>(t[j])];
          if (j == i) {
            f.D += jac[i].transpose() * jac[i];
          } else if (!bj.first_stage) {
            auto c = std::find_if(f.couple.begin(), f.couple.end(), [&](const auto& e) { return e.first == t[j]; });
            if (c == f.couple.end()) {
              f.couple.emplace_back(t[j], Eigen::MatrixXd::Zero(bi.tangent, bj.tangent));
              c = f.couple.end() - 1;
            }
            c->second += jac[i].transpose() * jac[j];
          }
        }
        continue;
      }
      g.segment(bi.offset, bi.tangent) += jac[i].transpose() * res;
      for (size_t j = 0; j < t.size(); ++j) {
        const Block& bj = blocks[static_cast<size_t>(t[j])];
        if (bj.first_stage) continue;
        H.block(bi.offset, bj.offset, bi.tangent, bj.tangent) += jac[i].transpose() * jac[j];
      }
    }
  }
  // First stage: H -= C^T D^+ C, g -= C^T D^+ g_b over the blocks each one couples to.
  for (const FirstStage& f : first) {
    if (f.D.size() == 0) continue;
    const Eigen::MatrixXd Dinv = psd_pseudo_inverse(f.D, eps);
    for (const auto& [j, Cj] : f.couple) {
      const Block& bj = blocks[static_cast<size_t>(j)];
      const Eigen::MatrixXd CjT_Dinv = Cj.transpose() * Dinv;
      g.segment(bj.offset, bj.tangent) -= CjT_Dinv * f.g;
      for (const auto& [l, Cl] : f.couple) {
        const Block& bl = blocks[static_cast<size_t>(l)];
        H.block(bj.offset, bl.offset, bj.tangent, bl.tangent) -= CjT_Dinv * Cl;
      }
    }
  }
  // Second stage.
  Eigen::MatrixXd Hs = H.bottomRightCorner(k, k);
  Eigen::VectorXd gs = g.tail(k);
  if (m2 > 0) {
    const Eigen::MatrixXd Hmm_inv = psd_pseudo_inverse(H.topLeftCorner(m2, m2), eps);
    const Eigen::MatrixXd Hkm = H.bottomLeftCorner(k, m2);
    Hs -= Hkm * Hmm_inv * Hkm.transpose();
    gs -= Hkm * Hmm_inv * g.head(m2);
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
  std::vector<PriorBlock> prior_blocks;
  for (const double* p : kept) {
    PriorBlock b;
    b.parameters = p;
    b.size = blocks[static_cast<size_t>(index.at(p))].size;
    b.is_pose = is_pose(p);
    b.x0.assign(p, p + b.size);
    prior_blocks.push_back(std::move(b));
  }
  if (stats) {
    stats->removed_dims = m;
    stats->kept_dims = k;
    stats->residual_blocks = static_cast<int>(residual_blocks.size());
    stats->rank = rank;
  }
  return std::make_unique<LinearPrior>(std::move(prior_blocks), Jstar, rstar);
}

}  // namespace evio::backend
