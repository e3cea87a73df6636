// Eigen forward pass: against PyTorch's outputs (the parity fixture written by
// training/export_fixture.py) and against the plain double-precision reference.
#include "bodyd/inference/mlpwin.h"
#include "bodyd/inference/sampler.h"
#include "reference_network.h"
#include "test_util.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cstdio>
#include <random>

namespace bodyd::test {
namespace {

using inference::MlpWin;
using inference::MlpWinScratch;

// Parity with PyTorch: relative_error (max |a - b| / max |b|) at most this.
constexpr double kParityTolerance = 1e-4;
// Float forward against the double reference.
constexpr double kReferenceTolerance = 5e-6;

TEST(MlpWin, MatchesPyTorchOnTheFixture) {
  const auto model = inference::load_model(tiny_model_path());
  const auto io = inference::read_tensor_file(tiny_io_path());
  const auto cases = nlohmann::json::parse(io.metadata.at("cases"));
  const MlpWin net(*model);
  MlpWinScratch scratch(net);
  ASSERT_EQ(cases["forward"].size(), 3u);
  for (std::size_t i = 0; i < cases["forward"].size(); ++i) {
    const std::string p = "forward." + std::to_string(i) + ".";
    const int t = cases["forward"][i]["t"];
    const auto& x = io.tensors.at(p + "x").data;
    const auto& m = io.tensors.at(p + "m").data;
    const auto& expected = io.tensors.at(p + "out").data;
    std::vector<float> out(expected.size());
    net.forward(x, m, t, out, scratch);
    const double err = relative_error(out, expected);
    std::printf("forward case %zu (t=%d): relative error vs PyTorch %.3g\n", i, t, err);
    EXPECT_LE(err, kParityTolerance) << "case " << i << " t=" << t;
    // The reference agrees with PyTorch too (so the two checks test the same thing).
    EXPECT_LE(relative_error(reference_forward(*model, x, m, t), expected), kParityTolerance) << "case " << i;
    // And the check can fail: the output at another step differs by far more than the tolerance.
    std::vector<float> other(expected.size());
    net.forward(x, m, (t + 3) % model->config.steps(), other, scratch);
    EXPECT_GT(relative_error(other, expected), 100 * kParityTolerance);
  }
}

TEST(MlpWin, MatchesReferenceOnLargerConfig) {
  const auto tiny = inference::load_model(tiny_model_path());
  // Default-like shape (E, W, D as deployed) with a smaller trunk to keep the naive reference fast.
  const inference::MlpWinConfig config{20, 191, 64, 128, 2, 64, 100};
  const auto model = random_model(config.to_model_config(), 11, *tiny);
  const MlpWin net(model);
  MlpWinScratch scratch(net, 2);
  std::mt19937 rng(5);
  const std::size_t n = static_cast<std::size_t>(net.window_size());
  for (int t : {0, 37, 99}) {
    const auto x = random_window(rng, n, false);
    const auto m = random_window(rng, n, true);
    std::vector<float> out(n);
    net.forward(x, m, t, out, scratch);
    const auto ref = reference_forward(model, x, m, t);
    const double err = relative_error(out, ref);
    std::printf("t=%d: relative error vs double reference %.3g\n", t, err);
    EXPECT_LE(err, kReferenceTolerance) << "t=" << t;
  }
}

TEST(MlpWin, BatchOfTwoEqualsTwoSingles) {
  expect_a_batch_of_two_equals_two_singles<MlpWinScratch>(MlpWin(*inference::load_model(tiny_model_path())), 9, 4);
}

// train.py's mlpwin-v1 defaults on 20-frame windows, random weights.
std::shared_ptr<const MlpWin> default_shape(std::uint32_t seed) {
  const auto tiny = inference::load_model(tiny_model_path());
  return std::make_shared<const MlpWin>(
      random_model(inference::MlpWinConfig{20, 191, 64, 512, 2, 64, 100}.to_model_config(), seed, *tiny));
}

TEST(MlpWin, NewestFrameAloneEqualsTheWindowsLastFrameWhatTheCacheHolds) {
  std::mt19937 rng(12);
  for (const auto& net : {std::make_shared<const MlpWin>(*inference::load_model(tiny_model_path())), default_shape(3)}) {
    EXPECT_TRUE(net->computes_newest_alone());
    expect_newest_frame_equals_the_windows_last<MlpWinScratch>(
        *net, rng, [](std::vector<float>&, std::vector<float>& m, const auto& expect_equal) {
          // A past frame's mask changes: recomputed.
          m[1] = 1.0f - m[1];
          expect_equal(1, "a past mask changed");
        });
  }
  // Two networks of one shape sharing a scratch: each computes its own past.
  expect_a_shared_scratch_keeps_each_networks_past<MlpWinScratch>(*default_shape(3), *default_shape(4), rng);
}

TEST(MlpWin, TheSamplerWithAnObservedPastComputesTheNewestFrameAloneToTheSameResult) {
  const auto net = default_shape(5);
  SamplerOnlineRun run(net, 4);  // checks the first run against DDIM by whole windows
  run.expect_the_next_window_computed_anew(*net, 4);
}

TEST(MlpWin, OutputDependsOnMaskAndStep) {
  const auto model = inference::load_model(tiny_model_path());
  const MlpWin net(*model);
  MlpWinScratch s(net);
  std::mt19937 rng(2);
  const std::size_t n = static_cast<std::size_t>(net.window_size());
  const auto x = random_window(rng, n, false);
  auto m = random_window(rng, n, true);
  std::vector<float> a(n), b(n), c(n);
  net.forward(x, m, 3, a, s);
  net.forward(x, m, 3, b, s);
  EXPECT_EQ(a, b);  // deterministic
  m[17] = 1.0f - m[17];
  net.forward(x, m, 3, c, s);
  EXPECT_NE(a, c);
}

TEST(MlpWin, TimestepEmbedding) {
  std::vector<double> e(8);
  inference::timestep_embedding(0, e);
  for (int i = 0; i < 4; ++i) {
    EXPECT_EQ(e[static_cast<std::size_t>(i)], 0.0);
    EXPECT_EQ(e[static_cast<std::size_t>(4 + i)], 1.0);
  }
  inference::timestep_embedding(3, e);
  // freq_1 = exp(-ln(10000) / 4) = 0.1
  EXPECT_NEAR(e[1], std::sin(0.3), 1e-12);
  EXPECT_NEAR(e[5], std::cos(0.3), 1e-12);
  EXPECT_NEAR(e[0], std::sin(3.0), 1e-12);
}

TEST(NetworkDeathTest, BrokenPreconditionsAbort) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  const auto model = inference::load_model(tiny_model_path());
  const MlpWin net(*model);
  MlpWinScratch s(net);
  const std::size_t n = static_cast<std::size_t>(net.window_size());
  std::vector<float> x(n, 0.0f), m(n, 0.0f), out(n);
  EXPECT_DEATH(net.forward(x, m, model->config.steps(), out, s), "t must be in");
  EXPECT_DEATH(net.forward(x, m, -1, out, s), "t must be in");
  std::vector<float> x2(2 * n), m2(2 * n), out2(2 * n);
  EXPECT_DEATH(net.forward(x2, m2, 0, out2, s), "batch");
  EXPECT_DEATH(net.forward(std::span(x).first(n - 1), m, 0, out, s), "whole windows");
  // The newest-frame pass: one window in, one frame out, a step in range, no aliasing, its own scratch.
  const auto D = static_cast<std::size_t>(net.dim());
  std::vector<float> one(D);
  EXPECT_DEATH(net.forward_newest(x, m, 0, out, s), "one frame of D");
  EXPECT_DEATH(net.forward_newest(x2, m2, 0, one, s), "one window");
  EXPECT_DEATH(net.forward_newest(x, m, -1, one, s), "t must be in");
  EXPECT_DEATH(net.forward_newest(x, m, 0, std::span(x).first(D), s), "alias");
  const inference::Model other = random_model(inference::MlpWinConfig{net.config().W, net.config().D, net.config().E,
                                                                      2 * net.config().H, net.config().L,
                                                                      net.config().TE, net.config().T}
                                                  .to_model_config(),
                                              2, *model);
  MlpWinScratch wrong(MlpWin{other});
  EXPECT_DEATH(net.forward_newest(x, m, 0, one, wrong), "another network");
}

}  // namespace
}  // namespace bodyd::test
