// Writes a deterministic synthetic sequence in the Event Camera Dataset layout: events of a
// vertical edge sweeping across the sensor (with random background activity), a 1 kHz IMU of a
// camera yawing at constant rate, 100 Hz ground-truth poses of that rotation, and a DAVIS240C
// calib.txt. For benchmarks and the demo; the simulator (sensors) is the tool for ground truth.
#pragma once

#include <cstdint>
#include <string>

#include "evio/sensors/event_buffer.h"

namespace evio::bench {

struct SequenceSpec {
  int64_t events = 100000;   // number of events
  double event_rate_hz = 1e6;  // mean event rate, events/s
  int width = 240, height = 180;  // px
  bool side_files = true;    // also imu.txt, groundtruth.txt, calib.txt
  uint64_t seed = 1;
};

// The events of the sequence (edge sweep + background activity), in time order.
EventBuffer make_synthetic_events(const SequenceSpec& spec);

// Creates dir if needed; returns the path of events.txt.
std::string make_ecd_sequence(const std::string& dir, const SequenceSpec& spec);

}  // namespace evio::bench
