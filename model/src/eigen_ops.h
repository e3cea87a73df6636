// Internal: the float building blocks the Eigen networks share (network.cpp, tcn.cpp): tensors to
// Eigen, SiLU and LayerNorm exactly as PyTorch computes them (docs/model-file.md).
#pragma once

#include "bodyd/inference/model_file.h"

#include <Eigen/Core>

#include <cmath>

namespace bodyd::inference::detail {

inline constexpr float kLayerNormEps = 1e-5f;

using RowMatrix = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

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

}  // namespace bodyd::inference::detail
