// iniVation AEDAT 4.0 reader (DV / dv-processing recordings): "#!AER-DAT4.0\r\n", an int32 size
// and an IOHeader flatbuffer (compression, dataTablePosition, infoNode XML naming the streams),
// then packets (int32 stream id, int32 size, a size-prefixed flatbuffer compressed with LZ4
// frames, LZ4 high, Zstd or nothing) and an optional FileDataTable. Schemas: dv-processing
// events.fbs (EVTS), imu.fbs (IMUS), frame.fbs (FRME), trigger.fbs (TRIG), IOHeader.fbs,
// FileDataTable.fbs; the flatbuffers are read directly with bounds-checked little-endian reads.
//
// Conventions applied (also in event_report()):
// - time: int64 microseconds -> t_ns = t_us * 1000 (the file's absolute timestamps are kept);
// - events: polarity bool true (ON) -> +1, false (OFF) -> -1 (reported as convention 0/1);
// - IMU: accelerometer in g * 9.80665 m/s^2 per g (standard gravity), gyroscope in deg/s *
//   pi/180 -> rad/s; absent flatbuffer fields take their schema default (0);
// - frames: t_ns is the exposure midpoint (timestampStartOfExposure + timestampEndOfExposure) / 2
//   when both fields are present and ordered, else the frame's `timestamp`; GRAY pixels give a
//   CV_8UC1 image, BGR / BGRA are converted to grey (0.299 R + 0.587 G + 0.114 B); the image is
//   the stored region (positionX/positionY are not applied);
// - triggers: channel = dv::TriggerType value (0 timestamp reset, 1/2/3 external input
//   rising/falling/pulse, 4/5 generator rising/falling, 6/7 APS frame start/end, 8/9 APS exposure
//   start/end); polarity -1 for the falling-edge types 2 and 5, +1 otherwise.
// The first stream of each type (lowest stream id) is read; sensor size comes from the event
// stream's sizeX/sizeY in the infoNode (TextReadOptions::sensor when the file states none).
#pragma once

#include <memory>
#include <string>

#include "evio/sensors/dataset.h"

namespace evio {

// Opens an AEDAT 4.0 file: reads and validates the header, the stream list and (when present)
// the file data table. Throws InputError naming the file, the byte offset and the expected form
// on any malformed input; read_events / read_imu / read_frames / read_triggers throw the same way
// on corrupt packets.
std::unique_ptr<DatasetReader> open_aedat4_dataset(const std::string& path, const DatasetOptions& options);

}  // namespace evio
