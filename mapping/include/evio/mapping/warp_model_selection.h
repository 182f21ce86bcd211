// Choosing a warp model (cmax.h) for a set of events, one rule for every caller (a cluster of
// `evio segment`, a window of `evio flow --model auto`): the simplest model that explains the
// events. Each candidate's motion is fitted with the same objective (so the values compare); a
// candidate's gain is its objective over the simplest candidate's, minus 1; its score is that gain
// minus gain_per_parameter for each parameter it has beyond the simplest. The highest score wins,
// a tie going to the simpler model, so a richer model has to raise the objective by more than
// gain_per_parameter per extra parameter to be chosen.
#pragma once

#include <vector>

#include <Eigen/Core>

#include "evio/mapping/cmax.h"

namespace evio::mapping {

// One model tried, for the report.
struct ModelTrial {
  WarpModel model = WarpModel::kFlow;
  Eigen::VectorXd params;
  double objective = 0;  // the objective of the events under this model's fitted motion
  double gain = 0;       // objective / the simplest candidate's objective - 1
  double score = 0;      // gain - gain_per_parameter * (extra parameters over the simplest)
  bool chosen = false;
};

// The candidates sorted simplest first (by parameter count; equal counts keep the given order),
// duplicates removed.
std::vector<WarpModel> sort_warp_models(const std::vector<WarpModel>& models);

// trials: the candidates with model, params and objective filled in, simplest first (the first
// is the reference). Fills gain, score and chosen; returns the index of the chosen trial (0 when
// the reference's objective is not positive). gain_per_parameter >= 0.
size_t choose_warp_model(std::vector<ModelTrial>* trials, double gain_per_parameter);

}  // namespace evio::mapping
