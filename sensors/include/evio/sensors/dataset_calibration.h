// The camera calibration of a dataset, found one way for every command and tool: a given file
// (Kalibr camchain YAML or ECD calib.txt), else the dataset folder's calib.yaml (written by
// `evio simulate`), else the calibration the dataset itself carries.
#pragma once

#include <filesystem>
#include <optional>
#include <string>

#include "evio/calib/calibration_io.h"
#include "evio/sensors/dataset.h"

namespace evio {

struct DatasetCalibration {
  std::optional<calib::CameraCalibration> camera;  // nullopt: none found
  std::string kalibr_yaml;  // the Kalibr YAML it came from ("" otherwise); may hold imu0 noise
};

inline DatasetCalibration find_dataset_calibration(const std::string& dataset, const std::string& calib_arg,
                                                   DatasetReader& reader) {
  namespace fs = std::filesystem;
  DatasetCalibration out;
  std::string file = calib_arg;
  if (file.empty()) {
    const fs::path p = fs::is_directory(dataset) ? fs::path(dataset) / "calib.yaml" : fs::path(dataset).parent_path() / "calib.yaml";
    if (fs::exists(p)) file = p.string();
  }
  const std::string ext = fs::path(file).extension().string();
  if (!file.empty() && (ext == ".yaml" || ext == ".yml")) {
    out.camera = calib::load_kalibr_camchain(file).front();
    out.kalibr_yaml = file;
  } else if (!file.empty()) {
    out.camera = calib::load_ecd_calib(file);
  } else {
    out.camera = reader.read_calibration();
  }
  return out;
}

}  // namespace evio
