// HDF5 event reader (DSEC/TUM-VIE, E2VID/event_utils, MVSEC layouts): see evio/sensors/h5.h.
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


// =============================================================================================
// reader

struct H5EventReader::Impl {
  // One event column: a 1-D dataset, or one column of a 2-D dataset (col >= 0).
  struct Column {
    std::string name;  // dataset path in the file
    int col = -1;      // column of a 2-D dataset, -1 for 1-D
    hsize_t ncols = 1;
    Hid ds, fspace;
    NumType type;
    hsize_t rows = 0;
  };

  std::string path;
  DatasetOptions options;
  std::string layout;
  Hid apl;  // access list for every object open: refuses external links
  Hid file;
  Column x, y, t, p;
  bool matrix = false;  // x, y, t, p are the columns of one N x >=4 dataset (read together)
  hsize_t n = 0;        // events in the file
  TimeConv tconv;
  std::string t_offset_name;  // "" when the file has none
  int64_t t_offset_ns = 0;
  Column ms_index;      // ms_to_idx (name empty when absent)
  SensorSize sensor;
  std::string sensor_source;
  ReadReport report;
  SeekStats seek_stats;
  std::string event_form;  // expected form for bad-data messages

  // Fast path: x and y of one 16-bit integer type and an 8-bit p (DSEC, evio, event_utils) are
  // checked straight from the raw buffers; other types are converted into staging first.
  enum class Fused { kNone, kU16U8, kU16I8, kI16U8, kI16I8 };
  Fused fused = Fused::kNone;

  // Streaming state.
  size_t block = size_t{1} << 18;  // events per block read
  hsize_t next_row = 0;            // first row not yet loaded
  hsize_t blk_start = 0;           // row of staging element 0
  size_t blk_len = 0, blk_pos = 0;
  int64_t last_t = kBadTime + 1;
  PolarityConvention convention = PolarityConvention::kUnknown;
  std::array<bool, 4> pol_ok{{false, true, false, false}};
  bool finished = false;

  // Raw column bytes of the current block (one buffer in matrix mode) and converted values.
  std::vector<unsigned char> raw_x, raw_y, raw_t, raw_p;
  std::vector<int64_t> st_t;
  std::vector<uint32_t> st_x, st_y;
  std::vector<uint8_t> st_p;

  Impl(const std::string& p, const DatasetOptions& o) : path(p), options(o) {}

  [[noreturn]] void fail(const std::string& problem, const std::string& expected = {}) const {
    throw InputError(path, 0, problem, expected);
  }
  [[noreturn]] void fail_h5(const std::string& what, const std::string& expected = "an intact HDF5 file") const {
    throw InputError(path, 0, what + ": " + h5_error_text(), expected);
  }

  void open_file() {
    std::error_code ec;
    if (!fs::exists(path, ec)) fail("no such file", "an HDF5 event file");
    if (fs::is_directory(path, ec)) fail("is a directory", "an HDF5 event file");
    const htri_t is_h5 = H5Fis_hdf5(path.c_str());
    if (is_h5 == 0) {
      fail("not an HDF5 file: no HDF5 signature at byte offset 0 (nor at 512, 1024, ... for files with a user block)",
           "an HDF5 file (starting with the signature \\211HDF\\r\\n\\032\\n)");
    }
    if (is_h5 < 0) fail_h5("cannot read the file", "a readable HDF5 file");
    const std::string bad_superblock = check_superblock(path);
    if (!bad_superblock.empty()) fail(bad_superblock, "an intact HDF5 file");
    apl = make_access_list();
    if (!apl.valid()) fail_h5("HDF5 access setup failed");
    Hid fapl(H5Pcreate(H5P_FILE_ACCESS));
    if (!fapl.valid() || H5Pset_fclose_degree(fapl.get(), H5F_CLOSE_STRONG) < 0) fail_h5("HDF5 file access setup failed");
    file = Hid(H5Fopen(path.c_str(), H5F_ACC_RDONLY, fapl.get()));
    if (!file.valid()) {
      fail_h5("cannot open the HDF5 file", "an intact HDF5 file (a truncated or partly copied file fails here)");
    }
  }

