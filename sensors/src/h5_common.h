// HDF5 helpers shared by the HDF5 event reader (h5_reader.cc) and writer (h5_writer.cc): owned
// identifiers, silenced error stacks, numeric types, column conversions, links and attributes,
// filters. Internal to evio::sensors.
#pragma once

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
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "evio/sensors/h5.h"

namespace evio::detail::h5 {
namespace fs = std::filesystem;


constexpr H5Z_filter_t kBloscFilter = 32001;
constexpr int64_t kBadTime = std::numeric_limits<int64_t>::min();  // sentinel of a timestamp that did not convert
constexpr uint32_t kBadCoord = 0xFFFFFFFFu;                         // sentinel of a coordinate that did not convert
constexpr hsize_t kMaxChunkBytes = hsize_t{512} << 20;              // larger HDF5 chunks are treated as corrupt
constexpr double kMaxCompressionRatio = 1e4;                        // declared bytes / stored bytes above this: corrupt

// ---------------------------------------------------------------------------------------------
// HDF5 handles and errors

// Owns one HDF5 identifier of any kind and closes it with the matching H5*close.
class Hid {
 public:
  Hid() = default;
  explicit Hid(hid_t id) : id_(id) {}
  ~Hid() { reset(); }
  Hid(Hid&& o) noexcept : id_(o.id_) { o.id_ = -1; }
  Hid& operator=(Hid&& o) noexcept {
    if (this != &o) {
      reset();
      id_ = o.id_;
      o.id_ = -1;
    }
    return *this;
  }
  Hid(const Hid&) = delete;
  Hid& operator=(const Hid&) = delete;

  hid_t get() const { return id_; }
  bool valid() const { return id_ >= 0; }
  // Closes now; returns false when HDF5 reported an error (e.g. a failed flush on H5Fclose).
  bool reset() {
    if (id_ < 0) return true;
    herr_t r = 0;
    switch (H5Iget_type(id_)) {
      case H5I_FILE: r = H5Fclose(id_); break;
      case H5I_GROUP: r = H5Gclose(id_); break;
      case H5I_DATATYPE: r = H5Tclose(id_); break;
      case H5I_DATASPACE: r = H5Sclose(id_); break;
      case H5I_DATASET: r = H5Dclose(id_); break;
      case H5I_ATTR: r = H5Aclose(id_); break;
      case H5I_GENPROP_LST: r = H5Pclose(id_); break;
      default: r = H5Idec_ref(id_) < 0 ? -1 : 0; break;
    }
    id_ = -1;
    return r >= 0;
  }

 private:
  hid_t id_ = -1;
};

// Turns off HDF5's automatic error-stack printing for the lifetime of the object (this thread),
// restoring the caller's setting afterwards: the library never prints, errors become InputError.
class H5Quiet {
 public:
  H5Quiet() {
    if (H5Eget_auto2(H5E_DEFAULT, &func_, &data_) >= 0) {
      saved_ = true;
      H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
    }
  }
  ~H5Quiet() {
    if (saved_) H5Eset_auto2(H5E_DEFAULT, func_, data_);
  }
  H5Quiet(const H5Quiet&) = delete;
  H5Quiet& operator=(const H5Quiet&) = delete;

