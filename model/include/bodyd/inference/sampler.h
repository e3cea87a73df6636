// DDIM imputation sampler (docs/model-file.md, "Sampler"): CondMDI Algorithm 2 with K DDIM steps.
//
// Works in normalised feature space ((f - norm.mean) / norm.std). At each step tau with
// ab = alpha_bar[tau]:
//   x   <- m * obs + (1 - m) * x                        (observations replace the noisy sample)
//   x0  <- net(x, m, tau)                               (or with guidance s != 1:
//                                                         x0_u + s * (x0_c - x0_u), x0_u = net(x, 0, tau))
//   x0  <- m * obs + (1 - m) * x0
//   last step: the result is x0. Otherwise, ab' = alpha_bar[next tau]:
//   eps <- (x - sqrt(ab) x0) / sqrt(1 - ab)
//   x   <- sqrt(ab') x0 + sqrt(1 - ab' - sigma^2) eps + sigma z,
//          sigma = eta sqrt((1 - ab') / (1 - ab)) sqrt(1 - ab / ab'), z ~ N(0, I)
// The same algorithm is training/model_net.py's ddim_sample. Deterministic for a seed.
//
// A Sampler is one session's state (noise, x_t, x0, network scratch), all allocated at
// construction; sample() does not allocate. The Denoiser it uses (any architecture, denoiser.h)
// is shared and immutable.
#pragma once

#include "bodyd/inference/denoiser.h"

#include <cstdint>
#include <memory>
#include <span>
#include <vector>

namespace bodyd::inference {

struct SamplerOptions {
  int steps = 4;          // K, in [1, T]
  float guidance = 1.0f;  // classifier-free guidance scale s; 1 = conditional only (one pass per step)
  float eta = 0.0f;       // DDIM eta >= 0; 0 = deterministic given the initial noise
};

// The K DDIM steps from T-1 down to 0: tau_k = floor((T-1) * (K-1-k) / (K-1)), k = 0..K-1;
// K = 1 gives {T-1}. T=100, K=4: {99, 66, 33, 0}. Throws UserError unless 1 <= K <= T (K is the
// user's --steps); T < 1 is a bug.
[[nodiscard]] std::vector<int> ddim_timesteps(int T, int K);

// Small deterministic generator: xoshiro256** (Blackman & Vigna) seeded by splitmix64, standard
// normals by the Box-Muller transform. Not the generator PyTorch uses (parity tests pass noise in).
class Rng {
 public:
  explicit Rng(std::uint64_t seed = 0) { reseed(seed); }
  void reseed(std::uint64_t seed);
  [[nodiscard]] std::uint64_t next_u64();
  // Uniform in (0, 1]: never 0, so log() in Box-Muller is finite.
  [[nodiscard]] double uniform();
  [[nodiscard]] float normal();

 private:
  std::uint64_t s_[4] = {};
  double spare_ = 0.0;
  bool has_spare_ = false;
};

class Sampler {
 public:
  // Throws UserError if the user's options are out of range (steps not in [1, T], guidance not
  // finite); a null network or an eta negative or not finite is a bug (BODYD_REQUIRE).
  Sampler(std::shared_ptr<const Denoiser> network, const SamplerOptions& options = {}, std::uint64_t seed = 0);

  [[nodiscard]] const Denoiser& network() const { return *network_; }
  [[nodiscard]] const SamplerOptions& options() const { return options_; }
  [[nodiscard]] std::span<const int> timesteps() const { return timesteps_; }
  void reseed(std::uint64_t seed) { rng_.reseed(seed); }

  // obs, mask, out: W * D floats each, frame-major, normalised space; mask entries are 0 or 1.
  // Draws the initial noise (and, with eta > 0, the step noise) from this sampler's generator.
  // Sizes must match (a bug otherwise: abort with a message). Does not allocate. When every
  // frame but the newest is fully observed and there is no guidance, the network computes only
  // the newest frame where it can (Denoiser::forward_newest); the result is the same (the
  // generator then draws the newest frame's noise alone: the past frames are the observations).
  void sample(std::span<const float> obs, std::span<const float> mask, std::span<float> out);
  // The same, starting from the given initial noise x_{tau_0} (W * D floats).
  void sample_from_noise(std::span<const float> obs, std::span<const float> mask, std::span<const float> noise,
                         std::span<float> out);

 private:
  void run(std::span<const float> obs, std::span<const float> mask, std::span<float> out);
  // The online case above: the network computes the newest frame alone.
  [[nodiscard]] bool newest_only(std::span<const float> mask) const;

  std::shared_ptr<const Denoiser> network_;
  SamplerOptions options_;
  std::vector<int> timesteps_;
  Rng rng_;
  std::unique_ptr<DenoiserScratch> scratch_;
  // Network input: [x; x] for two windows (conditional, unconditional), and [m; 0].
  std::vector<float> x_in_;
  std::vector<float> m_in_;
  std::vector<float> x0_;  // network output, one or two windows
};

}  // namespace bodyd::inference
