#include "evio/sensors/h5.h"

#include <hdf5.h>

#include <algorithm>
#include <chrono>
#include <iterator>
#include <thread>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <random>

#include <gtest/gtest.h>

#include "evio/calib/error.h"
#include "evio/calib/log.h"
#include "evio/sensors/ecd.h"
#include "evio_test/fuzz_seed.h"
#include "evio_test/real_data.h"
#include "evio_test/temp_dir.h"

#if defined(__SANITIZE_ADDRESS__)
#include <dlfcn.h>
// HDF5 dlopens its filter plugins (Blosc, ...) from its plugin folder and unloads them at exit. The
// blocks a plugin keeps in its globals (3,392 bytes from posix_memalign) then lose their only
// reference, and LeakSanitizer reported them as leaks from "<unknown module>" (H5Compression.*).
// With the plugins kept mapped (RTLD_NODELETE) those globals are still scanned and nothing is
// reported: no suppression, and a real leak would still show.
static const bool kKeepHdf5FilterPluginsMapped = [] {
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator("/usr/lib/x86_64-linux-gnu/hdf5/serial/plugins", ec)) {
    if (e.path().extension() == ".so") dlopen(e.path().c_str(), RTLD_LAZY | RTLD_LOCAL | RTLD_NODELETE);
  }
  return true;
}();
#endif

namespace evio {
namespace {

using evio_test::TempDir;

// ---------------------------------------------------------------------------------------------
// A minimal raw HDF5 writer for layouts that evio does not write itself (DSEC without unit
// attributes, event_utils, MVSEC) and for malformed files.

template <typename T> hid_t native();
template <> hid_t native<uint8_t>() { return H5T_NATIVE_UINT8; }
template <> hid_t native<int8_t>() { return H5T_NATIVE_INT8; }
template <> hid_t native<uint16_t>() { return H5T_NATIVE_UINT16; }
template <> hid_t native<int16_t>() { return H5T_NATIVE_INT16; }
template <> hid_t native<uint32_t>() { return H5T_NATIVE_UINT32; }
template <> hid_t native<int32_t>() { return H5T_NATIVE_INT32; }
template <> hid_t native<uint64_t>() { return H5T_NATIVE_UINT64; }
template <> hid_t native<int64_t>() { return H5T_NATIVE_INT64; }
template <> hid_t native<double>() { return H5T_NATIVE_DOUBLE; }

class RawH5 {
 public:
  explicit RawH5(const std::string& path) : file_(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT)) {
    EXPECT_GE(file_, 0) << path;
  }
  ~RawH5() { close(); }
  void close() {
    if (file_ >= 0) H5Fclose(file_);
    file_ = -1;
  }
  hid_t id() const { return file_; }

  // A dataset of the given shape (1-D by default) with file type ftype (default: T's native type).
  template <typename T>
  hid_t put(const std::string& name, const std::vector<T>& v, std::vector<hsize_t> dims = {}, hid_t ftype = -1,
            hid_t dcpl = H5P_DEFAULT, hid_t mtype = -1) {
    if (dims.empty()) dims = {v.size()};
    hid_t space = H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr);
    hid_t lcpl = H5Pcreate(H5P_LINK_CREATE);
    H5Pset_create_intermediate_group(lcpl, 1);
    hid_t ds = H5Dcreate2(file_, name.c_str(), ftype >= 0 ? ftype : native<T>(), space, lcpl, dcpl, H5P_DEFAULT);
    EXPECT_GE(ds, 0) << name;
    if (!v.empty()) {
      EXPECT_GE(H5Dwrite(ds, mtype >= 0 ? mtype : native<T>(), H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data()), 0) << name;
    }
    H5Pclose(lcpl);
    H5Sclose(space);
    return ds;  // caller may add attributes; closed by put_* wrappers or close_ds()
  }
  template <typename T>
  void column(const std::string& name, const std::vector<T>& v, hid_t dcpl = H5P_DEFAULT) {
    H5Dclose(put(name, v, {}, -1, dcpl));
  }
  template <typename T>
  void scalar(const std::string& name, T value, const char* unit = nullptr) {
    hid_t space = H5Screate(H5S_SCALAR);
    hid_t ds = H5Dcreate2(file_, name.c_str(), native<T>(), space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    H5Dwrite(ds, native<T>(), H5S_ALL, H5S_ALL, H5P_DEFAULT, &value);
    if (unit != nullptr) string_attr(ds, "unit", unit);
    H5Dclose(ds);
    H5Sclose(space);
  }
  static void string_attr(hid_t obj, const char* name, const std::string& value) {
    hid_t type = H5Tcopy(H5T_C_S1);
    H5Tset_size(type, value.size() + 1);
    hid_t space = H5Screate(H5S_SCALAR);
    hid_t a = H5Acreate2(obj, name, type, space, H5P_DEFAULT, H5P_DEFAULT);
    H5Awrite(a, type, value.c_str());
    H5Aclose(a);
    H5Sclose(space);
    H5Tclose(type);
  }
  static void int_attr(hid_t obj, const char* name, int64_t value) {
    hid_t space = H5Screate(H5S_SCALAR);
    hid_t a = H5Acreate2(obj, name, H5T_STD_I64LE, space, H5P_DEFAULT, H5P_DEFAULT);
    H5Awrite(a, H5T_NATIVE_INT64, &value);
    H5Aclose(a);
    H5Sclose(space);
  }

 private:
  hid_t file_ = -1;
};

// h5py's bool: an enum {FALSE = 0, TRUE = 1} over int8.
hid_t bool_type() {
  hid_t t = H5Tenum_create(H5T_NATIVE_INT8);
  int8_t v = 0;
  H5Tenum_insert(t, "FALSE", &v);
  v = 1;
  H5Tenum_insert(t, "TRUE", &v);
  return t;
}

std::vector<Event> random_events(size_t n, uint64_t seed, int64_t t0, int64_t max_step, int w = 640, int h = 480) {
  std::mt19937_64 rng(seed);
  std::vector<Event> ev(n);
  int64_t t = t0;
  for (Event& e : ev) {
    t += static_cast<int64_t>(rng() % static_cast<uint64_t>(max_step + 1));  // includes equal stamps
    e = Event{t, static_cast<uint16_t>(rng() % w), static_cast<uint16_t>(rng() % h), static_cast<int8_t>(rng() % 2 ? 1 : -1)};
  }
  return ev;
}

std::vector<Event> read_all(const std::string& path, const DatasetOptions& options = {}, ReadReport* report = nullptr,
                            size_t max_events = 100000) {
  evio_test::export_fuzz_seed(path, "fuzz_h5");
  EventBuffer buf;
  {
    auto reader = open_h5_dataset(path, options);
    while (reader->read_events(&buf, max_events) > 0) {
    }
    if (report != nullptr) *report = reader->event_report();
    EXPECT_DOUBLE_EQ(reader->progress(), 1.0);
  }
  EXPECT_EQ(h5_open_object_count(), 0) << "HDF5 handles left open after reading " << path;
  return buf.events();
}

void write_evio(const std::string& path, const std::vector<Event>& ev, H5WriteOptions o = {}, int64_t* rounded = nullptr) {
  H5EventWriter w(path, o);
  std::mt19937 rng(1);
  size_t i = 0;
  while (i < ev.size()) {  // uneven write() sizes, including empty ones
    const size_t k = std::min(ev.size() - i, static_cast<size_t>(rng() % 5000));
    w.write(EventSpan(ev.data() + i, k));
    i += k;
  }
  const int64_t r = w.close();
  EXPECT_EQ(w.events_written(), static_cast<int64_t>(ev.size()));
  if (rounded != nullptr) *rounded = r;
}

// Expects f() to throw an InputError whose message names the file and contains every fragment.
// With handles_closed, also checks that no HDF5 handle stays open (when no other reader or
// writer is alive).
void expect_error(const std::string& path, const std::function<void()>& f, const std::vector<std::string>& fragments,
                  bool handles_closed = true) {
  try {
    f();
    ADD_FAILURE() << "no error for " << path;
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(path), std::string::npos) << msg;
    for (const std::string& s : fragments) EXPECT_NE(msg.find(s), std::string::npos) << "'" << s << "' not in: " << msg;
  }
  if (handles_closed) {
    EXPECT_EQ(h5_open_object_count(), 0) << "HDF5 handles left open after the error for " << path;
  }
}

