#include "evio/mapping/warp_model_selection.h"

#include <algorithm>

namespace evio::mapping {

std::vector<WarpModel> sort_warp_models(const std::vector<WarpModel>& models) {
  std::vector<WarpModel> out;
  for (WarpModel m : models)
    if (std::find(out.begin(), out.end(), m) == out.end()) out.push_back(m);
  std::stable_sort(out.begin(), out.end(), [](WarpModel a, WarpModel b) { return warp_dof(a) < warp_dof(b); });
  return out;
}

size_t choose_warp_model(std::vector<ModelTrial>* trials, double gain_per_parameter) {
  std::vector<ModelTrial>& t = *trials;
  if (t.empty()) return 0;
  const double f0 = t.front().objective;
  const int dof0 = warp_dof(t.front().model);
  size_t best = 0;
  for (size_t i = 0; i < t.size(); ++i) {
    t[i].gain = f0 > 0 ? t[i].objective / f0 - 1.0 : 0.0;
    t[i].score = t[i].gain - gain_per_parameter * (warp_dof(t[i].model) - dof0);
    t[i].chosen = false;
    if (i > 0 && f0 > 0 && t[i].score > t[best].score) best = i;
  }
  t[best].chosen = true;
  return best;
}

}  // namespace evio::mapping
