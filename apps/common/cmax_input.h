// The input side shared by `evio flow` and `evio segment`: the dataset with its camera (the
// pinhole the 3-D warps need) and sensor size, and a timed stream of its sub-pixel events over
// [t_start, t_end) into a pipeline, with progress on stderr. `evio reconstruct` opens its dataset
// and camera here too.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "evio/calib/camera.h"
#include "evio/mapping/cmax.h"
#include "evio/sensors/dataset.h"
#include "evio/sensors/dataset_calibration.h"

namespace evio::apps {

struct CmaxInput {
  std::unique_ptr<DatasetReader> reader;
  DatasetCalibration calibration;              // as found (camera, extrinsics, where from)
  std::optional<calib::PinholeCamera> camera;  // its camera, if any
  SensorSize sensor;                           // the camera's, else the dataset's
};

// Opens the dataset and its calibration (calib: --calib, empty for the dataset's own). Throws
// evio::InputError when the sensor size is unknown, or when one of `models` is a 3-D warp
// (rotation, 6dof) and there is no camera calibration.
CmaxInput open_cmax_input(const std::string& dataset, const DatasetOptions& options, const std::string& calib,
                          const std::vector<mapping::WarpModel>& models);

struct CmaxStreamTotals {
  int64_t events = 0;                  // events with t_start <= t < t_end
  int64_t t_first_ns = 0, t_last_ns = 0;
  double process_s = 0;                // time inside process() and finish(), s (handle() excluded)
};

// Streams the events with t_start <= t < t_end (either optional) to process(e), which returns true
// when results are ready; handle() then runs outside the timed part (output time is not
// processing time), and once more after finish(). progress_text() adds to the progress line.
CmaxStreamTotals stream_cmax_events(DatasetReader* reader, std::optional<int64_t> t_start_ns,
                                    std::optional<int64_t> t_end_ns, const std::string& command, bool progress,
                                    const std::function<bool(const SubpixelEvent&)>& process,
                                    const std::function<void()>& finish, const std::function<void()>& handle,
                                    const std::function<std::string()>& progress_text);

}  // namespace evio::apps