  // Opens a dataset and checks everything that could make reading it fail or misbehave:
  // link kind, layout, filters (with their availability), chunk size and stored size.
  Hid open_dataset(const std::string& name, const std::string& role) const {
    bool ext = false;
    if (!link_exists(file.get(), name, apl.get(), &ext)) {
      if (ext) fail("dataset " + q_name(name) + " (" + role + ") is an external link to another file", "a dataset inside this file");
      fail("dataset " + q_name(name) + " (" + role + ") not found in the " + layout + " layout; top-level objects: " +
               describe_top_level(file.get(), apl.get()),
           "an HDF5 event file with the " + layout + " datasets, or set the dataset names in the HDF5 layout options");
    }
    if (!is_dataset(file.get(), name, apl.get())) {
      fail(q_name(name) + " (" + role + ") is not a dataset", "a dataset of event " + role);
    }
    Hid ds(H5Dopen2(file.get(), name.c_str(), apl.get()));
    if (!ds.valid()) fail_h5("cannot open dataset " + q_name(name));
    Hid dcpl(H5Dget_create_plist(ds.get()));
    if (!dcpl.valid()) fail_h5("cannot read the creation properties of dataset " + q_name(name));
    const H5D_layout_t lay = H5Pget_layout(dcpl.get());
    if (lay == H5D_VIRTUAL) fail("dataset " + q_name(name) + " is a virtual dataset (data in other files)", "a dataset stored in this file");
    if (lay < 0) fail_h5("cannot read the layout of dataset " + q_name(name));
    const int n_external = H5Pget_external_count(dcpl.get());
    if (n_external != 0) fail("dataset " + q_name(name) + " stores its data in external files", "a dataset stored in this file");
    const int nf = H5Pget_nfilters(dcpl.get());
    if (nf < 0) fail_h5("cannot read the filters of dataset " + q_name(name));
    for (int i = 0; i < nf; ++i) {
      unsigned flags = 0, config = 0;
      size_t n_cd = 0;
      char fname[128] = {0};
      const H5Z_filter_t id = H5Pget_filter2(dcpl.get(), static_cast<unsigned>(i), &flags, &n_cd, nullptr,
                                             sizeof(fname) - 1, fname, &config);
      if (id < 0) fail_h5("cannot read filter " + std::to_string(i) + " of dataset " + q_name(name));
      fname[sizeof(fname) - 1] = '\0';
      const htri_t avail = H5Zfilter_avail(id);
      H5Eclear2(H5E_DEFAULT);
      unsigned info = 0;
      const bool decodes = avail > 0 && H5Zget_filter_info(id, &info) >= 0 && (info & H5Z_FILTER_CONFIG_DECODE_ENABLED);
      H5Eclear2(H5E_DEFAULT);
      if (!decodes) {
        fail("dataset " + q_name(name) + " is compressed with HDF5 filter " + std::to_string(id) + " (" +
                 filter_name(id, fname) + "), which is not available" + (avail > 0 ? " for decoding" : ""),
             filter_install_hint(id));
      }
    }
    hsize_t chunk_bytes = 0;
    if (lay == H5D_CHUNKED) {
      hsize_t cdims[H5S_MAX_RANK] = {0};
      const int crank = H5Pget_chunk(dcpl.get(), H5S_MAX_RANK, cdims);
      if (crank <= 0) fail_h5("cannot read the chunk shape of dataset " + q_name(name));
      Hid ftype(H5Dget_type(ds.get()));
      long double bytes = ftype.valid() ? static_cast<long double>(H5Tget_size(ftype.get())) : 0.0L;
      for (int i = 0; i < crank; ++i) bytes *= static_cast<long double>(cdims[i]);
      if (bytes <= 0 || bytes > static_cast<long double>(kMaxChunkBytes)) {
        fail("dataset " + q_name(name) + " declares HDF5 chunks of " + std::to_string(static_cast<double>(bytes)) + " bytes",
             "chunks of 1 byte to 512 MiB (a corrupted dataset header)");
      }
      chunk_bytes = static_cast<hsize_t>(bytes);
    }
    // Unfiltered chunks are read straight into the caller's buffer (no cache copy); filtered
    // ones keep two chunks cached so a block boundary inside a chunk does not decompress it twice.
    const bool direct = lay == H5D_CHUNKED && nf == 0;
    if (direct || chunk_bytes > (hsize_t{1} << 19)) {
      Hid dapl = make_access_list();
      const size_t cache = direct ? 0 : static_cast<size_t>(2 * chunk_bytes);
      if (dapl.valid() && H5Pset_chunk_cache(dapl.get(), direct ? 0 : 521, cache, 1.0) >= 0) {
        ds.reset();
        ds = Hid(H5Dopen2(file.get(), name.c_str(), dapl.get()));
        if (!ds.valid()) fail_h5("cannot open dataset " + q_name(name));
      }
    }
    return ds;
  }

  // Checks that the stored bytes can hold the declared elements (a truncated or corrupted
  // dataset otherwise reads fill values or decompresses absurd amounts).
  void check_storage(const Column& c, hsize_t elems, size_t elem_bytes) const {
    if (elems == 0) return;
    Hid dcpl(H5Dget_create_plist(c.ds.get()));
    const bool filtered = dcpl.valid() && H5Pget_nfilters(dcpl.get()) > 0;
    const H5D_layout_t lay = dcpl.valid() ? H5Pget_layout(dcpl.get()) : H5D_LAYOUT_ERROR;
    H5Eclear2(H5E_DEFAULT);
    const long double declared = static_cast<long double>(elems) * static_cast<long double>(elem_bytes);
    const hsize_t stored = H5Dget_storage_size(c.ds.get());
    H5Eclear2(H5E_DEFAULT);
    const std::string what = "dataset " + q_name(c.name) + " declares " + std::to_string(elems) + " elements (" +
                             std::to_string(static_cast<double>(declared)) + " bytes) but stores ";
    if (stored == 0) fail(what + "no data", "a completely written dataset");
    if (!filtered && static_cast<long double>(stored) < declared) {
      fail(what + "only " + std::to_string(stored) + " bytes", "a completely written dataset");
    }
    if (filtered && declared > static_cast<long double>(stored) * kMaxCompressionRatio) {
      fail(what + "only " + std::to_string(stored) + " compressed bytes (ratio above 10000)",
           "a completely written dataset (a corrupted header declares more data than the file holds)");
    }
    if (lay == H5D_CHUNKED) {
      hsize_t nchunks = 0;
      hsize_t cdims[H5S_MAX_RANK] = {0};
      const int crank = H5Pget_chunk(dcpl.get(), H5S_MAX_RANK, cdims);
      if (crank >= 1 && cdims[0] > 0 && H5Dget_num_chunks(c.ds.get(), H5S_ALL, &nchunks) >= 0) {
        hsize_t dims[H5S_MAX_RANK] = {0};
        const int rank = H5Sget_simple_extent_dims(c.fspace.get(), dims, nullptr);
        long double expected = 1;
        for (int i = 0; i < rank && i < crank; ++i) {
          if (cdims[i] == 0) break;
          expected *= static_cast<long double>((dims[i] + cdims[i] - 1) / cdims[i]);
        }
        if (static_cast<long double>(nchunks) < expected) {
          fail("dataset " + q_name(c.name) + " has only " + std::to_string(nchunks) + " of " +
                   std::to_string(static_cast<double>(expected)) + " chunks written",
               "a completely written dataset");
        }
      }
      H5Eclear2(H5E_DEFAULT);
    }
  }

  // Opens column `name`: rank 1 (or rank 2 with one column), numeric type.
  void open_column(Column* c, const std::string& name, const std::string& role) {
    c->name = name;
    c->ds = open_dataset(name, role);
    c->fspace = Hid(H5Dget_space(c->ds.get()));
    if (!c->fspace.valid()) fail_h5("cannot read the shape of dataset " + q_name(name));
    const int rank = H5Sget_simple_extent_ndims(c->fspace.get());
    hsize_t dims[H5S_MAX_RANK] = {0};
    if (rank < 0 || H5Sget_simple_extent_dims(c->fspace.get(), dims, nullptr) < 0) {
      fail_h5("cannot read the shape of dataset " + q_name(name));
    }
    if (rank == 1) {
      c->col = -1;
      c->ncols = 1;
    } else if (rank == 2 && dims[1] == 1) {
      c->col = 0;
      c->ncols = 1;
    } else {
      std::string shape;
      for (int i = 0; i < rank; ++i) shape += (i ? " x " : "") + std::to_string(dims[i]);
      fail("dataset " + q_name(name) + " (" + role + ") has rank " + std::to_string(rank) +
               (rank > 0 ? " (shape " + shape + ")" : std::string(" (a scalar)")),
           "a 1-D dataset with one value per event");
    }
    c->rows = dims[0];
    set_type(c, role);
    check_storage(*c, c->rows, c->type.size);
  }

