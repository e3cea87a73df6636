// Eigen evaluation of a causal dilated block stack (causal_stack.h): whole windows, the newest
// frame alone. The streamed form lives with its network (tcn.cpp's TcnStream).
#include "bodyd/inference/causal_stack.h"

#include "eigen_ops.h"

#include <algorithm>
#include <set>

namespace bodyd::inference::detail {

namespace {
// out += w * in. Eigen's matrix-matrix product packs w on every call, which costs more than the
// product itself for the few columns of forward_newest()'s upper blocks: there, one
// matrix-vector product per column (measured with bodyd-bench-net, "sample online").
constexpr Eigen::Index kMatrixVectorColumns = 8;
template <typename In, typename Out>
void mul_add(const RowMatrix& w, const Eigen::MatrixBase<In>& in, Eigen::MatrixBase<Out>& out) {
  if (in.cols() <= kMatrixVectorColumns) {
    for (Eigen::Index j = 0; j < in.cols(); ++j) out.col(j).noalias() += w * in.col(j);
  } else {
    out.noalias() += w * in;
  }
}
int dilation_of(int block, int R) { return 1 << (block % R); }
}  // namespace

void CausalStack::add_tensors(TensorShapes& v, const std::string& prefix, std::int64_t C, std::int64_t K, int L) {
  for (int b = 0; b < L; ++b) {
    const std::string p = prefix + std::to_string(b) + ".";
    add_layer_norm(v, p + "norm", C);
    v.emplace_back(p + "conv.weight", std::vector<std::int64_t>{C, C, K});
    v.emplace_back(p + "conv.bias", std::vector<std::int64_t>{C});
    add_linear(v, p + "fc", C, C);
  }
}

long CausalStack::receptive_field(int K, int L, int R) {
  long sum = 0;
  for (int b = 0; b < L; ++b) sum += dilation_of(b, R);
  return 1 + static_cast<long>(K - 1) * sum;
}

CausalStack::CausalStack(const Model& model, const std::string& prefix, int W, int C, int K, int L, int R) : K_(K) {
  for (int b = 0; b < L; ++b) {
    const std::string p = prefix + std::to_string(b) + ".";
    Block blk;
    blk.norm = load_layer_norm(model, p + "norm");
    // PyTorch's Conv1d weight [out, in, K]: tap k of output o and input i at (o * C + i) * K + k.
    const TensorF32& w = model.tensor(p + "conv.weight");
    blk.taps.assign(static_cast<std::size_t>(K), RowMatrix(C, C));
    for (int o = 0; o < C; ++o)
      for (int i = 0; i < C; ++i)
        for (int k = 0; k < K; ++k)
          blk.taps[static_cast<std::size_t>(k)](o, i) =
              w.data[(static_cast<std::size_t>(o) * static_cast<std::size_t>(C) + static_cast<std::size_t>(i)) *
                         static_cast<std::size_t>(K) +
                     static_cast<std::size_t>(k)];
    blk.conv_bias = to_vector(model.tensor(p + "conv.bias"));
    blk.fc = load_linear(model, p + "fc");
    blk.dilation = dilation_of(b, R);
    blocks_.push_back(std::move(blk));
  }
  plan_newest(W);
}

void CausalStack::plan_newest(int W) {
  const auto L = blocks_.size();
  // Top down: the newest output needs the last block's output at frame W-1; a block's output at
  // frame f needs its input at f (the residual) and at f - (K-1-k) * dilation for each tap k that
  // stays in the window. levels[b]: the frames of block b's input, ascending; levels[L]: {W-1}.
  std::vector<std::vector<Eigen::Index>> levels(L + 1);
  levels.back() = {static_cast<Eigen::Index>(W) - 1};
  for (std::size_t b = L; b-- > 0;) {
    std::set<Eigen::Index> in;
    for (Eigen::Index f : levels[b + 1])
      for (int k = 0; k < K_; ++k)
        if (const Eigen::Index g = f - static_cast<Eigen::Index>(K_ - 1 - k) * blocks_[b].dilation; g >= 0) in.insert(g);
    levels[b].assign(in.begin(), in.end());
  }
  newest_frames_ = levels.front();
  newest_blocks_.assign(L, {});
  for (std::size_t b = 0; b < L; ++b) {
    const auto& in = levels[b];
    const auto column = [&in](Eigen::Index frame) -> Eigen::Index {
      const auto it = std::lower_bound(in.begin(), in.end(), frame);
      return it != in.end() && *it == frame ? static_cast<Eigen::Index>(it - in.begin()) : -1;
    };
    NewestBlock& nb = newest_blocks_[b];
    nb.taps.assign(static_cast<std::size_t>(K_), {});
    for (Eigen::Index f : levels[b + 1]) {
      nb.residual.push_back(column(f));
      for (int k = 0; k < K_; ++k) {
        const Eigen::Index g = f - static_cast<Eigen::Index>(K_ - 1 - k) * blocks_[b].dilation;
        nb.taps[static_cast<std::size_t>(k)].push_back(g >= 0 ? column(g) : -1);
      }
    }
  }
}

void CausalStack::forward(Eigen::Ref<Eigen::MatrixXf> h, Eigen::Ref<Eigen::MatrixXf> n, Eigen::Ref<Eigen::MatrixXf> a,
                          Eigen::Index batch) const {
  const Eigen::Index W = h.cols() / batch;
  for (const Block& blk : blocks_) {
    layer_norm(h, blk.norm.weight, blk.norm.bias, n);
    a.setZero();
    a.colwise() += blk.conv_bias;
    // Tap k reads frame w - offset (offset = (K-1-k) * dilation); frames before the window are 0.
    for (int k = 0; k < K_; ++k) {
      const Eigen::Index offset = static_cast<Eigen::Index>(K_ - 1 - k) * blk.dilation;
      if (offset >= W) continue;
      const RowMatrix& tap = blk.taps[static_cast<std::size_t>(k)];
      for (Eigen::Index b = 0; b < batch; ++b)
        a.middleCols(b * W + offset, W - offset).noalias() += tap * n.middleCols(b * W, W - offset);
    }
    silu_inplace(a);
    h.noalias() += blk.fc.weight * a;
    h.colwise() += blk.fc.bias;
  }
}

void CausalStack::forward_newest(Eigen::MatrixXf& h, Eigen::MatrixXf& n_buf, Eigen::MatrixXf& a_buf,
                                 Eigen::MatrixXf& g_buf, Eigen::MatrixXf& h2_buf) const {
  // Each block at its output frames only: h holds the block's input columns, h2 its output.
  auto in_cols = static_cast<Eigen::Index>(newest_frames_.size());
  for (std::size_t b = 0; b < blocks_.size(); ++b) {
    const Block& blk = blocks_[b];
    const NewestBlock& plan = newest_blocks_[b];
    const auto out_cols = static_cast<Eigen::Index>(plan.residual.size());
    auto n = n_buf.leftCols(in_cols);
    layer_norm(h.leftCols(in_cols), blk.norm.weight, blk.norm.bias, n);
    auto a = a_buf.leftCols(out_cols);
    auto g = g_buf.leftCols(out_cols);
    a.setZero();
    a.colwise() += blk.conv_bias;
    for (int k = 0; k < K_; ++k) {
      const auto& cols = plan.taps[static_cast<std::size_t>(k)];
      bool any = false;
      for (Eigen::Index j = 0; j < out_cols; ++j) {
        const Eigen::Index col = cols[static_cast<std::size_t>(j)];
        if (col >= 0) {
          g.col(j) = n.col(col);
          any = true;
        } else {
          g.col(j).setZero();  // before the window: zeros, as forward()'s
        }
      }
      if (any) mul_add(blk.taps[static_cast<std::size_t>(k)], g, a);
    }
    silu_inplace(a);
    auto h2 = h2_buf.leftCols(out_cols);
    for (Eigen::Index j = 0; j < out_cols; ++j) h2.col(j) = h.col(plan.residual[static_cast<std::size_t>(j)]);
    mul_add(blk.fc.weight, a, h2);
    h2.colwise() += blk.fc.bias;
    h.leftCols(out_cols) = h2;
    in_cols = out_cols;
  }
}

}  // namespace bodyd::inference::detail
