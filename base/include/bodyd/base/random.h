// SplitMix64 (Steele, Lea, Flood 2014; Vigna's reference splitmix64.c): the one seed mixer of
// bodyd. Everything seeded in bodyd (the sampler's xoshiro256** state, the simulators' per-role
// streams, the fake devices' noise, bodyd-eval's per-clip seeds) derives its numbers from it, so a
// seed gives the same numbers on every machine and in every build.
#pragma once

#include <cstdint>

namespace bodyd {

inline constexpr std::uint64_t kSplitMix64Increment = 0x9E3779B97F4A7C15ULL;

// The SplitMix64 finaliser: a bijective mix of one 64-bit value.
[[nodiscard]] constexpr std::uint64_t splitmix64_mix(std::uint64_t z) {
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
  return z ^ (z >> 31);
}

// The generator: advances `state` by the increment and returns the next output
// (the first output for state 0 is 0xE220A8397B1DCDAF).
[[nodiscard]] constexpr std::uint64_t splitmix64(std::uint64_t& state) {
  state += kSplitMix64Increment;
  return splitmix64_mix(state);
}

// Output number `index` (0-based) of the generator started from `seed`, without the state: a hash
// of (seed, index) that decorrelates nearby seeds (splitmix64_at(seed, 0) is the first output).
[[nodiscard]] constexpr std::uint64_t splitmix64_at(std::uint64_t seed, std::uint64_t index) {
  return splitmix64_mix(seed + kSplitMix64Increment * (index + 1));
}

}  // namespace bodyd
