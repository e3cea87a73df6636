// The seam for model architectures: a Denoiser is any network that maps a noisy, partly
// observed window to its clean estimate, x0_hat = f(x, m, t); the model file's "architecture"
// field picks which one (docs/model-file.md, "Architectures").
//
// To add an architecture: implement Denoiser (weights only, immutable, shared between sessions)
// and its DenoiserScratch (one session's buffers, sized at construction), then add one row to
// the table in src/denoiser.cpp: its name, the tensors a model file of it must hold, and its
// factory. The model loader checks a file against that row; DiffusionReconstructor and Sampler
// only ever see this interface.
#pragma once

#include "bodyd/inference/model_file.h"

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace bodyd::inference {

// One session's buffers for Denoiser::forward. Made by the denoiser it belongs to.
class DenoiserScratch {
 public:
  virtual ~DenoiserScratch() = default;
  [[nodiscard]] virtual int max_batch() const = 0;
};

class Denoiser {
 public:
  virtual ~Denoiser() = default;

  // The architecture name as written in model files (e.g. "mlpwin-v1").
  [[nodiscard]] virtual std::string_view architecture() const = 0;
  [[nodiscard]] virtual const NetConfig& config() const = 0;
  [[nodiscard]] int frames() const { return config().W; }
  [[nodiscard]] int dim() const { return config().D; }
  [[nodiscard]] int steps() const { return config().T; }
  // Floats in one window: W * D.
  [[nodiscard]] int window_size() const { return config().W * config().D; }
  // diffusion.alpha_bar[t], t in [0, T).
  [[nodiscard]] virtual std::span<const float> alpha_bar() const = 0;
  // Feature normalisation (D each): the network works on (f - mean) / std.
  [[nodiscard]] virtual std::span<const float> norm_mean() const = 0;
  [[nodiscard]] virtual std::span<const float> norm_std() const = 0;

  // Buffers for up to max_batch windows per forward() call (allocates; call at set-up).
  [[nodiscard]] virtual std::unique_ptr<DenoiserScratch> make_scratch(int max_batch) const = 0;
  // Evaluates `batch` windows at step t: x, m, out hold batch * W * D floats (frame-major windows,
  // normalised features; m is 1 where observed). Requirements as Network::forward (a bug if
  // broken: abort with a message), including a scratch made by this denoiser's make_scratch().
  // Does not allocate.
  virtual void forward(std::span<const float> x, std::span<const float> m, int t, std::span<float> out,
                       DenoiserScratch& scratch) const = 0;
};

// One row of the architecture table.
struct Architecture {
  std::string_view name;
  // The tensors a model file of this architecture holds for `config`, with their shapes, in file
  // order (including norm.mean, norm.std, diffusion.alpha_bar); the loader requires exactly these.
  std::vector<std::pair<std::string, std::vector<std::int64_t>>> (*expected_tensors)(const NetConfig& config);
  // Builds the denoiser from a model that parse_model() has checked against expected_tensors.
  std::shared_ptr<const Denoiser> (*make)(const Model& model);
};

// Every architecture this build runs, in the order they were added.
[[nodiscard]] std::span<const Architecture> architectures();
// The row for `name`, or nullptr.
[[nodiscard]] const Architecture* find_architecture(std::string_view name);
// "mlpwin-v1, ..." for messages.
[[nodiscard]] std::string architecture_names();
// The denoiser of a loaded model, by its architecture field. Throws ModelFileError naming the
// model's source if the architecture is unknown (parse_model already refuses such files).
[[nodiscard]] std::shared_ptr<const Denoiser> make_denoiser(const Model& model);

}  // namespace bodyd::inference
