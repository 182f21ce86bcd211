// The outputs of `evio vio` that summarise a run: stats.json (model selection, spans, health,
// front-end counters, timing) and the summary printed at the end.
#pragma once

#include <cstddef>
#include <iosfwd>
#include <string>

#include "evio/evaluation/track_oracle.h"
#include "evio/pipeline/vio_pipeline.h"
#include "vio_command.h"

namespace evio::apps {

// What the command measured around the pipeline's result.
struct VioRunSummary {
  double processing_s = 0;  // wall time of the streaming and the final optimisation
  double duration_s = 0;    // the recording's span of the inputs used (events, or APS frames)
  std::string init_method;  // how the estimator was initialised, in words
  std::string noise_source; // the file the IMU noise came from ("defaults" without one)
  size_t landmarks = 0;     // points written to map.ply
};

// Writes stats.json at path as it is formatted (a long run's file is not held in memory twice).
void write_vio_stats(const std::string& path, const VioArgs& args, const VioConfig& cfg, const pipeline::VioResult& r,
                     const VioRunSummary& run, const evaluation::TrackOracle* oracle);

// The end-of-run summary: counts, initialisation, speed, motion models, tracking lost.
void print_vio_summary(std::ostream& out, const pipeline::VioResult& r, const VioRunSummary& run);

}  // namespace evio::apps