 private:
  H5E_auto2_t func_ = nullptr;
  void* data_ = nullptr;
  bool saved_ = false;
};

inline herr_t collect_error(unsigned /*n*/, const H5E_error2_t* err, void* data) {
  auto* v = static_cast<std::vector<std::string>*>(data);
  if (err != nullptr && err->desc != nullptr && err->desc[0] != '\0') {
    std::string d(err->desc);
    if (d.size() > 200) d = d.substr(0, 200) + "...";
    if (v->empty() || v->back() != d) v->push_back(d);
  }
  return 0;
}

// The messages on HDF5's error stack (outermost first, at most three), then clears it.
inline std::string h5_error_text() {
  std::vector<std::string> msgs;  // innermost first (upward walk)
  H5Ewalk2(H5E_DEFAULT, H5E_WALK_UPWARD, collect_error, &msgs);
  H5Eclear2(H5E_DEFAULT);
  if (msgs.empty()) return "HDF5 reported an error without details";
  std::reverse(msgs.begin(), msgs.end());
  if (msgs.size() > 3) msgs.erase(msgs.begin() + 1, msgs.end() - 2);
  std::string s;
  for (const std::string& m : msgs) s += (s.empty() ? "" : ": ") + m;
  return s;
}

inline std::string q_name(const std::string& s) { return "'" + s + "'"; }

// ---------------------------------------------------------------------------------------------
// element types

enum class Num : uint8_t { kU8, kI8, kU16, kI16, kU32, kI32, kU64, kI64, kF32, kF64 };

struct NumType {
  Num num = Num::kU8;
  size_t size = 1;          // bytes of one element in memory
  bool is_float = false;
  std::string name;         // "uint16", "float64", "enum(int8)", ...
  hid_t mem() const {
    switch (num) {
      case Num::kU8: return H5T_NATIVE_UINT8;
      case Num::kI8: return H5T_NATIVE_INT8;
      case Num::kU16: return H5T_NATIVE_UINT16;
      case Num::kI16: return H5T_NATIVE_INT16;
      case Num::kU32: return H5T_NATIVE_UINT32;
      case Num::kI32: return H5T_NATIVE_INT32;
      case Num::kU64: return H5T_NATIVE_UINT64;
      case Num::kI64: return H5T_NATIVE_INT64;
      case Num::kF32: return H5T_NATIVE_FLOAT;
      case Num::kF64: return H5T_NATIVE_DOUBLE;
    }
    return H5T_NATIVE_UINT8;
  }
};

inline std::string integer_name(bool is_signed, size_t bytes) {
  return std::string(is_signed ? "int" : "uint") + std::to_string(bytes * 8);
}

// Native memory type for a file type: same integer width and sign (so HDF5 only byte-swaps),
// float32/float64, enums read through their integer base type. nullopt for anything else.
inline std::optional<NumType> classify(hid_t ftype) {
  NumType t;
  H5T_class_t cls = H5Tget_class(ftype);
  std::string prefix;
  Hid base;
  hid_t it = ftype;
  if (cls == H5T_ENUM) {
    base = Hid(H5Tget_super(ftype));
    if (!base.valid()) return std::nullopt;
    it = base.get();
    cls = H5Tget_class(it);
    prefix = "enum";
  }
  const size_t bytes = H5Tget_size(it);
  if (cls == H5T_INTEGER) {
    const H5T_sign_t sign = H5Tget_sign(it);
    if (sign == H5T_SGN_ERROR || bytes == 0 || bytes > 8) return std::nullopt;
    const bool s = sign == H5T_SGN_2;
    const size_t w = bytes <= 1 ? 1 : bytes <= 2 ? 2 : bytes <= 4 ? 4 : 8;
    static const Num kSigned[] = {Num::kI8, Num::kI16, Num::kI32, Num::kI64};
    static const Num kUnsigned[] = {Num::kU8, Num::kU16, Num::kU32, Num::kU64};
    const int k = w == 1 ? 0 : w == 2 ? 1 : w == 4 ? 2 : 3;
    t.num = s ? kSigned[k] : kUnsigned[k];
    t.size = w;
    t.name = integer_name(s, bytes);
  } else if (cls == H5T_FLOAT && prefix.empty()) {
    if (bytes == 0 || bytes > 16) return std::nullopt;
    t.is_float = true;
    t.num = bytes <= 4 ? Num::kF32 : Num::kF64;
    t.size = bytes <= 4 ? 4 : 8;
    t.name = "float" + std::to_string(bytes * 8);
  } else {
    return std::nullopt;
  }
  if (!prefix.empty()) t.name = prefix + "(" + t.name + ")";
  return t;
}

inline const char* class_name(H5T_class_t c) {
  switch (c) {
    case H5T_INTEGER: return "integer";
    case H5T_FLOAT: return "float";
    case H5T_TIME: return "time";
    case H5T_STRING: return "string";
    case H5T_BITFIELD: return "bitfield";
    case H5T_OPAQUE: return "opaque";
    case H5T_COMPOUND: return "compound";
    case H5T_REFERENCE: return "reference";
    case H5T_ENUM: return "enum";
    case H5T_VLEN: return "variable-length";
    case H5T_ARRAY: return "array";
    default: return "unknown";
  }
}

// Dispatches f(const T* typed_pointer) on the element type.
template <typename F>
inline void with_type(Num n, const void* p, F&& f) {
  switch (n) {
    case Num::kU8: f(static_cast<const uint8_t*>(p)); break;
    case Num::kI8: f(static_cast<const int8_t*>(p)); break;
    case Num::kU16: f(static_cast<const uint16_t*>(p)); break;
    case Num::kI16: f(static_cast<const int16_t*>(p)); break;
    case Num::kU32: f(static_cast<const uint32_t*>(p)); break;
    case Num::kI32: f(static_cast<const int32_t*>(p)); break;
    case Num::kU64: f(static_cast<const uint64_t*>(p)); break;
    case Num::kI64: f(static_cast<const int64_t*>(p)); break;
    case Num::kF32: f(static_cast<const float*>(p)); break;
    case Num::kF64: f(static_cast<const double*>(p)); break;
  }
}

// The raw value at element i (stride applied by the caller) as text, for error messages.
inline std::string value_text(Num n, const void* p, size_t i) {
  std::string s;
  with_type(n, p, [&](auto* v) {
    using T = std::remove_cv_t<std::remove_pointer_t<decltype(v)>>;
    if constexpr (std::is_floating_point_v<T>) {
      std::ostringstream o;
      o.precision(17);
      o << static_cast<double>(v[i]);
      s = o.str();
    } else {
      s = std::to_string(static_cast<std::conditional_t<std::is_signed_v<T>, int64_t, uint64_t>>(v[i]));
    }
  });
  return s;
}

// ---------------------------------------------------------------------------------------------
// column conversion (vectorisable loops per element type)

// Pixel coordinates: whole numbers in [0, 65535], else kBadCoord.
template <typename T>
inline void convert_coords(const T* in, size_t stride, size_t n, uint32_t* out) {
  for (size_t i = 0; i < n; ++i) {
    const T v = in[i * stride];
    if constexpr (std::is_floating_point_v<T>) {
      out[i] = (v >= 0 && v <= 65535 && v == std::floor(v)) ? static_cast<uint32_t>(v) : kBadCoord;
    } else if constexpr (std::is_signed_v<T>) {
      out[i] = (v >= 0 && static_cast<int64_t>(v) <= 65535) ? static_cast<uint32_t>(v) : kBadCoord;
    } else {
      out[i] = static_cast<uint64_t>(v) <= 65535 ? static_cast<uint32_t>(v) : kBadCoord;
    }
  }
}

// Polarity codes: 1 = value 1 (ON), 2 = value 0 (OFF in 0/1), 3 = value -1 (OFF in -1/+1), 0 = other.
template <typename T>
inline void convert_polarity(const T* in, size_t stride, size_t n, uint8_t* out) {
  for (size_t i = 0; i < n; ++i) {
    const T v = in[i * stride];
    uint8_t c = 0;
    if (v == T(1)) c = 1;
    else if (v == T(0)) c = 2;
    if constexpr (std::is_signed_v<T> || std::is_floating_point_v<T>) {
      if (v == T(-1)) c = 3;
    }
    out[i] = c;
  }
}

// How file times become ns: t_ns = value * 10^exponent + offset_ns (exact for integers; floats
// split into integer and fractional part so that 1.7e9 s keeps sub-microsecond digits).
struct TimeConv {
  int64_t mult = 1000;   // 10^exponent
  int64_t offset_ns = 0;
};

template <typename T>
inline void convert_times(const T* in, size_t stride, size_t n, const TimeConv& c, int64_t* out) {
  const int64_t mult = c.mult;
  const int64_t off = c.offset_ns;
  if constexpr (std::is_integral_v<T>) {
    // t -> t * mult + off is monotone: when the smallest and largest value convert, all do, and
    // the loop runs without per-element overflow checks.
    if (n > 1) {
      T lo = in[0], hi = in[0];
      for (size_t i = 1; i < n; ++i) {
        const T v = in[i * stride];
        lo = v < lo ? v : lo;
        hi = v > hi ? v : hi;
      }
      int64_t ends[2];
      const T ends_in[2] = {lo, hi};
      convert_times(ends_in, 1, 1, c, &ends[0]);
      convert_times(ends_in + 1, 1, 1, c, &ends[1]);
      if (ends[0] != kBadTime && ends[1] != kBadTime) {
        for (size_t i = 0; i < n; ++i) out[i] = static_cast<int64_t>(in[i * stride]) * mult + off;
        return;
      }
    }
  }
  for (size_t i = 0; i < n; ++i) {
    const T v = in[i * stride];
    int64_t r = 0;
    bool ok;
    if constexpr (std::is_floating_point_v<T>) {
      const double d = static_cast<double>(v);
      const double limit = 9.2e18 / static_cast<double>(mult);
      if (!(d > -limit && d < limit)) {
        ok = false;
      } else {
        const double ip = std::floor(d);
        const int64_t whole = static_cast<int64_t>(ip);
        const int64_t frac = std::llround((d - ip) * static_cast<double>(mult));
        ok = !__builtin_mul_overflow(whole, mult, &r) && !__builtin_add_overflow(r, frac, &r) &&
             !__builtin_add_overflow(r, off, &r);
      }
    } else if constexpr (std::is_same_v<T, uint64_t>) {
      ok = v <= static_cast<uint64_t>(std::numeric_limits<int64_t>::max()) &&
           !__builtin_mul_overflow(static_cast<int64_t>(v), mult, &r) && !__builtin_add_overflow(r, off, &r);
    } else {
      ok = !__builtin_mul_overflow(static_cast<int64_t>(v), mult, &r) && !__builtin_add_overflow(r, off, &r);
    }
    out[i] = (ok && r != kBadTime) ? r : kBadTime;
  }
}

// ---------------------------------------------------------------------------------------------
// file structure helpers

// True when every component of `path` exists as a link inside the file; external links (which
// would open other files) count as absent-with-reason via *external.
inline bool link_exists(hid_t file, const std::string& path, hid_t apl, bool* external = nullptr) {
  if (external != nullptr) *external = false;
  if (path.empty()) return false;
  size_t pos = 0;
  while (pos <= path.size()) {
    size_t next = path.find('/', pos);
    if (next == std::string::npos) next = path.size();
    const std::string prefix = path.substr(0, next);
    if (!prefix.empty() && prefix.back() != '/') {
      if (H5Lexists(file, prefix.c_str(), apl) <= 0) {
        H5Eclear2(H5E_DEFAULT);
        return false;
      }
      H5L_info_t info;
      if (H5Lget_info(file, prefix.c_str(), &info, apl) < 0) {
        H5Eclear2(H5E_DEFAULT);
        return false;
      }
      if (info.type != H5L_TYPE_HARD && info.type != H5L_TYPE_SOFT) {
        if (external != nullptr) *external = true;
        return false;
      }
    }
    pos = next + 1;
  }
  return true;
}

// External links (reached through soft links) would open other files: refuse to traverse them.
inline herr_t refuse_external_link(const char* /*parent_file*/, const char* /*parent_group*/, const char* /*child_file*/,
                            const char* /*child_object*/, unsigned* /*acc_flags*/, hid_t /*fapl*/, void* /*data*/) {
  return -1;
}

// A dataset access list (also usable as link access list) that refuses external links.
inline Hid make_access_list() {
  Hid apl(H5Pcreate(H5P_DATASET_ACCESS));
  if (apl.valid() && H5Pset_elink_cb(apl.get(), refuse_external_link, nullptr) < 0) return Hid();
  return apl;
}

inline bool is_dataset(hid_t file, const std::string& path, hid_t apl) {
  if (!link_exists(file, path, apl)) return false;
  Hid obj(H5Oopen(file, path.c_str(), apl));
  if (!obj.valid()) {
    H5Eclear2(H5E_DEFAULT);
    return false;
  }
  return H5Iget_type(obj.get()) == H5I_DATASET;
}

inline herr_t collect_name(hid_t /*group*/, const char* name, const H5L_info_t* /*info*/, void* data) {
  auto* v = static_cast<std::vector<std::string>*>(data);
  if (v->size() >= 64) return 1;  // stop: enough for a message
  v->push_back(name);
  return 0;
}

inline std::vector<std::string> member_names(hid_t group) {
  std::vector<std::string> names;
  hsize_t idx = 0;
  if (H5Literate(group, H5_INDEX_NAME, H5_ITER_NATIVE, &idx, collect_name, &names) < 0) H5Eclear2(H5E_DEFAULT);
  return names;
}

// "a (group: b, c), d (dataset)" for the top level of the file.
inline std::string describe_top_level(hid_t file, hid_t apl) {
  std::vector<std::string> names = member_names(file);
  if (names.empty()) return "none (the file is empty)";
  std::string s;
  size_t shown = 0;
  for (const std::string& n : names) {
    if (shown == 20) {
      s += ", ...";
      break;
    }
    s += (s.empty() ? "" : ", ") + n;
    ++shown;
    bool ext = false;
    if (!link_exists(file, n, apl, &ext)) {
      s += ext ? " (external link)" : " (dangling link)";
      continue;
    }
    Hid obj(H5Oopen(file, n.c_str(), apl));
    if (!obj.valid()) {
      H5Eclear2(H5E_DEFAULT);
      continue;
    }
    const H5I_type_t type = H5Iget_type(obj.get());
    if (type == H5I_DATASET) {
      s += " (dataset)";
    } else if (type == H5I_GROUP) {
      std::vector<std::string> sub = member_names(obj.get());
      s += " (group";
      for (size_t i = 0; i < sub.size() && i < 8; ++i) s += (i == 0 ? ": " : ", ") + sub[i];
      if (sub.size() > 8) s += ", ...";
      s += ")";
    }
  }
  return s;
}

// A scalar (or one-element) attribute or dataset value.
struct Scalar {
  bool is_float = false;
  int64_t i = 0;
  double f = 0;
  double as_double() const { return is_float ? f : static_cast<double>(i); }
};

// Errors of the HDF5 readers: the file, the problem and the expected form.
[[noreturn]] inline void fail(const std::string& path, const std::string& problem, const std::string& expected = {}) {
  throw InputError(path, 0, problem, expected);
}
[[noreturn]] inline void fail_h5(const std::string& path, const std::string& what,
                                 const std::string& expected = "an intact HDF5 file") {
  throw InputError(path, 0, what + ": " + h5_error_text(), expected);
}

// Reads a scalar number of HDF5 type ftype through read(mem_type, buffer) (a dataset or an
// attribute): floats as double, integers as int64 (uint64 above 2^63 is an error).
template <typename ReadFn>
Scalar read_scalar(const std::string& path, hid_t ftype, const std::string& name, const std::string& role, ReadFn&& read) {
  const std::optional<NumType> t = classify(ftype);
  if (!t) fail(path, q_name(name) + " (" + role + ") is not a number (type class " + class_name(H5Tget_class(ftype)) + ")", "a numeric scalar");
  Scalar s;
  if (t->is_float) {
    s.is_float = true;
    if (read(H5T_NATIVE_DOUBLE, &s.f) < 0) fail_h5(path, "cannot read " + q_name(name));
  } else if (t->num == Num::kU64) {
    uint64_t u = 0;
    if (read(H5T_NATIVE_UINT64, &u) < 0) fail_h5(path, "cannot read " + q_name(name));
    if (u > static_cast<uint64_t>(std::numeric_limits<int64_t>::max())) fail(path, q_name(name) + " = " + std::to_string(u) + " is out of range", "a value below 2^63");
    s.i = static_cast<int64_t>(u);
  } else {
    if (read(H5T_NATIVE_INT64, &s.i) < 0) fail_h5(path, "cannot read " + q_name(name));
  }
  return s;
}

// Attribute `name` on obj as a number; nullopt when absent.
inline std::optional<Scalar> read_number_attr(const std::string& path, hid_t obj, const std::string& obj_name, const char* name) {
  const htri_t e = H5Aexists(obj, name);
  if (e <= 0) {
    H5Eclear2(H5E_DEFAULT);
    return std::nullopt;
  }
  Hid attr(H5Aopen(obj, name, H5P_DEFAULT));
  Hid space(attr.valid() ? H5Aget_space(attr.get()) : -1);
  Hid ftype(attr.valid() ? H5Aget_type(attr.get()) : -1);
  const std::string full = obj_name + " attribute " + name;
  if (!attr.valid() || !space.valid() || !ftype.valid()) fail_h5(path, "cannot read " + full);
  if (H5Sget_simple_extent_npoints(space.get()) != 1) fail(path, full + " holds " + std::to_string(H5Sget_simple_extent_npoints(space.get())) + " values", "a scalar");
  return read_scalar(path, ftype.get(), full, "attribute", [&](hid_t mem, void* buf) { return H5Aread(attr.get(), mem, buf); });
}

// String attribute `name` on obj; nullopt when absent.
inline std::optional<std::string> read_string_attr(const std::string& path, hid_t obj, const std::string& obj_name, const char* name) {
  const htri_t e = H5Aexists(obj, name);
  if (e <= 0) {
    H5Eclear2(H5E_DEFAULT);
    return std::nullopt;
  }
  const std::string full = obj_name + " attribute " + name;
  Hid attr(H5Aopen(obj, name, H5P_DEFAULT));
  Hid space(attr.valid() ? H5Aget_space(attr.get()) : -1);
  Hid ftype(attr.valid() ? H5Aget_type(attr.get()) : -1);
  if (!attr.valid() || !space.valid() || !ftype.valid()) fail_h5(path, "cannot read " + full);
  if (H5Tget_class(ftype.get()) != H5T_STRING) fail(path, full + " is not a string", "a string such as \"us\" or \"ns\"");
  if (H5Sget_simple_extent_npoints(space.get()) != 1) fail(path, full + " holds several values", "one string");
  Hid mem(H5Tcopy(H5T_C_S1));
  if (!mem.valid()) fail_h5(path, "cannot read " + full);
  std::string value;
  if (H5Tis_variable_str(ftype.get()) > 0) {
    if (H5Tset_size(mem.get(), H5T_VARIABLE) < 0) fail_h5(path, "cannot read " + full);
    char* s = nullptr;
    if (H5Aread(attr.get(), mem.get(), &s) < 0) fail_h5(path, "cannot read " + full);
    if (s != nullptr) {
      value.assign(s, strnlen(s, 256));
      H5free_memory(s);
    }
  } else {
    const size_t size = H5Tget_size(ftype.get());
    if (size == 0 || size > 4096) fail(path, full + " is a string of " + std::to_string(size) + " bytes", "a short string");
    std::vector<char> buf(size + 1, '\0');
    if (H5Tset_size(mem.get(), size) < 0 || H5Tset_strpad(mem.get(), H5T_STR_NULLPAD) < 0 ||
        H5Aread(attr.get(), mem.get(), buf.data()) < 0) {
      fail_h5(path, "cannot read " + full);
    }
    value.assign(buf.data(), strnlen(buf.data(), size));
  }
  return value;
}

inline std::optional<TimeUnit> parse_unit_text(std::string u) {
  while (!u.empty() && (u.back() == ' ' || u.back() == '\0')) u.pop_back();
  if (auto t = time_unit_from_name(u); t && *t != TimeUnit::kAuto) return t;
  if (u == "seconds" || u == "second" || u == "sec") return TimeUnit::kSeconds;
  if (u == "milliseconds" || u == "millisecond" || u == "msec") return TimeUnit::kMilliseconds;
  if (u == "microseconds" || u == "microsecond" || u == "usec" || u == "\xC2\xB5s") return TimeUnit::kMicroseconds;
  if (u == "nanoseconds" || u == "nanosecond" || u == "nsec") return TimeUnit::kNanoseconds;
  return std::nullopt;
}

// Checks the one part of an HDF5 version 0/1 superblock that libhdf5 1.10 trusts before it reads
// it: the driver information block, whose 32-bit size libhdf5 allocates (up to 4 GiB for a
// 50-byte file). Returns an empty string when the superblock is plausible, else the problem.
// Later versions (2, 3) carry a checksum that libhdf5 verifies.
inline std::string check_superblock(const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) return {};
  std::string problem;
  std::fseek(f, 0, SEEK_END);
  const long size_l = std::ftell(f);
  const uint64_t size = size_l > 0 ? static_cast<uint64_t>(size_l) : 0;
  auto read_at = [&](uint64_t off, unsigned char* buf, size_t n) {
    return off + n <= size && std::fseek(f, static_cast<long>(off), SEEK_SET) == 0 && std::fread(buf, 1, n, f) == n;
  };
  // Like libhdf5, reads past the end of the file as zeros.
  auto read_zero = [&](uint64_t off, unsigned char* buf, size_t n) {
    std::memset(buf, 0, n);
    if (off >= size) return;
    const size_t avail = static_cast<size_t>(std::min<uint64_t>(n, size - off));
    if (std::fseek(f, static_cast<long>(off), SEEK_SET) == 0) (void)std::fread(buf, 1, avail, f);
  };
  auto le = [](const unsigned char* b, unsigned n) {
    uint64_t v = 0;
    for (unsigned i = 0; i < n && i < 8; ++i) v |= static_cast<uint64_t>(b[i]) << (8 * i);
    return v;
  };
  static const unsigned char kSig[8] = {0x89, 'H', 'D', 'F', '\r', '\n', 0x1a, '\n'};
  // The signature is at 0, 512, 1024, 2048, ... (after a user block).
  for (uint64_t base = 0; base + 8 <= size; base = base == 0 ? 512 : base * 2) {
    unsigned char sb[64] = {0};
    if (!read_at(base, sb, 8) || std::memcmp(sb, kSig, 8) != 0) continue;
    if (!read_at(base, sb, 24)) break;  // libhdf5 reports the truncation itself
    const unsigned version = sb[8];
    if (version > 1) break;
    const unsigned so = sb[13], sl = sb[14];
    const auto valid_size = [](unsigned v) { return v == 2 || v == 4 || v == 8 || v == 16 || v == 32; };
    if (!valid_size(so) || !valid_size(sl)) {
      problem = "HDF5 superblock at byte offset " + std::to_string(base) + " declares " + std::to_string(so) +
                "-byte addresses and " + std::to_string(sl) + "-byte lengths";
      break;
    }
    if (so > 8) break;  // not produced in practice; libhdf5 decides
    const uint64_t fixed = 24 + (version == 1 ? 4 : 0);
    unsigned char addr[8] = {0};
    read_zero(base + fixed + 3 * so, addr, so);
    const uint64_t undefined = so == 8 ? ~uint64_t{0} : (uint64_t{1} << (8 * so)) - 1;
    const uint64_t driver = le(addr, so);
    if (driver == undefined) break;
    unsigned char hdr[16] = {0};
    if (driver <= size) read_zero(base + driver, hdr, 16);
    const uint64_t info_size = driver <= size ? le(hdr + 4, 4) : ~uint64_t{0};
    if (driver > size || info_size > size || base + driver + 16 + info_size > size) {
      problem = "HDF5 superblock at byte offset " + std::to_string(base) + " points to a driver information block at " +
                std::to_string(driver) + (info_size == ~uint64_t{0} ? std::string() : " of " + std::to_string(info_size) + " bytes") +
                " beyond the end of the " + std::to_string(size) + "-byte file";
    }
    break;
  }
  std::fclose(f);
  return problem;
}

