// eFAST (see the header). The arc test does not scan every (start, length) pair: a valid arc
// holds the circle's newest pixel, and growing an arc from that pixel by always taking the newer
// of its two outside neighbours visits, at each length k, the only arc of length k that can be
// valid (if the k newest pixels form a contiguous arc strictly newer than the rest, every step
// stays inside it, because inside pixels are strictly newer than outside ones). So per length
// it suffices to test the greedy arc: its two outside neighbours first (cheap rejection), then
// that every other pixel is strictly older than its oldest pixel. Same decisions as the
// exhaustive scan, including ties (a tie across the arc boundary is never valid).
#include "evio/frontend/efast.h"
#include "evio/frontend/option_tables.h"

#include <algorithm>
#include <stdexcept>
#include <string>

namespace evio::frontend {

const std::array<std::array<int, 2>, 16> kEfastCircle3 = {{{0, -3}, {1, -3}, {2, -2}, {3, -1}, {3, 0}, {3, 1},
                                                          {2, 2}, {1, 3}, {0, 3}, {-1, 3}, {-2, 2}, {-3, 1},
                                                          {-3, 0}, {-3, -1}, {-2, -2}, {-1, -3}}};
const std::array<std::array<int, 2>, 20> kEfastCircle4 = {{{0, -4}, {1, -4}, {2, -3}, {3, -2}, {4, -1}, {4, 0},
                                                          {4, 1}, {3, 2}, {2, 3}, {1, 4}, {0, 4}, {-1, 4},
                                                          {-2, 3}, {-3, 2}, {-4, 1}, {-4, 0}, {-4, -1}, {-3, -2},
                                                          {-2, -3}, {-1, -4}}};

namespace {

constexpr int kBorder = 4;  // radius of the outer circle

template <int N, int KMIN, int KMAX>
inline bool arc_test(const int64_t* t) {
  static_assert(KMAX + 2 <= N, "arcs must leave two outside neighbours");
  int m = 0;
  int64_t newest = t[0];
  for (int i = 1; i < N; ++i) {
    if (t[i] > newest) {
      newest = t[i];
      m = i;
    }
  }
  int l = m, r = m;
  int64_t oldest_in_arc = newest;
  for (int k = 2; k <= KMAX; ++k) {
    const int li = l == 0 ? N - 1 : l - 1;
    const int ri = r == N - 1 ? 0 : r + 1;
    if (t[li] > t[ri]) {
      l = li;
      oldest_in_arc = std::min(oldest_in_arc, t[li]);
    } else {
      r = ri;
      oldest_in_arc = std::min(oldest_in_arc, t[ri]);
    }
    if (k < KMIN) continue;
    const int lo = l == 0 ? N - 1 : l - 1;
    const int ro = r == N - 1 ? 0 : r + 1;
    if (t[lo] >= oldest_in_arc || t[ro] >= oldest_in_arc) continue;
    int not_older = 0;
    for (int i = 0; i < N; ++i) not_older += t[i] >= oldest_in_arc ? 1 : 0;
    if (not_older == k) return true;
  }
  return false;
}

}  // namespace

bool efast_arc_test_16(const int64_t t[16]) { return arc_test<16, 3, 6>(t); }
bool efast_arc_test_20(const int64_t t[20]) { return arc_test<20, 4, 8>(t); }

bool EfastOptions::Validate(std::string* why) const { return efast_table().check(*this, why); }

EfastDetector::EfastDetector(int width, int height, const EfastOptions& options)
    : options_(options), sae_(width, height), latest_(options.filter_sae ? width : 1, options.filter_sae ? height : 1) {
  std::string why;
  if (!options.Validate(&why)) throw std::invalid_argument("eFAST options: " + why);
  for (size_t i = 0; i < off3_.size(); ++i) off3_[i] = kEfastCircle3[i][1] * static_cast<ptrdiff_t>(width) + kEfastCircle3[i][0];
  for (size_t i = 0; i < off4_.size(); ++i) off4_[i] = kEfastCircle4[i][1] * static_cast<ptrdiff_t>(width) + kEfastCircle4[i][0];
}

void EfastDetector::reset() {
  sae_.reset();
  latest_.reset();
  stats_ = EfastStats{};
}

bool EfastDetector::process(const Event& e) {
  ++stats_.events;
  const size_t idx = sae_.index(e.x, e.y);
  if (options_.filter_sae) {
    int64_t& same = latest_.plane(e.polarity)[idx];
    const int64_t other = latest_.plane(static_cast<int8_t>(-e.polarity))[idx];
    const bool update = same == kNeverNs || other > same || e.t_ns - same > options_.filter_window_ns;
    same = e.t_ns;
    if (!update) return false;
  }
  int64_t* plane = sae_.plane(e.polarity);
  plane[idx] = e.t_ns;
  if (e.x < kBorder || e.y < kBorder || e.x >= sae_.width() - kBorder || e.y >= sae_.height() - kBorder) return false;
  ++stats_.tested;
  const int64_t* c = plane + idx;
  int64_t t3[16];
  for (int i = 0; i < 16; ++i) t3[i] = c[off3_[i]];
  if (!arc_test<16, 3, 6>(t3)) return false;
  ++stats_.inner_passed;
  int64_t t4[20];
  for (int i = 0; i < 20; ++i) t4[i] = c[off4_[i]];
  if (!arc_test<20, 4, 8>(t4)) return false;
  ++stats_.corners;
  return true;
}

}  // namespace evio::frontend