  void set_type(Column* c, const std::string& role) {
    Hid ftype(H5Dget_type(c->ds.get()));
    if (!ftype.valid()) fail_h5("cannot read the element type of dataset " + q_name(c->name));
    const std::optional<NumType> t = classify(ftype.get());
    if (!t) {
      fail("dataset " + q_name(c->name) + " (" + role + ") has element type class " +
               class_name(H5Tget_class(ftype.get())) + " of " + std::to_string(H5Tget_size(ftype.get())) + " bytes",
           "integer (up to 64 bit), float or enum (bool) values");
    }
    c->type = *t;
  }

  void open_matrix(const std::string& name) {
    matrix = true;
    Column m;
    m.name = name;
    m.ds = open_dataset(name, "events");
    m.fspace = Hid(H5Dget_space(m.ds.get()));
    if (!m.fspace.valid()) fail_h5("cannot read the shape of dataset " + q_name(name));
    const int rank = H5Sget_simple_extent_ndims(m.fspace.get());
    hsize_t dims[H5S_MAX_RANK] = {0};
    if (rank < 0 || H5Sget_simple_extent_dims(m.fspace.get(), dims, nullptr) < 0) {
      fail_h5("cannot read the shape of dataset " + q_name(name));
    }
    if (rank != 2 || dims[1] < 4) {
      std::string shape;
      for (int i = 0; i < rank; ++i) shape += (i ? " x " : "") + std::to_string(dims[i]);
      fail("dataset " + q_name(name) + " has rank " + std::to_string(rank) + (rank > 0 ? " (shape " + shape + ")" : ""),
           "an N x 4 matrix with columns x, y, t, p (MVSEC)");
    }
    set_type(&m, "events");
    check_storage(m, dims[0], m.type.size * static_cast<size_t>(dims[1]));
    const char* roles[4] = {"x", "y", "t", "p"};
    Column* cols[4] = {&x, &y, &t, &p};
    for (int i = 0; i < 4; ++i) {
      cols[i]->name = name + "[:, " + std::to_string(i) + "] (" + roles[i] + ")";
      cols[i]->col = i;
      cols[i]->ncols = dims[1];
      cols[i]->rows = dims[0];
      cols[i]->type = m.type;
    }
    // All four share the dataset; x holds the handles.
    x.ds = std::move(m.ds);
    x.fspace = std::move(m.fspace);
  }

  const Column& data_of(const Column& c) const { return matrix ? x : c; }

  // Reads rows [start, start + count) of column c (ncols_read columns starting at c.col for
  // 2-D datasets) into buf.
  void read_rows(const Column& c, hsize_t start, hsize_t count, hsize_t ncols_read, void* buf) const {
    const Column& d = data_of(c);
    if (count == 0) return;
    herr_t r;
    if (c.col < 0) {
      const hsize_t s[1] = {start}, k[1] = {count};
      r = H5Sselect_hyperslab(d.fspace.get(), H5S_SELECT_SET, s, nullptr, k, nullptr);
    } else {
      const hsize_t s[2] = {start, static_cast<hsize_t>(c.col)}, k[2] = {count, ncols_read};
      r = H5Sselect_hyperslab(d.fspace.get(), H5S_SELECT_SET, s, nullptr, k, nullptr);
    }
    if (r < 0) fail_h5("cannot select events " + std::to_string(start) + ".." + std::to_string(start + count) + " of " + q_name(c.name));
    const hsize_t mdims[1] = {count * (c.col < 0 ? 1 : ncols_read)};
    Hid mspace(H5Screate_simple(1, mdims, nullptr));
    if (!mspace.valid() || H5Dread(d.ds.get(), c.type.mem(), mspace.get(), d.fspace.get(), H5P_DEFAULT, buf) < 0) {
      fail_h5("cannot read events " + std::to_string(start) + ".." + std::to_string(start + count - 1) + " of dataset " + q_name(c.name),
              "an intact HDF5 file (a corrupted or truncated chunk fails here)");
    }
  }

  // Reads a scalar (rank 0 or one element) numeric dataset or attribute.
  Scalar read_scalar_dataset(const std::string& name, const std::string& role) const {
    Hid ds = open_dataset(name, role);
    Hid space(H5Dget_space(ds.get()));
    Hid ftype(H5Dget_type(ds.get()));
    if (!space.valid() || !ftype.valid()) fail_h5("cannot read dataset " + q_name(name));
    if (H5Sget_simple_extent_npoints(space.get()) != 1) {
      fail("dataset " + q_name(name) + " (" + role + ") holds " + std::to_string(H5Sget_simple_extent_npoints(space.get())) + " values",
           "a scalar (one value)");
    }
    return read_scalar(path, ftype.get(), name, role, [&](hid_t mem, void* buf) {
      return H5Dread(ds.get(), mem, H5S_ALL, H5S_ALL, H5P_DEFAULT, buf);
    });
  }

  // The `unit` attribute of dataset `name`, nullopt when absent.
  std::optional<TimeUnit> unit_attr(hid_t ds, const std::string& name) const {
    const std::optional<std::string> u = read_string_attr(path, ds, "dataset " + q_name(name), "unit");
    if (!u) return std::nullopt;
    const std::optional<TimeUnit> unit = parse_unit_text(*u);
    if (!unit) fail("dataset " + q_name(name) + " attribute unit = \"" + *u + "\" is not a time unit", "unit \"s\", \"ms\", \"us\" or \"ns\"");
    return unit;
  }

  // ---- layout ---------------------------------------------------------------------------------

