// Eigen forward pass of tcn-v1 (docs/model-file.md, "Network "tcn-v1""), whole windows and streamed.
//
// Layout as network.cpp: a batch of windows is C x (W * batch), one column per frame, window after
// window, so every per-frame layer is one matrix product over all frames; a causal convolution
// tap is one product over a window's frames shifted by the tap's offset.
#include "bodyd/inference/tcn.h"

#include "bodyd/base/require.h"
#include "eigen_ops.h"

#include <algorithm>
#include <atomic>
#include <set>
#include <string>

namespace bodyd::inference {

using namespace detail;  // eigen_ops.h

TcnConfig TcnConfig::from(const ModelConfig& c) {
  return TcnConfig{c.at("W"), c.at("D"), c.at("C"), c.at("K"), c.at("L"), c.at("R"), c.at("TE"), c.at("T")};
}

ModelConfig TcnConfig::to_model_config() const {
  return ModelConfig{{"W", W}, {"D", D}, {"C", C}, {"K", K}, {"L", L}, {"R", R}, {"TE", TE}, {"T", T}};
}

long TcnConfig::receptive_field() const {
  long sum = 0;
  for (int b = 0; b < L; ++b) sum += dilation(b);
  return 1 + static_cast<long>(K - 1) * sum;
}

TensorShapes Tcn::tensors(const ModelConfig& config) {
  using Shape = std::vector<std::int64_t>;
  const TcnConfig c = TcnConfig::from(config);
  TensorShapes v;
  const std::int64_t D = c.D, C = c.C, K = c.K, TE = c.TE;
  add_linear(v, "enc", 2 * D, C);
  add_linear(v, "time1", TE, C);
  add_linear(v, "time2", C, C);
  for (int b = 0; b < c.L; ++b) {
    const std::string p = "blocks." + std::to_string(b) + ".";
    add_layer_norm(v, p + "norm", C);
    v.emplace_back(p + "conv.weight", Shape{C, C, K});
    v.emplace_back(p + "conv.bias", Shape{C});
    add_linear(v, p + "fc", C, C);
  }
  add_layer_norm(v, "out_norm", C);
  add_linear(v, "dec1", C, C);
  add_linear(v, "dec2", C, D);
  return v;
}

namespace {
std::atomic<std::uint64_t> next_tcn_id{1};

// out += w * in. Eigen's matrix-matrix product packs w on every call, which costs more than the
// product itself for the few columns of forward_newest()'s upper blocks: there, one
// matrix-vector product per column (measured with bodyd-bench-net, "sample online").
constexpr Eigen::Index kMatrixVectorColumns = 8;
template <typename In, typename Out>
void mul_add(const detail::RowMatrix& w, const Eigen::MatrixBase<In>& in, Eigen::MatrixBase<Out>& out) {
  if (in.cols() <= kMatrixVectorColumns) {
    for (Eigen::Index j = 0; j < in.cols(); ++j) out.col(j).noalias() += w * in.col(j);
  } else {
    out.noalias() += w * in;
  }
}
}  // namespace

Tcn::Tcn(const Model& model) : EigenDenoiser(model), id_(next_tcn_id.fetch_add(1)) {
  const TcnConfig& c = config_;
  enc_ = detail::load_split_linear(model, "enc", c.D);
  for (int b = 0; b < c.L; ++b) {
    const std::string p = "blocks." + std::to_string(b) + ".";
    Block blk;
    blk.norm = load_layer_norm(model, p + "norm");
    // PyTorch's Conv1d weight [out, in, K]: tap k of output o and input i at (o * C + i) * K + k.
    const TensorF32& w = model.tensor(p + "conv.weight");
    blk.taps.assign(static_cast<std::size_t>(c.K), RowMatrix(c.C, c.C));
    for (int o = 0; o < c.C; ++o)
      for (int i = 0; i < c.C; ++i)
        for (int k = 0; k < c.K; ++k)
          blk.taps[static_cast<std::size_t>(k)](o, i) =
              w.data[(static_cast<std::size_t>(o) * static_cast<std::size_t>(c.C) + static_cast<std::size_t>(i)) *
                         static_cast<std::size_t>(c.K) +
                     static_cast<std::size_t>(k)];
    blk.conv_bias = detail::to_vector(model.tensor(p + "conv.bias"));
    blk.fc = load_linear(model, p + "fc");
    blk.dilation = c.dilation(b);
    blocks_.push_back(std::move(blk));
  }
  out_norm_ = load_layer_norm(model, "out_norm");
  dec1_ = load_linear(model, "dec1");
  dec2_ = load_linear(model, "dec2");

  // The time MLP depends on t alone: evaluated once per step here (in double, then rounded).
  time_table_ = detail::time_table(load_linear(model, "time1"), load_linear(model, "time2"), c.TE, c.T, nullptr);
  plan_newest();
  enc_mask_ones_ = enc_.v.rowwise().sum();
}

void Tcn::plan_newest() {
  const TcnConfig& c = config_;
  // Top down: the newest output needs the last block's output at frame W-1; a block's output at
  // frame f needs its input at f (the residual) and at f - (K-1-k) * dilation for each tap k that
  // stays in the window. levels[b]: the frames of block b's input, ascending; levels[L]: {W-1}.
  std::vector<std::vector<Eigen::Index>> levels(static_cast<std::size_t>(c.L) + 1);
  levels.back() = {static_cast<Eigen::Index>(c.W) - 1};
  for (int b = c.L - 1; b >= 0; --b) {
    std::set<Eigen::Index> in;
    for (Eigen::Index f : levels[static_cast<std::size_t>(b) + 1])
      for (int k = 0; k < c.K; ++k)
        if (const Eigen::Index g = f - static_cast<Eigen::Index>(c.K - 1 - k) * c.dilation(b); g >= 0) in.insert(g);
    levels[static_cast<std::size_t>(b)].assign(in.begin(), in.end());
  }
  newest_frames_ = levels.front();
  newest_blocks_.assign(static_cast<std::size_t>(c.L), {});
  for (int b = 0; b < c.L; ++b) {
    const auto& in = levels[static_cast<std::size_t>(b)];
    const auto& outs = levels[static_cast<std::size_t>(b) + 1];
    const auto column = [&in](Eigen::Index frame) -> Eigen::Index {
      const auto it = std::lower_bound(in.begin(), in.end(), frame);
      return it != in.end() && *it == frame ? static_cast<Eigen::Index>(it - in.begin()) : -1;
    };
    NewestBlock& nb = newest_blocks_[static_cast<std::size_t>(b)];
    nb.taps.assign(static_cast<std::size_t>(c.K), {});
    for (Eigen::Index f : outs) {
      nb.residual.push_back(column(f));
      for (int k = 0; k < c.K; ++k) {
        const Eigen::Index g = f - static_cast<Eigen::Index>(c.K - 1 - k) * c.dilation(b);
        nb.taps[static_cast<std::size_t>(k)].push_back(g >= 0 ? column(g) : -1);
      }
    }
  }
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

  for (const Block& blk : blocks_) {
    layer_norm(h, blk.norm.weight, blk.norm.bias, n);
    a.setZero();
    a.colwise() += blk.conv_bias;
    // Tap k reads frame w - offset (offset = (K-1-k) * dilation); frames before the window are 0.
    for (int k = 0; k < c.K; ++k) {
      const Eigen::Index offset = static_cast<Eigen::Index>(c.K - 1 - k) * blk.dilation;
      if (offset >= W) continue;
      const RowMatrix& tap = blk.taps[static_cast<std::size_t>(k)];
      for (Eigen::Index b = 0; b < batch; ++b)
        a.middleCols(b * W + offset, W - offset).noalias() += tap * n.middleCols(b * W, W - offset);
    }
    silu_inplace(a);
    h.noalias() += blk.fc.weight * a;
    h.colwise() += blk.fc.bias;
  }

  // y_w = dec2(SiLU(dec1(SiLU(LayerNorm_out(h_w))))).
  layer_norm(h, out_norm_.weight, out_norm_.bias, n);
  silu_inplace(n);
  detail::linear(dec1_, n, d);
  silu_inplace(d);
  detail::linear(dec2_, d, Y);
}

void Tcn::forward_newest(std::span<const float> x, std::span<const float> m, int t, std::span<float> out,
                         DenoiserScratch& scratch) const {
  auto* s = dynamic_cast<TcnScratch*>(&scratch);
  BODYD_REQUIRE(s != nullptr, kWrongScratch);
  forward_newest(x, m, t, out, *s);
}

void Tcn::forward_newest(std::span<const float> x, std::span<const float> m, int t, std::span<float> out,
                         TcnScratch& s) const {
  const TcnConfig& c = config_;
  BODYD_REQUIRE(s.config_.W == c.W && s.config_.D == c.D && s.config_.C == c.C, "TcnScratch was made for another network");
  const std::size_t window = static_cast<std::size_t>(c.W) * static_cast<std::size_t>(c.D);
  BODYD_REQUIRE(x.size() == window && m.size() == window, "forward_newest: x and m must hold one window of W * D floats");
  BODYD_REQUIRE(out.size() == static_cast<std::size_t>(c.D), "forward_newest: out must hold one frame of D floats");
  BODYD_REQUIRE(t >= 0 && t < c.T, "t must be in [0, T)");
  const auto overlaps = [&out](std::span<const float> v) {
    return out.data() < v.data() + v.size() && v.data() < out.data() + out.size();
  };
  BODYD_REQUIRE(!overlaps(x) && !overlaps(m), "out may not alias x or m");

  const Eigen::Map<const Eigen::MatrixXf> X(x.data(), c.D, c.W);
  const Eigen::Map<const Eigen::MatrixXf> M(m.data(), c.D, c.W);
  Eigen::Map<Eigen::VectorXf> Y(out.data(), c.D);

  // The encoder at the frames the newest output depends on. Its output before the step embedding
  // depends on a frame's x and m alone, so the past frames' columns are kept in the scratch and
  // reused while the next call's past frames are the same (the steps of one online sample: the
  // past is observed and only the newest frame changes). A fully observed frame's mask term is
  // the same every time (enc_mask_ones_), so only a partly observed frame multiplies its mask.
  const auto frames = static_cast<Eigen::Index>(newest_frames_.size());
  const Eigen::Index past = frames - 1;  // newest_frames_ ends with the newest frame, W - 1
  bool reuse = s.enc_owner_ == id_;
  for (Eigen::Index j = 0; reuse && j < past; ++j) {
    const Eigen::Index f = newest_frames_[static_cast<std::size_t>(j)];
    reuse = X.col(f) == s.xg_.col(j) && M.col(f) == s.mg_.col(j);
  }
  if (!reuse) {
    s.enc_owner_ = 0;
    for (Eigen::Index j = 0; j < past; ++j) {
      s.xg_.col(j) = X.col(newest_frames_[static_cast<std::size_t>(j)]);
      s.mg_.col(j) = M.col(newest_frames_[static_cast<std::size_t>(j)]);
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

  // Each block at its output frames only: h_ holds the block's input columns, h2_ its output.
  Eigen::Index in_cols = frames;
  for (std::size_t b = 0; b < blocks_.size(); ++b) {
    const Block& blk = blocks_[b];
    const NewestBlock& plan = newest_blocks_[b];
    const auto out_cols = static_cast<Eigen::Index>(plan.residual.size());
    auto n = s.n_.leftCols(in_cols);
    layer_norm(s.h_.leftCols(in_cols), blk.norm.weight, blk.norm.bias, n);
    auto a = s.a_.leftCols(out_cols);
    auto g = s.g_.leftCols(out_cols);
    a.setZero();
    a.colwise() += blk.conv_bias;
    for (int k = 0; k < c.K; ++k) {
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
    auto h2 = s.h2_.leftCols(out_cols);
    for (Eigen::Index j = 0; j < out_cols; ++j) h2.col(j) = s.h_.col(plan.residual[static_cast<std::size_t>(j)]);
    mul_add(blk.fc.weight, a, h2);
    h2.colwise() += blk.fc.bias;
    s.h_.leftCols(out_cols) = h2;
    in_cols = out_cols;
  }

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
  for (const Tcn::Block& blk : network_->blocks_) {
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

  for (std::size_t b = 0; b < net.blocks_.size(); ++b) {
    const Tcn::Block& blk = net.blocks_[b];
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
