// What the Eigen denoisers (mlpwin.h's mlpwin-v1, tcn.h's tcn-v1) share: their layer types and a
// base that holds the config and the model's diffusion / normalisation data, answers the
// Denoiser accessors from them and makes the network's scratch. The arithmetic they share lives
// in model/src/eigen_ops.h.
#pragma once

#include "bodyd/base/require.h"
#include "bodyd/inference/denoiser.h"
#include "bodyd/inference/model_file.h"

#include <Eigen/Core>

#include <memory>
#include <span>
#include <type_traits>
#include <vector>

namespace bodyd::inference::detail {

using RowMatrix = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// A PyTorch Linear: y = weight x + bias.
struct Linear {
  RowMatrix weight;      // out x in, as in PyTorch
  Eigen::VectorXf bias;  // out
};

struct LayerNorm {
  Eigen::VectorXf weight, bias;
};

// A Linear over the concatenation [u; v], its weight split into the columns that multiply u and
// those that multiply v, so the concatenation never has to be built (the encoders' [x_w; m_w]).
struct SplitLinear {
  RowMatrix u, v;
  Eigen::VectorXf bias;
};

// mlpwin-v1's residual block (and tcnmlp-v1's trunk): h + fc2(SiLU(fc1(LayerNorm(h)))).
struct ResidualBlock {
  LayerNorm norm;
  Linear fc1, fc2;
};

// The MLP trunk after its input and time embedding, mlpwin-v1's and tcnmlp-v1's alike: the
// residual blocks (blocks.*), out_norm and out, and the per-frame decoder dec1 (its weight's
// columns for z_w and for e_w) and dec2.
struct MlpTrunkLayers {
  std::vector<ResidualBlock> blocks;
  LayerNorm out_norm;
  Linear out;
  SplitLinear dec1;
  Linear dec2;
};

// The per-session buffers' base: the config they were sized for and the most windows per call.
template <typename Config>
class EigenScratch : public DenoiserScratch {
 public:
  [[nodiscard]] int max_batch() const override { return max_batch_; }

 protected:
  // `what`: the message when max_batch < 1 (a bug: abort).
  EigenScratch(const Config& config, int max_batch, const char* what) : config_(config), max_batch_(max_batch) {
    BODYD_REQUIRE(max_batch >= 1, what);
  }

  Config config_;
  int max_batch_;
};

// `Config` has the fields W (frames), D (features per frame), T (steps) and from(ModelConfig);
// `Net` derives from EigenDenoiser<Config, Net, Scratch>, has Net(const Model&), forward(..., Scratch&)
// (and, where it has a newest-frame pass, forward_newest(..., Scratch&))
// and kWrongScratch (the message when forward() is given another scratch); `Scratch` has
// Scratch(const Net&, int max_batch).
template <typename Config, typename Net, typename Scratch>
class EigenDenoiser : public Denoiser {
 public:
  // The architecture row's factory (denoiser.h). A network with a bf16 path takes `weights` in its
  // constructor; the others run float32 and ignore it.
  [[nodiscard]] static std::shared_ptr<const Denoiser> make(const Model& model, Weights weights) {
    if constexpr (std::is_constructible_v<Net, const Model&, Weights>) {
      return std::make_shared<const Net>(model, weights);
    } else {
      (void)weights;
      return std::make_shared<const Net>(model);
    }
  }

  [[nodiscard]] const Config& config() const { return config_; }
  [[nodiscard]] int frames() const override { return config_.W; }
  [[nodiscard]] int dim() const override { return config_.D; }
  [[nodiscard]] int steps() const override { return config_.T; }
  // diffusion.alpha_bar[t], t in [0, T).
  [[nodiscard]] std::span<const float> alpha_bar() const override { return alpha_bar_; }
  // Feature normalisation (D each): the network works on (f - mean) / std.
  [[nodiscard]] std::span<const float> norm_mean() const override { return norm_mean_; }
  [[nodiscard]] std::span<const float> norm_std() const override { return norm_std_; }
  [[nodiscard]] std::unique_ptr<DenoiserScratch> make_scratch(int max_batch) const override {
    return std::make_unique<Scratch>(static_cast<const Net&>(*this), max_batch);
  }
  // The Denoiser entry point: `scratch` must be a Scratch (a bug otherwise: abort).
  void forward(std::span<const float> x, std::span<const float> m, int t, std::span<float> out,
               DenoiserScratch& scratch) const override {
    static_cast<const Net&>(*this).forward(x, m, t, out, own_scratch(scratch));
  }
  // A Net with forward_newest(..., Scratch&) has the newest-frame pass (Denoiser::forward_newest);
  // this entry point takes its Scratch as forward() does.
  [[nodiscard]] bool computes_newest_alone() const override { return has_newest(); }
  void forward_newest(std::span<const float> x, std::span<const float> m, int t, std::span<float> out,
                      DenoiserScratch& scratch) const override {
    if constexpr (has_newest()) {
      static_cast<const Net&>(*this).forward_newest(x, m, t, out, own_scratch(scratch));
    } else {
      Denoiser::forward_newest(x, m, t, out, scratch);
    }
  }

 protected:
  // `scratch` as this network's Scratch (a bug otherwise: abort).
  static Scratch& own_scratch(DenoiserScratch& scratch) {
    auto* s = dynamic_cast<Scratch*>(&scratch);
    BODYD_REQUIRE(s != nullptr, Net::kWrongScratch);
    return *s;
  }
  explicit EigenDenoiser(const Model& model)
      : config_(Config::from(model.config)),
        alpha_bar_(model.alpha_bar),
        norm_mean_(model.norm_mean),
        norm_std_(model.norm_std) {}

  Config config_;
  std::vector<float> alpha_bar_, norm_mean_, norm_std_;

 private:
  // A function, not a constant: evaluated where it is used, when Net is complete.
  static constexpr bool has_newest() {
    // Net's own overload for its Scratch (the DenoiserScratch one below would take a Scratch too).
    using Newest = void (Net::*)(std::span<const float>, std::span<const float>, int, std::span<float>, Scratch&) const;
    return requires { static_cast<Newest>(&Net::forward_newest); };
  }
};

}  // namespace bodyd::inference::detail
