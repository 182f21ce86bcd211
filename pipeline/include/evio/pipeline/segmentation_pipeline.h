// Streaming motion segmentation by contrast maximisation (mapping::MotionSegmenter, Stoffregen et
// al. ICCV 2019) over a recording, as `evio segment` runs it: event windows (CmaxWindower), each
// segmented warm-started from the previous window's clusters, so a cluster keeps its label while it
// lives and new clusters get new labels; per-event labels with their stream indices, per-window
// clusters with their motions and the model and count decisions. No file I/O, no flags.
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "evio/calib/camera.h"
#include "evio/mapping/cmax_segmentation.h"
#include "evio/mapping/image.h"
#include "evio/pipeline/cmax_windows.h"
#include "evio/sensors/measurements.h"

namespace evio::pipeline {

struct SegmentationPipelineOptions {
  // Windows of ~0.1 s at the event rates of DAVIS recordings of moving objects (0.3-0.7 M ev/s):
  // long enough for slow objects to move a few pixels, short enough for a constant velocity
  // (dynamic_3objects: 70k-event windows 0.952 label accuracy, 20k 0.907, 30k 0.940, 50k 0.949).
  CmaxWindowOptions window = [] {
    CmaxWindowOptions w;
    w.window_events = 60000;
    w.max_window_ns = 150'000'000;
    return w;
  }();
  mapping::SegmentationOptions segmentation;  // cmax width/height/geometry are set from the camera
  bool warm_start = true;   // start each window from the previous window's clusters (persistent labels)
  bool keep_iwe = false;    // each window carries the per-cluster IWEs (unblurred, own events only)
  bool Validate(std::string* why) const;
};

struct SegmentationWindow {
  int64_t index = 0;
  int64_t t_start_ns = 0, t_end_ns = 0, t_ref_ns = 0;
  int64_t events = 0;                          // segmented
  std::vector<mapping::SegmentCluster> clusters;   // by id
  std::vector<mapping::CountStep> count_steps;     // automatic count decisions
  std::vector<int64_t> input_index;            // stream index of each segmented event
  std::vector<int> labels;                     // its cluster id, or -1 (noise)
  int64_t input_begin = 0, input_end = 0;      // stream indices covered (dropped events included)
  int alternations = 0, evaluations = 0;
  double time_ms = 0;                          // wall time of this window, ms
  std::vector<mapping::ImageF> iwe;            // keep_iwe: one per cluster, same order
  mapping::ImageF iwe_zero;                    // keep_iwe: all events unwarped
};

struct SegmentationStats {
  int64_t windows = 0;
  int64_t events_labelled = 0;   // segmented events with a cluster label
  int64_t events_noise = 0;      // segmented events labelled -1
  int64_t alternations = 0, evaluations = 0;
  int next_id = 0;               // labels handed out so far (ids 0 .. next_id-1)
  double time_ms = 0;
  double max_window_ms = 0;
};

class SegmentationPipeline {
 public:
  // camera: pinhole and undistortion (required for the rotation and 6dof models). Throws
  // std::invalid_argument for invalid options.
  SegmentationPipeline(const SegmentationPipelineOptions& options, int width, int height,
                       const std::optional<calib::PinholeCamera>& camera);
  ~SegmentationPipeline();

  bool process(const SubpixelEvent& e);  // true when windows were segmented (take_windows())
  void finish();
  std::vector<SegmentationWindow> take_windows();

  const CmaxWindower& windows() const { return *windower_; }
  const SegmentationStats& stats() const { return stats_; }
  const SegmentationPipelineOptions& options() const { return options_; }
  const mapping::SegmentationOptions& segmentation_options() const { return segmenter_->options(); }
  mapping::CmaxObjective objective() const { return segmenter_->objective(); }

 private:
  void run(std::vector<CmaxWindow> windows);

  SegmentationPipelineOptions options_;
  std::unique_ptr<CmaxWindower> windower_;
  std::unique_ptr<mapping::MotionSegmenter> segmenter_;
  std::vector<mapping::SegmentCluster> previous_;
  SegmentationStats stats_;
  std::vector<SegmentationWindow> done_;
};

}  // namespace evio::pipeline
