// Window-by-window label accuracy and the true-label file (windowed_label_evaluation.h).
#include "evio/evaluation/windowed_label_evaluation.h"

#include <cmath>
#include <cstdlib>

#include "evio/calib/error.h"

namespace evio::evaluation {
namespace {

constexpr const char* kExpected =
    "one label per event of the dataset, in event order (0 background, 1..N objects, 65535 noise)";

}  // namespace

EventLabelReader::EventLabelReader(const std::string& path) : path_(path), f_(path) {
  if (!f_) throw InputError(path, 0, "cannot open the true labels", kExpected);
}

uint16_t EventLabelReader::next() {
  std::string l;
  if (!std::getline(f_, l)) throw InputError(path_, line_, "fewer labels than events", kExpected);
  ++line_;
  char* end = nullptr;
  const unsigned long v = std::strtoul(l.c_str(), &end, 10);
  if (end == l.c_str() || v > 65535) throw InputError(path_, line_, "'" + l + "' is not a label", kExpected);
  return static_cast<uint16_t>(v);
}

bool EventLabelReader::more() {
  std::string l;
  while (std::getline(f_, l))
    if (l.find_first_not_of(" \t\r") != std::string::npos) return true;
  return false;
}

void WindowedLabelScore::add_outside(uint16_t truth) { outside_scored_ += truth != kNoiseLabel; }

void WindowedLabelScore::add(int predicted, uint16_t truth) {
  predicted_.push_back(predicted);
  truth_.push_back(truth);
}

void WindowedLabelScore::end_window() {
  if (predicted_.empty()) return;
  in_windows_.add(score_labels(predicted_, truth_));
  predicted_.clear();
  truth_.clear();
}

double WindowedLabelScore::accuracy() const {
  return scored() > 0 ? static_cast<double>(correct()) / static_cast<double>(scored()) : NAN;
}

double WindowedLabelScore::accuracy_in_windows() const { return in_windows_.scored ? in_windows_.accuracy() : NAN; }

}  // namespace evio::evaluation
