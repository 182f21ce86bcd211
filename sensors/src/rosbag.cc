#include "evio/sensors/rosbag.h"

#include <algorithm>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "ros_messages.h"
#include "rosbag_container.h"

namespace evio {
namespace {

using namespace detail::rosbag;  // NOLINT: the bag container

// A ROS1 bag as a message source: one topic per connection, messages in chunk order.
class Ros1Cursor final : public detail::ros::MessageCursor {
 public:
  Ros1Cursor(const Bag& bag, std::vector<uint32_t> conns) : bag_(bag), cursor_(bag, std::move(conns)) {}

  bool next(detail::ros::MessageView* m) override {
    if (!cursor_.next(&msg_)) return false;
    m->topic = bag_.by_id.at(msg_.conn->id);
    m->data = msg_.data;
    m->size = msg_.size;
    return true;
  }
  std::string at(uint64_t k) const override { return msg_.where->at(msg_.off + k); }
  double progress() const override { return cursor_.progress(); }

 private:
  const Bag& bag_;
  detail::rosbag::MessageCursor cursor_;
  Message msg_;
};

class Ros1Source final : public detail::ros::MessageSource {
 public:
  explicit Ros1Source(const std::string& path) : bag_(open_bag(path)) {
    for (const Connection& c : bag_->connections) {
      topics_.push_back(detail::ros::Topic{c.topic, c.type, "ros1", c.messages});
    }
  }
  const std::string& path() const override { return bag_->path; }
  const std::vector<detail::ros::Topic>& topics() const override { return topics_; }
  std::unique_ptr<detail::ros::MessageCursor> cursor(const std::vector<size_t>& topics, int64_t /*start_ns*/) const override {
    std::vector<uint32_t> conns;
    for (size_t i : topics) conns.push_back(bag_->connections[i].id);
    return std::make_unique<Ros1Cursor>(*bag_, std::move(conns));
  }
  DatasetFormat format() const override { return DatasetFormat::kRosbag; }
  std::string describe() const override {
    return "ROS bag 2.0, " + std::to_string(bag_->connections.size()) + " connection(s), " +
           std::to_string(bag_->chunks.size()) + " chunk(s)";
  }
  std::string container_name() const override { return "ROS1 bag"; }

 private:
  std::shared_ptr<Bag> bag_;
  std::vector<detail::ros::Topic> topics_;
};

}  // namespace

std::unique_ptr<DatasetReader> open_rosbag_dataset(const std::string& path, const DatasetOptions& options) {
  std::string why;
  if (!options.Validate(&why)) throw InputError(path, 0, "invalid dataset options: " + why);
  return detail::ros::open_ros_dataset(std::make_unique<Ros1Source>(path), options);
}

}  // namespace evio
