// HDF5 event writer (DSEC layout): see evio/sensors/h5.h.
#include "evio/sensors/h5.h"

#include <hdf5.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <sstream>
#include "evio/calib/error.h"
#include "evio/calib/log.h"

#include "h5_common.h"

namespace evio {
namespace fs = std::filesystem;
using namespace detail::h5;  // NOLINT: the shared HDF5 helpers

const char* h5_compression_name(H5WriteOptions::Compression c) {
  switch (c) {
    case H5WriteOptions::Compression::kNone: return "none";
    case H5WriteOptions::Compression::kGzip: return "gzip";
    case H5WriteOptions::Compression::kBlosc: return "blosc";
  }
  return "?";
}

bool H5WriteOptions::Validate(std::string* why) const {
  auto fail = [&](const std::string& m) {
    if (why != nullptr) *why = m;
    return false;
  };
  if (time_unit != TimeUnit::kNanoseconds && time_unit != TimeUnit::kMicroseconds) {
    return fail("time_unit must be ns (lossless) or us (DSEC)");
  }
  if (gzip_level < 1 || gzip_level > 9) return fail("gzip_level must be 1..9");
  if (blosc_level < 1 || blosc_level > 9) return fail("blosc_level must be 1..9");
  if (chunk_events < 16 || chunk_events > (int64_t{1} << 24)) return fail("chunk_events must be 16..2^24 events");
  if (sensor.width < 0 || sensor.height < 0 || sensor.width > 65536 || sensor.height > 65536 ||
      (sensor.width == 0) != (sensor.height == 0)) {
    return fail("sensor must be unknown (0x0) or a size of 1..65536 px in both directions");
  }
  return true;
}

struct H5EventWriter::Impl {
  std::string path;
  Options opt;
  Hid file, dx, dy, dt, dp, dms;
  std::vector<uint16_t> bx, by;
  std::vector<uint8_t> bp;
  std::vector<int64_t> bt;
  std::vector<uint64_t> bms;
  hsize_t rows_on_disk = 0, ms_on_disk = 0;
  int64_t total = 0;
  int64_t rounded = 0;
  bool have_first = false;
  int64_t t_offset = 0;  // in the file unit
  int64_t last_ns = std::numeric_limits<int64_t>::min();
  int64_t per_ms = 1000000;  // file units per ms
  int64_t next_ms = 0;       // next ms_to_idx entry to fill
  bool closed = false;

  [[noreturn]] void fail_h5(const std::string& what) const {
    throw InputError(path, 0, what + ": " + h5_error_text(), "a writable path with free space");
  }

  Hid make_dataset(const char* name, hid_t type, hsize_t chunk) {
    const hsize_t dims[1] = {0}, maxdims[1] = {H5S_UNLIMITED}, cdims[1] = {chunk};
    Hid space(H5Screate_simple(1, dims, maxdims));
    Hid dcpl(H5Pcreate(H5P_DATASET_CREATE));
    // No object modification times: the same events give a byte-identical file.
    if (!space.valid() || !dcpl.valid() || H5Pset_chunk(dcpl.get(), 1, cdims) < 0 ||
        H5Pset_obj_track_times(dcpl.get(), 0) < 0) {
      fail_h5(std::string("cannot set up dataset ") + name);
    }
    if (opt.compression == Options::Compression::kGzip) {
      if (H5Pset_shuffle(dcpl.get()) < 0 || H5Pset_deflate(dcpl.get(), static_cast<unsigned>(opt.gzip_level)) < 0) {
        fail_h5(std::string("cannot set gzip compression on ") + name);
      }
    } else if (opt.compression == Options::Compression::kBlosc) {
      // Blosc filter parameters: [0..3] filled by the filter itself, [4] clevel, [5] shuffle
      // (1 = byte shuffle), [6] compressor (1 = LZ4).
      // Optional: a chunk that Blosc cannot shrink (small or random) is stored as it is.
      const unsigned cd[7] = {0, 0, 0, 0, static_cast<unsigned>(opt.blosc_level), 1, 1};
      if (H5Pset_filter(dcpl.get(), kBloscFilter, H5Z_FLAG_OPTIONAL, 7, cd) < 0) {
        fail_h5(std::string("cannot set Blosc compression on ") + name);
      }
    }
    Hid lcpl(H5Pcreate(H5P_LINK_CREATE));
    if (!lcpl.valid() || H5Pset_create_intermediate_group(lcpl.get(), 1) < 0) fail_h5("cannot set up link creation");
    Hid ds(H5Dcreate2(file.get(), name, type, space.get(), lcpl.get(), dcpl.get(), H5P_DEFAULT));
    if (!ds.valid()) fail_h5(std::string("cannot create dataset ") + name);
    return ds;
  }

