// Little-endian fields, the byte order of every bodyd wire and file format (pose messages,
// recordings, model files, HID reports, SlimeVR frames). Assembled byte by byte, so neither the
// host's byte order nor alignment matters. The caller checks the size: these read or write
// exactly sizeof(T) bytes at `p`.
#pragma once

#include <bit>
#include <cstddef>
#include <cstdint>
#include <type_traits>

namespace bodyd {

// An unsigned integer of N bytes (1..8) at p, the least significant byte first.
template <std::size_t N>
[[nodiscard]] constexpr std::uint64_t load_le_bytes(const std::uint8_t* p) {
  static_assert(N >= 1 && N <= 8);
  std::uint64_t v = 0;
  for (std::size_t i = 0; i < N; ++i) v |= static_cast<std::uint64_t>(p[i]) << (8 * i);
  return v;
}

// T: an integer of 1, 2, 4 or 8 bytes, float or double (IEEE-754, bit for bit).
template <typename T>
[[nodiscard]] constexpr T load_le(const std::uint8_t* p) {
  static_assert(std::is_arithmetic_v<T> && !std::is_same_v<T, bool> && (sizeof(T) == 1 || sizeof(T) == 2 || sizeof(T) == 4 || sizeof(T) == 8));
  const std::uint64_t v = load_le_bytes<sizeof(T)>(p);
  if constexpr (std::is_floating_point_v<T>) {
    using Bits = std::conditional_t<sizeof(T) == 4, std::uint32_t, std::uint64_t>;
    return std::bit_cast<T>(static_cast<Bits>(v));
  } else {
    return static_cast<T>(v);
  }
}

template <typename T>
constexpr void store_le(std::uint8_t* p, T value) {
  static_assert(std::is_arithmetic_v<T> && !std::is_same_v<T, bool> && (sizeof(T) == 1 || sizeof(T) == 2 || sizeof(T) == 4 || sizeof(T) == 8));
  std::uint64_t v = 0;
  if constexpr (std::is_floating_point_v<T>) {
    using Bits = std::conditional_t<sizeof(T) == 4, std::uint32_t, std::uint64_t>;
    v = std::bit_cast<Bits>(value);
  } else {
    v = static_cast<std::make_unsigned_t<T>>(value);
  }
  for (std::size_t i = 0; i < sizeof(T); ++i) p[i] = static_cast<std::uint8_t>(v >> (8 * i));
}

}  // namespace bodyd
