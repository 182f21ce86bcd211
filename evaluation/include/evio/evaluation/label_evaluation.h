// Per-event label accuracy of a motion segmentation against true object labels (e.g. the
// simulator's event_labels.txt: 0 background, 1..N objects, 65535 noise). Cluster ids are arbitrary,
// so each predicted cluster is mapped to the true label most of its events carry (majority vote,
// ties to the smaller label) within one scored group of events (one segmentation window: clusters
// may be renumbered between windows); an event is correct when its cluster maps to its true label.
// Events whose true label is noise are left out; events without a cluster (predicted id < 0: noise
// or unsegmented) count as wrong. As in tests/mapping/test_cmax_segmentation.cc.
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <vector>

namespace evio::evaluation {

constexpr uint16_t kNoiseLabel = 65535;  // a true label that is scored nowhere (a noise event)

struct LabelAgreement {
  int64_t scored = 0;   // events with a true (non-noise) label
  int64_t correct = 0;  // of those, events whose cluster maps to their true label
  std::map<int, int64_t> scored_per_label, correct_per_label;  // by true label
  double accuracy() const { return scored > 0 ? static_cast<double>(correct) / static_cast<double>(scored) : 0.0; }
  // Adds another group's counts (e.g. the next window).
  void add(const LabelAgreement& other);
};

// predicted[k] (cluster id, < 0: none) against truth[k], k < n, as one group (one majority mapping).
LabelAgreement score_labels(const int* predicted, const uint16_t* truth, size_t n);
inline LabelAgreement score_labels(const std::vector<int>& predicted, const std::vector<uint16_t>& truth) {
  return score_labels(predicted.data(), truth.data(), predicted.size() < truth.size() ? predicted.size() : truth.size());
}

}  // namespace evio::evaluation
