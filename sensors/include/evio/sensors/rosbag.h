// ROS1 bag reader without ROS, per the ROS wiki "Bags/Format/2.0" and rosbag_storage (chunks none,
// bz2, or lz4 frames as roslz4 writes them), decoding dvs_msgs/EventArray,
// prophesee_event_msgs/EventArray, event_camera_msgs/EventPacket (evt3, evt2, mono),
// sensor_msgs/Imu and sensor_msgs/Image (ROS1 little-endian serialisation). The message decoders
// are shared with the ROS 2 bag reader (rosbag2.h).
#pragma once

#include <memory>
#include <string>

#include "evio/sensors/dataset.h"

namespace evio {

// Opens a ROS1 bag (v2.0). Topics come from options.topics: an empty name picks the single topic of
// the matching message type (no such topic: that stream is empty; several: an InputError listing
// them); a named topic that is missing or of the wrong type is an InputError.
//
// Listing (streams()): from the bag's index (connection and chunk info records at index_pos),
// without decompressing chunks. A bag without index (index_pos = 0, a recording that was not
// closed) is scanned linearly once when opened, which is logged. Opening also decompresses the
// first chunk holding an event message, for the sensor size.
//
// Events stream chunk by chunk in file order, one decompressed chunk in memory at a time.
//  - dvs_msgs/EventArray and prophesee_event_msgs/EventArray (the same layout): t_ns = ROS time of
//    each event (uint32 sec, uint32 nsec); bool polarity true -> +1, false -> -1.
//  - event_camera_msgs/EventPacket, encoding "evt3" (or "evt2"): the payload is decoded by one
//    Evt3Decoder (Evt2Decoder) whose state carries across the packets of the topic (as
//    event_camera_codecs does). EVT carries sensor time only (time_base is undefined for evt3),
//    so events are put on the ROS clock like the event_camera tools do: t_ns = sensor_us * 1000 +
//    (header.stamp of the first packet that has a sensor time - the first sensor time decoded in
//    that packet). EXT_TRIGGER words go to read_triggers() with the same clock. Encoding "mono"
//    (64-bit words: bit 63 polarity, bits 48-62 y, 32-47 x, 0-31 dt): t_ns = header.stamp + dt.
//    Other encodings are an InputError.
// The sensor size is the width x height of the first event message (options.text.sensor when that
// message states 0 x 0). Events outside it or going back in time are bad data handled by
// options.text.on_bad_line; messages name the byte offset of the message. event_report().lines
// counts event messages read.
//
// Bad input is an InputError naming the byte offset and the expected form: in a compressed chunk
// the offset is into the decompressed chunk, with the chunk's file offset. Limits: record headers
// up to 1 MiB, connection records up to 16 MiB, chunks up to 1 GiB (decompression buffers grow
// with the data actually produced, so a false size field allocates nothing up front).
//
// read_imu(): sensor_msgs/Imu, header.stamp, angular_velocity [rad/s] and linear_acceleration
// [m/s^2] as stored (ROS messages are SI). read_frames(): sensor_msgs/Image at header.stamp;
// "mono8"/"8UC1" is copied (respecting step), "mono16"/"16UC1" keeps the high byte,
// "rgb8"/"bgr8"/"rgba8"/"bgra8" are converted to grey with the ITU-R BT.601 weights 0.299 R +
// 0.587 G + 0.114 B (OpenCV's fixed-point rounding); other encodings are an InputError naming the
// encoding.
std::unique_ptr<DatasetReader> open_rosbag_dataset(const std::string& path, const DatasetOptions& options);

}  // namespace evio
