// Shared by the pipeline tests: a DAVIS240C-like camera without distortion, and the check that an
// Options struct is rejected with a reason naming the bad field.
#pragma once

#include <string>

#include <gtest/gtest.h>

#include "evio/calib/calibration_io.h"

namespace evio::pipeline::testing {

inline calib::CameraCalibration test_camera() {
  calib::CameraIntrinsics in;
  in.width = 240;
  in.height = 180;
  in.fx = in.fy = 200;
  in.cx = 120;
  in.cy = 90;
  calib::CameraCalibration c;
  c.camera = calib::PinholeCamera(in);
  return c;
}

// EXPECTs that o.Validate fails with a reason containing `reason`.
template <typename Options>
void expect_rejected(const Options& o, const std::string& reason) {
  std::string w;
  EXPECT_FALSE(o.Validate(&w)) << reason;
  EXPECT_NE(w.find(reason), std::string::npos) << w;
}

}  // namespace evio::pipeline::testing
