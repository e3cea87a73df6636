// tcn-v1 (tcn.h): the loader's row, PyTorch parity on the fixture written by
// training/export_fixture.py (forward and DDIM), causality, and streaming equal to full recomputation.
#include "bodyd/inference/denoiser.h"
#include "bodyd/inference/sampler.h"
#include "bodyd/inference/tcn.h"
#include "test_util.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>
#include <random>

namespace bodyd::test {
namespace {

using inference::Tcn;
using inference::TcnScratch;
using inference::TcnStream;

constexpr double kParityTolerance = 1e-4;

std::shared_ptr<const Tcn> tiny_tcn() {
  const auto model = inference::load_model(tiny_tcn_path());
  return std::make_shared<const Tcn>(*model);
}

TEST(Tcn, TheTableHasItsRowAndTheFixtureLoads) {
  const inference::Architecture* row = inference::find_architecture("tcn-v1");
  ASSERT_NE(row, nullptr);
  EXPECT_NE(inference::architecture_names().find("tcn-v1"), std::string::npos);
  const auto model = inference::load_model(tiny_tcn_path());
  const std::vector<std::pair<std::string, int>> config = {{"W", 10}, {"D", 191}, {"C", 16}, {"K", 3},
                                                           {"L", 3},  {"R", 2},   {"TE", 64}, {"T", 10}};
  EXPECT_EQ(model->config.values(), config);
  const auto denoiser = inference::make_denoiser(*model);
  EXPECT_EQ(denoiser->architecture(), "tcn-v1");
  EXPECT_EQ(denoiser->frames(), 10);
  EXPECT_EQ(denoiser->dim(), 191);
  EXPECT_EQ(denoiser->steps(), 10);
  ASSERT_NE(dynamic_cast<const Tcn*>(denoiser.get()), nullptr);
  // It streams through the Denoiser interface; mlpwin-v1, whose every output sees the whole window, does not.
  EXPECT_NE(denoiser->make_stream(0), nullptr);
  EXPECT_EQ(inference::make_denoiser(*inference::load_model(tiny_model_path()))->make_stream(0), nullptr);
  // Dilations 1, 2, 1 with K = 3: 1 + 2 * 4 frames.
  EXPECT_EQ(dynamic_cast<const Tcn&>(*denoiser).config().receptive_field(), 9);
  // 3 (enc, time1, time2) + 3 blocks * 3 (norm, conv, fc) + 3 (out_norm, dec1, dec2) = 15 weight/bias
  // pairs, + norm.mean, norm.std, diffusion.alpha_bar.
  EXPECT_EQ(inference::expected_tensors(*row, model->config).size(), 2u * 15u + 3u);
  EXPECT_EQ(model->tensor("blocks.1.conv.weight").shape, (std::vector<std::int64_t>{16, 16, 3}));
}

TEST(Tcn, MatchesPyTorchOnTheFixture) { expect_fixture_parity(tiny_tcn(), tiny_tcn_io_path(), "tcn", kParityTolerance); }

TEST(Tcn, OutputsDependOnlyOnTheFrameAndEarlierOnes) {
  const auto net = tiny_tcn();
  TcnScratch s(*net);
  std::mt19937 rng(4);
  const std::size_t D = 191, W = 10, n = W * D;
  auto x = random_window(rng, n, false);
  const auto m = random_window(rng, n, true);
  std::vector<float> a(n), b(n);
  net->forward(x, m, 5, a, s);
  for (std::size_t d = 0; d < D; ++d) x[6 * D + d] += 1.0f;  // frame 6 changes
  net->forward(x, m, 5, b, s);
  EXPECT_EQ(std::vector<float>(a.begin(), a.begin() + 6 * D), std::vector<float>(b.begin(), b.begin() + 6 * D));
  EXPECT_GT(relative_error(std::span(b).subspan(6 * D), std::span(a).subspan(6 * D)), 1e-3);
}

TEST(Tcn, BatchOfTwoEqualsTwoSingles) { expect_a_batch_of_two_equals_two_singles<TcnScratch>(*tiny_tcn(), 8, 2); }

TEST(Tcn, StreamingEqualsFullRecomputation) {
  const auto net = tiny_tcn();
  TcnScratch s(*net);
  const std::size_t D = 191, W = 10;
  std::mt19937 rng(6);
  // A stream of 37 frames, 4 times W.
  const std::size_t frames = 37;
  const auto x = random_window(rng, frames * D, false);
  const auto m = random_window(rng, frames * D, true);
  for (int t : {0, 9}) {
    TcnStream stream(*net, t);
    std::vector<std::vector<float>> streamed(frames, std::vector<float>(D));
    for (std::size_t f = 0; f < frames; ++f)
      stream.push(std::span(x).subspan(f * D, D), std::span(m).subspan(f * D, D), streamed[f]);
    // The first W frames are the window that starts with the stream: every frame's output equals forward()'s.
    std::vector<float> full(W * D);
    net->forward(std::span(x).first(W * D), std::span(m).first(W * D), t, full, s);
    for (std::size_t f = 0; f < W; ++f)
      EXPECT_LE(relative_error(streamed[f], std::span(full).subspan(f * D, D)), 1e-5) << "t " << t << " frame " << f;
    // Later, the newest frame equals forward()'s newest frame on the window of the last W frames
    // (the receptive field, 9 frames, fits in W = 10).
    for (std::size_t end = W; end <= frames; ++end) {
      const std::size_t begin = end - W;
      net->forward(std::span(x).subspan(begin * D, W * D), std::span(m).subspan(begin * D, W * D), t, full, s);
      EXPECT_LE(relative_error(streamed[end - 1], std::span(full).subspan((W - 1) * D, D)), 1e-5)
          << "t " << t << " frame " << end - 1;
    }
    // The check can fail: the window's first frame, whose receptive field reaches before the window
    // (zeros for forward(), the stream's past for the stream), differs.
    EXPECT_GT(relative_error(streamed[frames - W], std::span(full).first(D)), 1e-3);
    // reset() starts a new window.
    stream.reset();
    std::vector<float> again(D);
    stream.push(std::span(x).first(D), std::span(m).first(D), again);
    EXPECT_EQ(again, streamed[0]);
  }
}

// The default shape of training/train.py --arch tcn-v1: W = 64, receptive field 63.
std::shared_ptr<const Tcn> default_shape_tcn(std::uint32_t seed) {
  const auto tiny = inference::load_model(tiny_tcn_path());
  return std::make_shared<const Tcn>(
      random_model(inference::TcnConfig{64, 191, 128, 3, 5, 5, 64, 100}.to_model_config(), seed, *tiny));
}

TEST(Tcn, NewestFrameAloneEqualsTheWindowsLastFrame) {
  std::mt19937 rng(12);
  // The fixture (dilations 1, 2, 1: W = 10 > receptive field 9) and the default shape (dilations
  // 1..16: W = 64 > 63).
  for (const auto& net : {tiny_tcn(), default_shape_tcn(3)}) {
    TcnScratch s(*net);
    const auto D = static_cast<std::size_t>(net->dim()), W = static_cast<std::size_t>(net->frames());
    const std::size_t n = W * D;
    EXPECT_EQ(net->newest_frames().size(), static_cast<std::size_t>(net->config().receptive_field()));
    EXPECT_EQ(net->newest_frames().back(), static_cast<Eigen::Index>(W) - 1);
    for (int t : {0, net->steps() / 2, net->steps() - 1}) {
      auto x = random_window(rng, n, false);
      const auto m = random_window(rng, n, true);
      std::vector<float> full(n), newest(D);
      net->forward(x, m, t, full, s);
      net->forward_newest(x, m, t, newest, s);
      EXPECT_LE(relative_error(newest, std::span(full).subspan((W - 1) * D, D)), 1e-5) << "W " << W << " t " << t;
      // The same through the Denoiser interface.
      std::vector<float> via_base(D);
      const inference::Denoiser& base = *net;
      const auto scratch = base.make_scratch(1);
      EXPECT_TRUE(base.computes_newest_alone());
      base.forward_newest(x, m, t, via_base, *scratch);
      EXPECT_EQ(via_base, newest);
      // The frame before the receptive field does not matter; the oldest frame in it does.
      const std::size_t outside = W - 1 - static_cast<std::size_t>(net->config().receptive_field());
      for (std::size_t d = 0; d < D; ++d) x[outside * D + d] += 3.0f;
      std::vector<float> again(D);
      net->forward_newest(x, m, t, again, s);
      EXPECT_EQ(again, newest);
      for (std::size_t d = 0; d < D; ++d) x[(outside + 1) * D + d] += 3.0f;
      net->forward_newest(x, m, t, again, s);
      EXPECT_GT(relative_error(again, newest), 1e-4);
    }
  }
  expect_a_shared_scratch_keeps_each_networks_past<TcnScratch>(*default_shape_tcn(3), *default_shape_tcn(4), rng);
}

TEST(Tcn, TheSamplerWithAnObservedPastComputesTheNewestFrameAloneToTheSameResult) {
  const auto net = default_shape_tcn(5);
  SamplerOnlineRun run(net, 3);  // checks the first run against DDIM by whole windows
  const std::size_t D = run.D, W = run.W, n = W * D;
  auto& [obs, noise, mask] = run.c;
  inference::Sampler& sampler = run.sampler;
  std::vector<float>& out = run.out;
  // A past frame with one entry unobserved takes the whole-window path, and still matches.
  mask[5 * D + 7] = 0.0f;
  sampler.sample_from_noise(obs, mask, noise, out);
  EXPECT_LE(relative_error(out, ddim_by_full_windows(*net, obs, mask, noise, 3)), 1e-5);
  // sample() in the online case draws the newest frame's noise alone (the past frames are the
  // observations): the generator's first D normals, whatever the past frames' noise would be.
  mask[5 * D + 7] = 1.0f;
  sampler.reseed(9);
  sampler.sample(obs, mask, out);
  std::vector<float> drawn(noise);
  inference::Rng gen(9);
  for (std::size_t i = (W - 1) * D; i < n; ++i) drawn[i] = gen.normal();
  EXPECT_LE(relative_error(out, ddim_by_full_windows(*net, obs, mask, drawn, 3)), 1e-5);
}

TEST(TcnDeathTest, BrokenPreconditionsAbort) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  const auto net = tiny_tcn();
  TcnScratch s(*net);
  const std::size_t n = static_cast<std::size_t>(net->window_size());
  std::vector<float> x(n, 0.0f), m(n, 0.0f), out(n);
  EXPECT_DEATH(net->forward(x, m, net->steps(), out, s), "t must be in");
  std::vector<float> x2(2 * n), m2(2 * n), out2(2 * n);
  EXPECT_DEATH(net->forward(x2, m2, 0, out2, s), "batch");
  EXPECT_DEATH(TcnStream(*net, -1), "t must be in");
  TcnStream stream(*net, 0);
  std::vector<float> frame(190), y(191);
  EXPECT_DEATH(stream.push(frame, frame, y), "one frame");
  std::vector<float> one(191);
  EXPECT_DEATH(net->forward_newest(x, m, 0, out, s), "one frame of D");
  EXPECT_DEATH(net->forward_newest(x2, m2, 0, one, s), "one window");
  EXPECT_DEATH(net->forward_newest(x, m, -1, one, s), "t must be in");
  EXPECT_DEATH(net->forward_newest(x, m, 0, std::span(x).first(191), s), "alias");
}

}  // namespace
}  // namespace bodyd::test
