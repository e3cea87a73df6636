// Helpers shared by the tests of tests/model.
#pragma once

#include "bodyd/inference/denoiser.h"
#include "bodyd/inference/model_file.h"
#include "bodyd/inference/sampler.h"

#include "../test_paths.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdio>
#include <memory>
#include <cmath>
#include <cstdint>
#include <random>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

namespace bodyd::test {

inline std::filesystem::path tiny_model_path() { return fixtures() / "tiny_model.safetensors"; }
inline std::filesystem::path tiny_io_path() { return fixtures() / "tiny_model_io.safetensors"; }
inline std::filesystem::path tiny_tcn_path() { return fixtures() / "tiny_tcn.safetensors"; }
inline std::filesystem::path tiny_tcn_io_path() { return fixtures() / "tiny_tcn_io.safetensors"; }
inline std::filesystem::path tiny_tcnmlp_path() { return fixtures() / "tiny_tcnmlp.safetensors"; }
inline std::filesystem::path tiny_tcnmlp_io_path() { return fixtures() / "tiny_tcnmlp_io.safetensors"; }

// n random floats: a mask (1 with probability 1/3, else 0) or standard normal values.
inline std::vector<float> random_window(std::mt19937& rng, std::size_t n, bool mask) {
  std::normal_distribution<float> normal(0.0f, 1.0f);
  std::vector<float> v(n);
  for (float& x : v) x = mask ? static_cast<float>(rng() % 3 == 0) : normal(rng);
  return v;
}

// The parity metric: max |a - b| / max(1e-6, max |b|), b the reference.
template <typename A, typename B>
double relative_error(const A& a, const B& b) {
  double diff = 0.0, scale = 1e-6;
  for (std::size_t i = 0; i < b.size(); ++i) {
    diff = std::max(diff, std::abs(static_cast<double>(a[i]) - static_cast<double>(b[i])));
    scale = std::max(scale, std::abs(static_cast<double>(b[i])));
  }
  return diff / scale;
}

// A model of `like`'s architecture with the given config and random weights (all finite), built in memory.
inline inference::Model random_model(const inference::ModelConfig& config, std::uint32_t seed, const inference::Model& like) {
  inference::Model m = like;  // metadata (architecture), skeleton
  m.config = config;
  m.tensors.clear();
  std::mt19937 rng(seed);
  std::normal_distribution<float> normal(0.0f, 1.0f);
  const inference::Architecture* arch = inference::find_architecture(like.metadata.at("architecture"));
  if (arch == nullptr) throw std::logic_error("random_model: unknown architecture");
  for (const auto& [name, shape] : inference::expected_tensors(*arch, config)) {
    inference::TensorF32 t;
    t.shape = shape;
    std::size_t n = 1;
    for (auto d : shape) n *= static_cast<std::size_t>(d);
    t.data.resize(n);
    const float scale = shape.size() == 2 ? 1.5f / std::sqrt(static_cast<float>(shape[1])) : 0.3f;
    for (float& v : t.data) v = scale * normal(rng);
    if (name.find("norm") != std::string::npos && name.ends_with(".weight")) {
      for (float& v : t.data) v += 1.0f;
    }
    m.tensors[name] = std::move(t);
  }
  m.norm_mean.assign(static_cast<std::size_t>(config.dim()), 0.0f);
  m.norm_std.assign(static_cast<std::size_t>(config.dim()), 1.0f);
  m.alpha_bar = m.tensors.at("diffusion.alpha_bar").data;
  for (std::size_t i = 0; i < m.alpha_bar.size(); ++i) {
    m.alpha_bar[i] = 0.999f - 0.99f * static_cast<float>(i) / static_cast<float>(m.alpha_bar.size());
  }
  return m;
}

// The online case of one W x D window: observations and a noise draw (in that order from rng),
// and a mask with every frame but the newest observed, the newest one in part (its trackers).
struct OnlineCase {
  std::vector<float> obs, noise, mask;
};
inline OnlineCase random_online_case(std::mt19937& rng, std::size_t W, std::size_t D) {
  OnlineCase c;
  c.obs = random_window(rng, W * D, false);
  c.noise = random_window(rng, W * D, false);
  c.mask.assign(W * D, 1.0f);
  const auto newest_mask = random_window(rng, D, true);
  std::copy(newest_mask.begin(), newest_mask.end(), c.mask.begin() + static_cast<std::ptrdiff_t>((W - 1) * D));
  return c;
}

// The parity fixture of a temporal network (training/export_fixture.py's write_temporal): its
// forward cases and its DDIM run, each within `tolerance` of PyTorch's outputs; and, so that the
// check can fail, another step's output far off.
inline void expect_fixture_parity(std::shared_ptr<const inference::Denoiser> net, const std::filesystem::path& io_path,
                                  const char* name, double tolerance) {
  const auto io = inference::read_tensor_file(io_path);
  const auto cases = nlohmann::json::parse(io.metadata.at("cases"));
  const auto scratch = net->make_scratch(1);
  ASSERT_EQ(cases["forward"].size(), 2u);
  for (std::size_t i = 0; i < cases["forward"].size(); ++i) {
    const std::string p = "forward." + std::to_string(i) + ".";
    const int t = cases["forward"][i]["t"];
    const auto& expected = io.tensors.at(p + "out").data;
    std::vector<float> out(expected.size()), other(expected.size());
    net->forward(io.tensors.at(p + "x").data, io.tensors.at(p + "m").data, t, out, *scratch);
    const double err = relative_error(out, expected);
    std::printf("%s forward case %zu (t=%d): relative error vs PyTorch %.3g\n", name, i, t, err);
    EXPECT_LE(err, tolerance) << "case " << i;
    net->forward(io.tensors.at(p + "x").data, io.tensors.at(p + "m").data, (t + 3) % net->steps(), other, *scratch);
    EXPECT_GT(relative_error(other, expected), 100 * tolerance);
  }
  ASSERT_EQ(cases["ddim"].size(), 1u);
  const auto& c = cases["ddim"][0];
  inference::Sampler sampler(net, inference::SamplerOptions{c["K"].get<int>(), c["guidance"].get<float>(), 0.0f});
  const auto& expected = io.tensors.at("ddim.0.out").data;
  std::vector<float> out(expected.size());
  sampler.sample_from_noise(io.tensors.at("ddim.0.obs").data, io.tensors.at("ddim.0.mask").data,
                            io.tensors.at("ddim.0.noise").data, out);
  const double err = relative_error(out, expected);
  std::printf("%s ddim: relative error vs PyTorch %.3g\n", name, err);
  EXPECT_LE(err, tolerance);
}

// DDIM with eta 0 and no guidance from the noise x, written out with forward() on the whole window
// (sampler.cpp's loop, for the reference of the sampler's newest-frame path).
inline std::vector<float> ddim_by_full_windows(const inference::Denoiser& net, std::span<const float> obs,
                                               std::span<const float> mask, std::vector<float> x, int K) {
  const auto s = net.make_scratch(1);
  std::vector<float> x0(x.size());
  const auto taus = inference::ddim_timesteps(net.steps(), K);
  for (std::size_t k = 0; k < taus.size(); ++k) {
    for (std::size_t i = 0; i < x.size(); ++i) x[i] = mask[i] * obs[i] + (1 - mask[i]) * x[i];
    net.forward(x, mask, taus[k], x0, *s);
    for (std::size_t i = 0; i < x.size(); ++i) x0[i] = mask[i] * obs[i] + (1 - mask[i]) * x0[i];
    if (k + 1 == taus.size()) break;
    const double ab = net.alpha_bar()[static_cast<std::size_t>(taus[k])];
    const double ab_next = net.alpha_bar()[static_cast<std::size_t>(taus[k + 1])];
    for (std::size_t i = 0; i < x.size(); ++i) {
      const double eps = (x[i] - std::sqrt(ab) * x0[i]) / std::sqrt(1 - ab);
      x[i] = static_cast<float>(std::sqrt(ab_next) * x0[i] + std::sqrt(1 - ab_next) * eps);
    }
  }
  return x0;
}

// The sampler (K DDIM steps, one window) on a random online case (seed 21) of `net`, the case's
// noise sampled once: its output equals DDIM over whole windows (checked here). The case, the
// sampler and the window's sizes stay for the test's own checks.
struct SamplerOnlineRun {
  std::size_t D, W;
  OnlineCase c;
  inference::Sampler sampler;
  std::vector<float> out;