void expect_read_error(const std::string& path, const std::vector<std::string>& fragments, const DatasetOptions& o = {}) {
  evio_test::export_fuzz_seed(path, "fuzz_h5");
  expect_error(path, [&] { read_all(path, o); }, fragments);
}

// A DSEC file as DSEC ships it: relative uint32 us, int64 t_offset in us, no unit attributes.
struct DsecData {
  std::vector<uint16_t> x, y;
  std::vector<uint32_t> t;
  std::vector<uint8_t> p;
  int64_t t_offset_us = 0;
};

DsecData make_dsec(size_t n, uint64_t seed) {
  DsecData d;
  std::mt19937_64 rng(seed);
  d.t_offset_us = 1639152000000000LL + static_cast<int64_t>(rng() % 1000000);  // an epoch in us
  uint32_t t = 0;
  for (size_t i = 0; i < n; ++i) {
    t += static_cast<uint32_t>(rng() % 40);
    d.x.push_back(static_cast<uint16_t>(rng() % 640));
    d.y.push_back(static_cast<uint16_t>(rng() % 480));
    d.t.push_back(t);
    d.p.push_back(static_cast<uint8_t>(rng() % 2));
  }
  return d;
}

std::vector<uint64_t> ms_to_idx_us(const std::vector<uint32_t>& t) {
  std::vector<uint64_t> idx;
  if (t.empty()) return idx;
  for (uint64_t ms = 0; ms <= t.back() / 1000; ++ms) {
    idx.push_back(static_cast<uint64_t>(std::lower_bound(t.begin(), t.end(), ms * 1000) - t.begin()));
  }
  return idx;
}

void write_dsec(const std::string& path, const DsecData& d, bool with_index = true, hid_t dcpl = H5P_DEFAULT) {
  RawH5 f(path);
  f.column("events/x", d.x, dcpl);
  f.column("events/y", d.y, dcpl);
  f.column("events/t", d.t, dcpl);
  f.column("events/p", d.p, dcpl);
  f.scalar("t_offset", d.t_offset_us);
  if (with_index) f.column("ms_to_idx", ms_to_idx_us(d.t));
}

// ---------------------------------------------------------------------------------------------
// DSEC

TEST(H5Reader, ReadsDsecLayoutWrittenWithRawHdf5) {
  TempDir dir;
  const DsecData d = make_dsec(50000, 7);
  const std::string path = dir.file("dsec.h5");
  write_dsec(path, d);
  ReadReport rep;
  DatasetOptions o;
  o.text.sensor = SensorSize{640, 480};
  const std::vector<Event> ev = read_all(path, o, &rep, 3333);
  ASSERT_EQ(ev.size(), d.t.size());
  for (size_t i = 0; i < ev.size(); ++i) {
    const Event want{(static_cast<int64_t>(d.t[i]) + d.t_offset_us) * 1000, d.x[i], d.y[i],
                     static_cast<int8_t>(d.p[i] ? 1 : -1)};
    ASSERT_EQ(ev[i], want) << "event " << i;
  }
  EXPECT_EQ(rep.time_unit, TimeUnit::kMicroseconds);
  EXPECT_NE(rep.time_unit_reason.find("DSEC"), std::string::npos) << rep.time_unit_reason;
  EXPECT_EQ(rep.polarity, PolarityConvention::kZeroOne);
  EXPECT_EQ(rep.records, 50000);
  EXPECT_EQ(rep.path, path);

  auto reader = open_h5_dataset(path, o);
  auto* h5 = dynamic_cast<H5EventReader*>(reader.get());
  ASSERT_NE(h5, nullptr);
  EXPECT_EQ(h5->layout_name(), "DSEC");
  EXPECT_EQ(h5->event_count(), 50000);
  EXPECT_EQ(reader->format(), DatasetFormat::kHdf5);
  EXPECT_EQ(reader->sensor_size().width, 640);  // from the options: DSEC files do not store it
  const std::vector<StreamInfo> streams = reader->streams();
  ASSERT_EQ(streams.size(), 6u);
  EXPECT_EQ(streams[2].name, "events/t");
  EXPECT_EQ(streams[2].type, "uint32 us");
  EXPECT_EQ(streams[2].messages, 50000);
  EXPECT_EQ(streams[5].name, "ms_to_idx");
}

TEST(H5Reader, AnyIntegerOrFloatColumnTypeConverts) {
  TempDir dir;
  const std::string path = dir.file("types.h5");
  {
    RawH5 f(path);
    f.column<int32_t>("events/x", {0, 5, 65535});
    f.column<double>("events/y", {1.0, 2.0, 3.0});
    f.column<uint64_t>("events/t", {10, 20, 20});
    f.column<int16_t>("events/p", {-1, 1, -1});
    hid_t ds = f.put<int64_t>("t_offset", {1000000}, {1});  // one-element 1-D offset
    RawH5::string_attr(ds, "unit", "ms");                   // offset in its own unit
    H5Dclose(ds);
  }
  ReadReport rep;
  const std::vector<Event> ev = read_all(path, {}, &rep);
  ASSERT_EQ(ev.size(), 3u);
  const int64_t off = 1000000LL * 1000000LL;
  EXPECT_EQ(ev[0], (Event{off + 10000, 0, 1, -1}));
  EXPECT_EQ(ev[1], (Event{off + 20000, 5, 2, 1}));
  EXPECT_EQ(ev[2], (Event{off + 20000, 65535, 3, -1}));
  EXPECT_EQ(rep.polarity, PolarityConvention::kMinusPlusOne);
}

