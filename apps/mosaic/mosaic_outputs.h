// The outputs of `evio mosaic` after the run: rotation.tum, the panorama images, stats.json, the
// printed summary and, with --gt, eval.json (rotation error after aligning the initial
// orientation; the mosaic against the true panorama of a simulated dataset).
#pragma once

#include <cstdint>
#include <iosfwd>

#include "evio/pipeline/mosaic_pipeline.h"
#include "mosaic_command.h"

namespace evio::apps {

// A streamed run: the pipeline's result with the command's counts and times.
struct MosaicRun {
  pipeline::MosaicResult result;
  int64_t events = 0;
  int64_t t0_ns = 0, t_last_ns = 0;  // first and last event
  double processing_s = 0;           // wall time
  double cpu_s = 0;                  // every thread's CPU time over the same span
  int snapshots = 0;                 // snapshot PNGs written

  double duration_s() const { return static_cast<double>(t_last_ns - t0_ns) * 1e-9; }
};

void write_mosaic_outputs(const MosaicArgs& args, const MosaicConfig& cfg, const MosaicRun& run, std::ostream& out);
void evaluate_mosaic(const MosaicArgs& args, const MosaicConfig& cfg, const MosaicRun& run, std::ostream& out);

}  // namespace evio::apps
