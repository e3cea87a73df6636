// tcnmlp-v1 (tcnmlp.h): the loader's row, PyTorch parity on the fixture written by
// training/export_fixture.py (forward and DDIM), what the context sees, the newest-frame pass and
// its cache against whole windows, and the sampler's online path.
#include "bodyd/inference/denoiser.h"
#include "bodyd/inference/sampler.h"
#include "bodyd/inference/tcnmlp.h"
#include "test_util.h"

#include <gtest/gtest.h>

#include <random>

namespace bodyd::test {
namespace {

using inference::TcnMlp;
using inference::TcnMlpConfig;
using inference::TcnMlpScratch;

constexpr double kParityTolerance = 1e-4;

std::shared_ptr<const TcnMlp> tiny_tcnmlp() {
  return std::make_shared<const TcnMlp>(*inference::load_model(tiny_tcnmlp_path()));
}

// The default shape of training/train.py --arch tcnmlp-v1 on 64-frame windows: receptive field 63.
std::shared_ptr<const TcnMlp> default_shape(std::uint32_t seed) {
  const auto tiny = inference::load_model(tiny_tcnmlp_path());
  return std::make_shared<const TcnMlp>(
      random_model(TcnMlpConfig{64, 191, 20, 64, 512, 2, 64, 3, 5, 5, 64, 100}.to_model_config(), seed, *tiny));
}

TEST(TcnMlp, TheTableHasItsRowAndTheFixtureLoads) {
  const inference::Architecture* row = inference::find_architecture("tcnmlp-v1");
  ASSERT_NE(row, nullptr);
  const auto model = inference::load_model(tiny_tcnmlp_path());
  const std::vector<std::pair<std::string, int>> config = {{"W", 10}, {"D", 191}, {"N", 4}, {"E", 8},
                                                           {"H", 16}, {"L", 1},   {"C", 16}, {"K", 3},
                                                           {"B", 3},  {"R", 2},   {"TE", 64}, {"T", 10}};
  EXPECT_EQ(model->config.values(), config);
  const auto denoiser = inference::make_denoiser(*model);
  EXPECT_EQ(denoiser->architecture(), "tcnmlp-v1");
  EXPECT_EQ(denoiser->frames(), 10);
  EXPECT_TRUE(denoiser->computes_newest_alone());
  EXPECT_EQ(denoiser->make_stream(0), nullptr);  // the trunk sees N frames at once
  EXPECT_EQ(dynamic_cast<const TcnMlp&>(*denoiser).config().receptive_field(), 9);
  // cenc, 3 blocks * (norm, conv, fc), cnorm, cdec1, cdec2, ctx, enc, inp, time1, time2, 1 block *
  // (norm, fc1, fc2), out_norm, out, dec1, dec2: 25 weight/bias pairs, + norm.mean, norm.std, alpha_bar.
  EXPECT_EQ(inference::expected_tensors(*row, model->config).size(), 2u * 25u + 3u);
  EXPECT_EQ(model->tensor("inp.weight").shape, (std::vector<std::int64_t>{16, 4 * 8}));
  EXPECT_EQ(model->tensor("cblocks.2.conv.weight").shape, (std::vector<std::int64_t>{16, 16, 3}));
  // A trunk longer than the window is refused, naming the file and the fields.
  auto config_n = TcnMlpConfig::from(model->config);
  config_n.N = 11;
  const auto too_long = random_model(config_n.to_model_config(), 1, *model);
  try {
    (void)inference::make_denoiser(too_long);
    ADD_FAILURE() << "N > W loaded";
  } catch (const inference::ModelFileError& e) {
    EXPECT_NE(std::string(e.what()).find("N = 11 is more than W = 10"), std::string::npos) << e.what();
  }
}

TEST(TcnMlp, MatchesPyTorchOnTheFixture) {
  expect_fixture_parity(tiny_tcnmlp(), tiny_tcnmlp_io_path(), "tcnmlp", kParityTolerance);
}

TEST(TcnMlp, TheContextSeesOnlyObservationsAndTheTrunkOnlyTheNewestFrames) {
  const auto net = tiny_tcnmlp();
  TcnMlpScratch s(*net);
  std::mt19937 rng(3);
  const std::size_t D = 191, W = 10, N = 4, n = W * D;
  auto x = random_window(rng, n, false);
  const auto m = random_window(rng, n, true);
  std::vector<float> a(n), b(n);
  net->forward(x, m, 5, a, s);
  // An unobserved entry of an older frame reaches nothing: the context reads m * x.
  std::size_t hidden = 0;
  while (m[2 * D + hidden] != 0.0f) ++hidden;
  x[2 * D + hidden] += 5.0f;
  net->forward(x, m, 5, b, s);
  EXPECT_EQ(a, b);
  // An observed one of the same frame reaches that frame and every later one, through the context.
  std::size_t seen = 0;
  while (m[2 * D + seen] != 1.0f) ++seen;
  x[2 * D + seen] += 5.0f;
  net->forward(x, m, 5, b, s);
  EXPECT_EQ(std::vector<float>(a.begin(), a.begin() + 2 * D), std::vector<float>(b.begin(), b.begin() + 2 * D));
  EXPECT_GT(relative_error(std::span(b).subspan(2 * D, D), std::span(a).subspan(2 * D, D)), 1e-4);
  EXPECT_GT(relative_error(std::span(b).last(D), std::span(a).last(D)), 1e-4);
  // An unobserved entry of the newest N frames reaches the trunk's outputs (the noisy sample).
  x = random_window(rng, n, false);
  net->forward(x, m, 5, a, s);
  std::size_t noisy = (W - N) * D;
  while (m[noisy] != 0.0f) ++noisy;
  x[noisy] += 5.0f;
  net->forward(x, m, 5, b, s);
  EXPECT_EQ(std::vector<float>(a.begin(), a.begin() + (W - N) * D),
            std::vector<float>(b.begin(), b.begin() + (W - N) * D));
  EXPECT_GT(relative_error(std::span(b).last(N * D), std::span(a).last(N * D)), 1e-4);
}

TEST(TcnMlp, BatchOfTwoEqualsTwoSingles) {
  expect_a_batch_of_two_equals_two_singles<TcnMlpScratch>(*tiny_tcnmlp(), 8, 2);
}

TEST(TcnMlp, NewestFrameAloneEqualsTheWindowsLastFrameWhatTheCacheHolds) {
  std::mt19937 rng(12);
  for (const auto& net : {tiny_tcnmlp(), default_shape(3)}) {
    const auto D = static_cast<std::size_t>(net->dim());
    expect_newest_frame_equals_the_windows_last<TcnMlpScratch>(
        *net, rng, [D](std::vector<float>& x, const std::vector<float>& m, const auto& expect_equal) {
          // An observed entry of the newest frame changes: recomputed.
          std::size_t obs = m.size() - D;
          while (m[obs] != 1.0f) ++obs;
          x[obs] += 1.0f;
          expect_equal(1, "an observation of the newest frame changed");
        });
  }
  // Two networks of one shape sharing a scratch: each computes its own past.
  expect_a_shared_scratch_keeps_each_networks_past<TcnMlpScratch>(*default_shape(3), *default_shape(4), rng);
}

TEST(TcnMlp, TheSamplerWithAnObservedPastComputesTheNewestFrameAloneToTheSameResult) {
  const auto net = default_shape(5);
  SamplerOnlineRun run(net, 4);  // checks the first run against DDIM by whole windows
  run.expect_the_next_window_computed_anew(*net, 4);
}

TEST(TcnMlpDeathTest, BrokenPreconditionsAbort) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  const auto net = tiny_tcnmlp();
  TcnMlpScratch s(*net);
  const std::size_t n = static_cast<std::size_t>(net->window_size());
  std::vector<float> x(n, 0.0f), m(n, 0.0f), out(n), one(191);
  EXPECT_DEATH(net->forward(x, m, net->steps(), out, s), "t must be in");
  std::vector<float> x2(2 * n), m2(2 * n), out2(2 * n);
  EXPECT_DEATH(net->forward(x2, m2, 0, out2, s), "batch");
  EXPECT_DEATH(net->forward_newest(x, m, 0, out, s), "one frame of D");
  EXPECT_DEATH(net->forward_newest(x2, m2, 0, one, s), "one window");
  EXPECT_DEATH(net->forward_newest(x, m, -1, one, s), "t must be in");
  EXPECT_DEATH(net->forward_newest(x, m, 0, std::span(x).first(191), s), "alias");
  const auto other = inference::make_denoiser(*inference::load_model(tiny_tcn_path()));
  const auto wrong = other->make_scratch(1);
  EXPECT_DEATH(net->forward_newest(x, m, 0, one, *wrong), "TcnMlpScratch");
}

}  // namespace
}  // namespace bodyd::test
