// Bounds-checked FlatBuffers view for the AEDAT 4.0 reader (aedat4.cc): every offset is checked
// against the buffer and every problem is an evio::InputError naming the buffer. Internal to evio::sensors.
#pragma once

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <map>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "byte_order.h"
#include "evio/calib/error.h"

namespace evio::detail::aedat4 {
using detail::load_le;

// ---------------------------------------------------------------------------------------------
// Bounds-checked flatbuffer access (FlatBuffers binary format: little-endian, root uoffset at 0,
// 4-byte file identifier at 4, tables with an int32 soffset to their vtable, vtables of uint16
// [vtable size, table size, field offsets...], vectors and strings as uint32 length + data).

struct FbTable {
  size_t pos = 0;     // table start in the buffer
  size_t vtable = 0;  // vtable start in the buffer
  uint16_t vsize = 0;
  uint16_t tsize = 0;
};

struct FbVector {
  size_t start = 0;   // first element
  uint32_t size = 0;  // element count
};

class FbBuffer {
 public:
  // `where` names the buffer for messages, e.g. "EventPacket flatbuffer of the packet at byte offset 3226".
  FbBuffer(const uint8_t* data, size_t size, const std::string& path, std::string where, std::string expected)
      : data_(data), size_(size), path_(path), where_(std::move(where)), expected_(std::move(expected)) {}

  const uint8_t* data() const { return data_; }
  size_t size() const { return size_; }

  [[noreturn]] void bad(const std::string& problem) const {
    throw InputError(path_, 0, where_ + ": " + problem, expected_);
  }

  // Root table after checking the 4-character file identifier.
  FbTable root(const char* identifier) const {
    if (size_ < 8)
      bad("buffer of " + std::to_string(static_cast<int64_t>(size_)) +
          " bytes is too small for a root offset and file identifier");
    if (std::memcmp(data_ + 4, identifier, 4) != 0) {
      bad("file identifier \"" + printable(data_ + 4, 4) + "\" at offset 4 is not \"" + identifier + "\"");
    }
    return table_at(load_le<uint32_t>(data_), "root table");
  }

  FbTable table_at(uint64_t pos, const char* what) const {
    if (pos > size_ || size_ - pos < 4) {
      bad(std::string(what) + " offset " + std::to_string(static_cast<int64_t>(pos)) + " points outside the " +
          std::to_string(static_cast<int64_t>(size_)) + "-byte buffer");
    }
    const int64_t vt = static_cast<int64_t>(pos) - load_le<int32_t>(data_ + pos);
    if (vt < 0 || static_cast<uint64_t>(vt) > size_ || size_ - static_cast<uint64_t>(vt) < 4) {
      bad(std::string(what) + " at offset " + std::to_string(static_cast<int64_t>(pos)) + " has its vtable at " + std::to_string(vt) +
          ", outside the " + std::to_string(static_cast<int64_t>(size_)) + "-byte buffer");
    }
    FbTable t;
    t.pos = static_cast<size_t>(pos);
    t.vtable = static_cast<size_t>(vt);
    t.vsize = load_le<uint16_t>(data_ + t.vtable);
    t.tsize = load_le<uint16_t>(data_ + t.vtable + 2);
    if (t.vsize < 4 || t.vsize % 2 != 0 || t.vsize > size_ - t.vtable) {
      bad(std::string(what) + " at offset " + std::to_string(static_cast<int64_t>(pos)) + ": vtable size " + std::to_string(t.vsize) +
          " at offset " + std::to_string(static_cast<int64_t>(t.vtable)) + " is odd, below 4 or beyond the " +
          std::to_string(static_cast<int64_t>(size_)) + "-byte buffer");
    }
    if (t.tsize < 4 || t.tsize > size_ - t.pos) {
      bad(std::string(what) + " at offset " + std::to_string(static_cast<int64_t>(pos)) + ": table size " + std::to_string(t.tsize) +
          " is below 4 or beyond the " + std::to_string(static_cast<int64_t>(size_)) + "-byte buffer");
    }
    return t;
  }

  // Position of field `index` (0-based, schema order) of size `bytes`, or 0 when absent.
  size_t field(const FbTable& t, int index, size_t bytes) const {
    const size_t vo = 4 + 2 * static_cast<size_t>(index);
    if (vo + 2 > t.vsize) return 0;
    const uint16_t off = load_le<uint16_t>(data_ + t.vtable + vo);
    if (off == 0) return 0;
    if (off < 4 || off + bytes > t.tsize) {
      bad("field " + std::to_string(index) + " of the table at offset " + std::to_string(static_cast<int64_t>(t.pos)) + " lies at " +
          std::to_string(off) + ", outside the table's " + std::to_string(t.tsize) + " bytes");
    }
    return t.pos + off;
  }

  bool has(const FbTable& t, int index, size_t bytes) const { return field(t, index, bytes) != 0; }

  template <typename T>
  T scalar(const FbTable& t, int index, T default_value) const {
    const size_t p = field(t, index, sizeof(T));
    return p == 0 ? default_value : load_le<T>(data_ + p);
  }

  // Vector (or string, elem_bytes = 1) field; an absent field gives an empty vector.
  FbVector vector(const FbTable& t, int index, size_t elem_bytes, const char* what) const {
    const size_t p = field(t, index, 4);
    if (p == 0) return {};
    const uint64_t target = static_cast<uint64_t>(p) + load_le<uint32_t>(data_ + p);
    if (target > size_ || size_ - target < 4) {
      bad(std::string(what) + " offset at " + std::to_string(static_cast<int64_t>(p)) + " points to " +
          std::to_string(static_cast<int64_t>(target)) + ", outside the " + std::to_string(static_cast<int64_t>(size_)) + "-byte buffer");
    }
    const uint32_t n = load_le<uint32_t>(data_ + target);
    const uint64_t avail = size_ - target - 4;
    if (static_cast<uint64_t>(n) * elem_bytes > avail) {
      bad(std::string(what) + " length " + std::to_string(n) + " at offset " + std::to_string(static_cast<int64_t>(target)) + " needs " +
          std::to_string(static_cast<int64_t>(static_cast<uint64_t>(n) * elem_bytes)) + " bytes but only " +
          std::to_string(static_cast<int64_t>(avail)) + " remain in the buffer");
    }
    return FbVector{static_cast<size_t>(target + 4), n};
  }

  // Element j of a vector of tables.
  FbTable vector_table(const FbVector& v, uint32_t j, const char* what) const {
    const size_t slot = v.start + 4 * static_cast<size_t>(j);
    return table_at(static_cast<uint64_t>(slot) + load_le<uint32_t>(data_ + slot), what);
  }

  static std::string printable(const uint8_t* p, size_t n) {
    std::string s;
    for (size_t i = 0; i < n; ++i) {
      const unsigned char c = p[i];
      if (c >= 32 && c < 127 && c != '"' && c != '\\') {
        s += static_cast<char>(c);
      } else {
        static const char* hex = "0123456789abcdef";
        s += "\\x";
        s += hex[c >> 4];
        s += hex[c & 15];
      }
    }
    return s;
  }

 private:
  const uint8_t* data_;
  size_t size_;
  const std::string& path_;
  std::string where_;
  std::string expected_;
};

}  // namespace evio::detail::aedat4
