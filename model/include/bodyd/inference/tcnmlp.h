// The "tcnmlp-v1" denoising network (docs/model-file.md, "Network "tcnmlp-v1""): mlpwin-v1's
// trunk over the newest N frames of a W-frame window, given a causal temporal network's summary
// of the whole window, evaluated with Eigen in float.
//
// The context network sees the observations only, [m_w * x_w; m_w] per frame: an encoder, B causal
// dilated residual blocks (tcn-v1's, causal_stack.h) and SiLU(LayerNorm). It sees neither the step
// t nor the noise, so in the steps of one sample it is the same. Its output at the newest frame,
// which depends on the last F = receptive_field() frames, enters the trunk through ctx; the newest
// N frames are decoded as mlpwin-v1 decodes its window, the W - N older ones from the context
// alone. Identical to training/model_net.py's TcnMlp; tests/model checks the two.
//
// Like MlpWin: a TcnMlp holds only weights (immutable, shared between sessions); every buffer
// lives in a TcnMlpScratch owned by one session. forward() and forward_newest() do not allocate.
#pragma once

#include "bodyd/inference/bf16_matrix.h"
#include "bodyd/inference/causal_stack.h"
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

inline constexpr std::string_view kArchitectureTcnMlp = "tcnmlp-v1";

// tcnmlp-v1's hyper-parameters, the fields of its metadata "config".
struct TcnMlpConfig {
  int W = 0;   // frames per window (the context's history, newest last)
  int D = 0;   // features per frame (features::kDim)
  int N = 0;   // newest frames the trunk sees and decodes, N <= W
  int E = 0;   // the trunk's per-frame embedding width
  int H = 0;   // trunk width
  int L = 0;   // trunk residual blocks
  int C = 0;   // context channels
  int K = 0;   // context convolution kernel size
  int B = 0;   // context causal blocks
  int R = 0;   // dilation cycle: context block b has dilation 2^(b mod R), R <= 16
  int TE = 0;  // time-embedding sinusoid dimension (even)
  int T = 0;   // diffusion steps

  [[nodiscard]] static TcnMlpConfig from(const ModelConfig& config);
  [[nodiscard]] ModelConfig to_model_config() const;
  // Frames the context at a frame depends on: 1 + (K-1) * sum of the dilations.
  [[nodiscard]] long receptive_field() const;
};

class TcnMlpScratch;

class TcnMlp final : public detail::EigenDenoiser<TcnMlpConfig, TcnMlp, TcnMlpScratch> {
 public:
  // The architecture table's row (denoiser.h). N <= W is checked by the constructor.
  static constexpr std::array<ConfigField, 12> kConfigFields = {{
      {"W", "frames per window"},
      {"D", "features per frame"},
      {"N", "newest frames the trunk sees (at most W)"},
      {"E", "trunk per-frame embedding width"},
      {"H", "trunk width"},
      {"L", "trunk residual blocks"},
      {"C", "context channels"},
      {"K", "context convolution kernel size in frames"},
      {"B", "context causal blocks"},
      {"R", "dilation cycle (context block b has dilation 2^(b mod R))", 1, 16},
      {"TE", "time-embedding dimension", 2},
      {"T", "diffusion steps"},
  }};
  [[nodiscard]] static TensorShapes tensors(const ModelConfig& config);
  static constexpr const char* kWrongScratch = "TcnMlp::forward needs a TcnMlpScratch (made by TcnMlp::make_scratch)";

  // Throws ModelFileError naming the model's source if N > W. With Weights::bf16, forward_newest()
  // multiplies by bfloat16 copies of the trunk's largest matrices (inp and the residual blocks'
  // fc1, fc2: about nine tenths of the weights it reads per frame); forward() stays float32.
  explicit TcnMlp(const Model& model, Weights weights = Weights::f32);

