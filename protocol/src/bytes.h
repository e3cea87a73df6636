// Little-endian field writers and a bounds-checked reader (internal to bodyd_protocol), over
// the one little-endian definition (bodyd/base/little_endian.h).
#pragma once

#include "bodyd/base/little_endian.h"
#include "bodyd/base/require.h"

#include <bit>
#include <cstdint>
#include <cstring>
#include <span>
#include <vector>

namespace bodyd::protocol::detail {

inline void put_u8(std::vector<std::uint8_t>& out, std::uint8_t v) { out.push_back(v); }
template <typename T>
inline void put_le(std::vector<std::uint8_t>& out, T v) {
  std::uint8_t bytes[sizeof(T)];
  store_le(bytes, v);
  out.insert(out.end(), bytes, bytes + sizeof(T));
}
inline void put_u16(std::vector<std::uint8_t>& out, std::uint16_t v) { put_le(out, v); }
inline void put_u32(std::vector<std::uint8_t>& out, std::uint32_t v) { put_le(out, v); }
inline void put_u64(std::vector<std::uint8_t>& out, std::uint64_t v) { put_le(out, v); }
inline void put_i16(std::vector<std::uint8_t>& out, std::int16_t v) { put_u16(out, static_cast<std::uint16_t>(v)); }
inline void put_i64(std::vector<std::uint8_t>& out, std::int64_t v) { put_u64(out, static_cast<std::uint64_t>(v)); }
inline void put_f32(std::vector<std::uint8_t>& out, float v) { put_u32(out, std::bit_cast<std::uint32_t>(v)); }
inline void put_bytes(std::vector<std::uint8_t>& out, const void* data, std::size_t size) {
  const auto* p = static_cast<const std::uint8_t*>(data);
  out.insert(out.end(), p, p + size);
}

// Reads fields at explicit offsets. Callers check the total size first; every read is
// nevertheless checked, and an out-of-range read returns 0 and sets `overrun` (a bug guard).
class Reader {
 public:
  explicit Reader(std::span<const std::uint8_t> bytes) : bytes_(bytes) {}

  [[nodiscard]] bool has(std::size_t offset, std::size_t size) const {
    return offset <= bytes_.size() && size <= bytes_.size() - offset;
  }
  [[nodiscard]] std::uint64_t uint(std::size_t offset, int size) {
    if (!has(offset, static_cast<std::size_t>(size))) {
      overrun = true;
      return 0;
    }
    const std::uint8_t* p = bytes_.data() + offset;
    switch (size) {
      case 1: return load_le<std::uint8_t>(p);
      case 2: return load_le<std::uint16_t>(p);
      case 4: return load_le<std::uint32_t>(p);
      case 8: return load_le<std::uint64_t>(p);
    }
    BODYD_REQUIRE(false, "Reader::uint reads 1, 2, 4 or 8 bytes");
    return 0;
  }
  std::uint8_t u8(std::size_t o) { return static_cast<std::uint8_t>(uint(o, 1)); }
  std::uint16_t u16(std::size_t o) { return static_cast<std::uint16_t>(uint(o, 2)); }
  std::uint32_t u32(std::size_t o) { return static_cast<std::uint32_t>(uint(o, 4)); }
  std::uint64_t u64(std::size_t o) { return uint(o, 8); }
  std::int16_t i16(std::size_t o) { return static_cast<std::int16_t>(u16(o)); }
  std::int64_t i64(std::size_t o) { return static_cast<std::int64_t>(u64(o)); }
  float f32(std::size_t o) { return std::bit_cast<float>(u32(o)); }
  [[nodiscard]] const std::uint8_t* at(std::size_t o) const { return bytes_.data() + o; }
  [[nodiscard]] std::size_t size() const { return bytes_.size(); }

  bool overrun = false;

 private:
  std::span<const std::uint8_t> bytes_;
};

}  // namespace bodyd::protocol::detail
