// `evio simulate`: the scene config is parsed (simulator::load_simulation_config), the fast deterministic outputs
// (calibration, resolved config, poses, velocities, IMU) are written first, then the simulator
// streams events, frames and ground-truth views into the folder through one SimulationSink.
// Wall-clock figures go to simulation.json only, so every other file is byte-identical for the
// same config and seed.
#include "simulate_command.h"
#include "evio/calib/json.h"
#include "progress.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <ostream>
#include <sstream>
#include <stdexcept>


#include "evio/calib/calibration_io.h"
#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio/sensors/ecd.h"
#include "evio/sensors/h5.h"
#include "evio/sensors/image_io.h"
#include "evio/simulator/imu.h"
#include "evio/simulator/simulator.h"
#include "evio/sensors/time.h"
#include "evio/sensors/trajectory.h"

namespace evio::apps {
namespace {
namespace fs = std::filesystem;

constexpr const char* kWritable = "a writable output folder with free space";

// A FILE* that throws on failure and closes on scope exit.
class OutFile {
 public:
  explicit OutFile(std::string path) : path_(std::move(path)), f_(std::fopen(path_.c_str(), "wb")) {
    if (f_ == nullptr) throw InputError(path_, 0, "cannot create file", kWritable);
  }
  ~OutFile() {
    if (f_ != nullptr) std::fclose(f_);
  }
  OutFile(const OutFile&) = delete;
  OutFile& operator=(const OutFile&) = delete;
  void print(const char* fmt, ...) __attribute__((format(printf, 2, 3))) {
    va_list args;
    va_start(args, fmt);
    ok_ = std::vfprintf(f_, fmt, args) >= 0 && ok_;
    va_end(args);
  }
  void write(const void* data, size_t n) { ok_ = std::fwrite(data, 1, n, f_) == n && ok_; }
  void close() {
    if (f_ == nullptr) return;
    const bool closed = std::fclose(f_) == 0;
    f_ = nullptr;
    if (!closed || !ok_) throw InputError(path_, 0, "write failed", kWritable);
  }

 private:
  std::string path_;
  std::FILE* f_;
  bool ok_ = true;
};


void write_text(const std::string& path, const std::string& text) {
  OutFile f(path);
  f.write(text.data(), text.size());
  f.close();
}

// Linear texture -> 8-bit display image (gamma 2.2, scaled by the maximum).
cv::Mat display_image(const cv::Mat& linear) {
  double lo = 0, hi = 0;
  cv::minMaxLoc(linear, &lo, &hi);
  cv::Mat out(linear.size(), CV_8U);
  const double scale = hi > 0 ? 1.0 / hi : 1.0;
  for (int y = 0; y < linear.rows; ++y) {
    const float* in = linear.ptr<float>(y);
    uint8_t* o = out.ptr<uint8_t>(y);
    for (int x = 0; x < linear.cols; ++x) {
      const double v = std::clamp(in[x] * scale, 0.0, 1.0);
      o[x] = static_cast<uint8_t>(std::lround(255.0 * std::pow(v, 1.0 / 2.2)));
    }
  }
  return out;
}

// Streams the simulator's outputs into the folder.
class FolderSink final : public simulator::SimulationSink {
 public:
  FolderSink(const simulator::SimulationConfig& c, const fs::path& dir, int64_t bin_ns)
      : c_(c),
        dir_(dir),
        events_((dir / "events.txt").string(), PolarityConvention::kZeroOne),
        bin_ns_(bin_ns),
        bins_(std::max<int64_t>(1, (c.simulator.t_end_ns - c.simulator.t_begin_ns + bin_ns - 1) / bin_ns), 0) {
    if (c.write_h5) {
      H5WriteOptions o;
      o.sensor = SensorSize{c.camera.camera.width(), c.camera.camera.height()};
      h5_ = std::make_unique<H5EventWriter>((dir / "events.h5").string(), o);
    }
    if (c.ground_truth.event_labels) labels_ = std::make_unique<OutFile>((dir / "event_labels.txt").string());
    if (c.simulator.frames.rate_hz > 0) {
      fs::create_directories(dir / "images");
      images_ = std::make_unique<OutFile>((dir / "images.txt").string());
    }
    const simulator::GroundTruthConfig& g = c.ground_truth;
    if (!c.simulator.ground_truth_times_ns.empty()) {
      maps_ = std::make_unique<OutFile>((dir / "ground_truth_maps.txt").string());
      maps_->print("# index t_body[s] t_cam[s] T_w_c: tx ty tz qx qy qz qw (maps are <kind>/<index>.npy|png)\n");
      if (g.depth) fs::create_directories(dir / "depth");
      if (g.flow) fs::create_directories(dir / "flow");
      if (g.intensity) fs::create_directories(dir / "intensity");
      if (g.labels) fs::create_directories(dir / "labels");
    }
  }