  void open() {
    std::string why;
    if (!opt.Validate(&why)) throw InputError(path, 0, "invalid HDF5 writer options: " + why);
    if (opt.compression == Options::Compression::kBlosc) {
      unsigned info = 0;
      const bool ok = H5Zfilter_avail(kBloscFilter) > 0 && H5Zget_filter_info(kBloscFilter, &info) >= 0 &&
                      (info & H5Z_FILTER_CONFIG_ENCODE_ENABLED);
      H5Eclear2(H5E_DEFAULT);
      if (!ok) {
        throw InputError(path, 0, "Blosc compression requested but HDF5 filter 32001 (blosc) is not available",
                         filter_install_hint(kBloscFilter) + "; or write with gzip or no compression");
      }
    }
    std::error_code ec;
    const fs::path parent = fs::path(path).parent_path();
    if (!parent.empty()) fs::create_directories(parent, ec);
    file = Hid(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT));
    if (!file.valid()) fail_h5("cannot create the HDF5 file");
    per_ms = opt.time_unit == TimeUnit::kMicroseconds ? 1000 : 1000000;
    {
      Hid gcpl(H5Pcreate(H5P_GROUP_CREATE));
      if (!gcpl.valid() || H5Pset_obj_track_times(gcpl.get(), 0) < 0) fail_h5("cannot set up group events");
      Hid group(H5Gcreate2(file.get(), "events", H5P_DEFAULT, gcpl.get(), H5P_DEFAULT));
      if (!group.valid()) fail_h5("cannot create group events");
    }
    const hsize_t chunk = static_cast<hsize_t>(opt.chunk_events);
    dx = make_dataset("events/x", H5T_STD_U16LE, chunk);
    dy = make_dataset("events/y", H5T_STD_U16LE, chunk);
    dp = make_dataset("events/p", H5T_STD_U8LE, chunk);
    dt = make_dataset("events/t", H5T_STD_I64LE, chunk);
    dms = make_dataset("ms_to_idx", H5T_STD_U64LE, 4096);
    const size_t reserve = static_cast<size_t>(opt.chunk_events);
    bx.reserve(reserve);
    by.reserve(reserve);
    bp.reserve(reserve);
    bt.reserve(reserve);
  }

  void append(const Hid& ds, hid_t mem, const void* data, hsize_t count, hsize_t old_rows, const char* name) {
    if (count == 0) return;
    const hsize_t new_dims[1] = {old_rows + count};
    if (H5Dset_extent(ds.get(), new_dims) < 0) fail_h5(std::string("cannot extend ") + name);
    Hid fspace(H5Dget_space(ds.get()));
    const hsize_t start[1] = {old_rows}, k[1] = {count};
    Hid mspace(H5Screate_simple(1, k, nullptr));
    if (!fspace.valid() || !mspace.valid() ||
        H5Sselect_hyperslab(fspace.get(), H5S_SELECT_SET, start, nullptr, k, nullptr) < 0 ||
        H5Dwrite(ds.get(), mem, mspace.get(), fspace.get(), H5P_DEFAULT, data) < 0) {
      fail_h5(std::string("cannot write ") + name);
    }
  }

  void flush_events() {
    const hsize_t k = bt.size();
    append(dx, H5T_NATIVE_UINT16, bx.data(), k, rows_on_disk, "events/x");
    append(dy, H5T_NATIVE_UINT16, by.data(), k, rows_on_disk, "events/y");
    append(dp, H5T_NATIVE_UINT8, bp.data(), k, rows_on_disk, "events/p");
    append(dt, H5T_NATIVE_INT64, bt.data(), k, rows_on_disk, "events/t");
    rows_on_disk += k;
    bx.clear();
    by.clear();
    bp.clear();
    bt.clear();
  }

  void flush_index() {
    append(dms, H5T_NATIVE_UINT64, bms.data(), bms.size(), ms_on_disk, "ms_to_idx");
    ms_on_disk += bms.size();
    bms.clear();
  }

