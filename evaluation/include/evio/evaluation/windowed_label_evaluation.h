// Per-event label accuracy of a streaming motion segmentation (`evio segment`) against true labels,
// window by window: the events of one segmented window are one scored group of label_evaluation.h
// (one majority mapping of its clusters, which may be renumbered between windows), and an event in
// no segmented window (a window too small, the stream's tail) counts as wrong unless its true label
// is noise. The true labels are a file with one per event, in event order (the simulator's
// event_labels.txt: 0 background, 1..N objects, 65535 noise), read in step with the events.
#pragma once

#include <cstdint>
#include <fstream>
#include <string>
#include <vector>

#include "evio/evaluation/label_evaluation.h"

namespace evio::evaluation {

// The protocol above in one sentence (eval.json's "protocol").
constexpr const char* kWindowedLabelProtocol =
    "per window, each cluster mapped to the true label most of its events carry; accuracy over events with a true "
    "object label (not noise); events labelled -1 or in no segmented window count as wrong";

// The true labels, one per line, read one per event. Throws evio::InputError (file, line, expected
// form) when the file cannot be opened, has fewer labels than asked for, or a line is not a label.
class EventLabelReader {
 public:
  explicit EventLabelReader(const std::string& path);
  uint16_t next();
  // Whether a non-blank line follows (the file has more labels than were read); reads to the end.
  bool more();
  const std::string& path() const { return path_; }

 private:
  std::string path_;
  std::ifstream f_;
  int64_t line_ = 0;
};

class WindowedLabelScore {
 public:
  // An event in no segmented window.
  void add_outside(uint16_t truth);
  // An event of the current window: its cluster (< 0: none) and its true label.
  void add(int predicted, uint16_t truth);
  // Scores the current window's events as one group (nothing when it has none).
  void end_window();

  const LabelAgreement& in_windows() const { return in_windows_; }
  int64_t scored() const { return in_windows_.scored + outside_scored_; }  // true-labelled events
  int64_t correct() const { return in_windows_.correct; }
  double accuracy() const;             // correct / scored; NaN when none is scored
  double accuracy_in_windows() const;  // over the events in segmented windows; NaN when none

 private:
  LabelAgreement in_windows_;
  int64_t outside_scored_ = 0;  // true-labelled events in no segmented window (wrong)
  std::vector<int> predicted_;
  std::vector<uint16_t> truth_;
};

}  // namespace evio::evaluation
