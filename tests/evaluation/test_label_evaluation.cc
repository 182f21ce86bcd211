// evaluation::score_labels: majority mapping of clusters to true labels, hand-counted cases.
#include "evio/evaluation/label_evaluation.h"

#include <gtest/gtest.h>

namespace evio::evaluation {
namespace {

TEST(LabelEvaluation, PerfectUpToRenumbering) {
  // Clusters 7 and 3 are the true labels 0 and 1 renamed: every event right.
  const std::vector<int> pred = {7, 7, 3, 3, 3};
  const std::vector<uint16_t> truth = {0, 0, 1, 1, 1};
  const LabelAgreement a = score_labels(pred, truth);
  EXPECT_EQ(a.scored, 5);
  EXPECT_EQ(a.correct, 5);
  EXPECT_DOUBLE_EQ(a.accuracy(), 1.0);
}

TEST(LabelEvaluation, MajorityNoiseAndUnlabelled) {
  // Cluster 0 holds labels {1, 1, 1, 2}: maps to 1 (3 right, 1 wrong). Cluster 5 holds {2, 2} -> 2.
  // One event without a cluster (-1, true label 2) is wrong; one true-noise event is not scored.
  const std::vector<int> pred = {0, 0, 0, 0, 5, 5, -1, 5};
  const std::vector<uint16_t> truth = {1, 1, 1, 2, 2, 2, 2, kNoiseLabel};
  const LabelAgreement a = score_labels(pred, truth);
  EXPECT_EQ(a.scored, 7);
  EXPECT_EQ(a.correct, 5);
  EXPECT_DOUBLE_EQ(a.accuracy(), 5.0 / 7.0);
  EXPECT_EQ(a.scored_per_label.at(1), 3);
  EXPECT_EQ(a.correct_per_label.at(1), 3);
  EXPECT_EQ(a.scored_per_label.at(2), 4);
  EXPECT_EQ(a.correct_per_label.at(2), 2);
}

TEST(LabelEvaluation, TiesGoToTheSmallerLabelAndGroupsAdd) {
  // One cluster for everything, two labels equally often: it maps to 0, half right.
  const LabelAgreement a = score_labels(std::vector<int>{4, 4, 4, 4}, std::vector<uint16_t>{1, 0, 1, 0});
  EXPECT_EQ(a.correct, 2);
  EXPECT_EQ(a.correct_per_label.count(1), 0u);
  // A second window where the same cluster id is label 1: scored on its own mapping.
  LabelAgreement b = score_labels(std::vector<int>{4, 4}, std::vector<uint16_t>{1, 1});
  b.add(a);
  EXPECT_EQ(b.scored, 6);
  EXPECT_EQ(b.correct, 4);
  EXPECT_EQ(b.correct_per_label.at(1), 2);
  EXPECT_DOUBLE_EQ(score_labels(std::vector<int>{}, std::vector<uint16_t>{}).accuracy(), 0.0);
}

}  // namespace
}  // namespace evio::evaluation
