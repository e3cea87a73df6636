// bfloat16 matrix-vector products (bf16_matrix.h).
#include "bodyd/inference/bf16_matrix.h"

#include "bodyd/base/require.h"

#include <algorithm>
#include <bit>
#include <cmath>

#if defined(__AVX2__) && defined(__FMA__)
#include <immintrin.h>
#define BODYD_BF16_AVX2 1
#endif

namespace bodyd::inference::detail {

std::uint16_t to_bf16(float value) {
  const auto bits = std::bit_cast<std::uint32_t>(value);
  // Round to nearest, ties to even: add 0x7fff plus the lowest kept bit, then drop 16 bits.
  const std::uint32_t rounded = bits + 0x7fffu + ((bits >> 16) & 1u);
  const auto out = static_cast<std::uint16_t>(rounded >> 16);
  // Rounding up past the largest finite value gives infinity: keep the truncated value instead.
  if ((out & 0x7f80u) == 0x7f80u && std::isfinite(value)) return static_cast<std::uint16_t>(bits >> 16);
  return out;
}

float from_bf16(std::uint16_t value) { return std::bit_cast<float>(static_cast<std::uint32_t>(value) << 16); }

Eigen::Index Bf16Matrix::slot(Eigen::Index r) {
  const Eigen::Index half = r & 16, q = r & 15;
  // 0..3 -> 0..3, 4..7 -> 8..11, 8..11 -> 4..7, 12..15 -> 12..15 (within each 16).
  const Eigen::Index s = (q >= 4 && q < 8) ? q + 4 : (q >= 8 && q < 12) ? q - 4 : q;
  return half + s;
}

Bf16Matrix::Bf16Matrix(
    const Eigen::Ref<const Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>& weights)
    : rows_(weights.rows()), cols_(weights.cols()) {
  const Eigen::Index panels = (rows_ + kPanel - 1) / kPanel;
  panels_.assign(static_cast<std::size_t>(panels * cols_ * kPanel), std::uint16_t{0});
  for (Eigen::Index r = 0; r < rows_; ++r) {
    const Eigen::Index p = r / kPanel, s = slot(r % kPanel);
    for (Eigen::Index c = 0; c < cols_; ++c)
      panels_[static_cast<std::size_t>((p * cols_ + c) * kPanel + s)] = to_bf16(weights(r, c));
  }
}

float Bf16Matrix::at(Eigen::Index row, Eigen::Index col) const {
  BODYD_REQUIRE(row >= 0 && row < rows_ && col >= 0 && col < cols_, "Bf16Matrix::at: index out of range");
  const Eigen::Index p = row / kPanel, s = slot(row % kPanel);
  return from_bf16(panels_[static_cast<std::size_t>((p * cols_ + col) * kPanel + s)]);
}

void Bf16Matrix::multiply(const float* x, float* y, bool accumulate) const {
  const Eigen::Index panels = (rows_ + kPanel - 1) / kPanel;
  for (Eigen::Index p = 0; p < panels; ++p) {
    const std::uint16_t* w = panels_.data() + p * cols_ * kPanel;
    alignas(32) float acc[kPanel];
#ifdef BODYD_BF16_AVX2
    __m256 a0 = _mm256_setzero_ps(), a1 = a0, a2 = a0, a3 = a0;
    const __m256i zero = _mm256_setzero_si256();
    for (Eigen::Index c = 0; c < cols_; ++c, w += kPanel) {
      const __m256 xc = _mm256_broadcast_ss(x + c);
      const __m256i lo = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(w));
      const __m256i hi = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(w + 16));
      // A bfloat16 widened to float is its 16 bits above 16 zero bits.
      a0 = _mm256_fmadd_ps(_mm256_castsi256_ps(_mm256_unpacklo_epi16(zero, lo)), xc, a0);
      a1 = _mm256_fmadd_ps(_mm256_castsi256_ps(_mm256_unpackhi_epi16(zero, lo)), xc, a1);
      a2 = _mm256_fmadd_ps(_mm256_castsi256_ps(_mm256_unpacklo_epi16(zero, hi)), xc, a2);
      a3 = _mm256_fmadd_ps(_mm256_castsi256_ps(_mm256_unpackhi_epi16(zero, hi)), xc, a3);
    }
    _mm256_store_ps(acc, a0);
    _mm256_store_ps(acc + 8, a1);
    _mm256_store_ps(acc + 16, a2);
    _mm256_store_ps(acc + 24, a3);
#else
    for (float& a : acc) a = 0.0f;
    for (Eigen::Index c = 0; c < cols_; ++c, w += kPanel)
      for (Eigen::Index r = 0; r < kPanel; ++r) acc[r] += from_bf16(w[slot(r)]) * x[c];
#endif
    const Eigen::Index first = p * kPanel, n = std::min(kPanel, rows_ - first);
    if (accumulate) {
      for (Eigen::Index r = 0; r < n; ++r) y[first + r] += acc[r];
    } else {
      for (Eigen::Index r = 0; r < n; ++r) y[first + r] = acc[r];
    }
  }
}

}  // namespace bodyd::inference::detail
