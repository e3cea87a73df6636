// Little-endian field writers and a bounds-checked reader (internal to bodyd_protocol).
// Fields are assembled byte by byte, so neither host endianness nor alignment matters.
#pragma once

#include <bit>
#include <cstdint>
#include <cstring>
#include <span>
#include <vector>

namespace bodyd::protocol::detail {

inline void put_u8(std::vector<std::uint8_t>& out, std::uint8_t v) { out.push_back(v); }
inline void put_u16(std::vector<std::uint8_t>& out, std::uint16_t v) {
  out.push_back(static_cast<std::uint8_t>(v));
  out.push_back(static_cast<std::uint8_t>(v >> 8));
}
inline void put_u32(std::vector<std::uint8_t>& out, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}
inline void put_u64(std::vector<std::uint8_t>& out, std::uint64_t v) {
  for (int i = 0; i < 8; ++i) out.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}
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
    std::uint64_t v = 0;
    for (int i = 0; i < size; ++i) v |= static_cast<std::uint64_t>(bytes_[offset + i]) << (8 * i);
    return v;
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
