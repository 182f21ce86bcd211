// Poisson reconstruction: spectral full solve (OpenCV DCT / DFT) and the separable-eigenbasis
// region solve. Conventions in poisson.h.
#include "evio/mapping/poisson.h"
#include "evio/mapping/option_tables.h"

#include <algorithm>
#include <map>
#include <memory>
#include <mutex>
#include <tuple>
#include <cmath>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include <Eigen/Eigenvalues>
#include <opencv2/core.hpp>

namespace evio::mapping {
namespace {

constexpr double kPi = 3.14159265358979323846;

template <typename T>
using Image = Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

void check_size(const char* what, Eigen::Index rows, Eigen::Index cols, int width, int height) {
  if (rows != height || cols != width)
    throw std::invalid_argument(std::string("Poisson solver: ") + what + " is " + std::to_string(rows) + "x" +
                                std::to_string(cols) + " (rows x cols), expected " + std::to_string(height) + "x" +
                                std::to_string(width));
}

// Backward-difference divergence of the (optionally weighted) gradient field, into div (H x W).
template <typename T>
void divergence_into(const Image<T>& gx, const Image<T>& gy, const Image<T>* weight, bool periodic, T* div) {
  const Eigen::Index H = gx.rows(), W = gx.cols();
  auto wgx = [&](Eigen::Index j, Eigen::Index i) -> T { return weight ? (*weight)(j, i) * gx(j, i) : gx(j, i); };
  auto wgy = [&](Eigen::Index j, Eigen::Index i) -> T { return weight ? (*weight)(j, i) * gy(j, i) : gy(j, i); };
  for (Eigen::Index j = 0; j < H; ++j) {
    T* out = div + j * W;
    for (Eigen::Index i = 0; i < W; ++i) {
      T d = 0;
      if (i < W - 1 || periodic) d += wgx(j, i);  // right edge
      if (i > 0) {
        d -= wgx(j, i - 1);  // left edge
      } else if (periodic) {
        d -= wgx(j, W - 1);
      }
      if (j < H - 1) d += wgy(j, i);
      if (j > 0) d -= wgy(j - 1, i);
      out[i] = d;
    }
  }
}

// The 1-D Laplacian along one axis of n_domain pixels, restricted to the len pixels start,
// start+1, ... (mod n_domain when periodic); pixels outside the restriction are Dirichlet data.
Eigen::MatrixXd axis_operator(int n_domain, bool periodic, int start, int len) {
  Eigen::MatrixXd T = Eigen::MatrixXd::Zero(len, len);
  auto index = [&](int p) -> int {
    int t = p - start;
    if (periodic) t = ((t % n_domain) + n_domain) % n_domain;
    return (t >= 0 && t < len) ? t : -1;
  };
  const int n_edges = periodic ? n_domain : n_domain - 1;
  for (int p = 0; p < n_edges; ++p) {
    const int a = index(p), b = index((p + 1) % n_domain);
    if (a >= 0) T(a, a) -= 1.0;
    if (b >= 0) T(b, b) -= 1.0;
    if (a >= 0 && b >= 0) {
      T(a, b) += 1.0;
      T(b, a) += 1.0;
    }
  }
  return T;
}

// Eigenbasis of a symmetric 1-D operator.
struct AxisBasis {
  Eigen::MatrixXd Q;   // eigenvectors (columns)
  Eigen::VectorXd lam;  // eigenvalues
};

AxisBasis axis_basis(const Eigen::MatrixXd& T) {
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> e(T);
  if (e.info() != Eigen::Success)
    throw std::runtime_error("Poisson solver: eigen-decomposition of the region Laplacian failed");
  return {e.eigenvectors(), e.eigenvalues()};
}

// Solves Ty X + X Tx = R (Ty: h x h, Tx: w x w, symmetric, negative semi-definite) in the
// separable eigenbasis; modes whose eigenvalue sum vanishes (the constant of a pure Neumann /
// periodic problem) are set to zero.
Eigen::MatrixXd separable_solve(const AxisBasis& by, const AxisBasis& bx, const Eigen::MatrixXd& R) {
  const Eigen::MatrixXd& Qy = by.Q;
  const Eigen::MatrixXd& Qx = bx.Q;
  Eigen::MatrixXd X = Qy.transpose() * R * Qx;
  const Eigen::VectorXd& ly = by.lam;
  const Eigen::VectorXd& lx = bx.lam;
  for (Eigen::Index l = 0; l < X.rows(); ++l) {
    for (Eigen::Index k = 0; k < X.cols(); ++k) {
      const double lam = ly(l) + lx(k);
      X(l, k) = std::abs(lam) < 1e-9 ? 0.0 : X(l, k) / lam;
    }
  }
  return Qy * X * Qx.transpose();
}

// Solves lap(L) = div (H x W, both even) with the (0,0) mode set to zero. div is overwritten.
template <typename T>
void spectral_inverse(cv::Mat& div, bool periodic, Image<T>* L) {
  const int H = div.rows, W = div.cols;
  constexpr int kType = std::is_same<T, float>::value ? CV_32F : CV_64F;

  // 1-D eigenvalues of the Laplacian along each axis.
  std::vector<double> lx(W), ly(H);
  for (int l = 0; l < H; ++l) {
    const double s = std::sin(kPi * l / (2.0 * H));
    ly[l] = -4.0 * s * s;
  }
  for (int c = 0; c < W; ++c) {
    double s;
    if (periodic) {
      const int k = (c + 1) / 2;  // OpenCV's CCS row packing: Re0, Re1, Im1, Re2, Im2, ...
      s = std::sin(kPi * k / W);
    } else {
      s = std::sin(kPi * c / (2.0 * W));
    }
    lx[c] = -4.0 * s * s;
  }

  L->resize(H, W);
  if (!periodic) {
    cv::Mat F;
    cv::dct(div, F);
    for (int l = 0; l < H; ++l) {
      T* row = F.ptr<T>(l);
      for (int k = 0; k < W; ++k) {
        const double lam = ly[l] + lx[k];
        row[k] = (l == 0 && k == 0) ? T(0) : static_cast<T>(row[k] / lam);
      }
    }
    cv::Mat out(H, W, kType, L->data());
    cv::idct(F, out);
    return;
  }
  // Periodic in u: real DFT of each row, then a DCT of each column of the packed spectrum (done
  // as rows of the transpose), divide, and back.
  cv::Mat F, Ft, Gt;
  cv::dft(div, F, cv::DFT_ROWS);
  cv::transpose(F, Ft);  // W x H: row c = packed coefficient c over all image rows
  cv::dct(Ft, Gt, cv::DCT_ROWS);
  for (int c = 0; c < W; ++c) {
    T* row = Gt.ptr<T>(c);
    for (int l = 0; l < H; ++l) {
      const double lam = ly[l] + lx[c];
      row[l] = (l == 0 && c == 0) ? T(0) : static_cast<T>(row[l] / lam);
    }
  }
  cv::idct(Gt, Ft, cv::DCT_ROWS);
  cv::transpose(Ft, F);
  cv::Mat out(H, W, kType, L->data());
  cv::dft(F, out, cv::DFT_ROWS | cv::DFT_INVERSE | cv::DFT_SCALE | cv::DFT_REAL_OUTPUT);
}

template <typename T>
void spectral_solve(const Image<T>& gx, const Image<T>& gy, const Image<T>* weight, bool periodic, Image<T>* L) {
  const int H = static_cast<int>(gx.rows()), W = static_cast<int>(gx.cols());
  constexpr int kType = std::is_same<T, float>::value ? CV_32F : CV_64F;
  cv::Mat div(H, W, kType);
  divergence_into<T>(gx, gy, weight, periodic, div.ptr<T>());
  spectral_inverse<T>(div, periodic, L);
}

// Solves lap(L) = div in the dense separable eigenbases (any size), constant mode zero.
template <typename T>
void dense_inverse(const Image<T>& div, bool periodic, Image<T>* L) {
  const int H = static_cast<int>(div.rows()), W = static_cast<int>(div.cols());
  const Eigen::MatrixXd X =
      separable_solve(axis_basis(axis_operator(H, false, 0, H)), axis_basis(axis_operator(W, periodic, 0, W)),
                      div.template cast<double>());
  *L = X.cast<T>();
}

template <typename T>
void dense_solve(const Image<T>& gx, const Image<T>& gy, const Image<T>* weight, bool periodic, Image<T>* L) {
  const int H = static_cast<int>(gx.rows()), W = static_cast<int>(gx.cols());
  Image<T> div(H, W);
  divergence_into<T>(gx, gy, weight, periodic, div.data());
  dense_inverse<T>(div, periodic, L);
}


template <typename T>
void full_solve(int width, int height, const PoissonOptions& o, const Image<T>& gx, const Image<T>& gy, Image<T>* L,
                const Image<T>* weight) {
  if (L == nullptr) throw std::invalid_argument("Poisson solver: null output");
  check_size("gx", gx.rows(), gx.cols(), width, height);
  check_size("gy", gy.rows(), gy.cols(), width, height);
  if (weight) check_size("weight", weight->rows(), weight->cols(), width, height);
  const bool periodic = o.boundary == PoissonBoundary::kPeriodicU;
  if (width % 2 == 0 && height % 2 == 0) {
    spectral_solve<T>(gx, gy, weight, periodic, L);
  } else {
    dense_solve<T>(gx, gy, weight, periodic, L);
  }
}

}  // namespace

bool PoissonOptions::Validate(std::string* why) const { return poisson_table().check(*this, why); }

void forward_gradient(const ImageD& L, PoissonBoundary boundary, ImageD* gx, ImageD* gy) {
  const Eigen::Index H = L.rows(), W = L.cols();
  const bool periodic = boundary == PoissonBoundary::kPeriodicU;
  gx->setZero(H, W);
  gy->setZero(H, W);
  for (Eigen::Index j = 0; j < H; ++j) {
    for (Eigen::Index i = 0; i < W; ++i) {
      if (i + 1 < W) {
        (*gx)(j, i) = L(j, i + 1) - L(j, i);
      } else if (periodic) {
        (*gx)(j, i) = L(j, 0) - L(j, i);
      }
      if (j + 1 < H) (*gy)(j, i) = L(j + 1, i) - L(j, i);
    }
  }
}

ImageD divergence(const ImageD& gx, const ImageD& gy, PoissonBoundary boundary) {
  if (gx.rows() != gy.rows() || gx.cols() != gy.cols())
    throw std::invalid_argument("divergence: gx and gy differ in size");
  ImageD d(gx.rows(), gx.cols());
  divergence_into<double>(gx, gy, nullptr, boundary == PoissonBoundary::kPeriodicU, d.data());
  return d;
}

ImageD laplacian(const ImageD& L, PoissonBoundary boundary) {
  ImageD gx, gy;
  forward_gradient(L, boundary, &gx, &gy);
  return divergence(gx, gy, boundary);
}

// Eigenbases of restricted 1-D operators. A restriction of len pixels is determined by len,
// whether it starts at the domain's first pixel, whether it ends at its last, and (periodic) whether
// it is the whole ring.
struct PoissonSolver::EigenCache {
  std::mutex mutex;
  std::map<std::tuple<int, bool, bool, bool>, std::shared_ptr<const AxisBasis>> bases;

