// Internal: a stack of causal dilated residual blocks (tcn-v1's blocks, tcnmlp-v1's context
// network), evaluated over whole windows, at the newest frame alone, or one frame at a time.
//
// Block b: h + fc(SiLU(conv(LayerNorm(h)))), the convolution over frames with kernel K and dilation
// 2^(b mod R), reading only the current and earlier frames (zeros before the window's first frame).
// Columns are frames (C rows); a batch of windows is window after window.
#pragma once

#include "bodyd/inference/eigen_denoiser.h"
#include "bodyd/inference/model_file.h"

#include <Eigen/Core>

#include <string>
#include <vector>

namespace bodyd::inference::detail {

class CausalStack {
 public:
  struct Block {
    LayerNorm norm;
    std::vector<RowMatrix> taps;  // K matrices C x C: tap k multiplies frame w - (K-1-k) * dilation
    Eigen::VectorXf conv_bias;
    Linear fc;
    int dilation = 1;
  };

  // The tensors of blocks <prefix><b>.{norm,conv,fc}.*, b < L (Architecture::tensors).
  static void add_tensors(TensorShapes& v, const std::string& prefix, std::int64_t C, std::int64_t K, int L);
  // Frames an output depends on: 1 + (K-1) * sum over blocks of 2^(b mod R).
  [[nodiscard]] static long receptive_field(int K, int L, int R);

  CausalStack() = default;
  // Loads those blocks from a checked model; plans forward_newest() for windows of W frames.
  CausalStack(const Model& model, const std::string& prefix, int W, int C, int K, int L, int R);

  [[nodiscard]] const std::vector<Block>& blocks() const { return blocks_; }
  [[nodiscard]] int kernel() const { return K_; }

  // Every block over `batch` windows of W frames: h (C x W*batch) in place; n and a are buffers of
  // the same size. Does not allocate.
  void forward(Eigen::Ref<Eigen::MatrixXf> h, Eigen::Ref<Eigen::MatrixXf> n, Eigen::Ref<Eigen::MatrixXf> a,
               Eigen::Index batch) const;

  // The window's frames the newest output depends on, ascending, the newest (W-1) last.
  [[nodiscard]] const std::vector<Eigen::Index>& newest_frames() const { return newest_frames_; }
  // Every block at the frames the newest output depends on only: h's first newest_frames().size()
  // columns hold the stack's input at those frames; on return h's column 0 holds the output at the
  // newest frame. h, n, a, g, h2: C x W buffers. Does not allocate.
  void forward_newest(Eigen::MatrixXf& h, Eigen::MatrixXf& n, Eigen::MatrixXf& a, Eigen::MatrixXf& g,
                      Eigen::MatrixXf& h2) const;

 private:
  // Block b of forward_newest(): its output columns are the frames of level b + 1, its input
  // columns those of level b (level 0: newest_frames_).
  struct NewestBlock {
    std::vector<Eigen::Index> residual;           // per output column: the input column of the same frame
    std::vector<std::vector<Eigen::Index>> taps;  // [k][column]: the input column tap k reads, -1 before the window
  };
  void plan_newest(int W);

  int K_ = 0;
  std::vector<Block> blocks_;
  std::vector<Eigen::Index> newest_frames_;
  std::vector<NewestBlock> newest_blocks_;
};

}  // namespace bodyd::inference::detail