TEST(H5Reader, GivenTimeUnitOverridesTheDsecDefault) {
  TempDir dir;
  const std::string path = dir.file("ns.h5");
  {
    RawH5 f(path);
    f.column<uint16_t>("events/x", {1, 2});
    f.column<uint16_t>("events/y", {1, 2});
    f.column<int64_t>("events/t", {5, 7});
    f.column<uint8_t>("events/p", {1, 0});
  }
  DatasetOptions o;
  o.h5.time_unit = TimeUnit::kNanoseconds;
  ReadReport rep;
  const std::vector<Event> ev = read_all(path, o, &rep);
  ASSERT_EQ(ev.size(), 2u);
  EXPECT_EQ(ev[1].t_ns, 7);
  EXPECT_EQ(rep.time_unit_reason, "given");
  // Without the option: us (DSEC convention).
  EXPECT_EQ(read_all(path)[1].t_ns, 7000);
}

// ---------------------------------------------------------------------------------------------
// evio's writer

TEST(H5Writer, RoundTripIsLosslessInNanoseconds) {
  TempDir dir;
  std::vector<Event> in = random_events(120000, 3, 1700000000000000000LL, 1500);
  in[10].t_ns = in[9].t_ns;  // equal stamps
  in[11].t_ns = in[9].t_ns;
  const std::string path = dir.file("rt_ns.h5");
  H5WriteOptions o;
  o.chunk_events = 4096;
  o.sensor = SensorSize{640, 480};
  int64_t rounded = -1;
  write_evio(path, in, o, &rounded);
  EXPECT_EQ(rounded, 0);
  ReadReport rep;
  for (size_t max : {size_t{1}, size_t{777}, size_t{1} << 20}) {
    if (max == 1) {
      // One event per call for the first 2000 events, then the rest.
      auto reader = open_h5_dataset(path);
      EventBuffer buf;
      for (int i = 0; i < 2000; ++i) ASSERT_EQ(reader->read_events(&buf, 1), 1u);
      while (reader->read_events(&buf, 50000) > 0) {
      }
      ASSERT_EQ(buf.size(), in.size());
      for (size_t i = 0; i < in.size(); ++i) ASSERT_EQ(buf[i], in[i]) << "event " << i;
      continue;
    }
    const std::vector<Event> out = read_all(path, {}, &rep, max);
    ASSERT_EQ(out.size(), in.size());
    for (size_t i = 0; i < in.size(); ++i) ASSERT_EQ(out[i], in[i]) << "event " << i;
  }
  EXPECT_EQ(rep.time_unit, TimeUnit::kNanoseconds);
  EXPECT_NE(rep.time_unit_reason.find("unit attribute"), std::string::npos) << rep.time_unit_reason;
  auto reader = open_h5_dataset(path);
  EXPECT_EQ(reader->sensor_size().width, 640);
  EXPECT_EQ(reader->sensor_size().height, 480);
}

