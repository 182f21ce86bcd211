// Uses one piece of each installed evio library: a simulated trajectory (simulator), event
// storage (sensors), geometry (calib), the pipelines' options (pipeline, frontend, backend,
// mapping) and trajectory evaluation (evaluation); then writes and reads back a landmark map and a
// PNG in the folder argv[1] through the installed plugins (lib/evio: PCL, OpenCV imgcodecs).
// Prints "evio consumer ok" and exits 0.
#include <cstdio>
#include <string>

#include "evio/calib/geometry.h"
#include "evio/evaluation/trajectory_evaluation.h"
#include "evio/mapping/gradient_mosaic.h"
#include "evio/mapping/landmark_map.h"
#include "evio/pipeline/mosaic_pipeline.h"
#include "evio/pipeline/vio_pipeline.h"
#include "evio/sensors/event_buffer.h"
#include "evio/sensors/image_io.h"
#include "evio/simulator/trajectory.h"

int main(int argc, char** argv) {
  if (argc < 2) return 2;
  const std::string dir = argv[1];
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
  evio::mapping::write_landmark_map(dir + "/map.ply", {{Eigen::Vector3d(1, 2, 3), 4.0f}});
  const std::vector<evio::mapping::MapPoint> map = evio::mapping::read_landmark_map(dir + "/map.ply");
  if (map.size() != 1 || map[0].p_w.z() != 3.0) {
    std::printf("landmark map round trip failed\n");
    return 1;
  }
  const cv::Mat image(4, 6, CV_8UC1, cv::Scalar(77));
  if (!evio::write_image(dir + "/image.png", image) || evio::read_image(dir + "/image.png", cv::IMREAD_UNCHANGED).at<uint8_t>(3, 5) != 77) {
    std::printf("image round trip failed\n");
    return 1;
  }
  std::printf("evio consumer ok\n");
  return 0;
}
