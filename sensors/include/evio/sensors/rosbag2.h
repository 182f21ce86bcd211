// ROS 2 bag (rosbag2) reader without ROS: SQLite3 (.db3) and MCAP (.mcap) storage, CDR messages.
#pragma once

#include <memory>
#include <string>

#include "evio/sensors/dataset.h"

namespace evio {

// True when `path` is a folder holding a rosbag2 metadata.yaml, or no metadata but .db3 / .mcap
// files.
bool is_rosbag2_folder(const std::string& path);

// Opens a ROS 2 bag:
//  - a bag folder: metadata.yaml (rosbag2_bagfile_information: storage_identifier sqlite3 or mcap,
//    relative_file_paths read in the order listed, i.e. split bags in order; the topics' message
//    counts; compression_format zstd with compression_mode file or message). Without metadata.yaml,
//    the folder's .db3 or .mcap files in name order;
//  - metadata.yaml itself (its folder), or one .db3 / .mcap file.
// Storage:
//  - SQLite3 (Debian's libsqlite3, opened read-only and immutable): tables topics (id, name, type,
//    serialization_format) and messages (topic_id, timestamp, data), read in (timestamp, id) order,
//    one row in memory at a time.
//  - MCAP (read from the published specification): chunks uncompressed, lz4 or zstd, one
//    decompressed chunk in memory at a time; channels and counts from the summary section when
//    present, otherwise from one linear scan (a recording that was not closed; logged). Messages
//    in file order.
// Messages are CDR (serialization_format / message_encoding "cdr", little- or big-endian plain
// CDR); the types, topic choice (options.topics, or the only topic of each kind) and timestamps
// are as for ROS1 bags (rosbag.h), with the ROS 2 type names (e.g. event_camera_msgs/msg/
// EventPacket) and builtin_interfaces/Time stamps (int32 sec, uint32 nanosec):
//  - events: dvs_msgs/msg/EventArray and prophesee_event_msgs/msg/EventArray (each event's own
//    stamp); event_camera_msgs/msg/EventPacket with encoding evt3 or evt2 (sensor time put on the
//    ROS clock by the header stamp of the first packet with a sensor time; EXT_TRIGGER words go to
//    read_triggers(), apart from CD events) or mono (header.stamp + dt in ns);
//  - sensor_msgs/msg/Imu and sensor_msgs/msg/Image at header.stamp (mono8/8UC1, mono16/16UC1 by
//    their high byte, rgb8/bgr8/rgba8/bgra8 to grey by BT.601).
// Bad input is an InputError naming the file, the record or row and the byte offset. Events
// decoded before damage in the container are returned first; the error comes with the next read.
std::unique_ptr<DatasetReader> open_rosbag2_dataset(const std::string& path, const DatasetOptions& options);

}  // namespace evio
