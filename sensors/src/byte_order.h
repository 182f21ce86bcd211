// Loads of little- and big-endian integers from unaligned bytes, for the binary readers (AEDAT 2.0
// and 4.0, EVT 2.0/3.0, ROS1 bags): one memcpy (no alignment or aliasing assumption), byte-swapped
// when the host's order differs. Internal to evio::sensors.
#pragma once

#include <cstdint>
#include <cstring>
#include <type_traits>

namespace evio::detail {

template <typename T>
inline T byte_swap(T v) {
  static_assert(std::is_integral_v<T> && (sizeof(T) == 1 || sizeof(T) == 2 || sizeof(T) == 4 || sizeof(T) == 8),
                "byte_swap: 1-, 2-, 4- or 8-byte integers");
  if constexpr (sizeof(T) == 2) return static_cast<T>(__builtin_bswap16(static_cast<uint16_t>(v)));
  else if constexpr (sizeof(T) == 4) return static_cast<T>(__builtin_bswap32(static_cast<uint32_t>(v)));
  else if constexpr (sizeof(T) == 8) return static_cast<T>(__builtin_bswap64(static_cast<uint64_t>(v)));
  else return v;
}

// T (an integer type) stored little-endian at p.
template <typename T>
inline T load_le(const uint8_t* p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_BIG_ENDIAN__
  v = byte_swap(v);
#endif
  return v;
}

// T (an integer type) stored big-endian at p.
template <typename T>
inline T load_be(const uint8_t* p) {
  T v;
  std::memcpy(&v, p, sizeof(T));
#if !defined(__BYTE_ORDER__) || __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
  v = byte_swap(v);
#endif
  return v;
}

}  // namespace evio::detail