  void write(EventSpan events) {
    if (closed) throw InputError(path, 0, "write after close");
    const bool us = opt.time_unit == TimeUnit::kMicroseconds;
    const size_t cap = static_cast<size_t>(opt.chunk_events);
    for (const Event& e : events) {
      if (e.t_ns < last_ns) {
        throw InputError(path, 0,
                         "event " + std::to_string(total) + " at " + format_seconds(e.t_ns) +
                             " s is earlier than the previous event at " + format_seconds(last_ns) + " s",
                         "events in non-decreasing time");
      }
      last_ns = e.t_ns;
      int64_t tf = e.t_ns;
      if (us) {
        // Round half up to whole us: floor(t / 1000) plus one when the remainder is >= 500.
        int64_t q = e.t_ns / 1000;
        int64_t r = e.t_ns % 1000;
        if (r < 0) {
          r += 1000;
          --q;
        }
        tf = q + (r >= 500 ? 1 : 0);
        if (r != 0) ++rounded;
      }
      if (!have_first) {
        have_first = true;
        t_offset = tf;
      }
      int64_t rel = 0;  // >= 0: times never decrease and rounding is monotone
      if (__builtin_sub_overflow(tf, t_offset, &rel)) {
        throw InputError(path, 0, "time span from the first event to " + format_seconds(e.t_ns) + " s overflows int64",
                         "events spanning less than 292 years");
      }
      const int64_t ms = rel / per_ms;
      if (ms >= next_ms) {
        if (ms > 1000000000) {
          throw InputError(path, 0,
                           "event " + std::to_string(total) + " is " + std::to_string(ms) +
                               " ms after the first event; ms_to_idx would need one entry per ms",
                           "recordings shorter than 1e9 ms (11.6 days)");
        }
        while (next_ms <= ms) {
          bms.push_back(static_cast<uint64_t>(total));
          ++next_ms;
          if (bms.size() >= 65536) flush_index();
        }
      }
      bx.push_back(e.x);
      by.push_back(e.y);
      bp.push_back(e.polarity > 0 ? 1 : 0);
      bt.push_back(rel);
      ++total;
      if (bt.size() >= cap) flush_events();
    }
  }

  int64_t close() {
    if (closed) return rounded;
    closed = true;
    flush_events();
    flush_index();
    const char* unit = opt.time_unit == TimeUnit::kMicroseconds ? "us" : "ns";
    try {
      write_string_attr(dt.get(), "unit", unit);
      Hid space(H5Screate(H5S_SCALAR));
      Hid dcpl(H5Pcreate(H5P_DATASET_CREATE));
      if (!dcpl.valid() || H5Pset_obj_track_times(dcpl.get(), 0) < 0) throw std::runtime_error(h5_error_text());
      Hid ds(H5Dcreate2(file.get(), "t_offset", H5T_STD_I64LE, space.get(), H5P_DEFAULT, dcpl.get(), H5P_DEFAULT));
      if (!ds.valid() || H5Dwrite(ds.get(), H5T_NATIVE_INT64, H5S_ALL, H5S_ALL, H5P_DEFAULT, &t_offset) < 0) {
        throw std::runtime_error(h5_error_text());
      }
      write_string_attr(ds.get(), "unit", unit);
      if (opt.sensor.known()) {
        write_int_attr(file.get(), "width", opt.sensor.width);
        write_int_attr(file.get(), "height", opt.sensor.height);
      }
    } catch (const std::runtime_error& e) {
      if (dynamic_cast<const InputError*>(&e) != nullptr) throw;
      throw InputError(path, 0, std::string("cannot write attributes: ") + e.what(), "a writable path with free space");
    }
    // Closing flushes the chunk caches (compression happens here); keep the first error.
    std::string error;
    for (Hid* h : {&dx, &dy, &dp, &dt, &dms, &file}) {
      if (!h->reset() && error.empty()) error = h5_error_text();
    }
    if (!error.empty()) throw InputError(path, 0, "closing the HDF5 file failed: " + error, "a writable path with free space");
    return rounded;
  }
};

H5EventWriter::H5EventWriter(const std::string& path, const Options& options) : impl_(std::make_unique<Impl>()) {
  H5Quiet quiet;
  impl_->path = path;
  impl_->opt = options;
  impl_->open();
}

H5EventWriter::~H5EventWriter() {
  H5Quiet quiet;
  try {
    impl_->close();
  } catch (...) {
    // Documented: the destructor closes silently; call close() to see errors.
  }
  impl_.reset();
}

void H5EventWriter::write(EventSpan events) {
  H5Quiet quiet;
  impl_->write(events);
}

int64_t H5EventWriter::close() {
  H5Quiet quiet;
  return impl_->close();
}

int64_t H5EventWriter::events_written() const { return impl_->total; }
int64_t H5EventWriter::rounded_events() const { return impl_->rounded; }
const std::string& H5EventWriter::path() const { return impl_->path; }

}  // namespace evio