  SamplerOnlineRun(const std::shared_ptr<const inference::Denoiser>& net, int K)
      : D(static_cast<std::size_t>(net->dim())),
        W(static_cast<std::size_t>(net->frames())),
        c(random_case(W, D)),
        sampler(net, inference::SamplerOptions{K, 1.0f, 0.0f}, 1),
        out(W * D) {
    sampler.sample_from_noise(c.obs, c.mask, c.noise, out);
    EXPECT_LE(relative_error(out, ddim_by_full_windows(*net, c.obs, c.mask, c.noise, K)), 1e-5);
  }

  // The next frame: the window moved on by one frame (its oldest frame wrapped round to the
  // newest) gives DDIM by whole windows again, so a cache must not serve the old past.
  void expect_the_next_window_computed_anew(const inference::Denoiser& net, int K) {
    std::vector<float> next(c.obs.begin() + static_cast<std::ptrdiff_t>(D), c.obs.end());
    next.insert(next.end(), c.obs.begin(), c.obs.begin() + static_cast<std::ptrdiff_t>(D));
    sampler.sample_from_noise(next, c.mask, c.noise, out);
    EXPECT_LE(relative_error(out, ddim_by_full_windows(net, next, c.mask, c.noise, K)), 1e-5);
  }

 private:
  static OnlineCase random_case(std::size_t W, std::size_t D) {
    std::mt19937 rng(21);
    return random_online_case(rng, W, D);
  }
};

// Two windows in one forward() (a `Scratch` for two, the networks' own kind) give what each gives
// alone, at step `t`; a scratch for two also runs a single window.
template <class Scratch, class Net>
void expect_a_batch_of_two_equals_two_singles(const Net& net, std::uint32_t seed, int t) {
  Scratch single(net, 1), pair(net, 2);
  std::mt19937 rng(seed);
  const std::size_t n = static_cast<std::size_t>(net.window_size());
  const auto x = random_window(rng, 2 * n, false);
  const auto m = random_window(rng, 2 * n, true);
  std::vector<float> out2(2 * n), a(n), b(n);
  net.forward(x, m, t, out2, pair);
  net.forward(std::span(x).first(n), std::span(m).first(n), t, a, single);
  net.forward(std::span(x).subspan(n), std::span(m).subspan(n), t, b, single);
  EXPECT_LE(relative_error(std::span(out2).first(n), a), 1e-6);
  EXPECT_LE(relative_error(std::span(out2).subspan(n), b), 1e-6);
  std::vector<float> a2(n);
  net.forward(std::span(x).first(n), std::span(m).first(n), t, a2, pair);
  EXPECT_LE(relative_error(a2, a), 1e-6);
}

// forward_newest() against forward()'s last frame on one random window, in a `Scratch` of the
// network's kind, as the sampler calls it: the steps of one sample (the same past, the newest
// frame's noisy entries changing), a changed past frame, then `also(x, m, expect_equal)` for what
// else the network's cache is keyed on, then through the Denoiser interface from a fresh scratch.
template <class Scratch, class Net, class Also>
void expect_newest_frame_equals_the_windows_last(const Net& net, std::mt19937& rng, const Also& also) {
  Scratch s(net);
  const auto D = static_cast<std::size_t>(net.dim()), W = static_cast<std::size_t>(net.frames());
  const std::size_t n = W * D;
  auto x = random_window(rng, n, false);
  auto m = random_window(rng, n, true);
  std::vector<float> full(n), newest(D);
  const auto expect_equal = [&](int t, const char* what) {
    net.forward(x, m, t, full, s);
    net.forward_newest(x, m, t, newest, s);
    EXPECT_LE(relative_error(newest, std::span(full).last(D)), 1e-5) << "W " << W << " t " << t << ": " << what;
  };
  for (int t : {net.steps() - 1, net.steps() / 2, 0}) {
    for (std::size_t d = 0; d < D; ++d)
      if (m[n - D + d] == 0.0f) x[n - D + d] = static_cast<float>(t) * 0.01f - 0.3f;
    expect_equal(t, "steps of one sample");
  }
  x[(W - 2) * D + 1] += 1.0f;
  expect_equal(1, "a past frame changed");
  also(x, m, expect_equal);
  const inference::Denoiser& base = net;
  const auto scratch = base.make_scratch(1);
  std::vector<float> via_base(D);
  base.forward_newest(x, m, 1, via_base, *scratch);
  EXPECT_LE(relative_error(via_base, newest), 1e-6);
}

// A temporal network's scratch keeps the encoded past for the network that made it: `b`, of `a`'s
// shape with other weights, given the same window in the same scratch (a `Scratch`, the
// networks' own kind), encodes it anew, and so its newest frame is its whole-window pass's.
template <class Scratch, class Net>
void expect_a_shared_scratch_keeps_each_networks_past(const Net& a, const Net& b, std::mt19937& rng) {
  Scratch shared(a);
  const auto D = static_cast<std::size_t>(a.dim()), n = static_cast<std::size_t>(a.window_size());
  const auto x = random_window(rng, n, false), m = random_window(rng, n, true);
  std::vector<float> ya(D), yb(D), full(n);
  a.forward_newest(x, m, 10, ya, shared);
  b.forward_newest(x, m, 10, yb, shared);
  b.forward(x, m, 10, full, shared);
  EXPECT_LE(relative_error(yb, std::span(full).last(D)), 1e-5);
  EXPECT_GT(relative_error(ya, yb), 1e-3);
}

}  // namespace bodyd::test
