// Plain measurement types shared by every evio module: events, IMU samples, frames.
// Conventions (ARCHITECTURE.md): int64 ns time, polarity +1/-1, IMU in SI units in the body
// (IMU) frame, pixel coordinates with (0,0) the top-left pixel centre.
#pragma once

#include <cstdint>
#include <string>

#include <Eigen/Core>
#include <opencv2/core/mat.hpp>

namespace evio {

struct Event {
  int64_t t_ns = 0;
  uint16_t x = 0;
  uint16_t y = 0;
  int8_t polarity = 1;  // +1 (ON, brightness increase) or -1 (OFF)
};
static_assert(sizeof(Event) == 16, "Event is meant to pack into 16 bytes");

inline bool operator==(const Event& a, const Event& b) {
  return a.t_ns == b.t_ns && a.x == b.x && a.y == b.y && a.polarity == b.polarity;
}

// An event at a sub-pixel (float) position: pixel coordinates with (0,0) the top-left pixel centre,
// x to the right, y down. They may be fractional, negative or beyond the sensor size, e.g. for
// undistorted events (ECD events_undistorted.txt) or events warped by a motion model.
struct SubpixelEvent {
  int64_t t_ns = 0;
  float x = 0, y = 0;
  int8_t polarity = 1;  // +1 (ON) or -1 (OFF)
};

inline SubpixelEvent to_subpixel(const Event& e) {
  return SubpixelEvent{e.t_ns, static_cast<float>(e.x), static_cast<float>(e.y), e.polarity};
}

// How a file wrote polarity; readers report it, writers can reproduce it.
enum class PolarityConvention { kUnknown, kZeroOne, kMinusPlusOne };
const char* polarity_convention_name(PolarityConvention c);  // "unknown", "0/1", "-1/+1"

struct ImuSample {
  int64_t t_ns = 0;
  Eigen::Vector3d gyro = Eigen::Vector3d::Zero();   // angular velocity of body in body frame, rad/s
  Eigen::Vector3d accel = Eigen::Vector3d::Zero();  // specific force in body frame, m/s^2
};

// An intensity frame (APS). `image` may be empty when only the reference was read; `path` is
// where it came from (absolute), empty for frames created in memory.
struct Frame {
  int64_t t_ns = 0;
  std::string path;
  cv::Mat image;  // CV_8UC1 (mono8) unless stated otherwise
};

// An external trigger / special event (DAVIS trigger input, Prophesee EXT_TRIGGER), kept apart
// from the CD (contrast detection) event stream.
struct Trigger {
  int64_t t_ns = 0;
  int32_t channel = 0;  // trigger input id as the format states it
  int8_t polarity = 1;  // +1 rising edge, -1 falling edge (or the format's pulse type)
};

// Sensor geometry in pixels; 0 means unknown.
struct SensorSize {
  int width = 0;
  int height = 0;
  bool known() const { return width > 0 && height > 0; }
};

}  // namespace evio