  void on_events(const std::vector<Event>& events, const std::vector<uint16_t>* labels) override {
    if (events.empty()) return;
    const std::vector<Event>* out = &events;
    if (c_.clock_offset_ns != 0) {  // output.clock_offset_ns: the written stamps only
      shifted_ = events;
      for (Event& e : shifted_) e.t_ns += c_.clock_offset_ns;
      out = &shifted_;
    }
    const EventSpan span(out->data(), out->size());
    events_.write(span);
    if (h5_) h5_->write(span);
    if (labels_) {
      if (labels == nullptr || labels->size() != events.size()) {
        throw std::logic_error("simulator gave no per-event labels although event labels are on");
      }
      for (uint16_t l : *labels) labels_->print("%u\n", static_cast<unsigned>(l));
    }
    for (const Event& e : events) {
      e.polarity > 0 ? ++on_ : ++off_;
      // Bins over the body-clock span; an event at exactly t_end counts in the last bin.
      const int64_t bin = std::min<int64_t>((e.t_ns - c_.simulator.t_begin_ns + c_.simulator.time_shift_ns) / bin_ns_,
                                            static_cast<int64_t>(bins_.size()) - 1);
      if (bin >= 0) ++bins_[bin];
    }
  }

  void on_frame(const Frame& frame) override {
    if (!images_) return;
    char name[64];
    std::snprintf(name, sizeof(name), "images/frame_%08zu.png", frame_count_++);
    const std::string path = (dir_ / name).string();
    if (!write_image(path, frame.image)) throw InputError(path, 0, "cannot write image", kWritable);
    images_->print("%s %s\n", format_seconds(frame.t_ns + c_.clock_offset_ns).c_str(), name);
  }

  void on_ground_truth(const simulator::RenderedView& view, const simulator::CameraState& camera) override {
    if (!maps_) return;
    char name[32];
    std::snprintf(name, sizeof(name), "%06zu", map_count_++);
    const simulator::GroundTruthConfig& g = c_.ground_truth;
    if (g.depth && !view.depth.empty()) write_npy_float32((dir_ / "depth" / (std::string(name) + ".npy")).string(), view.depth);
    if (g.flow && !view.flow.empty()) write_npy_float32((dir_ / "flow" / (std::string(name) + ".npy")).string(), view.flow);
    if (g.intensity && !view.intensity.empty()) {
      write_npy_float32((dir_ / "intensity" / (std::string(name) + ".npy")).string(), view.intensity);
    }
    if (g.labels && !view.label.empty()) {
      const std::string path = (dir_ / "labels" / (std::string(name) + ".png")).string();
      if (!write_image(path, view.label)) throw InputError(path, 0, "cannot write label image", kWritable);
    }
    const calib::SE3& T = camera.T_w_c;
    const int64_t t = view.t_ns + c_.clock_offset_ns;
    maps_->print("%s %s %s %.17g %.17g %.17g %.17g %.17g %.17g %.17g\n", name, format_seconds(t).c_str(),
                 format_seconds(t - c_.simulator.time_shift_ns).c_str(), T.translation.x(),
                 T.translation.y(), T.translation.z(), T.rotation.x(), T.rotation.y(), T.rotation.z(),
                 T.rotation.w());
  }

  void close() {
    events_.close();
    if (h5_) h5_->close();
    if (labels_) labels_->close();
    if (images_) images_->close();
    if (maps_) maps_->close();
  }

