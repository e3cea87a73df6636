// bfloat16 online weights (bf16_matrix.h, denoiser.h's Weights): the rounding, the matrix-vector
// product against a double-precision product of the same rounded weights, and tcnmlp-v1's
// newest-frame pass and sampler with bf16 weights against float32 (parity within bfloat16's
// rounding, and not silently float32). The style-held-out effect on the body is measured by
// bodyd-eval (docs/model.md, "Weights in bf16").
#include "bodyd/inference/bf16_matrix.h"
#include "bodyd/inference/denoiser.h"
#include "bodyd/inference/mlpwin.h"
#include "bodyd/inference/sampler.h"
#include "bodyd/inference/tcnmlp.h"
#include "test_util.h"

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>

namespace bodyd::test {
namespace {

using inference::Weights;
using inference::detail::Bf16Matrix;
using inference::detail::from_bf16;
using inference::detail::to_bf16;

TEST(Bf16, RoundsToNearestTiesToEvenAndStaysFinite) {
  EXPECT_EQ(from_bf16(to_bf16(1.0f)), 1.0f);
  EXPECT_EQ(from_bf16(to_bf16(-2.5f)), -2.5f);
  EXPECT_EQ(from_bf16(to_bf16(0.0f)), 0.0f);
  EXPECT_TRUE(std::signbit(from_bf16(to_bf16(-0.0f))));
  // bfloat16 keeps 7 mantissa bits: next to 1 are 1 - 2^-8 below and 1 + 2^-7 above.
  const float ulp = std::ldexp(1.0f, -7);
  EXPECT_EQ(from_bf16(to_bf16(1.0f + 0.49f * ulp)), 1.0f);
  EXPECT_EQ(from_bf16(to_bf16(1.0f + 0.51f * ulp)), 1.0f + ulp);
  // Halfway: to the even neighbour (1 is even, 1 + ulp odd, 1 + 2 ulp even).
  EXPECT_EQ(from_bf16(to_bf16(1.0f + 0.5f * ulp)), 1.0f);
  EXPECT_EQ(from_bf16(to_bf16(1.0f + 1.5f * ulp)), 1.0f + 2.0f * ulp);
  EXPECT_EQ(from_bf16(to_bf16(-(1.0f + 1.5f * ulp))), -(1.0f + 2.0f * ulp));
  // The largest float rounds up past bfloat16's largest: kept finite (truncated) instead.
  const float big = std::numeric_limits<float>::max();
  EXPECT_TRUE(std::isfinite(from_bf16(to_bf16(big))));
  EXPECT_TRUE(std::isfinite(from_bf16(to_bf16(-big))));
  EXPECT_GT(from_bf16(to_bf16(big)), 3.3e38f);
  // At most half a unit in the last place, 2^(e-8) for |v| in [2^e, 2^(e+1)), over many magnitudes.
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> mant(-1.0f, 1.0f);
  for (int i = 0; i < 10000; ++i) {
    const float v = std::ldexp(mant(rng), static_cast<int>(rng() % 60) - 30);
    if (v == 0.0f) continue;
    EXPECT_LE(std::abs(from_bf16(to_bf16(v)) - v), std::ldexp(1.0f, std::ilogb(v) - 8)) << v;
  }
}

// y = W x in double from the stored (rounded) weights.
std::vector<double> reference_product(const Bf16Matrix& w, const std::vector<float>& x) {
  std::vector<double> y(static_cast<std::size_t>(w.rows()), 0.0);
  for (Eigen::Index r = 0; r < w.rows(); ++r)
    for (Eigen::Index c = 0; c < w.cols(); ++c) y[r] += static_cast<double>(w.at(r, c)) * x[c];
  return y;
}

TEST(Bf16, MatrixProductEqualsTheRoundedWeightsProduct) {
  std::mt19937 rng(9);
  std::normal_distribution<float> normal(0.0f, 1.0f);
  // Rows a multiple of the 32-row panel, not one, fewer than one; one column.
  for (const auto& [rows, cols] : {std::pair{64, 40}, std::pair{70, 37}, std::pair{5, 3}, std::pair{33, 1}}) {
    SCOPED_TRACE(testing::Message() << rows << " x " << cols);
    Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> w(rows, cols);
    for (Eigen::Index i = 0; i < w.size(); ++i) w.data()[i] = normal(rng);
    const Bf16Matrix b(w);
    ASSERT_EQ(b.rows(), rows);
    ASSERT_EQ(b.cols(), cols);
    for (Eigen::Index r = 0; r < rows; ++r)
      for (Eigen::Index c = 0; c < cols; ++c) ASSERT_EQ(b.at(r, c), from_bf16(to_bf16(w(r, c)))) << r << ", " << c;
    std::vector<float> x(static_cast<std::size_t>(cols));
    for (float& v : x) v = normal(rng);
    const auto ref = reference_product(b, x);
    // Overwrite: the guard past the end stays untouched.
    std::vector<float> y(static_cast<std::size_t>(rows) + 1, 7.0f);
    b.multiply(x.data(), y.data(), false);
    for (int r = 0; r < rows; ++r) EXPECT_NEAR(y[r], ref[r], 1e-4 * (1.0 + std::abs(ref[r]))) << "row " << r;
    EXPECT_EQ(y[rows], 7.0f);
    // Accumulate: added to what y holds.
    std::vector<float> acc(static_cast<std::size_t>(rows));
    for (int r = 0; r < rows; ++r) acc[r] = static_cast<float>(r) - 3.0f;
    b.multiply(x.data(), acc.data(), true);
    for (int r = 0; r < rows; ++r)
      EXPECT_NEAR(acc[r], ref[r] + r - 3.0, 1e-4 * (1.0 + std::abs(ref[r]) + r)) << "row " << r;
    // The float32 weights differ from the rounded ones by at most bfloat16's relative rounding, 2^-8.
    std::vector<double> exact(static_cast<std::size_t>(rows), 0.0);
    double scale = 0.0;
    for (int r = 0; r < rows; ++r) {
      for (int c = 0; c < cols; ++c) {
        exact[r] += static_cast<double>(w(r, c)) * x[c];
        scale += std::abs(static_cast<double>(w(r, c)) * x[c]);
      }
    }
    for (int r = 0; r < rows; ++r) EXPECT_LE(std::abs(y[r] - exact[r]), std::ldexp(scale, -8) + 1e-4) << "row " << r;
  }
}

TEST(Bf16, WeightNamesParse) {
  EXPECT_EQ(inference::weights_name(Weights::f32), "f32");
  EXPECT_EQ(inference::weights_name(Weights::bf16), "bf16");
  EXPECT_EQ(inference::parse_weights("bf16"), Weights::bf16);
  EXPECT_EQ(inference::parse_weights("f32"), Weights::f32);
  EXPECT_EQ(inference::parse_weights("int8"), std::nullopt);
  EXPECT_EQ(inference::parse_weights(""), std::nullopt);
}

// train.py --arch tcnmlp-v1's defaults on 64-frame windows, random weights of the trained scale.
inference::Model default_shape_model(std::uint32_t seed) {
  const auto tiny = inference::load_model(tiny_tcnmlp_path());
  return random_model(inference::TcnMlpConfig{64, 191, 20, 64, 512, 2, 64, 3, 5, 5, 64, 100}.to_model_config(), seed,
                      *tiny);
}

// train.py's mlpwin-v1 defaults on 20-frame windows, random weights of the trained scale.
inference::Model default_shape_mlpwin(std::uint32_t seed) {
  const auto tiny = inference::load_model(tiny_model_path());
  return random_model(inference::MlpWinConfig{20, 191, 64, 512, 2, 64, 100}.to_model_config(), seed, *tiny);
}

// `model`'s newest-frame pass with bf16 weights is float32's within bfloat16's rounding, uses the
// copies, and leaves forward() in float32; its cached past is the bf16 one.
void expect_newest_frame_within_rounding(const inference::Model& model, const char* name) {
  const auto f32 = inference::make_denoiser(model, Weights::f32);
  const auto bf16 = inference::make_denoiser(model, Weights::bf16);
  EXPECT_EQ(f32->weights(), Weights::f32);
  EXPECT_EQ(bf16->weights(), Weights::bf16);
  const auto D = static_cast<std::size_t>(f32->dim()), n = static_cast<std::size_t>(f32->window_size());
  std::mt19937 rng(17);
  auto x = random_window(rng, n, false);
  const auto m = random_window(rng, n, true);
  const auto sa = f32->make_scratch(1), sb = bf16->make_scratch(1);
  std::vector<float> a(D), b(D), full(n);
  for (int t : {99, 50, 0}) {
    f32->forward_newest(x, m, t, a, *sa);
    bf16->forward_newest(x, m, t, b, *sb);
    const double err = relative_error(b, a);
    std::printf("%s newest frame t=%d: bf16 against float32, relative error %.3g\n", name, t, err);
    EXPECT_LE(err, 5e-3) << name << " t " << t;
    EXPECT_GT(err, 1e-7) << name << " t " << t << ": the bf16 copies were not used";
    // forward() stays float32 whatever the weights.
    bf16->forward(x, m, t, full, *sb);
    EXPECT_LE(relative_error(std::span(full).last(D), a), 1e-5) << name << " t " << t;
    // The cached past is the bf16 one: the same call again gives the same frame.
    std::vector<float> again(D);
    bf16->forward_newest(x, m, t, again, *sb);
    EXPECT_EQ(again, b) << name;
  }
}

TEST(Bf16, TcnMlpNewestFrameWithBf16WeightsMatchesFloat32WithinRounding) {
  expect_newest_frame_within_rounding(default_shape_model(3), "tcnmlp");
  // An architecture without a bf16 path runs float32 and says so.
  const auto tcn = inference::make_denoiser(*inference::load_model(tiny_tcn_path()), Weights::bf16);
  EXPECT_EQ(tcn->weights(), Weights::f32);
}

TEST(Bf16, MlpWinNewestFrameWithBf16WeightsMatchesFloat32WithinRounding) {
  expect_newest_frame_within_rounding(default_shape_mlpwin(3), "mlpwin");
}

// An online K = 2 sample of `model` with bf16 weights stays within rounding of float32's, and the
// observed past comes back as observed.
void expect_online_sample_within_rounding(const inference::Model& model, const char* name) {
  const auto f32 = inference::make_denoiser(model, Weights::f32);
  const auto bf16 = inference::make_denoiser(model, Weights::bf16);
  const auto D = static_cast<std::size_t>(f32->dim()), W = static_cast<std::size_t>(f32->frames());
  const std::size_t n = W * D;
  std::mt19937 rng(21);
  const auto [obs, noise, mask] = random_online_case(rng, W, D);
  inference::Sampler sa(f32, inference::SamplerOptions{2, 1.0f, 0.0f}, 1);
  inference::Sampler sb(bf16, inference::SamplerOptions{2, 1.0f, 0.0f}, 1);
  std::vector<float> a(n), b(n);
  sa.sample_from_noise(obs, mask, noise, a);
  sb.sample_from_noise(obs, mask, noise, b);
  const auto newest_a = std::span(a).last(D), newest_b = std::span(b).last(D);
  std::printf("%s online 2-step sample: bf16 against float32, relative error %.3g\n", name,
              relative_error(newest_b, newest_a));
  EXPECT_LE(relative_error(newest_b, newest_a), 5e-3) << name;
  EXPECT_GT(relative_error(newest_b, newest_a), 1e-7) << name;
  EXPECT_EQ(std::vector<float>(b.begin(), b.end() - static_cast<std::ptrdiff_t>(D)),
            std::vector<float>(a.begin(), a.end() - static_cast<std::ptrdiff_t>(D)))
      << name;
}

TEST(Bf16, TcnMlpOnlineSampleWithBf16WeightsStaysCloseToFloat32) {
  expect_online_sample_within_rounding(default_shape_model(5), "tcnmlp");
}

TEST(Bf16, MlpWinOnlineSampleWithBf16WeightsStaysCloseToFloat32) {
  expect_online_sample_within_rounding(default_shape_mlpwin(5), "mlpwin");
}

}  // namespace
}  // namespace bodyd::test