  void resolve_layout() {
    const H5Layout& L = options.h5;
    H5Layout::Kind kind = L.kind;
    std::string xs = L.x, ys = L.y, ts = L.t, ps = L.p;
    if (kind == H5Layout::Kind::kAuto) {
      if (is_dataset(file.get(), L.t, apl.get())) {
        kind = H5Layout::Kind::kColumns;
        layout = L.t == H5Layout().t ? "DSEC" : "columns";
      } else if (is_dataset(file.get(), "events/ts", apl.get())) {
        kind = H5Layout::Kind::kColumns;
        layout = "event_utils";
        xs = "events/xs";
        ys = "events/ys";
        ts = "events/ts";
        ps = "events/ps";
      } else if (is_dataset(file.get(), L.matrix, apl.get())) {
        kind = H5Layout::Kind::kMatrix;
        layout = L.matrix == H5Layout().matrix ? "MVSEC" : "matrix";
      } else {
        fail("no event datasets found: looked for " + q_name(L.t) + " (DSEC/TUM-VIE), 'events/ts' (event_utils) and " +
                 q_name(L.matrix) + " (MVSEC); top-level objects: " + describe_top_level(file.get(), apl.get()),
             "an HDF5 event file in the DSEC, event_utils or MVSEC layout, or set the dataset names in the HDF5 "
             "layout options");
      }
    } else {
      layout = kind == H5Layout::Kind::kColumns ? (L.t == H5Layout().t ? "DSEC" : "columns")
                                                : (L.matrix == H5Layout().matrix ? "MVSEC" : "matrix");
    }
    if (kind == H5Layout::Kind::kColumns) {
      open_column(&x, xs, "x");
      open_column(&y, ys, "y");
      open_column(&t, ts, "t");
      open_column(&p, ps, "p");
      if (x.rows != y.rows || x.rows != t.rows || x.rows != p.rows) {
        fail("event columns have different lengths: " + q_name(x.name) + " " + std::to_string(x.rows) + ", " +
                 q_name(y.name) + " " + std::to_string(y.rows) + ", " + q_name(t.name) + " " + std::to_string(t.rows) +
                 ", " + q_name(p.name) + " " + std::to_string(p.rows),
             "x, y, t and p datasets of equal length");
      }
    } else {
      open_matrix(L.matrix);
    }
    n = t.rows;
    // DSEC and evio files carry t_offset and ms_to_idx; other layouts only when configured so.
    const bool dsec_like = layout == "DSEC" || layout == "columns";
    if (dsec_like && !L.t_offset.empty() && link_exists(file.get(), L.t_offset, apl.get())) t_offset_name = L.t_offset;
    if (dsec_like && !L.ms_to_idx.empty() && link_exists(file.get(), L.ms_to_idx, apl.get())) {
      // The index only speeds up seeking: a broken one is reported and not used.
      try {
        open_column(&ms_index, L.ms_to_idx, "ms_to_idx index");
        if (ms_index.type.is_float) fail("dataset " + q_name(L.ms_to_idx) + " holds floats", "unsigned integer event indices");
      } catch (const InputError& e) {
        log_warning(std::string(e.what()) + "; seeking without the index");
        ms_index = Column();
      }
    }
  }

  // ---- time unit --------------------------------------------------------------------------------

  // Reads the t values of rows [a, b) converted to ns (b - a small).
  void read_times(hsize_t a, hsize_t b, std::vector<int64_t>* out) {
    const size_t count = static_cast<size_t>(b - a);
    std::vector<unsigned char> raw(count * t.type.size);
    read_rows(t, a, count, 1, raw.data());
    out->resize(count);
    with_type(t.type.num, raw.data(), [&](auto* v) { convert_times(v, 1, count, tconv, out->data()); });
  }

  void resolve_time() {
    const std::string t_ds_name = matrix ? x.name.substr(0, x.name.find('[')) : t.name;
    const std::optional<TimeUnit> attr = unit_attr(data_of(t).ds.get(), t_ds_name);
    std::optional<Scalar> off;
    std::optional<TimeUnit> off_attr;
    if (!t_offset_name.empty()) {
      off = read_scalar_dataset(t_offset_name, "time offset");
      Hid ds = open_dataset(t_offset_name, "time offset");
      off_attr = unit_attr(ds.get(), t_offset_name);
    }
    TimeUnit unit = TimeUnit::kAuto;
    std::string reason;
    bool guessed = false;
    if (options.h5.time_unit != TimeUnit::kAuto) {
      unit = options.h5.time_unit;
      reason = "given";
    } else if (options.text.time_unit != TimeUnit::kAuto) {
      unit = options.text.time_unit;
      reason = "given";
    } else if (attr) {
      unit = *attr;
      reason = "unit attribute of " + q_name(t_ds_name);
    } else if (t.type.is_float) {
      unit = TimeUnit::kSeconds;
      reason = "floating-point timestamps without a unit attribute";
      guessed = true;
    } else {
      unit = TimeUnit::kMicroseconds;
      reason = "integer timestamps without a unit attribute (DSEC convention)";
      guessed = true;
      // Integers above 1e17 are ns: 1e17 us would be 3000 years.
      double first = 0;
      if (n > 0) {
        std::vector<unsigned char> raw(t.type.size);
        read_rows(t, 0, 1, 1, raw.data());
        with_type(t.type.num, raw.data(), [&](auto* v) { first = static_cast<double>(v[0]); });
      }
      const double off_raw = off && !off_attr ? off->as_double() : 0.0;
      if (first + off_raw > 1e17) {
        unit = TimeUnit::kNanoseconds;
        reason = "integer timestamps above 1e17 without a unit attribute";
      }
    }
    // t_offset: in its own unit attribute, else in the unit of t.
    int64_t offset_ns = 0;
    if (off) {
      const TimeUnit ou = off_attr ? *off_attr : unit;
      const TimeConv c{static_cast<int64_t>(std::llround(std::pow(10.0, time_unit_exponent(ou)))), 0};
      if (off->is_float) {
        convert_times(&off->f, 1, 1, c, &offset_ns);
      } else {
        convert_times(&off->i, 1, 1, c, &offset_ns);
      }
      if (offset_ns == kBadTime) {
        fail("dataset " + q_name(t_offset_name) + " = " + (off->is_float ? std::to_string(off->f) : std::to_string(off->i)) +
                 " " + time_unit_name(ou) + " does not fit int64 nanoseconds",
             "a time offset within +-292 years");
      }
    }
    t_offset_ns = offset_ns;
    tconv.mult = static_cast<int64_t>(std::llround(std::pow(10.0, time_unit_exponent(unit))));
    tconv.offset_ns = offset_ns;
    report.time_unit = unit;
    report.time_unit_reason = reason;
    if (guessed && options.text.check_time_unit && n >= 1000) {
      const hsize_t k = std::min<hsize_t>(n, 10000);
      std::vector<int64_t> ts;
      read_times(0, k, &ts);
      if (ts.front() != kBadTime && ts.back() != kBadTime && ts.back() > ts.front()) {
        const double rate = static_cast<double>(k - 1) / ns_to_seconds(ts.back() - ts.front());
        if (rate < 10.0 || rate > 2e9) {
          std::ostringstream s;
          s << "time unit " << time_unit_name(unit) << " (" << reason << ") implies " << rate
            << " events/s over the first " << k << " events of " << q_name(t.name);
          fail(s.str(), "event rates of 10..2e9 events/s; set the time unit (h5 time_unit) or add a unit attribute");
        }
      }
    }
  }

