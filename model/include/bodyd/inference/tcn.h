// The "tcn-v1" denoising network (docs/model-file.md, "Network "tcn-v1""): a temporal
// convolutional network whose weights are shared over time, evaluated with Eigen in float.
//
// x0_hat = f(x, m, t) on a W x D window, like every Denoiser (denoiser.h). Per frame an encoder of
// [x_w; m_w] plus the step embedding, then L residual blocks, each a LayerNorm, a causal dilated
// 1-D convolution over frames (kernel K, dilation 2^(b mod R), zeros before the window's first
// frame), SiLU and a per-frame linear layer, then a per-frame decoder. Frame w's output depends on
// frames w-F+1..w only, F = receptive_field(); with F <= W the newest frame's output is that of an
// unbounded stream, which TcnStream computes at a cost per frame that does not grow with W.
// Identical to training/model_net.py's TcnCausal; tests/model checks the two.
//
// Like MlpWin: a Tcn holds only weights (immutable, shared between sessions); every buffer lives
// in a TcnScratch (or a TcnStream) owned by one session. forward() does not allocate.
#pragma once

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

inline constexpr std::string_view kArchitectureTcn = "tcn-v1";

// tcn-v1's hyper-parameters, the fields of its metadata "config".
struct TcnConfig {
  int W = 0;   // frames per window (the history the sampler sees, newest last)
  int D = 0;   // features per frame (features::kDim)
  int C = 0;   // channels
  int K = 0;   // convolution kernel size (taps over frames)
  int L = 0;   // residual blocks
  int R = 0;   // dilation cycle: block b has dilation 2^(b mod R), R <= 16
  int TE = 0;  // time-embedding sinusoid dimension (even)
  int T = 0;   // diffusion steps

  [[nodiscard]] static TcnConfig from(const ModelConfig& config);
  [[nodiscard]] ModelConfig to_model_config() const;
  [[nodiscard]] int dilation(int block) const { return 1 << (block % R); }
  // Frames an output depends on: 1 + (K-1) * sum of the dilations.
  [[nodiscard]] long receptive_field() const;
};

class TcnScratch;
class TcnStream;

class Tcn final : public detail::EigenDenoiser<TcnConfig, Tcn, TcnScratch> {
 public:
  // The architecture table's row (denoiser.h).
  static constexpr std::array<ConfigField, 8> kConfigFields = {{
      {"W", "frames per window"},
      {"D", "features per frame"},
      {"C", "channels"},
      {"K", "convolution kernel size in frames"},
      {"L", "residual blocks"},
      {"R", "dilation cycle (block b has dilation 2^(b mod R))", 1, 16},
      {"TE", "time-embedding dimension", 2},
      {"T", "diffusion steps"},
  }};
  [[nodiscard]] static TensorShapes tensors(const ModelConfig& config);
  static constexpr const char* kWrongScratch = "Tcn::forward needs a TcnScratch (made by Tcn::make_scratch)";

  explicit Tcn(const Model& model);

  // make(), config(), frames(), dim(), steps(), alpha_bar(), norm_mean(), norm_std(), make_scratch()
  // and forward(..., DenoiserScratch&), which takes a TcnScratch: EigenDenoiser.
  [[nodiscard]] std::string_view architecture() const override { return kArchitectureTcn; }
  using EigenDenoiser::forward;
  // A TcnStream at step t.
  [[nodiscard]] std::unique_ptr<DenoiserStream> make_stream(int t) const override;
  // The newest frame's output alone (Denoiser::forward_newest), which takes a TcnScratch.
  using EigenDenoiser::forward_newest;
  // One window's newest output frame, equal to forward()'s last frame: every layer is evaluated
  // only at the frames that output depends on (newest_frames() for the encoder, fewer in each
  // block above: with W = 64, K = 3 and dilations 1..16, 63 encoder frames and 31 + 15 + 7 + 3 + 1
  // block outputs, where forward() computes 64 of each). The scratch keeps the encoded past
  // frames (the encoder does not depend on t) and reuses them while a call's past frames equal
  // the last call's, as in the steps of one online sample. x, m: W * D floats; out: D floats, not
  // aliasing them; 0 <= t < T; a scratch made by this network (a bug otherwise: abort). Does not
  // allocate.
  void forward_newest(std::span<const float> x, std::span<const float> m, int t, std::span<float> out,
                      TcnScratch& scratch) const;
  // The window's frames that forward_newest() encodes, ascending (min(W, receptive_field()) of them
  // when the dilations cover every offset, as with R >= L).
  [[nodiscard]] std::span<const Eigen::Index> newest_frames() const { return stack_.newest_frames(); }

