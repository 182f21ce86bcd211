// Per-event label accuracy with a majority mapping of clusters to true labels (label_evaluation.h).
#include "evio/evaluation/label_evaluation.h"

namespace evio::evaluation {

void LabelAgreement::add(const LabelAgreement& o) {
  scored += o.scored;
  correct += o.correct;
  for (const auto& [l, c] : o.scored_per_label) scored_per_label[l] += c;
  for (const auto& [l, c] : o.correct_per_label) correct_per_label[l] += c;
}

LabelAgreement score_labels(const int* predicted, const uint16_t* truth, size_t n) {
  std::map<int, std::map<int, int64_t>> votes;  // cluster -> true label -> events
  for (size_t k = 0; k < n; ++k)
    if (truth[k] != kNoiseLabel && predicted[k] >= 0) ++votes[predicted[k]][truth[k]];
  std::map<int, int> to_label;
  for (const auto& [cluster, v] : votes) {
    int best = -1;
    int64_t best_n = -1;
    for (const auto& [label, count] : v)  // ascending labels: ties go to the smaller
      if (count > best_n) best = label, best_n = count;
    to_label[cluster] = best;
  }
  LabelAgreement a;
  for (size_t k = 0; k < n; ++k) {
    if (truth[k] == kNoiseLabel) continue;
    ++a.scored;
    ++a.scored_per_label[truth[k]];
    if (predicted[k] < 0) continue;
    if (to_label.at(predicted[k]) == truth[k]) {
      ++a.correct;
      ++a.correct_per_label[truth[k]];
    }
  }
  return a;
}

}  // namespace evio::evaluation
