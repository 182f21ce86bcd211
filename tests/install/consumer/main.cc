// Uses one piece of each installed evio library: a simulated trajectory (simulator), event
// storage (sensors), geometry (calib), the pipelines' options (pipeline, frontend, backend,
// mapping) and trajectory evaluation (evaluation). Prints "evio consumer ok" and exits 0.
#include <cstdio>
#include <string>

#include "evio/calib/geometry.h"
#include "evio/evaluation/trajectory_evaluation.h"
#include "evio/mapping/gradient_mosaic.h"
#include "evio/pipeline/mosaic_pipeline.h"
#include "evio/pipeline/vio_pipeline.h"
#include "evio/sensors/event_buffer.h"
#include "evio/simulator/trajectory.h"

int main() {
  std::string why;
  const evio::pipeline::MosaicPipelineOptions mosaic;
  const evio::pipeline::VioPipelineOptions vio;
  if (!mosaic.Validate(&why) || !vio.Validate(&why)) {
    std::printf("invalid default options: %s\n", why.c_str());
    return 1;
  }
  const Eigen::Matrix3d R = evio::calib::so3_exp(Eigen::Vector3d(0.1, -0.2, 0.3));
  if ((evio::calib::so3_log(R) - Eigen::Vector3d(0.1, -0.2, 0.3)).norm() > 1e-12) return 1;
  evio::EventBuffer buffer;
  buffer.push_back(evio::Event{1000, 3, 4, 1});
  if (buffer.size() != 1) return 1;
  const evio::mapping::GradientMosaicOptions m;
  if (!m.Validate(&why)) return 1;
  std::printf("evio consumer ok\n");
  return 0;
}