  // ---- sensor size ---------------------------------------------------------------------------

  std::optional<int64_t> sensor_value(hid_t obj, const std::string& obj_name, const char* name, bool dataset_too) {
    std::optional<Scalar> s = read_number_attr(path, obj, obj_name, name);
    std::string where = obj_name + " attribute " + name;
    if (!s && dataset_too && is_dataset(obj, name, apl.get())) {
      Hid ds(H5Dopen2(obj, name, apl.get()));
      Hid space(ds.valid() ? H5Dget_space(ds.get()) : -1);
      Hid ftype(ds.valid() ? H5Dget_type(ds.get()) : -1);
      if (ds.valid() && space.valid() && ftype.valid() && H5Sget_simple_extent_npoints(space.get()) == 1) {
        s = read_scalar(path, ftype.get(), name, "sensor size", [&](hid_t mem, void* buf) {
          return H5Dread(ds.get(), mem, H5S_ALL, H5S_ALL, H5P_DEFAULT, buf);
        });
        where = "dataset " + q_name(name);
      }
      H5Eclear2(H5E_DEFAULT);
    }
    if (!s) return std::nullopt;
    const double v = s->as_double();
    if (!(v >= 1 && v <= 65536) || v != std::floor(v)) {
      fail(where + " = " + std::to_string(v) + " is not a sensor size", "a whole number of pixels in 1..65536");
    }
    sensor_source = where;
    return static_cast<int64_t>(v);
  }

  void resolve_sensor() {
    std::vector<std::pair<hid_t, std::string>> places = {{file.get(), "root group"}};
    Hid events_group;
    if (link_exists(file.get(), "events", apl.get())) {
      events_group = Hid(H5Oopen(file.get(), "events", apl.get()));
      H5Eclear2(H5E_DEFAULT);
      if (events_group.valid() && H5Iget_type(events_group.get()) == H5I_GROUP) places.push_back({events_group.get(), "group 'events'"});
    }
    for (const auto& [obj, name] : places) {
      for (const auto& [wn, hn] : {std::pair<const char*, const char*>{"width", "height"}, {"sensor_width", "sensor_height"}}) {
        const std::optional<int64_t> w = sensor_value(obj, name, wn, obj == file.get());
        const std::optional<int64_t> h = sensor_value(obj, name, hn, obj == file.get());
        if (w && h) {
          sensor = SensorSize{static_cast<int>(*w), static_cast<int>(*h)};
          sensor_source = name + " " + wn + "/" + hn;
          if (options.text.sensor.known() &&
              (options.text.sensor.width != sensor.width || options.text.sensor.height != sensor.height)) {
            log_warning(path + ": the file states a " + std::to_string(sensor.width) + "x" + std::to_string(sensor.height) +
                        " sensor (" + sensor_source + "); the " + std::to_string(options.text.sensor.width) + "x" +
                        std::to_string(options.text.sensor.height) + " sensor in the options is not used");
          }
          return;
        }
      }
    }
    sensor = options.text.sensor;
    sensor_source = sensor.known() ? "options" : "unknown";
  }

  void open() {
    std::string why;
    if (!options.Validate(&why)) fail("invalid dataset options: " + why);
    report.path = path;
    open_file();
    resolve_layout();
    resolve_time();
    resolve_sensor();
    const PolarityConvention given = options.h5.polarity;
    if (given == PolarityConvention::kZeroOne) pol_ok = {{false, true, true, false}};
    if (given == PolarityConvention::kMinusPlusOne) pol_ok = {{false, true, false, true}};
    convention = given;
    report.polarity = given;
    if (!matrix && x.type.num == y.type.num && (x.type.num == Num::kU16 || x.type.num == Num::kI16) &&
        (p.type.num == Num::kU8 || p.type.num == Num::kI8)) {
      const bool u16 = x.type.num == Num::kU16, u8 = p.type.num == Num::kU8;
      fused = u16 ? (u8 ? Fused::kU16U8 : Fused::kU16I8) : (u8 ? Fused::kI16U8 : Fused::kI16I8);
    }
    event_form = "events with x, y whole pixels" +
                 (sensor.known() ? " inside the " + std::to_string(sensor.width) + "x" + std::to_string(sensor.height) + " sensor"
                                 : std::string(" in 0..65535")) +
                 ", p 0/1 or -1/+1, t in " + time_unit_name(report.time_unit) + " never decreasing";
    // Block: a multiple of the t dataset's chunk length near 2^18 events, so block reads are
    // chunk-aligned.
    Hid dcpl(H5Dget_create_plist(data_of(t).ds.get()));
    if (dcpl.valid() && H5Pget_layout(dcpl.get()) == H5D_CHUNKED) {
      hsize_t cdims[H5S_MAX_RANK] = {0};
      if (H5Pget_chunk(dcpl.get(), H5S_MAX_RANK, cdims) >= 1 && cdims[0] > 0 && cdims[0] <= (hsize_t{1} << 22)) {
        const hsize_t c = cdims[0];
        block = static_cast<size_t>(std::max<hsize_t>(c, ((hsize_t{1} << 18) + c / 2) / c * c));
      }
    }
    H5Eclear2(H5E_DEFAULT);
    log_info(path + ": HDF5 " + layout + " layout, " + std::to_string(n) + " events, time unit " +
             time_unit_name(report.time_unit) + " (" + report.time_unit_reason + ")" +
             (t_offset_name.empty() ? "" : ", t_offset " + std::to_string(t_offset_ns) + " ns") +
             ", sensor " + (sensor.known() ? std::to_string(sensor.width) + "x" + std::to_string(sensor.height) + " (" + sensor_source + ")" : "unknown"));
  }

