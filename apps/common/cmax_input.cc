#include "cmax_input.h"

#include <chrono>

#include "evio/calib/error.h"
#include "progress.h"

namespace evio::apps {

CmaxInput open_cmax_input(const std::string& dataset, const DatasetOptions& options, const std::string& calib,
                          const std::vector<mapping::WarpModel>& models) {
  CmaxInput in;
  in.reader = open_dataset(dataset, options);
  in.calibration = find_dataset_calibration(dataset, calib, *in.reader);
  if (in.calibration.camera) in.camera = in.calibration.camera->camera;
  in.sensor = in.reader->sensor_size();
  if (in.camera) in.sensor = {in.camera->width(), in.camera->height()};
  if (!in.sensor.known())
    throw InputError(dataset, 0, "the sensor size is unknown (no calibration in the dataset)",
                     "--calib FILE (Kalibr camchain YAML or ECD calib.txt) or --sensor WxH");
  for (mapping::WarpModel m : models)
    if ((m == mapping::WarpModel::kRotation || m == mapping::WarpModel::kSixDof) && !in.camera)
      throw InputError(dataset, 0, std::string("no camera calibration (the ") + mapping::warp_model_name(m) +
                       " model needs the pinhole)", "--calib FILE (Kalibr camchain YAML or ECD calib.txt)");
  return in;
}

CmaxStreamTotals stream_cmax_events(DatasetReader* reader, std::optional<int64_t> t_start_ns,
                                    std::optional<int64_t> t_end_ns, const std::string& command, bool show_progress,
                                    const std::function<bool(const SubpixelEvent&)>& process,
                                    const std::function<void()>& finish, const std::function<void()>& handle,
                                    const std::function<std::string()>& progress_text) {
  using clock = std::chrono::steady_clock;
  CmaxStreamTotals t;
  Progress progress(command, show_progress, "events");
  if (t_start_ns) reader->seek_events(*t_start_ns);
  std::vector<SubpixelEvent> chunk;
  bool done = false;
  while (!done) {
    chunk.clear();
    if (reader->read_subpixel_events(&chunk, size_t{1} << 16) == 0) break;
    auto c0 = clock::now();
    for (const SubpixelEvent& e : chunk) {
      if (t_start_ns && e.t_ns < *t_start_ns) continue;
      if (t_end_ns && e.t_ns >= *t_end_ns) {
        done = true;
        break;
      }
      if (t.events == 0) t.t_first_ns = e.t_ns;
      t.t_last_ns = e.t_ns;
      ++t.events;
      if (process(e)) {
        t.process_s += std::chrono::duration<double>(clock::now() - c0).count();
        handle();
        c0 = clock::now();
      }
    }
    t.process_s += std::chrono::duration<double>(clock::now() - c0).count();
    progress.update(reader->progress(), t.events, progress_text());
  }
  const auto c0 = clock::now();
  finish();
  t.process_s += std::chrono::duration<double>(clock::now() - c0).count();
  handle();
  return t;
}

}  // namespace evio::apps
