// Eigen forward pass of mlpwin-v1 (docs/model-file.md, "Network "mlpwin-v1"").
//
// Layout: a batch of windows is viewed column-per-frame (D x W*batch, column-major), so every
// per-frame layer (enc, dec1, dec2) is one matrix product over all frames of all windows; the
// trunk layers are matrix-vector products (matrix-matrix for batch > 1). Weights are row-major
// (out x in, as stored), which suits Eigen's matrix-vector kernel. Every temporary lives in
// MlpWinScratch; products are written with noalias() into those buffers so nothing allocates.
#include "bodyd/inference/mlpwin.h"

#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "bodyd/base/require.h"
#include "eigen_ops.h"

namespace bodyd::inference {

using namespace detail;  // eigen_ops.h: the building blocks every line below uses

void timestep_embedding(int t, std::span<double> out) {
  const std::size_t half = out.size() / 2;
  for (std::size_t i = 0; i < half; ++i) {
    const double freq = std::exp(-std::log(10000.0) * static_cast<double>(i) / static_cast<double>(half));
    out[i] = std::sin(t * freq);
    out[half + i] = std::cos(t * freq);
  }
}

MlpWinConfig MlpWinConfig::from(const ModelConfig& c) {
  return MlpWinConfig{c.at("W"), c.at("D"), c.at("E"), c.at("H"), c.at("L"), c.at("TE"), c.at("T")};
}

ModelConfig MlpWinConfig::to_model_config() const {
  return ModelConfig{{"W", W}, {"D", D}, {"E", E}, {"H", H}, {"L", L}, {"TE", TE}, {"T", T}};
}

Eigen::MatrixXf detail::time_table(const Linear& time1, const Linear& time2, int TE, int T,
                                   const Eigen::VectorXf* added) {
  Eigen::MatrixXf table(time2.bias.size(), T);
  std::vector<double> emb(static_cast<std::size_t>(TE));
  // The weights in double once: a product with a cast operand is evaluated coefficient by
  // coefficient, which made this table a quarter of bodyd-eval's run time (one per clip).
  const Eigen::MatrixXd w1 = time1.weight.cast<double>(), w2 = time2.weight.cast<double>();
  const Eigen::VectorXd b1 = time1.bias.cast<double>(), b2 = time2.bias.cast<double>();
  for (int t = 0; t < T; ++t) {
    timestep_embedding(t, emb);
    const Eigen::VectorXd s = Eigen::Map<const Eigen::VectorXd>(emb.data(), TE);
    Eigen::VectorXd a = w1 * s + b1;
    a.array() = a.array() / (1.0 + (-a.array()).exp());
    const Eigen::VectorXd temb = w2 * a + b2;
    if (added != nullptr)
      table.col(t) = (temb + added->cast<double>()).cast<float>();
    else
      table.col(t) = temb.cast<float>();
  }
  return table;
}

TensorShapes MlpWin::tensors(const ModelConfig& config) {
  const MlpWinConfig c = MlpWinConfig::from(config);
  TensorShapes v;
  // In 64 bits: config values are at most 2^16, so products like W * E cannot overflow.
  const std::int64_t W = c.W, D = c.D, E = c.E, H = c.H, TE = c.TE;
  add_mlpwin_tensors(v, W, D, E, H, c.L, TE);
  return v;
}

namespace {
std::atomic<std::uint64_t> next_mlpwin_id{1};
}  // namespace

MlpWin::MlpWin(const Model& model, Weights weights)
    : EigenDenoiser(model), id_(next_mlpwin_id.fetch_add(1)), weights_(weights) {
  const MlpWinConfig& c = config_;
  enc_ = detail::load_split_linear(model, "enc", c.D);
  inp_ = load_linear(model, "inp");
  trunk_ = detail::load_mlp_trunk_layers(model, c.L, c.E);

  // The time MLP depends on t alone: evaluate it once per step here (in double, then rounded),
  // with inp.bias folded in.
  time_table_ = detail::time_table(load_linear(model, "time1"), load_linear(model, "time2"), c.TE, c.T, &inp_.bias);
  if (weights_ == Weights::bf16) {
    const Eigen::Index past = static_cast<Eigen::Index>(c.W - 1) * c.E;
    if (past > 0) inp_past_bf16_ = detail::Bf16Matrix(inp_.weight.leftCols(past));
    inp_newest_bf16_ = detail::Bf16Matrix(inp_.weight.rightCols(c.E));
    for (const detail::ResidualBlock& b : trunk_.blocks)
      blocks_bf16_.push_back({detail::Bf16Matrix(b.fc1.weight), detail::Bf16Matrix(b.fc2.weight)});
  }
}

MlpWinScratch::MlpWinScratch(const MlpWin& network, int max_batch)
    : EigenScratch(network.config(), max_batch, "MlpWinScratch needs max_batch >= 1") {
  const MlpWinConfig& c = config_;
  e_.resize(c.E, c.W * max_batch);
  h_.resize(c.H, max_batch);
  n_.resize(c.H, max_batch);
  a_.resize(c.H, max_batch);
  z_.resize(c.W * c.E, max_batch);
  d_.resize(c.E, c.W * max_batch);
  past_x_.resize(c.D, c.W - 1);
  past_m_.resize(c.D, c.W - 1);
  e_past_.resize(c.E, c.W - 1);
  h_past_.resize(c.H);
}

void MlpWin::require_own_scratch(const MlpWinScratch& s) const {
  const MlpWinConfig& c = config_;
  BODYD_REQUIRE(s.config_.W == c.W && s.config_.D == c.D && s.config_.E == c.E && s.config_.H == c.H,
                "MlpWinScratch was made for another network");
}

void MlpWin::forward(std::span<const float> x, std::span<const float> m, int t, std::span<float> out,
                     MlpWinScratch& s) const {
  const MlpWinConfig& c = config_;
  require_own_scratch(s);
  const Eigen::Index batch = detail::checked_batch(x, m, t, out, c.W, c.D, c.T, s.max_batch_);

  const Eigen::Index frames = c.W * batch;
  const Eigen::Map<const Eigen::MatrixXf> X(x.data(), c.D, frames);
  const Eigen::Map<const Eigen::MatrixXf> M(m.data(), c.D, frames);
  Eigen::Map<Eigen::MatrixXf> Y(out.data(), c.D, frames);

  // Blocks of the scratch matrices sized for this batch (views, no allocation).
  auto e = s.e_.leftCols(frames);
  auto d = s.d_.leftCols(frames);

  // 1. e_w = SiLU(enc [x_w; m_w] + b), all frames at once.
  detail::split_linear_silu(enc_, X, M, e);

  // 2-3. h = inp concat(e_w) + inp.bias + temb(t). A window's e columns are contiguous, so the
  // concatenation is a reshape: (E x W) column-major == (W * E) vector, frame-major.
  Eigen::Map<const Eigen::MatrixXf> e_cat(s.e_.data(), c.W * c.E, batch);
  auto h = s.h_.leftCols(batch);
  auto n = s.n_.leftCols(batch);
  auto a = s.a_.leftCols(batch);
  // The trunk runs one matrix-vector product per window: with batch <= 2 that streams each weight
  // matrix from cache twice, which measured faster than Eigen's matrix-matrix path (and that path
  // would need heap workspace for these sizes).
  for (Eigen::Index b = 0; b < batch; ++b) h.col(b).noalias() = inp_.weight * e_cat.col(b);
  h.colwise() += time_table_.col(t);

  // 4. Residual blocks: h += fc2(SiLU(fc1(LayerNorm(h)))).
  residual_blocks(trunk_.blocks, h, n, a);

  // 5. z = out(SiLU(LayerNorm_out(h))).
  auto z = s.z_.leftCols(batch);
  trunk_out(trunk_.out_norm, trunk_.out, h, n, z);

  // 6. y_w = dec2(SiLU(dec1 [z_w; e_w])); z viewed as E x (W * batch), frame-major like e.
  Eigen::Map<const Eigen::MatrixXf> Z(s.z_.data(), c.E, frames);
  detail::split_linear_silu(trunk_.dec1, Z, e, d);
  detail::linear(trunk_.dec2, d, Y);
}

void MlpWin::forward_newest(std::span<const float> x, std::span<const float> m, int t, std::span<float> out,
                            MlpWinScratch& s) const {
  const MlpWinConfig& c = config_;
  require_own_scratch(s);
  check_newest(x, m, t, out, c.W, c.D, c.T);

  const Eigen::Index W = c.W, past = W - 1;
  const Eigen::Map<const Eigen::MatrixXf> X(x.data(), c.D, W);
  const Eigen::Map<const Eigen::MatrixXf> M(m.data(), c.D, W);
  Eigen::Map<Eigen::VectorXf> Y(out.data(), c.D);

  // The past frames' part of the trunk's input, reused while they are the last call's.
  const bool reuse = s.owner_ == id_ && X.leftCols(past) == s.past_x_ && M.leftCols(past) == s.past_m_;
  if (!reuse) {
    s.owner_ = 0;
    s.past_x_ = X.leftCols(past);
    s.past_m_ = M.leftCols(past);
    if (past > 0) {
      split_linear_silu(enc_, X.leftCols(past), M.leftCols(past), s.e_past_);
      const Eigen::Map<const Eigen::VectorXf> e_cat(s.e_past_.data(), past * c.E);
      if (weights_ == Weights::bf16) {
        inp_past_bf16_.multiply(e_cat.data(), s.h_past_.data(), false);
      } else {
        s.h_past_.noalias() = inp_.weight.leftCols(past * c.E) * e_cat;
      }
    } else {
      s.h_past_.setZero();
    }
    s.owner_ = id_;
  }

  // The newest frame: e = SiLU(enc [x; m]); h = inp's part of it + the past's + temb(t) + inp.bias.
  auto e = s.e_.col(0);
  split_linear_silu(enc_, X.col(W - 1), M.col(W - 1), e);
  auto h = s.h_.col(0);
  auto n = s.n_.col(0);
  auto a = s.a_.col(0);
  h = s.h_past_ + time_table_.col(t);
  auto z = s.z_.col(0).head(c.E);
  auto d = s.d_.col(0);
  const TrunkBf16 bf16{inp_newest_bf16_, blocks_bf16_};
  trunk_newest(trunk_, inp_.weight.rightCols(c.E), weights_ == Weights::bf16 ? &bf16 : nullptr, e, h, n, a, z, d, Y);
}

}  // namespace bodyd::inference
