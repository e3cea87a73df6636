// DDIM imputation sampler (CondMDI Algorithm 2 with DDIM steps; docs/model-file.md, "Sampler").
#include "bodyd/inference/sampler.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <numbers>

#include "bodyd/base/random.h"
#include "bodyd/base/require.h"
#include "bodyd/base/user_error.h"

namespace bodyd::inference {
namespace {

std::uint64_t rotl(std::uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }

std::shared_ptr<const Denoiser> checked_network(std::shared_ptr<const Denoiser> network) {
  BODYD_REQUIRE(network != nullptr, "Sampler needs a network");
  return network;
}

}  // namespace

std::vector<int> ddim_timesteps(int T, int K) {
  // T comes from a checked model file (>= 1); K is the user's --steps.
  BODYD_REQUIRE(T >= 1, fmt::format("DDIM needs T >= 1 diffusion steps, got {}", T));
  if (K < 1 || K > T)
    throw UserError("", fmt::format("DDIM steps K must be in [1, T={}], got {}", T, K),
                    fmt::format("ask for 1 to {} steps per frame (--steps)", T));
  if (K == 1) return {T - 1};
  std::vector<int> taus(static_cast<std::size_t>(K));
  for (int k = 0; k < K; ++k) {
    taus[static_cast<std::size_t>(k)] = static_cast<int>((static_cast<std::int64_t>(T - 1) * (K - 1 - k)) / (K - 1));
  }
  return taus;
}

void Rng::reseed(std::uint64_t seed) {
  std::uint64_t state = seed;
  for (auto& s : s_) s = splitmix64(state);
  has_spare_ = false;
}

std::uint64_t Rng::next_u64() {
  const std::uint64_t result = rotl(s_[1] * 5, 7) * 9;
  const std::uint64_t t = s_[1] << 17;
  s_[2] ^= s_[0];
  s_[3] ^= s_[1];
  s_[1] ^= s_[2];
  s_[0] ^= s_[3];
  s_[2] ^= t;
  s_[3] = rotl(s_[3], 45);
  return result;
}

double Rng::uniform() {
  // 53 random bits -> (0, 1].
  return (static_cast<double>(next_u64() >> 11) + 1.0) * 0x1.0p-53;
}

float Rng::normal() {
  if (has_spare_) {
    has_spare_ = false;
    return static_cast<float>(spare_);
  }
  const double r = std::sqrt(-2.0 * std::log(uniform()));
  const double phi = 2.0 * std::numbers::pi * uniform();
  spare_ = r * std::sin(phi);
  has_spare_ = true;
  return static_cast<float>(r * std::cos(phi));
}

Sampler::Sampler(std::shared_ptr<const Denoiser> network, const SamplerOptions& options, std::uint64_t seed)
    : network_(checked_network(std::move(network))),
      options_(options),
      timesteps_(ddim_timesteps(network_->steps(), options.steps)),
      rng_(seed),
      scratch_(network_->make_scratch(options.guidance == 1.0f ? 1 : 2)) {
  if (!std::isfinite(options.guidance))
    throw UserError("", fmt::format("sampler guidance scale must be finite, got {}", options.guidance),
                    "give a number (--guidance; 1 = off)");
  // eta is bodyd's own choice (0 everywhere), never the user's.
  BODYD_REQUIRE(std::isfinite(options.eta) && options.eta >= 0.0f,
                fmt::format("sampler eta must be finite and >= 0, got {}", options.eta));
  const auto window = static_cast<std::size_t>(network_->window_size());
  x_in_.assign(2 * window, 0.0f);
  m_in_.assign(2 * window, 0.0f);  // the second window's mask stays 0 (unconditional pass)
  x0_.assign(2 * window, 0.0f);
}

void Sampler::sample(std::span<const float> obs, std::span<const float> mask, std::span<float> out) {
  const auto window = static_cast<std::size_t>(network_->window_size());
  BODYD_REQUIRE(out.size() == window && mask.size() == window, "mask and out must hold W * D floats");
  // In the online case the past frames' noise is never used (they are the observations).
  const std::size_t first = newest_only(mask) ? window - static_cast<std::size_t>(network_->dim()) : 0;
  for (float& v : std::span<float>(x_in_).subspan(first, window - first)) v = rng_.normal();
  run(obs, mask, out);
}

bool Sampler::newest_only(std::span<const float> mask) const {
  const auto D = static_cast<std::ptrdiff_t>(network_->dim());
  return options_.guidance == 1.0f && network_->computes_newest_alone() &&
         std::all_of(mask.begin(), mask.end() - D, [](float v) { return v == 1.0f; });
}

void Sampler::sample_from_noise(std::span<const float> obs, std::span<const float> mask, std::span<const float> noise,
                                std::span<float> out) {
  const auto window = static_cast<std::size_t>(network_->window_size());
  BODYD_REQUIRE(noise.size() == window, "noise must hold W * D floats");
  std::copy(noise.begin(), noise.end(), x_in_.begin());
  run(obs, mask, out);
}

// x_in_[0, window) holds the initial x on entry.
void Sampler::run(std::span<const float> obs, std::span<const float> mask, std::span<float> out) {
  const std::size_t window = static_cast<std::size_t>(network_->window_size());
  BODYD_REQUIRE(obs.size() == window && mask.size() == window && out.size() == window,
                        "obs, mask and out must hold W * D floats");
  const bool guided = options_.guidance != 1.0f;
  const std::size_t batch_size = guided ? 2 * window : window;
  const std::span<float> x(x_in_.data(), window);
  const std::span<float> x_uncond(x_in_.data() + window, window);
  const std::span<float> x0(x0_.data(), window);
  const std::span<const float> x0_uncond(x0_.data() + window, window);
  std::copy(mask.begin(), mask.end(), m_in_.begin());
  // The online case: every frame but the newest fully observed. Their x0 estimates are replaced
  // by the observations, so an architecture that can computes the newest frame's alone.
  const std::size_t D = static_cast<std::size_t>(network_->dim());
  const bool newest = newest_only(mask);
  // forward_newest() leaves the past frames of x0 alone: start them from the observations, not
  // from whatever an earlier call left there. The past frames of x are the observations at every
  // step (their mask is 1), so the element-wise updates below need only the newest frame.
  const std::size_t first = newest ? window - D : 0;
  if (newest) {
    std::copy(obs.begin(), obs.end() - static_cast<std::ptrdiff_t>(D), x0.begin());
    std::copy(obs.begin(), obs.end() - static_cast<std::ptrdiff_t>(D), x.begin());
  }

  const int K = static_cast<int>(timesteps_.size());
  const float s = options_.guidance;
  for (int k = 0; k < K; ++k) {
    const int tau = timesteps_[static_cast<std::size_t>(k)];
    for (std::size_t i = first; i < window; ++i) x[i] = mask[i] * obs[i] + (1.0f - mask[i]) * x[i];
    if (guided) std::copy(x.begin(), x.end(), x_uncond.begin());
    if (newest) {
      network_->forward_newest(x, std::span<const float>(m_in_.data(), window), tau, x0.last(D), *scratch_);
    } else {
      network_->forward(std::span<const float>(x_in_.data(), batch_size),
                        std::span<const float>(m_in_.data(), batch_size), tau, std::span<float>(x0_.data(), batch_size),
                        *scratch_);
    }
    if (guided) {
      for (std::size_t i = 0; i < window; ++i) x0[i] = x0_uncond[i] + s * (x0[i] - x0_uncond[i]);
    }
    for (std::size_t i = first; i < window; ++i) x0[i] = mask[i] * obs[i] + (1.0f - mask[i]) * x0[i];
    if (k == K - 1) break;

    const double ab = network_->alpha_bar()[static_cast<std::size_t>(tau)];
    const double ab_next = network_->alpha_bar()[static_cast<std::size_t>(timesteps_[static_cast<std::size_t>(k + 1)])];
    const double sigma = options_.eta * std::sqrt((1.0 - ab_next) / (1.0 - ab)) * std::sqrt(std::max(0.0, 1.0 - ab / ab_next));
    const auto sqrt_ab = static_cast<float>(std::sqrt(ab));
    const auto inv_sqrt_1mab = static_cast<float>(1.0 / std::sqrt(1.0 - ab));
    const auto sqrt_ab_next = static_cast<float>(std::sqrt(ab_next));
    const auto dir = static_cast<float>(std::sqrt(std::max(0.0, 1.0 - ab_next - sigma * sigma)));
    for (std::size_t i = first; i < window; ++i) {
      const float eps = (x[i] - sqrt_ab * x0[i]) * inv_sqrt_1mab;
      x[i] = sqrt_ab_next * x0[i] + dir * eps;
    }
    if (sigma > 0.0) {
      const auto sig = static_cast<float>(sigma);
      for (std::size_t i = first; i < window; ++i) x[i] += sig * rng_.normal();
    }
  }
  std::copy(x0.begin(), x0.end(), out.begin());
}

}  // namespace bodyd::inference