// ---------------------------------------------------------------------------------------------
// writer-side helpers

inline void write_string_attr(hid_t obj, const char* name, const std::string& value) {
  Hid type(H5Tcopy(H5T_C_S1));
  Hid space(H5Screate(H5S_SCALAR));
  if (!type.valid() || !space.valid() || H5Tset_size(type.get(), value.size() + 1) < 0 ||
      H5Tset_strpad(type.get(), H5T_STR_NULLTERM) < 0) {
    throw std::runtime_error(h5_error_text());
  }
  Hid attr(H5Acreate2(obj, name, type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT));
  if (!attr.valid() || H5Awrite(attr.get(), type.get(), value.c_str()) < 0) throw std::runtime_error(h5_error_text());
}

inline void write_int_attr(hid_t obj, const char* name, int64_t value) {
  Hid space(H5Screate(H5S_SCALAR));
  Hid attr(H5Acreate2(obj, name, H5T_STD_I64LE, space.get(), H5P_DEFAULT, H5P_DEFAULT));
  if (!attr.valid() || H5Awrite(attr.get(), H5T_NATIVE_INT64, &value) < 0) throw std::runtime_error(h5_error_text());
}

inline std::string filter_name(H5Z_filter_t id, const char* stored) {
  if (stored != nullptr && stored[0] != '\0') return stored;
  switch (id) {
    case H5Z_FILTER_DEFLATE: return "deflate";
    case H5Z_FILTER_SHUFFLE: return "shuffle";
    case H5Z_FILTER_FLETCHER32: return "fletcher32";
    case H5Z_FILTER_SZIP: return "szip";
    case H5Z_FILTER_NBIT: return "nbit";
    case H5Z_FILTER_SCALEOFFSET: return "scaleoffset";
    case 307: return "bzip2";
    case 32000: return "lzf";
    case kBloscFilter: return "blosc";
    case 32004: return "lz4";
    case 32008: return "bitshuffle";
    case 32013: return "zfp";
    case 32015: return "zstd";
    case 32026: return "blosc2";
    default: return "unregistered name";
  }
}

inline std::string filter_install_hint(H5Z_filter_t id) {
  if (id == kBloscFilter) {
    return "install Debian package hdf5-filter-plugin-blosc-serial or set HDF5_PLUGIN_PATH to a folder holding "
           "the Blosc HDF5 plugin (libH5Zblosc.so)";
  }
  return "install the HDF5 filter plugin for filter id " + std::to_string(id) +
         " and set HDF5_PLUGIN_PATH to its folder (Debian's default plugin folder is "
         "/usr/lib/x86_64-linux-gnu/hdf5/serial/plugins)";
}


}  // namespace evio::detail::h5
