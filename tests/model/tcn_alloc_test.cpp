// tcn-v1's forward pass, its newest-frame pass, the sampler over it and the streamed evaluation must not allocate,
// nor tcnmlp-v1's forward and newest-frame passes (the allocation counter of tests/support replaces malloc in this
// binary).
#include "bodyd/inference/sampler.h"
#include "bodyd/inference/tcn.h"
#include "bodyd/inference/tcnmlp.h"
#include "test_util.h"

#include "bodyd/test/alloc_counter.h"

#include <gtest/gtest.h>

#include <span>
#include <vector>

namespace bodyd::test {
namespace {

// A batch of two windows of n values (D a frame) with every fourth value observed, their first
// window's spans, and the online mask (the past observed, the newest frame partly), so that the
// sampler takes forward_newest().
struct AllocCase {
  AllocCase(std::size_t n, std::size_t D) : x(2 * n, 0.3f), m(2 * n, 0.0f), out(2 * n), frame_out(D), online(n, 1.0f) {
    for (std::size_t i = 0; i < m.size(); i += 4) m[i] = 1.0f;
    for (std::size_t d = 0; d < D; d += 3) online[n - D + d] = 0.0f;
    x1 = std::span<const float>(x.data(), n);
    m1 = std::span<const float>(m.data(), n);
    out1 = std::span<float>(out.data(), n);
  }
  std::vector<float> x, m, out, frame_out, online;
  std::span<const float> x1, m1;
  std::span<float> out1;
};

TEST(TcnAllocation, ForwardNewestFrameSampleAndStreamDoNotAllocate) {
  if (!AllocationCounter::counts_malloc()) GTEST_SKIP() << "sanitizer build: malloc is not ours to count";
  const auto tiny = inference::load_model(fixtures() / "tiny_tcn.safetensors");
  // The default shape of training/train.py --arch tcn-v1 (2.1 s of history at 30 fps), so Eigen takes
  // the product paths of a real model.
  const auto model = random_model(inference::TcnConfig{64, 191, 128, 3, 5, 5, 64, 100}.to_model_config(), 1, *tiny);
  const auto net = std::make_shared<const inference::Tcn>(model);
  const std::size_t D = 191;
  AllocCase c(static_cast<std::size_t>(net->window_size()), D);
  inference::TcnScratch scratch(*net, 2);
  inference::Sampler sampler(net, inference::SamplerOptions{2, 1.0f, 0.0f}, 1);
  const auto stream = net->make_stream(99);

  AllocationCounter allocations;
  for (int i = 0; i < 2; ++i) {
    net->forward(c.x1, c.m1, 50, c.out1, scratch);
    net->forward(c.x, c.m, 99, c.out, scratch);
    sampler.sample(c.x1, c.m1, c.out1);
    net->forward_newest(c.x1, c.m1, 50, c.frame_out, scratch);
    sampler.sample(c.x1, c.online, c.out1);
    for (std::size_t f = 0; f < 70; ++f)
      stream->push(std::span(c.x).subspan((f % 64) * D, D), std::span(c.m).subspan((f % 64) * D, D), c.frame_out);
  }
  EXPECT_EQ(allocations.count(), 0);
}

TEST(TcnMlpAllocation, ForwardNewestFrameAndSampleDoNotAllocateWithEitherWeights) {
  if (!AllocationCounter::counts_malloc()) GTEST_SKIP() << "sanitizer build: malloc is not ours to count";
  const auto tiny = inference::load_model(fixtures() / "tiny_tcnmlp.safetensors");
  // train.py --arch tcnmlp-v1's defaults on 64-frame windows.
  const auto model =
      random_model(inference::TcnMlpConfig{64, 191, 20, 64, 512, 2, 64, 3, 5, 5, 64, 100}.to_model_config(), 1, *tiny);
  for (const inference::Weights weights : {inference::Weights::f32, inference::Weights::bf16}) {
    SCOPED_TRACE(std::string(inference::weights_name(weights)));
    const auto net = std::make_shared<const inference::TcnMlp>(model, weights);
    AllocCase c(static_cast<std::size_t>(net->window_size()), 191);
    inference::TcnMlpScratch scratch(*net, 2);
    inference::Sampler sampler(net, inference::SamplerOptions{2, 1.0f, 0.0f}, 1);

    AllocationCounter allocations;
    for (int i = 0; i < 2; ++i) {
      net->forward(c.x1, c.m1, 50, c.out1, scratch);
      net->forward(c.x, c.m, 99, c.out, scratch);
      sampler.sample(c.x1, c.m1, c.out1);
      net->forward_newest(c.x1, c.m1, 50, c.frame_out, scratch);  // computes the past
      net->forward_newest(c.x1, c.m1, 20, c.frame_out, scratch);  // reuses it
      sampler.sample(c.x1, c.online, c.out1);
      c.x[0] += 1.0f;  // the next frame's past
    }
    EXPECT_EQ(allocations.count(), 0);
  }
}

}  // namespace
}  // namespace bodyd::test