  // As MlpWin::forward: `batch` windows at step t, frame-major, out the same size. Requirements
  // (a bug if broken: abort): whole windows, 1 <= batch <= scratch.max_batch(), 0 <= t < T, out
  // not aliasing x or m, a scratch made by this network. Does not allocate.
  void forward(std::span<const float> x, std::span<const float> m, int t, std::span<float> out,
               TcnScratch& scratch) const;

 private:
  friend class TcnScratch;
  friend class TcnStream;
  using RowMatrix = detail::RowMatrix;
  using Linear = detail::Linear;
  using LayerNorm = detail::LayerNorm;
  detail::SplitLinear enc_;  // enc.weight's columns for x_w and for m_w
  Eigen::MatrixXf time_table_;  // C x T: time2(SiLU(time1(sinusoid(t)))), column t
  detail::CausalStack stack_;  // blocks.*
  LayerNorm out_norm_;
  Linear dec1_, dec2_;
  Eigen::VectorXf enc_mask_ones_;  // enc_.v times a mask of ones: a fully observed frame's mask term
  std::uint64_t id_;               // this network's, unique in the process: whose encoded past a scratch holds
};

// Per-session buffers for Tcn::forward, for up to max_batch windows per call.
class TcnScratch final : public detail::EigenScratch<TcnConfig> {
 public:
  explicit TcnScratch(const Tcn& network, int max_batch = 1);

 private:
  friend class Tcn;
  Eigen::MatrixXf h_, n_, a_, d_;  // C x (W * batch) each
  Eigen::MatrixXf g_, h2_;         // forward_newest(): a tap's gathered inputs, a block's output (C x W)
  // forward_newest(): the encoded past frames' x and m (D x W) and their encoder outputs before
  // the step embedding (C x W), valid for the network whose id is enc_owner_ (0: none).
  Eigen::MatrixXf xg_, mg_, enc_past_;
  std::uint64_t enc_owner_ = 0;
};

// Streaming evaluation of a Tcn at one diffusion step: push() takes one new frame (x_w, m_w) and
// returns that frame's output, keeping the past frames' activations of every block (ring
// buffers of (K-1) * dilation frames each), so a frame costs the same whatever the history. The
// outputs equal Tcn::forward's on the window of every frame pushed since reset() (the first
// frame pushed is the window's first frame), and once F = receptive_field() frames or more have
// been pushed, the newest output equals forward()'s newest frame on any window of the last W >= F
// frames. Sized at construction; push() does not allocate. Must not outlive `network`.
class TcnStream final : public DenoiserStream {
 public:
  TcnStream(const Tcn& network, int t);
  // Forgets every frame pushed (the next frame is the first of a window).
  void reset() override;
  // x, m, out: D floats (normalised features, mask). Does not allocate.
  void push(std::span<const float> x, std::span<const float> m, std::span<float> out) override;
  [[nodiscard]] int step() const { return t_; }

 private:
  const Tcn* network_;
  int t_;
  long pushed_ = 0;
  // Per block: the LayerNorm output of the last `history` frames, column (pushed % history).
  std::vector<Eigen::MatrixXf> past_;
  Eigen::VectorXf h_, n_, a_, d_;
};

}  // namespace bodyd::inference
