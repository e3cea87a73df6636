// Eigen forward pass of mlpwin-v1 (docs/model-file.md, "Network").
//
// Layout: a batch of windows is viewed column-per-frame (D x W*batch, column-major), so every
// per-frame layer (enc, dec1, dec2) is one matrix product over all frames of all windows; the
// trunk layers are matrix-vector products (matrix-matrix for batch > 1). Weights are row-major
// (out x in, as stored), which suits Eigen's matrix-vector kernel. Every temporary lives in
// NetworkScratch; products are written with noalias() into those buffers so nothing allocates.
#include "bodyd/inference/network.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "bodyd/base/require.h"
#include "eigen_ops.h"

namespace bodyd::inference {

using detail::layer_norm;
using detail::RowMatrix;
using detail::silu_inplace;
using detail::to_matrix;
using detail::to_vector;

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

TensorShapes Network::tensors(const ModelConfig& config) {
  using Shape = std::vector<std::int64_t>;
  const MlpWinConfig c = MlpWinConfig::from(config);
  TensorShapes v;
  // In 64 bits: config values are at most 2^16, so products like W * E cannot overflow.
  const std::int64_t W = c.W, D = c.D, E = c.E, H = c.H, TE = c.TE;
  auto linear = [&](const std::string& name, std::int64_t in, std::int64_t out) {
    v.emplace_back(name + ".weight", Shape{out, in});
    v.emplace_back(name + ".bias", Shape{out});
  };
  auto norm = [&](const std::string& name, std::int64_t n) {
    v.emplace_back(name + ".weight", Shape{n});
    v.emplace_back(name + ".bias", Shape{n});
  };
  linear("enc", 2 * D, E);
  linear("inp", W * E, H);
  linear("time1", TE, H);
  linear("time2", H, H);
  for (int b = 0; b < c.L; ++b) {
    const std::string p = "blocks." + std::to_string(b) + ".";
    norm(p + "norm", H);
    linear(p + "fc1", H, H);
    linear(p + "fc2", H, H);
  }
  norm("out_norm", H);
  linear("out", H, W * E);
  linear("dec1", 2 * E, E);
  linear("dec2", E, D);
  return v;
}

std::shared_ptr<const Denoiser> Network::make(const Model& model) { return std::make_shared<const Network>(model); }

Network::Network(const Model& model)
    : config_(MlpWinConfig::from(model.config)), alpha_bar_(model.alpha_bar), norm_mean_(model.norm_mean), norm_std_(model.norm_std) {
  const MlpWinConfig& c = config_;
  const auto linear = [&](const std::string& name) {
    return Linear{to_matrix(model.tensor(name + ".weight")), to_vector(model.tensor(name + ".bias"))};
  };
  const auto norm = [&](const std::string& name) {
    return LayerNorm{to_vector(model.tensor(name + ".weight")), to_vector(model.tensor(name + ".bias"))};
  };
  const RowMatrix enc = to_matrix(model.tensor("enc.weight"));
  enc_x_ = enc.leftCols(c.D);
  enc_m_ = enc.rightCols(c.D);
  enc_b_ = to_vector(model.tensor("enc.bias"));
  inp_ = linear("inp");
  for (int b = 0; b < c.L; ++b) {
    const std::string p = "blocks." + std::to_string(b) + ".";
    blocks_.push_back(Block{norm(p + "norm"), linear(p + "fc1"), linear(p + "fc2")});
  }
  out_norm_ = norm("out_norm");
  out_ = linear("out");
  const RowMatrix dec1 = to_matrix(model.tensor("dec1.weight"));
  dec1_z_ = dec1.leftCols(c.E);
  dec1_e_ = dec1.rightCols(c.E);
  dec1_b_ = to_vector(model.tensor("dec1.bias"));
  dec2_ = linear("dec2");

  // The time MLP depends on t alone: evaluate it once per step here (in double, then rounded).
  const Linear time1 = linear("time1");
  const Linear time2 = linear("time2");
  time_table_.resize(c.H, c.T);
  std::vector<double> emb(static_cast<std::size_t>(c.TE));
  for (int t = 0; t < c.T; ++t) {
    timestep_embedding(t, emb);
    const Eigen::VectorXd s = Eigen::Map<const Eigen::VectorXd>(emb.data(), c.TE);
    Eigen::VectorXd a = time1.weight.cast<double>() * s + time1.bias.cast<double>();
    a.array() = a.array() / (1.0 + (-a.array()).exp());
    const Eigen::VectorXd temb = time2.weight.cast<double>() * a + time2.bias.cast<double>();
    time_table_.col(t) = (temb + inp_.bias.cast<double>()).cast<float>();
  }
}

NetworkScratch::NetworkScratch(const Network& network, int max_batch) : config_(network.config()), max_batch_(max_batch) {
  BODYD_REQUIRE(max_batch >= 1, "NetworkScratch needs max_batch >= 1");
  const MlpWinConfig& c = config_;
  e_.resize(c.E, c.W * max_batch);
  h_.resize(c.H, max_batch);
  n_.resize(c.H, max_batch);
  a_.resize(c.H, max_batch);
  z_.resize(c.W * c.E, max_batch);
  d_.resize(c.E, c.W * max_batch);
}

std::unique_ptr<DenoiserScratch> Network::make_scratch(int max_batch) const {
  return std::make_unique<NetworkScratch>(*this, max_batch);
}

void Network::forward(std::span<const float> x, std::span<const float> m, int t, std::span<float> out,
                      DenoiserScratch& scratch) const {
  auto* s = dynamic_cast<NetworkScratch*>(&scratch);
  BODYD_REQUIRE(s != nullptr, "Network::forward needs a NetworkScratch (made by Network::make_scratch)");
  forward(x, m, t, out, *s);
}

void Network::forward(std::span<const float> x, std::span<const float> m, int t, std::span<float> out,
                      NetworkScratch& s) const {
  const MlpWinConfig& c = config_;
  const std::size_t window = static_cast<std::size_t>(c.W) * static_cast<std::size_t>(c.D);
  BODYD_REQUIRE(s.config_.W == c.W && s.config_.D == c.D && s.config_.E == c.E && s.config_.H == c.H,
                    "NetworkScratch was made for another network");
  BODYD_REQUIRE(window > 0 && x.size() % window == 0, "x must hold whole windows of W * D floats");
  const auto batch = static_cast<Eigen::Index>(x.size() / window);
  BODYD_REQUIRE(batch >= 1 && batch <= s.max_batch_, "batch must be in [1, scratch.max_batch()]");
  BODYD_REQUIRE(m.size() == x.size() && out.size() == x.size(), "x, m and out must have the same size");
  BODYD_REQUIRE(t >= 0 && t < c.T, "t must be in [0, T)");
  BODYD_REQUIRE(out.data() != x.data() && out.data() != m.data(), "out may not alias x or m");

  const Eigen::Index frames = c.W * batch;
  const Eigen::Map<const Eigen::MatrixXf> X(x.data(), c.D, frames);
  const Eigen::Map<const Eigen::MatrixXf> M(m.data(), c.D, frames);
  Eigen::Map<Eigen::MatrixXf> Y(out.data(), c.D, frames);

  // Blocks of the scratch matrices sized for this batch (views, no allocation).
  auto e = s.e_.leftCols(frames);
  auto d = s.d_.leftCols(frames);

  // 1. e_w = SiLU(enc [x_w; m_w] + b), all frames at once.
  e.noalias() = enc_x_ * X;
  e.noalias() += enc_m_ * M;
  e.colwise() += enc_b_;
  silu_inplace(e);

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
  for (const Block& blk : blocks_) {
    layer_norm(h, blk.norm.weight, blk.norm.bias, n);
    for (Eigen::Index b = 0; b < batch; ++b) a.col(b).noalias() = blk.fc1.weight * n.col(b);
    a.colwise() += blk.fc1.bias;
    silu_inplace(a);
    for (Eigen::Index b = 0; b < batch; ++b) h.col(b).noalias() += blk.fc2.weight * a.col(b);
    h.colwise() += blk.fc2.bias;
  }

  // 5. z = out(SiLU(LayerNorm_out(h))).
  layer_norm(h, out_norm_.weight, out_norm_.bias, n);
  silu_inplace(n);
  auto z = s.z_.leftCols(batch);
  for (Eigen::Index b = 0; b < batch; ++b) z.col(b).noalias() = out_.weight * n.col(b);
  z.colwise() += out_.bias;

  // 6. y_w = dec2(SiLU(dec1 [z_w; e_w])); z viewed as E x (W * batch), frame-major like e.
  Eigen::Map<const Eigen::MatrixXf> Z(s.z_.data(), c.E, frames);
  d.noalias() = dec1_z_ * Z;
  d.noalias() += dec1_e_ * e;
  d.colwise() += dec1_b_;
  silu_inplace(d);
  Y.noalias() = dec2_.weight * d;
  Y.colwise() += dec2_.bias;
}

}  // namespace bodyd::inference
