// Eigen forward pass of tcnmlp-v1 (docs/model-file.md, "Network "tcnmlp-v1""): whole windows and
// the newest frame alone.
//
// Layout as mlpwin.cpp and tcn.cpp: a batch of windows is one column per frame, window after
// window. The context runs over every frame of a window, the trunk over its newest N.
#include "bodyd/inference/tcnmlp.h"

#include "bodyd/base/require.h"
#include "eigen_ops.h"

#include <fmt/format.h>

#include <atomic>
#include <string>

namespace bodyd::inference {

using namespace detail;  // eigen_ops.h

TcnMlpConfig TcnMlpConfig::from(const ModelConfig& c) {
  return TcnMlpConfig{c.at("W"), c.at("D"), c.at("N"), c.at("E"), c.at("H"),  c.at("L"),
                      c.at("C"), c.at("K"), c.at("B"), c.at("R"), c.at("TE"), c.at("T")};
}

ModelConfig TcnMlpConfig::to_model_config() const {
  return ModelConfig{{"W", W}, {"D", D}, {"N", N}, {"E", E}, {"H", H}, {"L", L},
                     {"C", C}, {"K", K}, {"B", B}, {"R", R}, {"TE", TE}, {"T", T}};
}

long TcnMlpConfig::receptive_field() const { return CausalStack::receptive_field(K, B, R); }

TensorShapes TcnMlp::tensors(const ModelConfig& config) {
  const TcnMlpConfig c = TcnMlpConfig::from(config);
  TensorShapes v;
  // In 64 bits: config values are at most 2^16, so products like N * E cannot overflow.
  const std::int64_t D = c.D, N = c.N, E = c.E, H = c.H, C = c.C, K = c.K, TE = c.TE;
  // PyTorch's registration order (model_net.py's TcnMlp): the context, then mlpwin-v1's trunk.
  add_linear(v, "cenc", 2 * D, C);
  CausalStack::add_tensors(v, "cblocks.", C, K, c.B);
  add_layer_norm(v, "cnorm", C);
  add_linear(v, "cdec1", C, C);
  add_linear(v, "cdec2", C, D);
  add_linear(v, "ctx", C, H);
  add_mlpwin_tensors(v, N, D, E, H, c.L, TE);
  return v;
}

namespace {
std::atomic<std::uint64_t> next_tcnmlp_id{1};

const TcnMlpConfig& checked(const TcnMlpConfig& c, const Model& model) {
  if (c.N > c.W)
    throw ModelFileError(fmt::format("model file '{}'", model.source),
                         fmt::format("tcnmlp-v1 config N = {} is more than W = {} (the trunk's frames are the window's "
                                     "newest)",
                                     c.N, c.W));
  return c;
}
}  // namespace

TcnMlp::TcnMlp(const Model& model, Weights weights)
    : EigenDenoiser(model), id_(next_tcnmlp_id.fetch_add(1)), weights_(weights) {
  const TcnMlpConfig& c = checked(config_, model);
  cenc_ = load_split_linear(model, "cenc", c.D);
  cenc_ones_ = (cenc_.v.cast<double>().rowwise().sum() + cenc_.bias.cast<double>()).cast<float>();
  cstack_ = CausalStack(model, "cblocks.", c.W, c.C, c.K, c.B, c.R);
  cnorm_ = load_layer_norm(model, "cnorm");
  cdec1_ = load_linear(model, "cdec1");
  cdec2_ = load_linear(model, "cdec2");
  const Linear ctx = load_linear(model, "ctx");
  ctx_ = ctx.weight;
  enc_ = load_split_linear(model, "enc", c.D);
  const Linear inp = load_linear(model, "inp");
  inp_ = inp.weight;
  trunk_ = load_mlp_trunk_layers(model, c.L, c.E);
  // The time MLP depends on t alone: evaluated once per step here, with inp.bias and ctx.bias folded in.
  const Eigen::VectorXf biases = inp.bias + ctx.bias;
  time_table_ = time_table(load_linear(model, "time1"), load_linear(model, "time2"), c.TE, c.T, &biases);
  if (weights_ == Weights::bf16) {
    const Eigen::Index past = static_cast<Eigen::Index>(c.N - 1) * c.E;
    if (past > 0) inp_past_bf16_ = detail::Bf16Matrix(inp_.leftCols(past));
    inp_newest_bf16_ = detail::Bf16Matrix(inp_.rightCols(c.E));
    for (const detail::ResidualBlock& b : trunk_.blocks)
      blocks_bf16_.push_back({detail::Bf16Matrix(b.fc1.weight), detail::Bf16Matrix(b.fc2.weight)});
  }
}

TcnMlpScratch::TcnMlpScratch(const TcnMlp& network, int max_batch)
    : EigenScratch(network.config(), max_batch, "TcnMlpScratch needs max_batch >= 1") {
  const TcnMlpConfig& c = config_;
  const Eigen::Index frames = static_cast<Eigen::Index>(c.W) * max_batch;
  xm_.resize(c.D, frames);
  mg_.resize(c.D, c.W);
  c_.resize(c.C, frames);
  cn_.resize(c.C, frames);
  ca_.resize(c.C, frames);
  cd_.resize(c.C, frames);
  e_.resize(c.E, static_cast<Eigen::Index>(c.N) * max_batch);
  d_.resize(c.E, static_cast<Eigen::Index>(c.N) * max_batch);
  h_.resize(c.H, max_batch);
  n_.resize(c.H, max_batch);
  a_.resize(c.H, max_batch);
  z_.resize(static_cast<Eigen::Index>(c.N) * c.E, max_batch);
  g_.resize(c.C, c.W);
  h2_.resize(c.C, c.W);
  past_x_.resize(c.D, c.W - 1);
  past_m_.resize(c.D, c.W);
  newest_xm_.resize(c.D);
  e_past_.resize(c.E, c.N - 1);
  h_past_.resize(c.H);
}

void TcnMlp::require_own_scratch(const TcnMlpScratch& s) const {
  const TcnMlpConfig& c = config_;
  BODYD_REQUIRE(s.config_.W == c.W && s.config_.D == c.D && s.config_.N == c.N && s.config_.E == c.E &&
                    s.config_.H == c.H && s.config_.C == c.C,
                "TcnMlpScratch was made for another network");
}

void TcnMlp::forward(std::span<const float> x, std::span<const float> m, int t, std::span<float> out,
                     TcnMlpScratch& s) const {
  const TcnMlpConfig& c = config_;
  require_own_scratch(s);
  const Eigen::Index batch = checked_batch(x, m, t, out, c.W, c.D, c.T, s.max_batch_);
  const Eigen::Index W = c.W, N = c.N, frames = W * batch;
  const Eigen::Map<const Eigen::MatrixXf> X(x.data(), c.D, frames);
  const Eigen::Map<const Eigen::MatrixXf> M(m.data(), c.D, frames);
  Eigen::Map<Eigen::MatrixXf> Y(out.data(), c.D, frames);

  // The context: SiLU(cenc [m_w * x_w; m_w]), the causal blocks, SiLU(LayerNorm).
  auto xm = s.xm_.leftCols(frames);
  xm = X.cwiseProduct(M);
  auto ctx = s.c_.leftCols(frames);
  auto cn = s.cn_.leftCols(frames);
  split_linear_silu(cenc_, xm, M, ctx);
  cstack_.forward(ctx, cn, s.ca_.leftCols(frames), batch);
  layer_norm(ctx, cnorm_.weight, cnorm_.bias, cn);
  silu_inplace(cn);

  // The W - N older frames: cdec2(SiLU(cdec1(context))).
  if (N < W) {
    for (Eigen::Index b = 0; b < batch; ++b) {
      auto d = s.cd_.leftCols(W - N);
      linear(cdec1_, cn.middleCols(b * W, W - N), d);
      silu_inplace(d);
      auto y = Y.middleCols(b * W, W - N);
      linear(cdec2_, d, y);
    }
  }

  // The trunk on the newest N frames: e_w = SiLU(enc [x_w; m_w]); h = inp concat(e_w) + ctx(context
  // at the newest frame) + temb(t) (+ both biases, in the table); residual blocks; out.
  auto h = s.h_.leftCols(batch);
  auto n = s.n_.leftCols(batch);
  auto a = s.a_.leftCols(batch);
  for (Eigen::Index b = 0; b < batch; ++b) {
    auto e = s.e_.middleCols(b * N, N);
    split_linear_silu(enc_, X.middleCols(b * W + W - N, N), M.middleCols(b * W + W - N, N), e);
  }
  const Eigen::Map<const Eigen::MatrixXf> e_cat(s.e_.data(), N * c.E, batch);
  for (Eigen::Index b = 0; b < batch; ++b) {
    h.col(b).noalias() = inp_ * e_cat.col(b);
    h.col(b).noalias() += ctx_ * cn.col(b * W + W - 1);
  }
  h.colwise() += time_table_.col(t);
  residual_blocks(trunk_.blocks, h, n, a);
  auto z = s.z_.leftCols(batch);
  trunk_out(trunk_.out_norm, trunk_.out, h, n, z);

  // y_w = dec2(SiLU(dec1 [z_w; e_w])) for the newest N frames.
  const Eigen::Map<const Eigen::MatrixXf> Z(s.z_.data(), c.E, N * batch);
  auto e = s.e_.leftCols(N * batch);
  auto d = s.d_.leftCols(N * batch);
  split_linear_silu(trunk_.dec1, Z, e, d);
  for (Eigen::Index b = 0; b < batch; ++b) {
    auto y = Y.middleCols(b * W + W - N, N);
    linear(trunk_.dec2, d.middleCols(b * N, N), y);
  }
}

void TcnMlp::forward_newest(std::span<const float> x, std::span<const float> m, int t, std::span<float> out,
                            TcnMlpScratch& s) const {
  const TcnMlpConfig& c = config_;
  require_own_scratch(s);
  check_newest(x, m, t, out, c.W, c.D, c.T);

  const Eigen::Index W = c.W, N = c.N, past = N - 1;
  const Eigen::Map<const Eigen::MatrixXf> X(x.data(), c.D, W);
  const Eigen::Map<const Eigen::MatrixXf> M(m.data(), c.D, W);
  Eigen::Map<Eigen::VectorXf> Y(out.data(), c.D);

  // What depends on the observations and the past frames only, reused while they are the last call's.
  const bool reuse = s.owner_ == id_ && X.leftCols(W - 1) == s.past_x_ && M == s.past_m_ &&
                     (X.col(W - 1).array() * M.col(W - 1).array() == s.newest_xm_.array()).all();
  if (!reuse) {
    s.owner_ = 0;
    s.past_x_ = X.leftCols(W - 1);
    s.past_m_ = M;
    s.newest_xm_ = X.col(W - 1).cwiseProduct(M.col(W - 1));
    // The context at the newest frame, from the frames it depends on.
    const auto& frames = cstack_.newest_frames();
    const auto nf = static_cast<Eigen::Index>(frames.size());
    for (Eigen::Index j = 0; j < nf; ++j) {
      const Eigen::Index f = frames[static_cast<std::size_t>(j)];
      s.xm_.col(j) = X.col(f).cwiseProduct(M.col(f));
      s.mg_.col(j) = M.col(f);
    }
    // Online, the past frames are observed whole (the emitted frames), so the mask's part of cenc
    // is the same vector for each of them: cenc_ones_ is added instead of multiplying the mask
    // (half the encoder's work); a frame with another mask (the newest) is multiplied as before.
    auto ctx = s.c_.leftCols(nf);
    ctx.noalias() = cenc_.u * s.xm_.leftCols(nf);
    for (Eigen::Index j = 0; j < nf; ++j) {
      if ((s.mg_.col(j).array() == 1.0f).all()) {
        ctx.col(j) += cenc_ones_;
      } else {
        ctx.col(j).noalias() += cenc_.v * s.mg_.col(j);
        ctx.col(j) += cenc_.bias;
      }
    }
    silu_inplace(ctx);
    cstack_.forward_newest(s.c_, s.cn_, s.ca_, s.g_, s.h2_);
    auto c0 = s.c_.col(0);
    auto cn0 = s.cn_.col(0);
    layer_norm(c0, cnorm_.weight, cnorm_.bias, cn0);
    silu_inplace(cn0);
    s.h_past_.noalias() = ctx_ * cn0;
    // The trunk's N - 1 earlier frames and their part of inp.
    if (past > 0) {
      split_linear_silu(enc_, X.middleCols(W - N, past), M.middleCols(W - N, past), s.e_past_);
      const Eigen::Map<const Eigen::VectorXf> e_cat(s.e_past_.data(), past * c.E);
      if (weights_ == Weights::bf16) {
        inp_past_bf16_.multiply(e_cat.data(), s.h_past_.data(), true);
      } else {
        s.h_past_.noalias() += inp_.leftCols(past * c.E) * e_cat;
      }
    }
    s.owner_ = id_;
  }

  auto e = s.e_.col(0);
  split_linear_silu(enc_, X.col(W - 1), M.col(W - 1), e);
  auto h = s.h_.col(0);
  auto n = s.n_.col(0);
  auto a = s.a_.col(0);
  h = s.h_past_ + time_table_.col(t);
  auto z = s.z_.col(0).head(c.E);
  auto d = s.d_.col(0);
  const TrunkBf16 bf16{inp_newest_bf16_, blocks_bf16_};
  trunk_newest(trunk_, inp_.rightCols(c.E), weights_ == Weights::bf16 ? &bf16 : nullptr, e, h, n, a, z, d, Y);
}

}  // namespace bodyd::inference