  uint64_t on() const { return on_; }
  uint64_t off() const { return off_; }
  size_t frames() const { return frame_count_; }
  size_t maps() const { return map_count_; }
  const std::vector<uint64_t>& bins() const { return bins_; }

 private:
  const simulator::SimulationConfig& c_;
  fs::path dir_;
  EcdEventWriter events_;
  std::unique_ptr<H5EventWriter> h5_;
  std::unique_ptr<OutFile> labels_, images_, maps_;
  int64_t bin_ns_;
  std::vector<uint64_t> bins_;
  std::vector<Event> shifted_;  // a step's events with output.clock_offset_ns added
  uint64_t on_ = 0, off_ = 0;
  size_t frame_count_ = 0, map_count_ = 0;
};

// groundtruth.txt (TUM, body pose in world) and velocities.txt at the pose rate.
size_t write_poses(const simulator::SimulationConfig& c, const fs::path& dir) {
  const int64_t t0 = c.simulator.t_begin_ns, t1 = c.simulator.t_end_ns;
  const int64_t period = std::max<int64_t>(1, std::llround(1e9 / c.ground_truth.pose_rate_hz));
  Trajectory poses;
  OutFile vel((dir / "velocities.txt").string());
  vel.print("# t[s] v_w[m/s](x y z) omega_b[rad/s](x y z) a_w[m/s^2](x y z, no gravity) alpha_b[rad/s^2](x y z)\n");
  for (int64_t t = t0; t <= t1; t += period) {
    const simulator::TrajectoryState s = c.trajectory->evaluate(t);
    poses.push_back({t + c.clock_offset_ns, s.T_w_b});
    vel.print("%s %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g %.17g\n", format_seconds(t + c.clock_offset_ns).c_str(),
              s.v_w.x(), s.v_w.y(), s.v_w.z(), s.omega_b.x(), s.omega_b.y(), s.omega_b.z(), s.a_w.x(), s.a_w.y(),
              s.a_w.z(), s.alpha_b.x(), s.alpha_b.y(), s.alpha_b.z());
  }
  vel.close();
  write_tum((dir / "groundtruth.txt").string(), poses);
  return poses.size();
}

size_t write_imu(const simulator::SimulationConfig& c, const fs::path& dir) {
  std::vector<simulator::ImuBiasSample> biases;
  std::vector<ImuSample> imu = simulator::simulate_imu(*c.trajectory, c.simulator.t_begin_ns, c.simulator.t_end_ns, c.imu, &biases);
  for (ImuSample& s : imu) s.t_ns += c.clock_offset_ns;
  write_ecd_imu((dir / "imu.txt").string(), imu);
  OutFile b((dir / "imu_biases.txt").string());
  b.print("# t[s] bias_gyro[rad/s](x y z) bias_accel[m/s^2](x y z)\n");
  for (const simulator::ImuBiasSample& s : biases) {
    b.print("%s %.17g %.17g %.17g %.17g %.17g %.17g\n", format_seconds(s.t_ns + c.clock_offset_ns).c_str(), s.gyro.x(), s.gyro.y(),
            s.gyro.z(), s.accel.x(), s.accel.y(), s.accel.z());
  }
  b.close();
  return imu.size();
}

}  // namespace

void write_npy_float32(const std::string& path, const cv::Mat& image) {
  if (image.depth() != CV_32F || image.dims != 2) {
    throw std::invalid_argument("write_npy_float32: expects a 2-D CV_32F image");
  }
  std::string shape = "(" + std::to_string(image.rows) + ", " + std::to_string(image.cols);
  shape += image.channels() == 1 ? ")" : ", " + std::to_string(image.channels()) + ")";
  std::string header = "{'descr': '<f4', 'fortran_order': False, 'shape': " + shape + ", }";
  // magic (6) + version (2) + header length (2) + header, padded with spaces to a multiple of 64
  // and ended by '\n' (NumPy format 1.0).
  const size_t total = 10 + header.size() + 1;
  header += std::string((64 - total % 64) % 64, ' ') + "\n";
  OutFile f(path);
  const unsigned char preamble[10] = {0x93, 'N', 'U', 'M', 'P', 'Y', 1, 0,
                                      static_cast<unsigned char>(header.size() & 0xFF),
                                      static_cast<unsigned char>(header.size() >> 8)};
  f.write(preamble, sizeof(preamble));
  f.write(header.data(), header.size());
  const size_t row_bytes = static_cast<size_t>(image.cols) * image.channels() * sizeof(float);
  for (int y = 0; y < image.rows; ++y) f.write(image.ptr<float>(y), row_bytes);  // x86/ARM hosts: little-endian
  f.close();
}

int run_simulate(const SimulateArgs& args, std::ostream& out) {
  const auto wall_start = std::chrono::steady_clock::now();
  simulator::SimulationConfig c = simulator::load_simulation_config(args.scene, args.overrides);
  c.simulator.threads = args.threads;
  const fs::path dir(args.out);
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (!fs::is_directory(dir, ec)) throw InputError(args.out, 0, "cannot create the output folder", kWritable);

  std::unique_ptr<simulator::Simulator> sim;
  try {
    sim = std::make_unique<simulator::Simulator>(c.scene, c.trajectory, c.simulator);
  } catch (const std::invalid_argument& e) {
    throw InputError(args.scene, 0, std::string("the simulator rejected the configuration: ") + e.what(),
                     "a scene YAML as documented in datasets/README.md");
  }

  // Deterministic, fast outputs first.
  write_text((dir / "scene_resolved.yaml").string(),
             "# " + c.path + " as simulated: overrides applied, seeds, duration and paths resolved.\n" + c.resolved_yaml);
  const calib::CameraIntrinsics& intr = c.camera.camera.intrinsics();
  if (intr.model != calib::DistortionModel::kEquidistant) write_ecd_calib((dir / "calib.txt").string(), c.camera.camera);
  calib::write_kalibr_camchain((dir / "calib.yaml").string(), {c.camera}, &c.imu.noise);
  const size_t poses = write_poses(c, dir);
  const size_t imu_samples = c.imu_enabled ? write_imu(c, dir) : 0;
  if (c.panorama && c.write_panorama) {
    write_npy_float32((dir / "panorama.npy").string(), c.panorama->level(0));
    const std::string png = (dir / "panorama.png").string();
    if (!write_image(png, display_image(c.panorama->level(0)))) throw InputError(png, 0, "cannot write", kWritable);
  }

  // The simulation.
  const int64_t span_ns = c.simulator.t_end_ns - c.simulator.t_begin_ns;
  const int64_t bin_ns = span_ns >= 1'000'000'000 ? 100'000'000 : std::max<int64_t>(1'000'000, span_ns / 10);
  FolderSink sink(c, dir, bin_ns);
  Progress progress("evio simulate", args.progress, "events", 1.0);
  if (args.progress) {
    std::fprintf(stderr, "evio simulate: %s, %dx%d, %.3f s (%s)\n", c.scene->describe().c_str(), intr.width,
                 intr.height, c.duration_s, c.trajectory->describe().c_str());
  }
  const simulator::SimulationStats stats =
      sim->run(&sink, [&progress](double f, uint64_t n) { progress.update(f, n); });
  sink.close();
  const double total_wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();

  // simulation.json: counts, rates, timing (the only file with wall-clock figures).
  const double duration_s = ns_to_seconds(span_ns);
  const uint64_t events = sink.on() + sink.off();
  std::ostringstream j;
  j << "{\n";
  j << "  \"scene_file\": \"" << json_escape(c.path) << "\",\n";
  j << "  \"description\": \"" << json_escape(c.description) << "\",\n";
  j << "  \"seed\": " << c.seed << ",\n";
  j << "  \"scene\": {\"type\": \"" << c.scene_type << "\", \"describe\": \"" << json_escape(c.scene->describe())
    << "\"},\n";
  j << "  \"camera\": {\"preset\": \"" << c.camera_preset << "\", \"width\": " << intr.width
    << ", \"height\": " << intr.height << ", \"model\": \"" << calib::distortion_model_name(intr.model)
    << "\", \"supersample\": " << c.simulator.supersample << "},\n";
  j << "  \"trajectory\": {\"type\": \"" << c.trajectory_type << "\", \"describe\": \""
    << json_escape(c.trajectory->describe()) << "\"";
  if (!c.trajectory_file.empty()) j << ", \"file\": \"" << json_escape(c.trajectory_file) << "\"";
  if (c.fit_report) {
    const simulator::SplineFitReport& r = *c.fit_report;
    j << ", \"fit\": {\"samples\": " << r.samples << ", \"control_points\": " << r.control_points
      << ", \"iterations\": " << r.iterations << ", \"position_rms_m\": " << json_number(r.position_rms_m, 9)
      << ", \"position_max_m\": " << json_number(r.position_max_m, 9) << ", \"rotation_rms_deg\": " << json_number(r.rotation_rms_deg, 9)
      << ", \"rotation_max_deg\": " << json_number(r.rotation_max_deg, 9) << "}";
  }
  j << "},\n";
  j << "  \"span_s\": [" << format_seconds(c.simulator.t_begin_ns) << ", " << format_seconds(c.simulator.t_end_ns)
    << "],\n";
  j << "  \"duration_s\": " << json_number(duration_s, 9) << ",\n";
  j << "  \"events\": {\"count\": " << events << ", \"on\": " << sink.on() << ", \"off\": " << sink.off()
    << ", \"rate_hz\": " << json_number(duration_s > 0 ? events / duration_s : 0.0, 9) << "},\n";
  j << "  \"event_rate_timeline\": {\"bin_s\": " << json_number(ns_to_seconds(bin_ns), 9) << ", \"rate_hz\": [";
  for (size_t i = 0; i < sink.bins().size(); ++i) j << (i ? ", " : "") << json_number(sink.bins()[i] / ns_to_seconds(bin_ns), 9);
  j << "]},\n";
  j << "  \"steps\": " << stats.steps << ",\n";
  j << "  \"step_s\": {\"min\": " << json_number(ns_to_seconds(stats.min_step_ns), 9) << ", \"max\": "
    << json_number(ns_to_seconds(stats.max_step_ns), 9) << ", \"mean\": "
    << json_number(stats.steps > 0 ? duration_s / static_cast<double>(stats.steps) : 0.0, 9) << "},\n";
  j << "  \"max_flow_pxps\": " << json_number(stats.max_flow_pxps, 9) << ",\n";
  j << "  \"frames\": " << sink.frames() << ",\n";
  j << "  \"imu_samples\": " << imu_samples << ",\n";
  j << "  \"poses\": " << poses << ",\n";
  j << "  \"ground_truth_maps\": " << sink.maps() << ",\n";
  j << "  \"wall_s\": {\"simulation\": " << json_number(stats.wall_s, 9) << ", \"render\": " << json_number(stats.render_s, 9)
    << ", \"events\": " << json_number(stats.events_s, 9) << ", \"total\": " << json_number(total_wall_s, 9) << "},\n";
  j << "  \"realtime_factor\": " << json_number(stats.wall_s > 0 ? duration_s / stats.wall_s : 0.0, 9) << ",\n";
  j << "  \"events_per_wall_s\": " << json_number(stats.wall_s > 0 ? events / stats.wall_s : 0.0, 9) << "\n";
  j << "}\n";
  write_text((dir / "simulation.json").string(), j.str());

  char line[256];
  std::snprintf(line, sizeof(line),
                "simulated %.3f s: %llu events (%.0f ev/s), %llu steps, %zu frames, %zu IMU samples in %.2f s wall "
                "(%.2fx real time) -> %s\n",
                duration_s, static_cast<unsigned long long>(events), duration_s > 0 ? events / duration_s : 0.0,
                static_cast<unsigned long long>(stats.steps), sink.frames(), imu_samples, stats.wall_s,
                stats.wall_s > 0 ? duration_s / stats.wall_s : 0.0, args.out.c_str());
  out << line;
  return 0;
}

}  // namespace evio::apps
