// Helpers shared by the tests of tests/model.
#pragma once

#include "bodyd/inference/denoiser.h"
#include "bodyd/inference/model_file.h"

#include "../test_paths.h"

#include <algorithm>
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

}  // namespace bodyd::test
