// The "mlpwin-v1" denoising network (docs/model-file.md, "Network "mlpwin-v1""), evaluated with
// Eigen in float.
//
// x0_hat = f(x, m, t): x (W x D) the noisy window with observed entries already replaced by the
// observations, m (W x D) the mask (1 = observed), t the diffusion step in [0, T). Identical to
// training/model_net.py's MlpWin; tests/model checks both against each other and against
// a plain double-precision reference.
//
// Model apart from state: an MlpWin holds only weights (immutable after construction, share it
// between sessions as std::shared_ptr<const MlpWin>); every buffer a forward pass needs lives in an
// MlpWinScratch owned by one session and sized when it is constructed. forward() and
// forward_newest() do not allocate. Windows are frame-major: element (w, d) of a window is at
// index w * D + d.
#pragma once

#include "bodyd/inference/bf16_matrix.h"
#include "bodyd/inference/denoiser.h"
#include "bodyd/inference/eigen_denoiser.h"
#include "bodyd/inference/model_file.h"

#include <Eigen/Core>

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

namespace bodyd::inference {

inline constexpr std::string_view kArchitectureMlpWin = "mlpwin-v1";

// mlpwin-v1's hyper-parameters, the fields of its metadata "config" (docs/model-file.md).
struct MlpWinConfig {
  int W = 0;   // frames per window
  int D = 0;   // features per frame (features::kDim)
  int E = 0;   // per-frame embedding width
  int H = 0;   // trunk width
  int L = 0;   // residual blocks
  int TE = 0;  // time-embedding sinusoid dimension (even)
  int T = 0;   // diffusion steps

  // From a config the loader checked against MlpWin::kConfigFields.
  [[nodiscard]] static MlpWinConfig from(const ModelConfig& config);
  [[nodiscard]] ModelConfig to_model_config() const;
};

class MlpWinScratch;

// The Denoiser of architecture "mlpwin-v1" (denoiser.h).
class MlpWin final : public detail::EigenDenoiser<MlpWinConfig, MlpWin, MlpWinScratch> {
 public:
  // Copies the weights out of a checked model and precomputes the time embedding of every step.
  // With Weights::bf16, forward_newest() multiplies by bfloat16 copies of inp, fc1 and fc2 (float32
  // accumulation; nearly all the weights it reads per frame); forward() stays float32.
  explicit MlpWin(const Model& model, Weights weights = Weights::f32);

  // The architecture table's row (denoiser.h): config fields, tensors, factory.
  static constexpr std::array<ConfigField, 7> kConfigFields = {{
      {"W", "frames per window"},
      {"D", "features per frame"},
      {"E", "per-frame embedding width"},
      {"H", "trunk width"},
      {"L", "residual blocks"},
      {"TE", "time-embedding dimension", 2},
      {"T", "diffusion steps"},
  }};
  // The network's parameters under their PyTorch state-dict names, in file order (docs/model-file.md).
  [[nodiscard]] static TensorShapes tensors(const ModelConfig& config);
  static constexpr const char* kWrongScratch = "MlpWin::forward needs an MlpWinScratch (made by MlpWin::make_scratch)";

  // make(), config(), frames(), dim(), steps(), alpha_bar(), norm_mean(), norm_std(), make_scratch()
  // and forward(..., DenoiserScratch&), which takes an MlpWinScratch: EigenDenoiser.
  [[nodiscard]] std::string_view architecture() const override { return kArchitectureMlpWin; }
  [[nodiscard]] Weights weights() const override { return weights_; }
  using EigenDenoiser::forward;
  using EigenDenoiser::forward_newest;

  // Evaluates `batch` windows at the same step t. x, m: batch * W * D floats (window after
  // window, each frame-major); out: the same size (may not alias x or m). Requirements (a bug
  // if broken; checked in every build type, abort with a message): 1 <= batch <=
  // scratch.max_batch(), spans of exactly batch * W * D, 0 <= t < T, scratch made for this
  // network's config. Does not allocate.
  void forward(std::span<const float> x, std::span<const float> m, int t, std::span<float> out,
               MlpWinScratch& scratch) const;

  // One window's newest output frame, equal to forward()'s last frame (with bf16 weights: up to
  // bfloat16's rounding), for the online sample, whose other frames are observed and replaced by
  // the observations. x, m, t as forward() with batch 1; out: D floats. The past frames'
  // embeddings and their part of inp are reused while the past frames' x and m equal the last
  // call's, as in the steps of one online sample. Does not allocate.
  void forward_newest(std::span<const float> x, std::span<const float> m, int t, std::span<float> out,
                      MlpWinScratch& scratch) const;

 private:
  // A bug check: `s` was made for this network's shape.
  void require_own_scratch(const MlpWinScratch& s) const;
  using Linear = detail::Linear;
  using LayerNorm = detail::LayerNorm;

  detail::SplitLinear enc_;  // enc.weight's columns for x_w and for m_w
  Linear inp_;
  // Column t: time2(SiLU(time1(sinusoid(t)))) + inp.bias (depends on t only), H x T.
  Eigen::MatrixXf time_table_;
  detail::MlpTrunkLayers trunk_;
  std::uint64_t id_;  // this network's, unique in the process: whose cached past a scratch holds
  // Weights::bf16: forward_newest()'s copies of inp (its columns for the W - 1 earlier frames and
  // for the newest) and of each residual block's fc1 and fc2.
  Weights weights_;
  detail::Bf16Matrix inp_past_bf16_, inp_newest_bf16_;
  std::vector<std::array<detail::Bf16Matrix, 2>> blocks_bf16_;
};

// Per-session buffers for MlpWin::forward, for up to max_batch windows per call.
class MlpWinScratch final : public detail::EigenScratch<MlpWinConfig> {
 public:
  explicit MlpWinScratch(const MlpWin& network, int max_batch = 1);

 private:
  friend class MlpWin;
  Eigen::MatrixXf e_;      // E x (W * batch): per-frame embeddings, frame after frame
  Eigen::MatrixXf h_;      // H x batch: trunk state
  Eigen::MatrixXf n_;      // H x batch: normalised / activated trunk state
  Eigen::MatrixXf a_;      // H x batch: block hidden activation
  Eigen::MatrixXf z_;      // (W * E) x batch: trunk output, frame-major per window
  Eigen::MatrixXf d_;      // E x (W * batch): decoder hidden activation
  // forward_newest()'s cache: the past frames' x and m it was computed for, and what it computed:
  // their embeddings (E x (W-1)) and inp's part of them (H), valid for the network whose id is owner_.
  Eigen::MatrixXf past_x_, past_m_;
  Eigen::MatrixXf e_past_;
  Eigen::VectorXf h_past_;
  std::uint64_t owner_ = 0;
};

// The sinusoidal time embedding of docs/model-file.md in double precision (dim even):
// out[i] = sin(t * f_i), out[half + i] = cos(t * f_i), f_i = exp(-ln(10000) * i / half).
void timestep_embedding(int t, std::span<double> out);

}  // namespace bodyd::inference
