// The seam for model architectures: a Denoiser is any network that maps a noisy, partly
// observed window to its clean estimate, x0_hat = f(x, m, t); the model file's "architecture"
// field picks which one (docs/model-file.md, "Architectures").
//
// To add an architecture: implement Denoiser (weights only, immutable, shared between sessions)
// and its DenoiserScratch (one session's buffers, sized at construction), then add one row to
// the table in src/denoiser.cpp: its name, the fields of its metadata "config", the tensors a
// model file of it must hold for a config, and its factory. The model loader checks a file
// against that row and knows nothing else of the architecture; DiffusionReconstructor and
// Sampler only ever see this interface.
#pragma once

#include "bodyd/inference/model_file.h"

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace bodyd::inference {

// How a denoiser holds the weights its online pass (forward_newest) streams per frame: float32,
// or bfloat16 for the largest matrices (half the memory traffic, products still accumulated in
// float; docs/model.md, "Weights in bf16"). An architecture without a bf16 path runs float32
// whatever is asked (Denoiser::weights() says which). forward() always computes in float32.
enum class Weights { f32, bf16 };
[[nodiscard]] std::string_view weights_name(Weights weights);  // "f32", "bf16"
[[nodiscard]] std::optional<Weights> parse_weights(std::string_view name);

// One session's buffers for Denoiser::forward. Made by the denoiser it belongs to.
class DenoiserScratch {
 public:
  virtual ~DenoiserScratch() = default;
  [[nodiscard]] virtual int max_batch() const = 0;
};

// Streamed evaluation at one diffusion step, for an architecture whose outputs depend only on the
// current and earlier frames (Denoiser::make_stream): push() takes one new frame (x_w, m_w: D
// floats each) and writes that frame's output, given every frame pushed since reset(), at a cost
// that does not grow with the history. Outputs equal forward()'s on the window of the frames
// pushed since reset(); the architecture says when they equal a sliding window's (tcn.h).
// Must not outlive its denoiser; push() does not allocate.
class DenoiserStream {
 public:
  virtual ~DenoiserStream() = default;
  virtual void reset() = 0;
  virtual void push(std::span<const float> x, std::span<const float> m, std::span<float> out) = 0;
};

class Denoiser {
 public:
  virtual ~Denoiser() = default;

  // The architecture name as written in model files (e.g. "mlpwin-v1").
  [[nodiscard]] virtual std::string_view architecture() const = 0;
  // The weights forward_newest() multiplies by (make_denoiser's request where the architecture has that path).
  [[nodiscard]] virtual Weights weights() const { return Weights::f32; }
  // Frames per window W (the newest last), features per frame D, diffusion steps T: the config's
  // W, D and T (kConfigFrames, kConfigFeatures, kConfigSteps), which every architecture has.
  [[nodiscard]] virtual int frames() const = 0;
  [[nodiscard]] virtual int dim() const = 0;
  [[nodiscard]] virtual int steps() const = 0;
  // Floats in one window: W * D.
  [[nodiscard]] int window_size() const { return frames() * dim(); }
  // diffusion.alpha_bar[t], t in [0, T).
  [[nodiscard]] virtual std::span<const float> alpha_bar() const = 0;
  // Feature normalisation (D each): the network works on (f - mean) / std.
  [[nodiscard]] virtual std::span<const float> norm_mean() const = 0;
  [[nodiscard]] virtual std::span<const float> norm_std() const = 0;

  // Buffers for up to max_batch windows per forward() call (allocates; call at set-up).
  [[nodiscard]] virtual std::unique_ptr<DenoiserScratch> make_scratch(int max_batch) const = 0;
  // Evaluates `batch` windows at step t: x, m, out hold batch * W * D floats (frame-major windows,
  // normalised features; m is 1 where observed). Requirements as MlpWin::forward (a bug if
  // broken: abort with a message), including a scratch made by this denoiser's make_scratch().
  // Does not allocate.
  virtual void forward(std::span<const float> x, std::span<const float> m, int t, std::span<float> out,
                       DenoiserScratch& scratch) const = 0;
  // Whether forward_newest() is available: an architecture whose newest output frame depends on
  // part of the window only (tcn-v1: its receptive field) computes it for less than forward().
  [[nodiscard]] virtual bool computes_newest_alone() const { return false; }
  // The newest frame's output alone, for one window at step t: x, m hold W * D floats as for
  // forward(), out D floats, equal to forward()'s last frame on the same window. The Sampler uses
  // it when every earlier frame is fully observed (the online case), where the other frames'
  // outputs are replaced by the observations anyway. Only where computes_newest_alone() (a bug
  // otherwise: abort with a message). Does not allocate.
  virtual void forward_newest(std::span<const float> x, std::span<const float> m, int t, std::span<float> out,
                              DenoiserScratch& scratch) const;
  // A streamed evaluation at step t (0 <= t < T), or nullptr for an architecture that cannot
  // stream (each output frame depends on the whole window). Allocates; call at set-up.
  [[nodiscard]] virtual std::unique_ptr<DenoiserStream> make_stream(int t) const {
    (void)t;
    return nullptr;
  }
};

// One integer field of an architecture's metadata "config". The loader requires it and checks that
// it is an integer in [1, max] and a multiple of `multiple_of`.
struct ConfigField {
  std::string_view key;
  std::string_view meaning;  // what it is, for readers of the table
  int multiple_of = 1;       // 2: the value must be even
  int max = kMaxConfigValue;
};

// One row of the architecture table: everything the loader knows of an architecture.
struct Architecture {
  std::string_view name;
  // The fields of metadata "config" its files hold, in the order messages list them. They include
  // W, D and T (kConfigFrames, kConfigFeatures, kConfigSteps); other keys in a file are ignored.
  std::span<const ConfigField> config;
  // The network's tensors for a config holding those fields (names and shapes, in file order).
  // The loader requires exactly these plus norm.mean, norm.std and diffusion.alpha_bar
  // (expected_tensors below), all finite.
  TensorShapes (*tensors)(const ModelConfig& config);
  // Builds the denoiser from a model that parse_model() has checked against this row, holding the
  // online pass's weights as `weights` asks if it has that path (float32 otherwise).
  std::shared_ptr<const Denoiser> (*make)(const Model& model, Weights weights);
};

// Every architecture this build runs, in the order they were added.
[[nodiscard]] std::span<const Architecture> architectures();
// The row for `name`, or nullptr.
[[nodiscard]] const Architecture* find_architecture(std::string_view name);
// "mlpwin-v1, ..." for messages.
[[nodiscard]] std::string architecture_names();
// Every tensor a model file of `arch` holds for `config`: arch.tensors(config), then norm.mean [D],
// norm.std [D] and diffusion.alpha_bar [T], which every architecture has.
[[nodiscard]] TensorShapes expected_tensors(const Architecture& arch, const ModelConfig& config);
// The denoiser of a loaded model, by its architecture field. Throws ModelFileError naming the
// model's source if the architecture is unknown (parse_model already refuses such files).
// `weights`: how its online pass holds its weights (Weights above).
[[nodiscard]] std::shared_ptr<const Denoiser> make_denoiser(const Model& model, Weights weights = Weights::f32);

}  // namespace bodyd::inference
