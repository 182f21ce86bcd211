// The event-feature front-end as one per-event chain, as `evio corners` runs it: events outside
// the sensor or at pixels the undistortion cannot map are dropped, then the optional refractory
// and background-activity filters, eFAST corner detection on the Surface of Active Events
// (Mueggler et al., BMVC 2017), and for each corner event an optional DART descriptor and the
// corner tracker. Plain events in, corner events and tracks out; no file I/O.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "evio/calib/camera.h"
#include "evio/frontend/corner_tracker.h"
#include "evio/frontend/dart.h"
#include "evio/frontend/efast.h"
#include "evio/frontend/event_filters.h"
#include "evio/sensors/measurements.h"

namespace evio::pipeline {

struct CornerPipelineOptions {
  bool refractory_enabled = false;                               // drop events within period_ns of the pixel's last
  frontend::RefractoryFilterOptions refractory;                  // period_ns (ns), per_polarity
  bool background_activity_enabled = false;                      // drop events without recent neighbours
  frontend::BackgroundActivityFilterOptions background_activity; // window_ns (ns), radius (px), min_support (count)
  frontend::EfastOptions efast;                                  // filter_sae, filter_window_ns (ns)
  bool tracks = true;                                            // run the corner tracker
  frontend::CornerTrackerOptions tracker;                        // gate (px), gap (ns), smoothing, descriptor test
  bool descriptors = true;                                       // a DART descriptor per corner event for the tracker
  frontend::DartOptions dart;                                    // rings, wedges, radii (px), window (ns)

  bool Validate(std::string* why) const;
};

struct CornerPipelineStats {
  int64_t events = 0;          // events given to process()
  int64_t outside = 0;         // outside the width x height sensor (skipped)
  int64_t not_undistortable = 0;  // at pixels the camera model cannot undistort
  int64_t corners = 0;         // corner events
  int64_t descriptors = 0;     // corner events that got a DART descriptor
};

class CornerPipeline {
 public:
  // camera: when given, events at pixels its undistortion cannot map are dropped. Throws
  // std::invalid_argument for invalid options or a non-positive sensor size.
  CornerPipeline(const CornerPipelineOptions& options, int width, int height,
                 const std::optional<calib::PinholeCamera>& camera);
  ~CornerPipeline();

  // One event (in time order): true when it is a corner event.
  bool process(const Event& e);

  // Tracks that ended since the last call (each with at least tracker.min_length corner events).
  std::vector<frontend::CornerTrack> take_finished_tracks();
  // Ends every track; returns the ones long enough, not yet taken.
  std::vector<frontend::CornerTrack> finish();

  const CornerPipelineStats& stats() const { return stats_; }
  const frontend::EfastStats& efast_stats() const { return detector_.stats(); }
  // Events the filters passed; nullopt when the filter is off.
  std::optional<int64_t> refractory_passed() const;
  std::optional<int64_t> background_activity_passed() const;
  // The tracker (its active tracks, its statistics), or nullptr when tracks are off.
  const frontend::CornerTracker* tracker() const { return tracker_.get(); }
  const CornerPipelineOptions& options() const { return o_; }

 private:
  CornerPipelineOptions o_;
  int width_, height_;
  std::unique_ptr<frontend::EventUndistorter> undistorter_;
  frontend::RefractoryFilter refractory_;
  frontend::BackgroundActivityFilter background_;
  frontend::EfastDetector detector_;
  std::unique_ptr<frontend::CornerTracker> tracker_;
  std::unique_ptr<frontend::DartExtractor> dart_;
  frontend::DartDescriptor descriptor_;
  CornerPipelineStats stats_;
};

}  // namespace evio::pipeline
