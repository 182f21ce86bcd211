// evaluation::WindowedLabelScore and EventLabelReader: one majority mapping per window, events in
// no window wrong unless noise, hand-counted accuracies; the label file's errors.
#include "evio/evaluation/windowed_label_evaluation.h"

#include <cmath>

#include <gtest/gtest.h>

#include "evio/calib/error.h"
#include "evio_test/temp_dir.h"

namespace evio::evaluation {
namespace {

TEST(WindowedLabelScore, EachWindowHasItsOwnMappingAndOutsideEventsAreWrong) {
  WindowedLabelScore s;
  // Window 1: cluster 3 is label 1 (3 of 4 right), one true-noise event not scored.
  for (auto [p, t] : std::vector<std::pair<int, uint16_t>>{{3, 1}, {3, 1}, {3, 1}, {3, 2}, {3, kNoiseLabel}}) s.add(p, t);
  s.end_window();
  s.end_window();  // an empty window adds nothing
  // Two events in no window: a true label (wrong) and noise (not scored).
  s.add_outside(2);
  s.add_outside(kNoiseLabel);
  // Window 2: the same cluster id 3 is now label 2 (2 right); one event without a cluster (wrong).
  for (auto [p, t] : std::vector<std::pair<int, uint16_t>>{{3, 2}, {3, 2}, {-1, 2}}) s.add(p, t);
  s.end_window();

  EXPECT_EQ(s.in_windows().scored, 7);
  EXPECT_EQ(s.correct(), 5);
  EXPECT_EQ(s.scored(), 8);
  EXPECT_DOUBLE_EQ(s.accuracy(), 5.0 / 8.0);
  EXPECT_DOUBLE_EQ(s.accuracy_in_windows(), 5.0 / 7.0);
  EXPECT_EQ(s.in_windows().scored_per_label.at(2), 4);
  EXPECT_EQ(s.in_windows().correct_per_label.at(2), 2);
}

TEST(WindowedLabelScore, NothingScoredIsNaN) {
  WindowedLabelScore s;
  s.add_outside(kNoiseLabel);
  EXPECT_EQ(s.scored(), 0);
  EXPECT_TRUE(std::isnan(s.accuracy()));
  EXPECT_TRUE(std::isnan(s.accuracy_in_windows()));
  s.add_outside(1);
  EXPECT_EQ(s.scored(), 1);
  EXPECT_DOUBLE_EQ(s.accuracy(), 0.0);
  EXPECT_TRUE(std::isnan(s.accuracy_in_windows()));
}

TEST(EventLabelReader, ReadsInOrderAndNamesTheBadLine) {
  evio_test::TempDir dir;
  EventLabelReader r(dir.write("labels.txt", "0\n2\n65535\n\n  \n"));
  EXPECT_EQ(r.next(), 0);
  EXPECT_EQ(r.next(), 2);
  EXPECT_EQ(r.next(), kNoiseLabel);
  EXPECT_FALSE(r.more());  // blank lines are not labels

  EventLabelReader more(dir.write("more.txt", "1\n1\n"));
  EXPECT_EQ(more.next(), 1);
  EXPECT_TRUE(more.more());

  EventLabelReader bad(dir.write("bad.txt", "1\nx\n70000\n"));
  EXPECT_EQ(bad.next(), 1);
  try {
    bad.next();
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("bad.txt:2"), std::string::npos) << e.what();
  }
  EXPECT_THROW(bad.next(), InputError);  // 70000 is no label
  EXPECT_THROW(bad.next(), InputError);  // fewer labels than events
  EXPECT_THROW(EventLabelReader(dir.file("missing.txt")), InputError);
}

}  // namespace
}  // namespace evio::evaluation
