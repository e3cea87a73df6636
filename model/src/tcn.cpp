// Eigen forward pass of tcn-v1 (docs/model-file.md, "Network "tcn-v1""), whole windows and streamed.
//
// Layout as mlpwin.cpp: a batch of windows is C x (W * batch), one column per frame, window after
// window, so every per-frame layer is one matrix product over all frames; a causal convolution
// tap is one product over a window's frames shifted by the tap's offset.
#include "bodyd/inference/tcn.h"

#include "bodyd/base/require.h"
#include "eigen_ops.h"

#include <atomic>
#include <string>

namespace bodyd::inference {

using namespace detail;  // eigen_ops.h

TcnConfig TcnConfig::from(const ModelConfig& c) {
  return TcnConfig{c.at("W"), c.at("D"), c.at("C"), c.at("K"), c.at("L"), c.at("R"), c.at("TE"), c.at("T")};
}

ModelConfig TcnConfig::to_model_config() const {
  return ModelConfig{{"W", W}, {"D", D}, {"C", C}, {"K", K}, {"L", L}, {"R", R}, {"TE", TE}, {"T", T}};
}

long TcnConfig::receptive_field() const { return CausalStack::receptive_field(K, L, R); }

TensorShapes Tcn::tensors(const ModelConfig& config) {
  const TcnConfig c = TcnConfig::from(config);
  TensorShapes v;
  const std::int64_t D = c.D, C = c.C, K = c.K, TE = c.TE;
  add_linear(v, "enc", 2 * D, C);
  add_linear(v, "time1", TE, C);
  add_linear(v, "time2", C, C);
  CausalStack::add_tensors(v, "blocks.", C, K, c.L);
  add_layer_norm(v, "out_norm", C);
  add_linear(v, "dec1", C, C);
  add_linear(v, "dec2", C, D);
  return v;
}

namespace {
std::atomic<std::uint64_t> next_tcn_id{1};

}  // namespace

Tcn::Tcn(const Model& model) : EigenDenoiser(model), id_(next_tcn_id.fetch_add(1)) {
  const TcnConfig& c = config_;
  enc_ = detail::load_split_linear(model, "enc", c.D);
  stack_ = CausalStack(model, "blocks.", c.W, c.C, c.K, c.L, c.R);
  out_norm_ = load_layer_norm(model, "out_norm");
  dec1_ = load_linear(model, "dec1");
  dec2_ = load_linear(model, "dec2");

  // The time MLP depends on t alone: evaluated once per step here (in double, then rounded).
  time_table_ = detail::time_table(load_linear(model, "time1"), load_linear(model, "time2"), c.TE, c.T, nullptr);
  enc_mask_ones_ = enc_.v.rowwise().sum();
}

TcnScratch::TcnScratch(const Tcn& network, int max_batch)
    : EigenScratch(network.config(), max_batch, "TcnScratch needs max_batch >= 1") {
  const Eigen::Index cols = static_cast<Eigen::Index>(config_.W) * max_batch;
  h_.resize(config_.C, cols);
  n_.resize(config_.C, cols);
  a_.resize(config_.C, cols);
  d_.resize(config_.C, cols);
  g_.resize(config_.C, config_.W);
  h2_.resize(config_.C, config_.W);
  xg_.resize(config_.D, config_.W);
  enc_past_.resize(config_.C, config_.W);
  mg_.resize(config_.D, config_.W);
}

void Tcn::forward(std::span<const float> x, std::span<const float> m, int t, std::span<float> out,
                  TcnScratch& s) const {
  const TcnConfig& c = config_;
  BODYD_REQUIRE(s.config_.W == c.W && s.config_.D == c.D && s.config_.C == c.C, "TcnScratch was made for another network");
  const Eigen::Index batch = detail::checked_batch(x, m, t, out, c.W, c.D, c.T, s.max_batch_);

  const Eigen::Index W = c.W;
  const Eigen::Index frames = W * batch;
  const Eigen::Map<const Eigen::MatrixXf> X(x.data(), c.D, frames);
  const Eigen::Map<const Eigen::MatrixXf> M(m.data(), c.D, frames);
  Eigen::Map<Eigen::MatrixXf> Y(out.data(), c.D, frames);
  auto h = s.h_.leftCols(frames);
  auto n = s.n_.leftCols(frames);
  auto a = s.a_.leftCols(frames);
  auto d = s.d_.leftCols(frames);

  // h_w = SiLU(enc [x_w; m_w] + b) + temb(t).
  detail::split_linear_silu(enc_, X, M, h);
  h.colwise() += time_table_.col(t);

  stack_.forward(h, n, a, batch);

  // y_w = dec2(SiLU(dec1(SiLU(LayerNorm_out(h_w))))).
  layer_norm(h, out_norm_.weight, out_norm_.bias, n);
  silu_inplace(n);
  detail::linear(dec1_, n, d);
  silu_inplace(d);
  detail::linear(dec2_, d, Y);
}

void Tcn::forward_newest(std::span<const float> x, std::span<const float> m, int t, std::span<float> out,
                         TcnScratch& s) const {
  const TcnConfig& c = config_;
  BODYD_REQUIRE(s.config_.W == c.W && s.config_.D == c.D && s.config_.C == c.C, "TcnScratch was made for another network");
  check_newest(x, m, t, out, c.W, c.D, c.T);

  const Eigen::Map<const Eigen::MatrixXf> X(x.data(), c.D, c.W);
  const Eigen::Map<const Eigen::MatrixXf> M(m.data(), c.D, c.W);
  Eigen::Map<Eigen::VectorXf> Y(out.data(), c.D);

  // The encoder at the frames the newest output depends on. Its output before the step embedding
  // depends on a frame's x and m alone, so the past frames' columns are kept in the scratch and
  // reused while the next call's past frames are the same (the steps of one online sample: the
  // past is observed and only the newest frame changes). A fully observed frame's mask term is
  // the same every time (enc_mask_ones_), so only a partly observed frame multiplies its mask.
  const auto frames = static_cast<Eigen::Index>(stack_.newest_frames().size());
  const Eigen::Index past = frames - 1;  // stack_.newest_frames() ends with the newest frame, W - 1
  bool reuse = s.enc_owner_ == id_;
  for (Eigen::Index j = 0; reuse && j < past; ++j) {
    const Eigen::Index f = stack_.newest_frames()[static_cast<std::size_t>(j)];
    reuse = X.col(f) == s.xg_.col(j) && M.col(f) == s.mg_.col(j);
  }
  if (!reuse) {
    s.enc_owner_ = 0;
    for (Eigen::Index j = 0; j < past; ++j) {
      s.xg_.col(j) = X.col(stack_.newest_frames()[static_cast<std::size_t>(j)]);
      s.mg_.col(j) = M.col(stack_.newest_frames()[static_cast<std::size_t>(j)]);
    }
    auto e = s.enc_past_.leftCols(past);
    e.noalias() = enc_.u * s.xg_.leftCols(past);
    for (Eigen::Index j = 0; j < past; ++j) {
      if ((s.mg_.col(j).array() == 1.0f).all())
        e.col(j) += enc_mask_ones_;
      else
        e.col(j).noalias() += enc_.v * s.mg_.col(j);
    }
    e.colwise() += enc_.bias;
    silu_inplace(e);
    s.enc_owner_ = id_;
  }
  {
    auto h = s.h_.leftCols(frames);
    h.leftCols(past) = s.enc_past_.leftCols(past);
    auto newest = h.col(past);
    newest.noalias() = enc_.u * X.col(c.W - 1);
    newest.noalias() += enc_.v * M.col(c.W - 1);
    newest += enc_.bias;
    silu_inplace(newest);
    h.colwise() += time_table_.col(t);
  }

  stack_.forward_newest(s.h_, s.n_, s.a_, s.g_, s.h2_);

  // The decoder at the newest frame (the one column left).
  auto h = s.h_.leftCols(1);
  auto n = s.n_.leftCols(1);
  auto d = s.d_.leftCols(1);
  layer_norm(h, out_norm_.weight, out_norm_.bias, n);
  silu_inplace(n);
  detail::linear(dec1_, n, d);
  silu_inplace(d);
  detail::linear(dec2_, d, Y);
}

std::unique_ptr<DenoiserStream> Tcn::make_stream(int t) const { return std::make_unique<TcnStream>(*this, t); }

TcnStream::TcnStream(const Tcn& network, int t) : network_(&network), t_(t) {
  const TcnConfig& c = network_->config();
  BODYD_REQUIRE(t >= 0 && t < c.T, "t must be in [0, T)");
  for (const CausalStack::Block& blk : network_->stack_.blocks()) {
    // The current frame and the (K-1) * dilation before it.
    past_.emplace_back(c.C, static_cast<Eigen::Index>(c.K - 1) * blk.dilation + 1);
  }
  h_.resize(c.C);
  n_.resize(c.C);
  a_.resize(c.C);
  d_.resize(c.C);
  reset();
}

void TcnStream::reset() {
  pushed_ = 0;
  for (auto& p : past_) p.setZero();
}

void TcnStream::push(std::span<const float> x, std::span<const float> m, std::span<float> out) {
  const Tcn& net = *network_;
  const TcnConfig& c = net.config();
  const auto D = static_cast<std::size_t>(c.D);
  BODYD_REQUIRE(x.size() == D && m.size() == D && out.size() == D, "x, m and out must hold one frame of D floats");
  const Eigen::Map<const Eigen::VectorXf> X(x.data(), c.D);
  const Eigen::Map<const Eigen::VectorXf> M(m.data(), c.D);
  Eigen::Map<Eigen::VectorXf> Y(out.data(), c.D);

  detail::split_linear_silu(net.enc_, X, M, h_);
  h_ += net.time_table_.col(t_);

  for (std::size_t b = 0; b < net.stack_.blocks().size(); ++b) {
    const CausalStack::Block& blk = net.stack_.blocks()[b];
    Eigen::MatrixXf& past = past_[b];
    const long size = past.cols();
    layer_norm(h_, blk.norm.weight, blk.norm.bias, n_);
    past.col(pushed_ % size) = n_;
    a_ = blk.conv_bias;
    for (int k = 0; k < c.K; ++k) {
      const long offset = static_cast<long>(c.K - 1 - k) * blk.dilation;
      if (offset > pushed_) continue;  // before the stream's first frame: zeros
      a_.noalias() += blk.taps[static_cast<std::size_t>(k)] * past.col((pushed_ - offset) % size);
    }
    silu_inplace(a_);
    h_.noalias() += blk.fc.weight * a_;
    h_ += blk.fc.bias;
  }
  ++pushed_;

  layer_norm(h_, net.out_norm_.weight, net.out_norm_.bias, n_);
  silu_inplace(n_);
  detail::linear(net.dec1_, n_, d_);
  silu_inplace(d_);
  detail::linear(net.dec2_, d_, Y);
}

}  // namespace bodyd::inference