  // ---- streaming -------------------------------------------------------------------------------

  // Raw element pointer and stride of column c in the current block.
  const unsigned char* raw_ptr(const Column& c) const {
    if (matrix) return raw_x.data() + static_cast<size_t>(c.col) * x.type.size;
    return (&c == &x ? raw_x : &c == &y ? raw_y : &c == &t ? raw_t : raw_p).data();
  }
  size_t raw_stride() const { return matrix ? 4 : 1; }
  uint32_t coord_at(const Column& c, size_t i) const {
    uint32_t v = kBadCoord;
    with_type(c.type.num, raw_ptr(c), [&](auto* a) { convert_coords(a + i * raw_stride(), 1, 1, &v); });
    return v;
  }
  uint8_t polarity_code_at(size_t i) const {
    uint8_t v = 0;
    with_type(p.type.num, raw_ptr(p), [&](auto* a) { convert_polarity(a + i * raw_stride(), 1, 1, &v); });
    return v;
  }
  // Raw value of element i of the current block in column c, as text.
  std::string raw_text(const Column& c, size_t i) const { return value_text(c.type.num, raw_ptr(c), i * raw_stride()); }

  void load_block() {
    const size_t count = static_cast<size_t>(std::min<hsize_t>(block, n - next_row));
    st_t.resize(count);
    if (matrix) {
      st_x.resize(count);
      st_y.resize(count);
      st_p.resize(count);
      const size_t stride = 4;
      raw_x.resize(count * stride * x.type.size);
      read_rows(x, next_row, count, 4, raw_x.data());
      const unsigned char* base = raw_x.data();
      const size_t es = x.type.size;
      with_type(x.type.num, base + 0 * es, [&](auto* v) { convert_coords(v, stride, count, st_x.data()); });
      with_type(x.type.num, base + 1 * es, [&](auto* v) { convert_coords(v, stride, count, st_y.data()); });
      with_type(x.type.num, base + 2 * es, [&](auto* v) { convert_times(v, stride, count, tconv, st_t.data()); });
      with_type(x.type.num, base + 3 * es, [&](auto* v) { convert_polarity(v, stride, count, st_p.data()); });
    } else {
      raw_x.resize(count * x.type.size);
      raw_y.resize(count * y.type.size);
      raw_t.resize(count * t.type.size);
      raw_p.resize(count * p.type.size);
      read_rows(x, next_row, count, 1, raw_x.data());
      read_rows(y, next_row, count, 1, raw_y.data());
      read_rows(t, next_row, count, 1, raw_t.data());
      read_rows(p, next_row, count, 1, raw_p.data());
      with_type(t.type.num, raw_t.data(), [&](auto* v) { convert_times(v, 1, count, tconv, st_t.data()); });
      if (fused == Fused::kNone) {
        st_x.resize(count);
        st_y.resize(count);
        st_p.resize(count);
        with_type(x.type.num, raw_x.data(), [&](auto* v) { convert_coords(v, 1, count, st_x.data()); });
        with_type(y.type.num, raw_y.data(), [&](auto* v) { convert_coords(v, 1, count, st_y.data()); });
        with_type(p.type.num, raw_p.data(), [&](auto* v) { convert_polarity(v, 1, count, st_p.data()); });
      }
    }
    blk_start = next_row;
    blk_len = count;
    blk_pos = 0;
    next_row += count;
  }

  void bad(const char* kind, int64_t index, const std::string& problem) {
    const std::string msg = "event " + std::to_string(index) + ": " + problem;
    if (options.text.on_bad_line == BadLinePolicy::kError) {
      throw InputError(path, 0, msg, event_form + "; or skip such events with --on-bad-line warn");
    }
    ReadReport::Skipped& s = report.skipped[kind];
    if (s.count == 0) {
      s.first_line = index;
      s.first_message = msg;
    }
    ++s.count;
  }

  // Decides about block element i that failed the fast check: emits it into *e (returns true)
  // when it only fixed the polarity convention, otherwise reports it as bad and returns false.
  bool slow_path(size_t i, Event* e) {
    const int64_t index = static_cast<int64_t>(blk_start + i);
    const int64_t tn = st_t[i];
    if (tn == kBadTime) {
      bad("malformed", index, "timestamp " + raw_text(t, i) + " (" + t.name + ") is not finite or does not fit int64 ns");
      return false;
    }
    const uint32_t xv = coord_at(x, i), yv = coord_at(y, i);
    if (xv == kBadCoord || yv == kBadCoord) {
      const bool xbad = xv == kBadCoord;
      bad("malformed", index, std::string(xbad ? "x" : "y") + " = " + raw_text(xbad ? x : y, i) + " (" +
                                  (xbad ? x.name : y.name) + ") is not a whole pixel coordinate in 0..65535");
      return false;
    }
    if (sensor.known() && (xv >= static_cast<uint32_t>(sensor.width) || yv >= static_cast<uint32_t>(sensor.height))) {
      bad("outside sensor", index, "pixel (" + std::to_string(xv) + ", " + std::to_string(yv) + ") outside the " +
                                       std::to_string(sensor.width) + "x" + std::to_string(sensor.height) + " sensor");
      return false;
    }
    const uint8_t pc = polarity_code_at(i);
    if (pc == 0) {
      bad("polarity", index, "p = " + raw_text(p, i) + " (" + p.name + ") is not 0, 1, -1 or +1");
      return false;
    }
    if (!pol_ok[pc]) {
      const PolarityConvention seen = pc == 2 ? PolarityConvention::kZeroOne : PolarityConvention::kMinusPlusOne;
      if (convention != PolarityConvention::kUnknown) {
        bad("polarity", index, "p = " + raw_text(p, i) + " (" + p.name + "): polarity convention " +
                                   polarity_convention_name(seen) + " mixed with " + polarity_convention_name(convention) +
                                   (options.h5.polarity != PolarityConvention::kUnknown ? " given in the options" : " used earlier in the file"));
        return false;
      }
      convention = seen;
      report.polarity = seen;
      pol_ok[pc] = true;
    }
    if (tn < last_t) {
      bad("time order", index, "timestamp " + format_seconds(tn) + " s (" + t.name + " = " + raw_text(t, i) +
                                   ") is earlier than the previous event's " + format_seconds(last_t) + " s");
      return false;
    }
    *e = Event{tn, static_cast<uint16_t>(xv), static_cast<uint16_t>(yv), static_cast<int8_t>(pc == 1 ? 1 : -1)};
    return true;
  }

