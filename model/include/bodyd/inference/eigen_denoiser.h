// What the Eigen denoisers (network.h's mlpwin-v1, tcn.h's tcn-v1) share: their layer types and a
// base that holds the config and the model's diffusion / normalisation data and answers the
// Denoiser accessors from them. The arithmetic they share lives in model/src/eigen_ops.h.
#pragma once

#include "bodyd/inference/denoiser.h"
#include "bodyd/inference/model_file.h"

#include <Eigen/Core>

#include <span>
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

// `Config` has the fields W (frames), D (features per frame), T (steps) and from(ModelConfig).
template <typename Config>
class EigenDenoiser : public Denoiser {
 public:
  [[nodiscard]] const Config& config() const { return config_; }
  [[nodiscard]] int frames() const override { return config_.W; }
  [[nodiscard]] int dim() const override { return config_.D; }
  [[nodiscard]] int steps() const override { return config_.T; }
  // diffusion.alpha_bar[t], t in [0, T).
  [[nodiscard]] std::span<const float> alpha_bar() const override { return alpha_bar_; }
  // Feature normalisation (D each): the network works on (f - mean) / std.
  [[nodiscard]] std::span<const float> norm_mean() const override { return norm_mean_; }
  [[nodiscard]] std::span<const float> norm_std() const override { return norm_std_; }

 protected:
  explicit EigenDenoiser(const Model& model)
      : config_(Config::from(model.config)),
        alpha_bar_(model.alpha_bar),
        norm_mean_(model.norm_mean),
        norm_std_(model.norm_std) {}

  Config config_;
  std::vector<float> alpha_bar_, norm_mean_, norm_std_;
};

}  // namespace bodyd::inference::detail