TEST(H5Writer, SameEventsGiveAByteIdenticalFileAtAnotherTime) {
  TempDir dir;
  const std::vector<Event> in = random_events(5000, 5, 1000, 1500);
  H5WriteOptions o;
  o.sensor = SensorSize{240, 180};
  write_evio(dir.file("a.h5"), in, o, nullptr);
  // HDF5 object headers store modification times in whole seconds unless the writer turns
  // them off: cross a second boundary before writing the second file.
  std::this_thread::sleep_for(std::chrono::milliseconds(1100));
  write_evio(dir.file("b.h5"), in, o, nullptr);
  auto bytes = [](const std::string& p) {
    std::ifstream f(p, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
  };
  const std::string a = bytes(dir.file("a.h5")), b = bytes(dir.file("b.h5"));
  ASSERT_FALSE(a.empty());
  EXPECT_TRUE(a == b);
}

TEST(H5Writer, MicrosecondsRoundHalfUpAndCountRoundedEvents) {
  TempDir dir;
  std::vector<Event> in = random_events(50000, 4, 1700000000000000000LL - 777, 2500);
  in[5].t_ns = in[4].t_ns;
  // Exact ties (half a microsecond) and whole microseconds.
  for (size_t i = 100; i < 50000; i += 97) in[i].t_ns = in[i].t_ns / 1000 * 1000 + (i % 2 ? 500 : 0);
  std::sort(in.begin(), in.end(), [](const Event& a, const Event& b) { return a.t_ns < b.t_ns; });
  int64_t ties = 0;
  for (const Event& e : in) ties += e.t_ns % 1000 == 500;
  ASSERT_GT(ties, 100);
  int64_t want_rounded = 0;
  for (const Event& e : in) want_rounded += e.t_ns % 1000 != 0;
  ASSERT_GT(want_rounded, 1000);
  ASSERT_LT(want_rounded, 50000);
  const std::string path = dir.file("rt_us.h5");
  H5WriteOptions o;
  o.time_unit = TimeUnit::kMicroseconds;
  o.chunk_events = 1000;
  int64_t rounded = -1;
  write_evio(path, in, o, &rounded);
  EXPECT_EQ(rounded, want_rounded);
  ReadReport rep;
  const std::vector<Event> out = read_all(path, {}, &rep);
  ASSERT_EQ(out.size(), in.size());
  for (size_t i = 0; i < in.size(); ++i) {
    Event want = in[i];
    want.t_ns = (in[i].t_ns + 500) / 1000 * 1000;  // positive times: half up
    ASSERT_EQ(out[i], want) << "event " << i;
  }
  for (size_t i = 0; i < in.size(); ++i) {
    if (in[i].t_ns % 1000 == 500) {
      ASSERT_EQ(out[i].t_ns, in[i].t_ns + 500) << "ties round up, event " << i;
    }
  }
  EXPECT_EQ(rep.time_unit, TimeUnit::kMicroseconds);

  // The file is DSEC-compatible: int64 relative us with unit "us", t_offset in us.
  hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  ASSERT_GE(f, 0);
  hid_t ds = H5Dopen2(f, "t_offset", H5P_DEFAULT);
  int64_t off = 0;
  H5Dread(ds, H5T_NATIVE_INT64, H5S_ALL, H5S_ALL, H5P_DEFAULT, &off);
  EXPECT_EQ(off, (in[0].t_ns + 500) / 1000);
  H5Dclose(ds);
  ds = H5Dopen2(f, "events/t", H5P_DEFAULT);
  hid_t type = H5Dget_type(ds);
  EXPECT_EQ(H5Tget_class(type), H5T_INTEGER);
  EXPECT_EQ(H5Tget_size(type), 8u);
  H5Tclose(type);
  H5Dclose(ds);
  H5Fclose(f);
}

TEST(H5Writer, EmptyStreamGivesAnEmptyReadableFile) {
  TempDir dir;
  const std::string path = dir.file("empty.h5");
  H5EventWriter w(path);
  EXPECT_EQ(w.close(), 0);
  EXPECT_EQ(w.close(), 0);  // second close does nothing
  EXPECT_TRUE(read_all(path).empty());
  auto r = open_h5_dataset(path);
  EXPECT_TRUE(r->seek_events(123));
}

TEST(H5Writer, RejectsDecreasingTimeInvalidOptionsAndWriteAfterClose) {
  TempDir dir;
  const std::string path = dir.file("w.h5");
  {
    H5EventWriter w(path);
    const std::vector<Event> ev = {{100, 1, 1, 1}, {99, 1, 1, 1}};
    expect_error(path, [&] { w.write(EventSpan(ev.data(), ev.size())); }, {"event 1", "earlier than", "non-decreasing"}, false);
  }
  H5WriteOptions bad;
  bad.time_unit = TimeUnit::kSeconds;
  std::string why;
  EXPECT_FALSE(bad.Validate(&why));
  EXPECT_NE(why.find("time_unit"), std::string::npos);
  expect_error(path, [&] { H5EventWriter w(path, bad); }, {"invalid HDF5 writer options"});
  bad = H5WriteOptions();
  bad.gzip_level = 11;
  EXPECT_FALSE(bad.Validate(&why));
  EXPECT_TRUE(H5WriteOptions().Validate(&why));
  H5EventWriter w(path);
  w.close();
  const Event e{1, 1, 1, 1};
  expect_error(path, [&] { w.write(EventSpan(&e, 1)); }, {"write after close"});
  const std::string under_file = dir.write("plain", "x") + "/a.h5";  // a regular file as folder
  expect_error(under_file, [&] { H5EventWriter w2(under_file); }, {"cannot create the HDF5 file"});
}

TEST(H5Writer, MsToIdxIsTheFirstEventAtOrAfterEachMillisecond) {
  TempDir dir;
  const std::vector<Event> in = random_events(20000, 9, 5000000123LL, 400000);  // gaps of up to 0.4 ms
  const std::string path = dir.file("idx.h5");
  write_evio(path, in);
  hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  hid_t ds = H5Dopen2(f, "ms_to_idx", H5P_DEFAULT);
  hid_t space = H5Dget_space(ds);
  const hssize_t m = H5Sget_simple_extent_npoints(space);
  std::vector<uint64_t> idx(static_cast<size_t>(m));
  H5Dread(ds, H5T_NATIVE_UINT64, H5S_ALL, H5S_ALL, H5P_DEFAULT, idx.data());
  H5Sclose(space);
  H5Dclose(ds);
  H5Fclose(f);
  const int64_t t0 = in.front().t_ns;
  ASSERT_EQ(m, (in.back().t_ns - t0) / 1000000 + 1);
  for (int64_t i = 0; i < m; ++i) {
    const auto it = std::lower_bound(in.begin(), in.end(), t0 + i * 1000000,
                                     [](const Event& e, int64_t t) { return e.t_ns < t; });
    ASSERT_EQ(idx[static_cast<size_t>(i)], static_cast<uint64_t>(it - in.begin())) << "ms " << i;
  }
}

// ---------------------------------------------------------------------------------------------
// event_utils and MVSEC

// Exact: s = m * 2^e with integer m, so s * 1e9 = m * 1e9 / 2^-e, rounded half away from zero in
// 128-bit integers (positive s only).
int64_t seconds_to_ns(double s) {
  int e = 0;
  const double fr = std::frexp(s, &e);  // s = fr * 2^e, fr in [0.5, 1)
  const __int128 m = static_cast<__int128>(std::ldexp(fr, 53));
  e -= 53;
  __int128 num = m * 1000000000;
  if (e >= 0) return static_cast<int64_t>(num << e);
  const __int128 den = static_cast<__int128>(1) << (-e);
  return static_cast<int64_t>((num + den / 2) / den);
}

TEST(H5Reader, ReadsEventUtilsLayoutWithFloatSecondsAndBoolPolarity) {
  TempDir dir;
  const std::string path = dir.file("event_utils.h5");
  std::mt19937_64 rng(5);
  std::vector<int16_t> xs, ys;
  std::vector<double> ts;
  std::vector<int8_t> ps;
  double t = 1500000000.123456;
  for (int i = 0; i < 5000; ++i) {
    t += static_cast<double>(rng() % 100) * 1e-6 + 0.3e-7;
    xs.push_back(static_cast<int16_t>(rng() % 346));
    ys.push_back(static_cast<int16_t>(rng() % 260));
    ts.push_back(t);
    ps.push_back(static_cast<int8_t>(rng() % 2));
  }
  {
    RawH5 f(path);
    f.column("events/xs", xs);
    f.column("events/ys", ys);
    f.column("events/ts", ts);
    hid_t bt = bool_type();
    H5Dclose(f.put("events/ps", ps, {}, bt, H5P_DEFAULT, bt));
    H5Tclose(bt);
    RawH5::int_attr(f.id(), "sensor_width", 346);
    RawH5::int_attr(f.id(), "sensor_height", 260);
  }
  ReadReport rep;
  const std::vector<Event> ev = read_all(path, {}, &rep);
  ASSERT_EQ(ev.size(), ts.size());
  for (size_t i = 0; i < ev.size(); ++i) {
    const Event want{seconds_to_ns(ts[i]), static_cast<uint16_t>(xs[i]), static_cast<uint16_t>(ys[i]),
                     static_cast<int8_t>(ps[i] ? 1 : -1)};
    ASSERT_EQ(ev[i], want) << "event " << i;
  }
  EXPECT_EQ(rep.time_unit, TimeUnit::kSeconds);
  EXPECT_EQ(rep.polarity, PolarityConvention::kZeroOne);
  auto reader = open_h5_dataset(path);
  EXPECT_EQ(dynamic_cast<H5EventReader&>(*reader).layout_name(), "event_utils");
  EXPECT_EQ(reader->sensor_size().width, 346);
  EXPECT_EQ(reader->sensor_size().height, 260);
}

std::vector<double> mvsec_matrix(size_t n, std::vector<Event>* want) {
  std::mt19937_64 rng(6);
  std::vector<double> m;
  double t = 1504645177.42;
  for (size_t i = 0; i < n; ++i) {
    t += static_cast<double>(rng() % 50) * 1e-6;
    const double x = static_cast<double>(rng() % 346), y = static_cast<double>(rng() % 260);
    const double p = rng() % 2 ? 1.0 : -1.0;
    m.insert(m.end(), {x, y, t, p});
    want->push_back(Event{seconds_to_ns(t), static_cast<uint16_t>(x), static_cast<uint16_t>(y), static_cast<int8_t>(p)});
  }
  return m;
}

TEST(H5Reader, ReadsMvsecMatrixLayout) {
  TempDir dir;
  const std::string path = dir.file("mvsec.hdf5");
  std::vector<Event> want;
  const std::vector<double> m = mvsec_matrix(7000, &want);
  {
    RawH5 f(path);
    H5Dclose(f.put("davis/left/events", m, {want.size(), 4}));
    f.column<double>("davis/left/image_raw_ts", {1.0, 2.0});
  }
  ReadReport rep;
  const std::vector<Event> ev = read_all(path, {}, &rep, 1000);
  ASSERT_EQ(ev.size(), want.size());
  for (size_t i = 0; i < ev.size(); ++i) ASSERT_EQ(ev[i], want[i]) << "event " << i;
  EXPECT_EQ(rep.time_unit, TimeUnit::kSeconds);
  EXPECT_EQ(rep.polarity, PolarityConvention::kMinusPlusOne);
  auto reader = open_h5_dataset(path);
  EXPECT_EQ(dynamic_cast<H5EventReader&>(*reader).layout_name(), "MVSEC");
  // Seeking without an index: binary search on the t column.
  const int64_t t = want[4321].t_ns;
  ASSERT_TRUE(reader->seek_events(t));
  EventBuffer buf;
  reader->read_events(&buf, 1);
  const size_t first = static_cast<size_t>(
      std::lower_bound(want.begin(), want.end(), t, [](const Event& e, int64_t v) { return e.t_ns < v; }) - want.begin());
  ASSERT_EQ(buf.size(), 1u);
  EXPECT_EQ(buf[0], want[first]);
  reader.reset();

  // The same matrix under another name, configured explicitly.
  const std::string path2 = dir.file("right.h5");
  {
    RawH5 f(path2);
    H5Dclose(f.put("davis/right/events", m, {want.size(), 4}));
  }
  expect_read_error(path2, {"no event datasets found", "davis (group: right)"});
  DatasetOptions o;
  o.h5.kind = H5Layout::Kind::kMatrix;
  o.h5.matrix = "davis/right/events";
  EXPECT_EQ(read_all(path2, o).size(), want.size());
}

// ---------------------------------------------------------------------------------------------
// compression

bool has_filter(const std::string& path, const char* dataset, H5Z_filter_t id) {
  hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  hid_t ds = H5Dopen2(f, dataset, H5P_DEFAULT);
  hid_t dcpl = H5Dget_create_plist(ds);
  bool found = false;
  for (int i = 0; i < H5Pget_nfilters(dcpl); ++i) {
    unsigned flags = 0, cfg = 0;
    size_t n = 0;
    found = found || H5Pget_filter2(dcpl, static_cast<unsigned>(i), &flags, &n, nullptr, 0, nullptr, &cfg) == id;
  }
  H5Pclose(dcpl);
  H5Dclose(ds);
  H5Fclose(f);
  return found;
}

TEST(H5Compression, GzipAndBloscFilesReadBack) {
  if (H5Zfilter_avail(32001) <= 0) GTEST_SKIP() << "Blosc HDF5 plugin not installed (hdf5-filter-plugin-blosc-serial)";
  TempDir dir;
  const std::vector<Event> in = random_events(70000, 11, 1000, 300);
  for (auto c : {H5WriteOptions::Compression::kGzip, H5WriteOptions::Compression::kBlosc}) {
    const std::string path = dir.file(std::string(h5_compression_name(c)) + ".h5");
    H5WriteOptions o;
    o.compression = c;
    o.chunk_events = 8192;
    write_evio(path, in, o);
    EXPECT_TRUE(has_filter(path, "events/t", c == H5WriteOptions::Compression::kGzip ? H5Z_FILTER_DEFLATE : 32001));
    const std::vector<Event> out = read_all(path, {}, nullptr, 5000);
    ASSERT_EQ(out.size(), in.size()) << path;
    for (size_t i = 0; i < in.size(); ++i) ASSERT_EQ(out[i], in[i]) << path << " event " << i;
    // Tiny chunks of random data do not shrink: they are stored as they are, still readable.
    const std::string small = dir.file(std::string("small_") + h5_compression_name(c) + ".h5");
    o.chunk_events = 16;
    write_evio(small, random_events(1000, 13, 0, 1 << 24), o);
    EXPECT_EQ(read_all(small).size(), 1000u) << small;
  }
  // DSEC ships Blosc with zstd (compressor code 5): written with raw HDF5 calls.
  const DsecData d = make_dsec(30000, 12);
  const std::string path = dir.file("dsec_blosc_zstd.h5");
  hid_t dcpl = H5Pcreate(H5P_DATASET_CREATE);
  const hsize_t chunk = 4096;
  H5Pset_chunk(dcpl, 1, &chunk);
  const unsigned cd[7] = {0, 0, 0, 0, 9, 1, 5};
  ASSERT_GE(H5Pset_filter(dcpl, 32001, H5Z_FLAG_MANDATORY, 7, cd), 0);
  write_dsec(path, d, true, dcpl);
  H5Pclose(dcpl);
  EXPECT_TRUE(has_filter(path, "events/x", 32001));
  const std::vector<Event> ev = read_all(path);
  ASSERT_EQ(ev.size(), d.t.size());
  for (size_t i = 0; i < ev.size(); ++i) ASSERT_EQ(ev[i].t_ns, (d.t[i] + d.t_offset_us) * 1000) << i;
}

TEST(H5Compression, MissingBloscFilterGivesAClearError) {
  if (H5Zfilter_avail(32001) <= 0) GTEST_SKIP() << "Blosc HDF5 plugin not installed: cannot write the test file";
  TempDir dir;
  const std::string path = dir.file("blosc.h5");
  H5WriteOptions o;
  o.compression = H5WriteOptions::Compression::kBlosc;
  write_evio(path, random_events(1000, 1, 0, 100), o);

  // Hide the plugin: empty search path, plugin loading off, and the already loaded filter
  // unregistered (HDF5 keeps loaded plugins in a cache that the search path does not affect).
  unsigned n_paths = 0;
  ASSERT_GE(H5PLsize(&n_paths), 0);
  std::vector<std::string> paths;
  for (unsigned i = 0; i < n_paths; ++i) {
    char buf[4096] = {0};
    H5PLget(i, buf, sizeof(buf));
    paths.push_back(buf);
  }
  for (unsigned i = 0; i < n_paths; ++i) H5PLremove(0);
  unsigned state = 0;
  H5PLget_loading_state(&state);
  H5PLset_loading_state(0);
  ASSERT_GE(H5Zunregister(32001), 0);
  ASSERT_LE(H5Zfilter_avail(32001), 0);

  expect_read_error(path, {"dataset 'events/x'", "HDF5 filter 32001 (blosc)", "not available",
                           "install Debian package hdf5-filter-plugin-blosc-serial or set HDF5_PLUGIN_PATH"});
  H5WriteOptions wo;
  wo.compression = H5WriteOptions::Compression::kBlosc;
  const std::string out = dir.file("w.h5");
  expect_error(out, [&] { H5EventWriter w(out, wo); }, {"filter 32001", "hdf5-filter-plugin-blosc-serial"});

  for (const std::string& p : paths) H5PLappend(p.c_str());
  H5PLset_loading_state(state);
  EXPECT_GT(H5Zfilter_avail(32001), 0);  // back for the other tests
  EXPECT_EQ(read_all(path).size(), 1000u);
}

// ---------------------------------------------------------------------------------------------
// seeking

// The first index with t >= t_ns in a sorted event vector.
size_t first_at_or_after(const std::vector<Event>& ev, int64_t t_ns) {
  return static_cast<size_t>(
      std::lower_bound(ev.begin(), ev.end(), t_ns, [](const Event& e, int64_t t) { return e.t_ns < t; }) - ev.begin());
}

void check_seeks(const std::string& path, const std::vector<Event>& ev, bool expect_index, uint64_t seed) {
  auto reader = open_h5_dataset(path);
  auto& h5 = dynamic_cast<H5EventReader&>(*reader);
  std::mt19937_64 rng(seed);
  const int64_t t0 = ev.front().t_ns - 5000000, t1 = ev.back().t_ns + 5000000;
  EventBuffer buf;
  for (int k = 0; k < 300; ++k) {
    int64_t t = t0 + static_cast<int64_t>(rng() % static_cast<uint64_t>(t1 - t0));
    if (k % 3 == 0) t = ev[rng() % ev.size()].t_ns;  // exactly on an event (and its equal-stamp run)
    if (k == 1) t = std::numeric_limits<int64_t>::min();
    if (k == 2) t = std::numeric_limits<int64_t>::max();
    ASSERT_TRUE(reader->seek_events(t));
    const H5EventReader::SeekStats stats = h5.last_seek_stats();
    if (expect_index && t > t0 && t < t1) {
      EXPECT_TRUE(stats.used_index) << t;
      EXPECT_LE(stats.index_values_read, 2);
    }
    EXPECT_LE(stats.t_values_read, 2 + 64 + 2048) << "seek read too many timestamps";
    const size_t first = first_at_or_after(ev, t);
    buf.clear();
    const bool full = k % 50 == 0;
    while (reader->read_events(&buf, full ? 100000 : 64 - buf.size()) > 0 && (full || buf.size() < 64)) {
    }
    const size_t want = full ? ev.size() - first : std::min<size_t>(64, ev.size() - first);
    ASSERT_EQ(buf.size(), want) << "seek to " << t;
    for (size_t i = 0; i < buf.size(); ++i) ASSERT_EQ(buf[i], ev[first + i]) << "seek to " << t << " event " << i;
  }
}

TEST(H5Seek, WithMsToIdxEqualsALinearFilter) {
  TempDir dir;
  // Bursts and gaps: steps of 0..3 us with occasional jumps of several ms (empty ms buckets).
  std::vector<Event> ev = random_events(200000, 21, 1700000000000000000LL, 3000);
  std::mt19937_64 rng(22);
  int64_t shift = 0;
  for (Event& e : ev) {
    if (rng() % 5000 == 0) shift += static_cast<int64_t>(rng() % 20000000);
    e.t_ns += shift;
  }
  const std::string path = dir.file("seek.h5");
  H5WriteOptions o;
  o.chunk_events = 10000;
  write_evio(path, ev, o);
  check_seeks(path, ev, true, 23);
  // Microsecond file: compare against the rounded events.
  const std::string path_us = dir.file("seek_us.h5");
  o.time_unit = TimeUnit::kMicroseconds;
  write_evio(path_us, ev, o);
  std::vector<Event> rounded = ev;
  for (Event& e : rounded) e.t_ns = (e.t_ns + 500) / 1000 * 1000;
  check_seeks(path_us, rounded, true, 24);
}

TEST(H5Seek, DsecIndexAndBinarySearchWithoutIndexAgree) {
  TempDir dir;
  const DsecData d = make_dsec(100000, 31);
  std::vector<Event> ev;
  for (size_t i = 0; i < d.t.size(); ++i) {
    ev.push_back(Event{(static_cast<int64_t>(d.t[i]) + d.t_offset_us) * 1000, d.x[i], d.y[i], static_cast<int8_t>(d.p[i] ? 1 : -1)});
  }
  const std::string with = dir.file("with.h5"), without = dir.file("without.h5");
  write_dsec(with, d, true);
  write_dsec(without, d, false);
  check_seeks(with, ev, true, 32);
  check_seeks(without, ev, false, 33);
  auto reader = open_h5_dataset(without);
  reader->seek_events(ev[50000].t_ns);
  EXPECT_FALSE(dynamic_cast<H5EventReader&>(*reader).last_seek_stats().used_index);
}

TEST(H5Seek, WrongMsToIdxFallsBackToBinarySearch) {
  TempDir dir;
  DsecData d = make_dsec(30000, 41);
  const std::string path = dir.file("bad_index.h5");
  {
    RawH5 f(path);
    f.column("events/x", d.x);
    f.column("events/y", d.y);
    f.column("events/t", d.t);
    f.column("events/p", d.p);
    f.scalar("t_offset", d.t_offset_us);
    std::vector<uint64_t> idx = ms_to_idx_us(d.t);
    std::reverse(idx.begin(), idx.end());  // nonsense index
    idx[3] = ~uint64_t{0};
    f.column("ms_to_idx", idx);
  }
  std::vector<Event> ev;
  for (size_t i = 0; i < d.t.size(); ++i) {
    ev.push_back(Event{(static_cast<int64_t>(d.t[i]) + d.t_offset_us) * 1000, d.x[i], d.y[i], static_cast<int8_t>(d.p[i] ? 1 : -1)});
  }
  check_seeks(path, ev, false, 42);

  // An index that is not even integers is reported and not used.
  const std::string float_index = dir.file("float_index.h5");
  {
    RawH5 f(float_index);
    f.column("events/x", d.x);
    f.column("events/y", d.y);
    f.column("events/t", d.t);
    f.column("events/p", d.p);
    f.scalar("t_offset", d.t_offset_us);
    f.column<double>("ms_to_idx", {0.0, 1.5});
  }
  std::vector<std::string> warnings;
  set_log_sink([&](LogLevel level, const std::string& m) {
    if (level == LogLevel::kWarning) warnings.push_back(m);
  });
  check_seeks(float_index, ev, false, 43);
  set_log_sink({});
  ASSERT_FALSE(warnings.empty());
  EXPECT_NE(warnings[0].find("'ms_to_idx' holds floats"), std::string::npos) << warnings[0];
  EXPECT_NE(warnings[0].find("; seeking without the index"), std::string::npos) << warnings[0];
}

// ---------------------------------------------------------------------------------------------
// malformed input

TEST(H5Malformed, MissingDatasetNamesItAndListsTheFile) {
  TempDir dir;
  const std::string path = dir.file("no_p.h5");
  {
    RawH5 f(path);
    f.column<uint16_t>("events/x", {1});
    f.column<uint16_t>("events/y", {1});
    f.column<int64_t>("events/t", {1});
  }
  expect_read_error(path, {"dataset 'events/p' (p) not found", "DSEC layout", "top-level objects: events (group: t, x, y)"});
}

TEST(H5Malformed, UnknownLayoutListsTopLevelObjects) {
  TempDir dir;
  const std::string path = dir.file("other.h5");
  {
    RawH5 f(path);
    f.column<double>("foo/bar", {1.0});
    f.column<int32_t>("baz", {1, 2});
  }
  expect_read_error(path, {"no event datasets found", "'events/t' (DSEC/TUM-VIE)", "'events/ts' (event_utils)",
                           "'davis/left/events' (MVSEC)", "baz (dataset)", "foo (group: bar)"});
  const std::string empty = dir.file("empty.h5");
  { RawH5 f(empty); }
  expect_read_error(empty, {"no event datasets found", "none (the file is empty)"});
}

TEST(H5Malformed, MismatchedColumnLengths) {
  TempDir dir;
  const std::string path = dir.file("len.h5");
  {
    RawH5 f(path);
    f.column<uint16_t>("events/x", {1, 2, 3});
    f.column<uint16_t>("events/y", {1, 2});
    f.column<int64_t>("events/t", {1, 2, 3});
    f.column<uint8_t>("events/p", {1, 0, 1});
  }
  expect_read_error(path, {"event columns have different lengths", "'events/x' 3", "'events/y' 2", "equal length"});
}

TEST(H5Malformed, WrongRankAndType) {
  TempDir dir;
  const std::string path = dir.file("rank.h5");
  {
    RawH5 f(path);
    H5Dclose(f.put<uint16_t>("events/x", {1, 2, 3, 4}, {2, 2}));
    f.column<uint16_t>("events/y", {1, 2});
    f.column<int64_t>("events/t", {1, 2});
    f.column<uint8_t>("events/p", {1, 0});
  }
  expect_read_error(path, {"dataset 'events/x' (x) has rank 2 (shape 2 x 2)", "a 1-D dataset"});
  const std::string mvsec = dir.file("mvsec3.h5");
  {
    RawH5 f(mvsec);
    H5Dclose(f.put<double>("davis/left/events", {1, 2, 3, 4, 5, 6}, {2, 3}));
  }
  expect_read_error(mvsec, {"'davis/left/events' has rank 2 (shape 2 x 3)", "N x 4 matrix with columns x, y, t, p"});
  const std::string strings = dir.file("string.h5");
  {
    RawH5 f(strings);
    f.column<uint16_t>("events/y", {1});
    f.column<int64_t>("events/t", {1});
    f.column<uint8_t>("events/p", {1});
    hid_t st = H5Tcopy(H5T_C_S1);
    H5Tset_size(st, 4);
    hsize_t one = 1;
    hid_t space = H5Screate_simple(1, &one, nullptr);
    hid_t ds = H5Dcreate2(f.id(), "events/x", st, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    H5Dwrite(ds, st, H5S_ALL, H5S_ALL, H5P_DEFAULT, "abc");
    H5Dclose(ds);
    H5Sclose(space);
    H5Tclose(st);
  }
  expect_read_error(strings, {"'events/x' (x) has element type class string", "integer (up to 64 bit), float or enum"});
}

// A 4-event DSEC-layout file (ns) with the given values.
std::string small_file(const TempDir& dir, const std::string& name, std::vector<int64_t> t, std::vector<int32_t> x,
                       std::vector<int8_t> p, int width = 0) {
  const std::string path = dir.file(name);
  RawH5 f(path);
  hid_t ds = f.put("events/t", t);
  RawH5::string_attr(ds, "unit", "ns");
  H5Dclose(ds);
  f.column("events/x", x);
  f.column("events/y", std::vector<uint16_t>(x.size(), 2));
  f.column("events/p", p);
  if (width > 0) {
    RawH5::int_attr(f.id(), "width", width);
    RawH5::int_attr(f.id(), "height", width);
  }
  return path;
}

TEST(H5Malformed, DecreasingTimestampsErrorOrSkip) {
  TempDir dir;
  const std::string path = small_file(dir, "order.h5", {10, 20, 15, 30}, {1, 2, 3, 4}, {1, 0, 1, 0});
  expect_read_error(path, {"event 2:", "timestamp 0.000000015 s", "earlier than the previous event's 0.000000020 s",
                           "never decreasing", "--on-bad-line warn"});
  DatasetOptions o;
  o.text.on_bad_line = BadLinePolicy::kWarnAndSkip;
  ReadReport rep;
  const std::vector<Event> ev = read_all(path, o, &rep);
  ASSERT_EQ(ev.size(), 3u);
  EXPECT_EQ(ev[2].t_ns, 30);
  EXPECT_EQ(rep.records, 3);
  ASSERT_EQ(rep.skipped.count("time order"), 1u);
  EXPECT_EQ(rep.skipped.at("time order").count, 1);
  EXPECT_EQ(rep.skipped.at("time order").first_line, 2);  // event index
}

TEST(H5Malformed, CoordinatesOutsideTheSensor) {
  TempDir dir;
  const std::string path = small_file(dir, "outside.h5", {1, 2, 3, 4}, {1, 10, 3, 70000}, {1, 1, 1, 1}, 10);
  expect_read_error(path, {"event 1:", "pixel (10, 2) outside the 10x10 sensor"});
  DatasetOptions o;
  o.text.on_bad_line = BadLinePolicy::kWarnAndSkip;
  ReadReport rep;
  EXPECT_EQ(read_all(path, o, &rep).size(), 2u);
  EXPECT_EQ(rep.skipped.at("outside sensor").count, 1);
  EXPECT_EQ(rep.skipped.at("malformed").count, 1);  // 70000 does not fit uint16
  EXPECT_NE(rep.skipped.at("malformed").first_message.find("x = 70000"), std::string::npos);
  // Negative coordinate without a sensor size.
  const std::string neg = small_file(dir, "neg.h5", {1, 2}, {1, -3}, {1, 1});
  expect_read_error(neg, {"event 1:", "x = -3", "not a whole pixel coordinate"});
  // The sensor given in the options applies when the file has none.
  const std::string plain = small_file(dir, "plain.h5", {1, 2}, {1, 50}, {1, 1});
  o = DatasetOptions();
  o.text.sensor = SensorSize{40, 40};
  expect_read_error(plain, {"pixel (50, 2) outside the 40x40 sensor"}, o);
}

TEST(H5Malformed, BadPolarityNonFiniteTimeAndMixedConventions) {
  TempDir dir;
  expect_read_error(small_file(dir, "pol.h5", {1, 2}, {1, 1}, {1, 5}), {"event 1:", "p = 5", "is not 0, 1, -1 or +1"});
  expect_read_error(small_file(dir, "mixed.h5", {1, 2, 3}, {1, 1, 1}, {0, 1, -1}),
                    {"event 2:", "polarity convention -1/+1 mixed with 0/1"});
  DatasetOptions o;
  o.h5.polarity = PolarityConvention::kMinusPlusOne;
  expect_read_error(small_file(dir, "given.h5", {1, 2}, {1, 1}, {-1, 0}), {"event 1:", "mixed with -1/+1 given in the options"}, o);
  const std::string nan = dir.file("nan.h5");
  {
    RawH5 f(nan);
    f.column<uint16_t>("events/xs", {1, 1, 1});
    f.column<uint16_t>("events/ys", {1, 1, 1});
    f.column<double>("events/ts", {0.5, std::nan(""), 1e300});
    f.column<uint8_t>("events/ps", {1, 1, 1});
  }
  expect_read_error(nan, {"event 1:", "timestamp nan", "not finite or does not fit int64 ns"});
  o = DatasetOptions();
  o.text.on_bad_line = BadLinePolicy::kWarnAndSkip;
  ReadReport rep;
  EXPECT_EQ(read_all(nan, o, &rep).size(), 1u);
  EXPECT_EQ(rep.skipped.at("malformed").count, 2);
}

TEST(H5Malformed, BadUnitAttributeAndSensorSize) {
  TempDir dir;
  const std::string path = dir.file("unit.h5");
  {
    RawH5 f(path);
    hid_t ds = f.put<int64_t>("events/t", {1});
    RawH5::string_attr(ds, "unit", "furlongs");
    H5Dclose(ds);
    f.column<uint16_t>("events/x", {1});
    f.column<uint16_t>("events/y", {1});
    f.column<uint8_t>("events/p", {1});
  }
  expect_read_error(path, {"attribute unit = \"furlongs\" is not a time unit", "\"s\", \"ms\", \"us\" or \"ns\""});
  const std::string size = dir.file("size.h5");
  {
    RawH5 f(size);
    f.column<int64_t>("events/t", {1});
    f.column<uint16_t>("events/x", {1});
    f.column<uint16_t>("events/y", {1});
    f.column<uint8_t>("events/p", {1});
    f.scalar<int32_t>("width", 0);
    f.scalar<int32_t>("height", 10);
  }
  expect_read_error(size, {"dataset 'width' = 0", "is not a sensor size"});
}

TEST(H5Malformed, ExternalLinksAreNotFollowed) {
  TempDir dir;
  const std::string other = dir.file("other.h5");
  {
    RawH5 f(other);
    f.column<int64_t>("t", {1, 2});
  }
  const std::string path = dir.file("ext.h5");
  {
    RawH5 f(path);
    f.column<uint16_t>("events/x", {1, 2});
    f.column<uint16_t>("events/y", {1, 2});
    f.column<uint8_t>("events/p", {1, 0});
    ASSERT_GE(H5Lcreate_external(other.c_str(), "t", f.id(), "events/t", H5P_DEFAULT, H5P_DEFAULT), 0);
  }
  DatasetOptions o;
  o.h5.kind = H5Layout::Kind::kColumns;
  expect_read_error(path, {"dataset 'events/t' (t) is an external link to another file", "a dataset inside this file"}, o);
  // Reached through a soft link, the external link is not traversed either.
  const std::string soft = dir.file("soft.h5");
  {
    RawH5 f(soft);
    f.column<uint16_t>("events/x", {1, 2});
    f.column<uint16_t>("events/y", {1, 2});
    f.column<uint8_t>("events/p", {1, 0});
    ASSERT_GE(H5Lcreate_external(other.c_str(), "t", f.id(), "ext", H5P_DEFAULT, H5P_DEFAULT), 0);
    ASSERT_GE(H5Lcreate_soft("/ext", f.id(), "events/t", H5P_DEFAULT, H5P_DEFAULT), 0);
  }
  expect_read_error(soft, {"'events/t' (t) is not a dataset"}, o);
}

TEST(H5Malformed, TruncatedFile) {
  TempDir dir;
  const std::string path = dir.file("full.h5");
  write_evio(path, random_events(20000, 51, 0, 1000));
  std::ifstream in(path, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string cut = dir.write("cut.h5", bytes.substr(0, bytes.size() / 2));
  expect_read_error(cut, {"cannot open the HDF5 file", "truncated", "an intact HDF5 file"});
}

TEST(H5Malformed, NotAnHdf5File) {
  TempDir dir;
  const std::string path = dir.write("events.h5", "0.1 1 2 0\n0.2 3 4 1\n");
  expect_read_error(path, {"not an HDF5 file", "no HDF5 signature at byte offset 0", "\\211HDF\\r\\n\\032\\n"});
  expect_read_error(dir.file("absent.h5"), {"no such file"});
  expect_read_error(dir.path(), {"is a directory"});
  const std::string empty = dir.write("zero.h5", "");
  expect_read_error(empty, {"not an HDF5 file"});
}

TEST(H5Malformed, SuperblockWithAbsurdDriverBlockIsRejectedBeforeLibhdf5ReadsIt) {
  // 49 bytes found by fuzzing: a version-0 superblock whose driver information block declares
  // ~4 GiB, which libhdf5 1.10.8 allocates inside H5Fopen.
  const unsigned char raw[49] = {0x89, 'H', 'D', 'F', '\r', '\n', 0x1a, '\n', 0, 0, 0, 0, 0, 8, 8, 0, 4, 0, 0x10,
                                 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0xff, 0xff, 0xff, 0x1a, 0, 0, 0, 0,
                                 0, 0, 0, 0, 0, 0, 0, 0, 0x1a};
  std::string bytes(reinterpret_cast<const char*>(raw), sizeof(raw));
  TempDir dir;
  const std::string path = dir.write("sb.h5", bytes);
  expect_read_error(path, {"HDF5 superblock at byte offset 0 points to a driver information block at 26",
                           "of 4294901760 bytes beyond the end of the 49-byte file", "an intact HDF5 file"});
  bytes[13] = 3;  // 3-byte addresses do not exist
  expect_read_error(dir.write("sb3.h5", bytes), {"declares 3-byte addresses and 8-byte lengths"});
}

TEST(H5Malformed, IncompleteDatasetIsRejected) {
  TempDir dir;
  const std::string path = dir.file("incomplete.h5");
  {
    RawH5 f(path);
    f.column<uint16_t>("events/x", {1, 2});
    f.column<uint16_t>("events/y", {1, 2});
    f.column<uint8_t>("events/p", {1, 1});
    // Declared but never written: HDF5 would return fill values.
    const hsize_t n = 2;
    hid_t space = H5Screate_simple(1, &n, nullptr);
    hid_t ds = H5Dcreate2(f.id(), "events/t", H5T_NATIVE_INT64, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
    H5Dclose(ds);
    H5Sclose(space);
  }
  expect_read_error(path, {"dataset 'events/t' declares 2 elements", "stores no data"});
}

// ---------------------------------------------------------------------------------------------
// real data: there is no HDF5 recording among the samples, so the real ECD events go through
// the writer and the reader.

TEST(H5RealData, EcdSliderEventsRoundTripThroughHdf5) {
  const auto dir = evio_test::real_data_dir("ecd_slider_depth_head");
  if (!dir) GTEST_SKIP() << "real data not found (../shared/data/real/ecd_slider_depth_head)";
  TextReadOptions to;
  to.sensor = SensorSize{240, 180};
  const EventBuffer in = read_ecd_events(*dir + "/events.txt", to);
  ASSERT_EQ(in.size(), 50000u);
  TempDir tmp;
  for (TimeUnit unit : {TimeUnit::kNanoseconds, TimeUnit::kMicroseconds}) {
    const std::string path = tmp.file(std::string("slider_") + time_unit_name(unit) + ".h5");
    H5WriteOptions o;
    o.time_unit = unit;
    o.sensor = SensorSize{240, 180};
    o.compression = H5WriteOptions::Compression::kGzip;
    int64_t rounded = -1;
    write_evio(path, in.events(), o, &rounded);
    int64_t want_rounded = 0;  // slider_depth stamps have ns digits (e.g. 0.003820001 s)
    for (const Event& e : in) want_rounded += e.t_ns % 1000 != 0;
    EXPECT_EQ(rounded, unit == TimeUnit::kMicroseconds ? want_rounded : 0);
    ReadReport rep;
    const std::vector<Event> out = read_all(path, {}, &rep);
    ASSERT_EQ(out.size(), 50000u);
    for (size_t i = 0; i < out.size(); ++i) {
      Event want = in[i];
      if (unit == TimeUnit::kMicroseconds) want.t_ns = (want.t_ns + 500) / 1000 * 1000;
      ASSERT_EQ(out[i], want) << "event " << i;
    }
    EXPECT_EQ(rep.records, 50000);
  }
}

}  // namespace
}  // namespace evio