  [[nodiscard]] std::string_view architecture() const override { return kArchitectureTcnMlp; }
  [[nodiscard]] Weights weights() const override { return weights_; }
  using EigenDenoiser::forward;
  // As MlpWin::forward: `batch` windows at step t, frame-major, out the same size. Requirements
  // (a bug if broken: abort): whole windows, 1 <= batch <= scratch.max_batch(), 0 <= t < T, out
  // not aliasing x or m, a scratch made by this network. Does not allocate.
  void forward(std::span<const float> x, std::span<const float> m, int t, std::span<float> out,
               TcnMlpScratch& scratch) const;
  using EigenDenoiser::forward_newest;
  // One window's newest output frame, equal to forward()'s last frame (with bf16 weights: up to
  // their rounding). What does not depend on the
  // newest frame's noisy entries (the context at the newest frame, the trunk's encoding of the
  // N - 1 earlier frames and their part of inp) is kept in the scratch and reused while a call's
  // observations and past frames equal the last call's, as in the steps of one online sample; the
  // context is computed only at the frames it depends on (CausalStack::forward_newest). Does not
  // allocate.
  void forward_newest(std::span<const float> x, std::span<const float> m, int t, std::span<float> out,
                      TcnMlpScratch& scratch) const;

 private:
  friend class TcnMlpScratch;
  // A bug check: `s` was made for this network's shape.
  void require_own_scratch(const TcnMlpScratch& s) const;
  using Linear = detail::Linear;
  using LayerNorm = detail::LayerNorm;

  detail::SplitLinear cenc_;  // cenc.weight's columns for m_w * x_w and for m_w
  Eigen::VectorXf cenc_ones_;  // cenc's m_w columns summed, plus its bias: its pre-activation part for a whole-observed frame
  detail::CausalStack cstack_;  // cblocks.*
  LayerNorm cnorm_;
  Linear cdec1_, cdec2_;
  detail::RowMatrix ctx_;  // ctx.weight (its bias is folded into time_table_)
  detail::SplitLinear enc_;
  detail::RowMatrix inp_;  // inp.weight (its bias is folded into time_table_)
  // Column t: time2(SiLU(time1(sinusoid(t)))) + inp.bias + ctx.bias, H x T.
  Eigen::MatrixXf time_table_;
  detail::MlpTrunkLayers trunk_;
  std::uint64_t id_;  // this network's, unique in the process: whose cached past a scratch holds
  // Weights::bf16: forward_newest()'s copies of inp (its columns for the N - 1 earlier frames and
  // for the newest) and of each residual block's fc1 and fc2.
  Weights weights_;
  detail::Bf16Matrix inp_past_bf16_, inp_newest_bf16_;
  std::vector<std::array<detail::Bf16Matrix, 2>> blocks_bf16_;
};

// Per-session buffers for TcnMlp, for up to max_batch windows per forward() call.
class TcnMlpScratch final : public detail::EigenScratch<TcnMlpConfig> {
 public:
  explicit TcnMlpScratch(const TcnMlp& network, int max_batch = 1);

 private:
  friend class TcnMlp;
  Eigen::MatrixXf xm_;               // D x (W * batch): m * x
  Eigen::MatrixXf mg_;               // D x W: forward_newest()'s gathered masks
  Eigen::MatrixXf c_, cn_, ca_;      // C x (W * batch): context, its LayerNorm, block activations
  Eigen::MatrixXf cd_;               // C x (W * batch): older frames' decoder hidden activation
  Eigen::MatrixXf e_, d_;            // E x (N * batch): trunk embeddings, decoder hidden activation
  Eigen::MatrixXf h_, n_, a_;        // H x batch
  Eigen::MatrixXf z_;                // (N * E) x batch
  Eigen::MatrixXf g_, h2_;           // C x W: forward_newest()'s context buffers
  // forward_newest()'s cache: the window's x (past frames), m and the newest frame's m * x it was
  // computed for, and what it computed: the past frames' embeddings (E x (N-1)), inp's part of
  // them plus ctx(context at the newest frame) (H), valid for the network whose id is owner_.
  Eigen::MatrixXf past_x_, past_m_;
  Eigen::VectorXf newest_xm_;
  Eigen::MatrixXf e_past_;
  Eigen::VectorXf h_past_;
  std::uint64_t owner_ = 0;
};

}  // namespace bodyd::inference
