// Internal: the float building blocks the Eigen networks share (mlpwin.cpp, tcn.cpp): tensors to
// Eigen, their layers' tensor lists and loading, SiLU and LayerNorm exactly as PyTorch computes
// them (docs/model-file.md), the input encoder and linear layers, the step-embedding table and the
// checks of forward(). Each network calls these in its own order; the arithmetic is theirs.
#pragma once

#include "bodyd/base/require.h"
#include "bodyd/inference/bf16_matrix.h"
#include "bodyd/inference/eigen_denoiser.h"
#include "bodyd/inference/model_file.h"

#include <Eigen/Core>

#include <array>
#include <cmath>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

namespace bodyd::inference::detail {

inline constexpr float kLayerNormEps = 1e-5f;

inline RowMatrix to_matrix(const TensorF32& t) {
  const auto rows = static_cast<Eigen::Index>(t.shape.at(0));
  const auto cols = static_cast<Eigen::Index>(t.shape.at(1));
  return Eigen::Map<const RowMatrix>(t.data.data(), rows, cols);
}

inline Eigen::VectorXf to_vector(const TensorF32& t) {
  return Eigen::Map<const Eigen::VectorXf>(t.data.data(), static_cast<Eigen::Index>(t.data.size()));
}

template <typename Derived>
void silu_inplace(Eigen::MatrixBase<Derived>& a) {
  a.array() = a.array() / (1.0f + (-a.array()).exp());
}

// out.col(c) = LayerNorm(in.col(c)) for each column (biased variance, eps inside the sqrt, as PyTorch).
template <typename In, typename Out>
void layer_norm(const Eigen::MatrixBase<In>& in, const Eigen::VectorXf& gamma, const Eigen::VectorXf& beta,
                Eigen::MatrixBase<Out>& out) {
  const float inv_n = 1.0f / static_cast<float>(in.rows());
  for (Eigen::Index c = 0; c < in.cols(); ++c) {
    const float mean = in.col(c).sum() * inv_n;
    const float var = (in.col(c).array() - mean).square().sum() * inv_n;
    const float rstd = 1.0f / std::sqrt(var + kLayerNormEps);
    out.col(c).array() = (in.col(c).array() - mean) * rstd * gamma.array() + beta.array();
  }
}

// Tensor lists (Architecture::tensors): a Linear's weight [out, in] and bias [out]; a LayerNorm's
// weight and bias [n].
inline void add_linear(TensorShapes& v, const std::string& name, std::int64_t in, std::int64_t out) {
  v.emplace_back(name + ".weight", std::vector<std::int64_t>{out, in});
  v.emplace_back(name + ".bias", std::vector<std::int64_t>{out});
}
inline void add_layer_norm(TensorShapes& v, const std::string& name, std::int64_t n) {
  v.emplace_back(name + ".weight", std::vector<std::int64_t>{n});
  v.emplace_back(name + ".bias", std::vector<std::int64_t>{n});
}

inline Linear load_linear(const Model& model, const std::string& name) {
  return Linear{to_matrix(model.tensor(name + ".weight")), to_vector(model.tensor(name + ".bias"))};
}
inline LayerNorm load_layer_norm(const Model& model, const std::string& name) {
  return LayerNorm{to_vector(model.tensor(name + ".weight")), to_vector(model.tensor(name + ".bias"))};
}
// A Linear over [u; v], u of `u_size` rows.
inline SplitLinear load_split_linear(const Model& model, const std::string& name, Eigen::Index u_size) {
  const RowMatrix w = to_matrix(model.tensor(name + ".weight"));
  return SplitLinear{w.leftCols(u_size), w.rightCols(w.cols() - u_size), to_vector(model.tensor(name + ".bias"))};
}

// blocks.<b>.{norm,fc1,fc2} for b < L, H wide: their tensors and their loading.
inline void add_residual_blocks(TensorShapes& v, std::int64_t H, int L) {
  for (int b = 0; b < L; ++b) {
    const std::string p = "blocks." + std::to_string(b) + ".";
    add_layer_norm(v, p + "norm", H);
    add_linear(v, p + "fc1", H, H);
    add_linear(v, p + "fc2", H, H);
  }
}
inline std::vector<ResidualBlock> load_residual_blocks(const Model& model, int L) {
  std::vector<ResidualBlock> blocks;
  for (int b = 0; b < L; ++b) {
    const std::string p = "blocks." + std::to_string(b) + ".";
    blocks.push_back(
        ResidualBlock{load_layer_norm(model, p + "norm"), load_linear(model, p + "fc1"), load_linear(model, p + "fc2")});
  }
  return blocks;
}
// The trunk's blocks, out_norm, out, dec1 (split after E rows) and dec2.
inline MlpTrunkLayers load_mlp_trunk_layers(const Model& model, int L, Eigen::Index E) {
  return MlpTrunkLayers{load_residual_blocks(model, L), load_layer_norm(model, "out_norm"), load_linear(model, "out"),
                        load_split_linear(model, "dec1", E), load_linear(model, "dec2")};
}

// h += fc2(SiLU(fc1(LayerNorm(h)))) for each block, on h's columns (one per window); n and a are
// buffers of h's size. `product(b, layer, x, y, accumulate)` computes y = W x (or y += W x) with
// block b's fc1 (layer 0) or fc2 (layer 1) weights, so a caller can multiply by other copies of
// them (tcnmlp-v1's bfloat16 ones, bf16_matrix.h); the biases come from `blocks`.
template <typename H, typename N, typename A, typename Product>
void residual_blocks_by(const std::vector<ResidualBlock>& blocks, Eigen::MatrixBase<H>& h, Eigen::MatrixBase<N>& n,
                        Eigen::MatrixBase<A>& a, const Product& product) {
  for (std::size_t b = 0; b < blocks.size(); ++b) {
    const ResidualBlock& blk = blocks[b];
    layer_norm(h, blk.norm.weight, blk.norm.bias, n);
    product(b, 0, n.derived(), a.derived(), false);
    a.colwise() += blk.fc1.bias;
    silu_inplace(a);
    product(b, 1, a.derived(), h.derived(), true);
    h.colwise() += blk.fc2.bias;
  }
}

// residual_blocks_by with the float32 weights. One matrix-vector product per column: with batch
// <= 2 that streams each weight matrix from cache twice, which measured faster than Eigen's
// matrix-matrix path (and that path would need heap workspace for these sizes).
template <typename H, typename N, typename A>
void residual_blocks(const std::vector<ResidualBlock>& blocks, Eigen::MatrixBase<H>& h, Eigen::MatrixBase<N>& n,
                     Eigen::MatrixBase<A>& a) {
  residual_blocks_by(blocks, h, n, a, [&blocks](std::size_t b, int layer, const auto& x, auto& y, bool accumulate) {
    const auto& w = layer == 0 ? blocks[b].fc1.weight : blocks[b].fc2.weight;
    for (Eigen::Index c = 0; c < x.cols(); ++c) {
      if (accumulate) {
        y.col(c).noalias() += w * x.col(c);
      } else {
        y.col(c).noalias() = w * x.col(c);
      }
    }
  });
}

// The trunk's tail on h's columns (one per window), after its residual blocks:
// z = out(SiLU(LayerNorm_out(h))), one matrix-vector product per column as residual_blocks; n is a
// buffer of h's size.
template <typename H, typename N, typename Z>
void trunk_out(const LayerNorm& norm, const Linear& out, const Eigen::MatrixBase<H>& h, Eigen::MatrixBase<N>& n,
               Eigen::MatrixBase<Z>& z) {
  layer_norm(h, norm.weight, norm.bias, n);
  silu_inplace(n);
  for (Eigen::Index c = 0; c < h.cols(); ++c) z.col(c).noalias() = out.weight * n.col(c);
  z.colwise() += out.bias;
}

// The bfloat16 copies of the trunk's weights that the newest-frame pass multiplies by
// (bf16_matrix.h): inp's columns of the newest frame and each residual block's fc1 and fc2.
struct TrunkBf16 {
  const Bf16Matrix& inp_newest;
  const std::vector<std::array<Bf16Matrix, 2>>& blocks;
};

// The trunk on the newest frame alone, after its past (the forward_newest of mlpwin-v1 and
// tcnmlp-v1). On entry h holds the past's part of inp, the step's embedding and inp's bias; this
// adds inp's newest columns times e (the newest frame's encoding), runs the residual blocks, then
// computes only the newest frame's rows of out and that frame's decoder, into y. The products use
// `bf16`'s copies when given, else the float32 weights (`inp_newest`: inp's last E columns).
// e, h, n, a, d: one contiguous column each; z: E floats.
template <typename InpNewest, typename Ev, typename Hv, typename Nv, typename Av, typename Zv, typename Dv,
          typename Yv>
void trunk_newest(const MlpTrunkLayers& trunk, const Eigen::MatrixBase<InpNewest>& inp_newest, const TrunkBf16* bf16,
                  Eigen::MatrixBase<Ev>& e, Eigen::MatrixBase<Hv>& h, Eigen::MatrixBase<Nv>& n,
                  Eigen::MatrixBase<Av>& a, Eigen::MatrixBase<Zv>& z, Eigen::MatrixBase<Dv>& d,
                  Eigen::MatrixBase<Yv>& y) {
  if (bf16 != nullptr) {
    bf16->inp_newest.multiply(e.derived().data(), h.derived().data(), true);
    residual_blocks_by(trunk.blocks, h, n, a, [bf16](std::size_t b, int layer, const auto& v, auto& out, bool accumulate) {
      bf16->blocks[b][static_cast<std::size_t>(layer)].multiply(v.data(), out.data(), accumulate);
    });
  } else {
    h.noalias() += inp_newest * e;
    residual_blocks(trunk.blocks, h, n, a);
  }
  layer_norm(h, trunk.out_norm.weight, trunk.out_norm.bias, n);
  silu_inplace(n);
  const Eigen::Index E = z.size();
  z.noalias() = trunk.out.weight.bottomRows(E) * n;
  z += trunk.out.bias.tail(E);
  split_linear_silu(trunk.dec1, z, e, d);
  linear(trunk.dec2, d, y);
}

// mlpwin-v1's tensors over a window of W frames (tcnmlp-v1's trunk: W = N), in PyTorch's order.
inline void add_mlpwin_tensors(TensorShapes& v, std::int64_t W, std::int64_t D, std::int64_t E, std::int64_t H, int L,
                               std::int64_t TE) {
  add_linear(v, "enc", 2 * D, E);
  add_linear(v, "inp", W * E, H);
  add_linear(v, "time1", TE, H);
  add_linear(v, "time2", H, H);
  add_residual_blocks(v, H, L);
  add_layer_norm(v, "out_norm", H);
  add_linear(v, "out", H, W * E);
  add_linear(v, "dec1", 2 * E, E);
  add_linear(v, "dec2", E, D);
}

// The requirements of forward_newest() (a bug if broken: abort with a message): x and m one window
// of W * D floats, out one frame of D floats not aliasing them, 0 <= t < T.
inline void check_newest(std::span<const float> x, std::span<const float> m, int t, std::span<float> out, int W, int D,
                         int T) {
  const std::size_t window = static_cast<std::size_t>(W) * static_cast<std::size_t>(D);
  BODYD_REQUIRE(x.size() == window && m.size() == window, "forward_newest: x and m must hold one window of W * D floats");
  BODYD_REQUIRE(out.size() == static_cast<std::size_t>(D), "forward_newest: out must hold one frame of D floats");
  BODYD_REQUIRE(t >= 0 && t < T, "t must be in [0, T)");
  const auto overlaps = [&out](std::span<const float> v) {
    return out.data() < v.data() + v.size() && v.data() < out.data() + out.size();
  };
  BODYD_REQUIRE(!overlaps(x) && !overlaps(m), "out may not alias x or m");
}

// out = layer.weight * in + layer.bias, column by column.
template <typename In, typename Out>
void linear(const Linear& layer, const Eigen::MatrixBase<In>& in, Eigen::MatrixBase<Out>& out) {
  out.noalias() = layer.weight * in;
  out.colwise() += layer.bias;
}

// out = SiLU(layer [u; v] + bias), column by column (the encoders: u = x, v = m).
template <typename U, typename V, typename Out>
void split_linear_silu(const SplitLinear& layer, const Eigen::MatrixBase<U>& u, const Eigen::MatrixBase<V>& v,
                       Eigen::MatrixBase<Out>& out) {
  out.noalias() = layer.u * u;
  out.noalias() += layer.v * v;
  out.colwise() += layer.bias;
  silu_inplace(out);
}

// Column t (t in [0, T)): time2(SiLU(time1(sinusoid_TE(t)))), plus `added` when given, evaluated in
// double and then rounded to float (mlpwin.cpp).
[[nodiscard]] Eigen::MatrixXf time_table(const Linear& time1, const Linear& time2, int TE, int T,
                                         const Eigen::VectorXf* added);

// The requirements of every forward() (a bug if broken: abort with a message) on windows of W * D
// floats at a step in [0, T), for a scratch of `max_batch`; returns the batch.
inline Eigen::Index checked_batch(std::span<const float> x, std::span<const float> m, int t, std::span<float> out,
                                  int W, int D, int T, int max_batch) {
  const std::size_t window = static_cast<std::size_t>(W) * static_cast<std::size_t>(D);
  BODYD_REQUIRE(window > 0 && x.size() % window == 0, "x must hold whole windows of W * D floats");
  const auto batch = static_cast<Eigen::Index>(x.size() / window);
  BODYD_REQUIRE(batch >= 1 && batch <= max_batch, "batch must be in [1, scratch.max_batch()]");
  BODYD_REQUIRE(m.size() == x.size() && out.size() == x.size(), "x, m and out must have the same size");
  BODYD_REQUIRE(t >= 0 && t < T, "t must be in [0, T)");
  BODYD_REQUIRE(out.data() != x.data() && out.data() != m.data(), "out may not alias x or m");
  return batch;
}

}  // namespace bodyd::inference::detail