  template <bool kCodes, typename P>
  static uint8_t polarity_code(P v) {
    if constexpr (kCodes) {
      return v;  // already a code (staging)
    } else if constexpr (std::is_same_v<P, uint8_t>) {
      return v == 1 ? 1 : v == 0 ? 2 : 0;
    } else {
      return v == 1 ? 1 : v == 0 ? 2 : v == -1 ? 3 : 0;
    }
  }

  // Writes the valid events among block elements [blk_pos, blk_pos + take) to dst and returns
  // how many. XY is the coordinate type (uint32_t staging with kBadCoord, or raw uint16_t /
  // int16_t), P the polarity type (raw uint8_t / int8_t, or staged polarity codes when kCodes).
  template <bool kCodes, typename XY, typename P>
  size_t assemble(const XY* xx, const XY* yy, const P* pp, size_t take, Event* dst) {
    const uint32_t wl = sensor.known() ? static_cast<uint32_t>(sensor.width) : 65536u;
    const uint32_t hl = sensor.known() ? static_cast<uint32_t>(sensor.height) : 65536u;
    const int64_t* tt = st_t.data();
    const std::array<bool, 4> ok = pol_ok;
    int64_t last = last_t;
    size_t k = 0;
    const size_t end = blk_pos + take;
    for (size_t i = blk_pos; i < end; ++i) {
      const int64_t tn = tt[i];
      // Negative int16 values turn into large uint32 values and fail the bounds check.
      const uint32_t xv = static_cast<uint32_t>(static_cast<std::conditional_t<std::is_signed_v<XY>, int32_t, uint32_t>>(xx[i]));
      const uint32_t yv = static_cast<uint32_t>(static_cast<std::conditional_t<std::is_signed_v<XY>, int32_t, uint32_t>>(yy[i]));
      const uint8_t pc = polarity_code<kCodes>(pp[i]);
      if (__builtin_expect(tn >= last && xv < wl && yv < hl && ok[pc & 3], 1)) {
        Event& e = dst[k++];
        e.t_ns = tn;
        e.x = static_cast<uint16_t>(xv);
        e.y = static_cast<uint16_t>(yv);
        e.polarity = static_cast<int8_t>(pc == 1 ? 1 : -1);
        last = tn;
      } else {
        last_t = last;
        if (slow_path(i, &dst[k])) {
          ++k;
          last = tn;
        }
        if (pol_ok != ok) {  // the polarity convention was fixed: continue with the new table
          last_t = last;
          blk_pos = i + 1;
          return k;
        }
      }
    }
    last_t = last;
    blk_pos = end;
    return k;
  }

  size_t assemble_block(size_t take, Event* v) {
    switch (fused) {
      case Fused::kU16U8:
        return assemble<false>(reinterpret_cast<const uint16_t*>(raw_x.data()), reinterpret_cast<const uint16_t*>(raw_y.data()),
                               reinterpret_cast<const uint8_t*>(raw_p.data()), take, v);
      case Fused::kU16I8:
        return assemble<false>(reinterpret_cast<const uint16_t*>(raw_x.data()), reinterpret_cast<const uint16_t*>(raw_y.data()),
                               reinterpret_cast<const int8_t*>(raw_p.data()), take, v);
      case Fused::kI16U8:
        return assemble<false>(reinterpret_cast<const int16_t*>(raw_x.data()), reinterpret_cast<const int16_t*>(raw_y.data()),
                               reinterpret_cast<const uint8_t*>(raw_p.data()), take, v);
      case Fused::kI16I8:
        return assemble<false>(reinterpret_cast<const int16_t*>(raw_x.data()), reinterpret_cast<const int16_t*>(raw_y.data()),
                               reinterpret_cast<const int8_t*>(raw_p.data()), take, v);
      case Fused::kNone:
        break;
    }
    return assemble<true>(st_x.data(), st_y.data(), st_p.data(), take, v);
  }

  size_t read(EventBuffer* out, size_t max_events) {
    std::vector<Event>& v = out->events();
    const size_t n0 = v.size();
    size_t produced = 0;
    try {
      while (produced < max_events) {
        if (blk_pos == blk_len) {
          if (next_row >= n) break;
          load_block();
        }
        const size_t take = std::min(blk_len - blk_pos, max_events - produced);
        v.resize(n0 + produced + take);
        produced += assemble_block(take, v.data() + n0 + produced);
        v.resize(n0 + produced);
      }
    } catch (...) {
      v.resize(n0 + produced);
      throw;
    }
    report.records += static_cast<int64_t>(produced);
    report.lines = static_cast<int64_t>(blk_start + blk_pos);
    if (produced == 0 && !finished) {
      finished = true;
      if (report.skipped_total() > 0) {
        std::ostringstream s;
        s << path << ": skipped " << report.skipped_total() << " bad event(s):";
        for (const auto& kv : report.skipped) {
          s << " " << kv.second.count << " " << kv.first << " (first: " << kv.second.first_message << ");";
        }
        log_warning(s.str());
      }
    }
    return produced;
  }

  // ---- seeking ---------------------------------------------------------------------------------

  int64_t time_at(hsize_t i) {
    std::vector<int64_t> v;
    read_times(i, i + 1, &v);
    ++seek_stats.t_values_read;
    return v[0];
  }

