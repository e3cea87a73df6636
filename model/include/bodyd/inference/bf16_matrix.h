// A float matrix held in bfloat16 for matrix-vector products: half the memory a float32 product
// streams, for the online pass of a network whose per-frame cost is its weights' memory traffic
// (docs/model.md, "Weights in bf16").
//
// bfloat16 is float32's upper 16 bits: the same sign and 8-bit exponent, 7 stored mantissa bits
// (8 significant bits: relative rounding error at most 2^-8). Products accumulate in float32. The weights are laid out
// in panels of 32 rows, column after column, so one product reads them once, in order; with AVX2
// and FMA (the default x86-64 build) 32 rows are accumulated in four registers, elsewhere a
// portable loop computes the same sums.
#pragma once

#include <Eigen/Core>

#include <cstdint>
#include <vector>

namespace bodyd::inference::detail {

// float32 -> bfloat16, rounded to nearest, ties to even. `value` must be finite; a value that
// would round past the largest bfloat16 is truncated to it instead of becoming infinite.
[[nodiscard]] std::uint16_t to_bf16(float value);
[[nodiscard]] float from_bf16(std::uint16_t value);

class Bf16Matrix {
 public:
  Bf16Matrix() = default;
  // Rounds each weight of `weights` (rows x cols, finite) to bfloat16.
  explicit Bf16Matrix(const Eigen::Ref<const Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>& weights);

  [[nodiscard]] Eigen::Index rows() const { return rows_; }
  [[nodiscard]] Eigen::Index cols() const { return cols_; }
  // The stored (rounded) weight at (row, col), as float.
  [[nodiscard]] float at(Eigen::Index row, Eigen::Index col) const;

  // y = W x, or y += W x when `accumulate`: x holds cols() floats, y rows(); they must not overlap.
  // Does not allocate.
  void multiply(const float* x, float* y, bool accumulate) const;

 private:
  static constexpr Eigen::Index kPanel = 32;
  // Where row r of a panel sits among its 32 stored values: the AVX2 kernel widens 16 values at a
  // time with unpacklo/unpackhi, which interleave per 128-bit lane, so rows 4..7 and 8..11 of each
  // 16 are stored swapped to come out in order.
  [[nodiscard]] static Eigen::Index slot(Eigen::Index row_in_panel);

  Eigen::Index rows_ = 0, cols_ = 0;
  std::vector<std::uint16_t> panels_;  // ceil(rows / 32) panels of cols x 32 values (rows past the end: 0)
};

}  // namespace bodyd::inference::detail