  std::shared_ptr<const AxisBasis> get(int n_domain, bool periodic, int start, int len) {
    const bool ring = periodic && len == n_domain;
    const auto key = std::make_tuple(len, !periodic && start == 0, !periodic && start + len == n_domain, ring);
    {
      std::lock_guard<std::mutex> lock(mutex);
      const auto it = bases.find(key);
      if (it != bases.end()) return it->second;
    }
    auto basis = std::make_shared<const AxisBasis>(axis_basis(axis_operator(n_domain, periodic, start, len)));
    std::lock_guard<std::mutex> lock(mutex);
    return bases.emplace(key, std::move(basis)).first->second;
  }
};

PoissonSolver::PoissonSolver(int width, int height, const PoissonOptions& options)
    : width_(width), height_(height), options_(options), cache_(std::make_shared<EigenCache>()) {
  std::string why;
  if (!options_.Validate(&why)) throw std::invalid_argument("PoissonOptions: " + why);
  if (width < 2 || height < 2)
    throw std::invalid_argument("Poisson solver: image must be at least 2x2 px, got " + std::to_string(width) + "x" +
                                std::to_string(height));
}

void PoissonSolver::solve(const ImageD& gx, const ImageD& gy, ImageD* L, const ImageD* weight) const {
  full_solve<double>(width_, height_, options_, gx, gy, L, weight);
}

void PoissonSolver::solve(const ImageF& gx, const ImageF& gy, ImageF* L, const ImageF* weight) const {
  full_solve<float>(width_, height_, options_, gx, gy, L, weight);
}

void PoissonSolver::solve_laplacian(const ImageD& f, ImageD* L) const {
  if (L == nullptr) throw std::invalid_argument("Poisson solver: null output");
  check_size("f", f.rows(), f.cols(), width_, height_);
  const bool periodic = options_.boundary == PoissonBoundary::kPeriodicU;
  if (width_ % 2 == 0 && height_ % 2 == 0) {
    cv::Mat div(height_, width_, CV_64F);
    // Remove the constant component (a consistent right-hand side has none; lap cannot produce it).
    const double mean = f.mean();
    Eigen::Map<ImageD>(div.ptr<double>(), height_, width_) = f.array() - mean;
    spectral_inverse<double>(div, periodic, L);
  } else {
    const ImageD g = f.array() - f.mean();
    dense_inverse<double>(g, periodic, L);
  }
}

PixelRect PoissonSolver::solve_region(const ImageD& gx, const ImageD& gy, const PixelRect& rect, ImageD* L,
                                 const ImageD* weight) const {
  if (L == nullptr) throw std::invalid_argument("Poisson solver: null output");
  check_size("gx", gx.rows(), gx.cols(), width_, height_);
  check_size("gy", gy.rows(), gy.cols(), width_, height_);
  check_size("L", L->rows(), L->cols(), width_, height_);
  if (weight) check_size("weight", weight->rows(), weight->cols(), width_, height_);
  const bool periodic = options_.boundary == PoissonBoundary::kPeriodicU;
  const int W = width_, H = height_;
  const std::string rect_text = "[" + std::to_string(rect.x) + ", " + std::to_string(rect.y) + ", " +
                                std::to_string(rect.width) + "x" + std::to_string(rect.height) + "]";
  if (rect.width <= 0 || rect.height <= 0)
    throw std::invalid_argument("Poisson solve_region: empty rectangle " + rect_text);
  if (rect.width > W) throw std::invalid_argument("Poisson solve_region: rectangle " + rect_text + " wider than the image");
  int y0 = std::max(rect.y, 0);
  const int y1 = std::min(rect.y + rect.height, H);
  if (y1 <= y0) throw std::invalid_argument("Poisson solve_region: rectangle " + rect_text + " has no rows in the image");
  int x0 = rect.x;
  if (periodic) {
    x0 = ((x0 % W) + W) % W;
  } else if (x0 < 0 || x0 + rect.width > W) {
    throw std::invalid_argument("Poisson solve_region: rectangle " + rect_text +
                                " leaves the image (u does not wrap with kNeumann)");
  }
  // Grow the sides to multiples of 16 px inside the image (cached eigenbases); a larger rectangle
  // is still an exact solve on it.
  constexpr int kQuantum = 16;
  int w = std::min(W, (rect.width + kQuantum - 1) / kQuantum * kQuantum);
  if (!periodic && x0 + w > W) x0 = W - w;
  int h = std::min(H, (y1 - y0 + kQuantum - 1) / kQuantum * kQuantum);
  y0 = std::min(y0, H - h);
  if ((w == W && h == H) || w > options_.max_region_side || h > options_.max_region_side) {
    solve(gx, gy, L, weight);
    return PixelRect{0, 0, W, H};
  }

  auto col = [&](int t) { return periodic ? (x0 + t) % W : x0 + t; };
  auto wt = [&](int j, int i) { return weight ? (*weight)(j, i) : 1.0; };
  // Edge residual e = w g - (L_q - L_p) for the edge p -> q; r(p) = sum over edges out of p minus
  // sum over edges into p = (div g - lap L)(p).
  const ImageD& Lc = *L;
  Eigen::MatrixXd r(h, w);
  for (int tj = 0; tj < h; ++tj) {
    const int j = y0 + tj;
    for (int ti = 0; ti < w; ++ti) {
      const int i = col(ti);
      double s = 0.0;
      if (i + 1 < W) {
        s += wt(j, i) * gx(j, i) - (Lc(j, i + 1) - Lc(j, i));
      } else if (periodic) {
        s += wt(j, i) * gx(j, i) - (Lc(j, 0) - Lc(j, i));
      }
      if (i > 0) {
        s -= wt(j, i - 1) * gx(j, i - 1) - (Lc(j, i) - Lc(j, i - 1));
      } else if (periodic) {
        s -= wt(j, W - 1) * gx(j, W - 1) - (Lc(j, 0) - Lc(j, W - 1));
      }
      if (j + 1 < H) s += wt(j, i) * gy(j, i) - (Lc(j + 1, i) - Lc(j, i));
      if (j > 0) s -= wt(j - 1, i) * gy(j - 1, i) - (Lc(j, i) - Lc(j - 1, i));
      r(tj, ti) = s;
    }
  }
  // The rectangle's Laplacian (Dirichlet to the pixels outside) is the Kronecker sum of the two
  // restricted 1-D operators: solve lap_rect(delta) = r and add delta.
  const Eigen::MatrixXd delta = separable_solve(*cache_->get(H, false, y0, h), *cache_->get(W, periodic, x0, w), r);
  for (int tj = 0; tj < h; ++tj)
    for (int ti = 0; ti < w; ++ti) (*L)(y0 + tj, col(ti)) += delta(tj, ti);
  return PixelRect{x0, y0, w, h};
}

}  // namespace evio::mapping
