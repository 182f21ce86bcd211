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

namespace evio {
namespace fs = std::filesystem;

namespace {

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

herr_t collect_error(unsigned /*n*/, const H5E_error2_t* err, void* data) {
  auto* v = static_cast<std::vector<std::string>*>(data);
  if (err != nullptr && err->desc != nullptr && err->desc[0] != '\0') {
    std::string d(err->desc);
    if (d.size() > 200) d = d.substr(0, 200) + "...";
    if (v->empty() || v->back() != d) v->push_back(d);
  }
  return 0;
}

// The messages on HDF5's error stack (outermost first, at most three), then clears it.
std::string h5_error_text() {
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

std::string q_name(const std::string& s) { return "'" + s + "'"; }

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

std::string integer_name(bool is_signed, size_t bytes) {
  return std::string(is_signed ? "int" : "uint") + std::to_string(bytes * 8);
}

// Native memory type for a file type: same integer width and sign (so HDF5 only byte-swaps),
// float32/float64, enums read through their integer base type. nullopt for anything else.
std::optional<NumType> classify(hid_t ftype) {
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

const char* class_name(H5T_class_t c) {
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
void with_type(Num n, const void* p, F&& f) {
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
std::string value_text(Num n, const void* p, size_t i) {
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
void convert_coords(const T* in, size_t stride, size_t n, uint32_t* out) {
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
void convert_polarity(const T* in, size_t stride, size_t n, uint8_t* out) {
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
void convert_times(const T* in, size_t stride, size_t n, const TimeConv& c, int64_t* out) {
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
bool link_exists(hid_t file, const std::string& path, hid_t apl, bool* external = nullptr) {
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
herr_t refuse_external_link(const char* /*parent_file*/, const char* /*parent_group*/, const char* /*child_file*/,
                            const char* /*child_object*/, unsigned* /*acc_flags*/, hid_t /*fapl*/, void* /*data*/) {
  return -1;
}

// A dataset access list (also usable as link access list) that refuses external links.
Hid make_access_list() {
  Hid apl(H5Pcreate(H5P_DATASET_ACCESS));
  if (apl.valid() && H5Pset_elink_cb(apl.get(), refuse_external_link, nullptr) < 0) return Hid();
  return apl;
}

bool is_dataset(hid_t file, const std::string& path, hid_t apl) {
  if (!link_exists(file, path, apl)) return false;
  Hid obj(H5Oopen(file, path.c_str(), apl));
  if (!obj.valid()) {
    H5Eclear2(H5E_DEFAULT);
    return false;
  }
  return H5Iget_type(obj.get()) == H5I_DATASET;
}

herr_t collect_name(hid_t /*group*/, const char* name, const H5L_info_t* /*info*/, void* data) {
  auto* v = static_cast<std::vector<std::string>*>(data);
  if (v->size() >= 64) return 1;  // stop: enough for a message
  v->push_back(name);
  return 0;
}

std::vector<std::string> member_names(hid_t group) {
  std::vector<std::string> names;
  hsize_t idx = 0;
  if (H5Literate(group, H5_INDEX_NAME, H5_ITER_NATIVE, &idx, collect_name, &names) < 0) H5Eclear2(H5E_DEFAULT);
  return names;
}

// "a (group: b, c), d (dataset)" for the top level of the file.
std::string describe_top_level(hid_t file, hid_t apl) {
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

std::optional<TimeUnit> parse_unit_text(std::string u) {
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
std::string check_superblock(const std::string& path) {
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

void write_string_attr(hid_t obj, const char* name, const std::string& value) {
  Hid type(H5Tcopy(H5T_C_S1));
  Hid space(H5Screate(H5S_SCALAR));
  if (!type.valid() || !space.valid() || H5Tset_size(type.get(), value.size() + 1) < 0 ||
      H5Tset_strpad(type.get(), H5T_STR_NULLTERM) < 0) {
    throw std::runtime_error(h5_error_text());
  }
  Hid attr(H5Acreate2(obj, name, type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT));
  if (!attr.valid() || H5Awrite(attr.get(), type.get(), value.c_str()) < 0) throw std::runtime_error(h5_error_text());
}

void write_int_attr(hid_t obj, const char* name, int64_t value) {
  Hid space(H5Screate(H5S_SCALAR));
  Hid attr(H5Acreate2(obj, name, H5T_STD_I64LE, space.get(), H5P_DEFAULT, H5P_DEFAULT));
  if (!attr.valid() || H5Awrite(attr.get(), H5T_NATIVE_INT64, &value) < 0) throw std::runtime_error(h5_error_text());
}

std::string filter_name(H5Z_filter_t id, const char* stored) {
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

std::string filter_install_hint(H5Z_filter_t id) {
  if (id == kBloscFilter) {
    return "install Debian package hdf5-filter-plugin-blosc-serial or set HDF5_PLUGIN_PATH to a folder holding "
           "the Blosc HDF5 plugin (libH5Zblosc.so)";
  }
  return "install the HDF5 filter plugin for filter id " + std::to_string(id) +
         " and set HDF5_PLUGIN_PATH to its folder (Debian's default plugin folder is "
         "/usr/lib/x86_64-linux-gnu/hdf5/serial/plugins)";
}

}  // namespace

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
    return read_scalar(ftype.get(), name, role, [&](hid_t mem, void* buf) {
      return H5Dread(ds.get(), mem, H5S_ALL, H5S_ALL, H5P_DEFAULT, buf);
    });
  }

  template <typename ReadFn>
  Scalar read_scalar(hid_t ftype, const std::string& name, const std::string& role, ReadFn&& read) const {
    const std::optional<NumType> t = classify(ftype);
    if (!t) fail(q_name(name) + " (" + role + ") is not a number (type class " + class_name(H5Tget_class(ftype)) + ")", "a numeric scalar");
    Scalar s;
    if (t->is_float) {
      s.is_float = true;
      if (read(H5T_NATIVE_DOUBLE, &s.f) < 0) fail_h5("cannot read " + q_name(name));
    } else if (t->num == Num::kU64) {
      uint64_t u = 0;
      if (read(H5T_NATIVE_UINT64, &u) < 0) fail_h5("cannot read " + q_name(name));
      if (u > static_cast<uint64_t>(std::numeric_limits<int64_t>::max())) fail(q_name(name) + " = " + std::to_string(u) + " is out of range", "a value below 2^63");
      s.i = static_cast<int64_t>(u);
    } else {
      if (read(H5T_NATIVE_INT64, &s.i) < 0) fail_h5("cannot read " + q_name(name));
    }
    return s;
  }

  // Attribute `name` on obj as a number; nullopt when absent.
  std::optional<Scalar> read_number_attr(hid_t obj, const std::string& obj_name, const char* name) const {
    const htri_t e = H5Aexists(obj, name);
    if (e <= 0) {
      H5Eclear2(H5E_DEFAULT);
      return std::nullopt;
    }
    Hid attr(H5Aopen(obj, name, H5P_DEFAULT));
    Hid space(attr.valid() ? H5Aget_space(attr.get()) : -1);
    Hid ftype(attr.valid() ? H5Aget_type(attr.get()) : -1);
    const std::string full = obj_name + " attribute " + name;
    if (!attr.valid() || !space.valid() || !ftype.valid()) fail_h5("cannot read " + full);
    if (H5Sget_simple_extent_npoints(space.get()) != 1) fail(full + " holds " + std::to_string(H5Sget_simple_extent_npoints(space.get())) + " values", "a scalar");
    return read_scalar(ftype.get(), full, "attribute", [&](hid_t mem, void* buf) { return H5Aread(attr.get(), mem, buf); });
  }

  // String attribute `name` on obj; nullopt when absent.
  std::optional<std::string> read_string_attr(hid_t obj, const std::string& obj_name, const char* name) const {
    const htri_t e = H5Aexists(obj, name);
    if (e <= 0) {
      H5Eclear2(H5E_DEFAULT);
      return std::nullopt;
    }
    const std::string full = obj_name + " attribute " + name;
    Hid attr(H5Aopen(obj, name, H5P_DEFAULT));
    Hid space(attr.valid() ? H5Aget_space(attr.get()) : -1);
    Hid ftype(attr.valid() ? H5Aget_type(attr.get()) : -1);
    if (!attr.valid() || !space.valid() || !ftype.valid()) fail_h5("cannot read " + full);
    if (H5Tget_class(ftype.get()) != H5T_STRING) fail(full + " is not a string", "a string such as \"us\" or \"ns\"");
    if (H5Sget_simple_extent_npoints(space.get()) != 1) fail(full + " holds several values", "one string");
    Hid mem(H5Tcopy(H5T_C_S1));
    if (!mem.valid()) fail_h5("cannot read " + full);
    std::string value;
    if (H5Tis_variable_str(ftype.get()) > 0) {
      if (H5Tset_size(mem.get(), H5T_VARIABLE) < 0) fail_h5("cannot read " + full);
      char* s = nullptr;
      if (H5Aread(attr.get(), mem.get(), &s) < 0) fail_h5("cannot read " + full);
      if (s != nullptr) {
        value.assign(s, strnlen(s, 256));
        H5free_memory(s);
      }
    } else {
      const size_t size = H5Tget_size(ftype.get());
      if (size == 0 || size > 4096) fail(full + " is a string of " + std::to_string(size) + " bytes", "a short string");
      std::vector<char> buf(size + 1, '\0');
      if (H5Tset_size(mem.get(), size) < 0 || H5Tset_strpad(mem.get(), H5T_STR_NULLPAD) < 0 ||
          H5Aread(attr.get(), mem.get(), buf.data()) < 0) {
        fail_h5("cannot read " + full);
      }
      value.assign(buf.data(), strnlen(buf.data(), size));
    }
    return value;
  }

  // The `unit` attribute of dataset `name`, nullopt when absent.
  std::optional<TimeUnit> unit_attr(hid_t ds, const std::string& name) const {
    const std::optional<std::string> u = read_string_attr(ds, "dataset " + q_name(name), "unit");
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
    std::optional<Scalar> s = read_number_attr(obj, obj_name, name);
    std::string where = obj_name + " attribute " + name;
    if (!s && dataset_too && is_dataset(obj, name, apl.get())) {
      Hid ds(H5Dopen2(obj, name, apl.get()));
      Hid space(ds.valid() ? H5Dget_space(ds.get()) : -1);
      Hid ftype(ds.valid() ? H5Dget_type(ds.get()) : -1);
      if (ds.valid() && space.valid() && ftype.valid() && H5Sget_simple_extent_npoints(space.get()) == 1) {
        s = read_scalar(ftype.get(), name, "sensor size", [&](hid_t mem, void* buf) {
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
