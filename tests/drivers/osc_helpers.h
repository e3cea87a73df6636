// OSC packets built by liblo for the network-input tests: an encoder independent of bodyd's
// decoder (io/osc/osc_decode.cpp), so the tests check one against the other.
#pragma once

#include <lo/lo.h>

#include <cstdint>
#include <cstdlib>
#include <initializer_list>
#include <vector>

namespace bodyd::test {

// The bytes of message `m` sent to `path`; frees `m`.
inline std::vector<std::uint8_t> osc_serialise(lo_message m, const char* path) {
  std::size_t n = 0;
  void* data = lo_message_serialise(m, path, nullptr, &n);
  std::vector<std::uint8_t> out(static_cast<std::uint8_t*>(data), static_cast<std::uint8_t*>(data) + n);
  std::free(data);
  lo_message_free(m);
  return out;
}

// PATH ,f... : VRChat OSC trackers' form.
inline std::vector<std::uint8_t> osc_floats(const char* path, std::initializer_list<float> values) {
  lo_message m = lo_message_new();
  for (float v : values) lo_message_add_float(m, v);
  return osc_serialise(m, path);
}

// PATH ,sf... : VMC's form (a serial or bone name, then floats).
inline std::vector<std::uint8_t> osc_vmc(const char* path, const char* serial, std::initializer_list<float> values) {
  lo_message m = lo_message_new();
  lo_message_add_string(m, serial);
  for (float v : values) lo_message_add_float(m, v);
  return osc_serialise(m, path);
}

// "#bundle", a zero time tag, then each element with its big-endian size (OSC 1.0).
inline std::vector<std::uint8_t> wrap_in_bundle(const std::vector<std::vector<std::uint8_t>>& elements) {
  std::vector<std::uint8_t> out{'#', 'b', 'u', 'n', 'd', 'l', 'e', 0, 0, 0, 0, 0, 0, 0, 0, 1};
  for (const auto& e : elements) {
    const auto n = static_cast<std::uint32_t>(e.size());
    for (int s = 24; s >= 0; s -= 8) out.push_back(static_cast<std::uint8_t>(n >> s));
    out.insert(out.end(), e.begin(), e.end());
  }
  return out;
}

}  // namespace bodyd::test