  // ms_to_idx[i] clamped to [0, n] (a hint: seek() verifies the bracket it gives).
  hsize_t index_at(hsize_t i) {
    unsigned char raw[8] = {0};
    read_rows(ms_index, i, 1, 1, raw);
    ++seek_stats.index_values_read;
    double d = 0;
    with_type(ms_index.type.num, raw, [&](auto* v) { d = static_cast<double>(v[0]); });
    if (!(d > 0)) return 0;
    if (d >= static_cast<double>(n)) return n;
    return static_cast<hsize_t>(d);
  }

  // First row in [lo, hi) with t >= t_ns (hi when none), assuming sorted times in the range.
  hsize_t search(hsize_t lo, hsize_t hi, int64_t t_ns) {
    while (hi - lo > 2048) {
      const hsize_t mid = lo + (hi - lo) / 2;
      const int64_t tm = time_at(mid);
      if (tm != kBadTime && tm >= t_ns) {
        hi = mid;
      } else {
        lo = mid + 1;
      }
    }
    std::vector<int64_t> v;
    read_times(lo, hi, &v);
    seek_stats.t_values_read += static_cast<int64_t>(v.size());
    for (size_t i = 0; i < v.size(); ++i) {
      if (v[i] != kBadTime && v[i] >= t_ns) return lo + i;
    }
    return hi;
  }

  void seek(int64_t t_ns) {
    seek_stats = SeekStats();
    hsize_t idx = 0;
    bool done = false;
    if (ms_index.ds.valid() && ms_index.rows > 0 && n > 0) {
      // ms bucket of t_ns relative to t_offset (floor division).
      int64_t rel = 0;
      int64_t ms = 0;
      if (!__builtin_sub_overflow(t_ns, t_offset_ns, &rel)) {
        ms = rel / 1000000 - ((rel % 1000000) < 0 ? 1 : 0);
        const int64_t m = static_cast<int64_t>(ms_index.rows);
        hsize_t lo = 0, hi = n;
        if (ms >= 0 && ms < m) lo = index_at(static_cast<hsize_t>(ms));
        if (ms >= m) lo = index_at(static_cast<hsize_t>(m - 1));
        if (ms + 1 >= 0 && ms + 1 < m) hi = index_at(static_cast<hsize_t>(ms + 1));
        if (ms < 0) hi = index_at(0);
        // The index is a hint: verify the bracket with the neighbouring timestamps.
        if (lo <= hi) {
          bool ok = true;
          if (lo > 0) {
            const int64_t tb = time_at(lo - 1);
            ok = tb != kBadTime && tb < t_ns;
          }
          if (ok && hi < n) {
            const int64_t ta = time_at(hi);
            ok = ta != kBadTime && ta >= t_ns;
          }
          if (ok) {
            idx = search(lo, hi, t_ns);
            seek_stats.used_index = true;
            done = true;
          }
        }
      }
    }
    if (!done) idx = n == 0 ? 0 : search(0, n, t_ns);
    next_row = idx;
    blk_start = idx;
    blk_len = blk_pos = 0;
    last_t = kBadTime + 1;
    finished = false;
  }

  StreamInfo info(const Column& c, const std::string& unit) const {
    StreamInfo s;
    s.name = c.name;
    s.type = c.type.name + (unit.empty() ? "" : " " + unit);
    s.messages = static_cast<int64_t>(c.rows);
    s.count_unit = "elements";
    s.selected = true;
    return s;
  }
};

H5EventReader::H5EventReader(const std::string& path, const DatasetOptions& options)
    : impl_(std::make_unique<Impl>(path, options)) {
  H5Quiet quiet;
  impl_->open();
}

H5EventReader::~H5EventReader() {
  H5Quiet quiet;
  impl_.reset();
}

const std::string& H5EventReader::path() const { return impl_->path; }
SensorSize H5EventReader::sensor_size() const { return impl_->sensor; }
const ReadReport& H5EventReader::event_report() const { return impl_->report; }
const std::string& H5EventReader::layout_name() const { return impl_->layout; }
int64_t H5EventReader::event_count() const { return static_cast<int64_t>(impl_->n); }
const H5EventReader::SeekStats& H5EventReader::last_seek_stats() const { return impl_->seek_stats; }

double H5EventReader::progress() const {
  if (impl_->n == 0) return 1.0;
  return static_cast<double>(impl_->blk_start + impl_->blk_pos) / static_cast<double>(impl_->n);
}

size_t H5EventReader::read_events(EventBuffer* out, size_t max_events) {
  H5Quiet quiet;
  return impl_->read(out, max_events);
}

bool H5EventReader::seek_events(int64_t t_ns) {
  H5Quiet quiet;
  impl_->seek(t_ns);
  return true;
}

std::vector<StreamInfo> H5EventReader::streams() const {
  const Impl& m = *impl_;
  std::vector<StreamInfo> s;
  const std::string unit = time_unit_name(m.report.time_unit);
  if (m.matrix) {
    StreamInfo e = m.info(m.x, "");
    e.name = m.x.name.substr(0, m.x.name.find('['));
    e.type = m.x.type.name + " N x " + std::to_string(m.x.ncols) + " (x, y, t[" + unit + "], p)";
    s.push_back(e);
  } else {
    s.push_back(m.info(m.x, "px"));
    s.push_back(m.info(m.y, "px"));
    s.push_back(m.info(m.t, unit));
    s.push_back(m.info(m.p, ""));
  }
  if (!m.t_offset_name.empty()) {
    StreamInfo o;
    o.name = m.t_offset_name;
    o.type = "scalar, " + std::to_string(m.t_offset_ns) + " ns";
    o.messages = 1;
    o.count_unit = "elements";
    o.selected = true;
    s.push_back(o);
  }
  if (m.ms_index.ds.valid()) s.push_back(m.info(m.ms_index, "event index per ms"));
  return s;
}

int64_t h5_open_object_count() {
  H5Quiet quiet;
  const ssize_t n = H5Fget_obj_count(static_cast<hid_t>(H5F_OBJ_ALL), H5F_OBJ_ALL);
  return n < 0 ? -1 : static_cast<int64_t>(n);
}

std::unique_ptr<DatasetReader> open_h5_dataset(const std::string& path, const DatasetOptions& options) {
  return std::make_unique<H5EventReader>(path, options);
}

// =============================================================================================
// writer

}  // namespace evio
